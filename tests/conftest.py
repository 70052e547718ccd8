"""Shared fixtures: where the real scans are, and the bpy marker skip."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

REAL_SCANS = Path(os.environ.get("BPY_PIPELINE_REAL_SCANS", Path(__file__).resolve().parents[2] / "shared" / "real_scans"))
HAS_BPY = importlib.util.find_spec("bpy") is not None


@pytest.fixture(scope="session")
def real_scans_folder() -> Path:
    """The folder of the real scans (it may be absent; tests skip with a reason then)."""
    return REAL_SCANS


@pytest.fixture
def real_scan():
    """Path of a file in ../shared/real_scans; skips with a reason where it is absent."""

    def get(name: str) -> Path:
        path = REAL_SCANS / name
        if not path.exists():
            pytest.skip(f"real scan {path} is absent (set BPY_PIPELINE_REAL_SCANS to its folder)")
        return path

    return get


def pytest_collection_modifyitems(config, items):
    if HAS_BPY:
        return
    skip = pytest.mark.skip(reason="needs the bpy module (pip install 'bpy==4.5.*' on Python 3.11)")
    for item in items:
        if "bpy" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def bpy_scene():
    """An empty Blender scene (what a builder keeps across frames is owned by each run or call, never by a module)."""
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy


RENDER_PROBE = """
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.engine = "BLENDER_WORKBENCH"
scene.render.resolution_x = scene.render.resolution_y = 8
camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
scene.collection.objects.link(camera)
scene.camera = camera
bpy.ops.render.render()
"""


@pytest.fixture(scope="session")
def blender_renders() -> None:
    """Skip unless the bpy module can render (Workbench needs an OpenGL driver through EGL: without Mesa's
    libegl-mesa0 and libgl1-mesa-dri, which setup.sh installs, Blender aborts the whole process)."""
    pytest.importorskip("bpy")
    probe = subprocess.run([sys.executable, "-c", RENDER_PROBE], capture_output=True, text=True, timeout=120)
    if probe.returncode != 0:
        pytest.skip("the bpy module cannot render here (no OpenGL driver through EGL: install libegl1 libegl-mesa0 libgl1-mesa-dri)")
