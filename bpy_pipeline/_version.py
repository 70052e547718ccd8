"""The package version (one place: the package root, the manifest and the extension build read it from here)."""

__version__ = "0.1.0"
