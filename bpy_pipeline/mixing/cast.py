"""One cast, exact per firing: every firing of the real sweep against the inserted meshes only.

Each firing keeps at most one return (:func:`merge_returns`):

- a new hit nearer than the real return replaces it (the real point behind is occluded);
- a new hit on an empty firing fills it (what the KITTI paper's point wall approximates);
- a new hit behind a real return is discarded.

The meshes go to Embree in the scan's sensor frame (:class:`~bpy_pipeline.lidar.cast.raycast.RayCaster`
with the identity as its local frame); each firing leaves from its own origin (the sensor's
position at firing time) along its own direction, so an inserted point lies exactly on a real
firing's ray. Glass (car windows) is traced as the scanner traces it (:func:`~bpy_pipeline.lidar.cast.scanner.trace_beams`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..buffers import ObjectTable, SceneBuffers
from ..geometry.objects import FITTINGS, OBJECT_TYPES, PARTS, ObjectPart, car_object
from ..lidar.effects.materials import CarGlass, glass_transmission, pane_internal, part_material
from ..lidar.cast.raycast import RayCaster
from ..lidar.cast.scanner import MirrorGlassRules, trace_beams
from .firings import Firings
from .objects import mesh_file_parts
from .paint import CarPaint, paint_car
from .placement import Placement


def car_glass_parts(parts: list[ObjectPart], glass: CarGlass) -> list[ObjectPart]:
    """A car of :func:`~bpy_pipeline.geometry.objects.car_object` (its own frame, nose +x) with its windows split
    into panes and its cabin darkened (``scene.car_glass``, :class:`~bpy_pipeline.lidar.effects.materials.CarGlass`).

    The windows part becomes ``tinted_glass`` (side and rear panes; it keeps its place, so part j is still
    ``PARTS[j]``) and a ``windshield_glass`` part appended after the others: the triangles whose normal points
    more along x than along y and which lie ahead of the car's centre. The interior takes ``glass.interior``.
    Unchanged when ``glass.enabled`` is false."""
    if not glass.enabled:
        return parts
    windows, interior = PARTS.index("windows"), PARTS.index("interior")
    w = parts[windows]
    corners = w.vertices[w.triangles]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    front = (np.abs(normal[:, 0]) > np.abs(normal[:, 1])) & (corners[:, :, 0].mean(axis=1) > 0)
    out = list(parts)
    out[windows] = ObjectPart(w.vertices, w.triangles[~front], "tinted_glass", w.reflectivity)
    out[interior] = ObjectPart(parts[interior].vertices, parts[interior].triangles, parts[interior].material, glass.interior)
    out.append(ObjectPart(w.vertices, w.triangles[front], "windshield_glass", w.reflectivity))
    return out


def car_part_names(fittings: bool, glass: CarGlass | None) -> list[str]:
    """Names of the parts of a car of :func:`object_parts` in order: ``PARTS``, then ``FITTINGS`` when ``fittings``, then
    ``windshield`` when ``glass`` is enabled (:func:`car_glass_parts` appends it)."""
    return [*PARTS, *(FITTINGS if fittings else ()), *(("windshield",) if glass is not None and glass.enabled else ())]


def object_parts(p: Placement, rng: np.random.Generator, car_bodies: str = "classic", glass: CarGlass | None = None, fittings: bool = False,
                 paint: CarPaint | None = None, paint_rng: np.random.Generator | None = None) -> list[ObjectPart]:
    """The parts of placement ``p`` in the sensor frame (the type's mesh scaled to the box, yawed, moved).

    A car is drawn from ``CAR_BODY_SETS[car_bodies]`` (``scene.car_bodies``), or is body ``p.body`` of it when the
    placement drew one, its windows and cabin as ``glass`` says (:func:`car_glass_parts`; None: as before), with plates
    and lamps when ``fittings`` (geometry/objects.py ``car_fittings``), each part with its own reflectance model when
    ``paint`` is enabled (:func:`~.paint.paint_car`, the body's pigment drawn from ``paint_rng``, the car's own
    generator); a mesh file's parts come from :mod:`.objects` (glass where its materials say so)."""
    if p.type == "car":
        parts = car_object(rng, p.size, car_bodies, getattr(p, "body", -1), fittings)
        if glass is not None:
            parts = car_glass_parts(parts, glass)
        if paint is not None and paint.enabled:
            parts = paint_car(parts, car_part_names(fittings, glass), paint, paint_rng)
    elif p.type in OBJECT_TYPES:
        parts = OBJECT_TYPES[p.type][1](rng, p.size)
    else:
        parts = mesh_file_parts(p.type, p.size)
    c, s = math.cos(p.yaw), math.sin(p.yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return [ObjectPart(part.vertices @ rotation.T + p.centre, part.triangles, part.material, part.reflectivity, part.paint) for part in parts]


def object_buffers(placements: list[Placement], parts: list[list[ObjectPart]], instances: list[int], semantic: list[int]) -> SceneBuffers:
    """Scene buffers of the inserted objects: one object row per part, the placement's class and instance.

    A part's material is a tracing material (diffuse, mirror, glass, absorber) or a reflectance model of
    lidar/effects/materials.py (``glossy_paint``, ``retroreflector``, ...: traced as diffuse, the model in the table's
    ``surface`` column, :func:`~bpy_pipeline.lidar.effects.materials.part_material`)."""
    vertices, triangles, rows, names, classes, sem, inst, material, reflect, surface = [], [], [], [], [], [], [], [], [], []
    offset = 0
    for k, (p, object_parts_) in enumerate(zip(placements, parts)):
        for j, part in enumerate(object_parts_):
            row = len(names)
            names.append(f"inserted_{k:03d}_{j}")
            classes.append(p.class_name)
            sem.append(semantic[k])
            inst.append(instances[k])
            traced, model = part_material(part.material, f"inserted object {k} part {j} material")
            material.append(traced)
            surface.append(model)
            reflect.append(part.reflectivity)
            vertices.append(part.vertices)
            triangles.append(np.asarray(part.triangles, np.int64) + offset)
            rows.append(np.full(len(part.triangles), row, np.int32))
            offset += len(part.vertices)
    k = len(names)
    table = ObjectTable(names, [""] * k, classes, np.array(sem, np.uint16), np.array(inst, np.uint32), np.array(material, np.uint8),
                        np.array(reflect, np.float32),
                        np.array(surface, np.uint8) if any(surface) else None)
    if not k:
        return SceneBuffers(np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros(0, np.int32), table)
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(rows), table)


def glass_rules(parts: list[list[ObjectPart]], glass: CarGlass | None) -> MirrorGlassRules:
    """The trace's rules for the inserted objects of :func:`object_buffers` (``parts``, in the same order): glass
    returns within 5 deg of normal incidence, and the car panes' round-trip transmission when ``glass`` is enabled."""
    if glass is None or not glass.enabled:
        return MirrorGlassRules(glass_return_deg=5.0)
    internal = pane_internal([part.material for object_parts_ in parts for part in object_parts_], glass)
    return MirrorGlassRules(glass_return_deg=5.0, glass_transmission=glass_transmission(internal, glass) if np.isfinite(internal).any() else None)


@dataclass
class InsertedHits:
    """The inserted objects' returns, one per firing that hit them (h of f firings).

    firing : (h,) int64; path : (h,) float64 metres from the firing's origin; row : (h,) object row of the final hit
    cos_incidence, gain : (h,) float64; bounces : (h,) uint8
    """

    firing: np.ndarray
    path: np.ndarray
    row: np.ndarray
    cos_incidence: np.ndarray
    gain: np.ndarray
    bounces: np.ndarray


def bounding_spheres(buffers: SceneBuffers) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(instance (k,), centre (k, 3), radius (k,))``: a sphere around each instance's triangles (slightly grown)."""
    instances = np.unique(buffers.objects.instance[np.unique(buffers.triangle_object)]) if len(buffers.triangles) else np.zeros(0, np.uint32)
    centre, radius = np.zeros((len(instances), 3)), np.zeros(len(instances))
    tri_instance = buffers.objects.instance[buffers.triangle_object]
    for k, inst in enumerate(instances):
        v = buffers.vertices[np.unique(buffers.triangles[tri_instance == inst])]
        centre[k] = (v.min(axis=0) + v.max(axis=0)) / 2
        radius[k] = float(np.linalg.norm(v - centre[k], axis=1).max()) * (1 + 1e-9) + 1e-6
    return instances, centre, radius


def near_objects(firings: Firings, buffers: SceneBuffers, instance: int | None = None) -> np.ndarray:
    """Indices of the firings whose ray passes through the bounding sphere of an object of ``buffers``
    (of instance ``instance`` alone when given).

    Exact as a filter: a ray that misses every bounding sphere misses every triangle, so casting
    only these firings gives the same hits as casting all of them (far cheaper for a few objects).
    """
    instances, centre, radius = bounding_spheres(buffers)
    if instance is not None:
        pick = instances == instance
        centre, radius = centre[pick], radius[pick]
    if not len(radius):
        return np.zeros(0, np.int64)
    to = centre[None, :, :] - firings.origin[:, None, :]  # (f, k, 3)
    along = np.einsum("fkj,fj->fk", to, firings.direction)
    across2 = np.einsum("fkj,fkj->fk", to, to) - along**2
    near = ((across2 <= radius**2) & (along >= -radius)).any(axis=1)
    return np.flatnonzero(near)


def cast_firings(firings: Firings, buffers: SceneBuffers, max_range: float, threads: int | None = None, surfaces: MirrorGlassRules | None = None, rng=None,
                 rows: np.ndarray | None = None) -> InsertedHits:
    """Every firing (or the firings ``rows``) against ``buffers`` alone; the nearest hit of each.

    Only the firings that pass an object's bounding sphere (:func:`near_objects`) go to Embree; the others cannot hit.
    The caster's local frame is the scan's sensor frame (identity): origins and directions go in unchanged.
    """
    rows = near_objects(firings, buffers) if rows is None else np.asarray(rows, np.int64)
    if not len(buffers.triangles) or not len(rows):
        z = np.zeros(0)
        return InsertedHits(np.zeros(0, np.int64), z, np.zeros(0, np.int32), z, z, np.zeros(0, np.uint8))
    caster = RayCaster(buffers, frame=np.eye(4), threads=threads)
    origin = firings.origin[rows]
    shared = not origin.any()
    beams = trace_beams(caster, buffers, np.zeros(3) if shared else origin, firings.direction[rows], 0.0, max_range, 3,
                        surfaces=surfaces or MirrorGlassRules(glass_return_deg=5.0), rng=rng)
    return InsertedHits(rows[beams.ray], beams.path, buffers.triangle_object[beams.triangle], beams.cos_incidence, beams.gain, beams.bounces)


def merge_returns(firings: Firings, hits: InsertedHits) -> tuple[np.ndarray, np.ndarray]:
    """Which hits are kept and which real returns they occlude: ``(kept (h,) bool, occluded (f,) bool)``.

    A hit is kept where its firing was empty or its path is shorter than the real return's range.
    """
    real = firings.range[hits.firing]
    kept = ~firings.valid[hits.firing] | (hits.path < real)
    occluded = np.zeros(len(firings), bool)
    occluded[hits.firing[kept & firings.valid[hits.firing]]] = True
    return kept, occluded
