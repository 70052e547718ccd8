"""The compiled scan is the default: setup.sh's environment (and `pip install bpy_pipeline`) imports the kernel."""

import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_numba_is_a_default_dependency():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert any(dep.split(">")[0].split("=")[0].strip() == "numba" for dep in project["dependencies"])


def test_the_installed_environment_compiles_the_scan_kernel():
    from bpy_pipeline.compiled import numba_available
    from bpy_pipeline.lidar.cast import kernels

    try:  # numba ships wheels for every Python this project supports; where none installs, the numpy path runs
        import numba  # noqa: F401
    except ImportError:
        pytest.skip("numba did not install on this Python: the scan takes the numpy path (same bytes)")
    assert numba_available()
    assert kernels.compiled() is not None
