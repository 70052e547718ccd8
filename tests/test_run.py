"""run.py end to end: Python and Blender-style invocations, seeds, bad input, the blend builder."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.io import read_dataset

pytestmark = pytest.mark.bpy
ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--set", "sensor.horizontal_resolution_deg=1.0", "--set", "effects.noise.sigma=0.01"]


def run(*args, cwd=ROOT):
    return subprocess.run([sys.executable, str(ROOT / "run.py"), *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def frame_files(out: Path) -> dict[str, bytes]:
    """The frames' files (not the run's manifest nor the frame records, which hold timings)."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file() and p.name != "manifest.json" and p.parent.name != "records"}


def test_python_and_blender_invocations_write_identical_files(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    first = run("--out", str(a), "--seed", "3", *SMALL)
    assert first.returncode == 0, first.stderr
    blender_style = run("--background", "--factory-startup", "--python", "run.py", "--", "--out", str(b), "--seed", "3", *SMALL)
    assert blender_style.returncode == 0, blender_style.stderr
    other_seed = run("--out", str(c), "--seed", "4", *SMALL)
    assert other_seed.returncode == 0, other_seed.stderr

    files_a, files_b, files_c = frame_files(a), frame_files(b), frame_files(c)
    assert {"ply/000000.ply", "sequences/00/velodyne/000000.bin", "sequences/00/labels/000000.label", "preview/000000.png"} <= set(files_a)
    assert files_a == files_b
    assert files_a.keys() == files_c.keys()
    assert files_a["sequences/00/velodyne/000000.bin"] != files_c["sequences/00/velodyne/000000.bin"]

    manifest = read_dataset(a)
    frame = manifest["frames"][0]
    assert manifest["seed"] == 3 and manifest["versions"]["blender"]
    assert set(frame["timings_s"]) == {"build", "export", "scan", "write"}
    assert frame["points"] == len(np.fromfile(a / "sequences/00/velodyne/000000.bin", np.float32)) // 4
    assert len(frame["sensor_pose"]) == 4


def test_default_job_labels_the_railway(tmp_path):
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.labels import load_class_table

    result = run("--out", str(tmp_path), "--set", "sensor.horizontal_resolution_deg=0.5")
    assert result.returncode == 0, result.stderr
    points = read_ply(tmp_path / "ply" / "000000.ply")
    table = load_class_table()
    seen = {table.names[i] for i in np.unique(points["semantic"])}
    assert {"ground", "ballast", "rail", "sleeper", "mast"} <= seen


def write_blend(path: Path):
    code = f"""
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_plane_add(size=50)
bpy.context.object.name = "Floor.001"
bpy.ops.mesh.primitive_cube_add(size=2, location=(5, 0, 1))
bpy.context.object.name = "Crate"
bpy.context.object["lidar_class"] = "shelf"
bpy.context.object["lidar_instance"] = 42
bpy.ops.mesh.primitive_cube_add(size=1, location=(-5, 0, 3))
bpy.context.object.name = "Helper"
bpy.context.object.hide_render = True
bpy.ops.wm.save_as_mainfile(filepath={str(path)!r})
"""
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


def test_blend_builder_scans_the_users_file(tmp_path):
    from bpy_pipeline.io import read_ply

    blend = tmp_path / "mine.blend"
    write_blend(blend)
    out = tmp_path / "out"
    result = run("--out", str(out), "--set", "scene.builder=blend", "--set", f"scene.path={blend}", "--set", "sensor.position=[0, 0, 1]")
    assert result.returncode == 0, result.stderr
    points = read_ply(out / "ply" / "000000.ply")
    objects = {o["name"]: o for o in read_dataset(out)["frames"][0]["objects"]}
    assert set(objects) == {"Floor.001", "Crate"}  # the render-hidden helper is not scanned
    assert objects["Floor.001"]["class"] == "floor"  # from the name rules
    assert objects["Crate"]["class"] == "shelf" and objects["Crate"]["instance"] == 42
    crate = points[points["instance"] == 42]
    assert len(crate) > 0 and (crate["semantic"] == objects["Crate"]["semantic"]).all()


BAD = {
    "missing file": (["--config", "{tmp}/nope.yaml"], "nope.yaml"),
    "malformed": (["--config", "{tmp}/bad.yaml"], "bad.yaml: not valid YAML"),
    "unknown key": (["--set", "scene.wheels=4"], "scene.wheels: unknown key"),
    "wrong type": (["--set", "sensor.channels=many"], "sensor.channels: expected an integer"),
    "unknown class": (["--set", "scene.builder=primitives", "--set", "scene.shapes=[{type: box, class: banana, name: crate}]"], "object 'crate': lidar_class: unknown class 'banana'"),
    "min range": (["--set", "sensor.min_range=500"], "sensor.min_range: must be >= 0 and below sensor.max_range"),
    "empty scene": (["--set", "scene.builder=primitives", "--set", "scene.shapes=[]"], "scene: nothing to scan"),
    "missing blend": (["--set", "scene.builder=blend", "--set", "scene.path={tmp}/gone.blend"], "scene.path: "),
    "out is a file": (["--out", "{tmp}/afile"], "--out: "),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, case):
    (tmp_path / "bad.yaml").write_text("scene: {builder: [\n")
    (tmp_path / "afile").write_text("x")
    args, expected = BAD[case]
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    out = tmp_path / "out"
    result = run(*(["--out", str(out)] if "--out" not in args else []), *args)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert expected in lines[0]
    written = [p for p in out.rglob("*") if p.is_file()] if out.exists() else []
    assert written == []
