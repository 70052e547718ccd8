"""Reference jobs as a user runs them: frames per second per core, beside the source documents' figures.

Each job runs end to end with ``run.py`` (start-up, build, export, scan, effects, boxes, writing
and committing every frame) on this machine's cores:

- the default job (the railway, the terrestrial scanner at 0.2 deg);
- parking frames (the parking paper's VLP-16 garage), with one process and with ``--workers 2``;
- industrial-hall frames (the human-robot paper's mirror LiDAR over people and an arm; the paper:
  27.6 s per frame);
- the railway thesis's full-resolution scan (23 M rays; the thesis: about 240 s);
- a mixed real-scan frame (cars inserted into the nuScenes sweep), where that builder and the
  scan are present.

``fps_per_core`` divides by the cores the job may use (a single process uses both through its
ray-casting threads). ``cores_used`` = CPU time / wall time of the job's processes: on a shared
machine, how many cores the job actually got. --small runs fewer frames and the thesis scan at a quarter of its sampling
factor (1/16 of the rays), scaled up.

    python benchmarks/bench_reference_jobs.py [--small]
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import ROOT, arguments, report

REAL_SCANS = Path(os.environ.get("BPY_PIPELINE_REAL_SCANS", ROOT.parent / "shared" / "real_scans"))


def timed(args: list[str], env: dict | None = None) -> tuple[float, float]:
    """``(wall s, CPU s)`` of ``run.py ARGS --out TMP`` (CPU: user + system of it and its workers)."""
    with tempfile.TemporaryDirectory() as out:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(Path(out) / "run"), *args], capture_output=True, text=True,
                              env={**os.environ, **(env or {})})
        if done.returncode != 0:
            raise RuntimeError(f"run.py {' '.join(args)}: {done.stderr.strip()[-500:]}")
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    cores = os.cpu_count() or 1
    parking_frames, hall_frames, sampling = (40, 6, 0.25) if args.small else (1000, 300, 1.0)
    jobs = [
        ("default job", [], 1, None, None),
        (f"{parking_frames} parking frames", ["--set", "scene.builder=parking", "--frames", str(parking_frames)], parking_frames, None, None),
        (f"{parking_frames} parking frames, --workers 2", ["--set", "scene.builder=parking", "--frames", str(parking_frames), "--workers", "2"], parking_frames,
         None, None),
        (f"{hall_frames} industrial-hall frames", ["--set", "scene.builder=industrial_hall", "--frames", str(hall_frames)], hall_frames, 27.6,
         "the human-robot paper: 27.6 s per frame"),
        ("railway thesis scan, 23 M rays", ["--set", "sensor.preset=railway_tls", "--set", f"sensor.sampling_factor={sampling}", "--set",
                                            "output.formats=[ply]", "--set", "output.preview=false"], sampling**2, 240.0, "the railway thesis: about 240 s"),
    ]
    sweep = REAL_SCANS / "nuscenes_hdl32e_sweep.bin"
    from bpy_pipeline.builders import BUILDERS

    if "real_scan" in BUILDERS and sweep.exists():
        cars = "[" + ", ".join(f"{{type: car, center: [{x}, {y}, -0.9], size: [4.5, 1.9, 1.6], yaw_deg: {a}}}" for x, y,
                               a in ((8, 4, 0), (-10, 5, 90), (12, -6, 30), (20, 2, 0), (-6, -8, 180))) + "]"
        jobs.append(("mixed real-scan frame, 5 cars", ["--set", "scene.builder=real_scan", "--set", f"scene.path={sweep}", "--set", f"scene.objects={cars}"], 1,
                     None, None))
    rows = []
    for name, run_args, frames, reference_s, source in jobs:
        took, cpu = timed(run_args, {"OPENBLAS_NUM_THREADS": "1"})
        per_frame = took / frames
        row = {"job": name, "wall_s": took, "s_per_frame": per_frame, "fps": 1 / per_frame, "fps_per_core": 1 / per_frame / cores, "cpu_s": cpu,
               "cores_used": cpu / took}
        print(name, row, flush=True)
        if reference_s is not None:
            row.update({"reference_s_per_frame": reference_s, "faster_than_reference": reference_s / per_frame, "reference": source})
        rows.append(row)
    report("reference_jobs", rows, args.out,
           {"cores": cores, "small": args.small,
            "note": "end to end with run.py, start-up included; the thesis scan at --small is 1/16 of the rays, scaled up"})


if __name__ == "__main__":
    main()
