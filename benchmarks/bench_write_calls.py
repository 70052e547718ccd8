"""What one write call of a frame's file costs against the same bytes in slices: wall and CPU (kernel time included).

The writers hash and write a frame's large files (a 131 k-point PLY is 4.8 MB) through ``atomic.HashedFile``, in calls of
``atomic.WRITE_SLICE`` bytes. This measures why: alternating, each ``--rounds`` times, the same bytes written to a new
file (open, write, close; no fsync, as the commit writes) in one call and in calls of 64 KiB to 4 MiB, with and without
sha256 as the writers take it; medians of the thread's CPU time and of the wall time.

    python benchmarks/bench_write_calls.py [--mb 4.77] [--rounds 30] [--name write_calls.json]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def write(path: Path, data: memoryview, piece: int, digest: bool) -> tuple[float, float]:
    """Wall and thread CPU seconds of writing ``data`` to the new file ``path`` in calls of ``piece`` bytes (0: one call)."""
    start, cpu = time.perf_counter(), time.thread_time()
    hashed = hashlib.sha256() if digest else None
    step = piece or len(data)
    with open(path, "wb") as handle:
        for at in range(0, len(data), step):
            part = data[at : at + step]
            if hashed is not None:
                hashed.update(part)
            handle.write(part)
    return time.perf_counter() - start, time.thread_time() - cpu


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mb", type=float, default=4.77, help="file size in MB (default: a 131 k-point PLY)")
    p.add_argument("--rounds", type=int, default=30)
    p.add_argument("--out", type=Path, default=HERE / "results")
    p.add_argument("--name", default="write_calls.json")
    args = p.parse_args()
    data = memoryview(os.urandom(int(args.mb * 1e6)))
    pieces = [0, 4 << 20, 2 << 20, 1 << 20, 1 << 19, 1 << 16]
    cases = [(piece, digest) for digest in (False, True) for piece in pieces]
    times: dict[tuple[int, bool], list[tuple[float, float]]] = {case: [] for case in cases}
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_SPEED_TMP")) as tmp:
        for k in range(args.rounds):
            for piece, digest in cases if k % 2 else cases[::-1]:
                times[piece, digest].append(write(Path(tmp) / f"{piece}-{digest}-{k}.bin", data, piece, digest))
    rows = [{"bytes_a_call": piece or len(data), "one_call": piece == 0, "sha256": digest, "wall_ms": round(statistics.median(w for w, _ in runs) * 1e3, 3),
             "cpu_ms": round(statistics.median(c for _, c in runs) * 1e3, 3)} for (piece, digest), runs in times.items()]  # fmt: skip
    for row in rows:
        print(row)
    result = {"bytes": len(data), "rounds": args.rounds, "rows": rows, "load_average": os.getloadavg(), "cores": os.cpu_count()}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / args.name).write_text(json.dumps(result, indent=1) + "\n")
    print("wrote", args.out / args.name)


if __name__ == "__main__":
    main()
