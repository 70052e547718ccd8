"""Support assets from files (``scene.assets``): a file's mast stands where each procedural one stood, the scan's
points of its classes lie on it, names in the file give classes, and bad files are one line naming the key."""

import json
import math
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.builders.railway.assets import foot_pose, part_class

ROOT = Path(__file__).resolve().parents[1]

# the mast asset: a 0.3 m square column 8 m tall on its foot, an arm reaching 1 m towards the track (+Y), an insulator at its tip
MAST = {
    "column": ((-0.15, -0.15, 0.0), (0.15, 0.15, 8.0), None),
    "arm": ((-0.05, 0.15, 7.0), (0.05, 1.0, 7.1), None),
    "insulator_tip": ((-0.04, 0.9, 6.7), (0.04, 0.98, 7.0), None),
}
# the cantilever asset: a tube object, a part named by its material, and one named by its object
CANTILEVER = {
    "tube": ((-0.03, 0.15, 6.9), (0.03, 3.4, 6.96), None),
    "arm": ((-0.02, 2.3, 5.8), (0.02, 3.4, 5.84), "Registration_Arm steel"),
    "Insulator.001": ((-0.04, 0.2, 6.8), (0.04, 0.5, 7.0), None),
}
SMALL_SCAN = ["sensor.preset=railway_tls", "sensor.sampling_factor=0.3", "effects.ideal=true", "scene.detail.stones=false",
              "scene.track.start=[-40,0,0]", "scene.track.mid=[0,0,0]", "scene.track.end=[40,0,0]", "scene.catenary.enabled=false",
              "scene.catenary.feeders=false"]


def box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (8, 3), triangles (12, 3))`` of the axis-aligned box from ``lo`` to ``hi`` (outward faces)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], float)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return v, np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.int32)


def write_glb(path: Path, parts: dict) -> Path:
    """Write ``parts`` ({object name: (lo, hi, material name or None)}, Blender's frame: Z up) as a binary glTF 2.0 file:
    one node and mesh per part, named; glTF is Y up, so (x, y, z) is written (x, z, -y).

    Written here, not by Blender's glTF exporter: a process that has run that exporter hangs at exit once it has
    scanned (bpy 4.5), which would hang pytest after the scan test."""
    blob, views, accessors, meshes, nodes, materials = bytearray(), [], [], [], [], []
    for name, (lo, hi, material) in parts.items():
        v, t = box(lo, hi)
        for data, target in ((np.column_stack([v[:, 0], v[:, 2], -v[:, 1]]).astype(np.float32), 34962), (t.astype(np.uint32).ravel(), 34963)):
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": data.nbytes, "target": target})
            blob += data.tobytes()
        position = views[-2]
        accessors.append({"bufferView": len(views) - 2, "componentType": 5126, "count": position["byteLength"] // 12, "type": "VEC3",
                          "min": np.min(v[:, [0, 2, 1]] * (1, 1, -1), axis=0).tolist(), "max": np.max(v[:, [0, 2, 1]] * (1, 1, -1), axis=0).tolist()})
        accessors.append({"bufferView": len(views) - 1, "componentType": 5125, "count": t.size, "type": "SCALAR"})
        primitive = {"attributes": {"POSITION": len(accessors) - 2}, "indices": len(accessors) - 1}
        if material:
            materials.append({"name": material})
            primitive["material"] = len(materials) - 1
        meshes.append({"name": name, "primitives": [primitive]})
        nodes.append({"name": name, "mesh": len(meshes) - 1})
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(range(len(nodes)))}], "nodes": nodes, "meshes": meshes,
           "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(blob)}], **({"materials": materials} if materials else {})}
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    path.write_bytes(struct.pack("<III", 0x46546C67, 2, 28 + len(text) + len(blob)) + struct.pack("<II", len(text), 0x4E4F534A) + text
                     + struct.pack("<II", len(blob), 0x004E4942) + bytes(blob))
    return path


def make_asset(path: Path, parts: dict) -> Path:
    """Write ``parts`` ({object name: (lo, hi, material name or None)}) with Blender's OBJ or PLY exporter."""
    import bpy

    from bpy_pipeline.blender.mesh_objects import mesh_data

    bpy.ops.wm.read_factory_settings(use_empty=True)
    for name, (lo, hi, material) in parts.items():
        mesh = mesh_data(name, *box(lo, hi))
        if material:
            mesh.materials.append(bpy.data.materials.new(material))
        bpy.context.scene.collection.objects.link(bpy.data.objects.new(name, mesh))
    if path.suffix.lower() == ".obj":
        bpy.ops.wm.obj_export(filepath=str(path))
    else:
        bpy.ops.wm.ply_export(filepath=str(path), ascii_format=False)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return path


def build(*overrides):
    """Build the railway of the config in Blender; ``(params, layout, {object name: object})`` of its scene collection."""
    import bpy

    from bpy_pipeline.builders.railway import scene as railway
    from bpy_pipeline.blender.mesh_objects import COLLECTION

    bpy.ops.wm.read_factory_settings(use_empty=True)
    params = load_config(None, ["scene.detail.mode=fixed", "scene.detail.stones=false", *overrides]).scene.params
    layout = railway.build(params, np.random.default_rng(3))
    return params, layout, {o.name: o for o in bpy.data.collections[COLLECTION].objects}


def world_vertices(obj) -> np.ndarray:
    v = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", v)
    m = np.array(obj.matrix_world)
    return v.reshape(-1, 3).astype(float) @ m[:3, :3].T + m[:3, 3]


def rows(v: np.ndarray) -> np.ndarray:
    """The distinct rows of ``v (n, 3)`` rounded to 0.1 mm, sorted."""
    return np.unique(np.round(v, 4), axis=0)


def procedural_masts() -> dict:
    """``{support.<k>.mast.<side>: (n, 3) world vertices}`` of the masts the "Railway Supports" group instanced."""
    import bpy

    from bpy_pipeline.builders.railway.support_nodes import realized_parts

    out = {}
    for obj in (o for o in bpy.data.objects if o.name.startswith("supports.mast.")):
        out |= realized_parts(obj)
    return out


def foot_of(obj) -> np.ndarray:
    """The middle of the bounding box of a mast's lowest vertices (world, m); ``obj`` an object or its (n, 3) world vertices."""
    v = obj if isinstance(obj, np.ndarray) else world_vertices(obj)
    bottom = v[v[:, 2] < v[:, 2].min() + 0.01]
    return (bottom.min(axis=0) + bottom.max(axis=0)) / 2


def track_distance(layout, xy: np.ndarray) -> float:
    """Horizontal distance (m) of a point from the nearest track centre (the alignment is the straight x axis here)."""
    return float(np.min(np.abs(xy[1] - layout.section.offsets)))


# ----------------------------------------------------------------------------- pure
def test_names_give_classes_and_rules_come_first():
    assert part_class(["Insulator_02", ""], "mast", {}) == "insulator"
    assert part_class(["arm", "registration-arm steel"], "cantilever", {}) == "registration arm"
    assert part_class(["section_insulator.3", ""], "cantilever", {}) == "section insulator"
    assert part_class(["IfcColumn", "galvanised"], "mast", {}) == "mast"
    assert part_class(["bracket", ""], "cantilever", {}) == "cantilever"
    assert part_class(["Isolator 7", ""], "mast", {"isolator*": "insulator"}) == "insulator"
    assert part_class(["plate", "Weight_cast"], "mast", {"*weight*": "tensioning_weight"}) == "tensioning weight"


@pytest.mark.parametrize("outward, toward", [(-1.0, (0.0, 1.0)), (1.0, (0.0, -1.0))])
def test_a_foot_pose_faces_its_track(outward, toward):
    frame = np.eye(4)
    frame[:3, 3] = (10.0, 0.0, 0.0)
    pose = foot_pose(frame, -3.2 * outward, 0.1, outward)
    assert pose[:3, 3] == pytest.approx((10.0, -3.2 * outward, 0.1))
    assert pose[:2, 1] == pytest.approx(toward)  # the asset's +Y, in the world
    assert pose[:3, 2] == pytest.approx((0.0, 0.0, 1.0))


def test_bad_assets_are_one_line_naming_the_key(tmp_path):
    (tmp_path / "mast.txt").write_text("a mast\n")
    (tmp_path / "broken.glb").write_bytes(b"not a gltf file at all")
    (tmp_path / "broken.ifc").write_text("hello\n")
    (tmp_path / "cut.glb").write_bytes(struct.pack("<III", 0x46546C67, 2, 4096) + b"{}")
    cases = {
        "scene.assets.mast": f"scene.assets.mast={tmp_path / 'missing.glb'}",
        "scene.assets.cantilever": f"scene.assets.cantilever={tmp_path / 'mast.txt'}",
        "scene.assets.gantry": f"scene.assets.gantry={tmp_path / 'broken.glb'}",
        "scene.assets.unit_scale": "scene.assets.unit_scale=0",
        "scene.assets.classes": "scene.assets.classes={'ins*': isolator}",
    }
    for key, override in cases.items():
        with pytest.raises(InputError) as err:
            load_config(None, [override])
        assert str(err.value).startswith(key) and "\n" not in str(err.value)
    with pytest.raises(InputError, match=r"^scene\.assets\.mast: .*not an IFC"):
        load_config(None, [f"scene.assets.mast={tmp_path / 'broken.ifc'}"])
    with pytest.raises(InputError, match=r"^scene\.assets\.mast: .*damaged binary glTF file \(its header says 4096 bytes, the file has 14\)"):
        load_config(None, [f"scene.assets.mast={tmp_path / 'cut.glb'}"])


@pytest.mark.bpy
def test_the_command_exits_2_and_writes_nothing(tmp_path):
    (tmp_path / "broken.glb").write_bytes(b"glTF\x01\x00\x00\x00")
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--set", f"scene.assets.mast={tmp_path / 'broken.glb'}"],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 2 and len(lines) == 1 and "scene.assets.mast" in lines[0] and "glTF 2.0" in lines[0]
    assert not out.exists() or not any(out.iterdir())


# ----------------------------------------------------------------------------- Blender
@pytest.mark.bpy
def test_a_gltf_mast_stands_where_every_procedural_mast_stood(tmp_path):
    glb = write_glb(tmp_path / "mast.glb", MAST)
    _, layout, procedural = build("scene.track.tracks=2", "scene.supports.layout=both_sides")
    assert not any(o.get("lidar_class") == "mast" and not name.startswith("supports.mast.") for name, o in procedural.items())
    feet = {name: foot_of(vertices) for name, vertices in procedural_masts().items()}
    assert len(feet) == 2 * len(layout.supports) >= 6
    _, layout, placed = build("scene.track.tracks=2", "scene.supports.layout=both_sides", f"scene.assets.mast={glb}")
    masts = {n: o for n, o in placed.items() if o.get("lidar_class") == "mast"}
    assert set(masts) == set(feet)  # every mast replaced, under its name; none left procedural
    local = rows(np.concatenate([box(*MAST[k][:2])[0] for k in ("column", "arm")]))  # the asset's mast-class vertices, no procedural mast's
    for name, obj in masts.items():
        pose = np.array(obj.matrix_world)
        assert pose[:3, 3] == pytest.approx(feet[name], abs=1e-4)  # the asset's origin on the procedural mast's foot
        back = (world_vertices(obj) - pose[:3, 3]) @ pose[:3, :3]  # the scene's vertices in the foot frame
        assert rows(back) == pytest.approx(local, abs=1e-4)
        tip = pose[:3, :3] @ np.array([0.0, 1.0, 7.0]) + pose[:3, 3]  # the arm's end: 1 m towards the track
        assert track_distance(layout, tip) == pytest.approx(track_distance(layout, pose[:3, 3]) - 1.0, abs=1e-4)
        assert placed[f"{name}.insulator"].get("lidar_class") == "insulator"
    assert len({placed[f"{name}.insulator"].data.name for name in masts}) == 1  # one mesh per slot and class, shared


@pytest.mark.bpy
def test_a_cantilever_asset_replaces_the_mast_face_assembly_and_names_give_classes(tmp_path):
    glb = write_glb(tmp_path / "cantilever.glb", CANTILEVER)
    _, layout, before = build("scene.catenary.steady_arms=true")
    _, layout, placed = build("scene.catenary.steady_arms=true", f"scene.assets.cantilever={glb}")
    for k in range(len(layout.supports)):
        stem = f"support.{k:02d}.cantilever.t0"
        assert f"support.{k:02d}.steady_arm.t0" in before and f"support.{k:02d}.steady_arm.t0" not in placed
        assert f"support.{k:02d}.registration_arm.t0" not in placed and f"support.{k:02d}.insulators.t0" not in placed
        classes = {n: placed[n].get("lidar_class") for n in (stem, f"{stem}.registration_arm", f"{stem}.insulator")}
        assert classes == {stem: "cantilever", f"{stem}.registration_arm": "registration arm", f"{stem}.insulator": "insulator"}
        masts = procedural_masts()
        assert f"support.{k:02d}.mast.right" in masts  # the mast stays procedural (instanced)
        pose = np.array(placed[stem].matrix_world)
        assert pose[:3, 3] == pytest.approx(foot_of(masts[f"support.{k:02d}.mast.right"]), abs=1e-4)  # at the foot of the mast it hangs on
        assert pose[:3, :3] == pytest.approx(np.eye(3), abs=1e-9)  # a right mast on a straight line: +Y towards the track


@pytest.mark.bpy
@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_obj_and_ply_assets_read_as_the_glb_does(tmp_path, suffix):
    from bpy_pipeline.builders.railway.scene_assets import asset_parts

    glb = asset_parts(str(write_glb(tmp_path / "mast.glb", MAST)), "mast", 1.0, {}, "scene.assets.mast")
    other = asset_parts(str(make_asset(tmp_path / f"mast{suffix}", MAST)), "mast", 1.0, {}, "scene.assets.mast")
    expected = {"mast", "insulator"} if suffix == ".obj" else {"mast"}  # PLY keeps no object names: one mesh of the slot's class
    assert set(other) == expected
    every = lambda parts: rows(np.concatenate([v for v, _ in parts.values()]))  # noqa: E731
    assert every(other) == pytest.approx(every(glb), abs=1e-4)


@pytest.mark.bpy
def test_the_scan_of_a_gltf_mast_lies_on_the_asset(tmp_path):
    import bpy

    from bpy_pipeline.io import read_ply
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.plan import run

    glb = write_glb(tmp_path / "mast.glb", MAST)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["output.formats=[ply]", "output.preview=false", "output.frame=world", *SMALL_SCAN, f"scene.assets.mast={glb}"])
    manifest = run(config, tmp_path / "out", log=lambda *_: None)
    points = read_ply(tmp_path / "out" / "ply" / "000000.ply")
    table = load_class_table()
    objects = manifest["frames"][0]["objects"]
    boxes = {"mast": [MAST["column"], MAST["arm"]], "insulator": [MAST["insulator_tip"]]}
    checked = {"mast": 0, "insulator": 0}
    for class_name in checked:
        mine = points[points["semantic"] == table.id_of(class_name)]
        owners = {o["instance"]: o["name"] for o in objects if o["class"] == class_name and ".mast." in o["name"]}  # the asset's objects
        for instance, name in owners.items():
            hits = mine[mine["instance"] == instance]
            if not len(hits):
                continue
            pose = np.array(bpy.data.objects[name].matrix_world)
            xyz = np.column_stack([hits["x"], hits["y"], hits["z"]]).astype(float)
            local = (xyz - pose[:3, 3]) @ pose[:3, :3]
            gap = np.min([surface_distance(local, lo, hi) for lo, hi, _ in boxes[class_name]], axis=0)
            assert gap.max() < 2e-3, f"{name}: a {class_name} point {gap.max():.4f} m off the asset"
            checked[class_name] += len(hits)
        if class_name == "mast":  # every mast point is the asset's (the cantilevers keep their procedural insulators)
            assert len(mine) == sum(np.sum(mine["instance"] == i) for i in owners)
    assert checked["mast"] > 200 and checked["insulator"] > 0, checked


def surface_distance(p: np.ndarray, lo, hi) -> np.ndarray:
    """``(n,)`` distance (m) of points ``(n, 3)`` from the surface of the box ``lo``..``hi``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    outside = np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)
    inside = np.min(np.minimum(p - lo, hi - p), axis=1)
    return np.where(outside > 0, outside, np.maximum(inside, 0.0))


# ----------------------------------------------------------------------------- IFC
def make_ifc(path: Path) -> Path:
    """An IFC4 file of a mast column (IfcColumn "Mast") and an insulator (a proxy named "Insulator A"), metres, Z up."""
    pytest.importorskip("ifcopenshell", reason="ifcopenshell is not installed (pip install 'bpy-pipeline[ifc]')")
    import ifcopenshell
    import ifcopenshell.api.aggregate
    import ifcopenshell.api.context
    import ifcopenshell.api.geometry
    import ifcopenshell.api.root
    import ifcopenshell.api.spatial
    import ifcopenshell.api.unit

    api = ifcopenshell.api
    model = ifcopenshell.file(schema="IFC4")
    project = api.root.create_entity(model, ifc_class="IfcProject", name="railway")
    api.unit.assign_unit(model)
    context = api.context.add_context(model, context_type="Model")
    body = api.context.add_context(model, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW", parent=context)
    site = api.root.create_entity(model, ifc_class="IfcSite", name="site")
    api.aggregate.assign_object(model, relating_object=project, products=[site])
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    for ifc_class, name, (lo, hi, _) in (("IfcColumn", "Mast", MAST["column"]), ("IfcBuildingElementProxy", "Insulator A", MAST["insulator_tip"])):
        element = api.root.create_entity(model, ifc_class=ifc_class, name=name)
        api.spatial.assign_container(model, relating_structure=site, products=[element])
        representation = api.geometry.add_mesh_representation(model, context=body, vertices=[box(lo, hi)[0].tolist()], faces=[quads])
        api.geometry.assign_representation(model, product=element, representation=representation)
        api.geometry.edit_object_placement(model, product=element, matrix=np.eye(4))
    model.write(str(path))
    return path


@pytest.mark.bpy
def test_an_ifc_mast_reads_by_product_name(tmp_path):
    from bpy_pipeline.builders.railway.scene_assets import asset_parts

    ifc = make_ifc(tmp_path / "mast.ifc")
    load_config(None, [f"scene.assets.mast={ifc}"])  # checks
    parts = asset_parts(str(ifc), "mast", 1.0, {}, "scene.assets.mast")
    assert set(parts) == {"mast", "insulator"}
    for class_name, key in (("mast", "column"), ("insulator", "insulator_tip")):
        v = parts[class_name][0]
        assert v.min(axis=0) == pytest.approx(MAST[key][0], abs=1e-6) and v.max(axis=0) == pytest.approx(MAST[key][1], abs=1e-6)
    _, layout, placed = build(f"scene.assets.mast={ifc}")
    right = [o for n, o in placed.items() if o.get("lidar_class") == "insulator" and n.endswith("mast.right.insulator")]
    assert len(right) == len(layout.supports) and math.isclose(world_vertices(right[0])[:, 2].max(), layout.supports[0].masts[0].base + 7.0, abs_tol=1e-4)
