"""Every class, both models: trained on the street's synthetic HDL-64E scans alone, tested on the real ones.

Issue 50's measure. The street (examples/street/ego_hdl64e.yaml) over 6 layouts x 12 frames is generated
(72 frames), and two models of ``bpy-pipeline evaluate`` are trained on it over every SemanticKITTI class that
both the street and the real frames hold (:data:`CLASSES`):

- ``lgbm``: per-point geometric features and LightGBM (no intensity, no drop);
- ``rangenet``: the range-image encoder-decoder (x y z range remission mask; bpy_pipeline/evaluate/rangenet.py);
- ``rangenet-geometry``: the same network with its remission channel zeroed.

Each is tested on the 15 real labelled HDL-64E frames of ../shared/real_scans (SemanticKITTI 000700, sequence 01
000000-2, sequence 08 000720, spvnas 000000; KITTI object 000001-5 and 004747, labelled by their boxes; four
SqueezeSeg frames of KITTI raw drive 0001, labelled from tracklets). Frames that label only car, person and
bicyclist (KITTI boxes, SqueezeSeg) count for those classes only. 000700 and sequence 01 carry no remission:
``rangenet`` (it reads remission) leaves them out of its training and test; the two other models use all 15.
Beside each, the same model trained on the real frames, leaving groups out (a group: a SemanticKITTI sequence, a
KITTI frame, the SqueezeSeg drive; the 10 groups dealt into :data:`TREE_FOLDS` folds for LightGBM,
:data:`NETWORK_FOLDS` for the networks, to bound the cost on 2 shared cores).

Per class: IoU with its 95 % interval (bootstrap over objects), mIoU, the ratio synthetic / real and the
issue's targets (car and person >= 0.6 of real-trained, mIoU >= 0.5). The realism part
(``bpy-pipeline realism``, bpy_pipeline/evaluate/realism.py) compares the same synthetic frames with the real
ones per class: saturated intensity, intensity Wasserstein distance, points per object against range, returns
per row, range distribution, BEV JSD / MMD.

Results: benchmarks/results/rangenet.json (and rangenet_realism.png). One command on any checkout:

    python benchmarks/bench_rangenet.py                 # the full run (about an hour on 2 shared cores)
    python benchmarks/bench_rangenet.py --small         # 2 layouts x 2 frames, 2 real frames, few steps: that it runs
    python benchmarks/bench_rangenet.py --models lgbm --parts realism   # parts and models to run
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_sim2real import generate  # noqa: E402

from bpy_pipeline.evaluate import labelled  # noqa: E402
from bpy_pipeline.evaluate.metrics import score  # noqa: E402
from bpy_pipeline.evaluate.models import NEEDS_TORCH, fit  # noqa: E402
from bpy_pipeline.evaluate.run import leave_one_group_out, ratios, with_remission  # noqa: E402

CLASSES = ("car", "truck", "other-vehicle", "person", "bicyclist", "road", "sidewalk", "parking", "building", "fence",
           "vegetation", "trunk", "terrain", "pole", "traffic-sign")  # fmt: skip
REAL = Path(os.environ.get("BPY_PIPELINE_REAL_SCANS", ROOT.parent / "shared" / "real_scans"))
REAL_FRAMES = (
    "semantickitti_000700_points.npy", "semantickitti_seq01_000000_points.npy", "semantickitti_seq01_000001_points.npy",
    "semantickitti_seq01_000002_points.npy", "semantickitti_seq08_000720.bin", "semantickitti_spvnas_000000.bin",
    "kitti_hdl64e_000001.bin", "kitti_hdl64e_000002.bin", "kitti_hdl64e_000003.bin", "kitti_hdl64e_000005.bin", "kitti_hdl64e_004747.bin",
    "squeezeseg_2011_09_26_0001_0000000010_points.npy", "squeezeseg_2011_09_26_0001_0000000030_points.npy",
    "squeezeseg_2011_09_26_0001_0000000040_points.npy", "squeezeseg_2011_09_26_0001_0000000050_points.npy",
)  # fmt: skip
SMALL_FRAMES = ("semantickitti_seq08_000720.bin", "semantickitti_spvnas_000000.bin")
MODELS = ("lgbm", "rangenet", "rangenet-geometry")
NETWORK_FOLDS = 3  # folds by group of the real-only reference: the networks', LightGBM's (TREE_FOLDS)
TREE_POINTS_PER_CLASS = 1000  # points of each label per training scan for LightGBM (15 classes x 72 frames)
TREE_FOLDS = 5
TARGETS = {"car": 0.6, "person": 0.6, "miou": 0.5}  # synthetic-only / real-trained, issue 50


def rangenet_settings() -> dict:
    from bpy_pipeline.evaluate import rangenet

    return {"epochs": rangenet.EPOCHS, "min_steps": rangenet.MIN_STEPS}


def summary(block: dict) -> dict:
    """Per class IoU, interval, objects found; and the mIoU of a score block."""
    out = {c: {"iou": r["iou"], "interval": r["interval"], "objects": r["objects"], "objects_found": r["objects_found"], "scans": r["scans"]}
           for c, r in block["classes"].items()}
    return {"classes": out, "miou": block["miou"]}


def run_model(name: str, synthetic: list, real: list, seed: int, threads: int, log) -> dict:
    """Synthetic-only and real-only (leave one group out) of model ``name`` on the real frames it can read."""
    test, left_out = with_remission(real, name)
    train, _ = with_remission(synthetic, name)
    points = TREE_POINTS_PER_CLASS
    start = time.perf_counter()
    model = fit(train, CLASSES, seed, points, name, threads, log)
    synthetic_seconds = time.perf_counter() - start
    block = score(test, [model.predict(s) for s in test], CLASSES, seed)
    log(f"{name} synthetic-only: mIoU {block['miou']:.3f} ({synthetic_seconds:.0f} s)")
    start = time.perf_counter()
    folds = NETWORK_FOLDS if name in NEEDS_TORCH else TREE_FOLDS
    predictions, fold_rows = leave_one_group_out(test, test, CLASSES, seed, name, points, threads, log, folds)
    real_block = score(test, predictions, CLASSES, seed)
    log(f"{name} real-only: mIoU {real_block['miou']:.3f} ({time.perf_counter() - start:.0f} s)")
    ratio = ratios(block, real_block)
    return {
        "test": [s.name for s in test], "left_out": left_out, "synthetic_only": {**summary(block), "train_seconds": round(synthetic_seconds, 1),
        "false_positives": {c: block["classes"][c]["false_positives"] for c in ("car", "person")}},
        "real_only": {**summary(real_block), "folds": [{k: f[k] for k in ("test_group", "seconds")} for f in fold_rows]},
        "ratio": ratio, "targets": {k: {"target": v, "ratio": ratio[k], "met": bool(math.isfinite(ratio[k]) and ratio[k] >= v)} for k, v in TARGETS.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--small", action="store_true", help="2 layouts x 2 frames, 2 real frames, short training: that it runs")
    parser.add_argument("--layouts", type=int, default=6)
    parser.add_argument("--frames", type=int, default=12, help="frames per layout")
    parser.add_argument("--models", default=",".join(MODELS), help=f"comma-separated, of {', '.join(MODELS)}")
    parser.add_argument("--parts", default="training,realism", help="training, realism or both")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    parser.add_argument("--work", type=Path, default=None, help="keep the generated frames here and reuse them (default: a temporary folder)")
    parser.add_argument("--threads", type=int, default=2, help="threads of each model (default 2)")
    parser.add_argument("--name", default="rangenet", help="results file name (NAME.json, NAME_realism.png)")
    args = parser.parse_args()
    if not (REAL / REAL_FRAMES[0]).is_file():
        print(f"SKIP: the real scans are not at {REAL} (set BPY_PIPELINE_REAL_SCANS)")
        return
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    parts = {p.strip() for p in args.parts.split(",") if p.strip()}
    if set(models) - set(MODELS) or not parts or parts - {"training", "realism"}:
        parser.error(f"--models: of {', '.join(MODELS)}; --parts: training, realism")
    if any(m in NEEDS_TORCH for m in models):
        try:
            import torch  # noqa: F401
        except ImportError:
            print("torch is not installed (pip install 'bpy_pipeline[network]'): the network models are left out")
            models = [m for m in models if m not in NEEDS_TORCH]
    layouts, frames = (2, 2) if args.small else (args.layouts, args.frames)
    seed = 0
    work = args.work or Path(tempfile.mkdtemp(prefix="rangenet_"))
    start = time.perf_counter()

    def log(message: str) -> None:
        print(f"[{time.perf_counter() - start:6.0f} s] {message}", flush=True)

    cost = generate(work / "street", layouts, frames, [], reuse=True)
    log(f"generated {cost}")
    real_files = [REAL / f for f in (SMALL_FRAMES if args.small else REAL_FRAMES)]
    path = args.out / (f"{args.name}_small.json" if args.small else f"{args.name}.json")
    result = json.loads(path.read_text()) if path.is_file() else {}
    result.update({"classes": list(CLASSES), "layouts": layouts, "frames_per_layout": frames, "generation": cost, "real": [f.name for f in real_files],
                   "targets": TARGETS, "config": "examples/street/ego_hdl64e.yaml", "load_average_at_start": os.getloadavg()[0],
                   "settings": {"tree_points_per_class": TREE_POINTS_PER_CLASS, "tree_folds": TREE_FOLDS, "network_folds": NETWORK_FOLDS,
                                "network_epochs": rangenet_settings()["epochs"], "network_min_steps": rangenet_settings()["min_steps"],
                                "threads": args.threads}})
    if "training" in parts:
        if args.small:
            import bpy_pipeline.evaluate.rangenet as rangenet

            rangenet.MIN_STEPS, rangenet.EPOCHS = 4, 1
        synthetic = [s for d in sorted((work / "street").glob("layout*")) for s in labelled.load_scans([d], CLASSES)]
        real = labelled.load_scans(real_files, CLASSES)
        result.setdefault("models", {})
        for name in models:
            result["models"][name] = run_model(name, synthetic, real, seed, args.threads, log)
            args.out.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(json_safe(result), indent=1) + "\n")  # each model as soon as it is done
    if "realism" in parts:
        from bpy_pipeline.evaluate.realism import realism_report, summary_lines

        realism = realism_report([work / "street" / d.name for d in sorted((work / "street").glob("layout*"))], real_files,
                                 plot=args.out / f"{args.name}_realism.png" if not args.small else None)
        result["realism"] = realism
        for line in summary_lines(realism):
            log(line)
    result["load_average_at_end"] = os.getloadavg()[0]
    result["seconds"] = round(time.perf_counter() - start, 1)
    args.out.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(json_safe(result), indent=1) + "\n")
    print(f"wrote {path}")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)


def json_safe(value):
    from bpy_pipeline.evaluate.run import json_safe as safe

    return safe(value)


if __name__ == "__main__":
    main()
