"""bpy-pipeline match: object statistics of real labelled frames against synthetic runs before and after matching.

Real: the labelled frames among the test scans (SemanticKITTI 000700 and sequence 01's three,
KITTI object 004747; objects with >= 10 points). Before: the real_scan builder's parking rule as
the paper set it (cars only, N(5, 4) per frame, N(10, 20) m within 2.5-20 m, random yaw); after:
the config `match` writes (one rule per class with the fitted count, distance and heading
histograms). Both insert into KITTI 004747 (HDL-64E), frames run through the pipeline (bpy
module); each frame's placed objects and their points are read from the frame records. Per class
and histogram: total variation distance to the real one (0: the same, 1: disjoint), the mean
count per frame, and the points per object against distance. The placement distributions are
also sampled directly (20,000 draws) to separate what the rule's checks refuse from what the
distributions give.
Run: python benchmarks/bench_match.py [--small]   (--small: 2 frames per run instead of 8)
"""

import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np
from common import ROOT, arguments, report

from bpy_pipeline.geometry.placement import sample, sample_count
from bpy_pipeline.cli.match import DISTANCE_EDGES, HEADING_EDGES, fit_real, histogram, matched_config, stats_report

REAL = ROOT.parent / "shared" / "real_scans"
FRAMES = ["semantickitti_000700_points.npy", "semantickitti_seq01_000000_points.npy", "semantickitti_seq01_000001_points.npy",
          "semantickitti_seq01_000002_points.npy", "kitti_hdl64e_004747.bin"]
BACKGROUND = "kitti_hdl64e_004747.bin"
KIND_CLASS = {"car": "car", "person": "person", "cyclist": "bicyclist"}


def base_config(frames: int) -> dict:
    return {"seed": 0, "frames": frames, "sensor": {"preset": "hdl64e"}, "output": {"formats": ["ply"]},
            "scene": {"builder": "real_scan", "path": str(REAL / BACKGROUND), "parking_rule": {"enabled": True}}}


def tv(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.sum() == 0 or b.sum() == 0:
        return float("nan")
    return 0.5 * float(np.abs(a / a.sum() - b / b.sum()).sum())


def run_objects(config: dict, out: Path) -> tuple[dict, float]:
    """Run ``config`` and return per class {counts, distances, headings, points} of the placed objects, and seconds."""
    import bpy_pipeline as bp

    start = time.perf_counter()
    bp.run(bp.load_config(config), out, log=lambda m: None)
    seconds = time.perf_counter() - start
    got = {}
    for record in sorted((out / "records").glob("*.json")):
        r = json.loads(record.read_text())
        points = {b["instance"]: b["points"] for b in r.get("boxes", [])}
        per_frame = {}
        for o in r["scene"]["objects"]:
            cls = KIND_CLASS.get(o["type"], o["type"])
            x, y = o["center"][:2]
            g = got.setdefault(cls, {"counts": [], "distances": [], "headings": [], "points": []})
            g["distances"].append(math.hypot(x, y))
            g["headings"].append((o["yaw_deg"] - math.degrees(math.atan2(y, x)) + 90) % 180 - 90)
            g["points"].append(points.get(o["instance"], 0))
            per_frame[cls] = per_frame.get(cls, 0) + 1
        for cls in set(got) | set(per_frame):
            got.setdefault(cls, {"counts": [], "distances": [], "headings": [], "points": []})["counts"].append(per_frame.get(cls, 0))
    return got, seconds


def sampled(rule_dict: dict, n: int = 20_000) -> dict:
    """The placement distributions of a parking rule mapping, drawn directly."""
    from bpy_pipeline.schema import from_dict
    from bpy_pipeline.mixing.section import ParkingRule

    rule = from_dict(ParkingRule, rule_dict, "rule")
    rng = np.random.default_rng(0)
    headings = sample(rule.heading, rng, n)
    return {"counts": [sample_count(rule.count, rng) for _ in range(n // 10)], "distances": sample(rule.distance, rng, n),
            "headings": (headings + 90) % 180 - 90}


def compare(real: dict, synth: dict) -> dict:
    c_real = np.bincount(real["counts"])
    c_syn = np.bincount(np.asarray(synth["counts"], int), minlength=len(c_real)) if len(synth["counts"]) else np.zeros(1)
    top = max(len(c_real), len(c_syn))
    return {
        "mean_count_real": float(np.mean(real["counts"])), "mean_count_synthetic": float(np.mean(synth["counts"])) if len(synth["counts"]) else 0.0,
        "tv_count": tv(np.pad(c_real, (0, top - len(c_real))), np.pad(c_syn, (0, top - len(c_syn)))),
        "tv_distance": tv(histogram(np.asarray(real["distances"]), DISTANCE_EDGES)["weights"],
                          histogram(np.asarray(synth["distances"]), DISTANCE_EDGES)["weights"]) if len(synth["distances"]) else None,
        "tv_heading": tv(histogram(np.asarray(real["headings"]), HEADING_EDGES)["weights"],
                         histogram(np.asarray(synth["headings"]), HEADING_EDGES)["weights"]) if len(synth["headings"]) else None,
    }


def main():
    args = arguments(__doc__)
    if not all((REAL / f).exists() for f in FRAMES):
        print(f"skipped: the labelled real frames are not all in {REAL}")
        return
    frames = 2 if args.small else 8
    stats, names = fit_real([REAL / f for f in FRAMES])
    real = {c: {"counts": s.counts, "distances": s.distances, "headings": s.headings, "points": s.points} for c, s in stats.items()}
    before_cfg = base_config(frames)
    after_cfg, notes = matched_config(before_cfg, stats)
    rules = {"before": {"car": before_cfg["scene"]["parking_rule"]},
             "after": {KIND_CLASS[r["type"]]: r for r in [after_cfg["scene"]["parking_rule"], *after_cfg["scene"]["parking_rules"]]}}
    rows, runs, seconds = [], {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, config in (("before", before_cfg), ("after", after_cfg)):
            runs[label], seconds[label] = run_objects(config, Path(tmp) / label)
    for label in ("before", "after"):
        for cls in real:
            empty = {"counts": [0] * frames, "distances": [], "headings": [], "points": []}
            run = runs[label].get(cls, empty)
            row = {"run": label, "class": cls, "objects_real": int(len(real[cls]["distances"])), "objects_run": len(run["distances"])}
            row.update({f"{k}_run": v for k, v in compare(real[cls], run).items()})
            if cls in rules[label]:
                drawn = sampled({k: v for k, v in rules[label][cls].items() if k != "near_rejection_probability"} | {"enabled": True})
                row.update({f"{k}_sampled": v for k, v in compare(real[cls], drawn).items() if not k.startswith("mean_count_real")})
            rows.append(row)
    notes_out = {
        "command": "python benchmarks/bench_match.py" + (" --small" if args.small else ""),
        "real_frames": names, "frames_per_run": frames, "background": BACKGROUND, "run_s": seconds, "match_notes": notes,
        "real": stats_report(stats, names),
        "synthetic_points_per_object": {label: {c: {"distances": [round(float(d), 2) for d in v["distances"]], "points": v["points"]} for c,
                                                v in r.items()} for label, r in runs.items()},
        "tv": "total variation distance of the normalised histograms (count per frame, distance in 5 m bins to 80 m, heading in 30 deg bins)",
    }
    name = "match" + ("_small" if args.small else "")
    report(name, rows, args.out, notes_out)
    chart(real, runs, stats, args.out / f"{name}.png")


def chart(real, runs, stats, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    classes = list(real)
    fig, ax = plt.subplots(len(classes), 4, figsize=(18, 3.8 * len(classes)), squeeze=False)
    colours = {"real": "k", "before": "tab:red", "after": "tab:green"}
    for i, cls in enumerate(classes):
        sources = {"real": real[cls], **{k: v.get(cls) for k, v in runs.items()}}
        for label, s in sources.items():
            if s is None or not len(s["distances"]):
                continue
            counts = np.bincount(np.asarray(s["counts"], int))
            ax[i, 0].plot(np.arange(len(counts)), counts / counts.sum(), "o-", color=colours[label], label=label)
            for j, (key, edges) in enumerate((("distances", DISTANCE_EDGES), ("headings", HEADING_EDGES)), 1):
                w = np.asarray(histogram(np.asarray(s[key]), edges)["weights"], float)
                ax[i, j].step(edges[:-1], w / w.sum(), where="post", color=colours[label], label=label)
            ax[i, 3].scatter(s["distances"], np.maximum(s["points"], 1), s=12, color=colours[label], label=label, alpha=0.7)
        law = stats[cls].curve["power_law"]
        if law:
            d = np.linspace(3, 80, 50)
            ax[i, 3].plot(d, law["a"] * d ** -law["b"], "k--", lw=0.8, label=f"real fit {law['a']:.0f} d^-{law['b']:.2f}")
        ax[i, 0].set_title(f"{cls}: objects per frame")
        ax[i, 1].set_title(f"{cls}: distance (m, 5 m bins)")
        ax[i, 2].set_title(f"{cls}: heading - bearing (deg)")
        ax[i, 3].set_title(f"{cls}: points per object")
        ax[i, 3].set_xscale("log")
        ax[i, 3].set_yscale("log")
        ax[i, 3].set_xlabel("distance, m")
        for a in ax[i]:
            a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    print(f"chart: {path}")


if __name__ == "__main__":
    main()
