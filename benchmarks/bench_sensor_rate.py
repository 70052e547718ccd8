"""The ego street example as users run it, against the rate its sensor records at (a Velodyne HDL-64E: 10 frames/s).

``examples/street/ego_hdl64e.yaml`` with every output it asks for (PLY, SemanticKITTI, KITTI and OpenPCDet boxes, the
preview), ``--frames`` frames, whole processes (start-up, Blender, the street, every frame written): once in one process
and once with ``--workers 2``, in alternating rounds; the best wall time of each is kept. ``fps`` = frames / wall;
``over_sensor`` = fps / 10. Both sides must give the same bytes (the frames' PLY files). ``cpu_s`` is the CPU time of a
run's processes.

    python benchmarks/bench_sensor_rate.py [--small] [--frames 200] [--rounds 2] [--out DIR]

Results: ``benchmarks/results/sensor_rate.json`` (``sensor_rate_small.json`` with ``--small``: 6 frames).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from bench_workers import digest, timed
from common import RESULTS, ROOT, report

SENSOR_HZ = 10.0  # the HDL-64E's rotation rate as KITTI recorded it


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--small", action="store_true", help="6 frames, one round (checks the benchmark runs)")
    p.add_argument("--frames", type=int, default=200)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args()
    frames, rounds = (6, 1) if args.small else (args.frames, args.rounds)
    config = ["--config", str(ROOT / "examples" / "street" / "ego_hdl64e.yaml"), "--frames", str(frames)]
    best: dict[int, tuple[float, float]] = {1: (float("inf"), 0.0), 2: (float("inf"), 0.0)}
    digests = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            for workers in (1, 2) if r % 2 == 0 else (2, 1):
                out = Path(tmp) / f"w{workers}r{r}"
                best[workers] = min(best[workers], timed([*config, "--workers", str(workers)], out))
                digests.setdefault(workers, digest(out))
    if digests[1] != digests[2]:
        raise SystemExit("two workers gave other bytes than one process")
    rows = [{"run": f"{'one process' if w == 1 else '--workers 2'}", "frames": frames, "wall_s": round(best[w][0], 2), "cpu_s": round(best[w][1], 2),
             "fps": round(frames / best[w][0], 2), "over_sensor": round(frames / best[w][0] / SENSOR_HZ, 2)}
            for w in (1, 2)]
    report("sensor_rate" + ("_small" if args.small else ""), rows, args.out, {"sensor_hz": SENSOR_HZ, "same_bytes": True, "rounds": rounds})


if __name__ == "__main__":
    main()
