"""Railway build time with support assets from files (``scene.assets``) against the procedural supports, in one run.

The scene is the thesis's (one track, 300 m on a 1.1 km curve, supports every 50 +- 5 m, full catenary), built
whole in Blender (no sensor view: every support) by ``builders.railway.scene.build``; the time is the best of 5 builds,
the scenarios taken in turn.
The assets are made here from the procedural supports of support 0 (mast with brackets; the mast-face
cantilever with its registration arm and insulators), moved into the foot frame and written as GLB:
``assets_same_detail`` has the procedural triangle count, ``assets_dense`` the same shapes cut 16 times finer
(a BIM export is often that heavy). Each build imports its files again (what a run does once per built line).
``ratio`` is each build time over the procedural one measured in the same run; ``import_s`` the part of it spent
reading the files (Blender's glTF importer, then the imported data removed).
Results: benchmarks/results/railway_assets.json.
Run: python benchmarks/bench_railway_assets.py [--small]
"""

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from common import ROOT, arguments, report

sys.path.insert(0, str(ROOT))
REPEAT = 5


def params_of(small: bool, **assets):
    from bpy_pipeline.config import load_config

    half = 60 if small else 150
    overrides = [f"scene.track.start=[{-half},0,0]", "scene.track.mid=[0,10,0]", f"scene.track.end=[{half},0,0]", "scene.detail.stones=false"]
    overrides += [f"scene.assets.{slot}={path}" for slot, path in assets.items()]
    return load_config(None, overrides).scene.params


def build_seconds(params) -> tuple[float, int]:
    """Wall time (s) of one build, and the triangles of the support classes in the built scene."""
    import bpy

    from bpy_pipeline.builders.railway import scene as railway
    from bpy_pipeline.blender.mesh_objects import COLLECTION

    bpy.ops.wm.read_factory_settings(use_empty=True)
    start = time.perf_counter()
    railway.build(params, np.random.default_rng(0))
    seconds = time.perf_counter() - start
    support = {"mast", "cantilever", "registration arm", "insulator", "steady arm"}
    triangles = 0
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for obj in bpy.data.collections[COLLECTION].objects:
        if obj.type == "MESH" and obj.get("lidar_class") in support and obj.name.startswith(("support.", "supports.")):  # supports.*: the instanced masts
            evaluated = obj.evaluated_get(depsgraph)
            mesh = evaluated.to_mesh()
            mesh.calc_loop_triangles()
            triangles += len(mesh.loop_triangles)
            evaluated.to_mesh_clear()
    return seconds, triangles


def import_seconds(files: dict) -> float:
    """Best of ``REPEAT`` wall times (s) of reading every file into its parts (what a build adds before placing)."""
    from bpy_pipeline.builders.railway.scene_assets import asset_parts

    best = np.inf
    for _ in range(REPEAT):
        start = time.perf_counter()
        for slot, path in files.items():
            asset_parts(str(path), slot, 1.0, {}, f"scene.assets.{slot}")
        best = min(best, time.perf_counter() - start)
    return best


def make_assets(folder: Path, small: bool, cuts: int) -> dict:
    """GLB files of support 0's procedural mast and mast-face cantilever assembly, in their foot frame (``cuts``: subdivision cuts, 0 none)."""
    import bpy
    from mathutils import Matrix

    from bpy_pipeline.builders.railway import scene as railway
    from bpy_pipeline.blender.mesh_objects import COLLECTION

    bpy.ops.wm.read_factory_settings(use_empty=True)
    params = params_of(small)
    layout = railway.build(params, np.random.default_rng(0))
    support = layout.supports[0]
    mast = support.masts[0]
    from bpy_pipeline.builders.railway.assets import foot_pose

    to_foot = Matrix(np.linalg.inv(foot_pose(support.frame, mast.lateral, mast.base, mast.outward)).tolist())
    objects = bpy.data.collections[COLLECTION].objects
    # the masts stand as instances of the "Railway Supports" group: support 0's is made an object of its own, from the pure mesh
    from bpy_pipeline.builders.railway.scene import _mast_mesh
    from bpy_pipeline.blender.mesh_objects import mesh_object

    mast_object = mesh_object(f"support.00.mast.{mast.side}", _mast_mesh(mast, params.catenary), bpy.data.collections[COLLECTION])
    mast_object.matrix_world = Matrix(support.frame.tolist())
    chosen = {"mast": [mast_object.name], "cantilever": ["support.00.cantilever.t0", "support.00.registration_arm.t0", "support.00.insulators.t0"]}
    files = {}
    for slot, names in chosen.items():
        bpy.ops.object.select_all(action="DESELECT")
        for name in names:
            obj = objects[name]
            obj.data = obj.data.copy()
            obj.data.transform(to_foot @ obj.matrix_world)
            obj.matrix_world = Matrix.Identity(4)
            if cuts:  # alone in edit mode (a multi-object edit would cut the ones before again)
                bpy.ops.object.select_all(action="DESELECT")
                obj.select_set(True)
                bpy.context.view_layer.objects.active = obj
                bpy.ops.object.mode_set(mode="EDIT")
                bpy.ops.mesh.select_all(action="SELECT")
                bpy.ops.mesh.subdivide(number_cuts=cuts)
                bpy.ops.object.mode_set(mode="OBJECT")
        bpy.ops.object.select_all(action="DESELECT")
        for name in names:
            objects[name].select_set(True)
        files[slot] = folder / f"{slot}_{cuts}.glb"
        bpy.ops.export_scene.gltf(filepath=str(files[slot]), export_format="GLB", use_selection=True)
    return files


def main():
    args = arguments(__doc__)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        same = make_assets(Path(tmp), args.small, 0)
        dense = make_assets(Path(tmp), args.small, 3)  # 3 cuts: each triangle becomes 16
        runs = {"procedural": params_of(args.small), "assets_same_detail": params_of(args.small, **same), "assets_dense": params_of(args.small, **dense)}
        measured = {}
        for _ in range(REPEAT):  # the scenarios in turn, the best of each: load on a shared machine hits them alike
            for name, params in runs.items():
                seconds, triangles = build_seconds(params)
                measured[name] = (min(seconds, measured.get(name, (np.inf,))[0]), triangles)
        imports = {"procedural": 0.0, "assets_same_detail": import_seconds(same), "assets_dense": import_seconds(dense)}
    reference = measured["procedural"][0]
    for name, (seconds, triangles) in measured.items():
        rows.append({"scenario": name, "build_s": round(seconds, 4), "ratio": round(seconds / reference, 3), "import_s": round(imports[name], 4),
                     "support_triangles": triangles})
    report("railway_assets", rows, args.out, {"scene": "the thesis's 300 m line, every support built" if not args.small else "a 120 m line", "repeat": REPEAT})


if __name__ == "__main__":
    main()
