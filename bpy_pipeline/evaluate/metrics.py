"""Per-class IoU over test scans, with bootstrap intervals over objects, per-object recall and what the false positives are.

IoU of class c = TP / (TP + FP + FN), counted over the points of all test scans together, points labelled
-1 left out. Its interval resamples *units* rather than points (points of one object are not independent):

- each ground-truth object of class c is a unit holding its TP and FN points;
- each connected region (points linked within 0.5 m) of points predicted c outside class c's ground truth is a
  unit holding its FP points.

A class is scored only on the test scans that label it (``LabelledScan.known``: a KITTI frame's boxes label car,
person and bicyclist, not road). ``miou`` is the mean IoU over the requested classes that some test scan holds
(a class no test scan holds is left out, even when predicted: its IoU would be 0 whatever the model).

Units are drawn with replacement (``draws`` times, one explicit Generator) and the 2.5 and 97.5 percentiles
of the resampled IoU are the 95 % interval. With a handful of objects the interval is wide, as it should be.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .label_maps import TRAINING_NAMES, other_index
from .labelled import LabelledScan, components

DRAWS = 1000
FOUND_RECALL = 0.5  # an object counts as found when at least half its points are predicted its class


def confusion(scans: Sequence[LabelledScan], predictions: Sequence[np.ndarray], n_labels: int) -> np.ndarray:
    """``(n_labels, n_labels)`` int64 point counts, rows truth, columns prediction, over all scans (-1 ignored)."""
    out = np.zeros((n_labels, n_labels), np.int64)
    for scan, pred in zip(scans, predictions):
        keep = scan.labels >= 0
        out += np.bincount(scan.labels[keep] * n_labels + pred[keep], minlength=n_labels * n_labels).reshape(n_labels, n_labels)
    return out


def iou(tp: float, fp: float, fn: float) -> float:
    """TP / (TP + FP + FN); NaN when the class is neither present nor predicted."""
    total = tp + fp + fn
    return float(tp / total) if total else float("nan")


def units(scan: LabelledScan, pred: np.ndarray, c: int) -> np.ndarray:
    """``(u, 3)`` int64 ``[tp, fp, fn]`` of the units (module notes) of class ``c`` in one scan."""
    truth = scan.labels == c
    rows = []
    if truth.any():
        ids, inverse = np.unique(scan.instances[truth], return_inverse=True)
        hit = (pred[truth] == c).astype(np.int64)
        tp = np.bincount(inverse, hit, len(ids))
        size = np.bincount(inverse, minlength=len(ids))
        rows.append(np.column_stack([tp, np.zeros(len(ids)), size - tp]))
    false = (pred == c) & (scan.labels >= 0) & ~truth
    if false.any():
        fp = np.bincount(components(scan.points[false]))
        rows.append(np.column_stack([np.zeros(len(fp)), fp, np.zeros(len(fp))]))
    return np.concatenate(rows).astype(np.int64) if rows else np.zeros((0, 3), np.int64)


def bootstrap_interval(unit_counts: np.ndarray, rng: np.random.Generator, draws: int = DRAWS, level: float = 0.95) -> tuple[float, float]:
    """The ``level`` percentile interval of IoU over ``draws`` resamplings of ``(u, 3)`` ``[tp, fp, fn]`` units."""
    u = len(unit_counts)
    if u == 0:
        return float("nan"), float("nan")
    pick = rng.integers(0, u, size=(draws, u))
    sums = unit_counts[pick].sum(axis=1).astype(np.float64)  # (draws, 3)
    total = sums.sum(axis=1)
    values = np.where(total > 0, sums[:, 0] / np.where(total > 0, total, 1), np.nan)
    tail = (1 - level) / 2 * 100
    lo, hi = np.nanpercentile(values, [tail, 100 - tail]) if np.isfinite(values).any() else (np.nan, np.nan)
    return float(lo), float(hi)


def false_positive_truth(scans: Sequence[LabelledScan], predictions: Sequence[np.ndarray], c: int, top: int = 8) -> dict[str, int]:
    """What the points wrongly predicted class ``c`` really are, largest first: SemanticKITTI training class names where
    the scan knows them, else the evaluation label (a requested class, or ``other``: outside every box)."""
    counts: dict[str, int] = {}
    for scan, pred in zip(scans, predictions):
        false = (pred == c) & (scan.labels >= 0) & (scan.labels != c)
        if not false.any():
            continue
        if scan.truth is not None:
            names = np.array(list(TRAINING_NAMES) + ["other-structure/object"])
            truth = scan.truth[false]
            keys = names[np.where(truth == -2, len(TRAINING_NAMES), np.clip(truth, 0, len(TRAINING_NAMES) - 1))]
        else:
            names = np.array(list(scan.classes) + ["other"])
            keys = names[scan.labels[false]]
        for key, n in zip(*np.unique(keys, return_counts=True)):
            counts[str(key)] = counts.get(str(key), 0) + int(n)
    return dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))[:top])


def object_recalls(scans: Sequence[LabelledScan], predictions: Sequence[np.ndarray], c: int) -> list[dict]:
    """One row per ground-truth object of class ``c``: scan, points, recall, median range (m)."""
    rows = []
    for scan, pred in zip(scans, predictions):
        truth = np.flatnonzero(scan.labels == c)
        if not len(truth):
            continue
        ids, inverse = np.unique(scan.instances[truth], return_inverse=True)
        hit = np.bincount(inverse, pred[truth] == c, len(ids))
        size = np.bincount(inverse, minlength=len(ids))
        rng = np.linalg.norm(scan.points[truth], axis=1)
        for k in range(len(ids)):
            rows.append({"scan": scan.name, "points": int(size[k]), "recall": round(float(hit[k] / size[k]), 4),
                         "range_m": round(float(np.median(rng[inverse == k])), 2)})
    return rows


def score(scans: Sequence[LabelledScan], predictions: Sequence[np.ndarray], classes: Sequence[str], seed: int = 0, draws: int = DRAWS) -> dict:
    """The report of one trained model on the test scans (keys: ``classes``: per class IoU, interval, counts, objects,
    false positives; ``per_scan``; ``confusion``). ``seed`` seeds the bootstrap's Generator."""
    classes = tuple(classes)
    n_labels = other_index(classes) + 1
    matrix = confusion(scans, predictions, n_labels)
    rng = np.random.default_rng(seed)
    out = {"classes": {}, "per_scan": {}, "confusion": matrix.tolist(), "confusion_labels": [*classes, "other"]}
    for c, name in enumerate(classes):
        pairs = [(s, p) for s, p in zip(scans, predictions) if s.knows(name)]
        m = confusion([s for s, _ in pairs], [p for _, p in pairs], n_labels)
        tp = int(m[c, c])
        fp = int(m[:, c].sum() - tp)
        fn = int(m[c, :].sum() - tp)
        all_units = np.concatenate([units(s, p, c) for s, p in pairs] or [np.zeros((0, 3), np.int64)])
        objects = object_recalls([s for s, _ in pairs], [p for _, p in pairs], c)
        found = sum(o["recall"] >= FOUND_RECALL for o in objects)
        lo, hi = bootstrap_interval(all_units, rng, draws)
        out["classes"][name] = {
            "iou": iou(tp, fp, fn), "interval": [lo, hi], "tp": tp, "fp": fp, "fn": fn, "scans": len(pairs),
            "objects": len(objects), "objects_found": int(found), "false_positive_regions": int((all_units[:, 1] > 0).sum()),
            "false_positives": false_positive_truth([s for s, _ in pairs], [p for _, p in pairs], c), "object_recall": objects,
        }
    out["miou"] = mean_iou(out["classes"])
    for scan, pred in zip(scans, predictions):
        m = confusion([scan], [pred], n_labels)
        out["per_scan"][scan.name] = {name: iou(m[c, c], m[:, c].sum() - m[c, c], m[c, :].sum() - m[c, c]) if scan.knows(name) else float("nan")
                                      for c, name in enumerate(classes)}
    return out


def mean_iou(per_class: dict) -> float:
    """The mean ``iou`` of the classes of ``{class: {iou, tp, fn}}`` that the test scans hold (``tp + fn > 0``);
    NaN when there is none."""
    values = [r["iou"] for r in per_class.values() if r["tp"] + r["fn"] > 0 and np.isfinite(r["iou"])]
    return float(np.mean(values)) if values else float("nan")
