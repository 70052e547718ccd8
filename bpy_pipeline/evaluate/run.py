"""``evaluate``: train the reference model on generated data, test it on real labelled scans, beside the same model trained on real frames.

The reference (``reference=``) is leave-one-group-out: for each group of test scans (a sequence, a KITTI
frame) the model is trained on the reference scans of every *other* group, so consecutive frames of one
sequence never sit on both sides. The report gives both IoUs per class with their intervals, and the ratio
synthetic / real.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..errors import InputError
from .features import FEATURE_NAMES
from .label_maps import parse_classes
from .labelled import IMAGE_SIZE, LabelledScan, load_scans
from .metrics import DRAWS, score
from .models import MAX_POINTS_PER_SCAN, fit

Source = str | Path | LabelledScan


def _names(scans: Sequence[LabelledScan]) -> list[str]:
    return [s.name for s in scans]


def leave_one_group_out(reference: Sequence[LabelledScan], test: Sequence[LabelledScan], classes: Sequence[str], seed: int, model: str,
                        max_points_per_scan: int, n_jobs: int, log=None) -> tuple[list[np.ndarray], list[dict]]:
    """Predictions for every test scan by a model trained on the reference scans of the other groups; and the folds
    (``{test_group, train: [names], seconds}``). ``InputError`` when a group leaves nothing to train on."""
    predictions: list[np.ndarray | None] = [None] * len(test)
    folds = []
    for group in sorted({s.group for s in test}):
        train = [s for s in reference if s.group != group]
        if not train:
            raise InputError(f"--reference: no reference scan outside group {group!r} to train on (leave-one-group-out needs two groups or more)")
        start = time.perf_counter()
        trained = fit(train, classes, seed, max_points_per_scan, model, n_jobs)
        for i, scan in enumerate(test):
            if scan.group == group:
                predictions[i] = trained.predict(scan)
        folds.append({"test_group": group, "train": _names(train), "seconds": round(time.perf_counter() - start, 2)})
        if log:
            log(f"reference fold {group}: trained on {len(train)} scans in {folds[-1]['seconds']} s")
    return predictions, folds


def evaluate(train: Iterable[Source], test: Iterable[Source], classes: str | Sequence[str] = ("car", "person"), reference: Iterable[Source] | None = None,
             model: str = "lgbm", seed: int = 0, every: int = 1, max_frames: int | None = None, max_points_per_scan: int = MAX_POINTS_PER_SCAN,
             n_jobs: int = 1, draws: int = DRAWS, image_size: tuple[int, int] = IMAGE_SIZE, log=None) -> dict:
    """Train ``model`` on ``train``, test on ``test``; with ``reference``, the same model trained on real frames
    (leave-one-group-out) on the same test scans. Returns the report (JSON-able; NaN where a class is absent).

    train, test, reference : paths (generated dataset folders, real labelled files or folders of them) or :class:`LabelledScan`
    classes : evaluation class names (SemanticKITTI's training names: ``car``, ``person``, ``road``, ...), a list or ``"car,person"``
    model : a :data:`~.models.MODELS` name (``lgbm``, ``forest``)
    seed : the model's seed, the background sampling's and the bootstrap's
    every, max_frames : subsample the frames of generated datasets
    max_points_per_scan : background points sampled from each training scan
    n_jobs : threads of the model
    draws : bootstrap resamplings of the intervals
    image_size : KITTI image width, height (px) bounding the labelled field of view
    log : ``print``-like progress callback, or ``None``
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"--seed: expected an integer >= 0, got {seed!r}")
    if isinstance(max_points_per_scan, bool) or not isinstance(max_points_per_scan, (int, np.integer)) or max_points_per_scan < 1:
        raise InputError(f"--max-points-per-scan: expected an integer >= 1, got {max_points_per_scan!r}")
    classes = parse_classes(classes)
    say = log or (lambda *_: None)
    train_scans = load_scans(list(train), classes, every, max_frames, image_size)
    if not train_scans:
        raise InputError("--train: the training set is empty (give a generated dataset folder or labelled scans)")
    test_scans = load_scans(list(test), classes, 1, None, image_size)
    if not test_scans:
        raise InputError("--test: no test scan given")
    reference_scans = load_scans(list(reference), classes, 1, None, image_size) if reference else []
    say(f"train: {len(train_scans)} scans, test: {len(test_scans)}, reference: {len(reference_scans)}; classes {', '.join(classes)}")
    start = time.perf_counter()
    trained = fit(train_scans, classes, seed, max_points_per_scan, model, n_jobs)
    fit_seconds = time.perf_counter() - start
    say(f"{model}: trained on {sum(trained.training_points)} points in {fit_seconds:.1f} s")
    synthetic = score(test_scans, [trained.predict(s) for s in test_scans], classes, seed, draws)
    synthetic["training_points"] = dict(zip([*classes, "other"], trained.training_points))
    for c, points in zip(classes, trained.training_points):
        if not points:  # the model never saw the class: its IoU of 0 would measure the training set, not the model
            synthetic["classes"][c].update(iou=float("nan"), interval=[float("nan"), float("nan")], measured=False)
            say(f"warning: {c}: no {c} point in --train; its IoU is not measured")
    synthetic["seconds"] = round(fit_seconds, 2)
    report = {
        "classes": list(classes), "model": model, "seed": seed, "features": list(FEATURE_NAMES),
        "train": _names(train_scans), "test": _names(test_scans), "reference": _names(reference_scans),
        "synthetic": synthetic, "real_reference": None, "ratio": None,
    }
    if reference_scans:
        predictions, folds = leave_one_group_out(reference_scans, test_scans, classes, seed, model, max_points_per_scan, n_jobs, say)
        real = score(test_scans, predictions, classes, seed, draws)
        real["folds"] = folds
        report["real_reference"] = real
        report["ratio"] = {c: _ratio(synthetic["classes"][c]["iou"], real["classes"][c]["iou"]) for c in classes}
    return report


def _ratio(a: float, b: float) -> float:
    return a / b if b and math.isfinite(a) and math.isfinite(b) else float("nan")


def table(report: dict) -> str:
    """The report as a text table: class, IoU [95 % interval] of the model trained on ``--train``, of the real reference, ratio."""

    def cell(block, c):
        if block is None:
            return "-"
        r = block["classes"][c]
        if r.get("measured") is False:
            return f"not measured (no {c} point in training)"
        lo, hi = r["interval"]
        return f"{_fmt(r['iou'])} [{_fmt(lo)}, {_fmt(hi)}]  {r['objects_found']}/{r['objects']} objects"

    rows = [("class", "trained on --train: IoU [95 %]", "real reference: IoU [95 %]", "ratio")]
    for c in report["classes"]:
        ratio = report["ratio"][c] if report["ratio"] else float("nan")
        rows.append((c, cell(report["synthetic"], c), cell(report["real_reference"], c), _fmt(ratio)))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    lines = ["  ".join(v.ljust(w) for v, w in zip(r, widths)).rstrip() for r in rows]
    for c in report["classes"]:
        fps = report["synthetic"]["classes"][c]["false_positives"]
        if fps:
            lines.append(f"points predicted {c} (trained on --train) are really: " + ", ".join(f"{k} {v:,}" for k, v in fps.items()))
    return "\n".join(lines)


def _fmt(x: float) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.3f}"


def json_safe(value):
    """The report with NaN as ``None`` (strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        return json_safe(value.item())
    return value
