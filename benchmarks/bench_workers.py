"""Workers scale: one job made by one process against ``--workers 2``, in the same run.

Each job runs end to end with ``run.py`` (start-up, build, scan, boxes, writing) into a fresh
folder: once with one process (all cores for its ray-casting threads, one BLAS thread: its best
case) and once with ``--workers 2`` (each worker one BLAS thread and half the ray-casting
threads, ``parallel.SINGLE_THREAD_ENV``), in alternating rounds so load on the shared machine
hits both alike; the best wall time of each is kept. ``speedup`` = one process / two workers
(target 1.8 on 2 cores). Both must give the same bytes: the frames' PLY files are compared.

The machine may be shared: ``cpu_s`` is the CPU time (user + system) of each run's processes and
``cores_used`` = cpu_s / wall, so a speedup held down by other jobs on the cores shows as two
workers getting fewer than two cores. ``cpu_ratio`` = one process's CPU time / the two workers'
(1.0: the workers add no work of their own).

- parking frames (small scans: per-frame Python work, boxes and writing dominate);
- industrial-hall frames (the mirror LiDAR's 262 k rays: the scan dominates, and one process
  already traces on both cores);
- a long parking run (1,000 frames), where each worker's own start-up and scene build (a second
  Blender) weigh little against its frames;
- the ego street example (``examples/street/ego_hdl64e.yaml``, 60 frames): its frames hold the interpreter on two
  threads (the next frame's build beside this frame's boxes and write), so a second process finds a core one
  process leaves idle.

Run: python benchmarks/bench_workers.py [--small]
"""

from __future__ import annotations

import hashlib
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, arguments, report

ROUNDS = 2


def timed(args: list[str], out: Path, root: Path = ROOT) -> tuple[float, float]:
    """``(wall s, CPU s)`` of ``run.py ARGS --out OUT`` (``root``'s, this checkout's by default) and its workers (one BLAS
    thread in the parent, as the workers have)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, str(Path(root) / "run.py"), "--out", str(out), *args], capture_output=True, text=True, cwd=root,
                          env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    if done.returncode != 0:
        raise RuntimeError(f"run.py {' '.join(args)}: {done.stderr.strip()[-800:]}")
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def digest(out: Path) -> str:
    """sha256 over the frames' PLY files in order."""
    h = hashlib.sha256()
    for path in sorted((out / "ply").glob("*.ply")):
        h.update(path.read_bytes())
    return h.hexdigest()


def job(name: str, args: list[str], frames: int) -> dict:
    best = {1: (float("inf"), 0.0), 2: (float("inf"), 0.0)}
    digests = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(ROUNDS):
            for workers in ((1, 2) if r % 2 == 0 else (2, 1)):
                out = Path(tmp) / f"w{workers}r{r}"
                best[workers] = min(best[workers], timed([*args, "--frames", str(frames), "--set", "output.formats=[ply]", "--workers", str(workers)], out))
                digests.setdefault(workers, digest(out))
    assert digests[1] == digests[2], f"{name}: two workers gave other bytes than one process"
    (wall1, cpu1), (wall2, cpu2) = best[1], best[2]
    return {"job": name, "frames": frames, "one_process_s": wall1, "two_workers_s": wall2, "one_process_fps": frames / wall1, "two_workers_fps": frames / wall2,
            "speedup": wall1 / wall2, "one_process_cores_used": cpu1 / wall1, "two_workers_cores_used": cpu2 / wall2, "cpu_ratio": cpu1 / cpu2}  # fmt: skip


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    parking, hall, long_parking, street = (20, 4, 40, 6) if args.small else (200, 30, 1000, 60)
    rows = [
        job("parking", ["--set", "scene.builder=parking"], parking),
        job("industrial hall", ["--set", "scene.builder=industrial_hall"], hall),
        job("parking, long run (start-up amortised)", ["--set", "scene.builder=parking"], long_parking),
        job("the ego street example", ["--config", str(ROOT / "examples" / "street" / "ego_hdl64e.yaml")], street),
    ]
    report("workers" + ("_small" if args.small else ""), rows, args.out,
           {"cores": os.cpu_count(), "rounds": ROUNDS,
            "note": "wall time end to end with run.py (start-up included), best of the rounds; speedup = one process / two workers"})


if __name__ == "__main__":
    main()
