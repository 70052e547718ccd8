"""The street's scattered items as Geometry Nodes instances against plain meshes: build and export time.

Scene: the default street of ``examples/street/ego_hdl64e.yaml`` (layout_seed 0, 100 m arms), its
static objects only. The same layout is built two ways, in turn, so a shared machine's load
weighs on both alike: every part as a plain mesh object (the reference: how the street was built
before its items were instanced), and the scattered kinds (trunks, crowns and bushes, lamps and
bollards, bins, bicycle stands, cones, barriers) as point-cloud objects with a live "Street
Scatter" modifier (``builders/street/scatter_nodes.py``). Reported: median seconds to create the objects
and evaluate the depsgraph, and to export the scene (``export_scene``), and their ratios to the
reference; the exported triangle counts must agree.

Run: python benchmarks/bench_street_nodes.py [--small]
"""

import statistics
import time

from common import arguments, report


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    import bpy
    import numpy as np

    from bpy_pipeline.builders.street.params import StreetScene
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.builders.street import layout as street
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.blender.mesh_objects import mesh_object, scene_collection, tag
    from bpy_pipeline.builders.street.scatter_nodes import prototypes_collection, scatter_object

    bpy.ops.wm.read_factory_settings(use_empty=True)
    params = StreetScene(ego_vehicle=True)
    layout = street.street_layout(params, np.random.default_rng(params.layout_seed))
    table = load_class_table()
    repeats = 2 if args.small else 6
    times = {"plain meshes": ([], []), "Street Scatter instances": ([], [])}
    triangles = {}
    for _ in range(repeats):
        for way, (build, export) in times.items():
            start = time.perf_counter()
            collection = scene_collection()
            prototypes = prototypes_collection(collection)
            for part in layout.parts:
                nodes = part.scatter is not None and way != "plain meshes"
                obj = scatter_object(part.name, part.scatter, collection, prototypes) if nodes else mesh_object(part.name, part.mesh, collection)
                tag(obj, part.class_name, part.material, part.reflectivity, part.instance)
            bpy.context.evaluated_depsgraph_get()
            build.append(time.perf_counter() - start)
            start = time.perf_counter()
            buffers = export_scene(table)
            export.append(time.perf_counter() - start)
            triangles[way] = len(buffers.triangles)
    if len(set(triangles.values())) != 1:
        raise SystemExit(f"the two ways export different scenes: {triangles}")
    reference = {k: statistics.median(v[1:]) for k, v in zip(("build", "export"), times["plain meshes"])}
    rows = []
    for way, (build, export) in times.items():
        b, e = statistics.median(build[1:]), statistics.median(export[1:])  # the first build of each warms up
        rows.append({"static street": way, "objects built s": round(b, 4), "export s": round(e, 4), "build vs meshes": round(b / reference["build"], 3),
                     "export vs meshes": round(e / reference["export"], 3), "triangles": triangles[way]})
    scattered = [p for p in layout.parts if p.scatter is not None]
    report("street_nodes", rows, args.out, notes={"scattered kinds": len(scattered), "items": sum(len(p.scatter.items) for p in scattered),
                                                  "prototypes": sum(len(p.scatter.prototypes) for p in scattered), "repeats": repeats})


if __name__ == "__main__":
    main()
