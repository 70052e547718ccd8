"""The package version in its one place (bpy_pipeline/_version.py) and the builder packages that are their params'
names (builders/real_scan, builders/blend): what they promise, checked."""

import tomllib
from pathlib import Path

import bpy_pipeline
from bpy_pipeline import _version
from bpy_pipeline.builders import BUILDERS
from bpy_pipeline.builders import blend, real_scan

ROOT = Path(__file__).resolve().parents[1]


def test_one_version_in_the_package_the_project_and_the_extension_manifest():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    assert bpy_pipeline.__version__ == _version.__version__
    assert project.get("version", _version.__version__) == _version.__version__ == manifest["version"]


def test_builder_packages_are_their_params_and_register_them():
    assert BUILDERS.get("real_scan").params is real_scan.RealScanScene
    assert BUILDERS.get("blend").params is blend.BlendScene and BUILDERS.get("blend").check is blend.check
