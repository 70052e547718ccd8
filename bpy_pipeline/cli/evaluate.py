"""``bpy-pipeline evaluate`` and ``bpy-pipeline realism``: generated data measured against real labelled scans.

``evaluate --train DATASET --test REAL [--reference REAL ...] --classes car,person --out report.json``: train the
reference segmentation model on generated datasets, test it on real labelled scans and print per-class IoU with
95 % intervals, beside the same model trained on real frames (leave one group out). ``realism``: per class, what
differs between a generated dataset and real scans of the same sensor (:mod:`bpy_pipeline.evaluate.realism`).
docs/evaluate.md.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import InputError
from .subcommand import Command


def run_evaluate(args) -> int:
    """Train on ``--train``, test on ``--test`` (and the real reference), print the table, write the JSON report."""
    from ..evaluate import evaluate, table
    from ..evaluate.run import write_report

    out = Path(args.out)
    if out.is_dir() or (out.parent.exists() and not out.parent.is_dir()):
        raise InputError(f"--out: {out} must be a file path in a folder")
    from ..io.confined import refuse_output_over_input

    refuse_output_over_input(out, [*args.train, *args.test, *(args.reference or [])])
    if args.every < 1 or (args.max_frames is not None and args.max_frames < 1) or args.jobs < 1:
        raise InputError("evaluate: --every, --max-frames and --jobs must be >= 1")
    report = evaluate(args.train, args.test, args.classes, args.reference, args.model, args.seed, args.every, args.max_frames,
                      args.max_points_per_scan, args.jobs, log=lambda m: print(m, file=sys.stderr), steps=args.steps)
    write_report(out, report)
    print(table(report))
    print(f"written: {out}")
    return 0


def evaluate_arguments(p) -> None:
    from ..evaluate.models import MAX_POINTS_PER_SCAN, MODELS

    p.add_argument("--train", action="append", required=True, metavar="DATASET", help="generated dataset folder (ply/) or labelled scans (repeatable)")
    p.add_argument("--test", action="append", required=True, metavar="REAL",
                   help="real labelled scan: SemanticKITTI .bin (+ .label), X_points.npy (+ X_labels.npy), "
                   "KITTI object .bin (+ label_2, calib), or a folder of them (repeatable)")
    p.add_argument("--reference", action="append", metavar="REAL", help="real labelled scans to train the reference on, leave one group out (repeatable)")
    p.add_argument("--classes", default="car,person", help="evaluation classes, SemanticKITTI training names, comma separated (default car,person)")
    p.add_argument("--out", required=True, metavar="REPORT.json", help="JSON report to write")
    p.add_argument("--model", default="lgbm", choices=list(MODELS), help="reference model (default lgbm)")
    p.add_argument("--seed", type=int, default=0, help="model, sampling and bootstrap seed (default 0)")
    p.add_argument("--every", type=int, default=1, help="use every N-th frame of the generated datasets (default 1)")
    p.add_argument("--max-frames", type=int, default=None, help="at most this many frames of each generated dataset")
    p.add_argument("--max-points-per-scan", type=int, default=MAX_POINTS_PER_SCAN,
                   help=f"background points sampled from each training scan (default {MAX_POINTS_PER_SCAN})")
    p.add_argument("--jobs", type=int, default=1, help="model threads (default 1)")
    p.add_argument("--steps", type=int, default=None, help="the networks' training steps, for --train's model and every --reference fold alike "
                   "(default: 12 passes over the --train frames in batches of 4, at least 120)")
    p.set_defaults(func=run_evaluate)


def realism_arguments(p) -> None:
    from ..evaluate.realism import add_realism_arguments, realism_main

    add_realism_arguments(p).set_defaults(func=realism_main)


EVALUATE = Command("evaluate", "train a reference model on generated data, report IoU on real labelled scans",
                   "Train the reference per-point segmentation model on generated datasets, test it on real labelled scans "
                   "and report per-class IoU with 95 %% intervals (bootstrap over objects); with --reference, the same model trained "
                   "on real frames, leave one group out, on the same test scans (docs/evaluate.md).", evaluate_arguments)
REALISM = Command("realism", "compare a generated dataset with real labelled scans of the same sensor, per class",
                  "Per class: intensity (Wasserstein distance, share saturated), points per object against range, returns per "
                  "row, range distribution; BEV occupancy JSD and MMD as the generative-LiDAR papers compute them. Prints what differs "
                  "most and writes a JSON report and a PNG (docs/evaluate.md).", realism_arguments)
