"""Every bad input of the hardening issue's matrix: one line naming what is wrong, exit code 2, no traceback.

Each row is (what, how it is given, the fragment its one line must hold). Rows that need the real
entry points (argparse, a config read from a device, SIGTERM) run ``python run.py`` or
``python -m bpy_pipeline`` in a subprocess; the rest run in-process (the CLI's ``main`` or the reader
itself), which is the same code without the start-up. The stale-lock race is a test of its own:
two processes take the same stale lock many times, never both.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline import cli
from bpy_pipeline.parallel import split
from bpy_pipeline.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable


# ----------------------------------------------------------------------------- helpers
def run_cli(capsys, *argv: str) -> tuple[int, str]:
    """``run.py ARGV`` in-process: (exit code, stderr)."""
    try:
        code = cli.main(["run.py", *argv])
    except SystemExit as exit_:
        code = exit_.code
    return code, capsys.readouterr().err


def one_line(stderr: str, fragment: str) -> None:
    lines = [line for line in stderr.splitlines() if line.strip() and not line.startswith("note: estimate")]
    assert "Traceback" not in stderr, stderr
    assert len(lines) == 1, stderr
    assert fragment in lines[0], lines[0]


def refused(fragment: str, func, *args, **kwargs) -> None:
    """``func(*args)`` raises InputError (exit code 2) with a one-line message holding ``fragment``."""
    with pytest.raises(InputError) as info:
        func(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message and fragment in message, message
    assert info.value.exit_code == 2


def subprocess_run(args: list[str], timeout: float = 120, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=timeout, **kw)


def write(path: Path, text: str | bytes) -> Path:
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


# ----------------------------------------------------------------------------- command line rows (in-process)
CLI_ROWS = [
    ("frames 1e12 with --frames-range 0:1", ["--frames", str(10**12), "--frames-range", "0:1"], "frames: must lie in 1..1000000000"),
    ("frames 2**63", ["--set", f"frames={2**63}"], "frames: must lie in 1..1000000000"),
    ("frames 1e9 with the last --shard", ["--frames", str(10**9), "--shard", "9/10"], "limits.seconds"),
    ("100k people in the garage", ["--set", "scene={builder: parking, population: {person: {count: 100000}}}"], "limits."),
    ("100k primitive shapes", ["--set", "scene={builder: primitives, shapes: [" + ", ".join(["{type: box}"] * 100000) + "]}"],
     "holds more than 100,000 values"),
    ("12k primitive shapes", ["--set", "scene={builder: primitives, shapes: [" + ", ".join(["{type: box}"] * 12000) + "]}"], "limits.objects"),
    ("a 3.7e8-ray sensor", ["--set", "sensor.sampling_factor=4"], "limits.rays_per_frame"),
    ("sphere segments 1e6", ["--set", "scene={builder: primitives, shapes: [{type: sphere, segments: 1000000}]}"], "limits.triangles"),
    ("val_fraction 2", ["--set", "output.kitti.val_fraction=2"], "output.kitti.val_fraction"),
    ("--frames-range with a step", ["--frames", "4", "--frames-range", "0:1:2"], "no step"),
    ("--frames-range backwards", ["--frames", "4", "--frames-range", "3:1"], "--frames-range: expected 0 <= A < B"),
    ("--shard out of range", ["--frames", "4", "--shard", "4/4"], "--shard: expected 0 <= I < N"),
    ("--out empty", ["--out", ""], "--out: empty"),
    ("--workers 0", ["--workers", "0"], "--workers: must be 1"),
    ("--ray at a bad address", ["--ray", "256.1.1.1:1"], "--ray: no Ray head answers at 256.1.1.1:1"),
    ("--ray without a port", ["--ray", "somewhere"], "--ray: expected auto or HOST:PORT"),
    ("limits zero", ["--set", "limits.seconds=0"], "limits.seconds: must be > 0"),
    ("frames 0", ["--frames", "0"], "frames: must lie in 1.."),
    # a sensor the builder cannot keep 0.5 m clear of its solids (docs/builders.md, what every builder guarantees)
    ("railway stations in the masts' line", ["--set", "scene={builder: railway, supports: {layout: single, side: left}, stations: {side: left, offset: 3.5}}"],
     "scene.stations.offset: stations 3.5 m beyond the outer track stand in the masts' line"),
    ("railway stations in the fence's line", ["--set", "scene={builder: railway, trackside: {fences: true, fence_offset: 4.2}}"],
     "scene.stations.offset: stations 4.0 m beyond the outer track stand in the fence's line"),
    ("parking sensor 0.2 m under the ceiling", ["--set", "scene={builder: parking, sensor_height: 2.4}"],
     "scene.sensor_height: must be below the ceiling (2.6 m) by at least 0.5 m"),
    ("parking driveway narrower than the robot's clearance", ["--set", "scene={builder: parking, driveway_width: 0.8}"], "scene.driveway_width: at least 1 m"),
    ("hall desks past its walls", ["--set", "scene={builder: industrial_hall, desks_per_row: 9}"],
     "scene.desks_per_row: 2 row(s) of 9 desk(s) and 3 shelf rack(s) do not fit"),
    ("hall sensor on a shelf", ["--set", "scene={builder: industrial_hall, width: 5, sensor_height: 2.5}"],
     "scene.sensor_height: the sensor 2.5 m above the hall's centre comes within 0.5 m of shelf_0"),
    # Blender's node seeds are 32-bit: a larger street layout_seed crashed in the planting group's modifier (a TypeError)
    ("street layout_seed 2**31", ["--set", f"scene={{builder: street, layout_seed: {2**31}}}"], "scene.layout_seed: must lie in 0..2147483647, got 2147483648"),
    # values that ran out of memory or ran until killed, or crashed, before their key was bounded (the sweep of round twenty-nine)
    ("street terrain_step 1 mm", ["--set", "scene={builder: street, terrain_step: 0.001}"],
     "scene.terrain_step: 0.001 m makes the ground beside the road a grid"),
    ("street crossing narrower than a person", ["--set", "scene={builder: street, crossing_width: 0.0001}"], "scene.crossing_width: must be >= 0.8 m"),
    ("street furniture 1e9 per 100 m", ["--set", "scene={builder: street, furniture_per_100m: 1e9}"], "scene.furniture_per_100m: must lie in 0..100"),
    ("hall 2**31 desk rows", ["--set", f"scene={{builder: industrial_hall, desk_rows: {2**31}}}"], "do not fit the hall's 16 x 12 m floor"),
    ("parking turned 2**31 times", ["--set", f"scene={{builder: parking, rotations: {2**31}}}"], "scene.rotations: at most 36 (one whole turn"),
]


@pytest.mark.parametrize("what, argv, fragment", CLI_ROWS, ids=[r[0] for r in CLI_ROWS])
def test_command_line_row(what, argv, fragment, capsys, tmp_path):
    code, err = run_cli(capsys, "--out", str(tmp_path / "out") if "--out" not in argv else argv[argv.index("--out") + 1],
                        *[a for i, a in enumerate(argv) if not (a == "--out" or (i and argv[i - 1] == "--out"))])
    assert code == 2, err
    one_line(err, fragment)
    assert not (tmp_path / "out").exists(), "refused before any work: nothing written"


def test_a_listening_port_passes_the_ray_probe():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    try:
        cli.check_ray_address(f"127.0.0.1:{server.getsockname()[1]}", timeout=2.0)
    finally:
        server.close()


def test_frame_selection_is_a_range_even_for_a_billion_frames():
    class Args:
        frames_range, shard = None, "999/1000"

    selected = cli.frame_selection(Args, 10**9)
    assert isinstance(selected, range) and len(selected) == 10**6 and selected[0] == 999 * 10**6 and selected[-1] == 10**9 - 1
    for n in (1, 7, 10, 11):  # shard_of agrees with split, part by part
        frames = range(3, 3 + n * 3 + 1)
        assert [list(cli.shard_of(frames, i, 4)) for i in range(4)] == [list(p) for p in split(list(frames), 4)]


# ----------------------------------------------------------------------------- config files
def test_config_from_dev_zero_is_refused_not_read_for_ever():
    result = subprocess_run([PY, "run.py", "--config", "/dev/zero", "--out", "/nonexistent/never"], timeout=60)
    assert result.returncode == 2
    one_line(result.stderr, "larger than 16 MB")


def test_yaml_nested_5000_deep(tmp_path, capsys):
    config = write(tmp_path / "deep.yaml", "a: " + "[" * 5000 + "]" * 5000 + "\n")
    code, err = run_cli(capsys, "--config", str(config), "--out", str(tmp_path / "out"))
    assert code == 2
    one_line(err, "deep.yaml: ")  # libyaml's own bound (not valid YAML) or ours, whichever comes first
    config = write(tmp_path / "deep100.yaml", "a: " + "[" * 100 + "]" * 100 + "\n")
    code, err = run_cli(capsys, "--config", str(config), "--out", str(tmp_path / "out"))
    assert code == 2
    one_line(err, "nested deeper than 64 levels")
    block = "".join(" " * k + f"k{k}:\n" for k in range(500)) + " " * 500 + "v: 1\n"
    code, err = run_cli(capsys, "--config", str(write(tmp_path / "deep_block.yaml", block)), "--out", str(tmp_path / "out"))
    assert code == 2
    one_line(err, "nested deeper than 64 levels")


def test_a_deep_mapping_through_the_api():
    from bpy_pipeline.config import load_config

    deep: dict = {}
    node = deep
    for _ in range(5000):
        node["a"] = {}
        node = node["a"]
    refused("nested deeper than 64 levels", load_config, {"scene": {"builder": "railway"}, "labels": deep})


# ----------------------------------------------------------------------------- argparse: one line, exit 2
@pytest.mark.parametrize("argv, fragment", [
    (["run.py", "--frames", "x"], "argument --frames: invalid int value: 'x'"),
    (["run.py", "--bogus"], "unrecognized arguments: --bogus"),
    (["-m", "bpy_pipeline", "nonsense"], "invalid choice: 'nonsense'"),
    (["-m", "bpy_pipeline", "fit"], "the following arguments are required"),
])
def test_argparse_errors_are_one_line(argv, fragment):
    result = subprocess_run([PY, *argv], timeout=120)
    assert result.returncode == 2
    one_line(result.stderr, fragment)


@pytest.mark.parametrize("option", [["--fields", "0"], ["--intensity-field", "9"], ["--rings", "0"]])
def test_fit_options_that_cannot_read_a_scan(option, tmp_path, capsys):
    from bpy_pipeline.cli.commands import main

    scan = write(tmp_path / "s.bin", np.zeros((32 * 4, 5), np.float32).tobytes())
    code = main(["fit", str(scan), "--out", str(tmp_path / "m.yaml"), *option])
    assert code == 2
    one_line(capsys.readouterr().err, "fit: need --fields >= 4")


# ----------------------------------------------------------------------------- readers
def pcd(header: dict, data: bytes, kind: str = "binary") -> bytes:
    lines = ["VERSION 0.7", "FIELDS x y z intensity", "SIZE 4 4 4 4", "TYPE F F F F", "COUNT 1 1 1 1"]
    lines += [f"{k} {v}" for k, v in header.items()] + [f"DATA {kind}"]
    return ("\n".join(lines) + "\n").encode() + data


def points(n: int) -> np.ndarray:
    return np.arange(4 * n, dtype=np.float32).reshape(n, 4) + 1


def las_bytes(n_claimed: int, n_records: int) -> bytes:
    """A LAS 1.2 file of point format 0 (20-byte records) whose header claims ``n_claimed`` points."""
    header = bytearray(227)
    header[0:4] = b"LASF"
    header[24:26] = bytes([1, 2])
    struct.pack_into("<H", header, 94, 227)  # header size
    struct.pack_into("<I", header, 96, 227)  # offset to point data
    struct.pack_into("<I", header, 100, 0)  # VLRs
    header[104] = 0  # point format 0
    struct.pack_into("<H", header, 105, 20)
    struct.pack_into("<I", header, 107, n_claimed)
    struct.pack_into("<3d", header, 131, 0.01, 0.01, 0.01)
    return bytes(header) + bytes(20 * n_records)


def read_scan(path, fmt=None):
    from bpy_pipeline.io.real_scans import read_real_scan

    return read_real_scan(path, fmt)


def test_binary_pcd_claiming_50000_points_holding_100(tmp_path):
    path = write(tmp_path / "a.pcd", pcd({"WIDTH": 50000, "HEIGHT": 1, "POINTS": 50000}, points(100).tobytes()))
    refused("PCD POINTS claims 50000 points", read_scan, path)
    from bpy_pipeline.io.pcd import read_pcd

    refused("PCD POINTS claims 50000 points", read_pcd, path)


def test_ascii_pcd_claiming_100000_points_with_10_rows(tmp_path):
    rows = "\n".join(" ".join(map(str, r)) for r in points(10)).encode()
    path = write(tmp_path / "a.pcd", pcd({"WIDTH": 100000, "HEIGHT": 1, "POINTS": 100000}, rows, "ascii"))
    refused("the ASCII data holds 10 rows", read_scan, path)


def test_pcd_whose_width_disagrees_with_its_points(tmp_path):
    path = write(tmp_path / "a.pcd", pcd({"WIDTH": 7, "HEIGHT": 1, "POINTS": 100}, points(100).tobytes()))
    refused("WIDTH x HEIGHT = 7 x 1 = 7, but POINTS says 100", read_scan, path)


def test_an_honest_pcd_reads_whole(tmp_path):
    path = write(tmp_path / "a.pcd", pcd({"WIDTH": 100, "HEIGHT": 1, "POINTS": 100}, points(100).tobytes()))
    scan = read_scan(path)
    assert len(scan) == 100 and np.allclose(scan.points[:, 0], points(100)[:, 0])


def test_las_header_claiming_10m_points_with_2000_records(tmp_path):
    pytest.importorskip("laspy")
    path = write(tmp_path / "a.las", las_bytes(10_000_000, 2000))
    refused("claims 10000000", read_scan, path)
    from bpy_pipeline.io.las import read_las

    refused("LAS", read_las, path)  # this package's own reader refuses it too (it reads LAS 1.4 format 6 only)


def test_kitti_bin_with_3_stray_bytes(tmp_path):
    path = write(tmp_path / "a.bin", points(100).tobytes() + b"abc")
    refused("3 bytes left over", read_scan, path, "kitti")


def test_nuscenes_bin_with_a_ring_of_1e9(tmp_path):
    data = np.zeros((64, 5), np.float32)
    data[:, 4] = np.arange(64) % 32
    data[5, 4] = 1e9
    path = write(tmp_path / "a.bin", data.tobytes())
    start = time.perf_counter()
    refused("field ring: expected whole numbers 0 .. 1023; record 5 has 1e+09", read_scan, path, "nuscenes")
    assert time.perf_counter() - start < 5


def test_ply_with_a_lying_header(tmp_path):
    from bpy_pipeline.io.ply import read_ply

    head = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    path = write(tmp_path / "a.ply", head + bytes(12 * 10))
    refused("claims 1000000000000 vertices", read_ply, path)
    refused("not a readable PLY file", read_scan, path)


def test_ply_with_a_lying_header_as_an_object_mesh(tmp_path):
    from bpy_pipeline.mixing.cast import mesh_file_parts

    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            b"element face 1000\nproperty list uchar int vertex_indices\nend_header\n")
    path = write(tmp_path / "a.ply", head + np.eye(3, dtype=np.float32).tobytes() + bytes([3]) + np.array([0, 1, 2], np.int32).tobytes())
    refused("not a readable PLY mesh", mesh_file_parts, str(path), (1.0, 1.0, 1.0))


def test_obj_with_a_face_index_past_its_vertices(tmp_path):
    from bpy_pipeline.mixing.cast import mesh_file_parts

    path = write(tmp_path / "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n")
    refused("triangles: indices 0 .. 98 for 3 vertices", mesh_file_parts, str(path), (1.0, 1.0, 1.0))


def test_obj_with_a_nan_vertex(tmp_path):
    from bpy_pipeline.mixing.cast import mesh_file_parts

    path = write(tmp_path / "a.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    refused("vertex 1 is not finite", mesh_file_parts, str(path), (1.0, 1.0, 1.0))


def test_obj_with_a_word_for_a_number(tmp_path):
    from bpy_pipeline.mixing.cast import mesh_file_parts

    path = write(tmp_path / "a.obj", "v 0 0 0\nv one 0 0\n")
    refused("line 2: malformed 'v' line", mesh_file_parts, str(path), (1.0, 1.0, 1.0))


def test_an_honest_obj_with_relative_indices(tmp_path):
    from bpy_pipeline.mixing.cast import mesh_file_parts

    path = write(tmp_path / "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf -4 -3 -2\nf 1/1 2/2 4/4\n")
    (part,) = mesh_file_parts(str(path), (1.0, 1.0, 1.0))
    assert part.triangles.tolist() == [[0, 1, 2], [0, 1, 3]]


URDF = """<robot name="r"><link name="a"/><link name="b"/>
<joint name="j" type="revolute"><parent link="a"/><child link="{child}"/><limit lower="{lower}" upper="1"/></joint></robot>"""


@pytest.mark.parametrize("child, lower, fragment", [
    ("c", "0", "link 'c' is not a <link> of the file"),
    ("b", "abc", "limit.lower: expected 1 numbers"),
    ("b", "-inf", "limit.lower: expected 1 numbers"),
])
def test_urdf_that_lies(child, lower, fragment, tmp_path):
    from bpy_pipeline.geometry.urdf import read_urdf

    refused(fragment, read_urdf, write(tmp_path / "r.urdf", URDF.format(child=child, lower=lower)))


# ----------------------------------------------------------------------------- the API
ROOM_V = np.array([[x, y, z] for x in (-10, 10) for y in (-10, 10) for z in (0, 4)], float)
ROOM_T = np.array([[0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5]])
LIFTED = np.eye(4)
LIFTED[2, 3] = 1.5
TURNED = np.eye(4)
TURNED[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
API_ROWS = [
    ("(m, 2) triangles", ({"r": (ROOM_V, ROOM_T[:, :2])},), {}, "triangles: expected an (m, 3) array"),
    ("float triangles", ({"r": (ROOM_V, ROOM_T.astype(float))},), {}, "triangles: expected integer vertex indices"),
    ("1-D vertices", ({"r": (ROOM_V.ravel(), ROOM_T)},), {}, "vertices: expected an (n, 3) array"),
    ("indices past the vertices", ({"r": (ROOM_V, ROOM_T + 5)},), {}, "indices 5 .. 12 for 8 vertices"),
    ("NaN vertex", ({"r": (np.where(np.arange(24).reshape(8, 3) == 4, np.nan, ROOM_V), ROOM_T)},), {}, "vertex 1 is not finite"),
    ("NaN pose", ({"r": (ROOM_V, ROOM_T)},), {"pose": np.full((4, 4), np.nan)}, "pose: holds non-finite values"),
    ("NaN reflectivity", ({"r": (ROOM_V, ROOM_T, "wall", "diffuse", float("nan"))},), {"pose": LIFTED}, "reflectivity: expected a number in 0..1"),
    ("3x3 pose", ({"r": (ROOM_V, ROOM_T)},), {"pose": np.eye(3)}, "pose: expected a (4, 4) rigid transform"),
    ("4x3 pose", ({"r": (ROOM_V, ROOM_T)},), {"pose": np.eye(4)[:, :3]}, "pose: expected a (4, 4) rigid transform"),
    ("zero pose", ({"r": (ROOM_V, ROOM_T)},), {"pose": np.zeros((4, 4))}, "pose: not a rigid transform"),
    ("scaled pose", ({"r": (ROOM_V, ROOM_T)},), {"pose": np.diag([2.0, 2.0, 2.0, 1.0])}, "pose: not a rigid transform"),
    ("a list of meshes", ([(ROOM_V, ROOM_T)],), {}, "meshes: expected scene buffers or a mapping"),
    ("a mesh that is not a tuple", ({"r": ROOM_V},), {}, "meshes['r']: expected (vertices (n, 3), triangles (m, 3)"),
    ("a negative seed", ({"r": (ROOM_V, ROOM_T)},), {"seed": -1}, "seed: expected an integer >= 0"),
]


@pytest.mark.parametrize("what, args, kwargs, fragment", API_ROWS, ids=[r[0] for r in API_ROWS])
def test_api_scan_row(what, args, kwargs, fragment):
    import bpy_pipeline as bp

    refused(fragment, bp.scan, *args, **{"sensor": "vlp16", **kwargs})


def test_api_scan_takes_a_rigid_pose_and_a_good_room():
    import bpy_pipeline as bp

    straight = bp.scan({"room": (ROOM_V, ROOM_T, "wall")}, "vlp16", LIFTED, effects={"ideal": True}, seed=1)
    turned = bp.scan({"room": (ROOM_V, ROOM_T, "wall")}, "vlp16", LIFTED @ TURNED, effects={"ideal": True}, seed=1)
    assert len(straight) == len(turned) == 16 * 1809


# ----------------------------------------------------------------------------- the dataset folder
def test_resume_with_fewer_frames_is_refused_and_more_extends(tmp_path):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.dataset import Dataset

    out = tmp_path / "out"
    config = load_config({"scene": {"builder": "parking"}, "frames": 20})
    dataset = Dataset.open(out, config, "new")
    dataset._unlock()  # as a killed run leaves it: a manifest of 20 frames, no records
    refused("holds a run of 20 frames, this config has frames: 10", Dataset.open, out, load_config({"scene": {"builder": "parking"}, "frames": 10}), "resume")
    grown = Dataset.open(out, load_config({"scene": {"builder": "parking"}, "frames": 30}), "resume")
    grown._unlock()
    assert json.loads((out / "manifest.json").read_text())["config"]["frames"] == 30


def test_a_new_run_into_a_folder_of_the_same_run_is_refused_naming_resume(tmp_path):
    """A second --shard of a run (the same config and seed) into its folder without --resume: one line saying the folder
    holds this run's frames, and nothing in the folder changed."""
    from bpy_pipeline.config import load_config
    from bpy_pipeline.dataset import Dataset

    out = tmp_path / "out"
    config = load_config({"scene": {"builder": "parking"}, "frames": 20})
    Dataset.open(out, config, "new")._unlock()
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    refused("holds 0 frames of this run (same config and seed); give --resume", Dataset.open, out, config, "new")
    refused("holds another run (seed 0, 0 frames)", Dataset.open, out, load_config({"scene": {"builder": "railway"}, "frames": 20}), "new")
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def stale_lock(out: Path, holder) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    lock = out / ".lock"
    lock.write_text(holder if isinstance(holder, str) else json.dumps(holder))
    return lock


def dead_pid() -> int:
    child = subprocess.Popen([PY, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_lock_of_a_dead_pid_is_taken_over(tmp_path):
    from bpy_pipeline.dataset import release_lock, take_lock

    lock = stale_lock(tmp_path, {"pid": dead_pid(), "host": socket.gethostname(), "started": "then"})
    said = []
    fd = take_lock(lock, said.append)
    assert json.loads(lock.read_text())["pid"] == os.getpid() and "taking over" in said[0]
    release_lock(lock, fd)
    assert not lock.exists() and not list(tmp_path.glob(".lock*"))


@pytest.mark.parametrize("content", ["", "{garbage", "[1, 2]"])
def test_an_unreadable_lock_is_refused_while_young_and_taken_over_when_old(content, tmp_path):
    from bpy_pipeline.dataset import GARBAGE_LOCK_AGE_S, release_lock, take_lock

    lock = stale_lock(tmp_path, content)
    refused(f"remove {lock}", take_lock, lock)
    old = time.time() - GARBAGE_LOCK_AGE_S - 5
    os.utime(lock, (old, old))
    said = []
    fd = take_lock(lock, said.append)
    assert "unreadable lock" in said[0]
    release_lock(lock, fd)


def test_a_held_lock_is_refused_naming_its_holder(tmp_path):
    from bpy_pipeline.dataset import release_lock, take_lock

    lock = tmp_path / ".lock"
    holder = subprocess.Popen([PY, "-c",
                               f"import sys, time; sys.path.insert(0, {str(ROOT)!r}); from bpy_pipeline.dataset import take_lock; from pathlib import Path; "
                               f"take_lock(Path({str(lock)!r})); print('held', flush=True); time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        refused(f"is being written by pid {holder.pid}", take_lock, lock)
    finally:
        holder.kill()
        holder.wait()
    fd = take_lock(lock)  # its flock died with it: taken over
    release_lock(lock, fd)


RACE = """
import json, os, sys, time
sys.path.insert(0, {root!r})
from pathlib import Path
from bpy_pipeline.dataset import take_lock
from bpy_pipeline.errors import InputError
lock, go, done = (Path(a) for a in sys.argv[1:4])
print("ready", flush=True)  # imported: the parent starts the race only when both are
while not go.exists():
    pass
try:
    fd = take_lock(lock)
except InputError:
    print("refused", flush=True)
    sys.exit(0)
print("took", flush=True)
while not done.exists():  # hold it until the parent has both answers, however slowly the other one ran
    time.sleep(0.01)
"""


def race_once(folder: Path, script: Path) -> int:
    """Two processes take one stale lock at the same moment; returns how many took it.

    Both hold what they took until the parent has read both answers, so a slow second process can never
    find the first one's lock already released (which would be a fair take-over, not a race)."""
    folder.mkdir()
    lock = stale_lock(folder, {"pid": dead_pid(), "host": socket.gethostname(), "started": "then"})
    go, done = folder / "go", folder / "done"
    procs = [subprocess.Popen([PY, str(script), str(lock), str(go), str(done)], stdout=subprocess.PIPE, text=True) for _ in range(2)]
    try:
        assert [p.stdout.readline().strip() for p in procs] == ["ready", "ready"]
        go.touch()
        outs = [p.stdout.readline().strip() for p in procs]
    finally:
        done.touch()
        for p in procs:
            p.communicate(timeout=60)
    assert all(o in ("took", "refused") for o in outs), outs
    return outs.count("took")


def test_two_resumes_on_a_stale_lock_never_both_take_it(tmp_path):
    script = write(tmp_path / "race.py", RACE.format(root=str(ROOT)))
    wins = [race_once(tmp_path / f"try{k}", script) for k in range(4)]  # benchmarks/bench_hardening.py runs 50
    assert wins.count(2) == 0, wins
    assert wins.count(1) == len(wins), wins  # and never both refused


@pytest.mark.parametrize("workers", [[], ["--workers", "2"]], ids=["one process", "two workers"])
def test_bad_input_found_while_building_is_one_line_and_leaves_no_folder(tmp_path, workers):
    """A .blend that is not there is found when the scene is built, in the process that builds it: with workers, theirs.
    The run says it once and leaves no folder behind, as one process does."""
    pytest.importorskip("bpy")
    out = tmp_path / "out"
    result = subprocess_run([PY, "run.py", "--set", "scene.builder=blend", "--set", f"scene.path={tmp_path / 'gone.blend'}", "--frames", "4", "--out",
                             str(out), *workers], timeout=300)
    assert result.returncode == 2
    one_line(result.stderr, "scene.path: ")
    assert not out.exists()


@pytest.mark.parametrize("workers", [[], ["--workers", "2"]], ids=["one process", "two workers"])
def test_sigterm_is_one_line_exit_143_lock_released_frames_kept(tmp_path, workers):
    pytest.importorskip("bpy")
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([PY, "run.py", "--set", "scene.builder=parking", "--frames", "200", "--out", str(out), *workers], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.time() + 120
    while time.time() < deadline and len(list((out / "records").glob("*.json"))) < 2:
        time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith(("note:", "warning:"))]
    assert "Traceback" not in err and len(lines) == 1 and lines[0].startswith("terminated (SIGTERM)"), err
    assert not (out / ".lock").exists()
    kept = len(list((out / "records").glob("*.json")))
    assert kept >= 2
    result = subprocess_run([PY, "run.py", "--set", "scene.builder=parking", "--frames", "200", "--out", str(out), "--frames-range", f"0:{kept}", "--resume"],
                            timeout=300)
    assert result.returncode == 0, result.stderr


SIGTERM_IN_BLENDERS_START = """
import os, signal, sys
class Hook:  # SIGTERM sent while Blender's own startup scripts run (they import bl_ui)
    def find_spec(self, name, path=None, target=None):
        if name == "bl_ui":
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGTERM)
        return None
sys.meta_path.insert(0, Hook())
from bpy_pipeline.cli import exit_process, main
exit_process(main(["run.py", "--set", "scene.builder=parking", "--frames", "3", "--out", sys.argv[1]]))
"""


def test_sigterm_while_blender_starts_stops_the_run_in_one_line(tmp_path):
    """Raised inside Blender's start, SIGTERM landed in Blender's startup scripts, which printed its traceback and
    went on: the run made every frame and exited 0. Held until Blender has started, it stops the run."""
    pytest.importorskip("bpy")
    out = tmp_path / "out"
    result = subprocess_run([PY, "-c", SIGTERM_IN_BLENDERS_START, str(out)], timeout=300)
    assert result.returncode == 143, result.stderr[-2000:]
    one_line(result.stderr, "terminated (SIGTERM)")
    assert not out.exists()


def test_a_signal_that_a_c_extension_wraps_still_stops_the_run_in_one_line(capsys):
    """SIGTERM landing while numba loads a cached kernel comes back as a SystemError raised from the handler's
    exception (seen once in the test above); Ctrl-C likewise. An error raised while handling one, and any other
    error, passes through with its traceback."""
    from bpy_pipeline.cli import Terminated, guarded

    def wrapped(stop):
        def func(_):
            try:
                raise stop()
            except BaseException as err:
                raise SystemError("<function _numba_unpickle> returned a result with an exception set") from err

        return func

    assert guarded(wrapped(Terminated), None) == 143
    assert capsys.readouterr().err.splitlines() == ["terminated (SIGTERM): every frame written so far is committed; --resume continues the run"]

    assert guarded(wrapped(KeyboardInterrupt), None) == 130
    assert capsys.readouterr().err.startswith("interrupted: ")

    def in_handling(_):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise RuntimeError("cleanup failed")

    with pytest.raises(RuntimeError, match="cleanup failed"):
        guarded(in_handling, None)

    def broken(_):
        raise ValueError("a bug")

    with pytest.raises(ValueError, match="a bug"):
        guarded(broken, None)


def test_blenders_start_noise_is_dropped_from_stderr_and_everything_else_said():
    """Where /etc/mtab is missing (containerd's Debian images; a minimal chroot), Blender's start writes "could not get a
    list of mounted file-systems" to stderr: a run's one line of bad input was two. What C and Python write to stderr
    while Blender starts goes through :func:`cli.start_noise_dropped`: that line is dropped, every other one said, in order;
    held in memory, so where no temporary folder can be written (a container's read-only root) the run still starts."""
    code = (
        "import os, sys, tempfile\n"
        "tempfile.tempdir = '/nonexistent/tmp'\n"
        "from bpy_pipeline.cli import start_noise_dropped\n"
        "with start_noise_dropped():\n"
        "    os.write(2, b'could not get a list of mounted file-systems\\nBlender: something else\\n')\n"
        "    print('a Python line', file=sys.stderr)\n"
        "print('after', file=sys.stderr)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines() == ["Blender: something else", "a Python line", "after"]


@pytest.mark.parametrize("closed", [0, 1, 2])
def test_a_run_started_without_a_standard_stream_runs_and_keeps_it_off_its_files(closed, tmp_path):
    """``run.py ... 2>&-`` (a daemon, a cron line) ended with a traceback nobody saw (exit 1): Python has no
    ``sys.stderr`` then. Worse, the first file the run opened took number 2, so what Blender or a library wrote to stderr
    went into it. Now the closed stream is opened on the null device first: the run makes its frame, and a file it
    opens never takes a standard stream's number."""

    def without_it(*command: str) -> subprocess.CompletedProcess:  # the command started by a shell that closed the stream
        return subprocess.run(["sh", "-c", f'exec "$@" {closed}>&-', "sh", *command], cwd=ROOT, capture_output=closed == 0, timeout=300, check=False)

    code = (
        "import os, sys\n"
        "from bpy_pipeline.cli import standard_streams_open\n"
        "standard_streams_open()\n"
        "f = open(sys.argv[1], 'w')\n"
        "print(f.fileno(), os.fstat(%d).st_rdev == os.stat(os.devnull).st_rdev, file=open(sys.argv[2], 'w'))\n" % closed
    )
    assert without_it(sys.executable, "-c", code, str(tmp_path / "data"), str(tmp_path / "said")).returncode == 0
    fileno, on_null = (tmp_path / "said").read_text().split()
    assert int(fileno) > 2 and on_null == "True"
    out = tmp_path / "run"
    assert without_it(sys.executable, "run.py", "--out", str(out), "--frames", "1").returncode == 0
    assert len(list((out / "ply").glob("*.ply"))) == 1 and (out / "manifest.json").is_file()


@pytest.mark.parametrize("case", ["the temporary folder itself", "another name"])
def test_the_end_of_a_run_removes_only_blenders_own_session_folder(tmp_path, monkeypatch, case):
    """``cli.exit_process`` removes ``bpy.app.tempdir`` (Blender's ``blender_XXXXXX``, made for this process). Where Blender
    could not make it, ``tempdir`` is the temporary folder it was given, perhaps a user's folder of a like name: that one,
    and a folder of any other name, is left whole."""
    user = tmp_path / ("blender_ab12CD" if case == "the temporary folder itself" else "blender_mine")
    (user / "sub").mkdir(parents=True)
    (user / "sub" / "theirs.txt").write_text("kept")
    monkeypatch.setenv("TMPDIR", str(user if case == "the temporary folder itself" else tmp_path))
    cli.remove_blender_session_folder(types.SimpleNamespace(app=types.SimpleNamespace(tempdir=f"{user}/")))
    assert (user / "sub" / "theirs.txt").read_text() == "kept"
    session = user / "blender_Xy9z0Q"  # what Blender makes inside the folder it was given: removed
    (session / "render").mkdir(parents=True)
    monkeypatch.setenv("TMPDIR", str(user))
    cli.remove_blender_session_folder(types.SimpleNamespace(app=types.SimpleNamespace(tempdir=f"{session}/")))
    assert not session.exists() and (user / "sub" / "theirs.txt").read_text() == "kept"
