"""The one error type users see.

Anything the user can fix (a config key, a file, an object in their scene) raises
:class:`InputError` with a one-line message that names the key, object or file and what is
allowed. ``run.py`` prints it and exits with code 2; nothing half-written is left behind.
"""


class InputError(Exception):
    """Bad user input: a one-line message naming the key, object or file and what is allowed."""

    exit_code = 2


def require(module: str, extra: str, what: str, package: str | None = None):
    """The imported ``module``, or :class:`InputError` naming the extra that installs it:
    ``{what} needs scipy, which is not installed: pip install 'bpy-pipeline[evaluate]'``."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        name = package or module.split(".")[0]
        raise InputError(f"{what} needs {name}, which is not installed: pip install 'bpy-pipeline[{extra}]' (or pip install {name})") from None


def path_argument(value, name: str = "path"):
    """``value`` when it is a path (``str`` or ``os.PathLike``); else :class:`InputError` naming the argument ``name``."""
    import os

    if isinstance(value, (str, os.PathLike)) and str(value):
        return value
    raise InputError(f"{name}: expected a file or folder path (str or pathlib.Path), got {value!r}")
