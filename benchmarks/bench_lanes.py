"""Where one process's ego frame goes: its two lanes apart and together.

One process runs a frame's first stages (the road users' build, the export, the scan, the effects) while the frame
before finishes beside it on a thread (its boxes and its files; ``plan.run_frames``). Three ways to run the ego job
(``examples/street/ego_hdl64e.yaml``), each a fresh process, in alternating rounds:

- ``together``: as users run it (the finishing beside the next frame);
- ``apart``: every stage alone (``run_frames(overlap=False)``), the two lanes one after the other;
- ``first``: the first stages alone, the finishing stages and the commit left out: the frame's floor while one
  process holds the first lane.

Per way: wall ms and CPU ms (every thread) a frame after the first (its start left out), medians over rounds.
``apart - first`` is the finishing lane alone; ``together`` against ``first`` and against ``apart / 2`` tells how much of
the two cores the two lanes share well.

    python benchmarks/bench_lanes.py [--frames 60] [--rounds 3] [--name lanes.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

CHILD = r"""
import bpy_pipeline
import json, os, sys, tempfile, time
from bpy_pipeline import dataset, plan
from bpy_pipeline.config import load_config

way, frames = sys.argv[1], int(sys.argv[2])
config = load_config("examples/street/ego_hdl64e.yaml", [f"frames={frames}"])
if way == "first":  # the finishing stages and the commit left out
    run_stages = plan.run_stages
    stages = plan.plan(config)
    finishing = {stage.name for stage in stages[plan.finishing_start(stages):]}
    plan.run_stages = lambda frame, run, stages, said: None if stages and stages[0].name in finishing else run_stages(frame, run, stages, said)
    dataset.Dataset.commit = lambda self, frame, say=None: {"points": len(frame.points)}
with tempfile.TemporaryDirectory() as tmp:
    for frame in plan.run_frames(config, os.path.join(tmp, "run"), overlap=way != "apart"):
        if frame.index == 0:
            wall, cpu = time.perf_counter(), time.process_time()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
print(json.dumps({"wall_ms": 1000 * wall / (frames - 1), "cpu_ms": 1000 * cpu / (frames - 1)}))
os._exit(0)  # bpy's exit handlers are slow and say nothing here
"""

WAYS = ("together", "apart", "first")


def one(way: str, frames: int) -> dict:
    """One fresh process running the ego job ``way``: its ms a frame after the first."""
    done = subprocess.run([sys.executable, "-c", CHILD, way, str(frames)], cwd=ROOT, check=True, capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=HERE / "results")
    parser.add_argument("--name", default="lanes.json")
    args = parser.parse_args()
    runs: dict[str, list[dict]] = {way: [] for way in WAYS}
    for r in range(args.rounds):
        for way in WAYS if r % 2 == 0 else WAYS[::-1]:
            runs[way].append(one(way, args.frames))
            print(f"round {r + 1} {way}: {runs[way][-1]['wall_ms']:.1f} ms a frame, CPU {runs[way][-1]['cpu_ms']:.1f} ms", flush=True)
    median = {way: {k: statistics.median(run[k] for run in runs[way]) for k in ("wall_ms", "cpu_ms")} for way in WAYS}
    finishing = median["apart"]["wall_ms"] - median["first"]["wall_ms"]
    result = {"frames": args.frames, "rounds": args.rounds, "runs": runs, "median": median,
              "finishing_alone_ms": finishing,
              "together_over_first": median["together"]["wall_ms"] / median["first"]["wall_ms"],
              "together_over_half_apart": median["together"]["wall_ms"] / (median["apart"]["wall_ms"] / 2),
              "cores_used_together": median["together"]["cpu_ms"] / median["together"]["wall_ms"]}
    print(json.dumps({k: v for k, v in result.items() if k != "runs"}, indent=1))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / args.name).write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out / args.name}")


if __name__ == "__main__":
    main()
