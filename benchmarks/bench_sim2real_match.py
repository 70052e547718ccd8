"""Does `bpy-pipeline match` help a model trained on mixed-domain data work on real scans?

The mixed domain of the sim-to-real benchmark (benchmarks/bench_sim2real.py, benchmarks/sim2real_mixed.py):
synthetic cars and people cast into real HDL-64E backgrounds, a per-point LightGBM classifier
trained on them and tested on real labelled frames of another group. Two ways to place the objects,
each fold with the same backgrounds, frames and seed:
- **papers**: the KITTI paper's rule for cars and the parking paper's rule for people (sim2real_mixed.py);
- **matched**: the rules `bpy-pipeline match` fits (objects per frame, distance and heading per class)
  to the fold's *training* real frames (the backgrounds themselves: nothing of the test group).
Car and person IoU on the tested frames with 95 % bootstrap intervals (`evaluate`'s scoring).

Run: python benchmarks/bench_sim2real_match.py [--small] [--frames N]   (N frames per background; --small: 1)
Results: benchmarks/results/sim2real_match.json
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
from pathlib import Path

from bench_sim2real import CLASSES, REAL, ROOT, TEST_FRAMES, summary
from sim2real_mixed import CAR_RULE, PERSON_RULE, make_mixed_dataset

from bpy_pipeline.evaluate import labelled
from bpy_pipeline.evaluate.metrics import score
from bpy_pipeline.evaluate.models import fit
from bpy_pipeline.cli.match import fit_real, matched_config


def matched_rules(backgrounds: list[Path]) -> tuple[dict, list[str]]:
    """The scene keys ``match`` writes for the ``real_scan`` builder from ``backgrounds``, the KITTI rule off; a class
    of :data:`CLASSES` the frames hold none of keeps the papers' rule (the frames say nothing about it)."""
    stats, _ = fit_real(backgrounds)
    config, notes = matched_config({"scene": {"builder": "real_scan"}}, stats)
    rules = [config["scene"]["parking_rule"], *config["scene"]["parking_rules"]]
    kitti = {"enabled": False}
    if not any(r["type"] == "car" for r in rules):
        kitti = dict(CAR_RULE)
        notes.append("car: none in the frames; the KITTI paper's rule")
    if not any(r["type"] == "person" for r in rules):
        rules.append(dict(PERSON_RULE))
        notes.append("person: none in the frames; the parking paper's rule")
    return {"kitti_rule": kitti, "parking_rule": rules[0], "parking_rules": rules[1:]}, notes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--small", action="store_true", help="one frame per background: that it runs")
    parser.add_argument("--frames", type=int, default=3, help="frames per background")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = parser.parse_args()
    if not (REAL / TEST_FRAMES[0]).is_file():
        print(f"SKIP: the real scans are not at {REAL} (set BPY_PIPELINE_REAL_SCANS)")
        return
    per_background = 1 if args.small else args.frames
    seed = 0
    test = labelled.load_scans([REAL / f for f in TEST_FRAMES], CLASSES)  # 000700 as shared now is in its sensor's frame
    paths = [REAL / f for f in TEST_FRAMES]
    work = Path(tempfile.mkdtemp(prefix="sim2real_match_"))
    predictions = {"papers": [None] * len(test), "matched": [None] * len(test)}
    folds = []
    try:
        for group in sorted({s.group for s in test}):
            usable = [b for b, s in zip(paths, test) if s.group != group]
            if not any(b.suffix == ".npy" for b in usable):
                folds.append({"test_group": group, "skipped": "no background with per-point labels outside the test group"})
                continue
            rules, notes = matched_rules(usable)
            fold = {"test_group": group, "backgrounds": [b.name for b in usable], "match_notes": notes}
            for name, given in (("papers", None), ("matched", rules)):
                folder = work / f"{group}_{name}"
                dataset = make_mixed_dataset(usable, folder / "data", per_background, seed, folder / "work", given)
                model = fit(labelled.load_scans([dataset], CLASSES), CLASSES, seed)
                for i, s in enumerate(test):
                    if s.group == group:
                        predictions[name][i] = model.predict(s)
                objects = [json.loads(r.read_text())["scene"]["objects"] for r in sorted((dataset / "records").glob("*.json"))]
                fold[name] = {c: sum(o["class"] == c for frame in objects for o in frame) / len(objects) for c in CLASSES}
            folds.append(fold)
            print(fold, flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    tested = [i for i, p in enumerate(predictions["papers"]) if p is not None]
    subset = [test[i] for i in tested]
    result = {"classes": list(CLASSES), "tested": [s.name for s in subset], "frames_per_background": per_background,
              "objects_per_frame": "per fold and placement: the mean count of each class a mixed frame holds",
              "folds": folds, "load_average": os.getloadavg()[0]}
    for name, got in predictions.items():
        result[name] = summary(score(subset, [got[i] for i in tested], CLASSES, seed))
        print(name, result[name], flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / ("sim2real_match_small.json" if args.small else "sim2real_match.json")
    path.write_text(json.dumps(result, indent=2, default=float) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
