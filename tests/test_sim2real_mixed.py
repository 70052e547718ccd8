"""benchmarks/sim2real_mixed.py: real backgrounds emptied of movable objects, synthetic cars and people cast in, real labels kept."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io.real_scans import RealScan
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.mixing.firings import recover_firings

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import sim2real_mixed as sm

SEQ01 = "semantickitti_seq01_000000_points.npy"


@pytest.fixture(scope="module")
def mixed(tmp_path_factory, real_scans_folder):
    """One frame mixed into SemanticKITTI sequence 01 frame 0: (dataset folder, points, record, source labels, scratch folder)."""
    pytest.importorskip("bpy", reason="the pipeline run needs the bpy module (pip install 'bpy==4.5.*')")
    source = real_scans_folder / SEQ01
    if not source.exists():
        pytest.skip(f"real scan {source} is absent (set BPY_PIPELINE_REAL_SCANS to its folder)")
    import bpy_pipeline as bp

    tmp = tmp_path_factory.mktemp("mixed")
    out = sm.make_mixed_dataset([source], tmp / "out", 1, 11, tmp / "work")
    points = bp.read_ply(out / "ply" / "000000.ply")
    record = json.loads((out / "records" / "000000.json").read_text())["scene"]
    labels = np.load(source.with_name(SEQ01.replace("_points", "_labels"))).reshape(-1)
    return out, points, record, labels, tmp


def test_synthetic_cars_and_people_are_the_only_movable_points(mixed):
    out, points, record, labels, _ = mixed
    table = load_class_table()
    car, person = table.id_of("car"), table.id_of("person")
    classes = [o["class"] for o in record["objects"]]
    assert classes.count("car") >= 2 and classes.count("person") >= 1  # the KITTI rule's cars, the parking rule's people
    for o in record["objects"]:  # off the recording car
        assert np.hypot(*o["center"][:2]) >= (sm.EGO_CLEARANCE_M if o["class"] == "car" else 4.0) - 1e-3, o
    movable = np.isin(points["semantic"], [car, person])
    assert (points["semantic"] == car).sum() > 100 and (points["semantic"] == person).sum() > 10
    # every car / person point is an inserted one: none of the source's 321 real car points is left
    assert (labels == 1).sum() > 300
    assert int(movable.sum()) == record["inserted_points"]
    assert set(np.unique(points["instance"][movable])) <= {o["instance"] for o in record["objects"]}
    manifest = json.loads((out / "manifest.json").read_text())["sim2real_mixed"]
    assert manifest["backgrounds"][0]["removed"] == int(np.isin(labels, sm.MOVABLE_TRAINING_IDS).sum())
    assert manifest["cpu_s_per_frame"] > 0


def test_background_labels_kept(mixed):
    """Real classes the mixing table maps by name arrive as the project's class; the real returns are the emptied
    scan's, less those the inserted objects hide."""
    _, points, record, labels, tmp = mixed
    table = load_class_table()
    real = len(points) - record["inserted_points"]
    kept = int((~np.isin(labels, sm.MOVABLE_TRAINING_IDS)).sum())
    assert real == kept - record["occluded_real"]
    road, sign = table.id_of("road"), table.id_of("traffic sign")
    for cls, training in ((road, 9), (sign, 19)):
        have = int((points["semantic"] == cls).sum())
        assert int((labels == training).sum()) - record["occluded_real"] <= have <= int((labels == training).sum())
    # the emptied background on disk: raw ids by the official inverse learning map, no movable class
    raw = np.fromfile(tmp / "work" / sm.BACKGROUND_FOLDER / "000000.label", np.uint32)
    assert len(raw) == kept and not np.isin(raw, [10, 11, 15, 18, 20, 30, 31, 32]).any()
    assert (raw == 70).sum() == (labels == 15).sum() and (raw == 40).sum() == (labels == 9).sum()


def test_background_vegetation_terrain_fence_pole_kept(mixed):
    _, points, _, labels, _ = mixed
    table = load_class_table()
    for name, training in (("vegetation", 15), ("terrain", 17), ("fence", 14), ("pole", 18)):
        assert (labels == training).sum() > 100
        assert (points["semantic"] == table.id_of(name)).sum() > 0, name


def test_same_seed_same_bytes(mixed, real_scans_folder):
    out, _, _, _, tmp = mixed
    again = sm.make_mixed_dataset([real_scans_folder / SEQ01], tmp / "again", 1, 11, tmp / "work2")
    assert (again / "ply" / "000000.ply").read_bytes() == (out / "ply" / "000000.ply").read_bytes()


def _box_corners_velodyne(line: str, calib: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A label_2 box in the velodyne frame, computed here independently: (centre (3,), axes (3, 3) rows, half sizes (3,))."""
    v = [float(x) for x in line.split()[1:15]]
    h, w, l, x, y, z, ry = v[7], v[8], v[9], v[10], v[11], v[12], v[13]
    to_rect = np.eye(4)
    to_rect[:3, :4] = calib["R0_rect"] @ calib["Tr_velo_to_cam"]
    back = np.linalg.inv(to_rect)
    centre = back[:3, :3] @ np.array([x, y - h / 2, z]) + back[:3, 3]
    # object axes in the camera frame: length along (cos ry, 0, -sin ry), height along y, width along (sin ry, 0, cos ry)
    axes = np.array([[np.cos(ry), 0, -np.sin(ry)], [0, 1, 0], [np.sin(ry), 0, np.cos(ry)]]) @ back[:3, :3].T
    return centre, axes, np.array([l, h, w]) / 2


def test_kitti_frame_emptied_of_every_box(real_scan):
    scan = real_scan("kitti_hdl64e_004747.bin")
    lines = [ln for ln in real_scan("kitti_004747_label_2.txt").read_text().splitlines() if ln.strip()]
    calib = sm.read_kitti_calib(real_scan("kitti_004747_calib.txt"))
    background = sm.empty_background(scan)
    data = np.fromfile(scan, np.float32).reshape(-1, 4)
    assert background.kind == "kitti_object" and len(background.points) + background.removed == len(data)
    assert (background.raw == 0).all()  # KITTI labels objects only: the rest is unlabelled
    inside_any = np.zeros(len(data), bool)
    for line in lines:
        if line.split()[0] == "DontCare":
            continue
        centre, axes, half = _box_corners_velodyne(line, calib)
        local = (data[:, :3] - centre) @ axes.T
        inside = (np.abs(local) <= half + sm.KITTI_BOX_MARGIN + 1e-6).all(axis=1)
        inside_any |= inside
        left = (np.abs((background.points[:, :3] - centre) @ axes.T) <= half + sm.KITTI_BOX_MARGIN - 1e-3).all(axis=1)
        assert not left.any(), line
    assert abs(int(inside_any.sum()) - background.removed) <= 2  # float32 points on a face
    assert background.removed > 1000  # 4 cars, 13 pedestrians, 3 cyclists


def test_bad_backgrounds_get_one_line(real_scan, tmp_path):
    real = real_scan("semantickitti_000700_points.npy")  # in its sensor's frame; moved 100 m off, it is not
    offset = tmp_path / "moved_points.npy"
    np.save(offset, np.load(real) + np.float32([0, -100, 0]))
    np.save(tmp_path / "moved_labels.npy", np.load(str(real).replace("_points", "_labels")))
    with pytest.raises(InputError, match="moved_points.npy: not in its sensor's frame"):
        sm.empty_background(offset)
    lone = tmp_path / "x_points.npy"
    np.save(lone, np.zeros((10, 3), np.float32))
    with pytest.raises(InputError, match="missing label file"):
        sm.empty_background(lone)
    np.save(tmp_path / "x_labels.npy", np.full(10, 25, np.int32))
    with pytest.raises(InputError, match="training ids are 0..19"):
        sm.empty_background(lone)
    with pytest.raises(InputError, match="backgrounds: give at least one"):
        sm.make_mixed_dataset([], tmp_path / "out", 1, 0, tmp_path / "work")
    work = tmp_path / "busy"
    (work / sm.BACKGROUND_FOLDER).mkdir(parents=True)
    (work / sm.BACKGROUND_FOLDER / "mine.bin").write_bytes(b"")
    with pytest.raises(InputError, match="holds other files"):
        sm.make_mixed_dataset([real_scan(SEQ01)], tmp_path / "out", 1, 0, work)


def test_kitti_rule_min_range_checked():
    from bpy_pipeline.builders.real_scan.params import check
    from bpy_pipeline.mixing.section import KittiRule, RealScanScene

    with pytest.raises(InputError, match=r"scene.kitti_rule.min_range: must be 0 .. kitti_rule.max_range \(50\), got 60"):
        check(RealScanScene(path="scan.bin", kitti_rule=KittiRule(min_range=60.0)), "scene")


def test_shuffled_scan_order_takes_the_presets_rings(real_scan):
    """A scan of returns whose order is not the scan order (as the shared SemanticKITTI samples) gets the preset's
    rings, not one ring per azimuth wrap (sequence 01 frame 0 read in its stored order gave 8,712 rings, 18 million firings)."""
    data = np.fromfile(real_scan("kitti_hdl64e_004747.bin"), np.float32).reshape(-1, 4).astype(np.float64)
    in_order = recover_firings(RealScan(data[:, :3], data[:, 3]), "hdl64e")
    shuffled = data[np.random.default_rng(0).permutation(len(data))]
    firings = recover_firings(RealScan(shuffled[:, :3], shuffled[:, 3]), "hdl64e")
    assert in_order.shape[0] == 64 and firings.shape[0] == 64
    assert any("nearest elevation of preset hdl64e" in note for note in firings.approximate)
    assert len(firings) < 1.5 * len(in_order)
