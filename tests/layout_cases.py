"""Random valid parameters of every builder by seed, and the invariants of its pure layout.

Each ``CASES[builder](seed)`` draws the builder's parameters and a set of sensor poses from the seed, builds the
builder's pure layout (no Blender) and returns the invariants it breaks as lines (none: it holds; ``None``: the
builder's check refused the parameters in one line, so nothing was built):

- no exception (a crash is raised, not returned);
- no intersecting solids: footprints (road users, furniture, pillars) and boxes (buildings) do not overlap;
- no solid within :data:`CLEAR` (0.5 m) of any sensor pose: the exact distance from every pose to every triangle
  of the static solids, and to the box of every placed object.

Used by tests/test_layout_properties.py (1,000 seeds a builder) and benchmarks/bench_layout_seeds.py (the share of
seeds that build).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from scipy.spatial import cKDTree

from bpy_pipeline.geometry.clearance import SensorPoses, sample_path
from bpy_pipeline.geometry.collision import rectangles_overlap

CLEAR = 0.5  # m
PATH_STEP = 0.25  # m between a test path's samples (the builders keep radius + step / 2 from them)


# ----------------------------------------------------------------------------- exact distances
def point_triangle_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``(n,)`` distance (m) from ``points[i]`` (n, 3) to triangle ``triangles[i]`` (n, 3, 3): the closest point on the
    triangle by its Voronoi regions (Ericson, Real-Time Collision Detection, 5.1.5), for every pair at once."""
    p = np.asarray(points, float)
    a, b, c = (np.asarray(triangles, float)[:, k] for k in range(3))
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    safe = np.where(np.abs(denom) > 1e-300, denom, 1.0)
    v, w = vb / safe, vc / safe
    closest = a + v[:, None] * ab + w[:, None] * ac  # inside the face
    edge_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    t = (d4 - d3) / np.where(edge_bc, (d4 - d3) + (d5 - d6), 1.0)
    closest = np.where(edge_bc[:, None], b + t[:, None] * (c - b), closest)
    edge_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    t = d2 / np.where(edge_ac, d2 - d6, 1.0)
    closest = np.where(edge_ac[:, None], a + t[:, None] * ac, closest)
    edge_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    t = d1 / np.where(edge_ab, d1 - d3, 1.0)
    closest = np.where(edge_ab[:, None], a + t[:, None] * ab, closest)
    closest = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, closest)
    closest = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, closest)
    closest = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, closest)
    return np.linalg.norm(p - closest, axis=1)


def mesh_distance(points: np.ndarray, mesh) -> float:
    """m: the smallest distance from ``points`` (n, 3) to the triangles of ``mesh`` (``inf`` when far or empty)."""
    distance = triangle_distances(points, mesh)
    return float(distance.min()) if len(distance) else np.inf


def nearest_parts(points: np.ndarray, parts: list[tuple[str, tuple]]) -> list[tuple[str, float]]:
    """``[(name, m)]`` of the ``parts`` ``[(name, mesh)]`` closer than :data:`CLEAR` to ``points`` (n, 3), checked as one mesh."""
    meshes = [mesh for _, mesh in parts]
    owner = np.repeat(np.arange(len(parts)), [len(t) for _, t in meshes])
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes])
    merged = (np.concatenate([np.asarray(v, float).reshape(-1, 3) for v, _ in meshes]),
              np.concatenate([np.asarray(t).reshape(-1, 3) + o for (_, t), o in zip(meshes, offsets)]))
    distance = triangle_distances(points, merged)
    close = distance < CLEAR
    return [(parts[k][0], float(distance[close & (owner == k)].min())) for k in np.unique(owner[close])]


def triangle_distances(points: np.ndarray, mesh) -> np.ndarray:
    """``(m,)`` m: each triangle of ``mesh``'s distance to the nearest of ``points`` (n, 3), exact below 2 :data:`CLEAR`
    (``inf`` beyond)."""
    vertices, triangles = mesh
    points = np.asarray(points, float).reshape(-1, 3)
    out = np.full(len(triangles), np.inf)
    if not len(points) or not len(triangles):
        return out
    tri = np.asarray(vertices, float)[np.asarray(triangles)]
    low, high = points.min(0) - 2 * CLEAR, points.max(0) + 2 * CLEAR
    near = np.flatnonzero(((tri.max(1) >= low) & (tri.min(1) <= high)).all(1))  # triangles whose bounds meet the points' bounds
    if not len(near):
        return out
    out[near] = _near_distances(points, tri[near])
    return out


def _near_distances(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """:func:`triangle_distances` of triangles ``tri`` (m, 3, 3) near ``points`` (n, 3)."""
    out = np.full(len(tri), np.inf)
    centre = tri.mean(1)
    radius = np.linalg.norm(tri - centre[:, None], axis=2).max(1)
    tree = cKDTree(points)
    nearest, _ = tree.query(centre, distance_upper_bound=radius.max() + 2 * CLEAR)
    candidates = np.flatnonzero(nearest - radius < 2 * CLEAR)
    pairs = [(k, i) for k, near in zip(candidates, tree.query_ball_point(centre[candidates], radius[candidates] + 2 * CLEAR)) for i in near]
    if pairs:
        k, i = np.array(pairs).T
        np.minimum.at(out, k, point_triangle_distance(points[i], tri[k]))
    return out


def poses_of(points, step: float = 0.0) -> SensorPoses:
    return SensorPoses(np.asarray(points, float).reshape(-1, 3), step=step)


def _overlapping_boxes(boxes: list[tuple[np.ndarray, np.ndarray]], what: str) -> list[str]:
    """Lines for the pairs of axis-aligned boxes ``(low (3,), high (3,))`` whose insides overlap (by more than 1 mm)."""
    out = []
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            (l1, h1), (l2, h2) = boxes[i], boxes[j]
            if (np.minimum(h1, h2) - np.maximum(l1, l2) > 1e-3).all():
                out.append(f"{what} {i} and {j} overlap")
    return out


# ----------------------------------------------------------------------------- street
def street_case(seed: int) -> list[str]:
    """A street of random valid parameters and junction kinds; a sensor driving along a random drive lane (at 0.6-2.5 m;
    along y only through four arms) and a rig of three sensors on a sidewalk; its static layout and one frame's road
    users, each on its lane, parking strip, sidewalk or crossing."""
    from bpy_pipeline.builders.street import params as street_params
    from bpy_pipeline.builders.street.layout import JUNCTIONS, junction, place_users, street_layout
    from bpy_pipeline.geometry.placement import Distribution

    rng = np.random.default_rng(seed)
    def u(lo, hi):
        return float(rng.uniform(lo, hi))
    lanes, lane_width, parking = int(rng.integers(1, 3)), u(2.8, 4.0), (0.0 if rng.random() < 0.2 else u(1.8, 2.8))
    kerb_width, sidewalk, crossing_width, crossing_offset = u(0.1, 0.3), u(1.5, 5.0), u(2.0, 5.0), u(0.0, 3.0)
    reach = lanes * lane_width + parking + kerb_width + crossing_offset + crossing_width + 10.0
    setback0, width0, spacing0 = u(0.0, 4.0), u(3.0, 10.0), u(2.0, 10.0)
    params = street_params.StreetScene(
        arm_length=u(reach, reach + 10.0), lanes_per_direction=lanes, lane_width=lane_width, parking_width=parking,
        kerb_width=kerb_width, kerb_height=u(0.08, 0.2), sidewalk_width=sidewalk, crossing_width=crossing_width,
        crossing_offset=crossing_offset, signs=int(rng.integers(0, 6)), building_depth=u(4.0, 12.0),
        building_width=(width0, width0 + u(0.0, 8.0)), building_height=(u(3.0, 8.0), u(8.0, 25.0)),
        setback=(setback0, setback0 + u(0.0, 6.0)), open_share=u(0, 1), plot_depth=u(3.0, 25.0),
        street_trees=u(0, 1), tree_spacing=(spacing0, spacing0 + u(0.0, 8.0)), yard_plants=u(0.0, 4.0),
        lamp_spacing=0.0 if rng.random() < 0.2 else u(8.0, 40.0), furniture_per_100m=u(0.0, 10.0), roadworks=u(0, 1),
        terrain=bool(rng.random() < 0.8), terrain_step=u(1.5, 4.0), terrain_relief=u(0.0, 1.0), terrain_slope=u(0.0, 0.1),
        layout_seed=seed, vehicles=Distribution("normal", u(0.0, 12.0), 3.0, 0.0, 40.0),
        parked=Distribution("normal", u(0.0, 12.0), 3.0, 0.0, 40.0), bicycles=Distribution("normal", u(0.0, 3.0), 1.0, 0.0, 10.0),
        motorcycles=Distribution("normal", u(0.0, 3.0), 1.0, 0.0, 10.0), pedestrians=Distribution("normal", u(0.0, 10.0), 3.0, 0.0, 40.0),
        clearance=u(0.0, 1.0), fov_aware=False,
    )
    params = dataclasses.replace(params, junction_mix={kind: float(rng.uniform(0.0, 1.0)) for kind in JUNCTIONS})  # every kind, drawn per layout_seed
    street_params.check(params, "scene")
    A, R = params.arm_length, lanes * lane_width + parking
    inner, outer = R + kerb_width, R + kerb_width + sidewalk
    offset = -(int(rng.integers(lanes)) + 0.5) * lane_width * float(rng.choice([-1, 1]))
    path = np.array([[-A, offset, 0.0], [A, offset, 0.0]]) + [0.0, 0.0, u(0.6, 2.5)]
    if rng.random() < 0.5 and junction(params).arms == (-1, 1):  # along the road along y where it runs whole
        path = path[:, [1, 0, 2]]
    along, across = u(inner + 0.4, A - 0.5) * rng.choice([-1, 1]), u(inner + 0.4, outer - 0.4) * rng.choice([-1, 1])
    station = np.array([along, across, params.kerb_height + u(0.6, 2.5)])
    rig = station + np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.3, 0.0]])
    points = np.vstack([sample_path(path, PATH_STEP), rig])
    poses = poses_of(points, PATH_STEP)
    layout = street_layout(params, np.random.default_rng(params.layout_seed), poses)
    users = place_users(params, layout, np.random.default_rng([seed, 1]), clear=poses).users
    out = [f"street {name} {d:.3f} m from a sensor pose" for name, d in nearest_parts(points, [(f"{p.name} ({p.class_name})", p.mesh) for p in layout.parts])]
    buildings = [(p.mesh[0].min(0), p.mesh[0].max(0)) for p in layout.parts if p.class_name == "building"]
    out += _overlapping_boxes(buildings, "buildings")
    obstacles = [(pl[:2], np.array([pl[2], pl[2]]), 0.0) for pl in layout.poles] + list(layout.blocks)
    for i, user in enumerate(users):
        if (d := poses.box_distance(user.centre, user.half, user.yaw, user.z, user.z + user.size[2])) < CLEAR:
            out.append(f"street {user.kind} {i} {d:.3f} m from a sensor pose")
        for j, other in enumerate(users[:i]):
            if rectangles_overlap(user.centre, user.half, user.yaw, other.centre, other.half, other.yaw, 0.0):
                out.append(f"street road users {j} and {i} overlap")
        for c, h, y in obstacles:
            if rectangles_overlap(user.centre, user.half, user.yaw, c, h, y, 0.0):
                out.append(f"street {user.kind} {i} overlaps an obstacle at {np.round(c, 2).tolist()}")
        area = user.where.partition(":")[0]
        corners = user.centre + np.array([[sx * user.half[0], sy * user.half[1]] for sx in (-1, 1) for sy in (-1, 1)]) @ np.array(
            [[np.cos(user.yaw), np.sin(user.yaw)], [-np.sin(user.yaw), np.cos(user.yaw)]])
        # a parked car's centre only: a strip narrower than a car lets it overhang the kerb
        if area in ("lane", "parking") and not all(layout.on_road(c) for c in (corners if area == "lane" else [user.centre])):
            out.append(f"street {user.kind} {i} ({user.where}) reaches off the road ({layout.junction.kind})")
        if (area == "sidewalk" and not layout.on_sidewalk(user.centre)) or (area == "crossing" and not layout.on_crossing(user.centre)):
            out.append(f"street person {i} off its {area} ({layout.junction.kind})")
    return out


# ----------------------------------------------------------------------------- parking
def parking_case(seed: int) -> list[str]:
    """A parking level of random valid parameters scanned from every station of the robot's round; cars placed
    around the first station by the level's placer, kept clear of every station."""
    from bpy_pipeline.builders.parking import params as parking_params
    from bpy_pipeline.builders.parking.layout import level_layout
    from bpy_pipeline.geometry.indoor import driveway, parking_station
    from bpy_pipeline.geometry.placement import FloorBoxPlacer

    rng = np.random.default_rng(seed)
    def u(lo, hi):
        return float(rng.uniform(lo, hi))
    length, ceiling = u(30.0, 90.0), u(2.2, 3.5)
    openings = int(rng.integers(0, 4))
    params = parking_params.ParkingScene(
        length=length, driveway_width=u(3.0, 8.0), bay_width=u(2.2, 3.0), bay_depth=u(4.5, 6.0), ceiling_height=ceiling,
        slab_thickness=u(0.2, 0.4), wall_thickness=u(0.2, 0.4), pillar_size=u(0.3, 0.8), pillar_every=int(rng.integers(1, 5)),
        ramp_length=0.0 if rng.random() < 0.3 else u(8.0, length - 8.0), wall_openings=openings,
        opening_width=u(0.8, min(2.0, 0.9 * length / (openings + 1))), opening_height=u(1.8, ceiling - 0.1),
        sensor_height=u(0.5, ceiling - 0.5), sensor_start=u(0.0, 10.0), sensor_step=u(0.5, 5.0),
    )
    parking_params.check(params, "scene")
    layout = level_layout(params)
    x0, x1 = driveway(params)
    frames = int(np.ceil((x1 - x0) / params.sensor_step)) + 1
    points = np.array([parking_station(params, f)[:3, 3] for f in range(frames)])
    poses = poses_of(points)
    out = [f"parking {name} {d:.3f} m from a sensor pose" for name, d in nearest_parts(points, list(layout.meshes().items()))]
    pillars = [(np.append(c - h, 0.0), np.append(c + h, 1.0)) for c, h, _ in layout.pillars]
    out += _overlapping_boxes(pillars, "pillars")
    placer = FloorBoxPlacer(points[0], (layout.low, layout.high), layout.obstacles, None, clearance=0.3, min_visible=0.0, keep_out=1.0, clear=poses)
    for _ in range(20):
        half = np.array([u(2.0, 2.5), u(0.85, 1.0), u(0.75, 0.85)])
        box = placer.try_place(points[0, :2] + rng.uniform(-15.0, 15.0, 2), u(-np.pi, np.pi), half)
        if box is not None:
            placer.commit(box)
    for i, box in enumerate(placer.boxes):
        if (d := poses.box_distance(box.centre[:2], box.half[:2], box.yaw, 0.0, 2 * box.half[2])) < CLEAR:
            out.append(f"parking car {i} {d:.3f} m from a sensor pose")
        for j, other in enumerate(placer.boxes[:i]):
            if rectangles_overlap(box.centre[:2], box.half[:2], box.yaw, other.centre[:2], other.half[:2], other.yaw, 0.0):
                out.append(f"parking cars {j} and {i} overlap")
    return out


# ----------------------------------------------------------------------------- industrial hall
def hall_case(seed: int) -> list[str]:
    """A hall of random valid parameters and its overhead sensor: furniture apart, inside the walls, clear of the sensor."""
    from bpy_pipeline.builders.industrial_hall import params as hall_params
    from bpy_pipeline.geometry.indoor import boxes_mesh, hall_layout, hall_station

    rng = np.random.default_rng(seed)
    def u(lo, hi):
        return float(rng.uniform(lo, hi))
    height = u(3.0, 8.0)
    params = hall_params.IndustrialHallScene(
        length=u(8.0, 40.0), width=u(8.0, 30.0), height=height, wall_thickness=u(0.2, 0.4), desk_rows=int(rng.integers(0, 4)),
        desks_per_row=int(rng.integers(0, 5)), desk_size=(u(1.0, 2.0), u(0.6, 1.0)), desk_height=u(0.6, 0.9), shelves=int(rng.integers(0, 5)),
        shelf_size=(u(1.0, 3.0), u(0.4, 0.8), u(1.5, 2.5)), shelf_levels=int(rng.integers(1, 6)), sensor_height=u(height / 2, height - 0.5),
    )
    try:
        hall_params.check(params, "scene")
    except hall_params.InputError:
        return None  # parameters the hall refuses in one line: nothing is built
    layout = hall_layout(params)
    points = hall_station(params)[:3, 3][None]
    out = []
    for name, boxes in (("walls", layout.walls), ("floor", layout.floor), ("ceiling", layout.ceiling)):
        if (d := mesh_distance(points, boxes_mesh(boxes))) < CLEAR:
            out.append(f"hall {name} {d:.3f} m from the sensor")
    footprints = []
    for item in layout.furniture:
        if (d := mesh_distance(points, item.mesh())) < CLEAR:
            out.append(f"hall {item.name} {d:.3f} m from the sensor")
        low, high = item.footprint
        if (low < layout.low - 1e-9).any() or (high > layout.high + 1e-9).any():
            out.append(f"hall {item.name} reaches past the walls")
        footprints.append((np.append(low, 0.0), np.append(high, 1.0)))
    out += _overlapping_boxes(footprints, "hall furniture")
    return out


# ----------------------------------------------------------------------------- railway
def railway_case(seed: int) -> list[str]:
    """A railway of random valid parameters scanned from its stations (2 m up, the railway_tls mount): masts clear of them."""
    from bpy_pipeline.builders.railway import params as railway_params
    from bpy_pipeline.builders.railway.layout import plan, station_frames
    from bpy_pipeline.builders.railway.parts import mast

    rng = np.random.default_rng(seed)
    def u(lo, hi):
        return float(rng.uniform(lo, hi))
    base = railway_params.RailwayScene()
    track = dataclasses.replace(base.track, tracks=int(rng.integers(1, 4)))
    supports = dataclasses.replace(base.supports, layout=str(rng.choice(["auto", "single", "both_sides", "gantry"])) if track.tracks > 1 else "single",
                                   side=str(rng.choice(["right", "left"])), span=u(35.0, 65.0), mast_offset=u(2.5, 4.0))
    stations = dataclasses.replace(base.stations, count=int(rng.integers(1, 6)), side=str(rng.choice(["right", "left"])), offset=u(1.5, 8.0))
    params = dataclasses.replace(base, track=track, supports=supports, stations=stations)
    try:
        railway_params.check(params, "scene")
    except railway_params.InputError:
        return None  # refused in one line
    layout = plan(params, np.random.default_rng(seed))
    points = station_frames(params)[:, :3, 3] + [0.0, 0.0, 2.0]
    out = []
    for support in layout.supports:
        for m in support.masts:
            base_point = support.frame[:3, :3] @ np.array([0.0, m.lateral, m.base]) + support.frame[:3, 3]
            if (d := mesh_distance(points, mast(m.kind if m.kind != "gantry" else "lattice", m.top - m.base, base_point))) < CLEAR:
                out.append(f"railway mast of support {support.index} ({m.side}) {d:.3f} m from a station")
    return out


# ----------------------------------------------------------------------------- primitives
def primitives_case(seed: int) -> list[str]:
    """Shapes of random valid sizes built as meshes; the default scene keeps clear of the default sensor."""
    from bpy_pipeline.builders.primitives import params as primitives_params
    from bpy_pipeline.builders.primitives.params import PrimitivesScene, Shape
    from bpy_pipeline.geometry.transforms import pose_matrix

    rng = np.random.default_rng(seed)
    sizes = {"plane": lambda: [float(v) for v in rng.uniform(0.1, 50.0, 2)], "box": lambda: [float(v) for v in rng.uniform(0.05, 10.0, 3)],
             "sphere": lambda: float(rng.uniform(0.05, 5.0)), "cylinder": lambda: [float(v) for v in rng.uniform(0.05, 5.0, 2)]}
    shapes = []
    for _ in range(int(rng.integers(1, 6))):
        kind = str(rng.choice(list(sizes)))
        shapes.append(Shape(kind, sizes[kind](), tuple(float(v) for v in rng.uniform(-20, 20, 3)), tuple(float(v) for v in rng.uniform(-180, 180, 3)),
                            segments=int(rng.integers(3, 48))))
    primitives_params.check(PrimitivesScene(shapes), "scene")
    meshes = [_placed_primitive(shape, pose_matrix) for shape in shapes]
    assert all(len(v) and np.isfinite(v).all() for v, _ in meshes)
    return [f"primitives: the default {name} {d:.3f} m from the default sensor" for name, d in _default_primitives()]


@functools.lru_cache(maxsize=1)
def _default_primitives() -> tuple:
    """The default primitives scene's shapes closer than :data:`CLEAR` to the default sensor (sensor.position [0, 0, 1.5])."""
    from bpy_pipeline.builders.primitives.params import PrimitivesScene
    from bpy_pipeline.geometry.transforms import pose_matrix

    shapes = PrimitivesScene().shapes
    return tuple(nearest_parts(np.array([[0.0, 0.0, 1.5]]), [(shape.name, _placed_primitive(shape, pose_matrix)) for shape in shapes]))


def _placed_primitive(shape, pose_matrix):
    """A shape's mesh at its position and rotation: builders/primitives/scene.py's ``shape_mesh`` (which imports bpy)
    made from the same geometry.primitives functions, placed as Blender places the object."""
    from bpy_pipeline.geometry import primitives

    size = shape.size if isinstance(shape.size, list) else [shape.size]
    if shape.type == "plane":
        vertices, triangles = primitives.plane(size[0], size[-1])
    elif shape.type == "box":
        vertices, triangles = primitives.box(*(size * 3 if len(size) == 1 else size))
    elif shape.type == "sphere":
        vertices, triangles = primitives.uv_sphere(size[0], shape.segments)
    else:
        vertices, triangles = primitives.cylinder(size[0], size[1], shape.segments)
    matrix = pose_matrix(shape.position, shape.rotation_deg)
    return vertices @ matrix[:3, :3].T + matrix[:3, 3], triangles


CASES = {"street": street_case, "parking": parking_case, "industrial_hall": hall_case, "railway": railway_case, "primitives": primitives_case}
