"""bpy-pipeline convert: a dense scan in a sparser sensor's pattern, each point keeping the labels of the return it came from."""

import math

import numpy as np
import pytest

from bpy_pipeline.cli.commands import main
from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.cli.convert import TRAINING_TO_RAW, convert, project_classes
from bpy_pipeline.geometry import primitives
from bpy_pipeline.io.class_maps import semantic_kitti_lut
from bpy_pipeline.io.semantickitti import read_bin, read_label
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
from bpy_pipeline.mixing.convert import METHODS, target_rays

SEQ01 = "semantickitti_seq01_000000"
CAR = (12.0, 3.0, -1.0), (4.5, 1.8, 1.5)  # centre (m, sensor frame), size; the ground 1.73 m below the sensor


def street(tmp_path):
    """An organised HDL-64E scan (rings, columns, 4) of a ground plane and a car-sized box, and its raw labels:
    road (40) on the ground, car (10) instance 7 on the box. Returns (scan.npy, labels.npy)."""
    ground = primitives.plane(200.0, 200.0)
    box = primitives.box(*CAR[1])
    box = (box[0] + np.array(CAR[0]) + [0.0, 0.0, 1.73], box[1])
    buffers = SceneBuffers.from_meshes({"ground": ground, "car": box})
    spec = resolve_sensor({"preset": "hdl64e"}, "s")
    directions, ring, column = target_rays(spec)
    frame = np.eye(4)
    frame[2, 3] = 1.73
    hits = RayCaster(buffers, frame=frame).intersect(np.zeros(3), directions, spec.max_range)
    grid = np.zeros((ring.max() + 1, column.max() + 1, 4))
    labels = np.zeros((ring.max() + 1, column.max() + 1), np.uint32)
    grid[ring[hits.ray], column[hits.ray], :3] = directions[hits.ray] * hits.distance[:, None]
    grid[ring[hits.ray], column[hits.ray], 3] = 0.5
    on_car = buffers.triangle_object[hits.triangle] == 1
    labels[ring[hits.ray], column[hits.ray]] = np.where(on_car, 10 | (7 << 16), 40)
    scan, lab = tmp_path / "street.npy", tmp_path / "street_labels.npy"
    np.save(scan, grid.astype(np.float32))
    np.save(lab, labels.T.reshape(-1).astype(np.int64))  # the reader lists an organised file column after column
    return scan, lab


def in_box(xyz, centre, size, grow):
    return (np.abs(xyz - np.asarray(centre)) <= np.asarray(size) / 2 + grow).all(axis=1)


@pytest.mark.parametrize("method", METHODS)
def test_labels_follow_the_geometry_on_a_street(tmp_path, method):
    scan, labels = street(tmp_path)
    out = convert(scan, "hdl32e", labels, method, label_space="raw")
    pts = out.points
    xyz = np.column_stack([pts["x"], pts["y"], pts["z"]]).astype(float)
    table_car = project_classes(np.array([10], np.uint32))[0][0]
    car = pts["semantic"] == table_car
    assert car.sum() > 50 and (~car).sum() > 5000
    assert (pts["instance"][car] == 7).all() and (pts["instance"][~car] == 0).all()
    # every point labelled car lies on the box (the cones' projection moves a point by at most half a ring spacing:
    # 0.67 deg, 14 cm at 12 m), every other on the ground
    assert in_box(xyz[car], CAR[0], CAR[1], 0.2).all()
    slack = pts["range"][~car] * math.radians(0.7) if method != "mesh" else 0.01  # the cones' move grows with range
    off_ground = np.abs(xyz[~car, 2] + 1.73) > slack + 1e-3
    # a road point off the ground is where the mesh joins the box's foot to the ground (its nearest corner is the ground's)
    assert in_box(xyz[~car][off_ground], CAR[0], CAR[1], 0.3).all() and off_ground.sum() <= 0.1 * car.sum()
    # and the box's front face, well inside its outline, holds car points only
    face = in_box(xyz, CAR[0], np.array(CAR[1]) + [0.1, -0.6, -0.6], 0.0)
    assert face.sum() > 10 and car[face].all()


@pytest.mark.parametrize("method", METHODS)
def test_labels_survive_the_conversion_of_a_real_kitti_scan(real_scan, method):
    scan, labels = real_scan(f"{SEQ01}_points.npy"), real_scan(f"{SEQ01}_labels.npy")
    train = np.load(labels).reshape(-1)
    points = np.load(scan).astype(float)
    out = convert(scan, "hdl32e", labels, method, source_preset="hdl64e")
    pts = out.points
    assert 5000 < len(pts) < len(points) / 3 and pts["ring"].max() < 32
    assert (out.source >= 0).all()
    # each point's label is the label of the source point it came from
    semantic, instance = project_classes(TRAINING_TO_RAW[train[out.source]])
    np.testing.assert_array_equal(pts["semantic"], semantic)
    np.testing.assert_array_equal(pts["instance"], instance)
    assert len(np.unique(pts["semantic"])) >= 5  # cars, road, vegetation, fence, terrain ... survive
    # and it did come from there: the point lies near its source, at the source's range seen from the target
    xyz = np.column_stack([pts["x"], pts["y"], pts["z"]]).astype(float)
    src = points[out.source]
    r = np.linalg.norm(src, axis=1)
    gap = np.linalg.norm(xyz - src, axis=1)
    if method == "cones":
        np.testing.assert_allclose(pts["range"], r, rtol=1e-5)
        assert (gap <= r * math.radians(1.0) + 1e-3).all()  # half a ring spacing (0.67 deg) and half a column
    else:
        # a mesh triangle joins returns within 10 % + 0.3 m in range and one ring or column apart (<= 0.6 deg)
        assert (gap <= 0.12 * r + 0.3).all() and np.median(gap / r) < 0.01


def test_the_written_dataset_holds_the_carried_labels(real_scan, tmp_path):
    scan, labels = real_scan(f"{SEQ01}_points.npy"), real_scan(f"{SEQ01}_labels.npy")
    out = tmp_path / "converted"
    assert main(["convert", str(scan), "--labels", str(labels), "--to", "hdl32e", "--from", "hdl64e", "--out", str(out), "--formats", "semantickitti,npy"]) == 0
    xyz = read_bin(out / "sequences" / "00" / "velodyne" / "000000.bin")
    semantic, instance = read_label(out / "sequences" / "00" / "labels" / "000000.label")
    again = convert(scan, "hdl32e", labels, source_preset="hdl64e")
    assert len(xyz) == len(semantic) == len(again.points)
    np.testing.assert_allclose(xyz[:, 0], again.points["x"])
    train = np.load(labels).reshape(-1)
    expected, expected_instance = project_classes(TRAINING_TO_RAW[train[again.source]])
    np.testing.assert_array_equal(semantic, semantic_kitti_lut()[expected])  # written back in SemanticKITTI's raw ids
    np.testing.assert_array_equal(instance, expected_instance)
    assert (semantic == 10).sum() > 20  # the highway's cars
    assert (out / "manifest.json").is_file() and (out / "records" / "000000.json").is_file() and (out / "npy" / "000000").is_dir()


def bad(capsys, argv):
    try:
        code = main(["convert", *argv])
    except SystemExit as exit_:  # argparse's own refusals (OneLineParser: one line, exit 2)
        code = exit_.code
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


@pytest.mark.parametrize("case, needle", [
    (lambda d: [str(d / "none.bin"), "--to", "hdl32e", "--out", str(d / "o")], "SCAN:"),
    (lambda d: [str(d / "street.npy"), "--to", "nosuch", "--out", str(d / "o")], "--to: unknown preset"),
    (lambda d: [str(d / "street.npy"), "--to", "flash96x16", "--out", str(d / "o")], "--to: flash96x16"),
    (lambda d: [str(d / "street.npy"), "--to", "hdl32e", "--out", str(d / "o"), "--labels", str(d / "short.npy")], "--labels:"),
    (lambda d: [str(d / "street.npy"), "--to", "hdl32e", "--out", str(d / "o"), "--labels", str(d / "street_labels.npy")], "training ids"),
    (lambda d: [str(d / "street.npy"), "--to", "hdl32e", "--out", str(d / "o"), "--formats", "kitti"], "--formats"),
    (lambda d: [str(d / "street.npy"), "--to", "hdl32e", "--out", str(d / "o"), "--method", "nearest"], "--method"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, case, needle):
    street(tmp_path)
    np.save(tmp_path / "short.npy", np.zeros(5, np.int32))
    code, err = bad(capsys, case(tmp_path))
    assert code == 2 and len(err) == 1 and needle in err[0], err
    assert not (tmp_path / "o").exists()  # nothing half-written
