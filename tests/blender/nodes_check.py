"""Runs inside a real Blender (``blender --background --python nodes_check.py -- OUT.json WORK``) for the lane.

What issue 31 asks of every Blender: per builder, the node groups and Geometry Nodes modifiers of
its first frame; the groups against the pure functions (catenary wires against the thesis's
parabola, the parking level and the hall against their pure boxes: the largest vertex
difference); and edit-and-rescan: a scene built, scanned, one group input changed from Python
(the parking's bay width, the street's tree density, a contact wire's sag), scanned again: what
changed and what did not. Writes its findings to OUT.json; test_real_blender.py judges them.
"""

from __future__ import annotations

import json
import sys
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

OUT, WORK = Path(sys.argv[-2]), Path(sys.argv[-1])


def config_of(builder: str, *overrides):
    from bpy_pipeline.config import load_config

    return load_config({"seed": 0, "frames": 1, "scene": {"builder": builder}, "effects": {"ideal": True}, "output": {"formats": ["ply"], "preview": False}},
                       list(overrides))


def built(builder: str, *overrides):
    from bpy_pipeline.stages.scene import build_frame_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = config_of(builder, *overrides)
    result = build_frame_scene(config, 0)
    return config, result


def counts() -> dict:
    modifiers = [m for o in bpy.data.objects for m in o.modifiers if m.type == "NODES"]
    return {"objects": len(bpy.data.objects), "modifiers": len(modifiers), "groups": sorted({m.node_group.name for m in modifiers})}


def scan(config, name: str) -> np.ndarray:
    """The scene as it is, scanned (the panel's Scan: no rebuild); the frame's points."""
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.plan import run_frames

    out = WORK / "nodes" / name
    for _ in run_frames(config, out, build=False, mode="overwrite"):
        pass
    return read_ply(out / "ply" / "000000.ply")


def evaluated(obj) -> np.ndarray:
    e = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = e.to_mesh()
    v = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", v)
    e.to_mesh_clear()
    return v.reshape(-1, 3).astype(np.float64)


def set_input(obj, name, value):
    from bpy_pipeline.blender.compat import set_modifier_input

    set_modifier_input(obj.modifiers[0], name, value)  # as a user would from the Python console
    obj.update_tag()
    bpy.context.view_layer.update()


def beams(points) -> dict:
    return {(int(r), float(t)): i for i, (r, t) in enumerate(zip(points["ring"], points["time"]))}


def exported_pieces(names) -> dict:
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    buffers = export_scene(load_class_table())
    out = {}
    for name in names:
        t = buffers.triangles[buffers.triangle_object == buffers.objects.names.index(name)]
        out[name] = buffers.vertices[t].reshape(-1, 3)
    return out


def main() -> dict:
    from bpy_pipeline.builders.railway.catenary import parabolic_sag
    from bpy_pipeline.geometry.indoor import boxes_mesh, hall_layout, parking_layout

    found: dict = {"blender": bpy.app.version_string, "counts": {}, "max_vertex_difference_m": {}}
    for builder in ("railway", "parking", "industrial_hall", "street"):
        built(builder)
        found["counts"][builder] = counts()

    # railway: every wire's centreline against the thesis's parabola
    config, result = built("railway", "sensor.horizontal_resolution_deg=0.3")  # a coarser scan: the lane's time is short
    layout = result.scene
    worst = 0.0
    for wire in layout.wires:
        obj = bpy.data.objects.get(f"span.{wire.run}.{wire.span:02d}.{wire.kind}")
        if obj is None:
            continue
        set_input(obj, "Sweep", False)
        points = evaluated(obj)
        set_input(obj, "Sweep", True)
        worst = max(worst, float(np.abs(points - parabolic_sag(wire.start, wire.end, wire.sag, len(points))).max()))
    found["max_vertex_difference_m"]["catenary wires"] = worst
    # railway: every instanced mast ("Railway Supports") against the pure layout's mast in its support's frame
    from bpy_pipeline.builders.railway.scene import _mast_mesh
    from bpy_pipeline.builders.railway.support_nodes import realized_parts

    worst, masts = 0.0, 0
    for obj in [o for o in bpy.data.objects if o.name.startswith("supports.mast.")]:
        for name, vertices in realized_parts(obj).items():
            support = layout.supports[int(name.split(".")[1])]
            mast = next(m for m in support.masts if m.side == name.split(".")[3])
            pure = _mast_mesh(mast, config.scene.params.catenary)[0] @ support.frame[:3, :3].T + support.frame[:3, 3]
            worst, masts = max(worst, float(np.abs(vertices - pure).max())), masts + 1
    found["max_vertex_difference_m"]["railway masts"] = worst
    found["railway_masts"] = masts
    # edit and rescan: every contact wire 0.3 m more sag
    before = scan(config, "railway_before")
    for obj in bpy.data.objects:
        if obj.name.endswith(".contact_wire"):
            from bpy_pipeline.blender.compat import get_modifier_input

            set_input(obj, "Sag", get_modifier_input(obj.modifiers[0], "Sag") + 0.3)
    after = scan(config, "railway_after")
    found["railway_sag"] = compare(before, after, "contact wire")

    # parking: pieces against the pure level, then a wider bay
    config, _ = built("parking", "output.frame=world")
    params = config.scene.params
    pure = parking_layout(params).meshes()
    got = exported_pieces(list(pure))
    found["max_vertex_difference_m"]["parking"] = max(float(np.abs(got[n] - pure[n][0][pure[n][1]].reshape(-1, 3)).max()) for n in pure)
    before = scan(config, "parking_before")
    set_input(bpy.data.objects["pillar"], "Bay Width", 2.8)
    after = scan(config, "parking_after")
    found["parking_bay_width"] = compare(before, after, "pillar")
    import dataclasses

    wider = parking_layout(dataclasses.replace(params, bay_width=2.8)).meshes()["pillar"]
    pillars = after[after["semantic"] == class_id("pillar")]
    world = np.column_stack([pillars["x"], pillars["y"], pillars["z"]]).astype(float)  # output.frame: world
    found["parking_bay_width"]["pillar_points_off_the_new_pillars_m"] = float(box_distance(world, wider[0]).max(initial=0.0))
    # parking: walls with three doorways each against the pure level's
    from bpy_pipeline.builders.parking.layout import level_layout

    config, _ = built("parking", "scene.wall_openings=3", "scene.opening_width=2.4")
    pure = level_layout(config.scene.params).meshes()["wall"]
    found["max_vertex_difference_m"]["parking doorways"] = float(np.abs(exported_pieces(["wall"])["wall"] - pure[0][pure[1]].reshape(-1, 3)).max())

    # hall: pieces against the pure boxes
    config, _ = built("industrial_hall")
    layout = hall_layout(config.scene.params)
    pure = {"floor": boxes_mesh(layout.floor), "ceiling": boxes_mesh(layout.ceiling),
            "walls": boxes_mesh(layout.walls)} | {f.name: f.mesh() for f in layout.furniture}
    got = exported_pieces(list(pure))
    found["max_vertex_difference_m"]["industrial_hall"] = max(float(np.abs(got[n] - pure[n][0][pure[n][1]].reshape(-1, 3)).max()) for n in pure)

    # street: half the trees' crowns and bushes
    config, _ = built("street")
    before = scan(config, "street_before")
    set_input(bpy.data.objects["street_plants"], "Density", 0.5)
    after = scan(config, "street_after")
    found["street_density"] = compare(before, after, "vegetation")
    # street: trees planted over the yards (the "Street Planting" modifier's Density, 0 by default)
    set_input(bpy.data.objects["street_yard_trees"], "Density", 5.0)
    found["street_planting"] = compare(after, scan(config, "street_planted"), "trunk")
    # street: every lane 1 m narrower (the road's "Street Road" modifier; a wider road hides under the kerbs), scanned again
    config, _ = built("street")
    from bpy_pipeline.builders.street.layout import road_meshes

    ordered = lambda v: v[np.lexsort(np.round(v, 4).T[::-1])]  # noqa: E731 - the vertices in one order (ties kept by rounding)
    pure = dict(zip(("street_road", "street_kerbs", "street_sidewalks"), road_meshes(config.scene.params)[:3]))
    found["max_vertex_difference_m"]["street road"] = max(float(np.abs(ordered(evaluated(bpy.data.objects[n])) - ordered(m[0])).max()) for n, m in pure.items())
    from bpy_pipeline.builders.street.layout import street_layout

    buildings = [p for p in street_layout(config.scene.params, np.random.default_rng(config.scene.params.layout_seed)).parts if p.front is not None]
    found["max_vertex_difference_m"]["street facades"] = max(
        float(np.abs(ordered(evaluated(bpy.data.objects[p.name])) - ordered(p.mesh[0])).max()) for p in buildings
    )
    set_input(bpy.data.objects["street_road"], "Lane Width", config.scene.params.lane_width - 1.0)
    found["street_lane_width"] = compare(before, scan(config, "street_wider"), "road")
    return found


def class_id(name: str) -> int:
    from bpy_pipeline.labels import load_class_table

    return load_class_table().id_of(name, "nodes_check")


def compare(before, after, edited: str) -> dict:
    """Points of class ``edited`` before and after, and how many beams that hit other classes in both moved."""
    k = class_id(edited)
    a, b = beams(before), beams(after)
    common = [(a[key], b[key]) for key in a.keys() & b.keys()]
    i, j = (np.array(x, int) for x in zip(*common)) if common else (np.zeros(0, int), np.zeros(0, int))
    other = (before["semantic"][i] != k) & (after["semantic"][j] != k)
    xyz = lambda p, idx: np.column_stack([p["x"][idx], p["y"][idx], p["z"][idx]]).astype(float)  # noqa: E731
    moved = np.linalg.norm(xyz(before, i[other]) - xyz(after, j[other]), axis=1)
    edited_before, edited_after = before[before["semantic"] == k], after[after["semantic"] == k]
    return {"edited_points": [len(edited_before), len(edited_after)], "edited_mean_z": [float(edited_before["z"].mean()) if len(edited_before) else None,
                                                                                        float(edited_after["z"].mean()) if len(edited_after) else None],
            "edited_changed": bool(len(edited_before) != len(edited_after) or not np.array_equal(edited_before["x"], edited_after["x"])),
            "other_beams": int(other.sum()), "other_moved_over_1mm": int((moved > 1e-3).sum())}


def box_distance(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Distance (m) of each point to the nearest of the axis-aligned boxes whose corners are ``vertices`` (8 a box, in order)."""
    boxes = vertices.reshape(-1, 8, 3)
    low, high = boxes.min(axis=1), boxes.max(axis=1)
    gap = np.maximum(np.maximum(low[None] - points[:, None], points[:, None] - high[None]), 0.0)
    return np.linalg.norm(gap, axis=2).min(axis=1)


if __name__ == "__main__":
    try:
        result = main()
    except Exception:  # reported to the lane test, which fails with it
        result = {"error": traceback.format_exc()}
    OUT.write_text(json.dumps(result, indent=1, default=str))
