"""Objects for real-scan insertion: cyclists (one instance, KITTI Cyclist), glTF / OBJ / PLY meshes with glass,
car bodies drawn per object; bad object types refused in one line (exit 2)."""

import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.objects import BODIES, OBJECT_TYPES, STYLES, cyclist_object, style_size
from bpy_pipeline.io.class_maps import load_class_maps
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.mixing import ObjectBox, ParkingRule, RealScanScene, mix_frame
from bpy_pipeline.mixing.objects import GLTF_TO_SENSOR, check_type, mesh_file_parts, type_class, type_size

ROOT = Path(__file__).resolve().parents[1]
SWEEP = "nuscenes_hdl32e_sweep.bin"


# ----------------------------------------------------------------------------- a small glTF writer (test data only)
def box_in_gltf(length: float, width: float, height: float, x0: float = 0.0):
    """A box of ``length`` along the insertion frame's x (the glTF +Z, the asset's front), ``x0`` its rear, on z = 0,
    in glTF axes: ``(positions (n, 3) float32, indices (m,) uint32)``."""
    v, t = primitives.box(length, width, height)
    v = v + [x0 + length / 2, 0.0, height / 2]
    return (v @ GLTF_TO_SENSOR).astype(np.float32), t.astype(np.uint32).ravel()  # sensor -> glTF is the transpose


def write_gltf(path: Path, meshes: list, translation=(0.0, 0.0, 0.0)) -> Path:
    """``meshes``: ``[(positions, indices, material name)]``; one node (translated) holding one mesh of one
    primitive per entry; .glb (a BIN chunk) or .gltf (a data URI) by the suffix."""
    blob, views, accessors, prims, materials = b"", [], [], [], []
    for k, (pos, idx, material) in enumerate(meshes):
        for array, target, kind, comp in ((pos, 34962, "VEC3", 5126), (idx, 34963, "SCALAR", 5125)):
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": array.nbytes, "target": target})
            acc = {"bufferView": len(views) - 1, "componentType": comp, "count": len(array), "type": kind}
            if kind == "VEC3":
                acc["min"], acc["max"] = array.min(axis=0).tolist(), array.max(axis=0).tolist()
            accessors.append(acc)
            blob += array.tobytes()
            blob += b"\0" * (-len(blob) % 4)
        materials.append({"name": material})
        prims.append({"attributes": {"POSITION": 2 * k}, "indices": 2 * k + 1, "material": k})
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "translation": list(translation)}],
           "meshes": [{"primitives": prims}], "materials": materials, "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": len(blob)}]}
    if path.suffix == ".gltf":
        import base64

        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        path.write_text(json.dumps(doc))
        return path
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return path


def glass_car(path: Path) -> Path:
    """A 'car': a diffuse block 1 m deep behind a 2 m x 1.6 m glass pane standing 2 m in front of it (facing -x)."""
    block = box_in_gltf(1.0, 2.0, 1.6, x0=0.0)
    pane = box_in_gltf(0.01, 2.0, 1.6, x0=-2.0)
    return write_gltf(path, [(*block, "CarPaint"), (*pane, "Windshield_Glass")])


# ----------------------------------------------------------------------------- pure: readers, classes, sizes
def test_gltf_reader_turns_axes_applies_nodes_and_finds_glass(tmp_path):
    for suffix in (".glb", ".gltf"):
        path = glass_car(tmp_path / f"car_model{suffix}")
        parts = mesh_file_parts(str(path), (3.0, 2.0, 1.6))
        assert [p.material for p in parts] == ["diffuse", "glass"]
        pane, block = parts[1].vertices, parts[0].vertices
        assert pane[:, 0].max() < block[:, 0].min() - 1.9  # the glass stands in front (-x) of the block, as written
        np.testing.assert_allclose(type_size(str(path)), (3.0, 2.0, 1.6), atol=1e-6)  # the file's own size (length along x)
        assert type_class(str(path)) == "car"  # by the file's name (labels.yaml name rules)
    moved = write_gltf(tmp_path / "thing.glb", [(*box_in_gltf(1.0, 1.0, 1.0), "paint")], translation=(0.0, 5.0, 0.0))
    (part,) = mesh_file_parts(str(moved), (1.0, 1.0, 1.0))
    assert part.material == "diffuse" and type_class(str(moved)) == "unlabeled"


def test_gltf_reader_agrees_with_trimesh(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    path = glass_car(tmp_path / "car.glb")
    scene = trimesh.load(str(path))
    theirs = np.concatenate([g.vertices for g in scene.dump()]) @ GLTF_TO_SENSOR.T
    ours = np.concatenate([p.vertices for p in __import__("bpy_pipeline.mixing.objects", fromlist=["file_parts"]).file_parts(str(path))])
    np.testing.assert_allclose(np.sort(ours, axis=0), np.sort(theirs, axis=0), atol=1e-6)


def test_obj_usemtl_glass_and_ply_meshes(tmp_path):
    obj = tmp_path / "person_scan.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 1\nusemtl skin\nf 1 2 3\nf 1 2 4\nusemtl Window.001\nf 2 3 5\n")
    parts = mesh_file_parts(str(obj), (1.0, 1.0, 1.0))
    assert [p.material for p in parts] == ["diffuse", "glass"] and [len(p.triangles) for p in parts] == [2, 1]
    assert type_class(str(obj)) == "person"
    pytest.importorskip("plyfile")
    from plyfile import PlyData, PlyElement

    v = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0)], dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    f = np.array([([0, 1, 2],)], dtype=[("vertex_indices", "i4", (3,))])
    ply = tmp_path / "car.ply"
    PlyData([PlyElement.describe(v, "vertex"), PlyElement.describe(f, "face")]).write(str(ply))
    (part,) = mesh_file_parts(str(ply), (1.0, 1.0, 0.0))
    assert part.material == "diffuse"


def test_bad_object_types_are_refused_in_one_line(tmp_path):
    lying = tmp_path / "car.glb"
    lying.write_bytes(b"glTF" + struct.pack("<II", 2, 40) + b"\0" * 28)
    cases = {"spaceship": "scene.objects[0].type", str(tmp_path / "absent.glb"): "absent.glb", str(lying): "not a readable glTF",
             str(tmp_path / "a.stl"): ".glb, .gltf"}
    for kind, expected in cases.items():
        with pytest.raises(InputError) as err:
            check_type(kind, "scene.objects[0].type")
        assert expected in str(err.value) and "\n" not in str(err.value)
    for kind in OBJECT_TYPES:
        check_type(kind, "x")


def test_a_cyclist_is_a_rider_on_a_bicycle():
    parts = cyclist_object(np.random.default_rng(0))
    assert [p.material for p in parts] == ["diffuse"] * 3 and len(parts) == 3
    v = np.concatenate([p.vertices for p in parts])
    size = v.max(axis=0) - v.min(axis=0)
    assert 1.6 < size[0] < 1.9 and 1.5 < size[2] < 1.9  # the bicycle's length, the seated rider's head
    rider, wheels = parts[2].vertices, parts[1].vertices
    assert rider[:, 2].min() > v[:, 2].min() + 0.3 and rider[:, 2].max() == v[:, 2].max()  # seated on the saddle, the head on top
    assert wheels[:, 2].min() == v[:, 2].min()  # the wheels stand on the ground
    assert OBJECT_TYPES["cyclist"][0] == "rider"
    table, maps = load_class_table(), load_class_maps()
    table.id_of("rider")
    assert maps.kitti_name("rider") == "Cyclist"


# ----------------------------------------------------------------------------- in a real scan
@pytest.fixture
def sweep(real_scan):
    return real_scan(SWEEP)


def test_cyclists_are_one_instance_with_one_class(sweep):
    section = RealScanScene(path=str(sweep), objects=[ObjectBox("cyclist", (7.0, 2.5, -0.95), (0, 0, 0), 30.0),
                                                      ObjectBox("cyclist", (9.0, -3.0, -0.95), (0, 0, 0), -60.0)])
    m = mix_frame(section, np.random.default_rng(2))
    rider = load_class_table().id_of("rider")
    new = m.points[m.inserted]
    assert len(new) > 50
    assert set(np.unique(new["semantic"]).tolist()) == {rider}
    assert len(np.unique(new["instance"])) == 2  # one per cyclist, the bicycle's points and the rider's alike
    for box, p in zip(m.boxes[: len(m.placements)], m.placements):
        mine = new[new["instance"] == box["instance"]]
        assert box["class_name"] == "rider" and len(mine) > 20
        assert load_class_maps().kitti_name(str(box["class_name"])) == "Cyclist"
        np.testing.assert_allclose(box["size"], OBJECT_TYPES["cyclist"][2])
        # every point of that instance lies in its box: bicycle and rider are one object
        d = np.column_stack([mine["x"], mine["y"]]) - p.centre[:2]
        c, s = np.cos(p.yaw), np.sin(p.yaw)
        along, across = d @ [c, s], d @ [-s, c]
        assert (np.abs(along) <= p.size[0] / 2 + 1e-3).all() and (np.abs(across) <= p.size[1] / 2 + 1e-3).all()


def test_a_gltf_car_inserts_with_glass_that_rays_pass(sweep, tmp_path):
    path = glass_car(tmp_path / "car.glb")
    painted = write_gltf(tmp_path / "car_paint.glb", [(*box_in_gltf(1.0, 2.0, 1.6), "CarPaint"), (*box_in_gltf(0.01, 2.0, 1.6, x0=-2.0), "CarPaint")])
    runs = {}
    for name, file in (("glass", path), ("paint", painted)):
        section = RealScanScene(path=str(sweep), objects=[ObjectBox(str(file), (9.0, 0.0, -1.0), (0, 0, 0), 0.0)])
        m = mix_frame(section, np.random.default_rng(0))
        assert [b["class_name"] for b in m.boxes[: len(m.placements)]] == ["car"]
        new = m.points[m.inserted]
        runs[name] = np.column_stack([new["x"], new["y"], new["z"]]).astype(float)
    # the pane's front face lies at x = 9 - 1.5 = 7.5, the block's at 9 - 1.5 + 2.0 = 9.5 (box centre 9, the file's length 3.0)
    on_pane = lambda xyz: np.abs(xyz[:, 0] - 7.5) < 0.05  # noqa: E731
    on_block = lambda xyz: np.abs(xyz[:, 0] - 9.5) < 0.05  # noqa: E731
    pane, block = on_pane(runs["paint"]).sum(), on_block(runs["paint"]).sum()  # opaque: the pane hides the block (but rays over its top)
    assert pane > 100 and block < 0.2 * pane
    # glass lets the rays through; as the scanner's glass (cast_firings: MirrorGlassRules(glass_return_deg=5)) the pane itself
    # returns only beams within 5 degrees of its normal (here the sensor's x axis)
    glass = runs["glass"]
    seen = glass[on_pane(glass)]
    incidence = np.degrees(np.arccos(seen[:, 0] / np.linalg.norm(seen, axis=1)))
    assert len(seen) < 0.25 * pane and (incidence <= 5.5).all()  # measured from the sensor origin; each firing leaves from its own
    assert on_block(glass).sum() >= block + 0.3 * pane  # the block behind gets the beams (fewer: it is farther, and rays through the
    # pane's lower part pass under it)


def test_rule_cars_take_a_drawn_bodys_size_and_classic_keeps_the_old_draw(sweep):
    base = dict(path=str(sweep), parking_rule=ParkingRule(enabled=True))
    a = mix_frame(RealScanScene(**base), np.random.default_rng(4))
    b = mix_frame(RealScanScene(**base), np.random.default_rng(4))
    assert np.array_equal(a.points, b.points)  # same seed, same bytes
    assert len(a.placements) >= 2 and all(0 <= p.body < len(BODIES) for p in a.placements)
    for p in a.placements:
        np.testing.assert_allclose(p.size / style_size(BODIES[p.body], BODIES[p.body].height), [1, 1, 1], atol=0.031)
    classic = mix_frame(RealScanScene(**base, car_bodies="classic"), np.random.default_rng(4))
    assert all(p.body == -1 and 1.55 <= p.size[2] <= 1.70 for p in classic.placements)  # the rule's height, a style drawn when meshed
    assert len(STYLES) == 3


def test_the_cli_writes_cyclists_and_gltf_cars_as_kitti_labels_and_refuses_bad_types(sweep, tmp_path):
    car = glass_car(tmp_path / "car.glb")
    objects = f"[{{type: cyclist, center: [7, 2.5, -0.95], yaw_deg: 30}}, {{type: '{car}', center: [10, -3, -1.0]}}]"
    def run(out, *extra):
        return subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--set", "scene.builder=real_scan", "--set", f"scene.path={sweep}",
                               "--set", "output.preview=false", *extra], capture_output=True, text=True, timeout=300)

    done = run(tmp_path / "a", "--set", f"scene.objects={objects}", "--set", "effects.ideal=true")
    assert done.returncode == 0, done.stderr
    (label,) = sorted((tmp_path / "a").glob("kitti/**/label_2/000000.txt"))
    names = sorted(line.split()[0] for line in label.read_text().splitlines())
    assert names == ["Car", "Cyclist"]
    done = run(tmp_path / "b", "--set", "scene.objects=[{type: unicycle}]")
    assert done.returncode == 2 and "scene.objects[0].type" in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "b" / "sequences").exists()
