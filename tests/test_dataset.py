"""The output folder as a dataset: frame ranges, atomic frames under kill -9, resume, refusal, lock, workers, Ray."""

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.io import read_dataset

pytestmark = pytest.mark.bpy
ROOT = Path(__file__).resolve().parents[1]
PARKING = ["--set", "scene.builder=parking", "--set", "output.formats=[ply,semantickitti]", "--seed", "11"]
RAILWAY = ["--set", "scene.stations.count=3", "--set", "sensor.horizontal_resolution_deg=1.0", "--set", "sensor.vertical_resolution_deg=1.0", "--set",
           "output.formats=[ply]", "--set", "output.preview=false", "--seed", "2"]


def cli(*args, env=None, **kwargs):
    return subprocess.run([sys.executable, str(ROOT / "run.py"), *args], cwd=ROOT, capture_output=True, text=True, timeout=600, env=env, **kwargs)


def frame_files(out: Path) -> dict[str, bytes]:
    """Every file of the frames (not the manifest, records or indexes, which hold timings or the run's extent)."""
    skip = {"manifest.json", "train.txt", "val.txt", "test.txt", "semantic-kitti.yaml", "calib.txt", "poses.txt", "times.txt", "npy_train.json", "npy_val.json",
            "npy_test.json",
            "semantickitti_infos_train.pkl", "semantickitti_infos_val.pkl", "semantickitti_infos_test.pkl",
            "openpcdet_kitti_dataset.yaml", "openpcdet_pv_rcnn.yaml", "openpcdet_pointpillar.yaml", "mmdet3d_pointpillars_kitti.py", "custom_dataset.yaml",
            "pv_rcnn.yaml"}  # the writers' index files
    files = (p for p in sorted(out.rglob("*")) if p.is_file() and p.name not in skip)
    return {
        str(p.relative_to(out)): p.read_bytes()
        for p in files
        if p.parent.name != "records" and not any(part.startswith(".") for part in p.relative_to(out).parts)
    }


def consistent(out: Path) -> set[int]:
    """Check that every frame on disk is complete and recorded, or absent; returns the recorded frames.

    Files a killed run was moving into place are named by its leftover intent (``.moving/``) and are
    not part of the dataset: the next start removes them.
    """
    records = read_dataset(out)["frames"] if (out / "manifest.json").exists() else []
    recorded = {str(rel) for r in records for rel in r["files"]}
    for r in records:
        for rel, digest in r["sha256"].items():
            assert (out / rel).is_file(), rel
    pending = {rel for intent in (out / ".moving").glob("*.json") for rel in json.loads(intent.read_text() or "[]")}
    assert not pending & recorded
    on_disk = set(frame_files(out))
    assert on_disk <= recorded | pending, sorted(on_disk - recorded - pending)[:5]
    return {r["index"] for r in records}


@pytest.fixture(scope="module")
def full_parking(tmp_path_factory):
    out = tmp_path_factory.mktemp("full") / "parking"
    done = cli("--out", str(out), "--frames", "10", *PARKING)
    assert done.returncode == 0, done.stderr
    return out


def test_frames_5_to_9_alone_give_the_bytes_of_the_full_run(full_parking, tmp_path):
    part = tmp_path / "part"
    done = cli("--out", str(part), "--frames", "10", "--frames-range", "5:10", *PARKING)
    assert done.returncode == 0, done.stderr
    full, alone = frame_files(full_parking), frame_files(part)
    assert alone and all("00000" in k for k in alone)
    assert {k: full[k] for k in alone} == alone
    assert consistent(part) == {5, 6, 7, 8, 9}


def test_the_parts_of_a_run_made_one_after_another_in_one_folder(full_parking, tmp_path):
    """``--shard 0/2`` then ``--shard 1/2`` into the same folder, as docs/datasets.md shows the parts of a run: the second
    is told the folder holds this run's frames and to give --resume, which adds its part: the full run's bytes."""
    out = tmp_path / "run"
    assert cli("--out", str(out), "--frames", "10", "--shard", "0/2", *PARKING).returncode == 0
    second = cli("--out", str(out), "--frames", "10", "--shard", "1/2", *PARKING)
    assert second.returncode == 2 and second.stderr.strip().splitlines() == [
        f"error: --out: {out} holds 5 frames of this run (same config and seed); give --resume to add the frames asked for to them or --overwrite to start "
        "it again"
    ]
    assert consistent(out) == {0, 1, 2, 3, 4}
    done = cli("--out", str(out), "--frames", "10", "--shard", "1/2", "--resume", *PARKING)
    assert done.returncode == 0, done.stderr
    assert frame_files(out) == frame_files(full_parking)


def test_a_frame_of_a_scene_serving_several_frames_alone(tmp_path):
    """A railway built once for three stations: frames 4 and 5 alone scan the scene frame 3 built."""
    full, part = tmp_path / "full", tmp_path / "part"
    assert cli("--out", str(full), "--frames", "6", *RAILWAY).returncode == 0
    done = cli("--out", str(part), "--frames", "6", "--shard", "2/3", *RAILWAY)
    assert done.returncode == 0, done.stderr
    files = frame_files(part)
    assert sorted(files) == ["ply/000004.ply", "ply/000005.ply"]
    assert files == {k: frame_files(full)[k] for k in files}


def test_a_second_run_into_the_folder_refuses(full_parking, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(full_parking, out)
    other_seed = cli("--out", str(out), "--frames", "10", *PARKING, "--seed", "12")
    fewer = cli("--out", str(out), "--frames", "3", *PARKING)
    assert other_seed.returncode == fewer.returncode == 2
    assert other_seed.stderr.strip().splitlines() == [
        f"error: --out: {out} holds another run (seed 11, 10 frames); give --resume to continue it (same config and seed) or --overwrite to replace it"
    ]
    assert fewer.stderr.strip().splitlines() == [  # the same run (frames is not part of its key), as a --shard of it meets it
        f"error: --out: {out} holds 10 frames of this run (same config and seed); give --resume to add the frames asked for to them or --overwrite to start "
        "it again"
    ]
    resumed_other = cli("--out", str(out), "--frames", "10", *PARKING, "--seed", "12", "--resume")
    assert resumed_other.returncode == 2 and "another config or seed (differs in: seed)" in resumed_other.stderr
    assert frame_files(out) == frame_files(full_parking)
    replaced = cli("--out", str(out), "--frames", "2", *PARKING, "--seed", "12", "--overwrite")
    assert replaced.returncode == 0, replaced.stderr
    assert consistent(out) == {0, 1} and read_dataset(out)["seed"] == 12


def test_two_runs_at_once_one_refuses(tmp_path, killed_run_environment):
    out = tmp_path / "busy"
    first = subprocess.Popen([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--frames", "40", *PARKING], cwd=ROOT, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True, env=killed_run_environment)
    try:
        deadline = time.time() + 60
        while not (out / ".lock").exists() and time.time() < deadline:
            time.sleep(0.05)
        second = cli("--out", str(out), "--frames", "40", *PARKING, "--resume")
        assert second.returncode == 2
        assert f"is being written by pid {first.pid} on {socket.gethostname()}" in second.stderr
    finally:
        first.kill()
        first.wait()


def test_kill_9_at_random_points_then_resume_gives_the_uninterrupted_bytes(full_parking, tmp_path, killed_run_environment):
    rng = np.random.default_rng(0)
    reference = frame_files(full_parking)
    runs = int(os.environ.get("BPY_PIPELINE_KILL_RUNS", "20"))
    for k in range(runs):
        out = tmp_path / f"killed{k}"
        proc = subprocess.Popen([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--frames", "10", *PARKING], cwd=ROOT, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, env=killed_run_environment)
        time.sleep(float(rng.uniform(0.6, 2.4)))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        if not (out / "manifest.json").exists():
            continue  # killed before the run began: nothing to resume
        consistent(out)  # what a killed run leaves is whole frames or nothing (after the next start's clean-up)
        done = cli("--out", str(out), "--frames", "10", *PARKING, "--resume")
        assert done.returncode == 0, done.stderr
        assert consistent(out) == set(range(10))
        assert frame_files(out) == reference
        assert not (out / ".lock").exists() and not (out / ".staging").exists() and not any((out / ".moving").glob("*"))


def test_a_kill_during_the_move_phase_leaves_no_frame_then_resume_completes(full_parking, tmp_path, monkeypatch, bpy_scene):
    """Forced: the process dies after the first of a frame's files is moved into place."""
    # bpy_scene: an empty Blender scene, as run.py starts from (the startup cube would be scanned as an unlabelled object)
    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import run_frames

    config = load_config(None, ["scene.builder=parking", "output.formats=[ply,semantickitti]", "seed=11", "frames=10"])
    out = tmp_path / "moved"
    frames = run_frames(config, out)
    next(frames)  # frame 0 committed
    original, moved = Path.replace, []

    def dying_replace(self, target):
        if moved:
            raise SystemExit("killed")
        moved.append(target)
        return original(self, target)

    monkeypatch.setattr(Path, "replace", dying_replace)
    with pytest.raises(SystemExit):
        next(frames)
    monkeypatch.setattr(Path, "replace", original)
    (out / ".lock").unlink(missing_ok=True)  # a killed process leaves its lock (a dead pid on this host is taken over anyway)
    assert moved and Path(moved[0]).exists()  # a file of frame 1 in place, without its record
    assert len(read_dataset(out)["frames"]) == 1
    done = cli("--out", str(out), "--frames", "10", *PARKING, "--resume")
    assert done.returncode == 0, done.stderr
    assert "removed the files of frame 000001" in done.stderr + done.stdout
    assert frame_files(out) == frame_files(full_parking)


def test_resume_removes_the_temporary_files_of_writes_a_kill_cut_short(full_parking, tmp_path):
    """A kill while an intent, a record or the manifest is being written leaves its temporary file (the random
    kills of the test above hit this once in a CI run); the next start removes them, and only them."""
    out = tmp_path / "cut"
    shutil.copytree(full_parking, out)
    (out / "records" / "000004.json").unlink()  # a frame left to make again, so the resume writes
    leftovers = [out / ".moving" / ".000004.json.0a1b2c3d.tmp", out / "records" / ".000004.json.deadbeef.tmp", out / ".manifest.json.12345678.tmp"]
    for path in leftovers:
        path.parent.mkdir(exist_ok=True)
        path.write_text('["ply/000004.ply"')  # cut short
    kept = out / "ply" / ".notes.tmp.txt"  # not a temporary file of ours
    kept.write_text("mine")
    done = cli("--out", str(out), "--frames", "10", *PARKING, "--resume")
    assert done.returncode == 0, done.stderr
    assert not any(path.exists() for path in leftovers) and kept.read_text() == "mine"
    assert not (out / ".moving").exists() and not (out / ".staging").exists()
    kept.unlink()
    assert consistent(out) == set(range(10)) and frame_files(out) == frame_files(full_parking)


def test_resume_redoes_a_frame_whose_file_changed(full_parking, tmp_path):
    out = tmp_path / "tampered"
    shutil.copytree(full_parking, out)
    (out / "ply" / "000003.ply").write_bytes(b"not a ply")
    done = cli("--out", str(out), "--frames", "10", *PARKING, "--resume")
    assert done.returncode == 0 and "frame 000003 does not match its record" in done.stdout + done.stderr
    assert frame_files(out) == frame_files(full_parking)


def test_two_workers_give_the_bytes_of_one_process(full_parking, tmp_path):
    out = tmp_path / "workers"
    done = cli("--out", str(out), "--frames", "10", *PARKING, "--workers", "2")
    assert done.returncode == 0, done.stderr
    assert frame_files(out) == frame_files(full_parking)
    assert consistent(out) == set(range(10))
    assert (out / "kitti" / "ImageSets" / "train.txt").read_text() == (full_parking / "kitti" / "ImageSets" / "train.txt").read_text()


def test_workers_frames_drive_the_runs_one_progress_bar(full_parking, tmp_path):
    """On a terminal, --workers 2 shows one progress bar that reaches every frame (the workers' frame lines said by
    the run's own process), not a bar per worker on one line beside the run's own left at 0."""
    pty = pytest.importorskip("pty", reason="a pseudo-terminal is POSIX's")
    import fcntl
    import struct
    import termios

    master, terminal = pty.openpty()
    fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 200, 0, 0))
    out = tmp_path / "bar"
    proc = subprocess.Popen([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--frames", "10", *PARKING, "--workers", "2"], cwd=ROOT,
                            stdin=terminal, stdout=terminal, stderr=terminal)
    os.close(terminal)
    shown = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # the terminal's last holder has ended
            break
        if not chunk:
            break
        shown += chunk
    os.close(master)
    assert proc.wait(timeout=600) == 0, shown.decode(errors="replace")[-2000:]
    states = re.findall(r"(\d+)/(\d+) \[", shown.decode(errors="replace"))
    assert states and set(total for _, total in states) == {"10"}  # one bar, the run's
    assert [int(done) for done, _ in states][-1] == 10
    assert frame_files(out) == frame_files(full_parking)


def test_worker_lines_go_to_the_runs_log_or_its_stderr(capsys):
    """Frame lines (a worker's stdout) and its warnings and notes go to the run's log, its error lines to the caller's
    list, anything else (a traceback) to the run's stderr; each line whole."""
    from bpy_pipeline.parallel import forward_lines

    program = ("import sys\n"
               "for k in range(300): print(f'frame {k + 1}/300: ' + 'x' * 300)\n"
               "print('warning: a builder gave up', file=sys.stderr)\n"
               "print('error: scene.path: gone', file=sys.stderr)\n"
               "print('Traceback (most recent call last):', file=sys.stderr)\n")
    procs = [subprocess.Popen([sys.executable, "-c", program], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    said: list[str] = []
    errors: list[str] = []
    readers = forward_lines(procs, said.append, errors)
    assert [p.wait(timeout=60) for p in procs] == [0, 0]
    for reader in readers:
        reader.join()
    frames = [line for line in said if line.startswith("frame ")]
    assert len(frames) == 600 and all(line.endswith("x" * 300) for line in frames)
    assert said.count("warning: a builder gave up") == 2 and errors == ["error: scene.path: gone"] * 2
    assert capsys.readouterr().err.splitlines() == ["Traceback (most recent call last):"] * 2


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (Linux's /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # ended meanwhile
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def running(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie no init has reaped yet has ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="finds the workers through Linux's /proc")
def test_workers_stop_when_their_parent_is_killed(tmp_path, killed_run_environment):
    """kill -9 of a --workers run: its workers stop too (SIGTERM's way: committed frames kept), instead of going on
    writing into the folder with no lock held, where the next run may resume or overwrite it."""
    out = tmp_path / "orphans"
    parent = subprocess.Popen([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--frames", "2000", *PARKING, "--workers", "2"], cwd=ROOT,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=killed_run_environment)
    try:
        deadline = time.time() + 120
        while not any((out / "records").glob("*.json")) and time.time() < deadline and parent.poll() is None:
            time.sleep(0.05)
        workers = children(parent.pid)
        assert len(workers) == 2 and any((out / "records").glob("*.json"))
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    deadline = time.time() + 60
    while any(running(pid) for pid in workers) and time.time() < deadline:
        time.sleep(0.05)
    left = [pid for pid in workers if running(pid)]
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert not left, "workers went on after their parent was killed"
    made = consistent(out)
    assert 0 < len(made) < 2000
    time.sleep(0.5)
    assert consistent(out) == made  # nobody writes any more


def test_a_local_ray_cluster_gives_the_bytes_of_one_process_and_says_bad_input_once(full_parking, tmp_path):
    pytest.importorskip("ray", reason="Ray is not installed (pip install '.[distributed]')")
    ray_cli = Path(sys.executable).with_name("ray")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
    start = subprocess.run([str(ray_cli), "start", "--head", "--node-ip-address=127.0.0.1", f"--port={port}", "--num-cpus=2", "--include-dashboard=false",
                            "--disable-usage-stats"], capture_output=True, text=True, timeout=180, env=env)
    if start.returncode != 0:
        pytest.skip(f"a local Ray cluster would not start: {start.stderr.strip().splitlines()[-1:]}")
    try:
        out = tmp_path / "ray"
        done = cli("--out", str(out), "--frames", "10", *PARKING, "--ray", f"127.0.0.1:{port}", env=env)
        assert done.returncode == 0, done.stderr
        assert frame_files(out) == frame_files(full_parking)
        assert consistent(out) == set(range(10))
        # a .blend that is not there, found by the tasks: one line, exit 2, no folder (and no task run again for it)
        bad = tmp_path / "bad"
        done = cli("--out", str(bad), "--frames", "4", "--set", "scene.builder=blend", "--set", f"scene.path={tmp_path / 'gone.blend'}", "--ray",
                   f"127.0.0.1:{port}", env=env)
        assert done.returncode == 2, done.stderr
        lines = [line for line in done.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: scene.path: "), done.stderr
        assert not bad.exists()
    finally:
        subprocess.run([str(ray_cli), "stop", "--force"], capture_output=True, timeout=120, env=env)


def test_records_hold_each_frame_and_the_manifest_is_written_once(full_parking):
    manifest = json.loads((full_parking / "manifest.json").read_text())
    assert "frames" not in manifest and manifest["summary"]["frames"] == 10 and manifest["summary"]["frame_indices"] == [[0, 9]]
    records = read_dataset(full_parking)["frames"]
    assert [r["index"] for r in records] == list(range(10))
    assert all(set(r["sha256"]) == set(r["files"]) and r["points"] > 0 for r in records)


@pytest.mark.bpy
def test_a_run_reads_its_records_back_once_when_it_closes_and_the_cli_reads_nothing_back(bpy_scene, tmp_path, monkeypatch):
    from bpy_pipeline import plan
    from bpy_pipeline.config import load_config
    from bpy_pipeline.dataset import Dataset

    reads = []
    read_records = Dataset._read_records
    monkeypatch.setattr(Dataset, "_read_records", lambda self: reads.append(self.out) or read_records(self))
    monkeypatch.setattr(plan, "read_dataset", lambda out: pytest.fail("generate read the dataset back"))
    config = load_config(None, ["sensor.preset=vlp16", "output.formats=[ply]", "frames=2"])
    plan.generate(config, tmp_path / "out", log=lambda line: None)  # what the CLI's run calls
    assert reads == [tmp_path / "out"]  # the summary and the indexes come from one read
    summary = read_dataset(tmp_path / "out")["summary"]
    assert summary["frames"] == 2 and summary["frame_indices"] == [[0, 1]]
