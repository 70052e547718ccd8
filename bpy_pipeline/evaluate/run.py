"""``evaluate``: train the reference model on generated data, test it on real labelled scans, beside the same model trained on real frames.

The reference (``reference=``) is leave-one-group-out: for each group of test scans (a sequence, a KITTI
frame) the model is trained on the reference scans of every *other* group, so consecutive frames of one
sequence never sit on both sides. When no test scan shares a group with a reference scan, the reference trains
once, on all of them. The report gives both IoUs per class with their intervals, the mean IoU, and the ratios
synthetic / real.

The networks (``rangenet``, ``rangenet-geometry``) train every reference fold for as many steps as the model
trained on ``train`` (``steps``, by default :func:`~.rangenet.default_steps` of the training frames): the real
reference gets the same optimisation budget as the model it is compared with, however few its frames.

A model that reads remission (``rangenet``) is trained and tested on the scans that carry it only; the others
are listed in the report's ``left_out`` (SemanticKITTI 000700 and sequence 01 as shared have none).
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
from .models import MAX_POINTS_PER_SCAN, MODELS, NEEDS_TORCH, READS_REMISSION, fit
from .projection import CHANNELS

Source = str | Path | LabelledScan


def _names(scans: Sequence[LabelledScan]) -> list[str]:
    return [s.name for s in scans]


def fold_groups(groups: Sequence[str], max_folds: int | None = None) -> list[list[str]]:
    """The test groups of each fold: one group a fold, or with ``max_folds`` the sorted groups dealt round-robin into
    that many folds (a few folds by group, where one training per group is too slow)."""
    groups = sorted(set(groups))
    if not max_folds or max_folds >= len(groups):
        return [[g] for g in groups]
    return [groups[k::max_folds] for k in range(max_folds)]


def leave_one_group_out(reference: Sequence[LabelledScan], test: Sequence[LabelledScan], classes: Sequence[str], seed: int, model: str,
                        max_points_per_scan: int, n_jobs: int, log=None, max_folds: int | None = None,
                        steps: int | None = None) -> tuple[list[np.ndarray], list[dict]]:
    """Predictions for every test scan by a model trained on the reference scans of the other groups (of the other
    folds' groups with ``max_folds``); and the folds (``{test_group, train: [names], seconds, steps}``; ``test_group``
    names a fold's groups, comma-separated); ``steps``: each fold's training steps (the networks'). When no test
    scan shares a group with a reference scan, one model trained on all the reference scans predicts every test scan.
    ``InputError`` when a group leaves nothing to train on."""
    predictions: list[np.ndarray | None] = [None] * len(test)
    folds = []
    disjoint = not {s.group for s in test} & {s.group for s in reference}
    for groups in [[]] if disjoint else fold_groups([s.group for s in test], max_folds):
        train = [s for s in reference if s.group not in groups]
        if not train:
            raise InputError(f"--reference: no reference scan outside group {', '.join(groups)} to train on (leave-one-group-out needs two groups or more)")
        start = time.perf_counter()
        trained = fit(train, classes, seed, max_points_per_scan, model, n_jobs, log, steps)
        for i, scan in enumerate(test):
            if disjoint or scan.group in groups:
                predictions[i] = trained.predict(scan)
        folds.append({"test_group": ", ".join(groups) or "all (no test group among the reference groups)", "train": _names(train),
                      "seconds": round(time.perf_counter() - start, 2), "steps": getattr(trained, "steps", None)})
        if log:
            log(f"reference fold {', '.join(groups) or 'all'}: trained on {len(train)} scans in {folds[-1]['seconds']} s")
    return predictions, folds


def with_remission(scans: Sequence[LabelledScan], model: str) -> tuple[list[LabelledScan], list[str]]:
    """The scans ``model`` can read (all, or those with remission when it reads remission) and the names of the others."""
    if model not in READS_REMISSION:
        return list(scans), []
    return [s for s in scans if s.remission is not None], [s.name for s in scans if s.remission is None]


def evaluate(train: Iterable[Source], test: Iterable[Source], classes: str | Sequence[str] = ("car", "person"), reference: Iterable[Source] | None = None,
             model: str = "lgbm", seed: int = 0, every: int = 1, max_frames: int | None = None, max_points_per_scan: int = MAX_POINTS_PER_SCAN,
             n_jobs: int = 1, draws: int = DRAWS, image_size: tuple[int, int] = IMAGE_SIZE, log=None, max_folds: int | None = None,
             steps: int | None = None) -> dict:
    """Train ``model`` on ``train``, test on ``test``; with ``reference``, the same model trained on real frames
    (leave-one-group-out) on the same test scans. Returns the report (JSON-able; NaN where a class is absent).

    train, test, reference : paths (generated dataset folders, real labelled files or folders of them) or :class:`LabelledScan`
    classes : evaluation class names (SemanticKITTI's training names: ``car``, ``person``, ``road``, ...), a list or ``"car,person"``
    model : a :data:`~.models.MODELS` name (``lgbm``, ``forest``, ``rangenet``, ``rangenet-geometry``)
    seed : the model's seed, the background sampling's and the bootstrap's
    every, max_frames : subsample the frames of generated datasets
    max_points_per_scan : points of each label sampled from each training scan (the trees)
    n_jobs : threads of the model
    draws : bootstrap resamplings of the intervals
    image_size : KITTI image width, height (px) bounding the labelled field of view
    log : ``print``-like progress callback, or ``None``
    max_folds : at most this many leave-group-out folds for the reference (groups dealt round-robin), ``None``: one per group
    steps : the networks' training steps, for the model on ``train`` and every reference fold alike (``None``: the
        default for the ``train`` frames, :func:`~.rangenet.default_steps`); not for the trees
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"--seed: expected an integer >= 0, got {seed!r}")
    if isinstance(max_points_per_scan, bool) or not isinstance(max_points_per_scan, (int, np.integer)) or max_points_per_scan < 1:
        raise InputError(f"--max-points-per-scan: expected an integer >= 1, got {max_points_per_scan!r}")
    classes = parse_classes(classes)
    if model not in MODELS:
        raise InputError(f"--model: unknown model {model!r}; allowed: {', '.join(MODELS)}")
    if steps is not None and (model not in NEEDS_TORCH or isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1):
        raise InputError(f"--steps: an integer >= 1 for the networks ({', '.join(sorted(NEEDS_TORCH))}); got {steps!r} with --model {model}")
    if model in NEEDS_TORCH:
        from .rangenet import torch_module

        torch_module()
    say = log or (lambda *_: None)
    train_scans, left_train = with_remission(load_scans(list(train), classes, every, max_frames, image_size), model)
    if not train_scans:
        raise InputError(
            "--train: the training set is empty (give a generated dataset folder or labelled scans"
            + (", with remission, for --model rangenet)" if left_train else ")")
        )
    test_scans, left_test = with_remission(load_scans(list(test), classes, 1, None, image_size), model)
    if not test_scans:
        raise InputError("--test: no test scan given" + (f" with remission ({model} reads it; use rangenet-geometry for these)" if left_test else ""))
    reference_scans, left_reference = with_remission(load_scans(list(reference), classes, 1, None, image_size) if reference else [], model)
    left_out = sorted(set(left_train + left_test + left_reference))
    if left_out:
        say(f"{model} reads remission: left out {len(left_out)} scans without it ({', '.join(left_out)})")
    say(f"train: {len(train_scans)} scans, test: {len(test_scans)}, reference: {len(reference_scans)}; classes {', '.join(classes)}")
    if model in NEEDS_TORCH and steps is None:
        from .rangenet import default_steps

        steps = default_steps(len(train_scans))
    start = time.perf_counter()
    trained = fit(train_scans, classes, seed, max_points_per_scan, model, n_jobs, say, steps)
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
        "classes": list(classes), "model": model, "seed": seed, "features": list(CHANNELS if model in NEEDS_TORCH else FEATURE_NAMES),
        "train": _names(train_scans), "test": _names(test_scans), "reference": _names(reference_scans),
        "synthetic": synthetic, "real_reference": None, "ratio": None, "left_out": left_out, "steps": steps,
    }
    if reference_scans:
        predictions, folds = leave_one_group_out(reference_scans, test_scans, classes, seed, model, max_points_per_scan, n_jobs, say, max_folds, steps)
        real = score(test_scans, predictions, classes, seed, draws)
        real["folds"] = folds
        report["real_reference"] = real
        report["ratio"] = ratios(synthetic, real)
    return report


def ratios(synthetic: dict, real: dict) -> dict:
    """Synthetic IoU / real-reference IoU per class of two score blocks, and of their mean IoUs (``miou``)."""
    out = {c: _ratio(synthetic["classes"][c]["iou"], real["classes"][c]["iou"]) for c in synthetic["classes"]}
    out["miou"] = _ratio(synthetic["miou"], real["miou"])
    return out


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
    rows.append(("mIoU", _fmt(report["synthetic"]["miou"]), _fmt(report["real_reference"]["miou"]) if report["real_reference"] else "-",
                 _fmt(report["ratio"]["miou"]) if report["ratio"] else "n/a"))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    lines = ["  ".join(v.ljust(w) for v, w in zip(r, widths)).rstrip() for r in rows]
    for c in report["classes"]:
        fps = report["synthetic"]["classes"][c]["false_positives"]
        if fps:
            lines.append(f"points predicted {c} (trained on --train) are really: " + ", ".join(f"{k} {v:,}" for k, v in fps.items()))
    return "\n".join(lines)


def _fmt(x: float) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.3f}"


def write_report(out: Path, report: dict) -> None:
    """``report`` as strict JSON at ``out`` (written whole or not at all); ``InputError`` naming ``--out`` when it cannot be written."""
    import json

    from ..io.atomic import atomic_write

    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(out) as tmp:
            tmp.write_text(json.dumps(json_safe(report), indent=1) + "\n")
    except OSError as err:
        raise InputError(f"--out: cannot write {out} ({err.strerror or err})") from None


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
