"""Speed as users see it: the scan and write stages against raw references, frames per second against older code.

Every figure is a ratio against a reference measured in the same run (no timed asserts):

- ``scan``: two jobs, run through ``run_frames`` as a user's run goes, but each stage alone (``overlap=False``: no
  frame finishing beside the next, whose wall times would hold the turns a stage waits for): the os1_128 preset in a closed
  40 m box (131,072 rays; ``scene.builder: primitives``; PLY + SemanticKITTI + preview) and the default
  railway (``python run.py`` with no options). The ``scan`` timing of the frame records (the trace with
  its point records; the effects are their own ``effects`` timing), median of frames 2-3, against raw
  embreex on the same rays and triangles (``EmbreeScene.run(output=1)``, chunks of 32,768 rays over 2
  threads, best of 3): ``scan_ratio = raw / scan`` (target >= 0.8), and ``scan_with_effects_ratio =
  raw / (scan + effects)``. Older code timed the effects inside ``scan``.
- ``write``: the ``write`` timing of the box's frames (PLY, SemanticKITTI, preview, hashes, commit)
  against writing the same bytes raw (open, write, fsync per file, best of 3) into the same file
  system: ``write_over_raw = write / raw`` (target <= 2); and against the same raw writes made in calls of 1 MiB
  (``write_over_raw_sliced``): on this project's machine a write call of a few MB can cost ten times the kernel
  time of the same bytes in slices, so the second reference is the faster raw write. ``write_cpu_s``: the commit's CPU
  seconds (every thread of the process: the preview's too), median of the frames from the second: what the stage costs,
  which the machine's load moves less than its wall time.
- ``fps``: ``run.py`` end to end (start-up included), one process: parking frames, and street frames
  scanned by the ``hdl64e`` from a car roof (``examples/street/ego_hdl64e.yaml``), this checkout
  against ``--old CHECKOUT`` (e.g. a ``git worktree`` of an older commit) in alternating rounds.
  Code without ``scene.ego_vehicle`` runs the nearest config it accepts: the same street builder and
  sensor, standing in the right-hand lane at the start of the ego's path (said in the results).
  ``--old-env KEY=VALUE`` adds a variable to the older side's environment; without ``--old`` that side is this
  checkout, so a setting is measured against its absence. ``--railway N``: the default railway as a job too;
  ``--street-standing N``: that nearest config (the street, the ``hdl64e`` standing in the lane) on both sides.
  Each run also gives when its first ``frame k/n`` line came (start-up and the first frame), its frames
  per second from that line to the last, and the time after the last; ``later_fps_new_over_old`` is the
  second, best against best.
- ``workers``: parking frames with ``--workers 2`` against one process, this checkout, in alternating rounds (best of each);
  and against one process on one thread (``--threads 1``, as each worker runs), the workers' own scaling. The one process
  keeps more than a core busy (its preview's thread, Embree's), so two workers can give it at most ``speed_up_ceiling``
  = 2 x its wall time / its CPU time.

Every run's environment is this one's without ``PYTHONDONTWRITEBYTECODE`` (:func:`run_environment`): each checkout imports
from its bytecode caches, as an installed package does. The scan and write parts run in a subprocess per checkout (``--baseline CHECKOUT`` adds the same
measurement of another checkout, interleaved); each subprocess reports which ``bpy_pipeline`` it imported.

    python benchmarks/bench_speed.py [--small] [--old DIR] [--old-env KEY=VALUE] [--baseline DIR] [--frames N] [--railway N]
                                     [--parking N] [--street N] [--street-standing N] [--scaling N] [--merge]

``--small`` (< 60 s): the scan and write parts (5 frames), 20 parking frames against one process with 2 workers,
no older checkout unless given. Results: ``benchmarks/results/speed.json`` (``speed_small.json``).
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
BOX = ["scene.builder=primitives", "scene.shapes=[{type: box, size: [40, 40, 10], position: [0, 0, 4], class: wall}]",
       "sensor.preset=os1_128", "sensor.position=[0.2, -0.3, 0.1]", "output.formats=[ply, semantickitti]", "output.preview=true"]  # fmt: skip
EGO = ["--config", "examples/street/ego_hdl64e.yaml"]
# the nearest a street without scene.ego_vehicle accepts: the same street and sensor, standing where the ego starts (right-hand lane)
EGO_STATIC = ["--set", "scene.builder=street", "--set", "scene.layout_seed=0", "--set", "sensor.preset=hdl64e", "--set", "sensor.position=[-60, -1.75, 0]",
              "--set", "output.formats=[ply, semantickitti]", "--set", "output.boxes.formats=[kitti, openpcdet]",
              "--set", "output.boxes.classes=[car, van, truck, bus, person, bicycle, motorcycle, rider]"]  # fmt: skip


JOBS = {"box": BOX, "railway": []}  # the scan stage's jobs: --set overrides
SLICE = 1 << 20  # bytes a write call in the second raw reference (the writers' atomic.WRITE_SLICE)


def stage_part(frames: int, job: str = "box") -> dict:
    """In the checkout being measured: job ``job``'s (:data:`JOBS`) scan and write timings and their raw references.

    Two readings: the issue's (median of frames 2-3 against the best of 3 raw runs after the run), and
    an interleaved one robust to a shared machine (after each frame from the second, one raw trace
    and one raw write of that frame's bytes; the median of the per-frame ratios).
    """
    import bpy_pipeline  # first, as run.py imports it: its settings for numpy apply only before numpy loads

    import numpy as np
    from concurrent.futures import ThreadPoolExecutor
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    from bpy_pipeline.config import load_config
    from bpy_pipeline.lidar.sensor.sensors import sensor_pattern

    try:
        from bpy_pipeline.plan import run_frames
    except ImportError:  # code before the frame plan
        from bpy_pipeline.plan import run_frames
    config = load_config(None, [*JOBS[job], f"frames={frames}"])
    d32 = np.ascontiguousarray(sensor_pattern(config.sensor.spec).directions, np.float32)
    o32 = np.lib.stride_tricks.as_strided(np.zeros(3, np.float32), d32.shape, (0, 4))
    spans = [slice(i, i + 32768) for i in range(0, len(d32), 32768)]
    limit = float(config.sensor.spec.max_range)
    pool = ThreadPoolExecutor(2)
    scene = None

    def raw_trace() -> float:
        start = time.perf_counter()
        list(pool.map(lambda s: scene.run(o32[s], d32[s], dists=limit, output=1), spans))
        return time.perf_counter() - start

    def raw_write(blobs: list[bytes], target: Path, piece: int = 0) -> float:  # piece: bytes a write call (0: the whole file in one)
        target.mkdir()
        start = time.perf_counter()
        for i, data in enumerate(blobs):
            fd = os.open(target / f"{i}.bin", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                view = memoryview(data)
                for at in range(0, len(view), piece or max(len(view), 1)):
                    os.write(fd, view[at : at + (piece or len(view))])
                os.fsync(fd)
            finally:
                os.close(fd)
        return time.perf_counter() - start

    from bpy_pipeline.dataset import Dataset

    commit, commit_cpu = Dataset.commit, {}

    def timed_commit(self, frame, *args, **kwargs):  # the write stage's CPU seconds
        start = time.process_time()
        try:
            return commit(self, frame, *args, **kwargs)
        finally:
            commit_cpu[frame.index] = time.process_time() - start

    Dataset.commit = timed_commit
    pairs = []
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_SPEED_TMP")) as tmp:
        out = Path(tmp) / "run"
        made = []
        alone = {"overlap": False} if "overlap" in inspect.signature(run_frames).parameters else {}  # each stage's cost alone (older code: always)
        for frame in run_frames(config, out, **alone):
            made.append(frame)
            if scene is None:  # the frame's triangles in its sensor frame, as the caster has them
                pose = frame.pose
                local = (np.asarray(frame.buffers.vertices, np.float64) - pose[:3, 3]) @ pose[:3, :3]
                scene = rtcore_scene.EmbreeScene()
                TriangleMesh(scene, np.ascontiguousarray(local, np.float32), np.ascontiguousarray(frame.buffers.triangles, np.int32))
                scene.run(o32[:1], d32[:1], output=1)  # commit before going parallel
                continue
            blobs = [(out / rel).read_bytes() for rel in frame.files]
            raws = raw_write(blobs, Path(tmp) / f"raw{frame.index}"), raw_write(blobs, Path(tmp) / f"sliced{frame.index}", SLICE)
            pairs.append((frame.timings["scan"], frame.timings.get("effects", 0.0), raw_trace(), frame.timings["write"], *raws))
        later = made[2:4]
        scan = statistics.median(f.timings["scan"] for f in later)
        effects = statistics.median(f.timings.get("effects", 0.0) for f in later)
        write = statistics.median(f.timings["write"] for f in later)
        last = made[-1]
        blobs = [(out / rel).read_bytes() for rel in last.files]
        best_trace = min(raw_trace() for _ in range(3))
        best_write = min(raw_write(blobs, Path(tmp) / f"best{k}") for k in range(3))
        best_sliced = min(raw_write(blobs, Path(tmp) / f"best_sliced{k}", SLICE) for k in range(3))
    Dataset.commit = commit
    cpu = cpu_part(config, made[-1].buffers, raw_trace)
    pool.shutdown()
    return {**cpu, "job": job, "code": str(Path(bpy_pipeline.__file__).parent), "rays": len(d32), "points": len(last.points), "frames": frames,
            "scan_s": scan, "effects_s": effects, "raw_embreex_s": best_trace, "scan_ratio": best_trace / scan,
            "scan_with_effects_ratio": best_trace / (scan + effects),
            "write_s": write, "raw_write_s": best_write, "write_over_raw": write / best_write,
            "raw_write_sliced_s": best_sliced, "write_over_raw_sliced": write / best_sliced,
            "write_cpu_s": statistics.median(commit_cpu[f.index] for f in made[1:]),
            "interleaved_scan_ratio": statistics.median(r / s for s, _, r, _, _, _ in pairs),
            "interleaved_scan_with_effects_ratio": statistics.median(r / (s + e) for s, e, r, _, _, _ in pairs),
            "interleaved_write_over_raw": statistics.median(w / r for _, _, _, w, r, _ in pairs),
            "interleaved_write_over_raw_sliced": statistics.median(w / r for _, _, _, w, _, r in pairs),
            "bytes_written": sum(len(b) for b in blobs), "files": list(last.files),
            "timings_frames_2_3": [{k: round(v, 4) for k, v in f.timings.items()} for f in later]}


def cpu_part(config, buffers, raw_trace, frames: int = 8) -> dict:
    """CPU seconds (every thread of the process) of the scan stages of ``frames`` frames of the box, one after
    another in one run, against the raw trace's, alternating: a reading the machine's load moves less than wall time."""
    from bpy_pipeline.frame import Frame, Run, frame_rng
    from bpy_pipeline.stages.scan import effects_stage, scan_stage
    from bpy_pipeline.stages.scene import pose_stage

    from bpy_pipeline.stages import scan as scan_module

    effects_cpu = [0.0]
    apply_effects = scan_module.apply_effects

    def timed_effects(*args, **kwargs):  # the effects' share of the stage (drop, noise, intensity: numpy on their own threads)
        start = time.process_time()
        try:
            return apply_effects(*args, **kwargs)
        finally:
            effects_cpu[0] += time.process_time() - start

    scan_module.apply_effects = timed_effects
    run = Run(config, build=False)
    stage, raw, effects = [], [], []
    for index in range(frames + 1):
        effects_cpu[0] = 0.0
        frame = Frame(index, config, frame_rng(config.seed, index), buffers=buffers)
        pose_stage(frame, run)
        start = time.process_time()
        scan_stage(frame, run)
        effects_stage(frame, run)
        took = time.process_time() - start
        start = time.process_time()
        raw_trace()
        if index:  # the first frame builds the caster and the kept rays
            stage.append(took)
            raw.append(time.process_time() - start)
            effects.append(effects_cpu[0])
    scan_module.apply_effects = apply_effects
    traced = [s - e for s, e in zip(stage, effects)]
    return {"scan_cpu_s": statistics.median(stage), "effects_cpu_s": statistics.median(effects), "raw_embreex_cpu_s": statistics.median(raw),
            "cpu_scan_ratio": statistics.median(raw) / statistics.median(stage),
            "cpu_scan_without_effects_ratio": statistics.median(raw) / statistics.median(traced)}


def in_checkout(code: Path, frames: int, job: str = "box") -> dict:
    """:func:`stage_part` in a subprocess importing ``code``'s bpy_pipeline (cwd and PYTHONPATH there)."""
    env = {**run_environment(), "PYTHONPATH": str(code), "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, str(HERE / "bench_speed.py"), "--part", "stages", "--job", job, "--frames", str(frames)], cwd=code, env=env,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"stages in {code}: {done.stderr.strip()[-800:]}")
    row = json.loads(done.stdout.strip().splitlines()[-1])
    if not row["code"].startswith(str(code)):
        raise RuntimeError(f"{code}: imported bpy_pipeline from {row['code']}")
    return row


def run_environment() -> dict:
    """This process's environment for a measured run, without ``PYTHONDONTWRITEBYTECODE`` (some sandboxes set it): the
    runs import each checkout from its bytecode caches, as an installed package does after its first start, instead of
    compiling its modules at every start (0.05-0.2 s a run, more for a checkout that never wrote them)."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def run_py(code: Path, args: list[str], workers: int = 1, env: dict | None = None) -> dict:
    """``run.py ARGS`` of checkout ``code`` end to end, with ``env`` added to the environment: wall s, CPU s (it and its
    workers), the run's peak resident memory (MiB, without its workers'), records' mean stage timings; and from the times its ``frame k/n`` lines
    came: the first one's
    (start-up and the first frame), the frames per second from the first line to the last (the frames after
    the first) and the time from the last line to the exit (the indexes, the manifest)."""
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_SPEED_TMP")) as tmp:
        out = Path(tmp) / "run"
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        command = [sys.executable, str(code / "run.py"), "--out", str(out), *args] + (["--workers", str(workers)] if workers > 1 else [])
        with open(Path(tmp) / "stderr", "w+") as errors:
            # each line as it is printed
            process = subprocess.Popen(command, cwd=code, stdout=subprocess.PIPE, stderr=errors, text=True,
                                       env={**run_environment(), "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(code), "PYTHONUNBUFFERED": "1", **(env or {})})
            lines = [time.perf_counter() - start for line in process.stdout if line.startswith("frame ")]
            _, status, usage = os.wait4(process.pid, 0)  # the run's own peak resident memory (its workers' are not in it)
            process.returncode = os.waitstatus_to_exitcode(status)
            wall = time.perf_counter() - start
            errors.seek(0)
            stderr = errors.read()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if process.returncode != 0:
            raise RuntimeError(f"{code}: run.py {' '.join(args)}: {stderr.strip()[-800:]}")
        records = [json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))]
    os.sync()  # the removed run's blocks and inodes committed: the next run's new files need not wait for them (docs/performance.md)
    stages: dict[str, float] = {}
    for record in records:
        for key, value in (record.get("timings_s") or record.get("timings") or {}).items():
            stages[key] = stages.get(key, 0.0) + value / len(records)
    timeline = {"first_frame_s": lines[0], "later_fps": (len(lines) - 1) / (lines[-1] - lines[0]),
                "after_last_frame_s": wall - lines[-1]} if len(lines) > 1 else {}
    return {"wall_s": wall, "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), "frames": len(records),
            "fps": len(records) / wall,
            "peak_rss_mb": usage.ru_maxrss / 1024, "stage_s_per_frame": stages, **timeline}


def accepts_ego(code: Path) -> bool:
    """Whether checkout ``code``'s street builder knows ``ego_vehicle``."""
    builders = code / "bpy_pipeline" / "builders"
    # a module, or a package since the layout issue
    return any(f.exists() and "ego_vehicle" in f.read_text() for f in (builders / "street.py", builders / "street" / "params.py"))


def compare(name: str, new_args: list[str], old_args: list[str] | None, old: Path | None, rounds: int, old_env: dict | None = None) -> dict:
    """Alternating rounds of this checkout and ``old`` (when given) with ``old_env`` added to its environment; the best
    round of each."""
    new_runs, old_runs = [], []
    for _ in range(rounds):
        new_runs.append(run_py(ROOT, new_args))
        if old is not None:
            old_runs.append(run_py(old, old_args, env=old_env))
        print(name, "new", round(new_runs[-1]["fps"], 2), "old", round(old_runs[-1]["fps"], 2) if old_runs else "-", flush=True)
    best_new = max(new_runs, key=lambda r: r["fps"])
    row = {"job": name, "new": best_new, "new_args": new_args, "new_rounds": new_runs}
    if old_runs:
        best_old = max(old_runs, key=lambda r: r["fps"])
        row.update({"old": best_old, "old_args": old_args, "fps_new_over_old": best_new["fps"] / best_old["fps"], "old_rounds": old_runs})
        if all("later_fps" in r for r in new_runs + old_runs):  # the frames after the first, best against best
            row["later_fps_new_over_old"] = max(r["later_fps"] for r in new_runs) / max(r["later_fps"] for r in old_runs)
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--small", action="store_true", help="under a minute: stages, and a short workers comparison")
    p.add_argument("--out", type=Path, default=HERE / "results")
    p.add_argument("--old", type=Path, help="an older checkout for frames per second side by side (e.g. git worktree add ../old 7513fcb)")
    p.add_argument("--old-env", action="append", default=[], metavar="KEY=VALUE",
                   help="an environment variable for the older side's runs; without --old, that side is this checkout with it")
    p.add_argument("--railway", type=int, default=0, help="default railway frames (run.py --frames N) for frames per second (default 0)")
    p.add_argument("--baseline", type=Path, help="another checkout whose scan and write stages are measured beside this one's")
    p.add_argument("--parking", type=int, help="parking frames for frames per second (default 120; --small 0)")
    p.add_argument("--street", type=int, help="street frames (default 20; --small 0)")
    p.add_argument("--street-standing", type=int, default=0, help="street frames with the hdl64e standing in the right-hand lane, on both sides (default 0)")
    p.add_argument("--scaling", type=int, help="parking frames for 2 workers against 1 (default 1000; --small 30)")
    p.add_argument("--rounds", type=int, default=2, help="alternating rounds per comparison (best kept)")
    p.add_argument("--part", help=argparse.SUPPRESS)
    p.add_argument("--job", choices=sorted(JOBS), default="box", help=argparse.SUPPRESS)
    p.add_argument("--frames", type=int, default=12, help="frames of the box run (scan and write stages; 0: skip them)")
    p.add_argument("--merge", action="store_true", help="keep the parts of an earlier results file that this run skips")
    p.add_argument("--name", help="the results file's name in --out (default speed.json; --small speed_small.json)")
    args = p.parse_args()
    if args.part == "stages":
        print(json.dumps(stage_part(args.frames, args.job)))
        return
    parking = args.parking if args.parking is not None else (0 if args.small else 120)
    street = args.street if args.street is not None else (0 if args.small else 20)
    scaling = args.scaling if args.scaling is not None else (20 if args.small else 1000)
    rounds = 1 if args.small else args.rounds
    if args.small and args.frames == 12:
        args.frames = 5
    results: dict = {"stages": []}
    for _ in range(rounds if args.frames else 0):  # interleaved: this checkout, then the baseline
        for job in JOBS:
            results["stages"].append({"checkout": "this", **in_checkout(ROOT, args.frames, job)})
            if args.baseline is not None:
                results["stages"].append({"checkout": "baseline", **in_checkout(args.baseline.resolve(), args.frames, job)})
    for row in results["stages"]:
        print(
            f"{row['checkout']} {row.get('job', 'box')}: scan {row['scan_s'] * 1e3:.1f} ms + effects {row.get('effects_s', 0.0) * 1e3:.1f} ms vs raw "
            f"{row['raw_embreex_s'] * 1e3:.1f} ms "
            f"(ratio {row['scan_ratio']:.2f}, interleaved {row['interleaved_scan_ratio']:.2f}; with the effects "
            f"{row.get('scan_with_effects_ratio', row['scan_ratio']):.2f}, CPU {row['cpu_scan_ratio']:.2f}); "
            f"write {row['write_s'] * 1e3:.1f} ms vs raw {row['raw_write_s'] * 1e3:.1f} ms ({row['write_over_raw']:.2f}x, interleaved "
            f"{row['interleaved_write_over_raw']:.2f}x)"
            + (
                f", vs raw in slices {row['raw_write_sliced_s'] * 1e3:.1f} ms ({row['write_over_raw_sliced']:.2f}x, interleaved "
                f"{row['interleaved_write_over_raw_sliced']:.2f}x)"
                if "raw_write_sliced_s" in row
                else ""
            )
            + f"; write CPU {row['write_cpu_s'] * 1e3:.1f} ms",
            flush=True,
        )
    old_env = dict(item.split("=", 1) for item in args.old_env)
    old = args.old.resolve() if args.old is not None else (ROOT if old_env else None)
    results["fps"] = []
    if args.railway:
        job = ["--frames", str(args.railway)]
        results["fps"].append(compare(f"{args.railway} default railway frames", job, job, old, rounds, old_env))
    if parking:
        job = ["--set", "scene.builder=parking", "--frames", str(parking)]
        results["fps"].append(compare(f"{parking} parking frames", job, job, old, rounds, old_env))
    if street:
        old_street = (EGO if accepts_ego(old) else EGO_STATIC) if old is not None else None
        row = compare(f"{street} street frames, hdl64e on a car roof", [*EGO, "--frames", str(street)],
                      None if old is None else [*old_street, "--frames", str(street)], old, rounds, old_env)
        if old is not None and old_street is EGO_STATIC:
            row["old_note"] = (
                "the older code has no scene.ego_vehicle: its street builder with the hdl64e standing where the ego starts (right-hand lane, static)"
            )
        results["fps"].append(row)
    if args.street_standing:
        job = [*EGO_STATIC, "--frames", str(args.street_standing)]
        results["fps"].append(compare(f"{args.street_standing} street frames, hdl64e standing in the lane", job, job, old, rounds, old_env))
    results["workers"] = []
    if scaling:
        job = ["--set", "scene.builder=parking", "--frames", str(scaling)]
        ones, singles, twos = [], [], []
        for _ in range(rounds):  # alternating, so a slow spell of the machine does not fall on one side only
            ones.append(run_py(ROOT, job))
            singles.append(run_py(ROOT, [*job, "--threads", "1"]))  # one process as a worker runs: one thread
            twos.append(run_py(ROOT, job, workers=2))
        one, single, two = (max(runs, key=lambda r: r["fps"]) for runs in (ones, singles, twos))
        results["workers"].append({"frames": scaling, "one": one, "two": two, "speed_up": two["fps"] / one["fps"], "one_rounds": ones, "two_rounds": twos,
                                   "round_speed_ups": [t["fps"] / o["fps"] for o, t in zip(ones, twos)],
                                   "one_thread": single, "one_thread_rounds": singles, "speed_up_over_one_thread": two["fps"] / single["fps"],
                                   "round_speed_ups_over_one_thread": [t["fps"] / o["fps"] for o, t in zip(singles, twos)],
                                   # what two workers of one core each can give over the one process at most: its wall time is its
                                   # CPU time over the cores it kept busy, two workers get two cores' worth
                                   "cores_busy_one_process": one["cpu_s"] / one["wall_s"], "speed_up_ceiling": 2.0 * one["wall_s"] / one["cpu_s"]})  # fmt: skip
        print(
            f"{scaling} parking frames: one process {one['fps']:.2f} frames/s ({one['cpu_s'] / one['wall_s']:.2f} cores busy), one process on one thread "
            f"{single['fps']:.2f}, "
            f"2 workers {two['fps']:.2f} ({two['fps'] / one['fps']:.2f}x and {two['fps'] / single['fps']:.2f}x, best of {rounds} alternating rounds each)",
            flush=True,
        )
    for row in results["fps"]:
        if "old" in row:
            print(f"{row['job']}: {row['new']['fps']:.2f} frames/s against {row['old']['fps']:.2f} ({row['fps_new_over_old']:.2f}x)"
                  + (f"; the frames after the first {row['later_fps_new_over_old']:.2f}x" if "later_fps_new_over_old" in row else ""))
    results["notes"] = {"load_average": os.getloadavg(), "cores": os.cpu_count(), "small": args.small, "old": str(old) if old else None, "old_env": old_env,
                        "baseline": str(args.baseline) if args.baseline else None}  # fmt: skip
    args.out.mkdir(parents=True, exist_ok=True)
    name = args.name or ("speed_small.json" if args.small else "speed.json")
    if args.merge and (args.out / name).exists():
        earlier = json.loads((args.out / name).read_text())
        for key in ("stages", "fps", "workers"):
            if not results.get(key) and earlier.get(key):
                results[key] = earlier[key]
                results["notes"][f"{key}_from"] = earlier.get("notes")
    (args.out / name).write_text(json.dumps(results, indent=2, default=float) + "\n")
    print("wrote", args.out / name)


if __name__ == "__main__":
    main()
