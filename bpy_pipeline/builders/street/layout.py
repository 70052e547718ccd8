"""An urban street (a four-arm intersection, a T-junction or a straight street) and its road users: layout, meshes and placement rules. Pure numpy.

World frame: the junction's centre at the origin, z up, the road surface at z = 0. The road along
x runs whole, ``arm_length`` metres either side of the centre; the road along y has the arms of
the layout's :class:`Junction` (drawn by :func:`junction` from ``junction_mix`` and ``layout_seed``):
both (``cross``, four arms), one (``t_junction``) or none (``straight``: a residential street, with
one mid-block zebra crossing). Traffic keeps right: on the road along x, lanes driving +x lie at y < 0.
Across a road (from its centre line out)::

    | drive lanes (lanes_per_direction x lane_width) | parking strip | kerb | sidewalk | facades

so a road's half width is ``R = lanes_per_direction * lane_width + parking_width``; the kerb
is a ``kerb_width`` strip ``kerb_height`` high at ``|y| = R``, the sidewalk a slab of the same
height out to ``R + kerb_width + sidewalk_width``, the buildings' facades stand at its outer
edge. A zebra crossing spans each arm of a junction ``crossing_offset`` metres from its edge.

Road users are upright boxes on the ground for placement (centre, half size, yaw), and meshes in
their own frame (x forward, y left, z up, origin on the ground below the box centre):

- vehicles (car, van, truck, bus): body, glass, tyres; headings along their lane;
- pedestrians: the articulated body of :mod:`.human` walking or standing, on sidewalks and crossings;
- bicycles and motorcycles with a seated rider, near the right edge of the rightmost lane.

Placement rules (:func:`place_users`):

- *lane following*: a vehicle's heading is its lane's; with probability ``platoon_probability``
  it follows the last vehicle placed in a lane at a gap drawn from ``platoon_gap`` (the KITTI
  wall-projection paper's pose rule: a synthetic vehicle near a real one takes its yaw; here
  the lane gives the yaw, and the platoon keeps the gap);
- *parked cars*: in the parking strips, nose along the traffic of their side, never on a crossing
  or in the intersection;
- *as many per metre*: the counts (``vehicles``, ``parked``, ``bicycles``, ``motorcycles``,
  ``pedestrians``) are for the four-arm intersection; a junction with fewer arms scales each by its
  lanes' length (parking strips', sidewalks' area) over the four-arm one's (:attr:`StreetLayout.scale`);
- *pedestrians*: on a sidewalk (heading along it) or on a crossing (heading across the road);
- *no overlap*: every footprint keeps ``clearance`` from every other and from poles;
- *clear of the sensor*: no user's box comes within ``clear.radius`` of a sensor pose of the run
  (:class:`~bpy_pipeline.geometry.clearance.SensorPoses`: every frame, rig member and path sample);
- *field-of-view aware*: when the sensors' :class:`FieldOfView` s are given, a candidate is kept
  only if at least ``min_in_view`` of the sample points of its box lie inside one sensor's field
  of view and range, so a narrow sensor sees what is placed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ...geometry import primitives
from ...geometry.primitives import box_mesh, transformed, transformed_parts
from ...geometry.clearance import NO_POSES, SensorPoses
from ...geometry.collision import rectangles_near, rectangles_overlap
from ...geometry.field_of_view import in_view_fraction
from ...geometry.objects import FITTINGS
from ...geometry.vehicles import saddle_height, two_wheeler_parts, vehicles_parts

Mesh = tuple[np.ndarray, np.ndarray]  # vertices (n, 3) float64, triangles (m, 3) int32

# road user kinds -> class of their main part (assets_manifest/labels.yaml)
VEHICLES = ("car", "van", "truck", "bus")
TWO_WHEELERS = ("bicycle", "motorcycle")
RIDER_CLASS = {"bicycle": "rider", "motorcycle": "motorcyclist"}  # a rider is labelled by what it rides (SemanticKITTI bicyclist 31, motorcyclist 32)
# nominal sizes (length, width, height, m) and the share of each drawn size's spread (+-)
NOMINAL_SIZE = {
    "car": (4.4, 1.8, 1.5),
    "van": (5.2, 2.0, 2.2),
    "truck": (8.5, 2.5, 3.4),
    "bus": (12.0, 2.55, 3.2),
    "bicycle": (1.75, 0.6, 1.75),  # with its rider
    "motorcycle": (2.1, 0.8, 1.6),
    "person": (0.6, 0.6, 1.75),
}
SPREAD = {"car": 0.08, "van": 0.06, "truck": 0.1, "bus": 0.05, "bicycle": 0.03, "motorcycle": 0.05, "person": 0.08}
EGO_HALF = (2.3, 0.95)  # m: half the ego car's footprint (a 4.6 x 1.9 m estate car), kept free under a roof sensor
MARKING_THICKNESS = 0.005  # m: road markings stand this proud of the road; users on the road stand on it
# Reflectivity at 905 nm. Road, sidewalk, building and pole fitted with the hdl64e reading to SemanticKITTI's remission
# per class, then checked on whole generated streets (docs/realism.md, "The HDL-64E's reading, fitted per class");
# the rest assumed. "building" is the median of each building's own draw (BUILDING).
REFLECTIVITY = {"road": 0.15, "marking": 0.6, "sidewalk": 0.25, "kerb": 0.35, "building": 0.55, "glass": 0.08,
                "tyre": 0.05, "pole": 0.2, "traffic light": 0.15, "traffic sign": 0.8, "frame": 0.3}
# Per-object reflectivity, lognormal: (median, sd of its log, lowest, highest). Buildings draw from the layout's
# generator, road users from the frame's. PAINT is a body's diffuse return beside its clear coat's mirror lobe
# (dark and metallic paints return 1-5 %, white up to 0.5), CLOTHING a pedestrian's or rider's; both fitted to
# KITTI and SemanticKITTI car and person remission through the hdl64e reading (docs/realism.md).
BUILDING = (0.55, 0.4, 0.15, 0.95)
# a body's paint stays below every fitting's reflectivity (FITTINGS' plates: 0.8), so a body and its plates never share an
# (instance, reflectivity) key: the material models tell a point's object by that key (lidar/effects/materials.py)
PAINT = (0.04, 1.2, 0.002, 0.79)
CLOTHING = (0.5, 0.6, 0.05, 0.95)


def ego_keep_free(params, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The rectangle ``(centre (2,), half size (2,), yaw)`` (m, radians) no road user may enter around the ego car whose roof
    sensor stands at ``(4, 4)`` ``pose``: its footprint (:data:`EGO_HALF`) and ``params.ego_headway`` metres ahead of it."""
    ahead = float(params.ego_headway) / 2
    yaw = float(np.arctan2(pose[1, 0], pose[0, 0]))
    return np.asarray(pose[:2, 3], float) + ahead * np.array([np.cos(yaw), np.sin(yaw)]), np.array(EGO_HALF) + (ahead, 0.0), yaw


def draw_reflectivity(rng: np.random.Generator, law: tuple[float, float, float, float]) -> float:
    """One object's reflectivity: ``median exp(log_sd z)``, ``z`` standard normal from ``rng``, clipped to ``[lowest, highest]``."""
    median, log_sd, lowest, highest = law
    return float(np.clip(median * math.exp(log_sd * float(rng.standard_normal())), lowest, highest))


# ----------------------------------------------------------------------------- the junction
JUNCTION_STREAM = 50  # the junction's generator: default_rng([layout_seed, JUNCTION_STREAM]), used by nothing else


@dataclass(frozen=True)
class Junction:
    """Which arms a street has. The road along x always runs whole; ``arms`` are the signs of the road along y's
    arms (``(-1, 1)``: both, ``(1,)``: +y only, ``()``: none); ``crossings`` the arms ``(axis, sign)`` with a zebra
    crossing by the centre, in the order the layout lists them."""

    kind: str
    arms: tuple[int, ...]
    crossings: tuple[tuple[int, int], ...]

    def has_arm(self, axis: int, sign: int) -> bool:
        return axis == 0 or sign in self.arms


def _t_junction(rng: np.random.Generator) -> Junction:
    side = int(rng.choice([-1, 1]))
    return Junction("t_junction", (side,), ((0, -1), (0, 1), (1, side)))


# kind -> its junction, drawn from the junction's generator (a T-junction's arm on either side)
JUNCTIONS = {
    "cross": lambda rng: Junction("cross", (-1, 1), ((0, -1), (0, 1), (1, -1), (1, 1))),
    "t_junction": _t_junction,
    "straight": lambda rng: Junction("straight", (), ((0, 1),)),  # one mid-block zebra crossing
}
FOUR_ARMS = JUNCTIONS["cross"](None)


def junction(p) -> Junction:
    """The :class:`Junction` of :class:`~bpy_pipeline.builders.street.StreetScene` ``p``: its kind drawn by the shares
    ``p.junction_mix`` from ``default_rng([p.layout_seed, JUNCTION_STREAM])`` (no draw when one kind has them all), so
    the layout's own generator draws the same whichever kind it is."""
    kinds = [k for k in JUNCTIONS if p.junction_mix.get(k, 0) > 0]
    rng = np.random.default_rng([int(p.layout_seed), JUNCTION_STREAM])
    if len(kinds) > 1:
        shares = np.array([p.junction_mix[k] for k in kinds], float)
        kinds = [kinds[int(rng.choice(len(kinds), p=shares / shares.sum()))]]
    return JUNCTIONS[kinds[0]](rng)


# ----------------------------------------------------------------------------- the layout
@dataclass(frozen=True)
class Lane:
    """A lane's centre line from ``start`` (2,) to ``end`` (2,), metres; traffic runs start -> end."""

    start: np.ndarray
    end: np.ndarray
    width: float
    kind: str  # drive | parking
    road: int  # 0: the road along x, 1: along y

    @cached_property
    def heading(self) -> float:
        d = self.end - self.start
        return math.atan2(d[1], d[0])

    @cached_property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))

    @cached_property
    def direction(self) -> np.ndarray:
        """(2,) the unit vector along the lane (read only)."""
        d = (self.end - self.start) / self.length
        d.flags.writeable = False
        return d

    @cached_property
    def left(self) -> np.ndarray:
        """(2,) the unit vector to the lane's left (read only)."""
        d = self.direction
        left = np.array([-d[1], d[0]])
        left.flags.writeable = False
        return left

    def at(self, s: float, lateral: float = 0.0) -> np.ndarray:
        """(2,) point ``s`` metres along the lane, ``lateral`` metres to its left."""
        return self.start + s * self.direction + lateral * self.left


@dataclass(frozen=True)
class Part:
    """One static object: name, class, material, reflectivity, instance id, mesh (world); for scattered items
    (street_dressing.Scatter) also ``scatter``, the prototypes and per-item transforms that ``mesh`` places."""

    name: str
    class_name: str
    reflectivity: float
    instance: int
    mesh: Mesh
    material: str = "diffuse"
    scatter: object = None
    front: tuple | None = None  # a building's facade line (dressing.Dressing.fronts), swept by "Street Facade"


@dataclass
class StreetLayout:
    """The static street: parts, lanes, walkable areas and obstacles.

    half_road : R (m), a road's half width to the kerb; walk_inner, walk_outer : the sidewalks'
    distance from the road's centre line (m); crossings : per crossed arm ``(axis, sign, s0, s1)`` the
    crossing spans along the road from ``s0`` to ``s1`` (m from the centre); poles : (k, 3)
    x, y, radius of every pole (lights, signs); junction : which arms it has (:class:`Junction`);
    scale : per ``drive`` / ``parking`` / ``sidewalk``, the drive lanes' length (parking strips',
    sidewalks' area) over the four-arm intersection's (1.0 for it): what the road users' counts are scaled by
    """

    parts: list[Part]
    lanes: list[Lane]
    half_road: float
    walk_inner: float
    walk_outer: float
    arm_length: float
    kerb_height: float
    crossings: list[tuple[int, int, float, float]]
    poles: np.ndarray
    walks: list[tuple[float, float, float, float]] = field(default_factory=list)
    blocks: list = field(default_factory=list)
    dressing: dict = field(default_factory=dict)
    yards: object = None  # dressing.Yards: where the "Street Planting" group plants
    junction: Junction = FOUR_ARMS
    scale: dict = field(default_factory=dict)

    def on_sidewalk(self, xy) -> bool:
        """True when ``xy`` (2,) lies on a sidewalk slab (kerbs excluded)."""
        x, y = (float(v) for v in xy)
        return any(x0 <= x <= x1 and y0 <= y <= y1 for x0, x1, y0, y1 in self.walks)

    def on_crossing(self, xy) -> bool:
        """True when ``xy`` lies on a zebra crossing."""
        x, y = (float(v) for v in xy)
        for axis, sign, s0, s1 in self.crossings:
            along, across = (x, y) if axis == 0 else (y, x)
            if s0 <= sign * along <= s1 and abs(across) <= self.half_road:
                return True
        return False

    def on_road(self, xy) -> bool:
        """True when ``xy`` lies on the carriageway (inside a kerb)."""
        a = np.abs(np.asarray(xy, float))
        on_y_arm = a[0] <= self.half_road and math.copysign(1.0, float(xy[1])) in self.junction.arms
        return bool((a <= self.arm_length).all() and (a[1] <= self.half_road or on_y_arm))


def road_meshes(p, j: Junction | None = None) -> tuple[Mesh, Mesh, Mesh, list[tuple[float, float, float, float]]]:
    """The carriageway, the kerbs and the sidewalks of :class:`~bpy_pipeline.builders.street.StreetScene` ``p``
    with the arms of junction ``j`` (default: :func:`junction` of ``p``) (meshes, m, world) and the sidewalks'
    rectangles ``(x0, x1, y0, y1)`` (m). The reference of the "Street Road" Geometry Nodes group (builders/street/road_nodes.py).

    road : the road along x whole (2 arm_length x 2 R), the road along y's arms beside it;
    kerbs : per arm and side a ``kerb_width`` x ``kerb_height`` box at ``|across| = R``, the x road's from the
    corner (``R``), the y road's from ``R + kerb_width``; sidewalks : per arm and side a slab ``kerb_height`` high
    from ``R + kerb_width`` to ``R + kerb_width + sidewalk_width`` across, the x road's from ``R + kerb_width``,
    the y road's from ``R + kerb_width + sidewalk_width`` along. On a side of the road along x without an arm
    across it, its kerb and its sidewalk run whole (one box each, ``-arm_length`` to ``arm_length``).
    """
    j = junction(p) if j is None else j
    lw, n, pw = p.lane_width, p.lanes_per_direction, p.parking_width
    R = n * lw + pw
    A = p.arm_length
    kw, kh, sw = p.kerb_width, p.kerb_height, p.sidewalk_width
    inner, outer = R + kw, R + kw + sw
    # carriageway: the road along x whole, the road along y in two halves beside it
    road = [primitives.translated(primitives.plane(2 * A, 2 * R), (0.0, 0.0, 0.0))]
    for sign in j.arms:
        road.append(primitives.translated(primitives.plane(2 * R, A - R), (0.0, sign * (A + R) / 2, 0.0)))
    # kerbs and sidewalks: along each arm, on both sides, up to the corner squares
    kerbs, walks, walk_rects = [], [], []
    for sx in (-1, 1):
        for sy in (-1, 1):
            if sy not in j.arms:  # no arm across this side: its kerb and sidewalk run whole
                if sx == 1:
                    kerbs.append(box_mesh(-A, A, *sorted((sy * R, sy * inner)), 0.0, kh))
                    walk_rects.append((-A, A, *sorted((sy * inner, sy * outer))))
                    walks.append(box_mesh(*walk_rects[-1], 0.0, kh))
                continue
            # kerb along the x road (y = sy R) from the corner to the arm's end, and along the y road
            kerbs.append(box_mesh(*sorted((sx * R, sx * A)), *sorted((sy * R, sy * inner)), 0.0, kh))
            kerbs.append(box_mesh(*sorted((sx * R, sx * inner)), *sorted((sy * inner, sy * A)), 0.0, kh))
            walk_rects.append((*sorted((sx * inner, sx * A)), *sorted((sy * inner, sy * outer))))
            walk_rects.append((*sorted((sx * inner, sx * outer)), *sorted((sy * outer, sy * A))))
            walks += [box_mesh(*rect, 0.0, kh) for rect in walk_rects[-2:]]
    return primitives.merge(road), primitives.merge(kerbs), primitives.merge(walks), walk_rects


def street_layout(p, rng: np.random.Generator, clear: SensorPoses = NO_POSES) -> StreetLayout:
    """The static street of :class:`~bpy_pipeline.builders.street.StreetScene` ``p`` at its :func:`junction`, its buildings
    drawn from ``rng``; traffic lights, signs and the dressing that would come within ``clear.radius`` of a sensor pose of
    ``clear`` are left out."""
    j = junction(p)
    lw, n, pw = p.lane_width, p.lanes_per_direction, p.parking_width
    R = n * lw + pw
    A = p.arm_length
    kw, kh, sw = p.kerb_width, p.kerb_height, p.sidewalk_width
    inner, outer = R + kw, R + kw + sw
    parts: list[Part] = []
    instance = iter(range(1, 100000))

    def add(name, class_name, reflectivity, mesh, material="diffuse", inst=None, scatter=None):
        parts.append(Part(name, class_name, reflectivity, next(instance) if inst is None else inst, mesh, material, scatter))

    road, kerbs, walks, walk_rects = road_meshes(p, j)
    add("street_road", "road", REFLECTIVITY["road"], road)
    add("street_kerbs", "kerb", REFLECTIVITY["kerb"], kerbs)
    add("street_sidewalks", "sidewalk", REFLECTIVITY["sidewalk"], walks)
    # markings: zebra crossings and dashed centre lines, 5 mm thick, class road
    crossings, marks = [], []
    c0, c1 = R + kw + p.crossing_offset, R + kw + p.crossing_offset + p.crossing_width
    starts = {}  # (axis, sign) of each arm -> m from the centre beyond which its centre line, parking strip and kerb-side items run
    for axis in (0, 1):
        for sign in (-1, 1):
            if not j.has_arm(axis, sign):
                continue
            crossed = (axis, sign) in j.crossings
            starts[axis, sign] = c1 if crossed else 0.0
            if crossed:
                crossings.append((axis, sign, c0, c1))
            for k in range(int((2 * R) // 1.0) if crossed else 0):
                across0 = -R + 0.25 + k * 1.0
                if across0 + 0.5 > R - 0.1:
                    break
                lo, hi = sorted((sign * c0, sign * c1))
                marks.append(box_mesh(lo, hi, across0, across0 + 0.5, 0.0, MARKING_THICKNESS) if axis == 0
                             else box_mesh(across0, across0 + 0.5, lo, hi, 0.0, MARKING_THICKNESS))
            for s in np.arange(starts[axis, sign] + 1.0, A - 3.0, 6.0):  # dashed centre line beyond the crossing
                lo, hi = sorted((sign * s, sign * (s + 3.0)))
                marks.append(box_mesh(lo, hi, -0.06, 0.06, 0.0, MARKING_THICKNESS) if axis == 0 else box_mesh(-0.06, 0.06, lo, hi, 0.0, MARKING_THICKNESS))
    add("street_markings", "road", REFLECTIVITY["marking"], primitives.merge(marks))
    lanes = _lanes(p, R, starts)
    # traffic lights at the corners beside the road along y's arms, facing the approaching traffic; signs along the sidewalks
    poles = []
    light_meshes, sign_meshes = [], []
    for sx in (-1, 1):
        for sy in j.arms:
            x, y = sx * (inner + 0.5), sy * (inner + 0.5)
            if not clear.clear_of_box((x, y), (0.15, 0.15), 0.0, 0.0, kh + 3.9):
                continue
            pole = primitives.translated(primitives.cylinder(0.07, 3.0, 8), (x, y, kh + 1.5))
            head = box_mesh(x - 0.15, x + 0.15, y - 0.15, y + 0.15, kh + 3.0, kh + 3.9)
            light_meshes.append(primitives.merge([pole, head]))
            poles.append((x, y, 0.2))
    for k, mesh in enumerate(light_meshes):
        add(f"street_traffic_light_{k}", "traffic light", REFLECTIVITY["traffic light"], mesh)
    for k in range(p.signs):
        axis, sx, sy = int(rng.integers(2)), int(rng.choice([-1, 1])), int(rng.choice([-1, 1]))
        axis = axis if j.has_arm(axis, sy) else 0  # by the road along x where the drawn arm is missing
        s = float(rng.uniform(c1 + 2.0, A - 2.0))
        x, y = (sx * s, sy * (inner + 0.4)) if axis == 0 else (sx * (inner + 0.4), sy * s)
        if not clear.clear_of_circle((x, y), 0.31, 0.0, kh + 2.8):  # the pole and its turning plate
            continue
        pole = primitives.translated(primitives.cylinder(0.04, 2.2, 8), (x, y, kh + 1.1))
        facing = 0.0 if axis == 1 else math.pi / 2
        plate = transformed(box_mesh(-0.02, 0.02, -0.3, 0.3, 0.0, 0.6), (x, y), facing, kh + 2.2)
        sign_meshes.append(primitives.merge([pole, plate]))
        poles.append((x, y, 0.35))
    for k, mesh in enumerate(sign_meshes):
        add(f"street_traffic_sign_{k}", "traffic sign", REFLECTIVITY["traffic sign"], mesh)
    # what real streets hold beside their roads: terrain, plots with buildings or gardens, fences, hedges,
    # walls, street trees, lamps, furniture and road works (builders/street/dressing.py)
    from .dressing import dress

    dressing = dress(p, R, inner, outer, kh, starts, j.arms, rng, clear)
    for mesh, front in zip(dressing.buildings, dressing.fronts, strict=True):
        add(f"street_building_{len(parts):03d}", "building", draw_reflectivity(rng, BUILDING), mesh)
        parts[-1] = dataclasses.replace(parts[-1], front=front)
    for name, class_name, reflectivity, mesh, scatter in dressing.parts:
        add(name, class_name, reflectivity, mesh, scatter=scatter)
    poles += dressing.circles
    return StreetLayout(parts, lanes, R, inner, outer, A, kh, crossings, np.array(poles, float).reshape(-1, 3), walk_rects, dressing.blocks, dressing.counts,
                        dressing.yards, j, _scale(p, R, c1, lanes, walk_rects))


def _lanes(p, R: float, starts: dict) -> list[Lane]:
    """Drive lanes along the arms ``starts`` holds (``(axis, sign)``: the road along x's through the junction, a lone
    y arm's from the road along x's edge) and, with ``parking_width``, one parking strip per arm and side from 1 m
    beyond ``starts[axis, sign]`` (m from the centre: the arm's crossing's far edge, or 0) to 1 m before the arm's end."""
    lw, n, pw, A = p.lane_width, p.lanes_per_direction, p.parking_width, p.arm_length
    lanes = []
    for axis in (0, 1):
        for direction in (1, -1):
            if (axis, direction) not in starts and (axis, -direction) not in starts:
                continue
            first = -direction * A if (axis, -direction) in starts else direction * R  # where the lane enters and leaves the road
            last = direction * A if (axis, direction) in starts else -direction * R
            for k in range(n):
                offset = -direction * (k + 0.5) * lw  # keep right
                a, b = np.array([first, offset]), np.array([last, offset])
                lanes.append(Lane(a if axis == 0 else a[::-1].copy(), b if axis == 0 else b[::-1].copy(), lw, "drive", axis))
            if pw > 0:
                offset = -direction * (n * lw + pw / 2)
                for end in (1, -1):  # one parking strip per arm and side, from beyond the crossing to the arm's end
                    if (axis, end) not in starts:
                        continue
                    s0, s1 = starts[axis, end] + 1.0, A - 1.0
                    a = np.array([end * s0 if direction * end > 0 else end * s1, offset])
                    b = np.array([end * s1 if direction * end > 0 else end * s0, offset])
                    lanes.append(Lane(a if axis == 0 else a[::-1].copy(), b if axis == 0 else b[::-1].copy(), pw, "parking", axis))
    return lanes


def _scale(p, R: float, c1: float, lanes: list[Lane], walk_rects) -> dict:
    """Per ``drive``, ``parking`` and ``sidewalk``: the street's drive lanes' length (parking strips' length, sidewalks'
    area) over those of the four-arm intersection of the same ``p`` (:attr:`StreetLayout.scale`)."""
    four = _lanes(p, R, {(axis, sign): c1 for axis in (0, 1) for sign in (-1, 1)})

    def extent(lanes, rects) -> dict:
        return {kind: sum(lane.length for lane in lanes if lane.kind == kind) for kind in ("drive", "parking")} | {
            "sidewalk": sum((x1 - x0) * (y1 - y0) for x0, x1, y0, y1 in rects)}

    street, reference = extent(lanes, walk_rects), extent(four, road_meshes(p, FOUR_ARMS)[3])
    return {kind: street[kind] / reference[kind] if reference[kind] > 0 else 1.0 for kind in street}


# ----------------------------------------------------------------------------- road users
@dataclass
class RoadUser:
    """One placed road user: kind, centre (2,) m, yaw (radians), size (3,) m (box), z of its base, the lane or area it uses.

    pose_angles : a pedestrian's or rider's joint angles (degrees), ``None`` for vehicles
    """

    kind: str
    centre: np.ndarray
    yaw: float
    size: np.ndarray
    z: float
    where: str  # lane:<i> | parking:<i> | sidewalk | crossing
    pose_angles: np.ndarray | None = None
    build: float = 1.0

    @property
    def half(self) -> np.ndarray:
        return self.size[:2] / 2


@dataclass
class Placement:
    """What :func:`place_users` did: the users and, per kind, how many were wanted, placed, refused for the view."""

    users: list[RoadUser] = field(default_factory=list)
    wanted: dict = field(default_factory=dict)
    out_of_view: dict = field(default_factory=dict)
    collisions: int = 0
    near_sensor: int = 0
    platoons: int = 0


def _draw_size(kind: str, rng) -> np.ndarray:
    spread = SPREAD[kind]
    return np.array(NOMINAL_SIZE[kind]) * (1.0 + rng.uniform(-spread, spread, 3))


def place_users(p, layout: StreetLayout, rng: np.random.Generator, views=(), tries: int = 40, reserved=(), clear: SensorPoses = NO_POSES) -> Placement:
    """Road users of one frame for :class:`~bpy_pipeline.builders.street.StreetScene` ``p`` on ``layout``.

    views : the sensors' :class:`FieldOfView` s, used when ``p.fov_aware`` (otherwise ignored)
    Each user gets up to ``tries`` candidate positions; the first that is free (and in view) is kept.
    reserved : rectangles ``(centre (2,), half (2,), yaw)`` kept free besides the layout's obstacles (the ego car)
    clear : the run's sensor poses: a user whose box comes within their radius is refused (``near_sensor``)
    """
    from ...geometry.placement import sample, sample_count

    views = list(views) if p.fov_aware else []
    out = Placement()
    obstacles = [(np.array(pl[:2]), np.array([pl[2], pl[2]]), 0.0) for pl in layout.poles] + list(layout.blocks) + list(reserved)
    drive = [i for i, lane in enumerate(layout.lanes) if lane.kind == "drive"]
    parking = [i for i, lane in enumerate(layout.lanes) if lane.kind == "parking"]
    last_in_lane: dict[int, RoadUser] = {}

    grow = p.clearance / 2.0
    # the obstacles', then the placed users' rectangles: centres (n, 2) and circumscribed radii grown by clearance / 2 (n,)
    reach = [np.array([c[:2] for c, _, _ in obstacles], float).reshape(-1, 2), np.array([math.hypot(h[0] + grow, h[1] + grow) for _, h, _ in obstacles])]
    rectangles = list(obstacles)  # (centre, half, yaw) in reach's order

    def free(centre, half, yaw) -> bool:
        """No obstacle, then no placed user, overlaps the rectangle (each tested in that order)."""
        for k in rectangles_near(centre, half, p.clearance, *reach):
            c, h, y = rectangles[k]
            if rectangles_overlap(centre, half, yaw, c, h, y, p.clearance):
                return False
        return True

    def accept(user: RoadUser) -> bool:
        half = user.half
        if not free(user.centre, half, user.yaw):
            out.collisions += 1
            return False
        if not clear.clear_of_box(user.centre, half, user.yaw, user.z, user.z + user.size[2]):
            out.near_sensor += 1
            return False
        if in_view_fraction(views, user.centre, half, user.yaw, user.size[2], user.z) < p.min_in_view:
            out.out_of_view[user.kind] = out.out_of_view.get(user.kind, 0) + 1
            return False
        out.users.append(user)
        rectangles.append((user.centre, half, user.yaw))
        reach[0] = np.vstack([reach[0], np.asarray(user.centre, float)[None, :2]])
        reach[1] = np.append(reach[1], math.hypot(half[0] + grow, half[1] + grow))
        return True

    shares = np.array([p.vehicle_mix.get(k, 0.0) for k in VEHICLES], float)
    shares = shares / shares.sum()
    # moving vehicles along the drive lanes, platooning
    wanted = _scaled(sample_count(p.vehicles, rng), layout, "drive")
    out.wanted["vehicles"] = wanted
    for _ in range(wanted):
        kind = VEHICLES[int(rng.choice(len(VEHICLES), p=shares))]
        size = _draw_size(kind, rng)
        for _ in range(tries):
            i = drive[int(rng.integers(len(drive)))]
            lane = layout.lanes[i]
            leader = last_in_lane.get(i)
            if leader is not None and rng.random() < p.platoon_probability:
                s_leader = float(np.dot(leader.centre - lane.start, lane.direction))
                s = s_leader - (leader.size[0] + size[0]) / 2 - float(sample(p.platoon_gap, rng))
                platoon = True
            else:
                s = float(rng.uniform(size[0] / 2, lane.length - size[0] / 2))
                platoon = False
            if not size[0] / 2 <= s <= lane.length - size[0] / 2:
                continue
            user = RoadUser(kind, lane.at(s), lane.heading, size, MARKING_THICKNESS, f"lane:{i}")
            if accept(user):
                last_in_lane[i] = user
                out.platoons += platoon
                break
    # parked cars in the parking strips
    wanted = _scaled(sample_count(p.parked, rng), layout, "parking") if parking else 0
    out.wanted["parked"] = wanted
    for _ in range(wanted):
        kind = "car" if rng.random() < 0.85 else "van"
        size = _draw_size(kind, rng)
        for _ in range(tries):
            lane = layout.lanes[i := parking[int(rng.integers(len(parking)))]]
            s = float(rng.uniform(size[0] / 2, lane.length - size[0] / 2))
            play = min(0.1, max(lane.width - size[1], 0.0) / 2)  # off the strip's middle, the footprint inside the strip
            if accept(RoadUser(kind, lane.at(s, lateral=float(rng.uniform(-play, play))), lane.heading, size, MARKING_THICKNESS, f"parking:{i}")):
                break
    # cyclists and motorcyclists at the right edge of the rightmost drive lanes
    rightmost = [i for i in drive if abs(abs(_lane_offset(layout.lanes[i])) - (p.lanes_per_direction - 0.5) * p.lane_width) < 1e-6]
    for kind, dist in (("bicycle", p.bicycles), ("motorcycle", p.motorcycles)):
        wanted = _scaled(sample_count(dist, rng), layout, "drive")
        out.wanted[kind] = wanted
        for _ in range(wanted):
            size = _draw_size(kind, rng)
            for _ in range(tries):
                lane = layout.lanes[i := rightmost[int(rng.integers(len(rightmost)))]]
                s = float(rng.uniform(size[0] / 2, lane.length - size[0] / 2))
                lateral = -(lane.width / 2 - size[1] / 2 - 0.3) if kind == "bicycle" else float(rng.uniform(-0.5, 0.5))
                if accept(RoadUser(kind, lane.at(s, lateral), lane.heading, size, MARKING_THICKNESS, f"lane:{i}")):
                    break
    # pedestrians on sidewalks and crossings
    sidewalks = _sidewalks(layout)
    wanted = _scaled(sample_count(p.pedestrians, rng), layout, "sidewalk")
    out.wanted["person"] = wanted
    for _ in range(wanted):
        size = _draw_size("person", rng)
        size[:2] = 0.7  # the footprint a walking body needs
        for _ in range(tries):
            if rng.random() < p.crossing_share:
                axis, sign, s0, s1 = layout.crossings[int(rng.integers(len(layout.crossings)))]
                along = sign * float(rng.uniform(s0 + 0.4, s1 - 0.4))
                across = float(rng.uniform(-layout.half_road + 0.4, layout.half_road - 0.4))
                centre = np.array([along, across]) if axis == 0 else np.array([across, along])
                yaw = (math.pi / 2 if axis == 0 else 0.0) + (math.pi if rng.random() < 0.5 else 0.0)
                where, z = "crossing", MARKING_THICKNESS
            else:
                centre, axis = _sidewalk_point(layout, rng, sidewalks)
                yaw = (0.0 if axis == 0 else math.pi / 2) + (math.pi if rng.random() < 0.5 else 0.0) + float(rng.normal(0.0, 0.15))
                where, z = "sidewalk", layout.kerb_height
            if accept(RoadUser("person", centre, yaw, size, z, where)):
                break
    return out


def _scaled(count: int, layout: StreetLayout, extent: str) -> int:
    """``count`` road users drawn for the four-arm intersection, scaled to ``layout``'s ``extent`` (:attr:`StreetLayout.scale`)."""
    scale = layout.scale.get(extent, 1.0)
    return count if scale == 1.0 else int(round(count * scale))


def _lane_offset(lane: Lane) -> float:
    """Signed distance of a drive lane's centre line from its road's centre line."""
    return float(lane.start[1] if lane.road == 0 else lane.start[0])


def _sidewalks(layout: StreetLayout) -> tuple[np.ndarray, np.ndarray]:
    """What :func:`_sidewalk_point` draws from on a junction with fewer than four arms: the sidewalk rectangles
    (:attr:`StreetLayout.walks`) 0.4 m in from their edges, ``(x0, x1, y0, y1)`` (k, 4) m, and each one's share of
    their area (k,)."""
    rects = np.array(layout.walks, float).reshape(-1, 4)
    size = np.column_stack([rects[:, 1] - rects[:, 0], rects[:, 3] - rects[:, 2]])
    margin = np.minimum(0.4, size / 2)  # a sidewalk narrower than 0.8 m: its middle
    return rects + np.column_stack([margin[:, 0], -margin[:, 0], margin[:, 1], -margin[:, 1]]), size.prod(1) / size.prod(1).sum()


def _sidewalk_point(layout: StreetLayout, rng, sidewalks: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, int]:
    """A point (2,) drawn uniformly on the sidewalks (0.4 m from their edges) and the axis of the road it runs along.

    Four arms: eight bands of one length, each from the corner square out (the square belongs to the road along
    x's band); fewer: the rectangles of ``sidewalks`` (:func:`_sidewalks`) by their area."""
    if layout.junction.arms == FOUR_ARMS.arms:
        lo, hi, A = layout.walk_inner + 0.4, layout.walk_outer - 0.4, layout.arm_length - 0.5
        band = float(rng.uniform(lo, hi)) * float(rng.choice([-1, 1]))
        along = float(rng.uniform(lo, A)) * float(rng.choice([-1, 1]))
        centre = np.array([along, band]) if rng.random() < 0.5 else np.array([band, along])
        return centre, 0 if abs(centre[1]) < abs(centre[0]) else 1
    rects, shares = sidewalks
    x0, x1, y0, y1 = rects[int(rng.choice(len(rects), p=shares))]
    return np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)]), 0 if x1 - x0 > y1 - y0 else 1


# ----------------------------------------------------------------------------- the users' meshes
def user_meshes(user: RoadUser, rng: np.random.Generator, fittings: bool = True) -> list[tuple[str, str, str, float, Mesh]]:
    """``[(part, class, material, reflectivity, mesh (world))]`` of one placed road user.

    A vehicle's paint reflectivity is drawn from ``rng`` (:data:`PAINT`), a person's or rider's clothing too
    (:data:`CLOTHING`); with ``fittings`` its plates
    (``retroreflector``) and lamps (``glossy_paint``) follow its parts (:func:`~.vehicles.vehicle_fittings`, no
    draw); a pedestrian walks or stands (:func:`~.human.sample_pose`); a rider sits on the saddle, hands towards the bar, labelled by
    its vehicle (:data:`RIDER_CLASS`: ``rider`` on a bicycle, ``motorcyclist`` on a motorcycle).
    """
    return users_meshes([user], rng, fittings)[0]


def users_meshes(users: list[RoadUser], rng: np.random.Generator, fittings: bool = True) -> list[list[tuple[str, str, str, float, Mesh]]]:
    """:func:`user_meshes` of each of ``users`` in turn, the same draws from ``rng`` in the same order and the same meshes;
    the pedestrians' and riders' bodies are posed and meshed together (:func:`~.human.pose_people`,
    :func:`~.human.body_meshes`) once every user's draws are made."""
    from ...geometry import human

    out, bodies, vehicles = [], [], []  # bodies: (user's index, part, class, clothing, pose_person's arguments); vehicles: (index, paint)
    for user in users:
        if user.kind in VEHICLES:
            out.append([])
            vehicles.append((len(out) - 1, draw_reflectivity(rng, PAINT)))
            continue
        build = float(rng.choice(list(human.BUILDS.values())))
        if user.kind == "person":
            angles = human.sample_pose("walking" if rng.random() < 0.7 else "standing", rng, build)
            pose = (angles, float(user.size[2]), build, "walking", user.centre, user.yaw, user.z)
            out.append([])
            bodies.append((len(out) - 1, "body", "person", draw_reflectivity(rng, CLOTHING), pose))
            continue
        parts = two_wheeler_parts(user.kind, user.size)
        out.append([(name, user.kind, "diffuse", REFLECTIVITY["frame"] if name == "frame" else REFLECTIVITY["tyre"],
                     transformed(mesh, user.centre, user.yaw, user.z)) for name, mesh in parts.items()])
        angles = human.sample_pose("sitting", rng, build)
        seat = saddle_height(user.kind, user.size)
        c, s = math.cos(user.yaw), math.sin(user.yaw)
        hip = user.centre + np.array([c, s]) * (-0.1 * user.size[0] - 0.05)
        pose = (angles, 0.95 * float(user.size[2]), build, "sitting", hip, user.yaw, user.z + seat + 0.005)
        bodies.append((len(out) - 1, "rider", RIDER_CLASS[user.kind], draw_reflectivity(rng, CLOTHING), pose))
    shapes = vehicles_parts([users[k].kind for k, _ in vehicles], [users[k].size for k, _ in vehicles], fittings)
    for (k, paint), parts in zip(vehicles, shapes):
        user = users[k]
        surfaces = {"body": ("diffuse", paint), "glass": ("glass", REFLECTIVITY["glass"]), "tyres": ("diffuse", REFLECTIVITY["tyre"]), **FITTINGS}
        named = [(name, mesh) for name, mesh in parts.items() if len(mesh[1])]
        moved = transformed_parts([mesh for _, mesh in named], user.centre, user.yaw, user.z)
        out[k] = [(name, user.kind, *surfaces[name], mesh) for (name, _), mesh in zip(named, moved)]
    people = human.pose_people(*map(list, zip(*(body[4] for body in bodies)))) if bodies else []
    for (k, part, class_name, clothing, _), mesh in zip(bodies, human.body_meshes(people, 8, 2)):
        out[k].append((part, class_name, "diffuse", clothing, mesh))
    return out


# ----------------------------------------------------------------------------- checks
def segments_cross_triangles(a: np.ndarray, b: np.ndarray, triangles: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """``(n,)`` bool: whether segment ``a[i]``-``b[i]`` ((n, 3) each) passes through the interior of any of
    ``triangles`` (m, 3, 3). Touching (an end on a face, a segment in a face's plane) does not count."""
    hit = np.zeros(len(a), bool)
    if len(a) == 0 or len(triangles) == 0:
        return hit
    d = b - a
    e1, e2 = triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    for start in range(0, len(a), 256):
        da, aa = d[start : start + 256, None], a[start : start + 256, None]
        h = np.cross(da, e2[None])
        det = np.einsum("ijk,jk->ij", h, e1)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = aa - triangles[None, :, 0]
        u = inv * np.einsum("ijk,ijk->ij", s, h)
        q = np.cross(s, e1[None])
        v = inv * np.einsum("ijk,ijk->ij", da * np.ones_like(q), q)
        t = inv * np.einsum("jk,ijk->ij", e2, q)
        inside = ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > eps) & (t < 1 - eps)
        hit[start : start + 256] = inside.any(axis=1)
    return hit


def meshes_intersect(first: Mesh, second: Mesh) -> bool:
    """True when an edge of one mesh passes through a triangle of the other.

    Only the triangles of each mesh that reach into the other's bounding box take part, so a
    small mesh against a large one (a pedestrian against the street's terrain) costs little.
    """
    (v1, t1), (v2, t2) = first, second
    if (v1.min(0) > v2.max(0) + 1e-6).any() or (v2.min(0) > v1.max(0) + 1e-6).any():
        return False

    def reaching(v, t, other):
        corners = v[t]
        keep = ((corners.min(axis=1) <= other.max(0) + 1e-6) & (corners.max(axis=1) >= other.min(0) - 1e-6)).all(axis=1)
        return t[keep]

    t1, t2 = reaching(v1, t1, v2), reaching(v2, t2, v1)
    if len(t1) == 0 or len(t2) == 0:
        return False
    for (va, ta), (vb, tb) in (((v1, t1), (v2, t2)), ((v2, t2), (v1, t1))):
        edges = np.unique(np.sort(np.concatenate([ta[:, [0, 1]], ta[:, [1, 2]], ta[:, [2, 0]]]), axis=1), axis=0)
        if segments_cross_triangles(va[edges[:, 0]], va[edges[:, 1]], vb[tb]).any():
            return True
    return False
