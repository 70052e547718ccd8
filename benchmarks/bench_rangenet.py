"""Every class, every side: the range-image network (and LightGBM) trained on synthetic HDL-64E scans, on real ones, and on both.

The street (examples/street/ego_hdl64e.yaml) over 6 layouts x 12 frames is generated (72 frames), and models of
``bpy-pipeline evaluate`` are trained over every SemanticKITTI class that both the street and the real frames hold
(:data:`CLASSES`):

- ``lgbm``: per-point geometric features and LightGBM (no intensity, no drop);
- ``rangenet``: the range-image encoder-decoder (x y z range remission mask; bpy_pipeline/evaluate/rangenet.py);
- ``rangenet-geometry``: the same network with its remission channel zeroed.

Each is tested on the 15 real labelled HDL-64E frames of ../shared/real_scans (SemanticKITTI 000700, sequence 01
000000-2, sequence 08 000720, spvnas 000000; KITTI object 000001-5 and 004747, labelled by their boxes; four
SqueezeSeg frames of KITTI raw drive 0001, labelled from tracklets). Frames that label only car, person and
bicyclist (KITTI boxes, SqueezeSeg) count for those classes only. 000700 and sequence 01 carry no remission:
``rangenet`` (it reads remission) leaves them out of its training and test; the two other models use all 15.

Parts (``--parts``, default all; each merges its block into the results file, with the commit of the code
that made it, so a later run of one part reuses the others' blocks):

- ``synthetic``: the model trained on the synthetic frames alone;
- ``real``: the same model trained on the real frames, leaving groups out (a group: a SemanticKITTI sequence, a
  KITTI frame, the SqueezeSeg drive), the groups dealt into :data:`NETWORK_FOLDS` folds for the networks
  (``--network-folds 0``: one per group) and :data:`TREE_FOLDS` for LightGBM. The networks train every fold for as many steps as
  the synthetic model (12 passes over the 72 frames: 216 steps), whatever the fold's size;
- ``mixed``: for each fully labelled real frame that carries remission (:data:`MIXED_FRAMES`), the model trained
  on the synthetic frames plus that one frame (a quarter of the frames drawn: :data:`MIXED_SHARE`), for the same
  number of steps, tested on every real frame of another group, beside the real-only predictions of the ``real``
  part (trained on the groups outside the test frame's fold) and the synthetic-only ones on the same frames;
- ``realism``: ``bpy-pipeline realism`` (bpy_pipeline/evaluate/realism.py) on the same synthetic and real frames:
  saturated intensity, intensity Wasserstein distance, points per object against range, returns per row,
  range distribution, BEV JSD / MMD.

The ``real`` and ``synthetic`` parts keep their predictions in ``--work`` (``predictions/``), so ``--parts mixed``
alone scores against them. Per class: IoU with its 95 % interval (bootstrap over objects), mIoU, the ratio
synthetic / real and the targets (car and person >= 0.6 of real-trained, mIoU >= 0.5).

Results: benchmarks/results/rangenet.json (and rangenet_realism.png). One command on any checkout:

    python benchmarks/bench_rangenet.py                 # the full run (hours on 2 shared cores)
    python benchmarks/bench_rangenet.py --small         # 2 layouts x 2 frames, 2 real frames, 4 steps, one mixed frame: that it runs
    python benchmarks/bench_rangenet.py --models rangenet --parts synthetic --work /tmp/w   # one part, the rest reused
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
from bench_sim2real import generate  # noqa: E402

from bpy_pipeline.evaluate import labelled  # noqa: E402
from bpy_pipeline.evaluate.metrics import score  # noqa: E402
from bpy_pipeline.evaluate.models import NEEDS_TORCH, fit  # noqa: E402
from bpy_pipeline.evaluate.rangenet import default_steps  # noqa: E402
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
PARTS = ("synthetic", "real", "mixed", "realism")
# folds by group of the networks' real-only reference (--network-folds 0: one per group). 4 deals rangenet's 8 groups so that each
# fold pairs one of the four with many objects (004747, sequence 08, spvnas, the SqueezeSeg drive) with a one-object
# KITTI frame: each model trains on 6 of the 8 groups, at half the cost of one training per group.
NETWORK_FOLDS = 4
TREE_POINTS_PER_CLASS = 1000  # points of each label per training scan for LightGBM (15 classes x 72 frames)
TREE_FOLDS = 5
SMALL_STEPS = 4  # the networks' training steps with --small
# the one real frame added to the synthetic ones: the fully labelled frames that carry remission
MIXED_FRAMES = ("semantickitti_seq08_000720", "semantickitti_spvnas_000000")
MIXED_SHARE = 0.25  # the real frame's share of the training samples (one of every four frames drawn)
TARGETS = {"car": 0.6, "person": 0.6, "miou": 0.5}  # synthetic-only / real-trained


def code_commit() -> str:
    """The checkout's commit, with ``+changes`` when its tracked files differ from it (recorded per part)."""
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+changes" if dirty else "")


def summary(block: dict) -> dict:
    """Per class IoU, interval, objects found; and the mIoU of a score block."""
    out = {c: {"iou": r["iou"], "interval": r["interval"], "objects": r["objects"], "objects_found": r["objects_found"], "scans": r["scans"]}
           for c, r in block["classes"].items()}
    return {"classes": out, "miou": block["miou"]}


def mixed_training(synthetic: list, frame, share: float = MIXED_SHARE) -> list:
    """The synthetic scans and ``frame`` repeated so that it is ``share`` of the list (at least once): drawn
    uniformly from it, one training frame in ``1 / share`` is the real one."""
    copies = max(1, round(share / (1 - share) * len(synthetic)))
    return [*synthetic, *[frame] * copies]


def mixed_test(real: list, frame) -> list[int]:
    """Indices of the real scans the model trained with ``frame`` is tested on: every one of another group."""
    return [i for i, s in enumerate(real) if s.group != frame.group]


class Predictions:
    """Each part's predictions on the real test frames, kept in ``--work`` so that a later run of another part reads
    them: ``folder/<model>_<key>.npz`` (one ``(n,)`` int64 array per scan name) and ``.json`` (what made them)."""

    def __init__(self, folder: Path):
        self.folder = folder

    def save(self, model: str, key: str, scans: list, predictions: list, made: dict) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(self.folder / f"{model}_{key}.npz", **{s.name.replace("/", "__"): p for s, p in zip(scans, predictions)})
        (self.folder / f"{model}_{key}.json").write_text(json.dumps({**made, "scans": [s.name for s in scans]}))

    def load(self, model: str, key: str, scans: list, made: dict | None = None) -> tuple[list, dict] | None:
        """The kept predictions for ``scans`` (checked against their point counts and, with ``made``, made with
        those settings) and what made them; or ``None``."""
        path = self.folder / f"{model}_{key}.npz"
        if not path.is_file() or not path.with_suffix(".json").is_file():
            return None
        info = json.loads(path.with_suffix(".json").read_text())
        if made and any(info.get(k) != v for k, v in made.items()):
            return None
        kept = np.load(path)
        keys = [s.name.replace("/", "__") for s in scans]
        if any(k not in kept for k in keys) or any(len(kept[k]) != len(s) for k, s in zip(keys, scans)):
            return None
        return [kept[k] for k in keys], info


def part_synthetic(name: str, synthetic: list, test: list, steps: int | None, seed: int, threads: int, log) -> tuple[dict, list]:
    """The model trained on the synthetic frames alone, scored on the real test frames; and its predictions."""
    start = time.perf_counter()
    model = fit(synthetic, CLASSES, seed, TREE_POINTS_PER_CLASS, name, threads, log, steps)
    seconds = time.perf_counter() - start
    predictions = [model.predict(s) for s in test]
    block = score(test, predictions, CLASSES, seed)
    log(f"{name} synthetic-only: mIoU {block['miou']:.3f} ({seconds:.0f} s)")
    return {**summary(block), "train_frames": len(synthetic), "steps": steps, "threads": threads, "train_seconds": round(seconds, 1),
            "false_positives": {c: block["classes"][c]["false_positives"] for c in ("car", "person")}}, predictions


def part_real(name: str, test: list, steps: int | None, seed: int, threads: int, log, folds: int | None) -> tuple[dict, list]:
    """The same model trained on the real frames, leaving groups out, scored on the same test frames; and its predictions."""
    start = time.perf_counter()
    predictions, fold_rows = leave_one_group_out(test, test, CLASSES, seed, name, TREE_POINTS_PER_CLASS, threads, log, folds, steps)
    block = score(test, predictions, CLASSES, seed)
    log(f"{name} real-only: mIoU {block['miou']:.3f} ({time.perf_counter() - start:.0f} s)")
    folds = [{"test_group": f["test_group"], "train": f["train"], "seconds": f["seconds"]} for f in fold_rows]
    return {**summary(block), "steps": steps, "threads": threads, "folds": folds}, predictions


def part_mixed(name: str, synthetic: list, test: list, real_predictions: list | None, synthetic_predictions: list | None,
               steps: int | None, seed: int, threads: int, log, kept: Predictions, commit: str, frames=MIXED_FRAMES) -> dict:
    """For each of ``frames`` among ``test``: the model trained on the synthetic frames plus that one real
    frame (:func:`mixed_training`), scored on every real frame of another group, beside the real-only (leave group
    out) and the synthetic-only predictions on the same frames. Its predictions are kept in ``kept`` and reused
    when made with the same settings; without ``real_predictions`` it trains and keeps them, and scores nothing."""
    out = {"share": MIXED_SHARE, "steps": steps, "frames": {}}
    by_name = {s.name: s for s in test}
    for frame_name in frames:
        if frame_name not in by_name:
            continue
        frame = by_name[frame_name]
        train = mixed_training(synthetic, frame)
        made = {"steps": steps, "seed": seed, "train_frames": len(train), "copies": len(train) - len(synthetic), "synthetic_frames": len(synthetic)}
        found = kept.load(name, f"mixed_{frame_name}", test, made)
        if found is None:
            start = time.perf_counter()
            model = fit(train, CLASSES, seed, TREE_POINTS_PER_CLASS, name, threads, log, steps)
            seconds = round(time.perf_counter() - start, 1)
            predictions = [model.predict(s) for s in test]
            info = {**made, "train_seconds": seconds, "threads": threads, "commit": commit}
            kept.save(name, f"mixed_{frame_name}", test, predictions, info)
        else:
            predictions, info = found
            log(f"{name} synthetic + {frame_name}: its predictions kept in {kept.folder}")
        on = mixed_test(test, frame)
        scans = [test[i] for i in on]
        block = {"test": [s.name for s in scans], **{k: info[k] for k in ("copies", "train_seconds", "threads", "commit")}}
        out["frames"][frame_name] = block
        if real_predictions is None:
            log(f"{name} synthetic + {frame_name}: trained; no real-only predictions in {kept.folder} to score against (run --parts real)")
            continue
        mixed = score(scans, [predictions[i] for i in on], CLASSES, seed)
        real = score(scans, [real_predictions[i] for i in on], CLASSES, seed)
        block.update(mixed=summary(mixed), real_only=summary(real))
        if synthetic_predictions is not None:
            block["synthetic_only"] = summary(score(scans, [synthetic_predictions[i] for i in on], CLASSES, seed))
        block["beats"] = {c: bool(mixed["classes"][c]["iou"] > real["classes"][c]["iou"]) for c in CLASSES
                          if math.isfinite(mixed["classes"][c]["iou"]) and math.isfinite(real["classes"][c]["iou"])}
        block["beats"]["miou"] = bool(mixed["miou"] > real["miou"])
        log(f"{name} synthetic + {frame_name}: mIoU {mixed['miou']:.3f} against real-only {real['miou']:.3f} on the same {len(scans)} frames")
    return out


def with_ratios(entry: dict) -> dict:
    """``entry`` with the ratio synthetic / real and the targets, when both parts are in it."""
    if "synthetic_only" in entry and "real_only" in entry:
        ratio = ratios(entry["synthetic_only"], entry["real_only"])
        entry["ratio"] = ratio
        entry["targets"] = {k: {"target": v, "ratio": ratio[k], "met": bool(math.isfinite(ratio[k]) and ratio[k] >= v)} for k, v in TARGETS.items()}
    return entry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--small", action="store_true", help="2 layouts x 2 frames, 2 real frames, short training: that it runs")
    parser.add_argument("--layouts", type=int, default=6)
    parser.add_argument("--frames", type=int, default=12, help="frames per layout")
    parser.add_argument("--models", default=",".join(MODELS), help=f"comma-separated, of {', '.join(MODELS)}")
    parser.add_argument("--parts", default=",".join(PARTS), help=f"comma-separated, of {', '.join(PARTS)} (default all)")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    parser.add_argument("--work", type=Path, default=None,
                        help="keep the generated frames and the predictions here and reuse them (default: a temporary folder)")
    parser.add_argument("--threads", type=int, default=1,
                        help="threads of each model (default 1: on a loaded machine 2 threads a model train slower)")
    parser.add_argument("--network-folds", type=int, default=NETWORK_FOLDS,
                        help=f"folds by group of the networks' real reference (default {NETWORK_FOLDS}; 0: one per group)")
    parser.add_argument("--name", default="rangenet", help="results file name (NAME.json, NAME_realism.png)")
    args = parser.parse_args()
    if not (REAL / REAL_FRAMES[0]).is_file():
        print(f"SKIP: the real scans are not at {REAL} (set BPY_PIPELINE_REAL_SCANS)")
        return
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    asked = {p.strip() for p in args.parts.split(",") if p.strip()}
    parts = [p for p in PARTS if p in asked]
    if set(models) - set(MODELS) or not asked or asked - set(PARTS):
        parser.error(f"--models: of {', '.join(MODELS)}; --parts: of {', '.join(PARTS)}")
    if any(m in NEEDS_TORCH for m in models):
        try:
            import torch  # noqa: F401
        except ImportError:
            print("torch is not installed (pip install 'bpy_pipeline[network]'): the network models are left out")
            models = [m for m in models if m not in NEEDS_TORCH]
    layouts, frames = (2, 2) if args.small else (args.layouts, args.frames)
    seed = 0
    work = args.work or Path(tempfile.mkdtemp(prefix="rangenet_"))
    commit = code_commit()
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
                   "settings": {"tree_points_per_class": TREE_POINTS_PER_CLASS, "tree_folds": TREE_FOLDS,
                                "mixed_frames": list(MIXED_FRAMES), "mixed_share": MIXED_SHARE}})

    def write() -> None:
        args.out.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(json_safe(result), indent=1) + "\n")

    kept = Predictions(work / "predictions")
    if set(parts) & {"synthetic", "real", "mixed"}:
        synthetic_all = [s for d in sorted((work / "street").glob("layout*")) for s in labelled.load_scans([d], CLASSES)]
        real_all = labelled.load_scans(real_files, CLASSES)
        result.setdefault("models", {})
        for name in models:
            test, left_out = with_remission(real_all, name)
            synthetic, _ = with_remission(synthetic_all, name)
            steps = (SMALL_STEPS if args.small else default_steps(len(synthetic))) if name in NEEDS_TORCH else None  # every side alike
            entry = result["models"].setdefault(name, {})
            entry.update({"test": [s.name for s in test], "left_out": left_out})
            synthetic_predictions = real_predictions = None
            if "synthetic" in parts:
                block, synthetic_predictions = part_synthetic(name, synthetic, test, steps, seed, args.threads, log)
                entry["synthetic_only"] = {**block, "commit": commit}
                kept.save(name, "synthetic", test, synthetic_predictions, {"steps": steps, "seed": seed, "commit": commit})
                write()
            if "real" in parts:
                folds = (args.network_folds or None) if name in NEEDS_TORCH else TREE_FOLDS
                block, real_predictions = part_real(name, test, steps, seed, args.threads, log, folds)
                entry["real_only"] = {**block, "commit": commit}
                kept.save(name, "real", test, real_predictions, {"steps": steps, "seed": seed, "folds": folds, "commit": commit})
                write()
            with_ratios(entry)
            if "mixed" in parts:
                same = {"steps": steps, "seed": seed}
                real_predictions = real_predictions or (kept.load(name, "real", test, same) or [None])[0]
                synthetic_predictions = synthetic_predictions or (kept.load(name, "synthetic", test, same) or [None])[0]
                entry["mixed"] = part_mixed(name, synthetic, test, real_predictions, synthetic_predictions, steps, seed, args.threads, log, kept,
                                            commit, MIXED_FRAMES[:1] if args.small else MIXED_FRAMES)
            write()  # each model as soon as it is done
    if "realism" in parts:
        from bpy_pipeline.evaluate.realism import realism_report, summary_lines

        realism = realism_report([work / "street" / d.name for d in sorted((work / "street").glob("layout*"))], real_files,
                                 plot=args.out / f"{args.name}_realism.png" if not args.small else None)
        result["realism"] = {**realism, "commit": commit}
        for line in summary_lines(realism):
            log(line)
    result["load_average_at_end"] = os.getloadavg()[0]
    result["seconds"] = round(time.perf_counter() - start, 1)
    write()
    print(f"wrote {path}")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)


def json_safe(value):
    from bpy_pipeline.evaluate.run import json_safe as safe

    return safe(value)


if __name__ == "__main__":
    main()
