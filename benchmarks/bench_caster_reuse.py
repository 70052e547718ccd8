"""The kept caster across a run's frames (``Run.casters``) against a fresh caster every frame, in one run.

Each frame's scene is built once; then the frame is made twice through the pipeline's stages after
the build (pose, export, scan, effects, boxes), once with the run's kept
:class:`~bpy_pipeline.lidar.cast.raycast.CasterCache` and once with a fresh one, in alternating order
(so a busy moment or a warm cache favours neither), and the two frames must give the same bytes.
Reported per job: seconds per frame of the scan stage (caster set-up, trace, records, effects) and
of the boxes stage (its visibility cast reuses the frame's caster in both), and ``speedup`` = fresh
time / kept time of those stages together. Jobs:

- the default railway (static scene and sensor: the whole caster is kept);
- the industrial hall (the hall is kept; the people and robots, placed every frame, get their own
  caster each frame, as in the fresh case);
- parking (the robot moves every frame: the caster's local frame is its pose, so nothing is kept;
  the control).

Run: python benchmarks/bench_caster_reuse.py [--small]
"""

import time

import numpy as np
from common import arguments, report

import bpy

from bpy_pipeline.config import load_config
from bpy_pipeline.frame import Frame
from bpy_pipeline.lidar.cast.raycast import CasterCache
from bpy_pipeline.frame import Run, frame_rng
from bpy_pipeline.plan import plan
from bpy_pipeline.stages.scene import build_stage

TIMED = ("scan", "boxes")


def remake(run: Run, index: int, scene, cache: CasterCache) -> Frame:
    """Frame ``index`` through the stages after the build (its scene already built), with ``cache`` as the run's casters."""
    kept, run.casters = run.casters, cache
    try:
        frame = Frame(index, run.config, frame_rng(run.config.seed, index), scene=scene)
        for stage in plan(run.config):
            if stage.name == "build":
                continue
            start = time.perf_counter()
            stage(frame, run)
            if stage.timing is not None:  # None: the stage timed its own parts
                frame.timings[stage.timing] = frame.timings.get(stage.timing, 0.0) + time.perf_counter() - start
    finally:
        run.casters = kept
    return frame


def job(name: str, overrides: list[str], frames: int) -> dict:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(overrides=[f"frames={frames}", "output.boxes.formats=[kitti]", *overrides])
    run = Run(config)
    times = {"kept": {k: [] for k in TIMED}, "fresh": {k: [] for k in TIMED}}
    for index in range(frames):
        holder = Frame(index, config, frame_rng(config.seed, index))
        build_stage(holder, run)
        scene = holder.scene
        order = ("kept", "fresh") if index % 2 == 0 else ("fresh", "kept")
        made = {}
        for which in order:
            made[which] = remake(run, index, scene, run.casters if which == "kept" else CasterCache(run.threads))
        assert made["kept"].points.tobytes() == made["fresh"].points.tobytes(), f"{name}: frame {index} differs with the kept caster"
        if index == 0:
            continue  # the first frame builds the kept caster (and loads the kernels): not a per-frame cost
        for which in ("kept", "fresh"):
            for k in TIMED:
                times[which][k].append(made[which].timings.get(k, 0.0))
    median = {w: {k: float(np.median(v)) for k, v in t.items()} for w, t in times.items()}
    kept_s, fresh_s = sum(median["kept"].values()), sum(median["fresh"].values())
    buffers = made["kept"].buffers
    return {
        "job": name,
        "frames_timed": frames - 1,
        "triangles": int(len(buffers.triangles)),
        "cache_builds": run.casters.builds,
        "cache_reuses": run.casters.reuses,
        "kept_scan_s": median["kept"]["scan"],
        "fresh_scan_s": median["fresh"]["scan"],
        "kept_boxes_s": median["kept"]["boxes"],
        "fresh_boxes_s": median["fresh"]["boxes"],
        "speedup": fresh_s / kept_s,
    }


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    frames = 4 if args.small else 9
    coarse = ["sensor.horizontal_resolution_deg=0.5", "sensor.vertical_resolution_deg=0.5"] if args.small else []
    rows = [
        job("default railway (nothing moves)", coarse, frames),
        job("industrial hall (people and robots move)", ["scene.builder=industrial_hall", *(["sensor.columns=512"] if args.small else [])], frames),
        job("parking (the sensor moves: nothing kept)", ["scene.builder=parking"], frames),
    ]
    report("caster_reuse", rows, args.out,
           {"note": "median seconds per frame after the first; speedup = fresh / kept time of the scan and boxes stages; same bytes checked per frame"})


if __name__ == "__main__":
    main()
