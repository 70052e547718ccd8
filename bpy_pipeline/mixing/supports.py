"""Twins from real scans: support surfaces found in a real scan's points, and people and robot arms placed on them.

The Raphael paper finds the floor and the desks of its reconstructed hall by RANSAC planes and DBSCAN
clusters; :func:`find_supports` does the same on the points of a real scan alone (no mesh, no labels):

1. sequential RANSAC: the near-horizontal plane (normal within ``max_tilt_deg`` of +z) with the most
   points within ``threshold`` m, refitted by least squares, its inliers taken out, ``max_planes`` times;
2. DBSCAN (:func:`dbscan`, a k-d tree and connected components, scipy) over each plane's inliers
   thinned to ``voxel`` m cells in the plane: one cluster is one surface; clusters under ``min_area``
   m^2 or narrower than ``min_width`` m (a wall's band at one height) are dropped;
3. the largest surface below the sensor (z < 0 in the scan's frame) is the floor; surfaces within
   ``floor_band`` m of its plane are floor too (sidewalks beside a road, pieces of a floor split by
   shadows) and surfaces ``desk_height`` m above it are desks, where their cells are mostly free of points
   in the ``headroom`` m above them (not a shelf board under the next); the rest are ``other``.

:func:`populate` then places standing people on the chosen surfaces and robot arms (the project's
six-axis arm at a valid random pose) on theirs, as :class:`Populated` placements carrying their meshes
in the scan's sensor frame, so the real-scan builder casts the real firings at them (:mod:`.cast`).
A candidate is refused when real returns more than ``clearance`` m above its surface fall in a
person's box or within ``margin`` m of an arm's capsules (:class:`~.ground.PointIndex`), when its
footprint leaves the surface (a foot or base point without surface points around it, on an edge, or
at a local height more than ``step`` m off), or when it comes within ``keep_out`` m of an object placed before.

Coordinates: the scan's sensor frame (x forward, y left, z up), metres; the sensor is assumed level
(a horizontal surface is horizontal in its frame within ``max_tilt_deg``). Pure numpy and scipy.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..geometry.objects import ARM_REFLECTIVITY, PERSON_REFLECTIVITY, ObjectPart
from ..geometry.placement import sample
from .ground import PointIndex, fit_plane
from .placement import Placement, boxes_overlap
from .section import RealPopulation, SupportParams

GAP = 0.01  # m: a placed object floats this far above its surface (as population/placer.py)
KINDS_OF_SURFACE = ("floor", "desk", "other")


@dataclass
class FoundSurface:
    """One support surface.

    kind : floor | desk | other; index : (k,) int64 rows of the scan's points on it
    normal : (3,) unit, up; offset : normal . p on its plane; height : m, median z of its points
    above_floor : m, its median height above the floor plane; area : m^2 (occupied cells); width : m (its minor extent)
    cells : (c, 2) float64 xy centres of its occupied ``voxel`` cells; covered : share of them with points just above
    """

    kind: str
    index: np.ndarray
    normal: np.ndarray
    offset: float
    height: float
    above_floor: float
    area: float
    width: float
    cells: np.ndarray
    covered: float = 0.0

    def info(self) -> dict:
        return {"kind": self.kind, "points": int(len(self.index)), "height": round(self.height, 4), "above_floor": round(self.above_floor, 4),
                "area": round(self.area, 3), "width": round(self.width, 3), "covered": round(self.covered, 3)}


def _need_scipy():
    try:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        from scipy.spatial import cKDTree
    except ImportError:  # pragma: no cover - scipy is in the mixing extra
        raise InputError("scene.population: finding surfaces needs scipy (pip install 'bpy-pipeline[mixing]')") from None
    return cKDTree, coo_matrix, connected_components


def dbscan(xy: np.ndarray, eps: float, min_samples: int) -> np.ndarray:
    """``(n,)`` int64 DBSCAN cluster of each of ``(n, d)`` points (-1: noise), numbered in order of their first point.

    A core point has at least ``min_samples`` points (itself included) within ``eps``; clusters are the connected
    components of core points within ``eps`` of each other; a border point joins the cluster of its lowest-numbered
    core neighbour (deterministic)."""
    cKDTree, coo_matrix, connected_components = _need_scipy()
    n = len(xy)
    if n == 0:
        return np.zeros(0, np.int64)
    tree = cKDTree(xy)
    core = np.asarray(tree.query_ball_point(xy, eps, return_length=True)) >= min_samples
    pairs = tree.query_pairs(eps, output_type="ndarray").astype(np.int64).reshape(-1, 2)
    both = core[pairs[:, 0]] & core[pairs[:, 1]]
    edges = pairs[both]
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    label = np.where(core, component, -1)
    one = pairs[core[pairs[:, 0]] ^ core[pairs[:, 1]]]  # border - core pairs
    if len(one):
        c_ = np.where(core[one[:, 0]], one[:, 0], one[:, 1])
        b_ = np.where(core[one[:, 0]], one[:, 1], one[:, 0])
        order = np.lexsort((c_, b_))
        b_, c_ = b_[order], c_[order]
        first = np.r_[True, b_[1:] != b_[:-1]]
        label[b_[first]] = component[c_[first]]
    # renumber in order of first appearance
    kept = label >= 0
    _, first_at, inverse = np.unique(label[kept], return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first_at))
    out = np.full(n, -1, np.int64)
    out[kept] = rank[inverse.reshape(-1)]
    return out


def _ransac_horizontal(points: np.ndarray, params: SupportParams, rng: np.random.Generator) -> tuple[np.ndarray, float] | None:
    """The near-horizontal plane ``(normal, offset)`` with the most of ``(n, 3)`` points within ``threshold`` (scored on a sample)."""
    n = len(points)
    if n < 3:
        return None
    score = points[rng.choice(n, params.sample, replace=False)] if n > params.sample else points
    picks = rng.integers(0, n, (params.iterations, 3))
    a, b, c = points[picks[:, 0]], points[picks[:, 1]], points[picks[:, 2]]
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal, axis=1)
    ok = length > 1e-9
    normal[ok] /= length[ok, None]
    normal *= np.where(normal[:, 2] < 0, -1.0, 1.0)[:, None]
    ok &= normal[:, 2] >= math.cos(math.radians(params.max_tilt_deg))
    if not ok.any():
        return None
    normal, offset = normal[ok], np.einsum("ij,ij->i", normal[ok], a[ok])
    counts = np.zeros(len(normal), np.int64)
    for s in range(0, len(normal), 64):
        counts[s : s + 64] = (np.abs(score @ normal[s : s + 64].T - offset[s : s + 64]) < params.threshold).sum(axis=0)
    best = int(np.argmax(counts))
    return normal[best], float(offset[best])


def find_supports(points: np.ndarray, params: SupportParams = SupportParams()) -> list[FoundSurface]:
    """The support surfaces of a scan (module notes): floors first (largest first), then desks, then the others.

    points : (n, 3) float64, the scan's returns in its sensor frame, metres
    """
    points = np.asarray(points, np.float64).reshape(-1, 3)
    rng = np.random.default_rng(params.seed)
    remaining = np.arange(len(points))
    found: list[tuple[np.ndarray, np.ndarray, float, float, float, np.ndarray]] = []
    for _ in range(params.max_planes):
        if len(remaining) < params.min_inliers:
            break
        plane = _ransac_horizontal(points[remaining], params, rng)
        if plane is None:
            break
        near = np.abs(points[remaining] @ plane[0] - plane[1]) < params.threshold
        if near.sum() < params.min_inliers:
            break
        normal, offset = fit_plane(points[remaining[near]])
        if normal[2] >= math.cos(math.radians(params.max_tilt_deg)):
            near = np.abs(points[remaining] @ normal - offset) < params.threshold
        else:
            normal, offset = plane
        inliers = remaining[near]
        remaining = remaining[~near]
        cells_of = np.floor(points[inliers, :2] / params.voxel).astype(np.int64)
        keys, which = np.unique(_key(cells_of), return_inverse=True)
        which = which.reshape(-1)
        cells = np.zeros((len(keys), 2), np.int64)
        cells[which] = cells_of
        label = dbscan((cells + 0.5) * params.voxel, params.eps, params.min_samples)
        for k in range(int(label.max(initial=-1)) + 1):
            mine = np.flatnonzero(label == k)
            centres = (cells[mine] + 0.5) * params.voxel
            area = len(mine) * params.voxel**2
            spread = np.linalg.eigvalsh(np.cov(centres.T)) if len(centres) > 2 else np.zeros(2)
            width = math.sqrt(12.0 * max(float(spread[0]), 0.0)) + params.voxel
            if area < params.min_area or width < params.min_width:
                continue
            rows = inliers[np.isin(which, mine)]
            found.append((rows, normal, offset, area, width, centres))
    if not found:
        return []
    below = [k for k, f in enumerate(found) if np.median(points[f[0], 2]) < 0.0] or list(range(len(found)))
    floor_k = max(below, key=lambda k: (found[k][3], -k))
    floor_normal, floor_offset = fit_plane(points[found[floor_k][0]])
    all_keys = _key(np.floor(points[:, :2] / params.voxel).astype(np.int64))
    out = []
    for k, (rows, normal, offset, area, width, centres) in enumerate(found):
        xyz = points[rows]
        height = float(np.median(xyz[:, 2]))
        above = float(np.median(xyz @ floor_normal - floor_offset) / floor_normal[2])
        covered = _covered(points, all_keys, rows, centres, height, params)
        if k == floor_k or (abs(above) <= params.floor_band and covered <= params.max_covered):
            kind = "floor"
        elif params.desk_height[0] <= above <= params.desk_height[1] and covered <= params.max_covered:
            kind = "desk"
        else:
            kind = "other"
        out.append(FoundSurface(kind, np.sort(rows), normal, offset, height, above, area, width, centres, covered))
    order = sorted(range(len(out)), key=lambda k: (KINDS_OF_SURFACE.index(out[k].kind), -out[k].area, k))
    return [out[k] for k in order]


def _key(cells: np.ndarray) -> np.ndarray:
    """``(n,)`` int64 one key per ``(n, 2)`` integer cell."""
    return (cells[:, 0] + (1 << 31)) * (1 << 32) + (cells[:, 1] + (1 << 31))


def _covered(points, all_keys, rows, centres, height, params) -> float:
    """Share of a surface's cells with a point of another surface or object within ``headroom`` m above it (all_keys: every point's cell key)."""
    cells = _key(np.floor(centres / params.voxel).astype(np.int64))
    z = points[:, 2]
    band = (z > height + params.threshold + 0.02) & (z < height + params.headroom)
    band[rows] = False
    if not band.any():
        return 0.0
    return float(np.isin(cells, all_keys[band]).mean())


def support_labels(n: int, supports: list[FoundSurface]) -> np.ndarray:
    """``(n,)`` int64: the index into ``supports`` of each of ``n`` points' surface, -1 for none."""
    out = np.full(n, -1, np.int64)
    for k, s in enumerate(supports):
        out[s.index] = k
    return out


# ----------------------------------------------------------------------------- population
@dataclass
class Populated(Placement):
    """A :class:`~.placement.Placement` with its meshes already made (``parts``, sensor frame) and what drew them (``detail``)."""

    parts: list = field(default_factory=list)
    detail: dict = field(default_factory=dict)


class SupportHeights:
    """The surfaces of some kinds, with each one's points in a k-d tree (xy) for local heights."""

    def __init__(self, points: np.ndarray, supports: list[FoundSurface], kinds, params: SupportParams):
        cKDTree = _need_scipy()[0]
        self.chosen = [s for s in supports if s.kind in kinds]
        self.points = points
        self.trees = [cKDTree(points[s.index, :2]) for s in self.chosen]
        self.weights = np.array([len(s.cells) for s in self.chosen], float)
        self.params = params

    def local_height(self, k: int, xy: np.ndarray, reach: float) -> np.ndarray:
        """``(m,)`` median z of surface ``k``'s points within ``reach`` m (xy) of each of ``(m, 2)`` points; nan where none."""
        return self.local(k, xy, reach)[0]

    def local(self, k: int, xy: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
        """``(height (m,), offset (m,))``: the median z of surface ``k``'s points within ``reach`` m (xy) of each of
        ``(m, 2)`` points and how far their mean lies from it in the plane (about 0.42 ``reach`` on a straight edge,
        near 0 inside); nan where none."""
        s = self.chosen[k]
        xy = np.asarray(xy, float)
        height, offset = np.full(len(xy), np.nan), np.full(len(xy), np.nan)
        for j, near in enumerate(self.trees[k].query_ball_point(xy, reach)):
            if len(near):
                rows = s.index[near]
                height[j] = float(np.median(self.points[rows, 2]))
                offset[j] = float(np.linalg.norm(self.points[rows, :2].mean(axis=0) - xy[j]))
        return height, offset

    def spot(self, rng: np.random.Generator) -> tuple[int, np.ndarray]:
        """A surface (weighted by its cells) and a point of one of its cells (uniform in the cell)."""
        k = int(rng.choice(len(self.chosen), p=self.weights / self.weights.sum()))
        cells = self.chosen[k].cells
        xy = cells[int(rng.integers(len(cells)))] + rng.uniform(-0.5, 0.5, 2) * self.params.voxel
        return k, xy


def _yawed_box(vertices: np.ndarray, yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """``(centre (3,), size (3,))`` of the box around ``(n, 3)`` vertices in a frame turned by ``yaw`` about z."""
    c, s = math.cos(yaw), math.sin(yaw)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    local = vertices @ turn
    low, high = local.min(axis=0), local.max(axis=0)
    return turn @ ((low + high) / 2), high - low


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(n, c)`` distance of each of ``(n, 3)`` points to each segment ``a``-``b`` ``(c, 3)``."""
    ab = b - a
    t = np.einsum("ncj,cj->nc", points[:, None, :] - a[None], ab) / np.maximum(np.einsum("cj,cj->c", ab, ab), 1e-12)
    t = np.clip(t, 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2)


def capsules_clear(obstacles: PointIndex, a: np.ndarray, b: np.ndarray, radius: np.ndarray, floor_z: float, clearance: float, margin: float) -> bool:
    """Whether no obstacle point more than ``clearance`` m above ``floor_z`` lies within ``margin`` m of the capsules ``(a, b, radius)``."""
    low = np.minimum(a, b).min(axis=0) - radius.max() - margin
    high = np.maximum(a, b).max(axis=0) + radius.max() + margin
    low[2] = max(low[2], floor_z + clearance)
    if high[2] <= low[2]:
        return True
    rows = obstacles.in_box((low + high) / 2, high - low, 0.0)
    if not len(rows):
        return True
    d = _segment_distance(obstacles.points[rows], a, b) - radius[None]
    return bool((d > margin).all())


EDGE = 0.3  # a footing point's surface points within reach must centre within this share of the reach on it (not on an edge)


def _footing(surfaces: SupportHeights, k: int, xy: np.ndarray, z: float, reach: float, step: float) -> bool:
    """Whether every one of ``(m, 2)`` footing points lies inside surface ``k``: its points within ``reach`` m centred
    on it (within ``EDGE`` of the reach: not on or past an edge) at a height within ``step`` m of ``z``."""
    h, offset = surfaces.local(k, xy, reach)
    return bool(np.isfinite(h).all() and (np.abs(h - z) <= step).all() and (offset <= EDGE * reach).all())


def _draw_person(rng: np.random.Generator, spec: RealPopulation) -> dict:
    from ..geometry.human import BUILDS, sample_pose

    pose = ("standing", "walking")[int(rng.integers(2))]
    build = BUILDS[("slim", "medium", "broad")[int(rng.integers(3))]]
    height = float(sample(spec.person_height, rng))
    return {"pose": pose, "build": float(build), "height": height, "angles": sample_pose(pose, rng, build)}


def _place_person(shape: dict, k: int, xy: np.ndarray, z: float, yaw: float, surfaces: SupportHeights, obstacles: PointIndex, spec: RealPopulation):
    """``(placement, why)``: the person of ``shape`` standing at ``xy`` on surface ``k`` at height ``z``, or ``None`` and the reason."""
    from ..geometry.human import body_mesh, pose_person

    person = pose_person(shape["angles"], shape["height"], shape["build"], shape["pose"], xy, yaw, z + GAP)
    ends = np.concatenate([person.a, person.b])
    r = np.concatenate([person.radius, person.radius])
    lo = np.concatenate([ends - r[:, None], ends + r[:, None]])
    centre, size = _yawed_box(lo, yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    corners = centre[:2] + 0.4 * np.array([[i * size[0], j * size[1]] for i in (-1, 1) for j in (-1, 1)]) @ np.array([[c, s], [-s, c]])
    if not _footing(surfaces, k, np.vstack([xy, corners]), z, spec.reach, spec.step):
        return None, "off_surface"
    bottom = z + spec.clearance
    top = centre[2] + size[2] / 2
    box_centre = np.array([centre[0], centre[1], (bottom + top) / 2])
    if len(obstacles.in_box(box_centre, (size[0], size[1], top - bottom), math.degrees(yaw))) > spec.max_points:
        return None, "real_points"
    v, t, _ = body_mesh(person.a, person.b, person.radius)
    p = Populated("person", "person", centre, size, yaw, "population", -1, [ObjectPart(v, np.asarray(t, np.int32), "diffuse", PERSON_REFLECTIVITY)],
                  {"pose": shape["pose"], "height": round(shape["height"], 4), "feet_z": round(float(person.support[2]), 4),
                   "surface": surfaces.chosen[k].kind})
    return p, ""


def _draw_arm(rng: np.random.Generator, spec: RealPopulation) -> dict:
    from ..geometry.kinematics import load_arm, random_configuration

    model = load_arm()
    return {"model": model, "q": random_configuration(model, rng, floor_z=0.0)}


def _place_arm(shape: dict, k: int, xy: np.ndarray, z: float, yaw: float, surfaces: SupportHeights, obstacles: PointIndex, spec: RealPopulation):
    """``(placement, why)``: the arm of ``shape`` with its base at ``xy`` on surface ``k`` at height ``z``, or ``None`` and the reason."""
    from ..geometry.kinematics import capsules_world, forward
    from ..geometry.objects import arm_mesh
    from ..population.placer import placement_matrix

    model, q = shape["model"], shape["q"]
    local, _ = arm_mesh(model, q)
    base = placement_matrix(xy, yaw, z + GAP - float(local[:, 2].min()))
    radius = float(model.capsule_radius[model.capsule_link == 0].max())
    ring = radius * np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    c, s = math.cos(yaw), math.sin(yaw)
    if not _footing(surfaces, k, xy + ring @ np.array([[c, s], [-s, c]]), z, spec.arm_reach, spec.step):
        return None, "off_surface"
    a, b, r = capsules_world(model, forward(model, np.asarray(q, float), base))
    if not capsules_clear(obstacles, a, b, np.asarray(r, float), z, spec.clearance, spec.margin):
        return None, "real_points"
    v, t = arm_mesh(model, q, base)
    centre, size = _yawed_box(v, yaw)
    p = Populated("robot_arm", "robot arm", centre, size, yaw, "population", -1, [ObjectPart(v, np.asarray(t, np.int32), "diffuse", ARM_REFLECTIVITY)],
                  {"q": [round(float(x), 6) for x in q], "base": [round(float(x), 4) for x in base[:3, 3]], "surface": surfaces.chosen[k].kind})
    return p, ""


# kind -> (draw a shape from the generator, place it at a spot, the config's count and surfaces)
KINDS = {
    "person": (_draw_person, _place_person, lambda spec: (spec.people, spec.people_on)),
    "robot_arm": (_draw_arm, _place_arm, lambda spec: (spec.arms, spec.arms_on)),
}


def populate(points: np.ndarray, spec: RealPopulation, rng: np.random.Generator, placed: list | None = None,
             supports: list[FoundSurface] | None = None) -> tuple[list[Populated], dict]:
    """People and arms on the surfaces of a real scan (module notes); ``(placements, log)``.

    points : (n, 3) float64 the scan's kept returns (sensor frame, m); placed : objects placed before (kept ``keep_out`` from)
    supports : already found (default: :func:`find_supports` of ``points`` with ``spec.supports``)
    Every draw comes from ``rng``: per object its shape, then per try a surface, a spot and a yaw.
    """
    points = np.asarray(points, np.float64).reshape(-1, 3)
    supports = find_supports(points, spec.supports) if supports is None else supports
    obstacles = PointIndex(points)
    before = list(placed or [])
    out: list[Populated] = []
    log = {"supports": [s.info() for s in supports], "rejections": {}}
    for kind, (draw, place, wanted) in KINDS.items():
        count, on = wanted(spec)
        surfaces = SupportHeights(points, supports, on, spec.supports)
        rejections: Counter = Counter()
        done = 0
        for _ in range(count):
            if not surfaces.chosen:
                rejections["no_surface"] += 1
                continue
            shape = draw(rng, spec)
            for _ in range(spec.tries):
                k, xy = surfaces.spot(rng)
                yaw = float(rng.uniform(-math.pi, math.pi))
                distance = float(np.hypot(*xy))
                if distance < spec.min_range or (spec.max_range > 0 and distance > spec.max_range):
                    rejections["range"] += 1
                    continue
                z = surfaces.local_height(k, xy[None], spec.reach)[0]
                if not np.isfinite(z):
                    rejections["off_surface"] += 1
                    continue
                p, why = place(shape, k, xy, float(z), yaw, surfaces, obstacles, spec)
                if p is not None and any(boxes_overlap(p, q, spec.keep_out) for q in before + out):
                    p, why = None, "keep_out"
                if p is None:
                    rejections[why] += 1
                    continue
                out.append(p)
                done += 1
                break
            else:
                rejections["gave_up"] += 1
        log[kind] = {"asked": int(count), "placed": done}
        log["rejections"][kind] = dict(sorted(rejections.items()))
    return out, log
