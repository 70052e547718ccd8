"""Where one process's threads spend the ego street job: on a core, waiting for one, or asleep.

Runs ``examples/street/ego_hdl64e.yaml`` for ``--frames`` frames in a child process that reads the kernel's account of
each of its threads (``/proc/self/task/TID/schedstat``: nanoseconds run on a core and nanoseconds runnable but waiting
for one) every ``--every`` seconds and once at the end. Per frame, the first frame (Blender's start, the street's
build) included, for the threads that live through the job: the main thread (the first lane: build, export, scan,
effects), the finishing lane's thread (boxes, files, commit) and the caster's pool (the scan's second thread), each
``run`` (on a core), ``queued`` (runnable, no core free) and ``asleep`` (its life less both: waiting for the
interpreter lock, for another thread's result, or for I/O). ``other threads`` are every other thread's (the preview's
and the KITTI image's writers, the libraries' own): the process's CPU less the named threads'. ``idle cores`` is the share of the cores'
time the process left unused: ``1 - CPU / (cores x wall)``. Linux only (the benchmark says so and stops elsewhere).

    python benchmarks/bench_thread_time.py [--small] [--frames 60] [--every 0.05] [--out DIR] [--name NAME]

Results: ``benchmarks/results/thread_time.json`` (``thread_time_small.json`` with ``--small``: 4 frames).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from common import RESULTS, ROOT, report, run_ego_job

LANES = {"MainThread": "main thread (first lane)", "finishing_0": "finishing lane", "caster_0": "caster's pool"}


def schedstat(native_id: int) -> tuple[int, int] | None:
    """``(ns run on a core, ns runnable waiting for one)`` of this process's thread ``native_id``, ``None`` once it has ended."""
    try:
        run, queued, _ = Path(f"/proc/self/task/{native_id}/schedstat").read_text().split()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return int(run), int(queued)


def child(frames: int, every: float, out: Path, result: Path) -> None:
    """In the child: the job through the command line, its threads' accounts sampled, the sums written to ``result``."""
    os.chdir(ROOT)  # the package is ROOT's (common put it first on sys.path)
    seen: dict[str, dict] = {}  # thread name -> {first, last (perf_counter s), run, queued (ns)}
    stop = threading.Event()

    def sample() -> None:
        now = time.perf_counter()
        for thread in threading.enumerate():
            if thread.name not in LANES or thread.native_id is None:
                continue
            account = schedstat(thread.native_id)
            if account is not None:
                row = seen.setdefault(thread.name, {"first": now})
                row.update(last=now, run=account[0], queued=account[1])

    def watch() -> None:
        while not stop.wait(every):
            sample()

    watcher = threading.Thread(target=watch, name="thread time watcher", daemon=True)
    start, before, base = time.perf_counter(), os.times(), schedstat(threading.get_native_id())  # the main thread's account so far
    seen["MainThread"] = {"first": start}
    watcher.start()
    code = run_ego_job(frames, out)
    sample()
    wall, after = time.perf_counter() - start, os.times()
    stop.set()
    watcher.join()
    seen["MainThread"]["run"] -= base[0]
    seen["MainThread"]["queued"] -= base[1]
    process_cpu = (after.user + after.system) - (before.user + before.system)  # every thread's, since the job began
    result.write_text(json.dumps({"wall": wall, "cpu": process_cpu, "cores": len(os.sched_getaffinity(0)), "threads": seen}))
    sys.stdout.flush()
    os._exit(code)  # Blender's modules are loaded: leave without their teardown


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--small", action="store_true", help="4 frames (checks the benchmark runs)")
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--every", type=float, default=0.05, help="seconds between readings of the threads' accounts")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--name", help="the results file's name in --out, without .json (default thread_time, thread_time_small)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--job-out", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args()
    frames = 4 if args.small else args.frames
    if args.child:
        child(frames, args.every, args.job_out, args.result)
    if not Path("/proc/self/task").is_dir():
        raise SystemExit("bench_thread_time.py: needs Linux's /proc/self/task/TID/schedstat")
    with tempfile.TemporaryDirectory() as tmp:
        result = Path(tmp) / "result.json"
        done = subprocess.run([sys.executable, __file__, "--child", "--frames", str(frames), "--every", str(args.every), "--result", str(result),
                               "--job-out", str(Path(tmp) / "out")], capture_output=True, text=True)
        if done.returncode != 0 or not result.exists():
            raise SystemExit(f"the job failed: {done.stderr.strip()[-800:]}")
        measured = json.loads(result.read_text())
    wall, cpu, cores = measured["wall"], measured["cpu"], measured["cores"]
    rows, named = [], 0.0
    for name, label in LANES.items():
        row = measured["threads"].get(name)
        if row is None:
            continue
        life = row["last"] - row["first"]
        run, queued = row["run"] / 1e9, row["queued"] / 1e9
        named += run
        rows.append({"thread": label, "run_ms_per_frame": round(run / frames * 1000, 1), "queued_ms_per_frame": round(queued / frames * 1000, 1),
                     "asleep_ms_per_frame": round(max(life - run - queued, 0.0) / frames * 1000, 1)})
    rows.append({"thread": "other threads", "run_ms_per_frame": round(max(cpu - named, 0.0) / frames * 1000, 1)})
    rows.append({"thread": "whole process", "run_ms_per_frame": round(cpu / frames * 1000, 1), "wall_ms_per_frame": round(wall / frames * 1000, 1),
                 "idle_cores": round(1.0 - cpu / (cores * wall), 3)})
    report(args.name or "thread_time" + ("_small" if args.small else ""), rows, args.out,
           {"frames": frames, "config": "examples/street/ego_hdl64e.yaml", "first_frame_included": True, "every_s": args.every})


if __name__ == "__main__":
    main()
