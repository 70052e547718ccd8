"""``bpy-pipeline match REAL... --config base.yaml --out matched.yaml``: object statistics fitted to
the user's labelled real scans, written as the builder's placement distributions.

What no simulator we know of does: the parking paper (Annotation-free Generation of Training Data
Using Mixed Domains for Segmentation of 3D LiDAR Point Clouds) tuned its distance histogram by
hand. Here the labelled objects of real frames (SemanticKITTI frames with per-point labels:
objects are the connected components of a class's points; KITTI object frames: the points in each
``label_2`` box; the readers of :mod:`.evaluate.labelled`) give, per class:

* the **count** of objects per frame (objects with at least ``min_points`` points: what a sensor
  sees, as a labelled scan holds it);
* the **distance** of each object from the sensor in the ground plane (its points' centroid), m;
* the **heading**: the object's long axis (the principal axis of its points in plan) minus its
  bearing from the sensor, folded to -90..90 degrees (a point cloud does not tell front from back);
* the **points per object against distance**: a power law ``n = a d^-b`` fitted in log-log, and
  the median points per distance bin, for charts (the sensor decides it; placement cannot).

:func:`matched_config` writes the first three as ``histogram`` distributions
(:class:`~.geometry.placement.Distribution`) into the base config's builder:

* ``real_scan``: one parking rule per class (``scene.parking_rule`` and ``scene.parking_rules``)
  with ``count``, ``distance`` and ``heading``; the paper's near rejection is switched off (the
  fitted histogram already holds the real near objects);
* ``parking``: cars only, ``scene.cars`` and ``scene.car_distance`` (the garage's yaw follows its bays).

Every other key of the base config stays as it was. Pure: numpy, no bpy.
"""

from __future__ import annotations

import copy
import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Sequence

import numpy as np
import yaml

from ..errors import InputError
from ..yaml_text import load_yaml
from .subcommand import Command

CLASSES = ("car", "person", "bicyclist")  # SemanticKITTI training names that KITTI boxes label too
OBJECT_TYPE = {"car": "car", "person": "person", "bicyclist": "cyclist"}  # class -> insertable object type
DISTANCE_EDGES = tuple(float(v) for v in np.arange(0.0, 80.1, 5.0))  # m
HEADING_EDGES = tuple(float(v) for v in np.arange(-90.0, 90.1, 30.0))  # deg
MATCH_BUILDERS = ("real_scan", "parking")


@dataclass
class RealObject:
    """One labelled real object: class, frame name, centroid (3,) m in the sensor frame, distance (m, plan),
    heading (deg, long axis minus bearing, -90..90), points."""

    class_name: str
    frame: str
    centre: np.ndarray
    distance: float
    heading: float
    points: int


@dataclass
class ClassStats:
    """Per class: ``counts`` (frames,) objects per frame, ``distances``, ``headings`` (deg), ``points`` (objects,)."""

    counts: np.ndarray
    distances: np.ndarray
    headings: np.ndarray
    points: np.ndarray
    curve: dict = field(default_factory=dict)  # points per object against distance: power law and binned medians


def heading_of(xy: np.ndarray, centre_xy: np.ndarray) -> float:
    """Long axis of ``(n, 2)`` plan points minus the bearing of ``centre_xy``, degrees folded to -90..90 (0 for fewer than 3 points)."""
    if len(xy) < 3:
        return 0.0
    d = xy - xy.mean(axis=0)
    cov = d.T @ d / len(d)
    values, vectors = np.linalg.eigh(cov)
    axis = vectors[:, int(np.argmax(values))]
    relative = math.degrees(math.atan2(axis[1], axis[0]) - math.atan2(centre_xy[1], centre_xy[0]))
    return float((relative + 90.0) % 180.0 - 90.0)


def real_objects(scans, classes: Sequence[str], min_points: int = 10) -> tuple[list[RealObject], list[str]]:
    """The objects (at least ``min_points`` points) of :class:`~.evaluate.labelled.LabelledScan` ``scans``, and the frame names."""
    out = []
    for scan in scans:
        for oid in np.unique(scan.instances[scan.instances >= 0]):
            mask = scan.instances == oid
            if mask.sum() < min_points:
                continue
            label = int(np.bincount(scan.labels[mask].clip(0)).argmax())
            if label >= len(classes):
                continue
            xyz = scan.points[mask].astype(np.float64)
            centre = xyz.mean(axis=0)
            out.append(RealObject(classes[label], scan.name, centre, float(np.hypot(centre[0], centre[1])), heading_of(xyz[:, :2], centre[:2]),
                                  int(mask.sum())))
    return out, [s.name for s in scans]


def points_curve(distances: np.ndarray, points: np.ndarray, edges: Sequence[float] = DISTANCE_EDGES) -> dict:
    """Points per object against distance: ``n = a d^-b`` fitted in log-log (least squares) and the median per distance bin."""
    edges = np.asarray(edges, float)
    medians = [float(np.median(points[(distances >= lo) & (distances < hi)])) if ((distances >= lo) & (distances < hi)).any() else None
               for lo, hi in zip(edges[:-1], edges[1:])]
    ok = (distances > 0) & (points > 0)
    if ok.sum() >= 2 and np.ptp(np.log(distances[ok])) > 0:
        slope, intercept = np.polyfit(np.log(distances[ok]), np.log(points[ok]), 1)
        law = {"a": float(math.exp(intercept)), "b": float(-slope)}
    else:
        law = None
    return {"power_law": law, "edges_m": [float(v) for v in edges], "median_points": medians}


def class_stats(objects: list[RealObject], frames: list[str], classes: Sequence[str]) -> dict[str, ClassStats]:
    """Per class with at least one object: counts per frame (every frame counts, with 0 objects too), distances, headings, points."""
    out = {}
    for c in classes:
        mine = [o for o in objects if o.class_name == c]
        if not mine:
            continue
        counts = np.array([sum(o.frame == f for o in mine) for f in frames], np.int64)
        d = np.array([o.distance for o in mine])
        n = np.array([o.points for o in mine], float)
        out[c] = ClassStats(counts, d, np.array([o.heading for o in mine]), n.astype(np.int64), points_curve(d, n))
    return out


def histogram(values: np.ndarray, edges: Sequence[float]) -> dict:
    """A ``histogram`` Distribution's mapping over ``edges`` (values outside them land in the end bins)."""
    edges = np.asarray(edges, float)
    clipped = np.clip(values, edges[0], np.nextafter(edges[-1], -np.inf))
    weights, _ = np.histogram(clipped, edges)
    return {"kind": "histogram", "edges": [float(v) for v in edges], "weights": [int(v) for v in weights]}


def count_histogram(counts: np.ndarray) -> dict:
    """Objects per frame as a ``histogram`` Distribution over the integers 0 .. max (edges k .. k + 1 hold the count k)."""
    top = int(counts.max())
    return {"kind": "histogram", "edges": [float(k) for k in range(top + 2)], "weights": [int(v) for v in np.bincount(counts, minlength=top + 1)]}


def distance_edges(distances: np.ndarray, step: float = 5.0) -> list[float]:
    """5 m bins from 0 to the farthest object's bin."""
    top = max(step, math.ceil(float(distances.max()) / step + 1e-9) * step)
    return [float(v) for v in np.arange(0.0, top + step / 2, step)]


def matched_config(base: dict, stats: dict[str, ClassStats]) -> tuple[dict, list[str]]:
    """``base`` (a config mapping) with its builder's placement distributions fitted to ``stats``; and notes
    (one line each: what was written, what was left out)."""
    from ..geometry.objects import OBJECT_TYPES
    from ..mixing.section import ParkingRule

    out = copy.deepcopy(base)
    scene = out.setdefault("scene", {})
    builder = scene.get("builder")
    if builder not in MATCH_BUILDERS:
        raise InputError(
            f"--config: scene.builder is {builder!r}; match writes the placement distributions of {', '.join(MATCH_BUILDERS)} (the real_scan builder's parking "
            "rules, the parking builder's cars)"
        )
    notes = []
    if builder == "parking":
        if "car" not in stats:
            raise InputError("match: the real scans hold no car with enough points; the parking builder places cars only")
        s = stats["car"]
        scene["cars"] = count_histogram(s.counts)
        scene["car_distance"] = histogram(s.distances, distance_edges(s.distances))
        notes.append(f"car: scene.cars and scene.car_distance from {len(s.distances)} objects in {len(s.counts)} frames (the garage's bays set the yaw)")
        notes += [f"{c}: left out (the parking builder places cars only)" for c in stats if c != "car"]
        return out, notes
    rules = []
    has_near = "near_rejection_probability" in {f.name for f in fields(ParkingRule)}
    for c, s in stats.items():
        kind = OBJECT_TYPE.get(c)
        if kind not in OBJECT_TYPES:
            notes.append(f"{c}: left out ({kind!r} is no insertable object type here)")
            continue
        old = scene.get("parking_rule") if not rules else None
        rule = dict(old) if isinstance(old, dict) and old.get("type", "car") == kind else {}
        rule.update({"enabled": True, "type": kind, "count": count_histogram(s.counts),
                     "distance": histogram(s.distances, distance_edges(s.distances)), "heading": histogram(s.headings, HEADING_EDGES)})
        if has_near:
            rule["near_rejection_probability"] = 0.0  # the fitted histogram holds the real near objects already
        rules.append(rule)
        notes.append(f"{c}: count, distance and heading from {len(s.distances)} objects in {len(s.counts)} frames (mean {s.counts.mean():.2f} per frame)")
    if not rules:
        raise InputError("match: the real scans hold no object of an insertable class (car, person, cyclist) with enough points")
    scene["parking_rule"], scene["parking_rules"] = rules[0], rules[1:]
    return out, notes


def fit_real(sources: Sequence[str | Path], classes: Sequence[str] = CLASSES, min_points: int = 10) -> tuple[dict[str, ClassStats], list[str]]:
    """Read labelled real frames and return ``(per-class statistics, frame names)``."""
    from ..evaluate.labelled import load_scans

    scans = load_scans(sources, tuple(classes))
    if not scans:
        raise InputError("match: no labelled frame among the REAL sources")
    objects, frames = real_objects(scans, tuple(classes), min_points)
    return class_stats(objects, frames, tuple(classes)), frames


def stats_report(stats: dict[str, ClassStats], frames: list[str]) -> dict:
    """A JSON-ready summary of the statistics."""
    return {"frames": frames, "classes": {c: {
        "objects": int(len(s.distances)), "count_per_frame": [int(v) for v in s.counts], "mean_per_frame": float(s.counts.mean()),
        "distance": histogram(s.distances, DISTANCE_EDGES), "heading": histogram(s.headings, HEADING_EDGES),
        "points_per_object": s.curve} for c, s in stats.items()}}


def match(sources: Sequence[str | Path], config_path: str | Path, out: str | Path, classes: Sequence[str] = CLASSES, min_points: int = 10) -> dict:
    """``bpy-pipeline match``: fit ``sources``, write the matched config to ``out`` (atomically, checked by
    :func:`~.config.load_config` first) and return ``{"notes", "report"}``."""
    from ..config import load_config, read_config_file
    from ..io.atomic import atomic_write

    try:  # the guard every command reads a config through: size, depth, values with aliases expanded
        base = read_config_file(config_path)
    except InputError as err:
        raise InputError(f"--config: {err}") from None
    stats, frames = fit_real(sources, classes, min_points)
    config, notes = matched_config(base, stats)
    out = Path(out)
    text = f"# matched to {len(frames)} labelled real frame(s) by bpy-pipeline match\n"
    text += yaml.safe_dump(config, sort_keys=False, width=120, default_flow_style=None)
    load_config(load_yaml(text), [])  # refuse before writing anything a run would refuse
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(out) as tmp:
            tmp.write_text(text)
    except OSError as err:
        raise InputError(f"--out: cannot write {out} ({err.strerror or err})") from None
    return {"notes": notes, "report": stats_report(stats, frames)}


def add_match_arguments(p):
    """The arguments of ``bpy-pipeline match``."""
    p.add_argument("real", nargs="+", metavar="REAL", help="labelled real frames: SemanticKITTI .bin (+ .label), X_points.npy (+ X_labels.npy), "
                   "KITTI object .bin (+ label_2, calib), or a folder of them")
    p.add_argument("--config", required=True, metavar="BASE.yaml",
                   help=f"the config to match (scene.builder: {' or '.join(MATCH_BUILDERS)}); its other keys are kept")
    p.add_argument("--out", required=True, metavar="MATCHED.yaml", help="the matched config to write")
    p.add_argument("--classes", default=",".join(CLASSES), help=f"classes to fit, SemanticKITTI training names (default {','.join(CLASSES)})")
    p.add_argument("--min-points", type=int, default=10, help="objects with fewer points are not counted (default 10)")
    p.add_argument("--report", metavar="STATS.json", help="also write the fitted statistics (counts, histograms, points per object against distance)")
    return p


def match_main(args) -> int:
    """``bpy-pipeline match``: fit, write, print what was written."""
    import json

    from ..evaluate.label_maps import parse_classes
    from ..io.atomic import atomic_write
    from ..io.confined import refuse_output_over_input

    if args.min_points < 1:
        raise InputError(f"--min-points: must be >= 1, got {args.min_points}")
    if args.report and os.path.realpath(args.report) == os.path.realpath(args.out):
        raise InputError(f"--report: {args.report} is the --out file too; give the statistics a file of their own")
    refuse_output_over_input(args.out, [*args.real, args.config])
    if args.report:
        refuse_output_over_input(args.report, [*args.real, args.config], "--report")
    classes = parse_classes(args.classes)
    result = match(args.real, args.config, args.out, classes, args.min_points)
    for line in result["notes"]:
        print(line)
    for c, s in result["report"]["classes"].items():
        law = s["points_per_object"]["power_law"]
        print(f"{c}: points per object ~ {law['a']:.0f} d^-{law['b']:.2f}" if law else f"{c}: too few objects for a points-per-object curve")
    if args.report:
        try:
            with atomic_write(args.report) as tmp:
                tmp.write_text(json.dumps(result["report"], indent=1) + "\n")
        except OSError as err:
            raise InputError(f"--report: cannot write {args.report} ({err.strerror or err})") from None
    print(f"written: {args.out}")
    return 0


def arguments(p) -> None:
    add_match_arguments(p).set_defaults(func=match_main)


COMMAND = Command("match", "fit object counts, distances and headings to labelled real scans; write them into a config",
                  "Fit per-class object counts, distance and heading histograms (and the points-per-object curve) to "
                  "labelled real frames and write them as the builder's placement distributions (docs/match.md).", arguments)
