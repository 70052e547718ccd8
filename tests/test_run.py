"""run.py end to end: Python and Blender-style invocations, seeds, bad input, the blend builder."""

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
    assert set(frame["timings_s"]) == {"build", "export", "scan", "effects", "write"}
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
    "unknown class": (["--set", "scene.builder=primitives", "--set", "scene.shapes=[{type: box, class: banana, name: crate}]"],
                      "object 'crate': lidar_class: unknown class 'banana'"),
    "min range": (["--set", "sensor.min_range=500"], "sensor.min_range: must be >= 0 and below sensor.max_range"),
    "empty scene": (["--set", "scene.builder=primitives", "--set", "scene.shapes=[]"], "scene: nothing to scan"),
    "missing blend": (["--set", "scene.builder=blend", "--set", "scene.path={tmp}/gone.blend"], "scene.path: "),
    "out is a file": (["--out", "{tmp}/afile"], "--out: "),
    "config not utf-8": (["--config", "{tmp}/latin1.yaml"], "latin1.yaml: not UTF-8 text"),
    "scene as a scalar": (["--set", "scene=railway"], "scene: expected a mapping"),
    "sensor as a list": (["--set", "sensor=[1, 2]"], "sensor: expected a mapping"),
    "rays beyond memory": (["--set", "sensor.preset=railway_tls", "--set", "sensor.sampling_factor=6.3", "--set", "limits.rays_per_frame=1e10"],
                           "rays per frame need about"),
    "a hall of 100000 people": (["--set", "scene.builder=industrial_hall", "--set", "scene.people={mean: 100000, std: 0, min: 0, max: 100000}"],
                                "scene.people.max: must be <= 500"),
    "scene out of range": (["--set", "scene.builder=primitives", "--set", "sensor.preset=vlp16", "--set", "sensor.position=[5000, 0, 1]"],
                           "no object of the scene lies within max_range"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, case):
    (tmp_path / "bad.yaml").write_text("scene: {builder: [\n")
    (tmp_path / "afile").write_text("x")
    (tmp_path / "latin1.yaml").write_bytes("scene: {builder: primitives}  # Stra\xdfe\n".encode("latin-1"))
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


def test_numbers_in_exponent_form_are_numbers(tmp_path):
    from bpy_pipeline.config import load_config

    assert load_config(None, ["effects.noise.sigma=2e-3"]).effects.noise.sigma == 0.002


@pytest.fixture
def tiny_mount(tmp_path):
    """A folder on its own small tmpfs (mounting needs root; skipped otherwise)."""
    mounted = []

    def mount(options: str) -> Path:
        folder = tmp_path / f"mnt{len(mounted)}"
        folder.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)], capture_output=True, text=True)
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip()})")
        mounted.append(folder)
        return folder

    yield mount
    for folder in mounted:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def test_read_only_out_refused_before_any_work(tiny_mount):
    out = tiny_mount("ro,size=1m")
    result = run("--out", str(out), *SMALL)
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [f"error: --out: cannot write into {out} (Read-only file system)"]
    assert "frame" not in result.stdout  # nothing was built or scanned


def test_full_disk_refused_before_any_work(tiny_mount):
    out = tiny_mount("size=64k")
    result = run("--out", str(out / "run"), *SMALL)
    assert result.returncode == 2 and " free; one frame of " in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not any((out / "run").rglob("*.ply")) if (out / "run").exists() else True


def test_disk_full_during_a_frame_leaves_no_half_frame(tiny_mount):
    """The estimate passes (a small scan) but the disk fills while a later frame is written."""
    out = tiny_mount("size=8m")
    result = run("--out", str(out / "run"), "--set", "scene.builder=primitives", "--set", "sensor.preset=vlp16", "--set", "sensor.position=[0, 0, 1.5]",
                 "--frames", "40", "--set", "output.formats=[ply,las]")
    assert result.returncode == 2 and "no space left on the device" in result.stderr, result.stderr
    from bpy_pipeline.io import read_dataset

    records = read_dataset(out / "run")["frames"]
    recorded = {f for r in records for f in r["files"]}
    on_disk = {
        str(p.relative_to(out / "run"))
        for p in (out / "run").rglob("*")
        if p.is_file()
        and p.parts[-2] not in ("records",)
        and not any(s.startswith(".") for s in p.relative_to(out / "run").parts)
        and p.name != "manifest.json"
    }
    assert 0 < len(records) < 40 and on_disk <= recorded


def test_empty_frame_warns_with_the_likely_cause(tmp_path):
    result = run("--out", str(tmp_path / "o"), "--set", "sensor.preset=vlp16")  # the railway's station is on the ground
    assert result.returncode == 0, result.stderr
    assert "warning: frame 0: 0 points. The sensor (vlp16" in result.stderr and "a sensor on or under the ground sees nothing" in result.stderr


def test_noise_never_pushes_a_range_past_max_range(tmp_path):
    result = run("--out", str(tmp_path / "o"), "--set", "scene.builder=primitives", "--set",
                 "scene.shapes=[{type: box, size: [1, 30, 30], position: [10.2, 0, 0], class: wall}]",
                 "--set", "sensor.preset=vlp16", "--set", "sensor.position=[0, 0, 0]", "--set", "sensor.max_range=10", "--set", "effects.noise.sigma=0.5",
                 "--set", "output.formats=[ply]")
    assert result.returncode == 0, result.stderr
    from bpy_pipeline.io import read_ply

    points = read_ply(tmp_path / "o" / "ply" / "000000.ply")
    assert len(points) and points["range"].max() <= 10.0


def test_fit_out_under_a_regular_file(tmp_path, real_scan):
    (tmp_path / "file").write_text("x")
    result = subprocess.run([sys.executable, "-m", "bpy_pipeline", "fit", str(real_scan("nuscenes_hdl32e_sweep.bin")), "--out",
                             str(tmp_path / "file" / "model.yaml")], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        f"error: --out: {tmp_path / 'file'} is not a folder (a file stands in the path); give a path in a folder"
    ]


@pytest.mark.parametrize("builder", ["parking", "street", "industrial_hall"])
def test_a_run_of_the_geometry_nodes_builders_frees_what_blender_allocates(tmp_path, builder):
    """Blender reports memory it never freed when it exits ("Not freed memory blocks"): the export of the
    builders' Geometry Nodes instancers must leave none (4.5's instance point clouds did)."""
    result = run("--set", f"scene.builder={builder}", "--set", "frames=1", "--set", "output.formats=[ply]", "--set", "output.preview=false", "--out",
                 str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    assert "Not freed memory blocks" not in result.stderr + result.stdout
