"""Hardening figures: the stale-lock race, the work estimate's error, and bad inputs by outcome.

1. The lock race: ``--tries`` times, a dataset folder whose ``.lock`` names a dead pid of this host,
   and two processes that open it with ``--resume`` (``Dataset.open(out, config, "resume")``, the
   code path of ``run.py --resume`` up to Blender) at the same moment, each holding it 2 s.
   Counts the tries where both held the lock at once (must be 0), where one took it and the other
   was refused, and where the second took it only after the first released it (a loaded machine
   can start one racer that late; not a race).
2. The estimate's error: ``python run.py`` of reference jobs, end to end (start-up included),
   against ``estimate_run(config).seconds``; error = estimate / measured - 1.
3. Bad inputs by outcome: the fuzzer's examples (tests/test_fuzz_inputs.py) counted as refused in
   one line, valid, or anything else (traceback, silent wrong result: the test fails).

Run: python benchmarks/bench_hardening.py [--small]
"""

from __future__ import annotations

import collections
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, arguments, report

RACER = """
import sys, time
sys.path.insert(0, {root!r})
from pathlib import Path
from bpy_pipeline.config import load_config
from bpy_pipeline.dataset import Dataset
from bpy_pipeline.errors import InputError
config = load_config({{"scene": {{"builder": "parking"}}, "frames": 4}})
go = Path(sys.argv[2])
while not go.exists():
    pass
try:
    dataset = Dataset.open(sys.argv[1], config, "resume")
except InputError:
    print("refused", flush=True)
    sys.exit(0)
took = time.time()
time.sleep(2.0)  # held long enough for the other one to try, however the machine schedules it
print("took", took, time.time(), flush=True)
dataset._unlock()
"""

JOBS = [
    ("default job", []),
    ("20 parking frames", ["--set", "scene.builder=parking", "--frames", "20"]),
    ("5 industrial_hall frames", ["--set", "scene.builder=industrial_hall", "--frames", "5"]),
    ("3 primitives frames, vlp16", ["--set", "scene.builder=primitives", "--set", "sensor.preset=vlp16", "--frames", "3"]),
]


def dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def lock_race(tries: int) -> dict:
    sys.path.insert(0, str(ROOT))
    from bpy_pipeline.config import load_config
    from bpy_pipeline.dataset import Dataset

    config = load_config({"scene": {"builder": "parking"}, "frames": 4})
    outcomes = collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        racer = Path(tmp) / "racer.py"
        racer.write_text(RACER.format(root=str(ROOT)))
        for k in range(tries):
            out = Path(tmp) / f"run{k}"
            Dataset.open(out, config, "new")._unlock()  # a run's folder, its lock then left by a dead process:
            (out / ".lock").write_text(json.dumps({"pid": dead_pid(), "host": socket.gethostname(), "started": "earlier"}))
            go = Path(tmp) / f"go{k}"
            procs = [subprocess.Popen([sys.executable, str(racer), str(out), str(go)], stdout=subprocess.PIPE, text=True) for _ in range(2)]
            time.sleep(1.5)  # both imported and spinning on the go file
            go.touch()
            held = [p.communicate(timeout=120)[0].split() for p in procs]
            spans = [(float(h[1]), float(h[2])) for h in held if h and h[0] == "took"]
            overlap = len(spans) == 2 and max(a for a, _ in spans) < min(b for _, b in spans)
            outcome = "both held it at once" if overlap else "one then the other" if len(spans) == 2 else {1: "one took it", 0: "neither took it"}[len(spans)]
            outcomes[outcome] += 1
    return {"what": "two --resume on a stale lock", "tries": tries,
            **{k: outcomes.get(k, 0) for k in ("both held it at once", "one took it", "one then the other", "neither took it")}}


def estimate_error(small: bool) -> list[dict]:
    sys.path.insert(0, str(ROOT))
    from bpy_pipeline.cli import load_run_config, parser
    from bpy_pipeline.estimate import estimate_run

    rows = []
    for name, argv in JOBS[:2] if small else JOBS:
        config = load_run_config(parser().parse_args(argv))
        estimate = estimate_run(config)
        measured = []
        for _ in range(1 if small else 3):
            with tempfile.TemporaryDirectory() as out:
                start = time.perf_counter()
                subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", out, *argv], check=True, capture_output=True)
                measured.append(time.perf_counter() - start)
        best = min(measured)
        rows.append({"job": name, "estimate_s": round(estimate.seconds, 3), "measured_s": round(best, 3), "error": round(estimate.seconds / best - 1, 3),
                     "rays_per_frame": estimate.rays_per_frame, "triangles": estimate.triangles})
    return rows


def fuzz_outcomes() -> dict:
    sys.path.insert(0, str(ROOT / "tests"))
    import test_fuzz_inputs as fuzz

    start = time.perf_counter()
    for name in dir(fuzz):
        if name.startswith("test_"):
            getattr(fuzz, name)()
    return {"what": "fuzzer examples", **dict(fuzz.OUTCOMES), "seconds": round(time.perf_counter() - start, 1)}


def main():
    sys.argv, parts = [a for a in sys.argv if not a.startswith("--parts=")], [a for a in sys.argv if a.startswith("--parts=")]
    args = arguments(__doc__)
    args.parts = parts[0].split("=", 1)[1] if parts else "race,fuzz,estimate"
    load = os.getloadavg()[0]
    parts = set(args.parts.split(","))
    rows = []
    if "race" in parts:
        rows.append(lock_race(5 if args.small else 50))
    if "fuzz" in parts:
        rows.append(fuzz_outcomes())
    if "estimate" in parts:
        rows += estimate_error(args.small)
    report("hardening" + ("_small" if args.small else "") + ("" if args.parts == "race,fuzz,estimate" else "_" + args.parts.replace(",", "_")), rows, args.out,
           {"command": "python benchmarks/bench_hardening.py" + (" --small" if args.small else ""), "load_average_before": round(load, 2),
            "error": "estimate / measured - 1 (python run.py end to end, best of 3)"})


if __name__ == "__main__":
    main()
