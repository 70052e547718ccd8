"""``scene.builder: railway``: tracks, supports and catenary along an arc through three points (bpy).

The layout (alignment, supports, spans, wires, droppers, stations) comes from the pure
:mod:`~bpy_pipeline.builders.railway.layout`; this module turns it into tagged Blender objects:

- ``track_centreline``: a poly curve through the alignment at formation level (not scanned);
  the "Track" Geometry Nodes group follows it, and a trajectory can follow it too
  (``sensor.trajectory.curve: track_centreline``; the rail heads are ``rail_top_height`` above it);
- one object per track part, each running the "Track" group (:mod:`.railway_nodes`) with its
  ``Part``: ``rails.t<i>`` and ``sleepers.t<i>`` per track, ``ballast``, ``ballast_stones.s<k>`` (around station k, or stretch k of a moving sensor's path),
  ``embankment``, ``ground``;
- per support ``support.<k>.mast.<side>``: the masts are instanced at the supports' frames by the "Railway Supports"
  group (:mod:`.support_nodes`) on one points object per mast prototype (``supports.mast.<side>.<n>``), whose
  realized faces carry the part name ``support.<k>.mast.<side>`` the export labels them by; or ``support.<k>.gantry``
  (an object); per track a support carries
  ``support.<k>.cantilever.t<i>``, ``support.<k>.registration_arm.t<i>``, ``support.<k>.insulators.t<i>``
  (``support.<k>.steady_arm.t<i>`` with ``catenary.steady_arms``), anchors and weights at the line's ends
  and at the two supports of every tension-section overlap (``support.<k>.anchor.<side>``),
  and ``support.<k>.insulators.<side>`` (the feeder's);
- per span and run (``t<i>``; ``t<i>s<m>`` for tension section m) ``span.<run>.<k>.<wire>`` (contact_wire, messenger_wire, feeder, earth_wire)
  and ``span.<run>.<k>.droppers``: wires are bevelled curves of their real diameters, so every
  element has its class and an instance per span.

Detail follows the sensor (:func:`~bpy_pipeline.builders.railway.layout.level_of_detail`) when the
pipeline passes a :class:`~bpy_pipeline.geometry.lod.SensorView`.
"""

from __future__ import annotations

import dataclasses
import math

import bpy
import mathutils
import numpy as np

from ...geometry.lod import equal_perimeter_radius
from ...geometry.primitives import merge
from ...blender.nodes import add_group_modifier
from ...blender.mesh_objects import mesh_data, mesh_object, scene_collection, tag
from . import parts as railway_parts, trackside
from .catenary import parabolic_sag
from .terrain import terrain_mesh
from .layout import (ARM_RISE, BEAM_RADIUS, EARTH_BRACKET, FEEDER_BRACKET, MIN_WIRE_SIDES, STAY_RISE, RailwayLayout, cant_angle, cantilevers,
                     level_of_detail, plan)
from . import catenary_nodes, scene_assets as railway_assets, support_nodes
from .track_nodes import PARTS, track_group

CENTRELINE = "track_centreline"
PATH_TOLERANCE = 0.01  # m: the centreline a planned path follows, sampled this close (detail grading only)
STONE_CENTRES = "track_stone_centres"
REFLECTIVITY = {
    "rail": 0.6, "sleeper": 0.4, "ballast": 0.35, "ground": 0.3, "mast": 0.5, "gantry": 0.5, "cantilever": 0.5,
    "registration arm": 0.5, "steady arm": 0.5, "insulator": 0.4, "contact wire": 0.7, "messenger wire": 0.7, "dropper": 0.6,
    "feeder wire": 0.6, "earth wire": 0.6, "auxiliary messenger": 0.7, "anchor": 0.5, "tensioning weight": 0.3, "section insulator": 0.4, "fence": 0.4,
    "signal": 0.5, "platform": 0.35, "vegetation": 0.45,
}


def build(params, rng: np.random.Generator, view=None) -> RailwayLayout:
    """Build the railway of a ``RailwayScene`` config; ``view`` (a SensorView) drives the level of detail.

    Returns the :class:`~bpy_pipeline.builders.railway.layout.RailwayLayout` that was built, with the
    ``(k, 4, 4)`` frames of the signals it placed (the ground truth writers read it, never re-draw it).
    """
    collection = scene_collection()
    layout = plan(params, rng)
    if view is not None:  # a moving sensor's path may follow the centreline: known now, before anything is built
        view = view.following({CENTRELINE: layout.alignment.point(layout.alignment.chainage_samples(PATH_TOLERANCE))})
    view = view.distinct() if view is not None else None
    detail = level_of_detail(layout, params, view)
    centreline = _centreline(layout, detail.centreline_tolerance, cant_angle(params.track, layout.alignment), collection)
    centreline["rail_top_height"] = float(layout.section.rail_top)
    _track(params, layout, detail, centreline, int(rng.integers(0, 2**31 - 1)), collection, cant_angle(params.track, layout.alignment))
    _supports(params, layout, detail, collection)
    railway_assets.place(params, layout, detail, collection, REFLECTIVITY)  # scene.assets: support assets from files in place of these
    _wires(layout, detail, collection)
    _anchors_and_sections(params, layout, detail, collection)
    signals = _trackside(params, layout, rng, collection)
    bpy.context.view_layer.update()
    return dataclasses.replace(layout, signals=signals)


def _centreline(layout: RailwayLayout, tolerance: float, roll: float, collection) -> bpy.types.Object:
    """The alignment as a poly curve; its points' tilt is the track's cant ``roll`` (radians, + raises the left rail)."""
    alignment = layout.alignment
    points = alignment.point(alignment.chainage_samples(tolerance))  # one tilt per point below
    curve = bpy.data.curves.new(CENTRELINE, "CURVE")
    curve.dimensions = "3D"
    spline = curve.splines.new("POLY")
    spline.points.add(len(points) - 1)
    spline.points.foreach_set("co", np.column_stack([points, np.ones(len(points))]).astype(np.float32).ravel())
    if roll:  # full cant on the arc, ramping with the curvature along transition curves
        s = alignment.chainage_samples(tolerance)
        share = alignment.curvature(s) * alignment.radius
        spline.points.foreach_set("tilt", (roll * share).astype(np.float32))
    obj = bpy.data.objects.new(CENTRELINE, curve)
    obj.hide_render = True  # a guide, not a surface: never scanned
    collection.objects.link(obj)
    return obj


def _stone_centre(name: str, points, collection) -> bpy.types.Object:
    """A mesh object of vertices at ``points`` ((c, 3) world, m): the centres the "Track" group scatters stones around."""
    points = np.asarray(points, np.float32).reshape(-1, 3)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(points))
    mesh.vertices.foreach_set("co", points.ravel())
    obj = bpy.data.objects.new(name, mesh)
    obj.hide_render = True
    collection.objects.link(obj)
    return obj


def _track(params, layout, detail, centreline, seed: int, collection, roll: float = 0.0) -> None:
    track = params.track
    rail = track.rail
    inputs = {
        "Centreline": centreline, "Tracks": track.tracks, "Track Spacing": track.track_spacing, "Gauge": track.gauge,
        "Rail Foot Width": rail.foot_width, "Rail Foot Height": rail.foot_height, "Rail Web Width": rail.web_width,
        "Rail Web Height": rail.web_height, "Rail Head Width": rail.head_width, "Rail Head Height": rail.head_height,
        "Sleeper Spacing": track.sleeper_spacing, "Sleeper Length": track.sleeper_length, "Sleeper Width": track.sleeper_width,
        "Sleeper Height": track.sleeper_height, "Ballast Height": track.ballast_height, "Crib Height": track.crib_height,
        "Ballast Shoulder": track.ballast_shoulder,
        "Ballast Slope": track.ballast_slope, "Embankment Height": track.embankment_height, "Embankment Slope": track.embankment_slope,
        "Embankment Berm": track.embankment_berm, "Ground Width": track.ground_width, "Stone Size": params.detail.stone_size, "Seed": seed, "Cant Angle": roll,
    }
    group = track_group()
    parts = [(f"rails.t{i}", "rails", "rail", i) for i in range(track.tracks)]
    parts += [(f"sleepers.t{i}", "sleepers", "sleeper", i) for i in range(track.tracks)]
    terrain = track.cut_depth > 0 or track.ground_roughness > 0  # the ground as a height field instead of the group's flat strip
    parts += [("ballast", "ballast", "ballast", -1)] + ([] if terrain else [("ground", "ground", "ground", -1)])
    if terrain and detail.ground_trim[1] > detail.ground_trim[0]:
        mesh = terrain_mesh(layout.alignment, layout.section, track.ground_width, detail.ground_trim, track.ground_roughness, track.ground_wavelength,
                            np.random.default_rng([seed, 1]))
        tag(mesh_object("ground", mesh, collection), "ground", reflectivity=REFLECTIVITY["ground"])
    if track.embankment_height > 0:
        parts.append(("embankment", "embankment", "ground", -1))
    trims = {name: detail.ground_trim if part == "ground" else detail.track_trim for name, part, _, _ in parts}
    extras = {}
    for (k, trim), points in zip(detail.stone_trims, detail.stone_centres):  # one stones object per station or stretch of path
        name = f"ballast_stones.s{k}"
        parts.append((name, "stones", "ballast", -1))
        trims[name] = trim
        centre = _stone_centre(f"{STONE_CENTRES}.s{k}", points, collection)
        extras[name] = {"Stone Centres": centre, "Stone Radius": detail.stone_radius, "Seed": seed + k}
    for name, part, class_name, index in parts:
        trim = trims[name]
        if trim[1] <= trim[0]:
            continue
        obj = mesh_object(name, (np.zeros((0, 3)), np.zeros((0, 3), np.int32)), collection)
        extra = {"Part": PARTS[part], "Track": index, "Trim Start": trim[0], "Trim End": trim[1]}
        add_group_modifier(obj, group, inputs | extra | extras.get(name, {}))
        tag(obj, class_name, reflectivity=REFLECTIVITY[class_name])


def _placed(name: str, mesh, frame: np.ndarray, class_name: str, collection) -> bpy.types.Object:
    obj = mesh_object(name, mesh, collection)
    obj.matrix_world = mathutils.Matrix(frame.tolist())
    return tag(obj, class_name, reflectivity=REFLECTIVITY[class_name])


def _mast_mesh(mast, cat) -> tuple[np.ndarray, np.ndarray]:
    """A mast with the brackets of its feeder and earth wire, in the support frame."""
    parts = [railway_parts.mast(mast.kind, mast.top - mast.base, (0.0, mast.lateral, mast.base))]
    if cat.feeders:
        parts.append(railway_parts.bracket(mast.lateral, mast.outward, FEEDER_BRACKET[0] + 0.15, mast.top - 0.05))
    if cat.earth_wire:
        parts.append(railway_parts.bracket(mast.lateral, mast.outward, EARTH_BRACKET[0] + 0.1, mast.top + EARTH_BRACKET[1] + 0.05))
    return merge(parts)


def _supports(params, layout: RailwayLayout, detail, collection) -> None:
    cat, section = params.catenary, layout.section
    contact_z = section.rail_top + cat.contact_wire_height
    messenger_z = contact_z + cat.system_height
    instanced: dict[tuple, tuple] = {}  # identical masts (same side, kind, height): one prototype -> (mast, [frames], [names])
    procedural_masts = not params.assets.mast  # scene.assets.mast: the files' masts stand in their place
    for k in detail.supports:
        support = layout.supports[k]
        frame = np.asarray(support.frame, float)
        label = f"support.{k:02d}"
        beam_underside = None
        if support.gantry:
            right, left = support.masts
            mesh, beam_underside = railway_parts.gantry(left.lateral, right.lateral, left.base, right.base, left.top, left.kind)
            _placed(f"{label}.gantry", mesh, frame, "gantry", collection)
        for mast in support.masts:
            if not support.gantry:
                key = (mast.side, mast.kind, round(mast.top, 6), round(mast.base, 6), round(mast.lateral, 6))
                if procedural_masts:
                    entry = instanced.setdefault(key, (mast, [], []))
                    entry[1].append(frame)
                    entry[2].append(f"{label}.mast.{mast.side}")
            if cat.feeders:  # the feeder hangs from its bracket on a rod insulator
                y = mast.lateral + mast.outward * FEEDER_BRACKET[0]
                feeder = railway_parts.insulator((0.0, y, mast.top - 0.075), (0.0, y, mast.top + FEEDER_BRACKET[1] + 0.02), 0.05, 3)
                _placed(f"{label}.insulators.{mast.side}", feeder, frame, "insulator", collection)
        for plan_ in cantilevers(support, section, cat, params.track.track_spacing, beam_underside):
            i = plan_.track
            steady = min(cat.steady_arm_length, plan_.arm_length - 0.2) if cat.steady_arms else 0.0
            pieces = railway_parts.cantilever(plan_.root_y, plan_.attach_y, contact_z, messenger_z, STAY_RISE, plan_.drop_from, plan_.arm_length, ARM_RISE,
                                              steady)
            if plan_.beam is not None:  # a mast's beam out to the drop tube of a farther track
                y0, y1, z = plan_.beam
                pieces["cantilever"] = merge([pieces["cantilever"],
                                              railway_parts.tube((0.0, y0, z), (0.0, y1 + np.sign(y1 - y0) * BEAM_RADIUS, z), BEAM_RADIUS)])
            _placed(f"{label}.cantilever.t{i}", pieces["cantilever"], frame, "cantilever", collection)
            _placed(f"{label}.registration_arm.t{i}", pieces["registration arm"], frame, "registration arm", collection)
            _placed(f"{label}.insulators.t{i}", pieces["insulator"], frame, "insulator", collection)
            if "steady arm" in pieces:
                _placed(f"{label}.steady_arm.t{i}", pieces["steady arm"], frame, "steady arm", collection)
    _instanced_masts(instanced, cat, collection)


def _instanced_masts(instanced: dict, cat, collection) -> None:
    """One "Railway Supports" object per mast prototype, at the frames of the supports that carry it (:mod:`.support_nodes`)."""
    for n, (mast, frames, names) in enumerate(instanced.values()):
        mesh = mesh_data(f"mast.{mast.side}.{mast.kind}", *_mast_mesh(mast, cat))
        prototype = support_nodes.prototype_object(f"mast.{mast.side}.{mast.kind}.{n}", mesh, collection)
        obj = support_nodes.supports_object(f"supports.mast.{mast.side}.{n}", prototype, np.stack(frames), names, collection)
        tag(obj, "mast", reflectivity=REFLECTIVITY["mast"])


def _anchors_and_sections(params, layout: RailwayLayout, detail, collection) -> None:
    """Tensioning weights at the end masts (``catenary.anchors``) and section insulators on the contact wires."""
    cat = params.catenary
    anchors: dict[tuple[int, str], tuple[float, list]] = {}  # (support, mast side) -> (behind, wire ends roped to it, world)
    if cat.anchors and len(layout.supports) > 1:
        for k, behind in ((0, -0.6), (len(layout.supports) - 1, 0.6)):
            for mast in layout.supports[k].masts:
                anchors[(k, mast.side)] = (behind, [])
    for overlap in layout.overlaps:  # the starting run is pulled off to an anchor at the near support, the ending run at the far one
        for k, run, behind, end in ((overlap.span, overlap.starting, -0.6, "start"), (overlap.span + 1, overlap.ending, 0.6, "end")):
            mast = next((m for m in layout.supports[k].masts if overlap.track in m.tracks), None)
            if mast is None:
                continue
            ends = [getattr(w, end) for w in layout.wires if w.span == overlap.span and w.run in (run, run + "b")]
            anchors.setdefault((k, mast.side), (behind, []))[1].extend(ends)
    for (k, side), (behind, ends) in sorted(anchors.items()):
        support = layout.supports[k]
        if k not in detail.supports or support.gantry:
            continue
        mast = next(m for m in support.masts if m.side == side)
        frame = np.asarray(support.frame, float)
        pieces = railway_parts.tensioning_weight(mast.lateral, behind, mast.top)
        anchor = pieces["anchor"]
        if ends:  # the ropes from the wires' raised ends, in the support's frame
            local = (np.asarray(ends, float) - frame[:3, 3]) @ frame[:3, :3]
            anchor = merge([anchor, railway_parts.anchor_ropes(local, railway_parts.pulley_top(mast.lateral, behind, mast.top))])
        _placed(f"support.{k:02d}.anchor.{side}", anchor, frame, "anchor", collection)
        _placed(f"support.{k:02d}.tensioning_weight.{side}", pieces["tensioning weight"], frame, "tensioning weight", collection)
    if cat.section_insulator_every > 0:
        twins = {(w.run[:-1], w.span): w for w in layout.wires if w.kind == "contact_wire" and w.run.endswith("b")}
        for wire, setting in zip(layout.wires, detail.wires):
            if wire.kind != "contact_wire" or wire.run.endswith("b") or setting is None or (wire.span + 1) % cat.section_insulator_every:
                continue
            centre = wire.points_at([0.5])[0]
            twin = twins.get((wire.run, wire.span))
            if twin is not None:  # one insulator takes both wires of a twin contact wire
                centre = (centre + twin.points_at([0.5])[0]) / 2
            direction = wire.end - wire.start
            yaw = math.atan2(direction[1], direction[0])
            obj = mesh_object(f"span.{wire.run}.{wire.span:02d}.section_insulator", railway_parts.section_insulator(), collection, location=tuple(centre),
                              rotation=(0.0, 0.0, yaw))
            tag(obj, "section insulator", reflectivity=REFLECTIVITY["section insulator"])


def _trackside(params, layout: RailwayLayout, rng: np.random.Generator, collection) -> np.ndarray:
    """Fences, signals, vegetation and the platform of ``scene.trackside`` (nothing is drawn from ``rng`` without
    signals or vegetation); returns the signals' ``(k, 4, 4)`` frames."""
    side, section, alignment = params.trackside, layout.section, layout.alignment
    if side.fences:
        for name, lateral in (("right", section.offsets[0] - side.fence_offset), ("left", section.offsets[-1] + side.fence_offset)):
            tag(mesh_object(f"fence.{name}", trackside.fence(alignment, section.surface, side, lateral), collection), "fence",
                reflectivity=REFLECTIVITY["fence"])
    signals = np.asarray(trackside.signal_frames(layout, side, rng), float).reshape(-1, 4, 4)
    for k, frame in enumerate(signals):
        tag(mesh_object(f"signal.{k:02d}", trackside.signal(frame, side.signal_height, -1.0), collection), "signal", reflectivity=REFLECTIVITY["signal"])
    inner = (side.fence_offset if side.fences else params.supports.mast_offset + 2.0) + float(section.offsets[-1]) + 1.0
    plants = trackside.vegetation(alignment, section.surface, side, inner, params.track.ground_width / 2 - 1.0, rng)
    if plants is not None:
        tag(mesh_object("vegetation", plants, collection), "vegetation", reflectivity=REFLECTIVITY["vegetation"])
    nearest = section.offsets[-1] if side.platform_side == "left" else section.offsets[0]
    mesh = trackside.platform(alignment, section.surface, side, section.rail_top, float(nearest))
    if mesh is not None:
        tag(mesh_object("platform", mesh, collection), "platform", reflectivity=REFLECTIVITY["platform"])
    return signals


def _bevel_sides(sides: int) -> int:
    """Sides of the section a curve bevel draws when asked for ``sides`` (4, 6, 8...: 4 + 2 x resolution)."""
    return 4 + 2 * max(0, (sides - 4) // 2)


def _wires(layout: RailwayLayout, detail, collection) -> None:
    """Wires and droppers as curves run by the "Catenary Wire" and "Catenary Droppers" groups (:mod:`.catenary_nodes`),
    swept to the mean width of their real diameters."""
    by_key = {(w.run, w.span, w.kind): w for w in layout.wires}
    for wire, setting in zip(layout.wires, detail.wires):
        if setting is None:
            continue
        samples, sides = setting
        points = parabolic_sag(wire.start, wire.end, wire.sag, samples, f"span {wire.run}.{wire.span}")
        sides = _bevel_sides(sides)
        obj = catenary_nodes.wire_object(f"span.{wire.run}.{wire.span:02d}.{wire.kind}", points, wire.sag, equal_perimeter_radius(wire.diameter / 2, sides),
                                         sides, collection)
        tag(obj, wire.class_name, reflectivity=REFLECTIVITY[wire.class_name])
    for droppers, built in zip(layout.droppers, detail.droppers):
        if built and len(droppers.t):
            lower, upper = _dropper_wires(droppers, by_key)
            name = f"span.{droppers.run}.{droppers.span:02d}.droppers"
            obj = catenary_nodes.droppers_object(name, droppers, lower, upper, equal_perimeter_radius(droppers.diameter / 2, MIN_WIRE_SIDES), MIN_WIRE_SIDES,
                                                 collection)
            tag(obj, "dropper", reflectivity=REFLECTIVITY["dropper"])


def _dropper_wires(droppers, by_key: dict):
    """The wires a set of droppers hangs between: (lower, upper). Run ``<base>p`` is the upper tier (auxiliary messenger to
    messenger); ``<base>b`` the second contact wire of ``<base>``, hung from the same messenger (or auxiliary messenger)."""
    run, span = droppers.run, droppers.span
    if run.endswith("p"):
        return by_key[(run[:-1], span, "auxiliary_messenger")], by_key[(run[:-1], span, "messenger_wire")]
    base = run[:-1] if run.endswith("b") else run
    upper = by_key.get((base, span, "auxiliary_messenger")) or by_key[(base, span, "messenger_wire")]
    return by_key[(run, span, "contact_wire")], upper
