"""A run's frame files written with their page cache handed back a frame later, against the same files left cached.

The files of one ego street frame (130 k points: PLY, SemanticKITTI points and labels, KITTI and OpenPCDet points, the
preview, the KITTI image and texts; about 12 MB) written ``--frames`` times as the commit writes them (a temporary
sibling through ``atomic.hashed_open``, then renamed), into new files that are kept, as a run keeps them: ``left``
leaves them to the kernel, ``released`` hands each frame's pages back a frame later
(``bpy_pipeline.io.page_cache.PageCacheRelease``, as ``Dataset.commit`` does). The two alternate for ``--rounds``
rounds, every round in a folder of its own, all removed at the end; medians of wall and process CPU seconds (kernel
time included), per frame, and ``released / left``. ``resident_mb``: what the run's files held in memory at its end
(util-linux ``fincore``; ``null`` without it).

What a page never written before costs depends on the machine: on a virtual machine whose free memory goes back to the
host (a balloon's free page reporting, as on this project's machine), its first touch is a fault in the host. Before
each case, ``--pause`` seconds let such a machine take freed memory back, then ``fresh_gb_s`` measures how fast 256 MB
go into new, kept files (plain writes): the state each case ran in (median).

    python benchmarks/bench_page_cache.py [--frames 100] [--rounds 3] [--pause 0] [--name page_cache]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from common import RESULTS, report

from bpy_pipeline.io.atomic import atomic_write, hashed_open
from bpy_pipeline.io.page_cache import PageCacheRelease

# bytes of one ego street frame's files (examples/street/ego_hdl64e.yaml, 130 420 points)
FRAME_FILES = {"ply/{}.ply": 5_347_585, "sequences/00/velodyne/{}.bin": 2_086_720, "sequences/00/labels/{}.label": 521_680,
               "kitti/velodyne/{}.bin": 2_086_720, "openpcdet/points/{}.npy": 2_086_848, "preview/{}.png": 31_465,
               "kitti/image_2/{}.png": 37_197, "kitti/label_2/{}.txt": 832, "kitti/calib/{}.txt": 1_601}  # fmt: skip


def write_frames(folder: Path, frames: int, data: memoryview, release: PageCacheRelease | None) -> tuple[float, float]:
    """Wall and process CPU seconds of writing ``frames`` frames' files under ``folder``."""
    start, cpu = time.perf_counter(), time.process_time()
    for index in range(frames):
        written = []
        for pattern, size in FRAME_FILES.items():
            path = folder / pattern.format(f"{index:06d}")
            with atomic_write(path) as tmp, hashed_open(tmp) as handle:
                handle.write(data[:size])
            written.append(path)
        if release is not None:
            release.written(written)
    return time.perf_counter() - start, time.process_time() - cpu


def fresh_write_rate(folder: Path, mb: int = 256) -> float:
    """GB/s of plain writes of ``mb`` MB into a new file under ``folder`` (kept: freeing it would warm the pages of what follows)."""
    data = memoryview(os.urandom(1 << 20))
    folder.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with open(folder / "probe.bin", "wb") as handle:
        for _ in range(mb):
            handle.write(data)
    return mb * (1 << 20) / 1e9 / (time.perf_counter() - start)


def resident_mb(folder: Path) -> float | None:
    """MB of the files under ``folder`` in the page cache (``fincore``), ``None`` without it."""
    if shutil.which("fincore") is None:
        return None
    files = [str(p) for p in folder.rglob("*") if p.is_file()]
    done = subprocess.run(["fincore", "--noheadings", "--raw", "--bytes", "--output", "RES", *files], capture_output=True, text=True, check=True)
    return round(sum(int(line) for line in done.stdout.split()) / 1e6, 1)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=100)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--pause", type=float, default=0.0, help="seconds to wait before each case")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--name", default="page_cache")
    args = p.parse_args()
    data = memoryview(os.urandom(max(FRAME_FILES.values())))
    times: dict[str, list[tuple[float, float]]] = {"left": [], "released": []}
    fresh: dict[str, list[float]] = {"left": [], "released": []}
    resident: dict[str, float | None] = {}
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_SPEED_TMP")) as tmp:
        for r in range(args.rounds):
            for case in ("left", "released") if r % 2 == 0 else ("released", "left"):
                folder = Path(tmp) / f"{case}{r}"
                time.sleep(args.pause)
                fresh[case].append(fresh_write_rate(Path(tmp) / f"probe-{case}{r}"))
                times[case].append(write_frames(folder, args.frames, data, PageCacheRelease() if case == "released" else None))
                resident[case] = resident_mb(folder)
    rows = []
    for case, runs in times.items():
        wall, cpu = statistics.median(w for w, _ in runs), statistics.median(c for _, c in runs)
        rows.append({"files": case, "frames": args.frames, "wall_ms_a_frame": round(wall / args.frames * 1e3, 2),
                     "cpu_ms_a_frame": round(cpu / args.frames * 1e3, 2), "resident_mb": resident[case],
                     "fresh_gb_s": round(statistics.median(fresh[case]), 2)})  # fmt: skip
    rows[1]["wall_vs_left"] = round(rows[1]["wall_ms_a_frame"] / rows[0]["wall_ms_a_frame"], 3)
    rows[1]["cpu_vs_left"] = round(rows[1]["cpu_ms_a_frame"] / rows[0]["cpu_ms_a_frame"], 3)
    report(args.name, rows, args.out, {"rounds": args.rounds, "pause_s": args.pause, "frame_bytes": sum(FRAME_FILES.values()), "load_average": os.getloadavg()})


if __name__ == "__main__":
    main()
