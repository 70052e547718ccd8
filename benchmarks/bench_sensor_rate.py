"""The ego street example as users run it, against the rate its sensor records at (a Velodyne HDL-64E: 10 frames/s).

``examples/street/ego_hdl64e.yaml`` with every output it asks for (PLY, SemanticKITTI, KITTI and OpenPCDet boxes, the
preview), ``--frames`` frames, whole processes (start-up, Blender, the street, every frame written): once in one process
and once with ``--workers 2``, in alternating rounds; the best wall time of each is kept. ``fps`` = frames / wall;
``over_sensor`` = fps / 10. Both sides must give the same bytes (the frames' PLY files). ``cpu_s`` is the CPU time of a
run's processes. ``--old DIR``: another checkout's two runs in the same rounds (one process and two workers must give
the same bytes on each side; ``same_bytes_as_old`` says whether the sides do), and ``against_old`` = its best wall time /
this checkout's, for the same worker count; ``against_old_rounds``, the same ratio of the two runs of each round (made
back to back, so a machine whose speed drifts over the minutes moves both alike), and ``against_old_median``, their
median. ``--settle S``: before each run, the disk is synced and the machine left alone for S seconds (untimed), so no
run pays for writing back the files of the one before.

    python benchmarks/bench_sensor_rate.py [--small] [--frames 200] [--rounds 2] [--old DIR] [--settle 0] [--out DIR] [--name NAME]

Results: ``benchmarks/results/sensor_rate.json`` (``sensor_rate_small.json`` with ``--small``: 6 frames).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from bench_workers import digest, timed
from common import RESULTS, ROOT, report

SENSOR_HZ = 10.0  # the HDL-64E's rotation rate as KITTI recorded it


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--small", action="store_true", help="6 frames, one round (checks the benchmark runs)")
    p.add_argument("--frames", type=int, default=200)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--old", type=Path, help="another checkout, measured in the same rounds")
    p.add_argument("--settle", type=float, default=0.0, help="seconds of quiet after syncing the disk, before each run")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--name", help="the results file's name in --out, without .json (default sensor_rate, sensor_rate_small)")
    args = p.parse_args()
    frames, rounds = (6, 1) if args.small else (args.frames, args.rounds)
    config = ["--config", "examples/street/ego_hdl64e.yaml", "--frames", str(frames)]  # each checkout's own example (run in its folder)
    sides = {"new": ROOT, **({"old": args.old.resolve()} if args.old else {})}
    runs = [(side, workers) for side in sides for workers in (1, 2)]
    taken = {run: [] for run in runs}  # each round's (wall s, CPU s), in round order
    digests = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            for side, workers in runs if r % 2 == 0 else runs[::-1]:
                out = Path(tmp) / f"{side}w{workers}r{r}"
                if args.settle:
                    os.sync()
                    time.sleep(args.settle)
                taken[side, workers].append(timed([*config, "--workers", str(workers)], out, sides[side]))
                digests.setdefault((side, workers), digest(out))
    for side in sides:
        if digests[side, 1] != digests[side, 2]:
            raise SystemExit(f"{side}: two workers gave other bytes than one process")
    best = {run: min(taken[run]) for run in runs}  # the fastest round's (wall, CPU)
    rows = []
    for side, workers in runs:
        wall, cpu = best[side, workers]
        row = {"run": f"{'' if side == 'new' else 'old: '}{'one process' if workers == 1 else '--workers 2'}", "frames": frames, "wall_s": round(wall, 2),
               "cpu_s": round(cpu, 2), "fps": round(frames / wall, 2), "over_sensor": round(frames / wall / SENSOR_HZ, 2)}
        if "old" in sides and side == "new":
            row["against_old"] = round(best["old", workers][0] / wall, 3)
            pairs = [old[0] / new[0] for old, new in zip(taken["old", workers], taken["new", workers])]
            row["against_old_rounds"] = [round(ratio, 3) for ratio in pairs]
            row["against_old_median"] = round(statistics.median(pairs), 3)
        rows.append(row)
    extra = {"sensor_hz": SENSOR_HZ, "same_bytes": True, "rounds": rounds, "settle_s": args.settle}
    if args.old:
        extra.update(old=str(args.old), same_bytes_as_old=digests["old", 1] == digests["new", 1])
    report(args.name or "sensor_rate" + ("_small" if args.small else ""), rows, args.out, extra)


if __name__ == "__main__":
    main()
