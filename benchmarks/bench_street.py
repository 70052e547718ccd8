"""The sparse-camera study on the street builder: frames per second of the three-camera rig, and the share of kept frames.

Scene: ``scene.builder: street`` (an intersection, road users drawn every frame) scanned by the
sparse-camera thesis's rig (``flash_post_240``: three 96 x 16 flash cameras, 80 x 13.3 deg,
35 m, on a 2 m post at a corner of the intersection). Boxes of cars, vans, trucks, buses,
pedestrians, bicycles and motorcycles (riders in their vehicle's box) are kept with the thesis's
minimum points (12 for cars, 6 for the rest); a frame without any box is skipped
(``output.skip_empty``), as the thesis dropped 1,783 of its 4,599 frames (61 % kept, 1.9 objects
per kept frame).

1. Speed: wall time per frame of the rig (build, export, three scans, boxes, write), against a
   reference measured in the same run: the middle camera alone on the same builder and seeds (its
   placement follows its own field of view, so its scenes hold other users); the two runs' frames
   are made in turn, so a shared machine's load weighs on both alike.
   Frames per second per core are reported (the machine's cores are shared).
2. Placement (the rig with the default and with sparse traffic, and one camera at its rated 10 m,
   pitched 12 deg down so that the ground within 10 m is in its 13.3 deg field): the share of frames kept and the boxes per kept frame with field-of-view-aware
   placement (``scene.fov_aware: true``, the default) and without it (users anywhere on the
   street, as the parking builder places cars all around a 360-degree robot).

Run: python benchmarks/bench_street.py [--small]
"""

import json
import statistics
import tempfile
import time
from pathlib import Path

from common import arguments, report

THESIS = {"frames": 4599, "kept": 2816, "objects_per_frame": 1.9}
BOX_CLASSES = ["car", "van", "truck", "bus", "person", "bicycle", "motorcycle", "rider"]


# Sparse traffic, about the thesis's objects per frame: a few users in the whole intersection.
SPARSE = {"vehicles": {"mean": 2.0, "std": 1.5, "max": 10.0}, "parked": {"mean": 1.0, "std": 1.0, "max": 5.0},
          "pedestrians": {"mean": 2.0, "std": 1.5, "max": 10.0},
          "bicycles": {"mean": 0.5, "std": 0.7, "max": 3.0}, "motorcycles": {"mean": 0.5, "std": 0.7, "max": 3.0}}


def config(frames: int, fov_aware: bool, single: bool = False, seed: int = 0, traffic: str = "default", max_range: float = 35.0, pitch: float = 0.0):
    from bpy_pipeline.config import load_config

    sensor = {"preset": "flash96x16_carla", "max_range": max_range, "position": [-7.6, -7.6, 2.15], "rotation_deg": [0.0, pitch, 45.0]} if single else {}
    scene = {"builder": "street", "fov_aware": fov_aware, **(SPARSE if traffic == "sparse" else {})}
    return load_config({"seed": seed, "frames": frames, "scene": scene, **({"sensor": sensor} if sensor else {}),
                        "output": {"formats": ["ply", "rig"] if not single else ["ply"], "preview": False, "skip_empty": True,
                                   "frame": "world" if pitch else "sensor", "boxes": {"formats": ["openpcdet"], "classes": BOX_CLASSES}}})


def measure(cfg) -> dict:
    """One run of ``cfg``: wall seconds per frame (median after the first), kept share, boxes per kept frame."""
    import bpy

    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    with tempfile.TemporaryDirectory() as folder:
        stamps = []
        start = time.perf_counter()

        def log(line: str) -> None:
            stamps.append(time.perf_counter())

        run(cfg, folder, log=log)
        records = [json.loads(p.read_text()) for p in sorted((Path(folder) / "records").glob("*.json"))]
    walls = [b - a for a, b in zip([start] + stamps[:-1], stamps)]
    kept = [r for r in records if not r.get("skipped")]
    stages = {}
    for r in records[1:] or records:
        for k, v in r["timings_s"].items():
            stages.setdefault(k, []).append(v)
    out = {"frames": len(records), "kept": len(kept), "kept_share": len(kept) / max(len(records), 1),
           "boxes_per_kept_frame": statistics.mean(len(r["boxes"]) for r in kept) if kept else 0.0,
           "wall_s": statistics.median(walls[1:] or walls), "first_frame_s": walls[0]}
    out["fps"] = 1.0 / out["wall_s"]
    out.update({f"{k}_s": statistics.median(v) for k, v in stages.items()})
    classes = {}
    for r in kept:
        for b in r["boxes"]:
            classes[b["class"]] = classes.get(b["class"], 0) + 1
    out["boxes_by_class"] = classes
    out["out_of_view_refused"] = sum(sum(r.get("scene", {}).get("out_of_view", {}).values()) for r in records)
    return out


def interleaved(configs: list, frames: int) -> list[dict]:
    """Per config, median wall seconds per frame and per stage, the configs' frames made in turn (frame k of
    each, then frame k + 1), so the load of a shared machine weighs on all alike. They share the street."""
    import bpy

    from bpy_pipeline.dataset import Dataset
    from bpy_pipeline.frame import Run
    from bpy_pipeline.plan import make_frame

    bpy.ops.wm.read_factory_settings(use_empty=True)
    walls = [[] for _ in configs]
    stages = [{} for _ in configs]
    with tempfile.TemporaryDirectory() as folder:
        runs = []
        for k, cfg in enumerate(configs):
            runs.append(Run(cfg, keep=runs[0].keep if runs else {}))  # one static street for all
        datasets = [Dataset.open(Path(folder) / str(k), cfg) for k, cfg in enumerate(configs)]
        try:
            for index in range(frames):
                for k, (run, dataset) in enumerate(zip(runs, datasets)):
                    start = time.perf_counter()
                    frame = make_frame(run, index)
                    dataset.commit(frame)
                    walls[k].append(time.perf_counter() - start)
                    if index:
                        for name, value in frame.timings.items():
                            stages[k].setdefault(name, []).append(value)
        finally:
            for dataset in datasets:
                dataset.close()
    out = []
    for k in range(len(configs)):
        wall = statistics.median(walls[k][1:] or walls[k])
        out.append({"wall_s": wall, "fps": 1.0 / wall, **{f"{n}_s": statistics.median(v) for n, v in stages[k].items()}})
    return out


def chart(rows: list, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    speed = [r for r in rows if r["part"] == "speed"]
    left.bar([r["sensor"] for r in speed], [r["wall_s"] * 1000 for r in speed], color=["tab:blue", "tab:grey"])
    left.set_ylabel("ms per frame (median)")
    left.set_title("Rig vs one camera, same builder and seeds")
    for i, r in enumerate(speed):
        left.text(i, r["wall_s"] * 1000, f"{r['fps']:.1f} fps", ha="center", va="bottom")
    place = [r for r in rows if r["part"] == "placement"]
    groups = list(dict.fromkeys((r["sensor"], r["traffic"]) for r in place))
    for g, (sensor, traffic) in enumerate(groups):
        for j, fov in enumerate((True, False)):
            r = next(r for r in place if (r["sensor"], r["traffic"], r["fov_aware"]) == (sensor, traffic, fov))
            bar = right.bar(g + (j - 0.5) * 0.38, r["kept_share"] * 100, 0.36, color="tab:blue" if fov else "tab:orange",
                            label=("field-of-view aware" if fov else "anywhere") if g == 0 else None)
            right.text(bar[0].get_x() + 0.18, bar[0].get_height(), f"{r['boxes_per_kept_frame']:.1f}", ha="center", va="bottom", fontsize=7)
    thesis = 100 * THESIS["kept"] / THESIS["frames"]
    right.axhline(thesis, color="tab:grey", ls="--", lw=1, label=f"thesis, CARLA ({thesis:.0f} %, {THESIS['objects_per_frame']} obj.)")
    right.set_xticks(range(len(groups)), [f"{s}\n{t} traffic" for s, t in groups], fontsize=7)
    right.legend(fontsize=7, loc="lower right")
    right.set_ylabel("frames kept (%)")
    right.set_ylim(0, 110)
    right.set_title("Frames kept (numbers: boxes per kept frame)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    frames = 3 if args.small else 40
    rows = []
    speed_rig, speed_single = interleaved([config(frames, True), config(frames, True, single=True)], frames)
    for name, result in (("3-camera rig", speed_rig), ("middle camera alone", speed_single)):
        rows.append({"part": "speed", "sensor": name, "frames": frames, "wall_s": result["wall_s"], "fps": result["fps"],
                     "ratio_to_one_camera": result["wall_s"] / speed_single["wall_s"],
                     **{k: result[k] for k in ("build_s", "export_s", "scan_s", "boxes_s", "write_s") if k in result}})
    rig = measure(config(frames, True))
    cases = [("3-camera rig", "default", {}), ("3-camera rig", "sparse", {}),
             ("one camera, 10 m, 12 deg down", "sparse", {"single": True, "max_range": 10.0, "pitch": 12.0})]
    for sensor, traffic, extra in cases:
        for fov in (True, False):
            result = rig if (sensor, traffic, fov) == ("3-camera rig", "default", True) else measure(config(frames, fov, traffic=traffic, **extra))
            rows.append({"part": "placement", "sensor": sensor, "traffic": traffic, "fov_aware": fov, "frames": result["frames"], "kept": result["kept"],
                         "kept_share": result["kept_share"],
                         "boxes_per_kept_frame": result["boxes_per_kept_frame"], "out_of_view_refused": result["out_of_view_refused"],
                         "boxes_by_class": json.dumps(result["boxes_by_class"], sort_keys=True)})
    name = "street_small" if args.small else "street"
    notes = {"thesis": THESIS, "thesis_kept_share": THESIS["kept"] / THESIS["frames"], "rig": "flash_post_240 (3 x flash96x16_carla, 2 m post)",
             "speed_reference": "the middle camera alone on the same frames, measured in the same run"}
    report(name, rows, args.out, notes)
    if not args.small:
        chart(rows, args.out / "street.png")


if __name__ == "__main__":
    main()
