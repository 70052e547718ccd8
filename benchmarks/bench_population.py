"""A populated user scene end to end: wall time per frame split by stage (build = open/populate, export, scan, boxes, write).

Scenes: the worked example's hall (examples/hall_twin: make_hall.py's .blend populated per frame by
``scene.population`` with 2-5 people, some seated, and a robot arm, scanned by the super-resolution
mirror LiDAR: OS1-128 x 2048 through its 8 mirrors, 229 k points a frame), and the parking garage
populated with imported car assets (the project's sedan GLB) and people, VLP-16. In one process
(``pipeline.make_frame``). Frame 0 opens the file, imports the assets and finds the surfaces; later
frames only draw, place and pose. Reference, measured in the same run: the same frames with the scene
and population rebuilt every frame (the .blend reopened, assets imported again); and the human-robot
paper's 27.6 s per frame ("Raphael: Realistic 3D Data Generation and Unsupervised Learning for Enhanced
Human-Robot Detection in the Real World"). Medians over the frames after the first.
Run: python benchmarks/bench_population.py [--small]
"""

import os
import statistics
import sys
import tempfile
import time

import yaml

from common import ROOT, arguments, report

PAPER_SECONDS = 27.6  # the human-robot paper: one virtual frame
STAGES = ("build", "export", "scan", "effects", "boxes", "write")


def frames(config, rebuild: bool):
    """``[(wall_s, timings, points, placed), ...]`` of one run of ``config``."""
    import bpy

    from bpy_pipeline.dataset import Dataset
    from bpy_pipeline.frame import Run
    from bpy_pipeline.plan import make_frame

    bpy.ops.wm.read_factory_settings(use_empty=True)
    out = []
    with tempfile.TemporaryDirectory() as folder, Dataset.open(folder, config) as dataset:
        run = Run(config)
        start = time.perf_counter()
        for index in range(config.frames):
            frame = make_frame(run, index)
            entry = dataset.commit(frame)
            info = frame.scene.info["population"]
            placed = sum(v["placed"] for k, v in info.items() if isinstance(v, dict) and "placed" in v)
            out.append((time.perf_counter() - start, entry["timings_s"], entry["points"], placed))
            if rebuild:
                run.keep.clear()  # the next frame opens the file and builds its population from nothing
            start = time.perf_counter()
    return out


def row(name: str, mode: str, runs: list) -> dict:
    later = runs[1:] or runs
    out = {"scene": name, "mode": mode, "frames": len(runs), "first_frame_s": runs[0][0], "wall_s": statistics.median(r[0] for r in later)}
    for stage in STAGES:
        out[f"{stage}_s"] = statistics.median(r[1].get(stage, 0.0) for r in later)
    out["points"] = int(statistics.median(r[2] for r in later))
    out["placed_objects"] = statistics.median(r[3] for r in later)
    out["vs_paper"] = PAPER_SECONDS / out["wall_s"]
    return out


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    sys.path.insert(0, str(ROOT / "examples" / "hall_twin"))
    from make_hall import build_hall

    from bpy_pipeline.config import load_config

    n = 3 if args.small else 10
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        blend = build_hall(f"{folder}/hall.blend")
        hall = yaml.safe_load((ROOT / "examples" / "hall_twin" / "hall_twin.yaml").read_text())
        hall["scene"]["path"] = str(blend)
        hall["frames"] = n
        parking = yaml.safe_load((ROOT / "examples" / "hall_twin" / "parking_assets.yaml").read_text())
        parking["frames"] = n
        for name, data in (("hall_twin (blend, mirror LiDAR)", hall), ("parking + car assets", parking)):
            config = load_config(data)
            rows.append(row(name, "populated in place", frames(config, rebuild=False)))
            rows.append(row(name, "rebuilt every frame", frames(config, rebuild=True)))
    report(
        "population",
        rows,
        args.out,
        {
            "paper_seconds_per_frame": PAPER_SECONDS,
            "stages": "build: open the .blend (first frame) and draw/place/pose the population; export: evaluated depsgraph to buffers; scan: Embree through "
                      "the sensor's mirrors; boxes: 3D boxes with occlusion; write: PLY/NPY/labels",
            "medians_over": "the frames after the first",
            "load_average_after": [round(x, 2) for x in os.getloadavg()],  # other jobs on the machine inflate every figure
        },
    )


if __name__ == "__main__":
    main()
