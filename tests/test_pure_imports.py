"""The pure part (config, geometry, lidar, io, buffers, labels) never imports bpy."""

import importlib.util
import pkgutil
import subprocess
import sys
from pathlib import Path

import bpy_pipeline

ROOT = Path(__file__).resolve().parents[1]
BPY_SIDE = {"bpy_pipeline.export", "bpy_pipeline.compat", "bpy_pipeline.scenes", "bpy_pipeline.pipeline_bpy"}


OPTIONAL = {"bpy_pipeline.lidar.numba_kernels": "numba"}  # modules that need an optional package (the 'fast' extra)


def pure_modules() -> list[str]:
    names = []
    for info in pkgutil.walk_packages(bpy_pipeline.__path__, "bpy_pipeline."):
        if any(info.name == b or info.name.startswith(b + ".") for b in BPY_SIDE):
            continue
        if info.name in OPTIONAL and importlib.util.find_spec(OPTIONAL[info.name]) is None:
            continue
        names.append(info.name)
    return names


def test_pure_modules_import_and_run_with_bpy_blocked():
    modules = pure_modules()
    assert {"bpy_pipeline.lidar.scanner", "bpy_pipeline.io.ply", "bpy_pipeline.config", "bpy_pipeline.geometry.primitives"} <= set(modules)
    code = f"""
import sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('bpy', 'bmesh', 'mathutils'):
            raise ImportError('blocked: ' + name)
sys.meta_path.insert(0, Block())
import importlib
for name in {modules!r}:
    importlib.import_module(name)
# and run the pure chain: config -> pattern -> scan of numpy buffers -> writer
import numpy as np
from bpy_pipeline.config import load_config
from bpy_pipeline.buffers import SceneBuffers, ObjectTable
from bpy_pipeline.geometry import primitives
from bpy_pipeline.lidar.raycast import RayCaster
from bpy_pipeline.lidar.scanner import scan
from bpy_pipeline.lidar.sensors import sensor_pattern
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.io import write_ply, read_ply
cfg = load_config()
v, t = primitives.box(10, 10, 10)
objs = ObjectTable(['room'], [''], ['wall'], np.array([17], np.uint16), np.array([1], np.uint32), np.array([0], np.uint8), np.array([0.5], np.float32))
buf = SceneBuffers(v, t, np.zeros(len(t), np.int32), objs)
pts, beam = scan(RayCaster(buf, frame=np.eye(4)), buf, sensor_pattern(cfg.sensor.spec), pose_matrix([0, 0, 0], [0, 0, 0]), 0.1, 100)
assert len(pts) == len(sensor_pattern(cfg.sensor.spec)), len(pts)
assert 'bpy' not in sys.modules
print('ok')
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("ok")
