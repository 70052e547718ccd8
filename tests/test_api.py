"""The public API: the README's example runs, with bpy and without it where it needs none."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bpy_pipeline
from bpy_pipeline import api

ROOT = Path(__file__).resolve().parents[1]


def example() -> str:
    """The example of the API's docstring, as code."""
    block = api.__doc__.split("Example (runs as a test, tests/test_api.py)::", 1)[1]
    return "\n".join(line[4:] for line in block.splitlines() if line.startswith("    ") or not line.strip())


def scan_part() -> str:
    return example().split("# a run with Blender", 1)[0]


def test_public_names():
    assert set(bpy_pipeline.__all__) >= {"load_config", "run", "scan", "read_ply", "read_semantickitti", "read_las", "read_npy_folder", "read_dataset"}


def test_scan_example_runs_without_bpy():
    blocked = ("import sys\nclass Block:\n    def find_spec(self, name, path=None, target=None):\n"
               "        if name.split('.')[0] in ('bpy', 'mathutils'):\n            raise ImportError(name)\nsys.meta_path.insert(0, Block())\n")
    result = subprocess.run([sys.executable, "-c", blocked + scan_part() + "\nassert 'bpy' not in sys.modules\nprint('ok')"], cwd=ROOT, capture_output=True,
                            text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("ok")


@pytest.mark.bpy
def test_whole_example_runs_with_bpy(tmp_path):
    result = subprocess.run([sys.executable, "-c", example()], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "out/parking/ply/000001.ply").is_file()


def test_scan_labels_and_effects_follow_the_arguments():
    v = np.array([[x, y, z] for x in (-10, 10) for y in (-10, 10) for z in (-1.5, 2.5)], float)
    t = np.array([[0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5]])
    ideal = bpy_pipeline.scan({"room": (v, t, "wall", "diffuse", 0.7)}, {"preset": "vlp16", "rotation_hz": 20.0},
                              effects={"ideal": True, "noise": {"sigma": 0.0}})
    noisy = bpy_pipeline.scan({"room": (v, t, "wall", "diffuse", 0.7)}, {"preset": "vlp16", "rotation_hz": 20.0},
                              effects={"ideal": True, "noise": {"sigma": 0.05}}, seed=3)
    again = bpy_pipeline.scan({"room": (v, t, "wall", "diffuse", 0.7)}, {"preset": "vlp16", "rotation_hz": 20.0},
                              effects={"ideal": True, "noise": {"sigma": 0.05}}, seed=3)
    from bpy_pipeline.labels import load_class_table

    assert len(ideal) == len(noisy) and set(np.unique(ideal["semantic"])) == {load_class_table().id_of("wall")}
    assert noisy.tobytes() == again.tobytes()
    assert 0.03 < np.std(noisy["range"] - ideal["range"]) < 0.07
    with pytest.raises(bpy_pipeline.errors.InputError, match=re.escape("meshes['room'] class")):
        bpy_pipeline.scan({"room": (v, t, "no such class")}, "vlp16")
