"""What a network that reads remission and drop gains or loses from each effect: the ablation, judged by the range-image network.

The street (examples/street/ego_hdl64e.yaml) is generated over ``--layouts`` x ``--frames`` frames once per variant
(:data:`VARIANTS`: ``--set`` overrides of the default street: the effects off, the intensity without the unit's reading,
the lidar equation's intensity, no drop, the material models, glossy vehicles, light rain; and the street's levels of
detail: bare, no vegetation, no terrain, no fences, walls and furniture, 40 m arms). On each the range-image
network (``bpy-pipeline evaluate --model rangenet``: x y z range remission mask) is trained alone, with the same
seed and settings, and tested on the real HDL-64E frames of ../shared/real_scans that carry remission (the same 11 as
``bench_rangenet.py``): per class IoU with its 95 % interval (bootstrap over objects) and mIoU over the classes both
hold. Differences inside the intervals are not findings.

The variants share every layout and frame seed, so they differ only by their overrides. The default run is half the
size of ``bench_rangenet.py``'s (3 layouts x 12 frames against 6 x 12) to bound the cost on 2 cores: compare variants
with each other here, and the default with ``bench_rangenet.py``'s figure there.

    python benchmarks/bench_rangenet_ablation.py [--layouts 3] [--frames 12] [--variants "default,effects off (ideal scan)"] [--work DIR]
    python benchmarks/bench_rangenet_ablation.py --small     # 1 layout x 2 frames, 2 real frames, few steps: that it runs

Results: benchmarks/results/rangenet_ablation.json (``--name``; a run of some ``--variants`` adds them to the file's
others) and beside it the chart of real IoU against the generation's frames per second (``rangenet_ablation.png``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_rangenet import CLASSES, REAL, REAL_FRAMES, SMALL_FRAMES, SMALL_STEPS, TREE_POINTS_PER_CLASS, summary  # noqa: E402
from bench_sim2real import ABLATION, generate  # noqa: E402

from bpy_pipeline.evaluate import labelled  # noqa: E402
from bpy_pipeline.evaluate.metrics import score  # noqa: E402
from bpy_pipeline.evaluate.models import fit  # noqa: E402
from bpy_pipeline.evaluate.run import json_safe, with_remission  # noqa: E402

MODEL = "rangenet"
VARIANTS = {
    "default": [],
    "effects off (ideal scan)": ["effects.ideal=true"],
    "no drop": ["effects.drop.model=none"],
    "reflectance without the unit's reading": ["effects.intensity.reading.enabled=false"],
    "lidar-equation intensity": ["effects.intensity.model=lidar", "effects.intensity.reading.enabled=false"],
    "material models": ABLATION["material models"],
    "glossy vehicles": ABLATION["glossy vehicles"],
    "light rain (4 mm/h)": ["effects.weather.rain.rate=4"],
    # the street's levels of detail (bench_sim2real.py's): what each costs against what it is worth
    **{name: ABLATION[name] for name in ("bare (the street before)", "no vegetation", "no terrain", "no fences walls furniture", "40 m arms")},
}


def chart(result: dict, path: Path) -> None:
    """Real mIoU and car IoU (95 % intervals) against the generation's frames per second, one point a variant."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for ax, what in zip(axes, ("miou", "car")):
        for name, row in result["variants"].items():
            fps = row["generation"]["frames"] / max(row["generation"]["wall_s"], 1e-9)
            if what == "miou":
                iou, error = row["miou"], None
            else:
                iou, (lo, hi) = row["classes"]["car"]["iou"], row["classes"]["car"]["interval"]
                error = [[iou - lo], [hi - iou]]
            ax.errorbar(fps, iou, yerr=error, fmt="o", capsize=3)
            ax.annotate(name, (fps, iou), fontsize=7, xytext=(4, 4), textcoords="offset points")
        ax.set_xlabel("generated frames per second (PLY and labels, 2 cores)")
        ax.set_ylabel("real mIoU" if what == "miou" else "real car IoU (95 % interval)")
    fig.suptitle("The range-image network trained on each variant of the street, tested on real HDL-64E scans")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--small", action="store_true", help="1 layout x 2 frames, 2 variants, 2 real frames, few steps: that it runs")
    parser.add_argument("--layouts", type=int, default=3)
    parser.add_argument("--frames", type=int, default=12, help="frames per layout")
    parser.add_argument("--variants", default=",".join(VARIANTS), help=f"comma-separated, of: {'; '.join(VARIANTS)}")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    parser.add_argument("--work", type=Path, default=None, help="keep the generated frames here and reuse them (default: a temporary folder)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--name", default="rangenet_ablation")
    args = parser.parse_args()
    if not (REAL / REAL_FRAMES[0]).is_file():
        print(f"SKIP: the real scans are not at {REAL} (set BPY_PIPELINE_REAL_SCANS)")
        return
    try:
        import torch  # noqa: F401
    except ImportError:
        print("SKIP: torch is not installed (pip install 'bpy_pipeline[network]')")
        return
    names = [v.strip() for v in args.variants.split(",") if v.strip()]
    if args.small:
        names = names[:2]
    unknown = [v for v in names if v not in VARIANTS]
    if unknown:
        parser.error(f"--variants: unknown {', '.join(unknown)}; allowed: {'; '.join(VARIANTS)}")
    layouts, frames = (1, 2) if args.small else (args.layouts, args.frames)
    work = args.work or Path(tempfile.mkdtemp(prefix="rangenet_ablation_"))
    seed = 0
    start = time.perf_counter()
    real, _ = with_remission(labelled.load_scans([REAL / f for f in (SMALL_FRAMES if args.small else REAL_FRAMES)], CLASSES), MODEL)
    path = args.out / (f"{args.name}_small.json" if args.small else f"{args.name}.json")
    result = json.loads(path.read_text()) if path.is_file() else {}  # a run of some variants adds to the others'
    result.update({"model": MODEL, "classes": list(CLASSES), "layouts": layouts, "frames_per_layout": frames, "test": [s.name for s in real],
                   "load_average_at_start": os.getloadavg()[0]})
    result.setdefault("variants", {})
    for name in names:
        folder = work / "".join(ch if ch.isalnum() else "_" for ch in name)
        cost = generate(folder, layouts, frames, VARIANTS[name], reuse=True)
        train, _ = with_remission([s for d in sorted(folder.glob("layout*")) for s in labelled.load_scans([d], CLASSES)], MODEL)
        begun = time.perf_counter()
        model = fit(train, CLASSES, seed, TREE_POINTS_PER_CLASS, MODEL, args.threads, steps=SMALL_STEPS if args.small else None)
        block = score(real, [model.predict(s) for s in real], CLASSES, seed)
        result["variants"][name] = {**summary(block), "sets": VARIANTS[name], "generation": cost, "train_seconds": round(time.perf_counter() - begun, 1)}
        print(f"[{time.perf_counter() - start:6.0f} s] {name}: mIoU {block['miou']:.3f}, car {block['classes']['car']['iou']:.3f}, "
              f"person {block['classes']['person']['iou']:.3f}", flush=True)
        args.out.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(json_safe(result), indent=1) + "\n")  # each variant as soon as it is done
    if not args.small:
        chart(result, path.with_suffix(".png"))
    result["load_average_at_end"] = os.getloadavg()[0]
    result["seconds"] = round(time.perf_counter() - start, 1)
    path.write_text(json.dumps(json_safe(result), indent=1) + "\n")
    print(f"wrote {path}")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
