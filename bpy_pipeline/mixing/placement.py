"""Where objects go in a real scan: explicit boxes, the parking paper's rule and the KITTI paper's rule.

A placement is a yawed box in the scan's sensor frame (:class:`Placement`); the object's mesh is
scaled into it later (:mod:`.objects`). Tests use the real returns only: non-ground returns in
a :class:`~.ground.PointIndex` for collisions, the ground plane for the height an object stands
on, and the firings for visibility (how many firings towards a box already return nearer).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry.objects import body_size, draw_body
from ..geometry.placement import insert_sequentially, sample, sample_count, turn_about
from .firings import Firings, angles_deg
from .ground import Ground, PointIndex, in_box
from .objects import type_class, type_size
from .section import KittiRule, ObjectBox, ParkingRule


@dataclass
class Placement:
    """One object to insert: ``type`` (car, person, robot_arm or a mesh file), its class, box centre (3,),
    size (3,) length, width, height (m), yaw (radians), how it was placed (``explicit``, ``parking``, ``kitti``) and,
    for a car, the body drawn with its size (an index of ``CAR_BODY_SETS[scene.car_bodies]``; -1: drawn when meshed)."""

    type: str
    class_name: str
    centre: np.ndarray
    size: np.ndarray
    yaw: float
    rule: str = "explicit"
    body: int = -1

    def info(self) -> dict:
        return {"type": self.type, "class": self.class_name, "center": [round(float(v), 4) for v in self.centre],
                "size": [round(float(v), 4) for v in self.size], "yaw_deg": round(math.degrees(self.yaw), 3), "rule": self.rule}


def nominal_size(kind: str) -> np.ndarray:
    """``(3,)`` m: the object type's nominal size (a mesh file's own bounding box)."""
    return type_size(kind)


def explicit_placements(objects: list[ObjectBox]) -> list[Placement]:
    out = []
    for o in objects:
        size = np.asarray(o.size, float)
        if not (size > 0).all():
            size = nominal_size(o.type)
        cls = o.class_name or type_class(o.type)
        out.append(Placement(o.type, cls, np.asarray(o.center, float), size, math.radians(o.yaw_deg)))
    return out


def ray_box_entry(origin: np.ndarray, direction: np.ndarray, centre, size, yaw: float) -> np.ndarray:
    """``(f,)`` distance along each ray to where it enters the yawed box, ``inf`` where it misses (slab test)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    o = (origin - np.asarray(centre, float)) @ rotation
    d = direction @ rotation
    half = np.asarray(size, float) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - o) / d, (half - o) / d
    near = np.nanmax(np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2)), axis=1)
    far = np.nanmin(np.where(np.isnan(t2), np.inf, np.maximum(t1, t2)), axis=1)
    return np.where((far >= np.maximum(near, 0.0)), np.maximum(near, 0.0), np.inf)


def hidden_fraction(firings: Firings, centre, size, yaw: float, sector: np.ndarray | None = None) -> tuple[float, int]:
    """``(share of the firings towards the box that return nearer than it, how many go towards it)``."""
    rows = np.arange(len(firings)) if sector is None else sector
    entry = ray_box_entry(firings.origin[rows], firings.direction[rows], centre, size, yaw)
    towards = np.isfinite(entry)
    n = int(towards.sum())
    if n == 0:
        return 1.0, 0
    hidden = firings.valid[rows][towards] & (firings.range[rows][towards] < entry[towards])
    return float(hidden.mean()), n


def boxes_overlap(a: Placement, b: Placement, clearance: float = 0.0) -> bool:
    """Whether two yawed boxes overlap in plan (separating axes) and in height."""
    if abs(a.centre[2] - b.centre[2]) > (a.size[2] + b.size[2]) / 2:
        return False
    axes = []
    corners = []
    for p in (a, b):
        c, s = math.cos(p.yaw), math.sin(p.yaw)
        ax = np.array([[c, s], [-s, c]])
        axes.extend(ax)
        h = p.size[:2] / 2 + clearance / 2
        corners.append(p.centre[:2] + np.array([[i * h[0], j * h[1]] for i in (-1, 1) for j in (-1, 1)]) @ ax)
    for axis in axes:
        pa, pb = corners[0] @ axis, corners[1] @ axis
        if pa.max() < pb.min() or pb.max() < pa.min():
            return False
    return True


@dataclass
class Scene:
    """What the rules test against: the firings, the ground, the non-ground index and the placements so far."""

    firings: Firings
    ground: Ground
    obstacles: PointIndex
    ground_points: PointIndex
    placed: list
    car_bodies: str = "classic"  # scene.car_bodies: a rule's car takes a drawn body's size (all) or the classic draw

    def sector(self, centre, size) -> np.ndarray:
        """Firings whose azimuth lies within the box's angular half-width (plus a margin) of its centre."""
        az, _ = angles_deg(self.firings.direction)
        centre_az = math.degrees(math.atan2(centre[1], centre[0]))
        half = math.degrees(math.atan2(np.linalg.norm(np.asarray(size[:2])) / 2 + 0.5, max(np.hypot(centre[0], centre[1]), 0.5)))
        return np.flatnonzero(np.abs((az - centre_az + 180.0) % 360.0 - 180.0) <= half + 1.0)


def fits(scene: Scene, p: Placement, rule: ParkingRule) -> bool:
    """The parking paper's checks (see :class:`~.section.ParkingRule`)."""
    grown = p.size * (1.0 + rule.box_margin)
    if len(scene.obstacles.in_box(p.centre, grown, math.degrees(p.yaw))) > rule.max_real_points:
        return False
    footprint = (p.centre[0], p.centre[1], p.centre[2] - p.size[2] / 2)
    if len(scene.ground_points.in_box(footprint, (grown[0], grown[1], 0.6), math.degrees(p.yaw))) < rule.min_ground_points:
        return False
    if any(boxes_overlap(p, q, 0.3) for q in scene.placed):
        return False
    hidden, towards = hidden_fraction(scene.firings, p.centre, p.size, p.yaw, scene.sector(p.centre, p.size))
    return towards > 0 and hidden <= rule.max_hidden_fraction


FULL_CIRCLE = ParkingRule().heading


def parking_rule(scene: Scene, rule: ParkingRule, rng: np.random.Generator) -> tuple[list[Placement], dict]:
    """Objects placed by the parking paper's rule (geometry/placement.py's retry loop); returns ``(placements, log)``."""
    kind = rule.type
    cls = type_class(kind)
    base = nominal_size(kind)
    near_rejections = [0]
    bodies = kind == "car" and scene.car_bodies != "classic"

    def new_object():
        body = draw_body(rng, scene.car_bodies) if bodies else -1
        height = float(sample(rule.height, rng)) if kind == "car" and not bodies else base[2]
        size = (body_size(body, scene.car_bodies) if bodies else base * (height / base[2])) * np.array([rng.uniform(0.97, 1.03), rng.uniform(0.97, 1.03), 1.0])
        distance = float(sample(rule.distance, rng))
        angle = float(rng.uniform(-math.pi, math.pi))
        if rule.heading == FULL_CIRCLE:  # the paper's random yaw (the same draws as before headings existed)
            yaw = float(rng.uniform(-math.pi, math.pi))
        else:
            yaw = angle + math.radians(float(sample(rule.heading, rng)))
        if distance < rule.near_rejection_distance and rng.random() < rule.near_rejection_probability:
            near_rejections[0] += 1
            return None  # the paper's near rejection: refused before placement (a failure of insert_sequentially)
        return size, distance * np.array([math.cos(angle), math.sin(angle)]), yaw, body

    def try_at(obj, angle_deg):
        size, xy, yaw, body = obj
        turned, turned_yaw = turn_about((0.0, 0.0), xy, yaw, angle_deg)
        z = float(scene.ground.height_at(turned)[0]) + size[2] / 2
        p = Placement(kind, cls, np.array([turned[0], turned[1], z]), size, turned_yaw, "parking", body)
        if fits(scene, p, rule):
            scene.placed.append(p)
            return p
        return None

    log = insert_sequentially(sample_count(rule.count, rng), new_object, try_at, rule.rotations, rule.rotation_step_deg, rule.max_consecutive_failures)
    return log.placed, {"objects_tried": log.objects_tried, "attempts": log.attempts, "stopped": log.stopped, "near_rejections": near_rejections[0]}


def kitti_yaw(lateral: float, rng: np.random.Generator) -> float:
    """The KITTI paper's equation (1): yaw (radians) from the lateral offset ``O_y`` (m)."""
    if abs(lateral) < 10.0:
        return float(rng.choice([0.0, math.pi]))
    if abs(lateral) < 30.0:
        pick = int(rng.integers(3))
        return (0.0, math.pi, float(rng.uniform(0.0, 2 * math.pi)))[pick]
    return float(rng.uniform(0.0, 2 * math.pi))


def kitti_rule(scene: Scene, rule: KittiRule, ground_xyz: np.ndarray, real_boxes: list[Placement], rng: np.random.Generator) -> tuple[list[Placement], dict]:
    """Objects placed by the KITTI paper's rule (see :class:`~.section.KittiRule`); returns ``(placements, log)``."""
    kind = rule.type
    cls = type_class(kind)
    size = nominal_size(kind)
    bodies = kind == "car" and scene.car_bodies != "classic"
    distance = np.hypot(ground_xyz[:, 0], ground_xyz[:, 1])
    near = ground_xyz[(distance <= rule.max_range) & (distance >= rule.min_range)]
    if not len(near):
        return [], {"candidates": 0}
    pick = rng.choice(len(near), min(rule.candidates, len(near)), replace=False)
    candidates = near[np.sort(pick)]
    # step 1: virtual-virtual: a random candidate removes the others within d
    kept = []
    alive = np.ones(len(candidates), bool)
    while alive.any():
        k = int(rng.choice(np.flatnonzero(alive)))
        kept.append(k)
        alive &= np.linalg.norm(candidates[:, :2] - candidates[k, :2], axis=1) >= rule.collision_distance
        alive[k] = False
    kept = candidates[kept]
    # step 2: virtual-non-ground within d / 2
    clear = ~np.isfinite(scene.obstacles.nearest_distance(kept, rule.collision_distance / 2))
    chosen = kept[clear][: rule.count]
    out = []
    for xyz in chosen:
        yaw = kitti_yaw(float(xyz[1]), rng)
        if rule.snap_distance > 0 and real_boxes:
            d = [np.linalg.norm(b.centre[:2] - xyz[:2]) for b in real_boxes]
            if min(d) <= rule.snap_distance:
                yaw = real_boxes[int(np.argmin(d))].yaw
        body = draw_body(rng, scene.car_bodies) if bodies else -1
        drawn = body_size(body, scene.car_bodies) if bodies else size.copy()
        z = float(scene.ground.height_at(xyz[:2])[0]) + drawn[2] / 2
        p = Placement(kind, cls, np.array([xyz[0], xyz[1], z]), drawn, yaw, "kitti", body)
        out.append(p)
        scene.placed.append(p)
    return out, {"candidates": int(len(candidates)), "after_virtual": int(len(kept)), "after_non_ground": int(clear.sum()), "placed": len(out)}


def real_placements(boxes: list[ObjectBox]) -> list[Placement]:
    """Labelled real objects given in the section, as placements (for occlusion updates and yaw snapping)."""
    return explicit_placements(boxes)


def returns_in(placements: list[Placement], xyz: np.ndarray) -> list[np.ndarray]:
    """Per placement, ``(n,)`` bool of the returns inside its box."""
    return [in_box(xyz, p.centre, p.size, math.degrees(p.yaw)) for p in placements]
