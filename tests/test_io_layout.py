"""The output-folder layout per format (io/layout.py, and the registered writers that use it); bpy_pipeline.io stays free of bpy."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import WRITERS, read_las, read_npy_folder, read_ply, read_semantickitti, write_frame_preview
from bpy_pipeline.io.layout import write_frame_las, write_frame_npy, write_frame_ply, write_frame_semantickitti
from bpy_pipeline.io.class_maps import load_class_maps
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.points import empty_points
from samples import random_points

LAYOUT = {"ply": write_frame_ply, "semantickitti": write_frame_semantickitti, "las": write_frame_las, "npy": write_frame_npy}
EXPECTED = {
    "ply": ["ply/000012.ply"],
    "semantickitti": ["sequences/03/velodyne/000012.bin", "sequences/03/labels/000012.label"],
    "las": ["las/000012.las"],
    "npy": [f"npy/000012/{name}.npy" for name in ("coord", "strength", "segment", "instance")],
}
READERS = {
    "ply": lambda paths: read_ply(paths[0]),
    "semantickitti": lambda paths: read_semantickitti(*paths),
    "las": lambda paths: read_las(paths[0]),
    "npy": lambda paths: read_npy_folder(paths[0].parent, load_class_maps()),
}


@pytest.mark.parametrize("fmt", sorted(EXPECTED))
def test_writer_layout_and_contents(tmp_path, fmt):
    pts = random_points(100, np.random.default_rng(0), extent=20.0, instances=100)
    paths = LAYOUT[fmt](tmp_path, 12, pts, 3)
    assert [p.relative_to(tmp_path).as_posix() for p in paths] == EXPECTED[fmt]
    assert all(p.is_file() for p in paths)
    back = READERS[fmt](paths)
    kept = load_class_maps().training[pts["semantic"]] > 0 if fmt == "npy" else slice(None)  # Pointcept: training ids, ignored ones lost
    np.testing.assert_array_equal(back["semantic"][kept], pts["semantic"][kept])
    np.testing.assert_allclose(back["x"], pts["x"], atol=0.0005)
    assert not [p for p in tmp_path.rglob("*") if p.name.startswith(".")]


def test_registered_point_writers_write_the_layout(tmp_path):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.frame import Frame

    pts = random_points(50, np.random.default_rng(4), extent=20.0, instances=100)
    frame = Frame(12, load_config(None, []), np.random.default_rng(0), points=pts)
    for fmt, expected in EXPECTED.items():
        expected = [p.replace("/03/", "/01/") for p in expected]  # the registered writer: frame 12 is block 1 of the default split, the second train unit
        paths = WRITERS.get(fmt).write(frame, tmp_path / fmt)
        assert [p.relative_to(tmp_path / fmt).as_posix() for p in paths] == expected


def test_writers_are_the_four_formats_and_check_the_frame_index(tmp_path):
    assert {"ply", "semantickitti", "las", "npy"} <= set(WRITERS)
    for fmt, write in LAYOUT.items():
        with pytest.raises(InputError, match="frame index"):
            write(tmp_path, -1, empty_points(1), 0)
    assert list(tmp_path.iterdir()) == []


def test_frame_preview_path(tmp_path):
    path = write_frame_preview(tmp_path, 7, random_points(10, np.random.default_rng(0), extent=20.0, instances=100), load_class_table().color_lut())
    assert path == tmp_path / "preview" / "000007.png" and path.read_bytes()[:4] == b"\x89PNG"


BLOCKED_IMPORT = r"""
import importlib, importlib.abc, pkgutil, sys, tempfile
from pathlib import Path

class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("bpy", "bmesh", "mathutils"):
            raise ImportError(f"bpy_pipeline.io imported {name}")

sys.meta_path.insert(0, Block())
import bpy_pipeline.io as io
for module in pkgutil.iter_modules(io.__path__):
    importlib.import_module(f"bpy_pipeline.io.{module.name}")
from bpy_pipeline.lidar.points import empty_points
out = Path(tempfile.mkdtemp())
from bpy_pipeline.io.layout import write_frame_las, write_frame_npy, write_frame_ply, write_frame_semantickitti
for write in (write_frame_las, write_frame_npy, write_frame_ply, write_frame_semantickitti):
    write(out, 0, empty_points(3), 0)
assert not {"bpy", "bmesh", "mathutils"} & set(sys.modules)
print("ok")
"""


def test_io_never_imports_bpy():
    root = Path(__file__).resolve().parents[1]
    result = subprocess.run([sys.executable, "-c", BLOCKED_IMPORT], cwd=root, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stdout.strip() == "ok", result.stderr
