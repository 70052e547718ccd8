"""The default job (no --config): wall time split into build, export, scan and write.

Measures ``python run.py`` end to end in a subprocess (Python start and bpy import included)
and the in-process split from the frame's record; best of three.
Run: python benchmarks/bench_default_job.py [--small]
"""

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, arguments, report


def main():
    args = arguments(__doc__)
    extra = ["--set", "sensor.sampling_factor=0.1"] if args.small else []
    runs = []
    for _ in range(1 if args.small else 3):
        with tempfile.TemporaryDirectory() as out:
            start = time.perf_counter()
            subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", out, *extra], check=True, capture_output=True)
            wall = time.perf_counter() - start
            frame = json.loads((Path(out) / "records" / "000000.json").read_text())  # the frame's committed record
            runs.append({"wall_s": wall, **frame["timings_s"], "points": frame["points"], "triangles": frame["triangles"]})
    best = min(runs, key=lambda r: r["wall_s"])
    best["startup_s"] = best["wall_s"] - sum(best.get(k, 0.0) for k in ("build", "export", "scan", "effects", "write"))
    report("default_job" + ("_small" if args.small else ""), [best], args.out, {"command": "python run.py --out OUT " + " ".join(extra)})


if __name__ == "__main__":
    main()
