"""Parking and industrial-hall frames end to end: wall time per frame, split into randomise, export, scan, boxes, write.

Each builder runs with its own default sensor (parking: the paper's VLP-16 at 0.4 deg on the
cleaning robot; hall: the OS1-128 x 2048 through its eight mirrors, overhead) and the default
outputs plus both box formats, in one process (``pipeline.run_frames``). Frame 0 builds the
static scene; later frames only re-randomise it. Reference, measured in the same run: the same
frames with the scene rebuilt every frame (every object created anew; the mesh datablocks of the
car styles and the body builds, made once per Blender session, are kept); and the human-robot
paper's 27.6 s per frame (seed 002). Reports medians over the frames after the first.
Run: python benchmarks/bench_scenes.py [--small]
"""

import os
import statistics
import tempfile
import time

from common import RESULTS, arguments, report

PAPER_SECONDS = 27.6  # the human-robot paper: one virtual frame, Blender Geometry Nodes
TARGET_SECONDS = 2.0
STAGES = ("build", "export", "scan", "effects", "boxes", "write")


def frames(config, rebuild: bool):
    """``[(wall_s, timings, points, boxes), ...]`` of one run of ``config``."""
    import bpy

    from bpy_pipeline.frame import Run
    from bpy_pipeline.plan import make_frame
    from bpy_pipeline.dataset import Dataset

    bpy.ops.wm.read_factory_settings(use_empty=True)
    out = []
    with tempfile.TemporaryDirectory() as folder, Dataset.open(folder, config) as dataset:
        run = Run(config)
        start = time.perf_counter()
        for index in range(config.frames):
            entry = dataset.commit(make_frame(run, index))
            out.append((time.perf_counter() - start, entry["timings_s"], entry["points"], len(entry.get("boxes", []))))
            if rebuild:
                run.keep.clear()  # the next frame builds its scene from nothing
            start = time.perf_counter()
    return out


def row(name: str, mode: str, runs: list) -> dict:
    later = runs[1:] or runs
    out = {"scene": name, "mode": mode, "frames": len(runs), "first_frame_s": runs[0][0], "wall_s": statistics.median(r[0] for r in later)}
    for stage in STAGES:
        out[f"{stage}_s"] = statistics.median(r[1].get(stage, 0.0) for r in later)
    out["points"] = int(statistics.median(r[2] for r in later))
    out["boxes"] = statistics.median(r[3] for r in later)
    return out


def chart(rows: list, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.2))
    labels = [f"{r['scene']}\n{r['mode']}" for r in rows]
    left = [0.0] * len(rows)
    for stage, colour in zip(STAGES, ("#4c72b0", "#55a868", "#c44e52", "#dd8452", "#8172b2", "#ccb974")):
        widths = [r[f"{stage}_s"] for r in rows]
        ax.barh(labels, widths, left=left, color=colour, label=stage)
        left = [a + b for a, b in zip(left, widths)]
    ax.axvline(TARGET_SECONDS, color="black", linestyle="--", linewidth=1)
    ax.text(TARGET_SECONDS, -0.6, "target ", ha="right", va="bottom", fontsize=8)
    ax.set_xlabel(f"seconds per frame, median (the paper: {PAPER_SECONDS} s)")
    ax.legend(fontsize=8, loc="center right")
    ax.invert_yaxis()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    args = arguments(__doc__)
    from bpy_pipeline.config import load_config

    count = 3 if args.small else 10
    scenes = {
        "parking": ["scene.builder=parking"],
        "industrial_hall": ["scene.builder=industrial_hall"] + (["sensor.columns=512"] if args.small else []),
    }
    rows = []
    for name, sets in scenes.items():
        config = load_config(None, sets + [f"frames={count}"])
        rerandomised = row(name, "re-randomise", frames(config, rebuild=False))
        rebuilt = row(name, "rebuild", frames(config, rebuild=True))
        rerandomised["speedup_vs_rebuild"] = rebuilt["wall_s"] / rerandomised["wall_s"]
        rerandomised["build_speedup_vs_rebuild"] = rebuilt["build_s"] / max(rerandomised["build_s"], 1e-6)
        rerandomised["speedup_vs_paper"] = PAPER_SECONDS / rerandomised["wall_s"]
        rows += [rerandomised, rebuilt]
    name = "scenes" + ("_small" if args.small else "")
    report(name, rows, args.out, {
        "command": "python benchmarks/bench_scenes.py" + (" --small" if args.small else ""),
        "reference": f"the same frames rebuilt from nothing each frame (same run); the human-robot paper's {PAPER_SECONDS} s per frame",
        "target_s": TARGET_SECONDS,
        "load_average_1min": os.getloadavg()[0],  # other work on the machine while it ran
    })
    if not args.small or args.out != RESULTS:
        chart(rows, args.out / f"{name}.png")


if __name__ == "__main__":
    main()
