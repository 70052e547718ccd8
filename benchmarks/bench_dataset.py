"""The output folder as a dataset: does a frame's cost stay flat over a long run, and how do workers scale?

1. One run of N parking frames (the default 2,000; --small 150) into one folder: the wall time
   of each frame as the run loop sees it (build to committed record). Reported: the median of the
   first and of the last 100 (--small 25) frames, and their ratio (1.0: a frame's cost does not
   grow with the run; the earlier per-frame manifest rewrite made it grow with the square).
2. Frames per second of one parking run of M frames (the default 200; --small 30) with 1 and 2
   local worker processes (``--workers``), each measured end to end as a user runs it, and the
   speed-up. The machine's load average is recorded beside, since other work on the machine
   takes cores from the workers.
3. Projections from the measured rates: the parking paper's 6,740 scans, and the railway thesis's
   140 railway simulations at its scanner's full resolution (each a thesis-size scan; the time of
   one is measured here with the railway_tls preset at sampling factor 1, scaled from a 1/16
   sample where --small).

    python benchmarks/bench_dataset.py [--small]
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, arguments, report

PARKING = ["--set", "scene.builder=parking", "--set", "output.formats=[ply,semantickitti]"]


def frame_times(frames: int) -> list[float]:
    """Wall seconds of each frame of one in-process run of ``frames`` parking frames."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import run_frames

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["scene.builder=parking", "output.formats=[ply,semantickitti]", f"frames={frames}"])
    times = []
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        for _ in run_frames(config, Path(out) / "run"):
            now = time.perf_counter()
            times.append(now - start)
            start = now
    return times


def workers_run(frames: int, workers: int) -> tuple[float, float]:
    """(frames per second, load average during the run) of ``run.py --workers N`` end to end."""
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(Path(out) / "run"), "--frames", str(frames), "--workers", str(workers), *PARKING],
                       check=True, capture_output=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
        took = time.perf_counter() - start
        return frames / took, os.getloadavg()[0]


def railway_scan_s(sampling: float) -> float:
    """Seconds of one run.py railway frame with railway_tls at ``sampling_factor`` (PLY only)."""
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(Path(out) / "run"), "--set", "sensor.preset=railway_tls", "--set",
                        f"sensor.sampling_factor={sampling}",
                        "--set", "output.formats=[ply]", "--set", "output.preview=false"], check=True, capture_output=True)
        return time.perf_counter() - start


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    long_run, window, short_run = (150, 25, 30) if args.small else (2000, 100, 200)
    times = frame_times(long_run)
    first, last = statistics.median(times[:window]), statistics.median(times[-window:])
    rows = [{"what": f"{long_run} parking frames, one folder", "first_frames_s": first, "last_frames_s": last, "last_over_first": last / first,
             "window": window}]
    rates = {}
    for workers in (1, 2):
        rates[workers], load = workers_run(short_run, workers)
        rows.append({"what": f"{short_run} parking frames, --workers {workers}", "frames_per_s": rates[workers], "speedup": rates[workers] / rates[1],
                     "load_avg_1min": load})
    sampling = 0.25 if args.small else 1.0  # rays grow with the square of the sampling factor
    railway = railway_scan_s(sampling) / sampling**2
    rows.append({"what": "projection: the parking paper's 6,740 scans", "hours_1_worker": 6740 / rates[1] / 3600, "hours_2_workers": 6740 / rates[2] / 3600})
    rows.append({"what": "projection: the railway thesis's 140 simulations (23 M rays each)", "one_simulation_s": railway,
                 "hours_1_worker": 140 * railway / 3600, "thesis_hours": "8-10"})
    report("dataset", rows, args.out,
           {"cores": os.cpu_count(), "note": "ratios within one run; load_avg shows other work on the machine during the workers' runs"})


if __name__ == "__main__":
    main()
