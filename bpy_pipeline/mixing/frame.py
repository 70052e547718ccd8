"""A mixed frame: a real scan with synthetic objects cast in by its own firings, in five steps over a :class:`MixState`.

The steps (:data:`MIX_STEPS`): :func:`mix_background` (read the file -> :class:`~bpy_pipeline.io.real_scans.RealScan`,
firings :mod:`.firings`), :func:`mix_place` (ground :mod:`.ground`, placement :mod:`.placement`, meshes),
:func:`mix_cast` (:mod:`.cast`), :func:`mix_effects` (the fitted drop and noise models on inserted returns
only, the noise injections of :mod:`.noise`, then the records) and :func:`mix_annotate` (boxes, the record);
each part timed in ``info["timings_ms"]`` (read, firings, ground, placement, meshes, cast, effects, records,
boxes). The real-scan frame plan runs them as its stages (:mod:`bpy_pipeline.stages.mixing`);
:func:`mix_frame` runs them in a row.

Labels: real returns get ``background_class`` or, from a SemanticKITTI file with
``keep_labels``, their class mapped by name to the project's table (:data:`SEMANTICKITTI_NAMES`;
unknown ones the background) and their instance; inserted returns their object's class and an
instance above every real one. Boxes (:data:`~bpy_pipeline.geometry.boxes.BOX_DTYPE`): each inserted
object with truncation (the share of its surface outside the firings' azimuth span) and
occlusion (visible / unoccluded firings: those whose return is the object, against those that
hit it when it is alone); each of ``real_boxes`` with its occlusion updated from the share of its
real returns the inserted objects hid (the KITTI paper's synthetic annotation); a SemanticKITTI scan's labelled vehicles (car, van,
truck, bus instances) get boxes of their own the same way, and the KITTI rule snaps to them too.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geometry.boxes import BOX_DTYPE, footprint_heading
from ..io.real_scans import RealScan, read_real_scan
from ..labels import ClassTable, load_class_table
from ..lidar.effects.apply import apply_effects
from ..lidar.points import BEAM_DTYPE, POINT_DTYPE
from ..lidar.sensor.sensors import resolve_sensor
from ..lidar.cast.visibility import occlusion_levels, subset_buffers, surface_samples
from . import noise as injections
from .cast import InsertedHits, cast_firings, glass_rules, merge_returns, near_objects, object_buffers, object_parts
from .firings import Firings, angles_deg, recover_firings
from .ground import PointIndex, find_ground, in_box
from .placement import Placement, Scene, explicit_placements, kitti_rule, parking_rule, real_placements
from .paint import car_generator, detection_reflectivity, paint_beam
from .section import RealScanScene

# SemanticKITTI raw ids -> the project's class names (assets_manifest/labels.yaml); others: the background class
SEMANTICKITTI_NAMES = {
    10: "car", 11: "bicycle", 13: "bus", 15: "motorcycle", 18: "truck", 20: "van", 30: "person", 31: "rider", 32: "motorcyclist",
    40: "road", 44: "road", 48: "sidewalk", 49: "ground", 50: "building", 51: "fence", 52: "building", 60: "road", 70: "vegetation",
    71: "trunk", 72: "terrain", 80: "pole", 81: "traffic sign", 99: "unlabeled", 252: "car", 253: "rider", 254: "person", 255: "motorcyclist", 256: "unlabeled",
    257: "bus", 258: "truck", 259: "van",
}
OCCLUSION_LEVELS = (0.8, 0.4, 0.1)


@dataclass
class MixedFrame:
    """points : (p,) POINT_DTYPE in the scan's sensor frame, one per firing at most, in firing order;
    boxes : (b,) BOX_DTYPE; info : plain data for the manifest; firings : the recovered :class:`Firings`;
    firing : (p,) int64 firing of each point; inserted : (p,) bool, True for inserted returns;
    placements : the inserted objects' :class:`~.placement.Placement`; buffers : their scene buffers (sensor frame)."""

    points: np.ndarray
    boxes: np.ndarray
    info: dict
    firings: Firings
    firing: np.ndarray
    inserted: np.ndarray
    placements: list = field(default_factory=list)
    buffers: object = None


def real_labels(scan: RealScan, firings: Firings, section: RealScanScene, table: ClassTable) -> tuple[np.ndarray, np.ndarray]:
    """``(semantic (f,) uint16, instance (f,) uint32)`` of the real firings."""
    background = table.id_of(section.background_class, "scene.background_class")
    semantic = np.full(len(firings), background, np.uint16)
    instance = np.zeros(len(firings), np.uint32)
    if scan.labels is not None and section.keep_labels:
        have = firings.point >= 0
        raw = scan.labels[firings.point[have]]
        lut = {k: table.id_of(v) for k, v in SEMANTICKITTI_NAMES.items()}
        low = (raw & 0xFFFF).astype(np.int64)
        semantic[have] = np.array([lut.get(int(k), background) for k in low], np.uint16) if len(low) else semantic[have]
        instance[have] = raw >> 16
    return semantic, instance


VEHICLES = ("car", "van", "truck", "bus")


def labelled_boxes(firings: Firings, semantic: np.ndarray, instance: np.ndarray, table: ClassTable, min_points: int = 10) -> list:
    """Boxes of the labelled real vehicles of a SemanticKITTI scan (one per instance of a vehicle class),
    fitted around their returns at the heading of the smallest rectangle around their footprint."""
    ids = {table.id_of(name): name for name in VEHICLES}
    out = []
    returns = firings.returns
    for inst in np.unique(instance[firings.valid & (instance > 0) & np.isin(semantic, list(ids))]):
        rows = np.flatnonzero(firings.valid & (instance == inst))
        if len(rows) < min_points:
            continue
        xyz = returns[rows]
        yaw = footprint_heading(xyz[:, :2])
        c, s_ = math.cos(yaw), math.sin(yaw)
        local = xyz[:, :2] @ np.array([[c, -s_], [s_, c]])
        lo, hi = local.min(axis=0), local.max(axis=0)
        centre_xy = np.array([[c, -s_], [s_, c]]) @ ((lo + hi) / 2)
        z0, z1 = xyz[:, 2].min(), xyz[:, 2].max()
        cls = ids[int(np.bincount(semantic[rows]).argmax())]
        out.append(Placement(cls, cls, np.array([centre_xy[0], centre_xy[1], (z0 + z1) / 2]), np.array([*(hi - lo), z1 - z0]) + 0.02, yaw, "labels"))
    return out


def _effects(points: np.ndarray, beam: np.ndarray, effects, rng: np.random.Generator, objects=None, paints=None, rows=None) -> tuple[np.ndarray, np.ndarray]:
    """The fitted drop and noise models on the inserted returns; ``(points, kept firing rows)`` (a dropped firing stays empty).

    objects : the inserted objects' table; where a part names a reflectance model (a plate's ``retroreflector``) the
    model is applied to its returns (``effects.materials.objects`` on for them: the parts were made with it).
    paints, rows : each object row's own model (``scene.car_paint``, :func:`~.paint.paint_beam`: it wins over
    ``effects.materials``) and each return's object row (p,); None or no model: as before."""
    tag = points["time"].copy()
    points["time"] = np.arange(len(points), dtype=np.float64)  # carry each record's row through the drop
    materials = getattr(effects, "materials", None)
    if objects is not None and objects.surface is not None and materials is not None and not materials.objects:
        effects = replace(effects, materials=replace(materials, objects=True))
    if paints is not None and rows is not None and any(m is not None for m in paints) and materials is not None:
        beam = paint_beam(points, beam, rows, paints, effects.materials, effects.intensity.incidence_exponent, objects)
        effects = replace(effects, materials=replace(materials, classes={}, objects=False))  # applied above
        detection = detection_reflectivity(beam, rows, paints)  # a part's detection reflectivity: the drop decision's, not the reading's
    else:
        detection = None
    out = apply_effects(points, beam, effects, rng, objects=objects, detection=detection)
    rows = out["time"].astype(np.int64)
    out["time"] = tag[rows]
    return out, rows


def _timed(timings: dict, name: str, start: float) -> float:
    now = time.perf_counter()
    timings[name] = round((now - start) * 1e3, 3)
    return now


def scan_paths(section: RealScanScene) -> list[Path]:
    """The scans ``section.path`` names: one file, or every file of a folder (or a glob pattern) in name order."""
    if not section.path:
        raise InputError("scene.path: the real_scan builder needs the path of a scan file, a folder of them or a glob pattern")
    path = Path(section.path)
    if path.is_dir():
        found = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in SCAN_SUFFIXES)
    elif any(ch in section.path for ch in "*?["):
        found = sorted(p for p in path.parent.glob(path.name) if p.is_file())
    else:
        return [path]
    if not found:
        raise InputError(f"scene.path: no scan files ({', '.join(SCAN_SUFFIXES)}) in {section.path}")
    return found


SCAN_SUFFIXES = (".bin", ".npy", ".ply", ".las", ".laz", ".pcd")


@dataclass
class MixState:
    """A real-scan frame on its way through the mixing steps (:data:`MIX_STEPS`), each filling in its part.

    section, rng, effects, threads, table : as :func:`mix_frame`; scan, firings : the real sweep and its firings
    max_range : m, the cast's limit; timings : ms per step (``info["timings_ms"]``); clock : the last step's end (s)
    valid, removed : (f,) bool per firing: a real return kept, one removed by ``section.remove``
    semantic_real, instance_real : (f,) the real firings' labels; placements, rule_log : the inserted objects, the rules' log
    instances, semantic_ids : per placement; buffers : the inserted objects' scene buffers (sensor frame)
    hits, kept, occluded : the cast's hits, those kept, the real firings they hide
    new, h_firing : the inserted returns (POINT_DTYPE) and their firings; dropped_firings, visible_rays : for the record and boxes
    points, firing, inserted : the frame's records in firing order, their firings, which are inserted
    boxes, info : the frame's boxes (BOX_DTYPE, sensor frame) and its record
    """

    section: RealScanScene
    rng: np.random.Generator
    effects: object = None
    threads: int | None = None
    table: ClassTable | None = None
    scan: RealScan | None = None
    firings: Firings | None = None
    frame: int = 0
    timings: dict = field(default_factory=dict)
    clock: float = 0.0
    max_range: float = 100.0
    valid: np.ndarray | None = None
    removed: np.ndarray | None = None
    semantic_real: np.ndarray | None = None
    instance_real: np.ndarray | None = None
    placements: list = field(default_factory=list)
    surfaces: object = None  # the trace's MirrorGlassRules for the inserted objects (cast.glass_rules)
    paints: list = field(default_factory=list)  # per object row of buffers: its part's own model (paint.PartModel) or None
    rule_log: dict = field(default_factory=dict)
    instances: list = field(default_factory=list)
    semantic_ids: list = field(default_factory=list)
    buffers: object = None
    hits: InsertedHits | None = None
    kept: np.ndarray | None = None
    occluded: np.ndarray | None = None
    new: np.ndarray | None = None
    h_firing: np.ndarray | None = None
    dropped_firings: np.ndarray | None = None
    visible_rays: np.ndarray | None = None
    points: np.ndarray | None = None
    firing: np.ndarray | None = None
    inserted: np.ndarray | None = None
    boxes: np.ndarray | None = None
    info: dict | None = None

    def lap(self, name: str) -> None:
        """Time the step ``name`` ended now (ms since the last one ended)."""
        self.clock = _timed(self.timings, name, self.clock)

    def result(self) -> MixedFrame:
        return MixedFrame(self.points, self.boxes, self.info, self.firings, self.firing, self.inserted, self.placements, self.buffers)


def mix_background(state: MixState) -> None:
    """The real sweep: read (unless given), its firings recovered, ``section.remove`` cut out, its returns labelled."""
    section = state.section
    state.table = state.table or load_class_table()
    state.clock = time.perf_counter()
    if state.scan is None:
        paths = scan_paths(section)
        state.scan = read_real_scan(paths[state.frame % len(paths)], section.format or None)
    state.lap("read")
    state.firings = state.firings or recover_firings(state.scan, section.preset or None)
    state.lap("firings")
    state.max_range = section.max_range or 100.0
    if section.preset and not section.max_range:
        state.max_range = resolve_sensor({"preset": section.preset}, "scene.preset").max_range
    firings = state.firings
    valid = firings.valid.copy()
    returns = firings.returns
    removed = np.zeros(len(firings), bool)
    for box in section.remove:
        removed |= valid & in_box(returns, box.center, box.size, box.yaw_deg)
    valid &= ~removed
    state.valid, state.removed = valid, removed
    state.semantic_real, state.instance_real = real_labels(state.scan, firings, section, state.table)


def mix_place(state: MixState) -> None:
    """The objects to insert (explicit boxes, then the parking and KITTI rules on the ground found in the
    remaining real returns) and their meshes (each object's shape drawn from the generator)."""
    section, firings, valid, rng, table = state.section, state.firings, state.valid, state.rng, state.table
    returns = firings.returns
    placements = explicit_placements(section.objects)
    rule_log = {}
    if section.parking_rule.enabled or section.kitti_rule.enabled or any(r.enabled for r in section.parking_rules):
        xyz = returns[valid]
        ground = find_ground(xyz, section.ground)
        work = Firings(**{**firings.__dict__, "valid": valid})
        scene = Scene(work, ground, PointIndex(xyz[~ground.ground]), PointIndex(xyz[ground.ground]), list(placements), section.car_bodies)
        state.lap("ground")
        real = real_placements(section.real_boxes) + labelled_boxes(firings, state.semantic_real, state.instance_real, table)
        for k, rule in enumerate([section.parking_rule, *section.parking_rules]):
            if rule.enabled:
                placed, rule_log["parking" if k == 0 else f"parking_{k}"] = parking_rule(scene, rule, rng)
                placements += placed
        if section.kitti_rule.enabled:
            placed, rule_log["kitti"] = kitti_rule(scene, section.kitti_rule, xyz[ground.ground], real, rng)
            placements += placed
        rule_log["ground"] = {"method": ground.method, "normal": [round(float(v), 5) for v in ground.normal], "offset": round(ground.offset, 4),
                              "points": int(ground.ground.sum())}
    if section.population.people or section.population.arms:  # people and arms on the floors and desks found in the scan (.supports)
        from .supports import populate

        placed, rule_log["population"] = populate(returns[valid], section.population, rng, placements)
        placements += placed
    state.lap("placement")
    first_instance = int(state.instance_real.max(initial=0)) + 1
    state.instances = [first_instance + k for k in range(len(placements))]
    state.semantic_ids = [table.id_of(p.class_name, "scene.objects.class") for p in placements]
    paint = section.car_paint if section.car_paint.enabled else None  # each car's pigment from its own generator (rng is not advanced)
    parts = [getattr(p, "parts", None) or object_parts(p, rng, section.car_bodies, section.car_glass, section.car_fittings, paint,
                                                       paint and car_generator(rng, k))
             for k, p in enumerate(placements)]  # populated ones carry theirs
    state.paints = [part.paint for object_parts_ in parts for part in object_parts_]  # the rows of object_buffers, in order
    state.surfaces = glass_rules(parts, section.car_glass)
    state.buffers = object_buffers(placements, parts, state.instances, state.semantic_ids)
    state.placements, state.rule_log = placements, rule_log
    state.lap("meshes")


def mix_cast(state: MixState) -> None:
    """Every real firing cast at the inserted objects: their hits, those kept (nearer than the real return) and the real returns they hide."""
    work = Firings(**{**state.firings.__dict__, "valid": state.valid})
    state.hits = cast_firings(work, state.buffers, state.max_range, state.threads, surfaces=state.surfaces, rng=state.rng)
    state.kept, state.occluded = merge_returns(work, state.hits)
    state.lap("cast")


def mix_effects(state: MixState) -> None:
    """The inserted returns as records, given the fitted drop and noise models (``effects``) and the noise
    injections; then the real returns that stay, interior points and class flips: the frame's records in firing order."""
    firings, rng, section = state.firings, state.rng, state.section
    hits, kept = state.hits, state.kept
    h = InsertedHits(*(a[kept] for a in (hits.firing, hits.path, hits.row, hits.cos_incidence, hits.gain, hits.bounces)))
    objects = state.buffers.objects
    new = np.zeros(len(h.firing), POINT_DTYPE)
    xyz_new = firings.origin[h.firing] + h.path[:, None] * firings.direction[h.firing]
    new["x"], new["y"], new["z"] = xyz_new.T
    new["range"] = h.path
    new["semantic"] = objects.semantic[h.row]
    new["instance"] = objects.instance[h.row]
    new["ring"] = firings.ring[h.firing]
    new["time"] = firings.time[h.firing]
    new["bounces"] = h.bounces
    beam = np.zeros(len(h.firing), BEAM_DTYPE)
    beam["cos_incidence"] = h.cos_incidence
    beam["reflectivity"] = objects.reflectivity[h.row]
    beam["gain"] = h.gain
    beam["direction"] = firings.direction[h.firing]
    new["intensity"] = np.clip(beam["reflectivity"] * beam["cos_incidence"] * beam["gain"], 0, 1)
    state.visible_rays = np.bincount(new["instance"], minlength=max(state.instances, default=0) + 1)
    dropped_firings = np.zeros(0, np.int64)
    if state.effects is not None and len(new):
        new, rows = _effects(new, beam, state.effects, rng, objects, state.paints, h.row)
        dropped_firings = np.setdiff1d(h.firing, h.firing[rows])
        h_firing = h.firing[rows]
    else:
        h_firing = h.firing
    noise = section.noise
    if len(new) and (noise.dropout_max > 0 or noise.range_sigma[1] > 0 or noise.cutoff_probability > 0):
        present = np.unique(new["instance"])
        keep = injections.object_dropout(new["instance"], present, noise, rng)
        keep &= injections.vertical_cutoff(np.column_stack([new["x"], new["y"]]).astype(float), new["instance"], present, noise, rng)
        step = injections.object_range_noise(new["instance"], present, noise, rng).astype(np.float32)
        d = firings.direction[h_firing]
        for axis, k in enumerate("xyz"):
            new[k] += step * d[:, axis].astype(np.float32)
        new["range"] += step
        new, h_firing = new[keep], h_firing[keep]
    state.dropped_firings = dropped_firings
    state.hits = h
    state.lap("effects")
    _merge_records(state, new, h_firing)
    state.lap("records")


def _merge_records(state: MixState, new: np.ndarray, h_firing: np.ndarray) -> None:
    """The real returns that stay (valid, not hidden by a kept hit; a dropped inserted firing stays empty), the
    interior points (on the nearest firing, kept only where nearer than its return), all in firing order, class flips last."""
    firings, rng, noise, placements = state.firings, state.rng, state.section.noise, state.placements
    returns = firings.returns
    stay = state.valid & ~state.occluded
    real_rows = np.flatnonzero(stay)
    old = np.zeros(len(real_rows), POINT_DTYPE)
    old["x"], old["y"], old["z"] = returns[real_rows].T
    old["intensity"] = firings.intensity[real_rows]
    old["semantic"], old["instance"] = state.semantic_real[real_rows], state.instance_real[real_rows]
    old["ring"], old["time"], old["range"] = firings.ring[real_rows], firings.time[real_rows], firings.range[real_rows]

    extra_points, extra_firing = np.zeros(0, POINT_DTYPE), np.zeros(0, np.int64)
    if noise.interior_points > 0 and placements:
        centres = np.array([p.centre for p in placements])
        pts, owner = injections.interior_points(centres, noise, rng)
        f, r = injections.nearest_firing(firings, pts)
        current = np.full(len(firings), np.inf)
        current[real_rows] = firings.range[real_rows]
        current[h_firing] = new["range"]
        ok = (r > 0) & (r < current[f])
        order = np.argsort(r, kind="stable")
        seen = set()
        pick = [i for i in order if ok[i] and not (int(f[i]) in seen or seen.add(int(f[i])))]
        pick = np.array(sorted(pick), np.int64)
        if len(pick):
            extra_firing = f[pick]
            extra_points = np.zeros(len(pick), POINT_DTYPE)
            xyz = firings.origin[extra_firing] + r[pick, None] * firings.direction[extra_firing]
            extra_points["x"], extra_points["y"], extra_points["z"] = xyz.T
            extra_points["range"] = r[pick]
            extra_points["semantic"] = np.array(state.semantic_ids, np.uint16)[owner[pick]]
            extra_points["instance"] = np.array(state.instances, np.uint32)[owner[pick]]
            extra_points["ring"], extra_points["time"] = firings.ring[extra_firing], firings.time[extra_firing]
            # the firing's earlier return (real or inserted) gives way
            drop_real = np.isin(real_rows, extra_firing)
            old, real_rows = old[~drop_real], real_rows[~drop_real]
            drop_new = np.isin(h_firing, extra_firing)
            new, h_firing = new[~drop_new], h_firing[~drop_new]

    points = np.concatenate([old, new, extra_points])
    firing = np.concatenate([real_rows, h_firing, extra_firing])
    inserted = np.concatenate([np.zeros(len(old), bool), np.ones(len(new) + len(extra_points), bool)])
    order = np.argsort(firing, kind="stable")
    points, firing, inserted = points[order], firing[order], inserted[order]
    if noise.class_flip > 0:
        classes = np.unique(points["semantic"])
        points["semantic"] = injections.class_flips(points["semantic"], classes, noise, rng)
    state.points, state.firing, state.inserted = points, firing, inserted


def mix_annotate(state: MixState) -> None:
    """The frame's boxes (:func:`mixed_boxes`) and its record (``info``)."""
    firings, section, scan = state.firings, state.section, state.scan
    labelled = labelled_boxes(firings, state.semantic_real, state.instance_real, state.table) if scan.labels is not None and section.keep_labels else []
    state.boxes = mixed_boxes(firings, state.valid, state.placements, state.instances, state.buffers, state.visible_rays, state.points, section,
                              firings.returns, state.occluded, labelled, state.threads)
    state.lap("boxes")
    state.info = {
        "scan": {"path": str(scan.path), "format": scan.format, "points": int(len(scan)), "notes": list(scan.notes)},
        "firings": firings.info(),
        "removed": int(state.removed.sum()),
        "objects": [dict(p.info(), instance=i) for p, i in zip(state.placements, state.instances)],
        "rules": state.rule_log,
        "inserted_points": int(state.inserted.sum()),
        "occluded_real": int(state.occluded.sum()),
        "filled_empty": int((~state.valid[state.hits.firing]).sum()),
        "dropped_inserted": int(len(state.dropped_firings)),
        "timings_ms": state.timings,
    }


MIX_STEPS = (mix_background, mix_place, mix_cast, mix_effects, mix_annotate)  # in this order: the generator's draws follow it


def mix_frame(section: RealScanScene, rng: np.random.Generator, effects=None, threads: int | None = None, table: ClassTable | None = None,
              scan: RealScan | None = None, firings: Firings | None = None, frame: int = 0) -> MixedFrame:
    """Insert ``section``'s objects into its real scan, exact per firing (module notes): :data:`MIX_STEPS` in turn
    (the real-scan frame plan runs the same steps as its stages, :mod:`bpy_pipeline.stages.mixing`).

    rng : the frame's generator (placement rules, object shapes, effects and injections draw from it in a fixed order)
    frame : the frame index; with a folder or pattern of scans, frame k uses scan k (mod their number)
    effects : a ``config.EffectsConfig`` for the inserted returns (``None``: exact, no drop or noise)
    scan, firings : already read (benchmarks reuse them across frames); read from ``section.path`` when ``None``
    """
    state = MixState(section, rng, effects, threads, table, scan, firings, frame)
    for step in MIX_STEPS:
        step(state)
    return state.result()


def azimuth_coverage(firings: Firings, bins: int = 720) -> np.ndarray:
    """``(bins,)`` bool: azimuth cells (0.5 deg by default) some firing points into."""
    az, _ = angles_deg(firings.direction)
    covered = np.zeros(bins, bool)
    covered[((az + 180.0) / 360.0 * bins).astype(np.int64) % bins] = True
    return covered


def mixed_boxes(firings, valid, placements, instances, buffers, visible_rays, points, section, returns, occluded, labelled, threads) -> np.ndarray:
    """Boxes of the inserted objects, of the section's ``real_boxes`` and of the scan's labelled vehicles (module notes)."""
    real = real_placements(section.real_boxes) + list(labelled)
    boxes = np.zeros(len(placements) + len(real), BOX_DTYPE)
    if not len(boxes):
        return boxes
    covered = azimuth_coverage(firings)
    _, el = angles_deg(firings.direction)
    el_lo, el_hi = el.min() - 0.5, el.max() + 0.5
    counts = np.bincount(points["instance"], minlength=max(instances, default=0) + 1)
    for k, (p, inst) in enumerate(zip(placements, instances)):
        rows = np.flatnonzero(buffers.objects.instance == inst)
        alone = cast_firings(firings, _subset(buffers, rows), section.max_range or 100.0, threads, rows=near_objects(firings, buffers, inst))
        tri = buffers.triangles[np.isin(buffers.triangle_object, rows)]
        samples, _ = surface_samples(buffers.vertices[tri], 0.25)
        az, sel = angles_deg(samples / np.maximum(np.linalg.norm(samples, axis=1, keepdims=True), 1e-9))
        inside = covered[((az + 180.0) / 360.0 * len(covered)).astype(np.int64) % len(covered)] & (sel >= el_lo) & (sel <= el_hi)
        b = boxes[k]
        b["class_name"], b["instance"], b["centre"], b["size"], b["heading"] = p.class_name, inst, p.centre, p.size, p.yaw
        b["truncation"] = 1.0 - float(inside.mean()) if len(inside) else 0.0
        b["visible"], b["unoccluded"] = int(visible_rays[inst]) if inst < len(visible_rays) else 0, len(alone.firing)
        b["points"] = int(counts[inst]) if inst < len(counts) else 0
    for j, p in enumerate(real):
        inside = valid & in_box(returns, p.centre, p.size, math.degrees(p.yaw))
        b = boxes[len(placements) + j]
        b["class_name"], b["instance"], b["centre"], b["size"], b["heading"] = p.class_name, 0, p.centre, p.size, p.yaw
        b["unoccluded"] = int(inside.sum())
        b["visible"] = int((inside & ~occluded).sum())
        b["points"] = b["visible"]
    boxes["occlusion"] = occlusion_levels(boxes["visible"], boxes["unoccluded"], OCCLUSION_LEVELS)
    return boxes


def _subset(buffers, rows):
    return subset_buffers(buffers, list(int(r) for r in rows))


frame_boxes = mixed_boxes  # the old name (it collided with the sensor frames' boxes, stages.annotate.sensor_boxes)
