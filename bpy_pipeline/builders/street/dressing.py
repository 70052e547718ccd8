"""What real streets hold beside their roads: terrain, plots with buildings or gardens, their fences,
hedges and walls, street trees, lamps, bins, bicycle stands, bollards and road works. Pure numpy.

The sim-to-real benchmark showed why this exists: a model trained on a street of roads, kerbs,
facades and road users alone called real trees, fences, terrain and walls cars and people,
because it had never seen them. Everything here is static (drawn once from the layout's
generator) and laid out per corner block of the junction of :mod:`.layout` (where the road along y has no
arm, the two blocks on that side meet at x = 0 and the plots along the road along x run through):

- *terrain*: each block beyond the sidewalks is ground (class ``terrain``): a height field at
  ``terrain_step`` metres that leaves the sidewalk's edge at its height and then rolls gently
  (``terrain_relief`` metres of amplitude, ``terrain_slope`` of rise away from the road), with 2 cm
  of roughness per vertex, as grass verges and open ground are;
- *plots* along each frontage, ``building_width`` wide: a building set back ``setback`` metres from
  the sidewalk (its front yard holds bushes and small trees), or, a share ``open_share`` of
  them, an open plot of ground and vegetation ``plot_depth`` deep; each plot's front is a fence
  (bars or boards), a hedge, a low wall or nothing (``boundary_mix``);
- *street trees* on the sidewalk by the kerb (a share ``street_trees`` of the arm sides is lined
  with them, ``tree_spacing`` apart), *lamps* every ``lamp_spacing`` metres, and
  ``furniture_per_100m`` bins, bicycle stands and bollards per side and 100 m, all in the kerb-side
  band of the sidewalk so that pedestrians keep the rest;
- *road works*: with probability ``roadworks`` an arm side's parking strip holds a run of cones
  and construction barriers.

Every item that stands where road users go is an obstacle for their placement: circles
``(x, y, radius)`` and rectangles ``(centre (2,), half (2,), yaw)``. An item that would come within
``clear.radius`` of a sensor pose of the run (:class:`~bpy_pipeline.geometry.clearance.SensorPoses`) is left
out after its draws, so the rest of the street stays the one its seed gives (``counts["near sensor"]``).

Scattered items (trunks, crowns and bushes, lamps and bollards, bins, bicycle stands, cones,
barriers) are *instances*: a :class:`Scatter` holds a few prototype meshes per kind (crowns: a few
variants per shape drawn from the layout's generator) and per item a transform (position, yaw,
scale, prototype). Its :meth:`Scatter.mesh` places the prototypes by those transforms: the pure
reference that the "Street Scatter" Geometry Nodes group (builders/street/scatter_nodes.py) instances
in Blender. Terrain and plot boundaries (fences, walls, hedges) run along the plots and stay plain
meshes; buildings are boxes whose facade lines (``Dressing.fronts``) the "Street Facade" group
(builders/street/facade_nodes.py) sweeps in Blender.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...geometry import primitives
from ...geometry.clearance import NO_POSES, SensorPoses
from ...geometry.primitives import beam_mesh, beams_mesh, box_mesh, transformed
from . import vegetation

Mesh = tuple[np.ndarray, np.ndarray]

# reflectivity at 905 nm (of the order measured for each material: leaves 0.4-0.6 in the near infrared, bark 0.3,
# grass 0.4, grey paint and concrete 0.3-0.4, dark plastic 0.1-0.2); vegetation, terrain and pole fitted with the
# hdl64e reading to SemanticKITTI's remission (docs/realism.md, "The HDL-64E's reading, fitted per class")
REFLECTIVITY = {"vegetation": 0.35, "trunk": 0.3, "terrain": 0.4, "pole": 0.2, "fence": 0.3, "wall": 0.35,
                "barrier": 0.5, "traffic cone": 0.55, "bin": 0.15, "bicycle stand": 0.4}
BOUNDARIES = ("fence", "hedge", "wall", "none")
MAX_TERRAIN_VERTICES = 2_000_000  # a terrain block's grid (1 m steps over 1,400 x 1,400 m); a finer one's arrays run to gigabytes
LEAF_CARD = 0.25  # m: how far a crown's or hedge's leaf cards may reach beyond its nominal size (half a 0.4-0.5 m card)


def place(mesh: Mesh, position, yaw: float = 0.0, scale=(1.0, 1.0, 1.0)) -> Mesh:
    """``mesh`` scaled by ``scale`` (3,) along its own axes, turned by ``yaw`` (radians) about z and moved to ``position`` (3,) m."""
    c, s = math.cos(yaw), math.sin(yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return (mesh[0] * np.asarray(scale, float)) @ rotation.T + np.asarray(position, float), mesh[1]


@dataclass
class Scatter:
    """Items of one kind as prototypes placed by transforms (what a Geometry Nodes group instances).

    prototypes : ``[Mesh]``, each in an item's own frame (m, z up, its origin where the item stands)
    per item, in the order added: ``positions`` (k, 3) m, ``yaw`` (k,) radians about z, ``scale``
    (k, 3) along the prototype's axes, ``prototype`` (k,) int, an index into ``prototypes``
    """

    prototypes: list[Mesh] = field(default_factory=list)
    items: list[tuple[int, tuple, float, tuple]] = field(default_factory=list)

    def add(self, prototype: int, position, yaw: float = 0.0, scale=(1.0, 1.0, 1.0)) -> None:
        self.items.append((int(prototype), tuple(float(v) for v in position), float(yaw), tuple(float(v) for v in scale)))

    @property
    def positions(self) -> np.ndarray:
        return np.array([i[1] for i in self.items], float).reshape(-1, 3)

    @property
    def yaw(self) -> np.ndarray:
        return np.array([i[2] for i in self.items], float)

    @property
    def scale(self) -> np.ndarray:
        return np.array([i[3] for i in self.items], float).reshape(-1, 3)

    @property
    def prototype(self) -> np.ndarray:
        return np.array([i[0] for i in self.items], np.int32)

    def mesh(self) -> Mesh:
        """Every item's prototype placed by its transform (:func:`place`), merged in item order."""
        return primitives.merge([place(self.prototypes[k], position, yaw, scale) for k, position, yaw, scale in self.items])


@dataclass
class Yards:
    """Where and what the "Street Planting" group (builders/street/planting_nodes.py) plants: ``rects``
    ``[(x0, x1, y0, y1)]`` (m), each yard or open plot 1 m inside its bounds; ``terrain`` their ground;
    ``trunk`` the unit cylinder (radius 1, z 0..1); ``crowns`` the round leaf-card crowns (:data:`CROWN_VARIANTS`)
    scaled to radius 1 and height 1, centred on the origin."""

    rects: list[tuple[float, float, float, float]]
    terrain: Terrain
    trunk: Mesh
    crowns: list[Mesh]


@dataclass
class Dressing:
    """The dressing of one street: ``parts`` ``[(name, class, reflectivity, mesh, scatter)]`` (``scatter`` the
    :class:`Scatter` whose :meth:`~Scatter.mesh` ``mesh`` is, or ``None`` for a plain mesh) and the obstacles it adds."""

    parts: list[tuple[str, str, float, Mesh, Scatter | None]] = field(default_factory=list)
    circles: list[tuple[float, float, float]] = field(default_factory=list)
    blocks: list[tuple[np.ndarray, np.ndarray, float]] = field(default_factory=list)
    buildings: list[Mesh] = field(default_factory=list)
    fronts: list[tuple[np.ndarray, np.ndarray, float, float]] = field(default_factory=list)  # per building: start (3,), end (3,), depth, height (m); see dress
    yards: Yards | None = None  # where the "Street Planting" group may add trees
    counts: dict = field(default_factory=dict)

    def count(self, what: str, n: int = 1) -> None:
        self.counts[what] = self.counts.get(what, 0) + n


# ----------------------------------------------------------------------------- terrain
@dataclass(frozen=True)
class Terrain:
    """The ground beyond the sidewalks: ``z(x, y)`` (m) at world ``x, y`` of a corner block.

    ``d``, the distance from the nearest sidewalk's outer edge (the road along y's only on the sides ``arms`` of
    its arms), sets the shape: the ground meets
    the sidewalk 3 cm below its top and rises by ``slope * d`` plus a smooth relief of
    ``relief`` metres (a sum of ``waves`` (k, 4): amplitude share, kx, ky, phase), faded in over 4 m.
    """

    walk_outer: float
    top: float
    relief: float
    slope: float
    waves: np.ndarray
    arms: tuple[int, ...] = (-1, 1)

    def z(self, x, y) -> np.ndarray:
        x, y = np.asarray(x, float), np.asarray(y, float)
        across_y_road = np.where(np.isin(np.where(y < 0, -1, 1), self.arms), np.abs(x), np.inf)  # no arm on y's side: only the road along x is near
        d = np.maximum(np.minimum(across_y_road, np.abs(y)) - self.walk_outer, 0.0)
        rolling = np.zeros(np.broadcast(x, y).shape)
        for share, kx, ky, phase in self.waves:
            rolling = rolling + share * np.sin(kx * x + ky * y + phase)
        return self.top - 0.03 + self.slope * d + self.relief * (1.0 - np.exp(-d / 4.0)) * rolling


def make_terrain(walk_outer: float, top: float, relief: float, slope: float, rng: np.random.Generator, arms: tuple[int, ...] = (-1, 1)) -> Terrain:
    """A :class:`Terrain` with four waves of 15-60 m wavelength drawn from ``rng`` beside the road along y's ``arms``."""
    k = 2 * math.pi / rng.uniform(15.0, 60.0, 4)
    angle = rng.uniform(0.0, 2 * math.pi, 4)
    share = rng.uniform(0.5, 1.0, 4)
    share /= share.sum()
    waves = np.column_stack([share, k * np.cos(angle), k * np.sin(angle), rng.uniform(0.0, 2 * math.pi, 4)])
    return Terrain(walk_outer, top, relief, slope, waves, tuple(arms))


def _height_grid(terrain: Terrain, x0: float, x1: float, y0: float, y1: float, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(x, y, z, triangles)``: the ground over ``[x0, x1] x [y0, y1]`` sampled at about ``step`` metres;
    ``x, y, z`` (nx, ny) grids (m), ``triangles`` (2 (nx-1) (ny-1), 3) int32 into their raveled order."""
    nx, ny = max(2, int(math.ceil((x1 - x0) / step)) + 1), max(2, int(math.ceil((y1 - y0) / step)) + 1)
    if nx * ny > MAX_TERRAIN_VERTICES:
        raise InputError(f"scene.terrain_step: {step:g} m makes the ground beside the road a grid of {nx:,} x {ny:,} vertices over "
                         f"{x1 - x0:.0f} x {y1 - y0:.0f} m, more than {MAX_TERRAIN_VERTICES:,}; give a coarser terrain_step or shorter arms")
    gx, gy = np.meshgrid(np.linspace(x0, x1, nx), np.linspace(y0, y1, ny), indexing="ij")
    i = np.arange(nx - 1)[:, None] * ny + np.arange(ny - 1)[None, :]
    i = i.ravel()
    triangles = np.concatenate([np.column_stack([i, i + ny, i + ny + 1]), np.column_stack([i, i + ny + 1, i + 1])])
    return gx, gy, terrain.z(gx, gy), triangles.astype(np.int32)


def terrain_mesh(terrain: Terrain, x0: float, x1: float, y0: float, y1: float, step: float, rng: np.random.Generator) -> Mesh:
    """A height-field mesh over ``[x0, x1] x [y0, y1]`` at about ``step`` metres, with 2 cm of roughness
    inside (its border vertices keep their height so that neighbouring blocks meet the sidewalk)."""
    gx, gy, z, triangles = _height_grid(terrain, x0, x1, y0, y1, step)
    rough = rng.normal(0.0, 0.02, z.shape)
    rough[[0, -1], :] = 0.0
    rough[:, [0, -1]] = 0.0
    return np.column_stack([gx.ravel(), gy.ravel(), (z + rough).ravel()]), triangles


def yard_ground(terrain: Terrain, yards, step: float = 2.0) -> Mesh:
    """The ground of ``yards`` ``[(x0, x1, y0, y1)]`` (m; :attr:`Dressing.yards`), without the terrain's roughness,
    sampled at about ``step`` metres: where the "Street Planting" group distributes its trees."""
    if not yards:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int32)
    grids = [_height_grid(terrain, *yard, step) for yard in yards]
    return primitives.merge([(np.column_stack([gx.ravel(), gy.ravel(), z.ravel()]), triangles) for gx, gy, z, triangles in grids])


# ----------------------------------------------------------------------------- furniture meshes
def cone_mesh(base, radius: float, height: float, sides: int = 10) -> Mesh:
    """A traffic cone: a cone of ``radius`` and ``height`` on a square foot, standing at ``base`` (3,)."""
    angle = np.linspace(0.0, 2 * math.pi, sides, endpoint=False)
    ring = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.full(sides, 0.03)])
    vertices = np.vstack([ring, [[0.0, 0.0, height]]])
    k = np.arange(sides)
    triangles = np.column_stack([k, (k + 1) % sides, np.full(sides, sides)]).astype(np.int32)
    foot = primitives.translated(primitives.box(2.2 * radius, 2.2 * radius, 0.03), (0.0, 0.0, 0.015))
    return primitives.translated(primitives.merge([(vertices, triangles), foot]), base)


def hoop_mesh(base, yaw: float, width: float = 0.6, height: float = 0.8, thickness: float = 0.05) -> Mesh:
    """A bicycle stand's hoop: two posts and a top bar of ``thickness`` (m) square tube, across ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    base = np.asarray(base, float)
    a = base + [-s * width / 2, c * width / 2, 0.0]
    b = base + [s * width / 2, -c * width / 2, 0.0]
    up = np.array([0.0, 0.0, height])
    return primitives.merge([beam_mesh(a - [0, 0, 0.1], a + up, thickness), beam_mesh(b - [0, 0, 0.1], b + up, thickness),
                             beam_mesh(a + up, b + up, thickness)])


def unit_cylinder(sides: int) -> Mesh:
    """A capped cylinder of radius 1 from z = 0 to z = 1 (a pole, trunk or bollard scaled to its radius and length)."""
    return primitives.translated(primitives.cylinder(1.0, 1.0, sides), (0.0, 0.0, 0.5))


def lamp_head_mesh() -> Mesh:
    """A street lamp's arm and head in the lamp's frame: the origin at the pole's top (the lamp's height),
    the arm reaching 1.5 m along +x from 0.1 m below it up to the head 0.25 m above it."""
    tip = np.array([1.5, 0.0, 0.25])
    arm = beam_mesh([0.0, 0.0, -0.1], tip, 0.06)
    head = primitives.translated(box_mesh(-0.35, 0.35, -0.15, 0.15, -0.12, 0.0), tip)
    return primitives.merge([arm, head])


def fence_mesh(start, end, height: float, kind: str, z_at) -> Mesh:
    """A fence from ``start`` to ``end`` ((2,) m) on the ground ``z_at(x, y)``: ``bars`` (posts every 2.5 m,
    two rails and 2 cm bars every 12 cm) or ``boards`` (posts and a closed board panel 2 cm thick)."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    length = float(np.linalg.norm(end - start))
    along = (end - start) / length
    posts = np.linspace(0.0, length, max(2, int(math.ceil(length / 2.5)) + 1))
    ground = lambda s: float(z_at(*(start + s * along)))  # noqa: E731 - the ground below a point at s

    def on_ground(s, low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
        """``(bottoms, tops)`` (k, 3) of uprights at ``s`` (k,) along the fence, from ``low`` to ``high`` above the ground."""
        p = start + np.asarray(s, float)[:, None] * along
        z = np.asarray(z_at(p[:, 0], p[:, 1]), float)
        return np.column_stack([p, z + low]), np.column_stack([p, z + high])

    parts = [beams_mesh(*on_ground(posts, -0.2, height), 0.08)]
    if kind == "boards":
        for s0, s1 in zip(posts[:-1], posts[1:]):
            a, b = start + s0 * along, start + s1 * along
            za, zb = ground(s0), ground(s1)
            lo = min(za, zb) - 0.05
            v = np.array([[*a, lo], [*b, lo], [*b, zb + height - 0.05], [*a, za + height - 0.05]])
            normal = np.array([-along[1], along[0], 0.0]) * 0.01
            front, back = v + normal, v - normal
            vertices = np.vstack([front, back])
            triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]], np.int32)
            parts.append((vertices, triangles))
        return primitives.merge(parts)
    starts, ends, thickness = [], [], []  # per panel: its two rails, then its bars
    for s0, s1 in zip(posts[:-1], posts[1:]):
        a, b = start + s0 * along, start + s1 * along
        za, zb = ground(s0), ground(s1)
        for level in (0.15, height - 0.1):
            starts.append([[*a, za + level]])
            ends.append([[*b, zb + level]])
            thickness.append([0.04])
        bottoms, tops = on_ground(np.arange(s0 + 0.12, s1 - 0.06, 0.12), 0.1, height - 0.05)
        starts.append(bottoms)
        ends.append(tops)
        thickness.append(np.full(len(bottoms), 0.02))
    parts.append(beams_mesh(np.concatenate(starts), np.concatenate(ends), np.concatenate(thickness)))
    return primitives.merge(parts)


def wall_mesh(start, end, height: float, thickness: float, z_at) -> Mesh:
    """A garden wall from ``start`` to ``end`` ((2,) m), ``height`` above the ground ``z_at`` and 0.3 m into it."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    length = float(np.linalg.norm(end - start))
    mid = (start + end) / 2
    low = float(min(z_at(*start), z_at(*end), z_at(*mid))) - 0.3
    top = float(max(z_at(*start), z_at(*end), z_at(*mid))) + height
    yaw = math.atan2(end[1] - start[1], end[0] - start[0])
    return transformed(box_mesh(-length / 2, length / 2, -thickness / 2, thickness / 2, low, top), mid, yaw)


def barrier_mesh(centre, yaw: float, length: float = 2.0) -> Mesh:
    """A construction barrier: a 0.25 m board 1 m high on two A-frame feet, ``length`` along ``yaw``."""
    board = box_mesh(-length / 2, length / 2, -0.02, 0.02, 0.75, 1.0)
    feet = [box_mesh(x - 0.04, x + 0.04, -0.3, 0.3, 0.0, 1.0) for x in (-length / 2 + 0.1, length / 2 - 0.1)]
    return transformed(primitives.merge([board, *feet]), centre[:2], yaw, float(centre[2]))


# ----------------------------------------------------------------------------- prototypes
CROWN_VARIANTS = 3  # prototype crowns per shape (and bushes), drawn from the layout's generator
REFERENCE_TREE = (11.0, 2.5)  # m: height and crown radius of the tree the prototype crowns are drawn for
REFERENCE_BUSH = (0.9, 1.3)  # m: radius and height of the prototype bushes


@dataclass
class Prototypes:
    """The scattered kinds' prototype meshes: ``plants`` (``CROWN_VARIANTS`` crowns per shape of
    :data:`~.vegetation.CROWN_SHAPES`, in that order, centred on the origin, then as many bushes resting
    on it) with ``plant_size`` (k, 2) their radius and height (m); ``poles`` (a unit 8-sided cylinder,
    a lamp's arm and head); ``bins``, ``stands`` (a hoop across x), ``cones``, ``barriers`` (along x)."""

    plants: list[Mesh]
    plant_size: np.ndarray
    poles: list[Mesh]
    bins: list[Mesh]
    stands: list[Mesh]
    cones: list[Mesh]
    barriers: list[Mesh]

    def crown(self, shape: str, variant: int) -> int:
        return vegetation.CROWN_SHAPES.index(shape) * CROWN_VARIANTS + variant

    def bush(self, variant: int) -> int:
        return len(vegetation.CROWN_SHAPES) * CROWN_VARIANTS + variant


def prototypes(rng: np.random.Generator) -> Prototypes:
    """The prototypes of :class:`Prototypes`; the crowns and bushes (leaf cards) are drawn from ``rng``."""
    plants, size = [], []
    height, crown_radius = REFERENCE_TREE
    for shape in vegetation.CROWN_SHAPES:
        radius, crown_height = vegetation.crown_size(shape, height, crown_radius)
        for _ in range(CROWN_VARIANTS):
            plants.append(vegetation.crown(shape, radius, crown_height, rng))
            size.append((radius, crown_height))
    radius, height = REFERENCE_BUSH
    for _ in range(CROWN_VARIANTS):
        plants.append(vegetation.bush((0.0, 0.0, 0.0), radius, height, rng))
        size.append((radius, height))
    return Prototypes(plants, np.array(size), [unit_cylinder(8), lamp_head_mesh()], [primitives.translated(primitives.cylinder(0.3, 1.0, 10), (0.0, 0.0, 0.5))],
                      [hoop_mesh((0.0, 0.0, 0.0), 0.0)], [cone_mesh((0.0, 0.0, 0.0), 0.15, 0.75)], [barrier_mesh(np.zeros(3), 0.0)])


# ----------------------------------------------------------------------------- the dressing
def dress(p, road_half: float, walk_inner: float, walk_outer: float, kerb_height: float, starts: dict, arms: tuple[int, ...],
          rng: np.random.Generator, clear: SensorPoses = NO_POSES) -> Dressing:
    """The dressing of :class:`~bpy_pipeline.builders.street.StreetScene` ``p`` around a junction.

    road_half : R (m), the carriageway's half width to the kerb; walk_inner / walk_outer : the
    sidewalks' inner and outer distance from a road's centre line (m); starts : per arm ``(axis, sign)``, the
    distance from the centre (m) where its crossing ends, or 0 without one (nothing stands on the kerb-side band
    before it); arms : the signs of the road along y's arms (the blocks on a side without one meet at x = 0).
    Buildings are in ``buildings`` (class ``building``), everything else in ``parts``. Each building's
    ``fronts`` entry is its facade line along the plot, ``(start (3,), end (3,), depth, height)`` (m): the
    building is the box standing ``height`` above the line (which lies at the box's bottom, under the
    ground) and reaching ``depth`` to the left of start -> end (away from the road): the reference of the
    "Street Facade" Geometry Nodes group (builders/street/facade_nodes.py).
    clear : the run's sensor poses; an item reaching within their radius is left out (its draws made all the same)
    """
    A = p.arm_length
    out = Dressing()
    kinds = prototypes(rng)
    terrain = make_terrain(walk_outer, kerb_height, p.terrain_relief, p.terrain_slope, rng, arms)
    z_at = terrain.z
    out.yards = Yards([], terrain, kinds.poles[0], [(kinds.plants[k][0] / kinds.plant_size[k][[0, 0, 1]], kinds.plants[k][1])
                                                   for k in (kinds.crown("round", v) for v in range(CROWN_VARIANTS))])
    trunks = Scatter([kinds.poles[0]])  # the unit cylinder, scaled to each trunk's radius and length
    plants = Scatter(kinds.plants)
    poles = Scatter(kinds.poles)  # lamp poles and bollards (the unit cylinder), lamps' arms and heads
    bins, stands, cones, barriers = Scatter(kinds.bins), Scatter(kinds.stands), Scatter(kinds.cones), Scatter(kinds.barriers)
    hedges: list[Mesh] = []
    fences: list[Mesh] = []
    walls: list[Mesh] = []

    def clear_of(centre, size, z0: float, z1: float, yaw: float = 0.0) -> bool:
        """Whether an item's upright box (``size`` (2,): half extents) or cylinder (``size``: radius) keeps clear of the
        sensor poses; counts it left out when not."""
        ok = clear.clear_of_circle(centre, size, z0, z1) if np.isscalar(size) else clear.clear_of_box(centre, size, yaw, z0, z1)
        if not ok:
            out.count("near sensor")
        return ok

    def segment_clear(a, b, width: float, z0: float, z1: float) -> bool:
        """:func:`clear_of` for a fence, hedge or wall ``width`` thick from ``a`` to ``b`` ((2,) m)."""
        a, b = np.asarray(a, float)[:2], np.asarray(b, float)[:2]
        half = (float(np.linalg.norm(b - a)) / 2.0, width / 2.0)
        return clear_of((a + b) / 2.0, half, z0, z1, math.atan2(b[1] - a[1], b[0] - a[0]))

    def plant(x: float, y: float, ground: float, big: bool, street: bool = False) -> bool:
        """A tree (``big``) or a bush at ``(x, y, ground)``; a street tree's crown clears 4.5 m (buses and lamps' arms).
        False when it would stand within reach of a sensor pose (left out).

        Its foliage is a prototype crown (or bush) of its shape, turned at random and scaled to its size."""
        if big:
            shape = vegetation.CROWN_SHAPES[int(rng.integers(len(vegetation.CROWN_SHAPES)))]
            height = float(rng.uniform(8.0, 14.0) if street else rng.uniform(4.0, 14.0))
            radius, crown_height = vegetation.crown_size(shape, height, float(rng.uniform(1.5, 3.5)), clear_below=4.5 if street else 1.5)
            k = kinds.crown(shape, int(rng.integers(CROWN_VARIANTS)))
            r0, h0 = kinds.plant_size[k]
            top = height - crown_height / 2.0  # the crown's centre above the ground
            yaw = float(rng.uniform(0.0, 2 * math.pi))
            r = vegetation.default_trunk_radius(height)  # from 0.2 m under the ground into the crown's middle
            if not (clear_of((x, y), r, ground - 0.2, ground + top)
                    and clear_of((x, y), radius + LEAF_CARD, ground + height - crown_height - LEAF_CARD, ground + height + LEAF_CARD)):
                return False
            plants.add(k, (x, y, ground + top), yaw, (radius / r0, radius / r0, crown_height / h0))
            trunks.add(0, (x, y, ground - 0.2), 0.0, (r, r, top + 0.2))
            out.count("trees")
            return True
        radius, height = float(rng.uniform(0.4, 1.4)), float(rng.uniform(0.6, 2.0))
        k = kinds.bush(int(rng.integers(CROWN_VARIANTS)))
        r0, h0 = kinds.plant_size[k]
        yaw = float(rng.uniform(0.0, 2 * math.pi))
        if not clear_of((x, y), radius + LEAF_CARD, ground - 0.1, ground + height + LEAF_CARD):
            return False
        plants.add(k, (x, y, ground - 0.1), yaw, (radius / r0, radius / r0, height / h0))
        out.count("bushes")
        return True

    def in_block(local_along: float, local_across: float, sx: int, sy: int, axis: int) -> tuple[float, float]:
        """World (x, y) of a point ``local_along`` the frontage and ``local_across`` from the road's centre line."""
        return (sx * local_along, sy * local_across) if axis == 0 else (sx * local_across, sy * local_along)

    shares = np.array([p.boundary_mix.get(k, 0.0) for k in BOUNDARIES], float)
    shares = shares / shares.sum()
    max_setback = float(p.setback[1])
    for sx in (-1, 1):
        for sy in (-1, 1):
            # terrain over the whole corner block beyond the sidewalks (from x = 0 on a side without a y arm)
            block_start = walk_outer if sy in arms else 0.0
            frontages = (0, 1) if sy in arms else (0,)
            if p.terrain:
                x0, x1 = sorted((sx * block_start, sx * A))
                y0, y1 = sorted((sy * walk_outer, sy * A))
                out.parts.append((f"street_terrain_{len(out.parts):03d}", "terrain", REFLECTIVITY["terrain"],
                                  terrain_mesh(terrain, x0, x1, y0, y1, p.terrain_step, rng), None))
            # plots along both frontages (the second starts behind the first's deepest plot)
            for axis in frontages:
                s = block_start if axis == 0 else walk_outer + max_setback + p.building_depth
                while s < A - 2.0:
                    width = min(float(rng.uniform(*p.building_width)), A - s)
                    is_open = rng.random() < p.open_share
                    setback = float(rng.uniform(*p.setback))
                    depth = p.plot_depth if is_open else setback
                    front = walk_outer + 0.2
                    if not is_open:
                        height = float(rng.uniform(*p.building_height))
                        a0, a1 = walk_outer + setback, walk_outer + setback + p.building_depth
                        cx0, cy0 = in_block(s, a0, sx, sy, axis)
                        cx1, cy1 = in_block(s + width, a1, sx, sy, axis)
                        low = float(np.min(z_at(np.array([cx0, cx1, cx0, cx1]), np.array([cy0, cy0, cy1, cy1])))) - 0.3
                        box_centre, box_half = ((cx0 + cx1) / 2, (cy0 + cy1) / 2), (abs(cx1 - cx0) / 2, abs(cy1 - cy0) / 2)
                        is_open = not clear_of(box_centre, box_half, low, low + 0.3 + height)  # left out: its front yard stays
                    if not is_open:
                        out.buildings.append(box_mesh(*sorted((cx0, cx1)), *sorted((cy0, cy1)), low, low + 0.3 + height))
                        start, end = (np.array([*in_block(t, a0, sx, sy, axis), low]) for t in (s, s + width))
                        away = np.array(in_block(0.0, 1.0, sx, sy, axis)) - np.array(in_block(0.0, 0.0, sx, sy, axis))
                        if (end - start)[0] * away[1] - (end - start)[1] * away[0] < 0:  # keep the building on the line's left
                            start, end = end, start
                        out.fronts.append((start, end, float(p.building_depth), 0.3 + height))
                    # the yard (or open plot): plants drawn by area, 1 m inside the plot's bounds (:class:`Yards`), so off the
                    # building; one rectangle (along0..along1, across0..across1) sets both its area and where its plants stand
                    along0, along1 = s + 1.0, s + width - 1.0
                    across0, across1 = walk_outer + 1.0, walk_outer + depth - 1.0
                    area = max(along1 - along0, 0.0) * max(across1 - across0, 0.0)
                    if area > 0.0:
                        (ax, ay), (bx, by) = in_block(along0, across0, sx, sy, axis), in_block(along1, across1, sx, sy, axis)
                        out.yards.rects.append((min(ax, bx), max(ax, bx), min(ay, by), max(ay, by)))
                    for _ in range(int(rng.poisson(p.yard_plants * area / 100.0))):
                        along = float(rng.uniform(along0, along1))
                        across = float(rng.uniform(across0, across1))
                        x, y = in_block(along, across, sx, sy, axis)
                        plant(x, y, float(z_at(x, y)), big=rng.random() < (0.5 if is_open else 0.3))
                    kind = BOUNDARIES[int(rng.choice(len(BOUNDARIES), p=shares))]
                    a = np.array(in_block(s + 0.1, front, sx, sy, axis))
                    b = np.array(in_block(s + width - 0.1, front, sx, sy, axis))
                    line = a + np.linspace(0.0, 1.0, 9)[:, None] * (b - a)
                    ground = min(float(z_at(*a)), float(z_at(*b)))
                    ridge = float(np.max(z_at(line[:, 0], line[:, 1])))  # the ground's highest along the boundary: a fence's or wall's top follows it
                    if kind == "fence":
                        height, style = float(rng.uniform(0.9, 1.8)), "bars" if rng.random() < 0.6 else "boards"
                        if segment_clear(a, b, 0.1, ground - 0.2, ridge + height):
                            fences.append(fence_mesh(a, b, height, style, z_at))
                            out.count("fences")
                    elif kind == "hedge":
                        height = float(rng.uniform(0.8, 2.0))
                        inward = np.array([0.0, 0.5 * sy] if axis == 0 else [0.5 * sx, 0.0])  # the hedge's axis 0.5 m into the plot
                        thickness = float(rng.uniform(0.6, 1.0))
                        hedge = vegetation.hedge([*(a + inward), ground - 0.05], [*(b + inward), ground - 0.05], thickness, height, rng)
                        if segment_clear(a + inward, b + inward, thickness + 2 * LEAF_CARD, ground - 0.05, ground + height + LEAF_CARD):
                            hedges.append(hedge)
                            out.count("hedges")
                    elif kind == "wall":
                        height = float(rng.uniform(0.4, 1.6))
                        if segment_clear(a, b, 0.25, ground - 0.3, ridge + height):
                            walls.append(wall_mesh(a, b, height, 0.25, z_at))
                            out.count("walls")
                    s += width
            # the kerb-side band of the sidewalks of this block's two arm sides
            for axis in frontages:
                band = walk_inner + 0.7
                crossing_end = starts[axis, sx if axis == 0 else sy]
                lined = rng.random() < p.street_trees
                trees_at = []
                if lined and p.tree_spacing[1] > 0:
                    t = crossing_end + 3.0 + float(rng.uniform(0.0, p.tree_spacing[1]))
                    while t < A - 2.0:
                        trees_at.append(t)
                        t += float(rng.uniform(*p.tree_spacing))
                for t in trees_at:
                    x, y = in_block(t, band, sx, sy, axis)
                    if plant(x, y, kerb_height, big=True, street=True):
                        out.circles.append((x, y, 0.45))
                taken = list(trees_at)
                if p.lamp_spacing > 0:
                    t = crossing_end + 2.0 + float(rng.uniform(0.0, p.lamp_spacing))
                    while t < A - 2.0:
                        if all(abs(t - u) > 2.0 for u in taken):
                            x, y = in_block(t, walk_inner + 0.4, sx, sy, axis)
                            facing = math.atan2(-y, 0.0) if axis == 0 else math.atan2(0.0, -x)
                            height = float(rng.uniform(6.0, 9.0))
                            top = kerb_height + height
                            if clear_of((x, y), 0.08, kerb_height - 0.3, top) and clear_of((x, y), 1.9, top - 0.3, top + 0.4):
                                poles.add(0, (x, y, kerb_height - 0.3), 0.0, (0.08, 0.08, height + 0.3))  # 0.3 m into the ground
                                poles.add(1, (x, y, top), facing)
                                out.circles.append((x, y, 0.3))
                                taken.append(t)
                                out.count("lamps")
                        t += p.lamp_spacing
                for _ in range(int(rng.poisson(p.furniture_per_100m * (A - crossing_end) / 100.0))):
                    t = float(rng.uniform(crossing_end + 2.0, A - 2.0))
                    if any(abs(t - u) < 1.5 for u in taken):
                        continue
                    taken.append(t)
                    x, y = in_block(t, band, sx, sy, axis)
                    what = rng.random()
                    if what < 0.4:
                        if clear_of((x, y), 0.3, kerb_height, kerb_height + 1.0):
                            bins.add(0, (x, y, kerb_height))
                            out.circles.append((x, y, 0.4))
                            out.count("bins")
                    elif what < 0.7:
                        yaw = 0.0 if axis == 0 else math.pi / 2
                        hoops = int(rng.integers(2, 5))
                        mx, my = in_block(0.4 * (hoops - 1), 0.0, sx, sy, axis)
                        half = (0.4 * (hoops - 1) + 0.3, 0.5)
                        block = (np.array([x + mx, y + my]), np.array(half if axis == 0 else half[::-1]), 0.0)
                        if clear_of(block[0], block[1], kerb_height - 0.1, kerb_height + 0.85):
                            for k in range(hoops):
                                dx, dy = in_block(0.8 * k, 0.0, sx, sy, axis)
                                stands.add(0, (x + dx, y + dy, kerb_height), yaw)
                            out.blocks.append(block)
                            taken += [t + 0.8 * k for k in range(hoops)]
                            out.count("bicycle stands")
                    elif clear_of((x, y), 0.1, kerb_height, kerb_height + 0.9):
                        poles.add(0, (x, y, kerb_height), 0.0, (0.1, 0.1, 0.9))
                        out.circles.append((x, y, 0.25))
                        out.count("bollards")
                # road works in the parking strip (an arm too short for a 12 m run beyond the crossing has none)
                if rng.random() < p.roadworks and A - 15.0 > crossing_end + 3.0:
                    lane_mid = road_half - p.parking_width / 2
                    t0 = float(rng.uniform(crossing_end + 3.0, A - 15.0))
                    length = float(rng.uniform(6.0, 12.0))
                    cx, cy = in_block(t0 + length / 2 + 0.5, lane_mid, sx, sy, axis)
                    across = max(p.parking_width / 2, 0.75)  # the strip, or the cones' and barriers' feet 0.4 m either side of its middle
                    half = np.array([length / 2 + 1.5, across]) if axis == 0 else np.array([across, length / 2 + 1.5])
                    if not clear_of((cx, cy), half, 0.0, 1.2):
                        continue
                    for t in np.arange(t0, t0 + length, 1.5):
                        x, y = in_block(t, lane_mid - 0.4, sx, sy, axis)
                        cones.add(0, (x, y, 0.0))
                    for t in np.arange(t0 + 0.5, t0 + length, 2.5):
                        x, y = in_block(t + 1.0, lane_mid + 0.4, sx, sy, axis)
                        barriers.add(0, (x, y, 0.0), 0.0 if axis == 0 else math.pi / 2)
                    out.blocks.append((np.array([cx, cy]), half, 0.0))
                    out.count("road works")
    for name, class_name, what in (("trunks", "trunk", trunks), ("plants", "vegetation", plants), ("hedges", "vegetation", hedges),
                                   ("fences", "fence", fences), ("walls", "fence", walls), ("lamps_bollards", "pole", poles), ("bins", "bin", bins),
                                   ("bicycle_stands", "bicycle stand", stands), ("cones", "traffic cone", cones), ("barriers", "barrier", barriers)):
        reflectivity = REFLECTIVITY["wall" if name == "walls" else class_name]
        if isinstance(what, Scatter):
            if what.items:
                out.parts.append((f"street_{name}", class_name, reflectivity, what.mesh(), what))
            continue
        meshes = [m for m in what if len(m[1])]
        if meshes:
            out.parts.append((f"street_{name}", class_name, reflectivity, primitives.merge(meshes), None))
    return out
