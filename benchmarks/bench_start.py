"""A run's start as users pay it: whole processes, this checkout against older ones, in alternating rounds.

Three measures, each a fresh process, its wall time and CPU time (user + system, its threads included):

- ``import``: ``python -c "import bpy_pipeline.cli"`` (what every ``run.py`` and ``bpy-pipeline`` command imports first);
- ``frames1``: ``run.py --config examples/street/ego_hdl64e.yaml --frames 1`` (start-up, the first frame, the exit);
- ``frames20``: the same job's 20 frames.

Each round runs every checkout once a measure, the order reversed every other round (the machine may be shared: the
medians and minima of each are reported, never one reading). Runs import from the bytecode caches
(``PYTHONDONTWRITEBYTECODE`` left out, as ``bench_speed.py`` does), each checkout's package first on the path.

    python benchmarks/bench_start.py --old ../main [--old ../base] [--rounds 9] [--measures import frames1 frames20]
                                     [--name start.json]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_street_frame import checkout_environment

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
EGO = ["run.py", "--config", "examples/street/ego_hdl64e.yaml"]
MEASURES = {"import": ["-c", "import bpy_pipeline.cli"], "frames1": [*EGO, "--frames", "1"], "frames20": [*EGO, "--frames", "20"]}


def one_run(code: Path, measure: str) -> tuple[float, float]:
    """Wall s and CPU s of one process of ``measure`` (:data:`MEASURES`) in checkout ``code``."""
    env = checkout_environment(code)
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_SPEED_TMP")) as tmp:
        args = MEASURES[measure] + (["--out", str(Path(tmp) / "run")] if measure != "import" else [])
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, *args], cwd=code, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def summary(runs: list[tuple[float, float]]) -> dict:
    walls, cpus = [r[0] for r in runs], [r[1] for r in runs]
    return {
        "wall_median_s": statistics.median(walls),
        "cpu_median_s": statistics.median(cpus),
        "wall_min_s": min(walls),
        "cpu_min_s": min(cpus),
        "wall_s": walls,
        "cpu_s": cpus,
    }


def relative(path: Path) -> str:
    """``path`` as the results name it: relative to this checkout (``../main``), never absolute."""
    return os.path.relpath(path.resolve(), ROOT)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--old", type=Path, action="append", default=[], help="an older checkout to measure against (repeatable)")
    p.add_argument("--rounds", type=int, default=9)
    p.add_argument("--measures", nargs="+", default=list(MEASURES), choices=list(MEASURES))
    p.add_argument("--name", default="start.json", help="results file name under benchmarks/results/")
    args = p.parse_args()
    sides = {"new": ROOT, **{relative(old): old.resolve() for old in args.old}}
    results = {"measures": {}, "notes": {"cores": os.cpu_count(), "rounds": args.rounds, "sides": {k: relative(v) for k, v in sides.items()}}}
    for measure in args.measures:
        runs: dict[str, list] = {side: [] for side in sides}
        for i in range(args.rounds):
            for side in list(sides)[:: 1 if i % 2 == 0 else -1]:
                runs[side].append(one_run(sides[side], measure))
        results["measures"][measure] = {side: summary(r) for side, r in runs.items()}
        line = ", ".join(f"{side} {s['wall_median_s']:.3f} s wall / {s['cpu_median_s']:.3f} s CPU" for side, s in results["measures"][measure].items())
        print(f"{measure} (medians of {args.rounds}): {line}", flush=True)
    results["notes"]["load_average"] = os.getloadavg()
    out = HERE / "results" / args.name
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {relative(out)}")


if __name__ == "__main__":
    main()
