"""Where a frame's CPU goes, call by call: named functions of the ego street job timed by their own thread's CPU.

Runs ``examples/street/ego_hdl64e.yaml`` for ``--frames`` frames in a child process whose named functions are wrapped:
each call's thread CPU time (``time.thread_time``, so a thread waiting for the interpreter lock or for I/O counts
nothing) and wall time are summed, a call inside a call of the same function counted once. Reported per frame, the first
frame (Blender's start, the street's build) included; each side runs one frame first, so numba's caches are filled. ``--old DIR``: the same functions in another
checkout, run the same way (a function it does not have is left out of its side).

    python benchmarks/bench_call_cpu.py [--small] [--frames 60] [--old DIR] [--functions module:qualname,...] [--out DIR] [--name NAME]

Results: ``benchmarks/results/call_cpu.json`` (``call_cpu_small.json`` with ``--small``: 4 frames).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from common import RESULTS, ROOT, report, run_ego_job

FUNCTIONS = (  # the parts round thirty changed, and the stages around them
    "bpy_pipeline.blender.export:parts_buffers",
    "bpy_pipeline.io.kitti:label_lines",
    "bpy_pipeline.geometry.field_of_view:in_view_fraction",
    "bpy_pipeline.lidar.cast.raycast:embree_part",
    "bpy_pipeline.stages.scene:build_stage",
    "bpy_pipeline.stages.scene:export_stage",
    "bpy_pipeline.stages.scan:scan_stage",
    "bpy_pipeline.stages.scan:effects_stage",
    "bpy_pipeline.stages.annotate:annotate_stage",
    "bpy_pipeline.dataset:Dataset.commit",
)


def timed_calls(specs: list[str]) -> dict[str, list[float]]:
    """Wrap each ``module:qualname`` where it is defined and wherever it was imported by name; returns the live
    ``{spec: [calls, wall s, thread CPU s]}`` (a spec its checkout does not have is skipped)."""
    stats: dict[str, list[float]] = {}
    lock = threading.Lock()

    def wrap(spec: str, function):
        inside = threading.local()

        def timed(*args, **kwargs):
            if getattr(inside, "depth", 0):
                return function(*args, **kwargs)
            inside.depth, wall, cpu = 1, time.perf_counter(), time.thread_time()
            try:
                return function(*args, **kwargs)
            finally:
                wall, cpu, inside.depth = time.perf_counter() - wall, time.thread_time() - cpu, 0
                with lock:
                    row = stats[spec]
                    row[0], row[1], row[2] = row[0] + 1, row[1] + wall, row[2] + cpu

        return timed

    for spec in specs:
        module, _, qualname = spec.partition(":")
        owner_name, _, name = qualname.rpartition(".")
        owner = importlib.import_module(module)
        if owner_name:
            owner = getattr(owner, owner_name, None)
        original = getattr(owner, name, None)
        if original is None:
            continue
        stats[spec] = [0, 0.0, 0.0]
        wrapped = wrap(spec, original)
        setattr(owner, name, wrapped)
        if not owner_name:  # module functions imported by name elsewhere
            for other in list(sys.modules.values()):
                for key, value in list(getattr(other, "__dict__", {}).items()):
                    if value is original:
                        setattr(other, key, wrapped)
    return stats


def child(root: Path, frames: int, specs: list[str], out: Path, result: Path) -> None:
    """In the child process: ``root``'s package, the job run through its command line, the sums written to ``result``."""
    sys.path.insert(0, str(root))
    os.chdir(root)
    from bpy_pipeline import cli  # noqa: F401  (the package loaded first: timed_calls wraps each name wherever it was imported)

    stats = timed_calls(specs)
    code = run_ego_job(frames, out)
    result.write_text(json.dumps(stats))
    sys.stdout.flush()
    os._exit(code)  # Blender's modules are loaded: leave without their teardown


def measure(root: Path, frames: int, specs: list[str], tmp: Path) -> dict[str, list[float]]:
    """The sums of ``frames`` frames in ``root``, after a one-frame run there (numba's caches filled, as a user's second run finds them)."""
    for count in (1, frames):
        result = tmp / f"{root.name}_{count}.json"
        done = subprocess.run([sys.executable, __file__, "--child", str(root), "--frames", str(count), "--functions", ",".join(specs),
                               "--result", str(result), "--job-out", str(tmp / f"{root.name}_{count}_out")], capture_output=True, text=True)
        if done.returncode != 0 or not result.exists():
            raise SystemExit(f"{root}: the job failed: {done.stderr.strip()[-800:]}")
    return json.loads(result.read_text())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--small", action="store_true", help="4 frames (checks the benchmark runs)")
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--old", type=Path, help="another checkout, measured the same way")
    p.add_argument("--functions", default=",".join(FUNCTIONS), help="module:qualname, comma separated")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--name", help="the results file's name in --out, without .json (default call_cpu, call_cpu_small)")
    p.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--job-out", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args()
    specs = [s for s in args.functions.split(",") if s]
    if args.child:
        child(args.child, args.frames, specs, args.job_out, args.result)
    frames = 4 if args.small else args.frames
    sides = {"new": ROOT, **({"old": args.old.resolve()} if args.old else {})}
    with tempfile.TemporaryDirectory() as tmp:
        measured = {side: measure(root, frames, specs, Path(tmp)) for side, root in sides.items()}
    rows = []
    for spec in specs:
        row = {"function": spec}
        for side, stats in measured.items():
            calls, wall, cpu = stats.get(spec, (0, 0.0, 0.0))
            prefix = "" if side == "new" else "old_"
            row.update({f"{prefix}calls": int(calls), f"{prefix}cpu_ms_per_frame": round(cpu / frames * 1000, 2),
                        f"{prefix}wall_ms_per_frame": round(wall / frames * 1000, 2)})
        rows.append(row)
    report(args.name or "call_cpu" + ("_small" if args.small else ""), rows, args.out,
           {"frames": frames, "config": "examples/street/ego_hdl64e.yaml", "first_frame_included": True, **({"old": str(args.old)} if args.old else {})})


if __name__ == "__main__":
    main()
