"""Collision-free placement: random draws from configured distributions, the parking paper's insertion
rule, and upright boxes placed on a floor around a sensor without collisions or heavy occlusion. Pure numpy.

The insertion rule (Section 3.2.2 and 4.3 of the underground-parking paper, seed 000): the number of
objects per scan is drawn from N(5, 4) (clipped at zero here); each object gets a distance from the
sensor and a random rotation about the sensor's vertical axis; when it cannot be inserted it is
turned on by 10 degrees about that axis and tried again, 36 times in all (the whole circle); an
object that fits nowhere is replaced by a fresh one, and insertion stops after ``k_f = 10``
consecutive objects failed. :func:`insert_sequentially` is that loop; :class:`FloorBoxPlacer`
says whether one candidate box fits.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Callable, Literal

import numpy as np

from ..errors import InputError
from ..schema import meta
from .clearance import NO_POSES, SensorPoses
from .collision import box_axes, rectangle_inside, rectangles_near, rectangles_overlap


@dataclass(frozen=True)
class Distribution:
    """A random quantity: ``normal`` (``mean``, ``std``; truncated to ``[min, max]`` by redrawing, a
    count rounded and clipped instead), ``uniform`` on ``[min, max]`` or ``histogram`` (a bin drawn
    with probability proportional to ``weights``, then uniform within its ``edges``; a count: the
    draw's integer part, so ``edges`` k .. k + 1 hold the count k, as ``bpy-pipeline match`` writes them)."""

    kind: Literal["normal", "uniform", "histogram"] = "normal"
    mean: float = field(default=0.0, metadata=meta(help="normal: the mean, in the quantity's unit"))
    std: float = field(default=1.0, metadata=meta("", low=0, help="normal: the standard deviation"))
    min: float = field(default=0.0, metadata=meta(help="the lowest value drawn"))
    max: float = field(default=1.0, metadata=meta(help="the highest value drawn"))
    edges: list[float] = field(default_factory=list, metadata=meta(help="histogram: (b + 1,) increasing bin edges"))
    weights: list[float] = field(default_factory=list, metadata=meta(help="histogram: (b,) bin weights >= 0, not all 0"))


def check_distribution(d: Distribution, where: str, low: float | None = None, high: float | None = None) -> None:
    if d.kind == "histogram":
        edges, weights = np.asarray(d.edges, float), np.asarray(d.weights, float)
        if edges.ndim != 1 or len(edges) < 2 or not (np.diff(edges) > 0).all():
            raise InputError(f"{where}.edges: a histogram needs at least 2 increasing edges, got {list(d.edges)}")
        if weights.shape != (len(edges) - 1,) or (weights < 0).any() or weights.sum() <= 0:
            raise InputError(f"{where}.weights: a histogram needs {len(edges) - 1} weights >= 0 (one per bin), not all 0, got {list(d.weights)}")
        if low is not None and edges[0] < low:
            raise InputError(f"{where}.edges: must be >= {low}, got {edges[0]}")
        if high is not None and edges[-1] > high:
            raise InputError(f"{where}.edges: must be <= {high}, got {edges[-1]}")
        return
    if d.min > d.max:
        raise InputError(f"{where}.min: must not exceed max ({d.max}), got {d.min}")
    if low is not None and d.min < low:
        raise InputError(f"{where}.min: must be >= {low}, got {d.min}")
    if high is not None and d.max > high:
        raise InputError(f"{where}.max: must be <= {high}, got {d.max}")


# ----------------------------------------------------------------------------- distributions
def sample(distribution, rng: np.random.Generator, size: int | None = None):
    """Draw from a ``config.Distribution`` (``kind`` normal or uniform, ``mean``, ``std``, ``min``, ``max``).

    ``normal`` is truncated to ``[min, max]`` by redrawing the values that fall outside (100
    rounds, then clipping), ``uniform`` is uniform on ``[min, max]``. Returns a float, or an
    ``(size,)`` float64 array.
    """
    n = 1 if size is None else size
    lo, hi = distribution.min, distribution.max
    if distribution.kind == "histogram":
        values = _histogram_draw(distribution, rng, n)
    elif distribution.kind == "uniform" or distribution.std == 0:
        values = rng.uniform(lo, hi, n) if distribution.kind == "uniform" else np.full(n, float(np.clip(distribution.mean, lo, hi)))
    else:
        values = rng.normal(distribution.mean, distribution.std, n)
        for _ in range(100):
            bad = (values < lo) | (values > hi)
            if not bad.any():
                break
            values[bad] = rng.normal(distribution.mean, distribution.std, int(bad.sum()))
        values = np.clip(values, lo, hi)
    return float(values[0]) if size is None else values


def _histogram_draw(distribution, rng: np.random.Generator, n: int) -> np.ndarray:
    """``(n,)`` float64 draws of a ``histogram`` distribution: a bin by its weight, then uniform within it."""
    edges, weights = np.asarray(distribution.edges, float), np.asarray(distribution.weights, float)
    cdf = np.cumsum(weights) / weights.sum()
    k = np.minimum(np.searchsorted(cdf, rng.random(n), side="right"), len(weights) - 1)
    return edges[k] + rng.random(n) * (edges[k + 1] - edges[k])


def sample_count(distribution, rng: np.random.Generator) -> int:
    """A count: a draw of ``distribution`` (normal: not truncated, as the paper's N(5, 4)), rounded, clipped to ``[min, max]``."""
    if distribution.kind == "histogram":
        return max(int(np.floor(_histogram_draw(distribution, rng, 1)[0])), 0)
    if distribution.kind == "uniform":
        return int(rng.integers(int(np.ceil(distribution.min)), int(np.floor(distribution.max)) + 1))
    return int(np.clip(round(rng.normal(distribution.mean, distribution.std)), distribution.min, distribution.max))


# ----------------------------------------------------------------------------- the insertion rule
@dataclass
class InsertionLog:
    """What :func:`insert_sequentially` did.

    placed : the accepted candidates, in insertion order
    attempts : candidate positions tried by each object drawn (``rotations`` for one that failed;
        0 for one rejected before any position was tried)
    stopped : ``"count"`` (all wanted objects placed) or ``"failures"`` (too many consecutive failures)
    """

    placed: list = field(default_factory=list)
    attempts: list[int] = field(default_factory=list)
    stopped: str = "count"

    @property
    def objects_tried(self) -> int:
        return len(self.attempts)


def insert_sequentially(
    count: int,
    new_object: Callable[[], object],
    try_at: Callable[[object, float], object | None],
    rotations: int = 36,
    step_deg: float = 10.0,
    max_consecutive_failures: int = 10,
) -> InsertionLog:
    """Insert up to ``count`` objects one after another with the parking paper's retry rule.

    new_object() : a fresh object (its size, distance from the sensor, initial angle, yaw: the
        caller's draws), or ``None`` when it is rejected before placement (counts as a failure)
    try_at(obj, angle_deg) : the accepted placement of ``obj`` turned by ``angle_deg`` about the
        sensor's vertical axis, or ``None`` when it does not fit there
    Each object is tried at ``0, step, 2 step, ...`` up to ``rotations`` positions; the first that
    fits is kept. After ``max_consecutive_failures`` objects in a row fit nowhere, insertion stops.
    """
    log = InsertionLog()
    failures = 0
    while len(log.placed) < count:
        if failures >= max_consecutive_failures:
            log.stopped = "failures"
            break
        obj = new_object()
        placed = None
        tried = 0
        if obj is not None:
            for k in range(rotations):
                tried += 1
                placed = try_at(obj, k * step_deg)
                if placed is not None:
                    break
        log.attempts.append(tried)
        if placed is None:
            failures += 1
        else:
            log.placed.append(placed)
            failures = 0
    return log


def turn_about(pivot_xy, position_xy, yaw: float, angle_deg: float) -> tuple[np.ndarray, float]:
    """``position_xy`` and ``yaw`` (radians) turned rigidly by ``angle_deg`` about the vertical axis through ``pivot_xy``.

    Called for every candidate of the insertion rule, so in Python floats: the products and sums numpy's scalars
    did, and ``math``'s radians, cosine and sine, which give numpy's bits; the yaw is wrapped by numpy's
    ``arctan2``, what ``np.angle(np.exp(1j * a))`` computed (``math.atan2`` rounds apart). The same bits:
    ``tests/test_box_speed_paths.py``.
    """
    angle = math.radians(angle_deg)
    c, s = math.cos(angle), math.sin(angle)
    px, py = float(pivot_xy[0]), float(pivot_xy[1])
    ox, oy = float(position_xy[0]) - px, float(position_xy[1]) - py
    turned = np.array([c * ox - s * oy + px, s * ox + c * oy + py])
    a = yaw + angle
    return turned, float(np.arctan2(math.sin(a), math.cos(a)))


# ----------------------------------------------------------------------------- boxes on a floor
def facing_samples(origin, centre, half, yaw: float, per_side: int = 4) -> np.ndarray:
    """``(m, 3)`` points on the faces of an upright box that face ``origin`` (a grid of ``per_side`` x ``per_side`` cell centres each)."""
    axes = box_axes(yaw)
    centre, half, origin = np.asarray(centre, float), np.asarray(half, float), np.asarray(origin, float)
    gu, gv = _face_grid(per_side)
    points = []
    for k, (i, j) in enumerate(_OTHER_AXES):
        for sign in (-1.0, 1.0):
            normal = sign * axes[:, k]
            face_centre = centre + normal * half[k]
            if np.dot(origin - face_centre, normal) <= 0:
                continue
            points.append(face_centre + gu * half[i] * axes[:, i] + gv * half[j] * axes[:, j])
    return np.concatenate(points) if points else np.zeros((0, 3))


_OTHER_AXES = ((1, 2), (0, 2), (0, 1))
_FACE_GRIDS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _face_grid(per_side: int) -> tuple[np.ndarray, np.ndarray]:
    """``(per_side^2, 1)`` cell-centre coordinates ``u``, ``v`` in -1..1 of a face's grid (kept per ``per_side``)."""
    if per_side not in _FACE_GRIDS:
        u = (np.arange(per_side) + 0.5) / per_side * 2.0 - 1.0
        gu, gv = np.meshgrid(u, u, indexing="ij")
        gu, gv = gu.reshape(-1, 1), gv.reshape(-1, 1)
        gu.flags.writeable = gv.flags.writeable = False
        _FACE_GRIDS[per_side] = (gu, gv)
    return _FACE_GRIDS[per_side]


def _slab_distance(local_o: np.ndarray, local_d: np.ndarray, half: np.ndarray) -> np.ndarray:
    """:func:`~bpy_pipeline.geometry.collision.ray_box_distance` with no distance limit, on rays already in a box's
    axes, the same operations on float64 arrays without its per-call conversions (the caller ignores division
    warnings): ``local_o`` (..., 3) origins, ``local_d`` (..., 3) directions and ``half`` (..., 3) extents, broadcast
    against each other (several boxes at once); ``(...)`` metres, inf on a miss."""
    inv = 1.0 / local_d
    t1 = (-half - local_o) * inv
    t2 = (half - local_o) * inv
    near = np.fmax.reduce(np.minimum(t1, t2), axis=-1)  # np.nanmax's own reduction
    far = np.fmin.reduce(np.maximum(t1, t2), axis=-1)
    parallel_out = ((local_d == 0) & (np.abs(local_o) > half)).any(axis=-1)
    start = np.maximum(near, 0.0)
    return np.where((far >= start) & ~parallel_out, start, np.inf)


@dataclass
class PlacedBox:
    """An upright box on the floor.

    centre : (3,) metres; half : (3,) half length, width, height; yaw : radians
    samples : (m, 3) points on its faces towards the sensor; visible : (m,) bool, unblocked now
    """

    centre: np.ndarray
    half: np.ndarray
    yaw: float
    samples: np.ndarray
    visible: np.ndarray
    rays: tuple | None = field(default=None, repr=False, compare=False)  # (directions, distances) of the samples from the placer's sensor, kept once computed
    axes: np.ndarray | None = field(default=None, repr=False, compare=False)  # box_axes(yaw), made with the box

    def __post_init__(self):
        if self.axes is None:
            self.axes = box_axes(self.yaw)

    @property
    def visible_fraction(self) -> float:
        return float(self.visible.mean()) if len(self.visible) else 0.0


class FloorBoxPlacer:
    """Decides whether an upright box fits on a floor seen by a sensor, and remembers the boxes placed.

    sensor : (3,) sensor position, metres
    region : ``(low (2,), high (2,))`` the floor area a box must lie inside (metres)
    obstacles : rectangles ``(centre (2,), half (2,), yaw)`` a box must not overlap (pillars, ramps)
    static_distance : ``f(directions (n, 3)) -> (n,)`` distance from the sensor to the first static
        surface along each unit direction (inf where none); ``None``: nothing static occludes
    clearance : metres kept between boxes, and between a box and an obstacle
    min_visible : the smallest fraction of a box's sensor-facing surface samples that must be in
        line of sight, for the new box and for every box already placed
    keep_out : radius (metres) around the sensor no box may reach into (the robot carrying it)
    clear : :class:`~.clearance.SensorPoses` of the whole run: no box comes within their radius (``near_sensor``)
    """

    def __init__(self, sensor, region, obstacles=(), static_distance=None, clearance: float = 0.3, min_visible: float = 0.3, keep_out: float = 1.0,
                 samples_per_side: int = 4,
                 clear: SensorPoses = NO_POSES):
        self.sensor = np.asarray(sensor, float)
        self.region = (np.asarray(region[0], float), np.asarray(region[1], float))
        self._bounds = ((float(self.region[0][0]), float(self.region[0][1])), (float(self.region[1][0]), float(self.region[1][1])))
        self.obstacles = list(obstacles)
        self.static_distance = static_distance
        self.clearance = clearance
        self.min_visible = min_visible
        self.keep_out = keep_out
        self.per_side = samples_per_side
        self.clear = clear
        self.boxes: list[PlacedBox] = []
        self.rejections: Counter = Counter()
        self._obstacle_reach = None  # kept from the first try (the obstacles stay)

    def _inside(self, centre_xy: np.ndarray, half_xy: np.ndarray, yaw: float) -> bool:
        """:func:`rectangle_inside` of the region, answered from the centre and the circumscribed circle where they
        settle it by more than a micrometre (far beyond rounding): a centre outside the region puts a corner
        outside, a circle inside puts every corner inside. Python floats: the answers of numpy's scalars."""
        (x0, y0), (x1, y1) = self._bounds
        cx, cy = float(centre_xy[0]), float(centre_xy[1])
        if cx < x0 - 1e-6 or cy < y0 - 1e-6 or cx > x1 + 1e-6 or cy > y1 + 1e-6:
            return False
        r = math.hypot(half_xy[0], half_xy[1]) + 1e-6  # np.hypot may round a bit apart: the circle's micrometre covers it
        if cx - r >= x0 and cy - r >= y0 and cx + r <= x1 and cy + r <= y1:
            return True
        return rectangle_inside(centre_xy, half_xy, yaw, *self.region)

    def _near_sensor(self, centre_xy: np.ndarray, half_xy: np.ndarray, yaw: float) -> bool:
        """Whether the box's floor rectangle comes within ``keep_out`` of the sensor (their distance on the floor plan)."""
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = float(self.sensor[0] - centre_xy[0]), float(self.sensor[1] - centre_xy[1])
        along, across = abs(dx * c + dy * s), abs(dy * c - dx * s)  # the sensor in the box's axes
        return math.hypot(max(along - half_xy[0], 0.0), max(across - half_xy[1], 0.0)) < self.keep_out

    def _rays(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        offset = points - self.sensor
        distance = np.linalg.norm(offset, axis=1)
        return offset / np.maximum(distance, 1e-12)[:, None], distance

    def _blocked(self, directions: np.ndarray, distance: np.ndarray, boxes: list[PlacedBox]) -> np.ndarray:
        """``(n,)`` bool: the rays from the sensor along unit ``directions`` (n, 3) that one of ``boxes`` blocks
        before ``distance`` (n,) metres. Each box's rays are turned into its axes by a product of their own (the
        bits of one box at a time); the slab test then takes every box at once."""
        if not boxes:
            return np.zeros(len(directions), bool)
        local_o = np.stack([(self.sensor - box.centre) @ box.axes for box in boxes])[:, None]  # (b, 1, 3)
        local_d = np.stack([directions @ box.axes for box in boxes])  # (b, n, 3)
        half = np.stack([box.half for box in boxes])[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            hit = _slab_distance(local_o, local_d, half)
        return (hit < distance - 1e-6).any(axis=0)

    def _hidden_by(self, box: PlacedBox) -> list[np.ndarray]:
        """For each placed box, ``(m,)`` bool: which of its samples ``box`` hides from the sensor (one slab test for all)."""
        if not self.boxes:
            return []
        rays = [self._box_rays(other) for other in self.boxes]
        local_d = np.concatenate([d @ box.axes for d, _ in rays])
        with np.errstate(divide="ignore", invalid="ignore"):
            hit = _slab_distance((self.sensor - box.centre) @ box.axes, local_d, box.half)
        hidden = hit < np.concatenate([dist for _, dist in rays]) - 1e-6
        return np.split(hidden, np.cumsum([len(d) for d, _ in rays])[:-1])

    def _box_rays(self, box: PlacedBox) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_rays` of a box's samples, computed once per box (the sensor and the samples stay)."""
        if box.rays is None:
            box.rays = self._rays(box.samples)
        return box.rays

    def try_place(self, centre_xy, yaw: float, half) -> PlacedBox | None:
        """The box standing on the floor at ``centre_xy`` with ``yaw`` and ``half`` extents, or ``None``.

        Rejection reasons are counted in :attr:`rejections`: ``outside`` the region or inside the
        keep-out circle, ``obstacle``, ``collision`` with a placed box, ``occluded`` (its own visible
        fraction too low), ``occludes`` (it would hide too much of a placed box).
        """
        half = np.asarray(half, float)
        centre_xy = np.asarray(centre_xy, float)
        if not self._inside(centre_xy, half[:2], yaw):
            self.rejections["outside"] += 1
            return None
        if self._near_sensor(centre_xy, half, yaw):
            self.rejections["outside"] += 1
            return None
        if not self.clear.clear_of_box(centre_xy, half[:2], yaw, 0.0, 2.0 * half[2]):
            self.rejections["near_sensor"] += 1
            return None
        if self.obstacles:
            if self._obstacle_reach is None:  # (centres (o, 2), circumscribed radii grown by clearance / 2 (o,))
                grow = self.clearance / 2.0
                self._obstacle_reach = (np.array([o[0][:2] for o in self.obstacles], float),
                                        np.array([np.hypot(o[1][0] + grow, o[1][1] + grow) for o in self.obstacles], float))
            for k in rectangles_near(centre_xy, half, self.clearance, *self._obstacle_reach):
                o_centre, o_half, o_yaw = self.obstacles[k]
                if rectangles_overlap(centre_xy, half[:2], yaw, o_centre, o_half, o_yaw, self.clearance):
                    self.rejections["obstacle"] += 1
                    return None
        for box in self.boxes:
            if rectangles_overlap(centre_xy, half[:2], yaw, box.centre[:2], box.half[:2], box.yaw, self.clearance):
                self.rejections["collision"] += 1
                return None
        centre = np.array([centre_xy[0], centre_xy[1], half[2]])
        samples = facing_samples(self.sensor, centre, half, yaw, self.per_side)
        directions, distance = self._rays(samples)
        visible = np.ones(len(samples), bool)
        if self.static_distance is not None and len(samples):
            visible &= self.static_distance(directions) >= distance - 1e-3
        candidate = PlacedBox(centre, half, yaw, samples, visible, (directions, distance))
        visible &= ~self._blocked(directions, distance, self.boxes)
        if candidate.visible_fraction < self.min_visible:
            self.rejections["occluded"] += 1
            return None
        for box, hidden in zip(self.boxes, self._hidden_by(candidate)):
            still = box.visible & ~hidden
            if still.mean() < self.min_visible:
                self.rejections["occludes"] += 1
                return None
        return candidate

    def commit(self, box: PlacedBox) -> None:
        """Keep ``box``: later boxes avoid it, and it now hides the samples of earlier boxes behind it."""
        for other, hidden in zip(self.boxes, self._hidden_by(box)):
            other.visible &= ~hidden
        self.boxes.append(box)
