"""Collision-free placement of people, robot arms and cars into a static scene. Pure numpy.

A candidate is a :class:`Shape` (a mesh in its own frame: origin on its support, facing +x, lowest
point at z = 0) put at a spot of a :class:`~.surfaces.Surface` with a yaw. :class:`Placer` accepts it
when

* its support points rest on an allowed surface (``surfaces.on_surface``),
* its footprint (the rectangle around its mesh in its own frame) stays ``keep_out`` m from every
  footprint placed before it whose height range it shares, and
* its mesh crosses no triangle of the static scene: no edge of either mesh passes through a triangle
  of the other (:func:`meshes_cross`, on the same triangles export hands to the scanner).

Every draw comes from the generator passed in, so a frame's placements depend on that frame's
generator only. Coordinates: metres, world frame, z up; yaw in radians about +z.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..geometry.clearance import NO_POSES, SensorPoses
from ..geometry.collision import rectangles_overlap
from ..geometry.surfaces import Surface, on_surface

GAP = 0.01  # m: a placed object floats this far above its surface, so touching is never counted as crossing


@dataclass
class Shape:
    """A mesh to place, in its own frame.

    vertices : (n, 3) float64 m (origin on the support, facing +x, lowest point z = 0)
    triangles : (m, 3) int32
    support : (k, 2) float64 xy (own frame) that must rest on the surface
    detail : what the kind needs to show it (pose, joint angles, style, asset index ...)
    seat_offset : for a seated shape, how far behind a seat edge its origin sits (m); ``None``: stands on spots
    """

    vertices: np.ndarray
    triangles: np.ndarray
    support: np.ndarray
    detail: dict = field(default_factory=dict)
    seat_offset: float | None = None


@dataclass
class Placed:
    """A shape accepted at ``matrix`` (4, 4) own frame -> world; ``vertices`` (n, 3) world."""

    kind: str
    shape: Shape
    matrix: np.ndarray
    vertices: np.ndarray
    footprint: tuple  # (centre (2,), half (2,), yaw, z_low, z_high)
    sight: tuple | None = None  # the visibility rule's (starts (s, 3), ends (s, 3), blocked (s,) bool) of its samples

    @property
    def yaw(self) -> float:
        return float(np.arctan2(self.matrix[1, 0], self.matrix[0, 0]))


def placement_matrix(xy, yaw: float, z: float) -> np.ndarray:
    """``(4, 4)`` a turn of ``yaw`` rad about z, then a move to ``(x, y, z)``."""
    c, s = np.cos(yaw), np.sin(yaw)
    m = np.eye(4)
    m[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    m[:3, 3] = [xy[0], xy[1], z]
    return m


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """``(e, 2)`` int unique undirected edges of ``triangles (m, 3)``."""
    t = np.asarray(triangles)
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0)


def segments_cross(p0: np.ndarray, p1: np.ndarray, tri: np.ndarray, eps: float = 1e-7, chunk: int = 1 << 20) -> bool:
    """True when a segment ``p0 (e, 3) -> p1 (e, 3)`` passes through the inside of a triangle ``tri (t, 3, 3)``.

    Möller-Trumbore on the pairs whose bounding boxes overlap; touching (an end on the plane, a
    crossing on the triangle's border) and segments in the triangle's plane do not count.
    """
    if not len(p0) or not len(tri):
        return False
    s_low, s_high = np.minimum(p0, p1), np.maximum(p0, p1)
    t_low, t_high = tri.min(axis=1), tri.max(axis=1)
    # candidate pairs: loop over the smaller side, vectorise over the larger
    step = max(1, chunk // len(p0))
    for k in range(0, len(tri), step):
        tl, th = t_low[k : k + step], t_high[k : k + step]
        overlap = ((s_low[:, None] <= th[None]) & (s_high[:, None] >= tl[None])).all(axis=-1)
        si, ti = np.nonzero(overlap)
        if not len(si):
            continue
        ti = ti + k
        o, d = p0[si], p1[si] - p0[si]
        a, b, c = tri[ti, 0], tri[ti, 1], tri[ti, 2]
        e1, e2 = b - a, c - a
        h = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, h)
        scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * np.linalg.norm(d, axis=1)
        ok = np.abs(det) > 1e-9 * np.maximum(scale, 1e-30)
        det = np.where(ok, det, 1.0)
        s = o - a
        u = np.einsum("ij,ij->i", s, h) / det
        q = np.cross(s, e1)
        v = np.einsum("ij,ij->i", d, q) / det
        t = np.einsum("ij,ij->i", e2, q) / det
        hit = ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > eps) & (t < 1 - eps)
        if hit.any():
            return True
    return False


def segments_blocked(p0: np.ndarray, p1: np.ndarray, tri: np.ndarray, eps: float = 1e-7, chunk: int = 1 << 20) -> np.ndarray:
    """``(e,)`` bool: each segment ``p0 -> p1`` passes through the inside of one of the triangles ``tri (t, 3, 3)``
    (the per-segment form of :func:`segments_cross`)."""
    blocked = np.zeros(len(p0), bool)
    if not len(p0) or not len(tri):
        return blocked
    s_low, s_high = np.minimum(p0, p1), np.maximum(p0, p1)
    t_low, t_high = tri.min(axis=1), tri.max(axis=1)
    step = max(1, chunk // len(p0))
    for k in range(0, len(tri), step):
        overlap = ((s_low[:, None] <= t_high[None, k : k + step]) & (s_high[:, None] >= t_low[None, k : k + step])).all(axis=-1)
        si, ti = np.nonzero(overlap & ~blocked[:, None])
        if not len(si):
            continue
        ti = ti + k
        o, d = p0[si], p1[si] - p0[si]
        a, e1, e2 = tri[ti, 0], tri[ti, 1] - tri[ti, 0], tri[ti, 2] - tri[ti, 0]
        h = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, h)
        ok = np.abs(det) > 1e-12
        det = np.where(ok, det, 1.0)
        sa = o - a
        u = np.einsum("ij,ij->i", sa, h) / det
        q = np.cross(sa, e1)
        v = np.einsum("ij,ij->i", d, q) / det
        t = np.einsum("ij,ij->i", e2, q) / det
        hit = ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > eps) & (t < 1 - eps)
        blocked[si[hit]] = True
    return blocked


def sample_points(vertices: np.ndarray, count: int = 48) -> np.ndarray:
    """``(<= count, 3)`` vertices at even index steps (the same for the same mesh)."""
    return vertices[np.linspace(0, len(vertices) - 1, min(count, len(vertices))).astype(int)]


def meshes_cross(va: np.ndarray, ta: np.ndarray, vb: np.ndarray, tb: np.ndarray) -> bool:
    """True when the surfaces of two triangle meshes cross (an edge of one through a triangle of the other)."""
    if not len(ta) or not len(tb):
        return False
    ea, eb = mesh_edges(ta), mesh_edges(tb)
    return segments_cross(va[ea[:, 0]], va[ea[:, 1]], vb[tb]) or segments_cross(vb[eb[:, 0]], vb[eb[:, 1]], va[ta])


def footprint(shape: Shape, matrix: np.ndarray) -> tuple:
    """``(centre (2,), half (2,), yaw, z_low, z_high)``: the rectangle around the shape's mesh in its own frame, placed."""
    low, high = shape.vertices.min(axis=0), shape.vertices.max(axis=0)
    centre = matrix[:3, :3] @ np.append((low[:2] + high[:2]) / 2, 0.0) + matrix[:3, 3]
    yaw = float(np.arctan2(matrix[1, 0], matrix[0, 0]))
    return centre[:2], (high[:2] - low[:2]) / 2, yaw, low[2] + matrix[2, 3], high[2] + matrix[2, 3]


class Placer:
    """Accepts shapes one after another against a static scene and everything placed before.

    vertices (n, 3), triangles (m, 3): the static scene as exported (world, m)
    keep_out : m kept between placed footprints
    sensor, min_visible : with a sensor position (3,) and ``min_visible`` > 0, the parking paper's rule: a shape
        is refused when less than ``min_visible`` of its sampled vertices are in the sensor's line of sight
        (past the static scene and the shapes placed before), or when it would leave one placed before below that
    clear : :class:`~.clearance.SensorPoses` of the whole run: a shape whose footprint box comes within their radius is refused
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, keep_out: float = 0.3, sensor: np.ndarray | None = None, min_visible: float = 0.0,
                 clear: SensorPoses = NO_POSES):
        self.vertices = np.asarray(vertices, float)
        self.triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
        self.tri = self.vertices[self.triangles]
        self.low, self.high = self.tri.min(axis=1), self.tri.max(axis=1)
        self.keep_out = keep_out
        self.placed: list[Placed] = []
        self.rejections: Counter = Counter()
        self.sensor = None if sensor is None else np.asarray(sensor, float)
        self.min_visible = min_visible
        self.clear = clear

    def sight_lines(self, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(starts, ends, blocked)``: segments from the sensor to ``vertices``' samples (stopping 2 cm short),
        and which the static scene and the objects placed so far block."""
        points = sample_points(vertices)
        direction = points - self.sensor
        ends = points - direction / np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-9) * 0.02
        starts = np.repeat(self.sensor[None], len(points), axis=0)
        blocked = segments_blocked(starts, ends, self.tri)
        for other in self.placed:
            blocked |= segments_blocked(starts, ends, other.vertices[other.shape.triangles])
        return starts, ends, blocked

    def visible_fraction(self, vertices: np.ndarray) -> float:
        """Share of ``vertices``' samples (world) seen from the sensor past the static scene and the objects placed."""
        return float(1.0 - self.sight_lines(vertices)[2].mean())

    def fits(self, kind: str, shape: Shape, matrix: np.ndarray, support: tuple[np.ndarray, np.ndarray] | None) -> Placed | None:
        """The placement of ``shape`` at ``matrix`` when it fits, else ``None`` (the reason counted in ``rejections``).

        support : ``(vertices, triangles)`` of the surface its support points must rest on (``None``: not checked)
        """
        rotation, move = matrix[:3, :3], matrix[:3, 3]
        if support is not None and len(shape.support):
            points = np.column_stack([shape.support, np.zeros(len(shape.support))]) @ rotation.T + move
            if not on_surface(points, *support, tolerance=GAP + 0.02).all():
                self.rejections["off_surface"] += 1
                return None
        box = footprint(shape, matrix)
        if not self.clear.clear_of_box(*box):
            self.rejections["near_sensor"] += 1
            return None
        for other in self.placed:
            c, h, y, z0, z1 = other.footprint
            if box[3] < z1 + self.keep_out and z0 < box[4] + self.keep_out and rectangles_overlap(box[0], box[1], box[2], c, h, y, self.keep_out):
                self.rejections["keep_out"] += 1
                return None
        world = shape.vertices @ rotation.T + move
        low, high = world.min(axis=0) - 1e-3, world.max(axis=0) + 1e-3
        near = np.flatnonzero(((self.low <= high) & (self.high >= low)).all(axis=1))
        if len(near):
            used, local = np.unique(self.triangles[near], return_inverse=True)
            if meshes_cross(world, shape.triangles, self.vertices[used], local.reshape(-1, 3)):
                self.rejections["static"] += 1
                return None
        placed = Placed(kind, shape, matrix, world, box)
        if self.sensor is not None and self.min_visible > 0:
            placed.sight = self.sight_lines(world)
            if 1.0 - placed.sight[2].mean() < self.min_visible:
                self.rejections["hidden"] += 1
                return None
            occluder = world[shape.triangles]
            for other in self.placed:
                starts, ends, blocked = other.sight
                if 1.0 - (blocked | segments_blocked(starts, ends, occluder)).mean() < self.min_visible:
                    self.rejections["hides"] += 1
                    return None
        return placed

    def commit(self, placed: Placed) -> None:
        if placed.sight is not None:  # the objects placed before lose the lines of sight it blocks
            occluder = placed.vertices[placed.shape.triangles]
            for other in self.placed:
                starts, ends, blocked = other.sight
                other.sight = (starts, ends, blocked | segments_blocked(starts, ends, occluder))
        self.placed.append(placed)


def place_on_spots(
    kind: str,
    draw: Callable[[np.random.Generator], Shape | None],
    rng: np.random.Generator,
    placer: Placer,
    spots: list[tuple[Surface, np.ndarray, np.ndarray]],
    tries: int,
    surface_mesh: Callable[[Surface], tuple[np.ndarray, np.ndarray]],
    fixed: np.ndarray | None = None,
) -> Placed | None:
    """Draw a shape and try it at random spots until one fits (``tries`` attempts).

    spots : per allowed surface ``(surface, spots (n, 3), outward (n, 2) or None)``: a standing shape
        goes to a spot of any floor-like surface with a uniform yaw; a seated shape (``seat_offset``)
        to an edge spot of a seat, facing outward, its origin ``seat_offset`` behind the edge
    fixed : (k, 3) [x, y, yaw_rad] positions to try instead of spots (a robot arm's base list)
    surface_mesh : ``surface -> (vertices, triangles)`` of its triangles, for the support check
    """
    for _ in range(tries):
        shape = draw(rng)
        if shape is None:
            placer.rejections["no_shape"] += 1
            continue
        seated = shape.seat_offset is not None
        usable = [s for s in spots if len(s[1]) and ((s[2] is not None) == seated)]
        if fixed is not None and not seated:
            x, y, yaw = fixed[rng.integers(len(fixed))]
            below = [s for s in spots if len(s[1])]
            if not below:
                placer.rejections["no_surface"] += 1
                continue
            surface = min(below, key=lambda s: np.min(np.linalg.norm(s[1][:, :2] - [x, y], axis=1)))[0]
            matrix = placement_matrix((x, y), float(yaw), surface.z + GAP)
        elif not usable:
            placer.rejections["no_surface"] += 1
            continue
        else:
            sizes = np.array([len(s[1]) for s in usable], float)
            surface, points, outward = usable[rng.choice(len(usable), p=sizes / sizes.sum())]
            k = rng.integers(len(points))
            if seated:
                direction = outward[k]
                origin = points[k, :2] - direction * shape.seat_offset
                matrix = placement_matrix(origin, float(np.arctan2(direction[1], direction[0])), points[k, 2] + GAP)
            else:
                matrix = placement_matrix(points[k, :2], float(rng.uniform(-np.pi, np.pi)), points[k, 2] + GAP)
        placed = placer.fits(kind, shape, matrix, surface_mesh(surface))
        if placed is not None:
            placer.commit(placed)
            return placed
    return None


# ----------------------------------------------------------------------------- shapes of the built-in kinds
def person_shape(angles: np.ndarray, height: float, build: float, pose: str) -> Shape:
    """A procedural body (:mod:`.human`) as a :class:`Shape`; seated bodies rest pelvis and thighs on z = 0."""
    from ..geometry import human

    person = human.pose_person(angles, height, build, pose, (0.0, 0.0), 0.0, 0.0)
    vertices, triangles, _ = human.body_mesh(person.a, person.b, person.radius)
    detail = {"angles": np.asarray(angles, float), "height": float(height), "build": float(build), "pose": pose}
    if pose == "sitting":
        return Shape(vertices, triangles, np.zeros((1, 2)), detail, seat_offset=human.seat_offset(angles, height, build))
    feet = np.array([vertices[:, :2].mean(axis=0)])
    return Shape(vertices, triangles, feet, detail)


def arm_shape(model, q: np.ndarray, mesh: tuple | None = None) -> Shape:
    """A robot arm at joint angles ``q`` (rad) with its base frame as the shape's frame (lowest point z = 0).

    mesh : the posed ``(vertices, triangles)`` in the base frame (a URDF arm's own meshes); default its capsules
    """
    from ..geometry.objects import arm_mesh

    vertices, triangles = arm_mesh(model, q) if mesh is None else mesh
    lift = -vertices[:, 2].min()
    vertices = vertices + [0.0, 0.0, lift]
    r = float(model.capsule_radius[model.capsule_link == 0].max()) * 0.7
    support = np.array([[0.0, 0.0], [r, 0.0], [-r, 0.0], [0.0, r], [0.0, -r]])
    return Shape(vertices, triangles, support, {"q": np.asarray(q, float), "lift": lift})


def box_support(vertices: np.ndarray, fraction: float = 0.8) -> np.ndarray:
    """``(5, 2)`` the centre and the corners of the xy box around ``vertices``, shrunk to ``fraction`` of its size."""
    low, high = vertices[:, :2].min(axis=0), vertices[:, :2].max(axis=0)
    centre, half = (low + high) / 2, (high - low) / 2 * fraction
    return centre + np.array([[0, 0], [1, 1], [1, -1], [-1, 1], [-1, -1]]) * half


def mesh_shape(vertices: np.ndarray, triangles: np.ndarray, scale: float, detail: dict, support_fraction: float = 0.8) -> Shape:
    """A unit-height mesh (feet on z = 0, centred on x = y = 0) scaled by ``scale`` m."""
    v = np.asarray(vertices, float) * scale
    return Shape(v, np.asarray(triangles, np.int32), box_support(v, support_fraction), {**detail, "scale": float(scale)})
