"""Sim-to-real: a model trained on our street scans alone, tested on real labelled HDL-64E scans.

The measure every document this project grows from judges its data by: train a network on the
generated scans, test it on real ones. Here the network is the reference model of
``bpy-pipeline evaluate`` (per-point geometric features and LightGBM, bpy_pipeline/evaluate/), the
real frames are those of ../shared/real_scans (SemanticKITTI 000700 and sequence 01, KITTI object
frame 004747 with its boxes), and the classes are car and person. Three trainings, on the same real
test frames:

- **synthetic only**: the `street` builder's ego HDL-64E (examples/street/ego_hdl64e.yaml) over
  several street layouts (``scene.layout_seed``), at each level of scene detail of the ablation;
- **mixed domain**: synthetic cars and people cast into real backgrounds by the `real_scan` builder
  (benchmarks/sim2real_mixed.py), the backgrounds always from another group than the frames tested;
- **real only**: the same model trained on the other real frames, leave one group out (a sequence's
  consecutive frames are one group, so they never sit on both sides).

It charts real IoU against generation cost: CPU seconds of generation per configuration, and the
curve of IoU against the number of synthetic frames. Every class, and the range-image network beside
LightGBM: benchmarks/bench_rangenet.py. Results: benchmarks/results/sim2real.json and
sim2real.png; docs/sim2real.md reads them.

    python benchmarks/bench_sim2real.py            # the full run (about an hour on 2 cores)
    python benchmarks/bench_sim2real.py --small    # 2 layouts x 2 frames, one ablation: that it runs
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bpy_pipeline.evaluate import labelled  # noqa: E402
from bpy_pipeline.evaluate.metrics import score  # noqa: E402
from bpy_pipeline.evaluate.models import fit  # noqa: E402
from bpy_pipeline.evaluate.run import leave_one_group_out  # noqa: E402

CLASSES = ("car", "person")
REAL = Path(os.environ.get("BPY_PIPELINE_REAL_SCANS", ROOT.parent / "shared" / "real_scans"))
TEST_FRAMES = ("semantickitti_000700_points.npy", "semantickitti_seq01_000000_points.npy", "semantickitti_seq01_000001_points.npy",
               "semantickitti_seq01_000002_points.npy", "kitti_hdl64e_004747.bin")
CONFIG = ROOT / "examples" / "street" / "ego_hdl64e.yaml"

# The ablation: each level of scene detail as --set overrides of the default street. "bare" is the street
# without its dressing (no terrain, vegetation, fences or furniture, 40 m arms, its old road-user counts).
NO_DRESSING = ["scene.terrain=false", "scene.open_share=0", "scene.street_trees=0", "scene.yard_plants=0", "scene.boundary_mix={none: 1}",
               "scene.lamp_spacing=0", "scene.furniture_per_100m=0", "scene.roadworks=0"]
OLD_USERS = ["scene.vehicles={mean: 8, std: 3, min: 0, max: 40}", "scene.parked={mean: 6, std: 3, min: 0, max: 40}",
             "scene.pedestrians={mean: 8, std: 4, min: 0, max: 60}", "scene.bicycles={mean: 2, std: 1.5, min: 0, max: 20}", "scene.ego_span=25"]
ABLATION = {
    "default": [],
    "bare (the street before)": NO_DRESSING + ["scene.arm_length=40"] + OLD_USERS,
    "no vegetation": ["scene.street_trees=0", "scene.yard_plants=0", "scene.boundary_mix={fence: 0.35, wall: 0.15, none: 0.5}"],
    "no terrain": ["scene.terrain=false"],
    "no fences walls furniture": ["scene.boundary_mix={hedge: 0.3, none: 0.7}", "scene.lamp_spacing=0", "scene.furniture_per_100m=0", "scene.roadworks=0"],
    "40 m arms": ["scene.arm_length=40", "scene.ego_span=25"],
    "ideal scan (no noise, drop)": ["effects.ideal=true"],
    "more yard trees": ["scene.yard_trees=2"],  # the "Street Planting" group's trees added (2 per 100 m^2 of yard, 4 m apart)
    "material models": ["effects.materials.objects=true"],  # the vehicles' plates (retroreflector) and lamps (glossy) as their models
    "glossy vehicles": ["effects.materials.objects=true",
                        "effects.materials.classes={car: glossy_paint, van: glossy_paint, truck: glossy_paint, bus: glossy_paint}"],
}


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def generate(out: Path, layouts: int, frames: int, sets: list[str], reuse: bool = False) -> dict:
    """``layouts`` street layouts x ``frames`` frames of the ego HDL-64E into ``out/layoutK``; CPU seconds spent
    (written beside them as ``cost.json``; with ``reuse``, a folder made with the same arguments is read back)."""
    key = {"layouts": layouts, "frames": frames, "sets": sets}
    if reuse and (out / "cost.json").is_file():
        kept = json.loads((out / "cost.json").read_text())
        if kept.get("key") == key:
            return kept["cost"]
    before, start = children_cpu(), time.perf_counter()
    for k in range(layouts):
        args = [sys.executable, str(ROOT / "run.py"), "--config", str(CONFIG), "--out", str(out / f"layout{k}"), "--frames", str(frames),
                "--seed", str(100 + k), "--overwrite", "--set", f"scene.layout_seed={100 + k}", "--set", "output.formats=[ply]",
                "--set", "output.preview=false", "--set", "output.boxes.formats=[]"]
        for s in sets:
            args += ["--set", s]
        subprocess.run(args, check=True, stdout=subprocess.DEVNULL, cwd=ROOT)
    cost = {"frames": layouts * frames, "cpu_s": round(children_cpu() - before, 1), "wall_s": round(time.perf_counter() - start, 1)}
    (out / "cost.json").write_text(json.dumps({"key": key, "cost": cost}))
    return cost


def scans_of(folder: Path, frames: int | None = None) -> list[labelled.LabelledScan]:
    """The generated frames below ``folder`` (the first ``frames`` of each layout, or all), in layout then frame order."""
    return [s for d in sorted(folder.glob("layout*")) for s in labelled.load_scans([d], CLASSES, max_frames=frames)]


def summary(block: dict) -> dict:
    """IoU and interval per class of a score block."""
    return {c: {"iou": block["classes"][c]["iou"], "interval": block["classes"][c]["interval"]} for c in CLASSES}


def trained_on(train: list, test: list, seed: int) -> tuple[dict, list]:
    """The score block of a model trained on ``train`` over ``test``, and its predictions."""
    model = fit(train, CLASSES, seed)
    predictions = [model.predict(s) for s in test]
    return score(test, predictions, CLASSES, seed), predictions


def chart(result: dict, path: Path) -> None:
    """Real IoU (car, person) against generation CPU seconds: each level of detail, the frames curve, and real only."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(CLASSES), figsize=(6 * len(CLASSES), 4.5))
    for ax, c in zip(axes, CLASSES):
        for name, row in result["synthetic"].items():
            lo, hi = row[c]["interval"]
            ax.errorbar(row["cost"]["cpu_s"], row[c]["iou"], yerr=[[row[c]["iou"] - lo], [hi - row[c]["iou"]]], fmt="o", capsize=3)
            ax.annotate(name, (row["cost"]["cpu_s"], row[c]["iou"]), fontsize=7, xytext=(4, 4), textcoords="offset points")
        curve = result.get("synthetic_curve", [])
        if curve:
            ax.plot([r["cpu_s"] for r in curve], [r[c]["iou"] for r in curve], "k--", lw=1, label="default, fewer frames")
        for key, style in (("real_only", "g-"),):
            if key in result:
                ax.axhline(result[key][c]["iou"], color=style[0], ls=style[1:], label=f"{key.replace('_', ' ')} {result[key][c]['iou']:.2f}")
        ax.set_xlabel("generation CPU seconds")
        ax.set_ylabel(f"real {c} IoU (95 % interval)")
        ax.set_ylim(0, 1)
        ax.legend(fontsize=7)
    fig.suptitle("Trained on generated street scans, tested on real HDL-64E scans")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--small", action="store_true", help="2 layouts x 2 frames and one ablation: that it runs")
    parser.add_argument("--layouts", type=int, default=8)
    parser.add_argument("--frames", type=int, default=20, help="frames per layout")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    parser.add_argument("--work", type=Path, default=None, help="keep the generated data here (default: a temporary folder)")
    parser.add_argument("--ablation", default=",".join(ABLATION), help=f"levels of detail to train on, comma-separated (default: all of {', '.join(ABLATION)})")
    parser.add_argument("--reuse", action="store_true", help="read back generated data that --work already holds for the same settings")
    parser.add_argument("--name", default="sim2real", help="results file name (NAME.json, NAME.png)")
    args = parser.parse_args()
    if not (REAL / TEST_FRAMES[0]).is_file():
        print(f"SKIP: the real scans are not at {REAL} (set BPY_PIPELINE_REAL_SCANS)")
        return
    layouts, frames = (2, 2) if args.small else (args.layouts, args.frames)
    wanted = ["default"] if args.small else [k.strip() for k in args.ablation.split(",") if k.strip()]
    unknown = [k for k in wanted if k not in ABLATION]
    if unknown or "default" not in wanted:
        parser.error(f"--ablation: 'default' and names of {', '.join(ABLATION)}; got {args.ablation!r}")
    ablation = {k: ABLATION[k] for k in wanted}
    work = args.work or Path(tempfile.mkdtemp(prefix="sim2real_"))
    seed = 0
    test = labelled.load_scans([REAL / f for f in TEST_FRAMES], CLASSES)  # 000700 as shared now is in its sensor's frame
    result = {"classes": list(CLASSES), "test": [s.name for s in test], "load_average_at_start": os.getloadavg()[0], "layouts": layouts,
              "frames_per_layout": frames}

    # real only: leave one group out over the real frames themselves
    predictions, folds = leave_one_group_out(test, test, CLASSES, seed, "lgbm", 20000, 1)
    real_predictions = predictions
    result["real_only"] = {**summary(score(test, predictions, CLASSES, seed)), "folds": folds}
    print("real only", result["real_only"], flush=True)

    # synthetic only, at each level of detail
    result["synthetic"] = {}
    for name, sets in ablation.items():
        folder = work / "".join(ch if ch.isalnum() else "_" for ch in name)
        cost = generate(folder, layouts, frames, sets, args.reuse)
        per_layout = {}
        for scan in scans_of(folder):  # kept per layout, so the curve below reuses their features
            per_layout.setdefault(scan.group, []).append(scan)
        train = [s for group in sorted(per_layout) for s in per_layout[group]]
        block, predictions = trained_on(train, test, seed)
        if name == "default":
            default_predictions = predictions
        result["synthetic"][name] = {**summary(block), "cost": cost, "sets": sets,
                                     "false_positives": {c: block["classes"][c].get("false_positives") for c in CLASSES}}
        print(name, result["synthetic"][name], flush=True)
        if name == "default":  # IoU against the number of frames: the first k of each layout
            curve = []
            for k in sorted({max(1, frames // 4), max(1, frames // 2)}):
                subset = [s for group in sorted(per_layout) for s in per_layout[group][:k]]
                b, _ = trained_on(subset, test, seed)
                curve.append({"frames": len(subset), "cpu_s": round(cost["cpu_s"] * len(subset) / cost["frames"], 1), **summary(b)})
            curve.append({"frames": len(train), "cpu_s": cost["cpu_s"], **summary(block)})
            result["synthetic_curve"] = curve

    # mixed domain: real backgrounds from the other groups, synthetic objects cast in
    from sim2real_mixed import make_mixed_dataset

    backgrounds = [REAL / f for f in TEST_FRAMES]
    mixed_predictions = [None] * len(test)
    mixed_folds = []
    for group in sorted({s.group for s in test}):
        usable = [b for b, s in zip([REAL / f for f in TEST_FRAMES], test) if s.group != group and b in backgrounds]
        if not any(b.suffix == ".npy" for b in usable):  # a KITTI object frame's points outside its boxes are unlabelled
            mixed_folds.append({"test_group": group, "skipped": "no background with per-point labels outside the test group "
                                f"({', '.join(b.name for b in usable) or 'none'}: a KITTI object frame labels its boxes only)"})
            continue
        fold_work = work / f"mixed_{len(mixed_folds)}"
        before = children_cpu() + resource.getrusage(resource.RUSAGE_SELF).ru_utime
        dataset = make_mixed_dataset(usable, fold_work / "data", 1 if args.small else max(1, layouts * frames // (2 * len(usable))), seed, fold_work / "work")
        cost = children_cpu() + resource.getrusage(resource.RUSAGE_SELF).ru_utime - before
        model = fit(labelled.load_scans([dataset], CLASSES), CLASSES, seed)
        for i, s in enumerate(test):
            if s.group == group:
                mixed_predictions[i] = model.predict(s)
        mixed_folds.append({"test_group": group, "backgrounds": [b.name for b in usable], "cpu_s": round(cost, 1)})
    tested = [i for i, p in enumerate(mixed_predictions) if p is not None]
    if tested:
        subset = [test[i] for i in tested]
        block = score(subset, [mixed_predictions[i] for i in tested], CLASSES, seed)
        same = {"synthetic": summary(score(subset, [default_predictions[i] for i in tested], CLASSES, seed)),
                "real_only": summary(score(subset, [real_predictions[i] for i in tested], CLASSES, seed))}
        result["mixed"] = {**summary(block), "folds": mixed_folds, "tested": [s.name for s in subset], "same_frames": same}
        print("mixed", result["mixed"], flush=True)

    real = result["real_only"]
    result["ratio_synthetic_to_real"] = {c: (result["synthetic"]["default"][c]["iou"] / real[c]["iou"]) if real[c]["iou"] else math.nan for c in CLASSES}
    result["load_average_at_end"] = os.getloadavg()[0]
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / (f"{args.name}_small.json" if args.small else f"{args.name}.json")
    path.write_text(json.dumps(result, indent=2, default=float) + "\n")
    if not args.small:
        chart(result, args.out / f"{args.name}.png")
    print(f"wrote {path}")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
