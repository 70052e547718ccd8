"""Every builder's procedural structure as Geometry Nodes groups against plain meshes: build and export time, and counts.

Per builder, the same layout is built two ways, in turn (so a shared machine's load weighs on both
alike): as plain objects written by Python from the pure functions (the reference: how the
builders worked before their groups), and through the groups the builders now use:

- railway: every wire and dropper set of a ``--length`` m line (1 km by default) as bevelled
  curves, against "Catenary Wire" / "Catenary Droppers" modifiers;
- parking: the default level's floor, ceiling, walls, pillars and ramp as meshes, against
  "Parking Level" modifiers instancing the unit box and wedge;
- industrial_hall: the default hall's slabs, walls, desks and racks as meshes, against
  "Industrial Hall" modifiers;
- street: the default street's static parts, the scattered kinds, the carriageway, kerbs,
  sidewalks and buildings as meshes, against "Street Scatter", "Street Road" and "Street Facade"
  modifiers (as benchmarks/bench_street_nodes.py for the scattered kinds).

Reported: median seconds to create the objects and evaluate the depsgraph, and to export them
(``export_scene``), their ratios to the reference, the exported triangle counts (must agree but
for the wires, whose section is swept by Curve to Mesh instead of a bevel); and, per builder,
the node groups and Geometry Nodes modifiers of its first frame built by the pipeline.

With ``--before DIR`` (the code before the groups, e.g. ``git archive b53ee32 | tar -x -C DIR``), whole
frames too: each builder's job (``python run.py --frames 2``, ideal effects, PLY only) run in turn
with the code in DIR and with this one, twice each; the frames' build and export seconds from
their records (the first frame builds the static scene), as medians and ratios.

With ``--builder NAME`` (repeatable) only those builders, reported as ``builder_nodes_<names>`` (the
whole table stays as it was).

Run: python benchmarks/bench_builder_nodes.py [--small] [--before DIR [--runs N]] [--builder street]
"""

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import arguments, report


def railway_ways(length: float):
    import numpy as np

    from bpy_pipeline.builders.railway.params import RailwayScene
    from bpy_pipeline.builders.railway.catenary import parabolic_sag
    from bpy_pipeline.geometry.lod import equal_perimeter_radius
    from bpy_pipeline.builders.railway.layout import MIN_WIRE_SIDES, level_of_detail, plan
    from bpy_pipeline.builders.railway import catenary_nodes
    from bpy_pipeline.blender.mesh_objects import wire_object
    from bpy_pipeline.builders.railway.scene import _bevel_sides, _dropper_wires
    import dataclasses

    params = RailwayScene()
    params = dataclasses.replace(params, track=dataclasses.replace(params.track, start=(-length / 2, 0.0, 0.0), end=(length / 2, 0.0, 0.0)))
    layout = plan(params, np.random.default_rng(0))
    detail = level_of_detail(layout, params, None)
    wires = [(w, s) for w, s in zip(layout.wires, detail.wires) if s is not None]
    by_key = {(w.run, w.span, w.kind): w for w in layout.wires}

    def build(collection, nodes: bool):
        for wire, (samples, sides) in wires:
            points = parabolic_sag(wire.start, wire.end, wire.sag, samples)
            n = _bevel_sides(sides)
            radius = equal_perimeter_radius(wire.diameter / 2, n)
            name = f"span.{wire.run}.{wire.span:02d}.{wire.kind}"
            catenary_nodes.wire_object(name, points, wire.sag, radius, n, collection) if nodes else wire_object(name, [points], radius, collection, sides)
        for d in layout.droppers:
            if len(d.t):
                name = f"span.{d.run}.{d.span:02d}.droppers"
                radius = equal_perimeter_radius(d.diameter / 2, MIN_WIRE_SIDES)
                if nodes:
                    catenary_nodes.droppers_object(name, d, *_dropper_wires(d, by_key), radius, MIN_WIRE_SIDES, collection)
                else:
                    wire_object(name, [np.stack([a, b]) for a, b in zip(d.lower, d.upper)], radius, collection, MIN_WIRE_SIDES)

    return build, {"wires": len(wires), "dropper sets": len(layout.droppers)}


def parking_ways():
    from bpy_pipeline.builders.parking.params import ParkingScene
    from bpy_pipeline.geometry.indoor import parking_layout
    from bpy_pipeline.blender import box_nodes
    from bpy_pipeline.builders.parking import level_nodes as parking_nodes
    from bpy_pipeline.blender.mesh_objects import mesh_object

    params = ParkingScene()
    meshes = parking_layout(params).meshes()

    def build(collection, nodes: bool):
        prototypes = box_nodes.prototypes(collection) if nodes else None
        for name, mesh in meshes.items():
            parking_nodes.level_object(name, name, params, collection, prototypes) if nodes else mesh_object(name, mesh, collection)

    return build, {"pieces": len(meshes)}


def hall_ways():
    from bpy_pipeline.builders.industrial_hall.params import IndustrialHallScene
    from bpy_pipeline.geometry.indoor import boxes_mesh, hall_layout
    from bpy_pipeline.blender import box_nodes
    from bpy_pipeline.builders.industrial_hall import hall_nodes
    from bpy_pipeline.blender.mesh_objects import mesh_object

    params = IndustrialHallScene()
    layout = hall_layout(params)

    def build(collection, nodes: bool):
        if nodes:
            prototypes = box_nodes.prototypes(collection)
            for name, part in (("floor", "floor"), ("ceiling", "ceiling"), ("walls", "walls")):
                hall_nodes.hall_object(name, part, params, collection, prototypes)
            for item in layout.furniture:
                hall_nodes.furniture_object(item, params, collection, prototypes)
        else:
            for name, boxes in (("floor", layout.floor), ("ceiling", layout.ceiling), ("walls", layout.walls)):
                mesh_object(name, boxes_mesh(boxes), collection)
            for item in layout.furniture:
                mesh_object(item.name, item.mesh(), collection)

    return build, {"furniture": len(layout.furniture)}


def street_ways():
    import numpy as np

    from bpy_pipeline.builders.street.params import StreetScene
    from bpy_pipeline.builders.street import layout as street
    from bpy_pipeline.blender.mesh_objects import mesh_object
    from bpy_pipeline.builders.street.facade_nodes import facade_object
    from bpy_pipeline.builders.street.road_nodes import road_object
    from bpy_pipeline.builders.street.scatter_nodes import prototypes_collection, scatter_object
    from bpy_pipeline.builders.street.scene import SWEPT

    params = StreetScene()
    layout = street.street_layout(params, np.random.default_rng(params.layout_seed))

    def build(collection, nodes: bool):
        prototypes = prototypes_collection(collection)
        for part in layout.parts:
            if nodes and part.name in SWEPT:
                road_object(part.name, SWEPT[part.name], params, collection, part.instance)
            elif nodes and part.front is not None:
                facade_object(part.name, part.front, collection, part.instance)
            elif nodes and part.scatter is not None:
                scatter_object(part.name, part.scatter, collection, prototypes)
            else:
                mesh_object(part.name, part.mesh, collection)

    return build, {"scattered kinds": sum(p.scatter is not None for p in layout.parts), "swept parts": sum(p.name in SWEPT for p in layout.parts),
                   "buildings": sum(p.front is not None for p in layout.parts)}


def counts(builder: str) -> dict:
    """Node groups and Geometry Nodes modifiers of ``builder``'s first frame built by the pipeline."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages.scene import build_frame_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    build_frame_scene(load_config({"seed": 0, "frames": 1, "scene": {"builder": builder}, "output": {"formats": ["ply"], "preview": False}}), 0)
    modifiers = [m for o in bpy.data.objects for m in o.modifiers if m.type == "NODES"]
    used = sorted({m.node_group.name for m in modifiers})
    groups = sorted(g.name for g in bpy.data.node_groups if g.bl_idname == "GeometryNodeTree")
    return {"objects": len(bpy.data.objects), "GN modifiers": len(modifiers), "node groups": len(groups), "groups on modifiers": ", ".join(used)}


FRAME_JOBS = {"railway": [], "parking": ["--set", "scene.builder=parking"], "industrial_hall": ["--set", "scene.builder=industrial_hall"],
              "street": ["--set", "scene.builder=street"]}


def frame_times(root: Path, builder: str) -> list[dict]:
    """Per frame ``{"build": s, "export": s}`` of ``builder``'s two-frame job run with the code in ``root``."""
    with tempfile.TemporaryDirectory() as out:
        args = [sys.executable, str(root / "run.py"), "--out", out, "--frames", "2", *FRAME_JOBS[builder],
                "--set", "effects.ideal=true", "--set", "output.formats=[ply]", "--set", "output.preview=false"]
        done = subprocess.run(args, cwd=root, capture_output=True, text=True, timeout=900)
        if done.returncode != 0:
            raise SystemExit(f"{builder} with {root}: {done.stderr.strip()[-500:]}")
        records = [json.loads(p.read_text()) for p in sorted(Path(out, "records").glob("*.json"))]
    return [{k: r["timings_s"][k] for k in ("build", "export")} for r in records]


def whole_frames(before: Path, repeats: int, builders=tuple(FRAME_JOBS)) -> list[dict]:
    here = Path(__file__).resolve().parents[1]
    rows = []
    for builder in builders:
        runs = {"before": [], "groups": []}
        for _ in range(repeats):
            for way, root in (("before", before), ("groups", here)):
                runs[way].append(frame_times(root, builder))
        row = {"builder": builder}
        for k, label in ((0, "first frame"), (1, "next frame")):
            for stage in ("build", "export"):
                b = statistics.median(r[k][stage] for r in runs["before"])
                g = statistics.median(r[k][stage] for r in runs["groups"])
                row[f"{label} {stage} s before / groups"] = f"{b:.3f} / {g:.3f}"
                row[f"{label} {stage} ratio"] = round(g / b, 3) if b > 0 else None
        rows.append(row)
    return rows


def main() -> None:
    import argparse

    before = argparse.ArgumentParser(add_help=False)
    before.add_argument("--before", type=Path)
    before.add_argument("--builder", action="append", choices=list(FRAME_JOBS))
    before.add_argument("--runs", type=int, default=2, help="runs of each way's whole-frame job (with --before)")
    known, rest = before.parse_known_args()
    sys.argv = [sys.argv[0], *rest]
    args = arguments(__doc__.splitlines()[0])
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.blender.mesh_objects import scene_collection

    table = load_class_table()
    repeats = 2 if args.small else 5
    length = 200.0 if args.small else 1000.0
    rows = []
    chosen = known.builder or list(FRAME_JOBS)
    suffix = "" if known.builder is None else "_" + "_".join(chosen)
    every = (("railway", lambda: railway_ways(length)), ("parking", parking_ways), ("industrial_hall", hall_ways), ("street", street_ways))
    for builder, ways in (w for w in every if w[0] in chosen):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        build, notes = ways()
        times = {False: ([], []), True: ([], [])}
        triangles = {}
        for _ in range(repeats):
            for nodes, (built, exported) in times.items():
                start = time.perf_counter()
                build(scene_collection(), nodes)
                bpy.context.evaluated_depsgraph_get()
                built.append(time.perf_counter() - start)
                start = time.perf_counter()
                triangles[nodes] = len(export_scene(table).triangles)
                exported.append(time.perf_counter() - start)
        median = {nodes: (statistics.median(b[1:]), statistics.median(e[1:])) for nodes, (b, e) in times.items()}  # the first of each warms up
        row = {"builder": builder, "meshes build s": round(median[False][0], 4), "groups build s": round(median[True][0], 4),
               "build ratio": round(median[True][0] / median[False][0], 3), "meshes export s": round(median[False][1], 4),
               "groups export s": round(median[True][1], 4), "export ratio": round(median[True][1] / median[False][1], 3),
               "triangles meshes": triangles[False], "triangles groups": triangles[True]}
        rows.append(row | counts(builder) | {"layout": ", ".join(f"{k} {v}" for k, v in notes.items())})
    report("builder_nodes" + suffix, rows, args.out, notes={"repeats": repeats, "railway length m": length})
    if known.before is not None:
        report("builder_nodes_frames" + suffix, whole_frames(known.before, known.runs, chosen), args.out,
               notes={"before": f"the code in {known.before.name} (before the groups)", "runs": known.runs})


if __name__ == "__main__":
    main()
