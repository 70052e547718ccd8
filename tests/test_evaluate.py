"""bpy-pipeline evaluate: label maps against SemanticKITTI's own tables, KITTI box labelling against an independent
count, IoU and its intervals, the reference model, the command end to end, and bad input."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("scipy", reason="evaluate needs the evaluate extra (pip install '.[evaluate]')")
pytest.importorskip("lightgbm", reason="evaluate's reference model needs LightGBM (pip install '.[evaluate]')")

from bpy_pipeline.cli.commands import main
from bpy_pipeline.evaluate import label_maps, labelled, metrics
from bpy_pipeline.evaluate.features import FEATURE_NAMES, point_features
from bpy_pipeline.evaluate.labelled import LabelledScan, load_scans
from bpy_pipeline.evaluate.models import fit
from bpy_pipeline.evaluate.run import evaluate
from bpy_pipeline.labels import load_class_table

ROOT = Path(__file__).resolve().parents[1]

# semantic-kitti.yaml (semantic-kitti-api, config/semantic-kitti.yaml): `labels` and `learning_map`, copied from the official file.
SK_LABELS = {
    0: "unlabeled", 1: "outlier", 10: "car", 11: "bicycle", 13: "bus", 15: "motorcycle", 16: "on-rails", 18: "truck",
    20: "other-vehicle", 30: "person", 31: "bicyclist", 32: "motorcyclist", 40: "road", 44: "parking", 48: "sidewalk",
    49: "other-ground", 50: "building", 51: "fence", 52: "other-structure", 60: "lane-marking", 70: "vegetation",
    71: "trunk", 72: "terrain", 80: "pole", 81: "traffic-sign", 99: "other-object", 252: "moving-car",
    253: "moving-bicyclist", 254: "moving-person", 255: "moving-motorcyclist", 256: "moving-on-rails", 257: "moving-bus",
    258: "moving-truck", 259: "moving-other-vehicle",
}  # fmt: skip
SK_LEARNING_MAP = {
    0: 0, 1: 0, 10: 1, 11: 2, 13: 5, 15: 3, 16: 5, 18: 4, 20: 5, 30: 6, 31: 7, 32: 8, 40: 9, 44: 10, 48: 11, 49: 12,
    50: 13, 51: 14, 52: 0, 60: 9, 70: 15, 71: 16, 72: 17, 80: 18, 81: 19, 99: 0, 252: 1, 253: 7, 254: 6, 255: 8,
    256: 5, 257: 5, 258: 4, 259: 5,
}  # fmt: skip
SK_LEARNING_MAP_INV = {0: 0, 1: 10, 2: 11, 3: 15, 4: 18, 5: 20, 6: 30, 7: 31, 8: 32, 9: 40, 10: 44, 11: 48, 12: 49, 13: 50,
                       14: 51, 15: 70, 16: 71, 17: 72, 18: 80, 19: 81}  # fmt: skip


# ----------------------------------------------------------------------------- label maps
def test_label_maps_match_semantickittis_own_tables():
    assert label_maps.SEMANTICKITTI_LEARNING_MAP == SK_LEARNING_MAP
    names = [SK_LABELS[SK_LEARNING_MAP_INV[t]] for t in range(20)]  # training id -> name, through the official inverse map
    assert list(label_maps.TRAINING_NAMES) == names
    classes = tuple(names[1:])  # every training class requested: evaluation index = training id - 1
    raw = np.array(sorted(SK_LABELS))
    got = label_maps.raw_to_eval(raw | (7 << 16), classes)  # instance bits are not the class
    for r, g in zip(raw, got):
        t = SK_LEARNING_MAP[int(r)]
        expected = -1 if r in (0, 1) else len(classes) if t == 0 else t - 1  # other-structure / other-object: labelled, "other"
        assert g == expected, (SK_LABELS[int(r)], g, expected)
    # training ids, for two classes: car and person; moving-person (254) is a person
    t = np.arange(20)
    assert list(label_maps.training_to_eval(t, ("car", "person"))) == [-1, 0] + [2] * 4 + [1] + [2] * 13
    assert label_maps.raw_to_eval(np.array([254, 252, 31, 70]), ("person", "car")).tolist() == [0, 1, 2, 2]


def test_project_classes_map_through_labels_yaml_to_semantickitti_names():
    table = load_class_table()
    classes = ("car", "person", "bicyclist", "vegetation", "fence")
    ids = {name: i for i, name in table.names.items()}
    expected = {"car": 0, "van": 0, "person": 1, "rider": 2, "vegetation": 3, "barrier": 4, "fence": 4, "road": 5,
                "building": 5, "traffic cone": 5, "gantry": 5, "unlabeled": -1, "reflection": -1}  # fmt: skip
    got = label_maps.project_to_eval(np.array([ids[n] for n in expected]), classes)
    assert dict(zip(expected, got.tolist())) == expected
    assert label_maps.project_to_eval(np.array([60000]), classes).tolist() == [-1]  # an id outside the table: ignored


def test_kitti_types_and_class_names():
    classes = ("car", "person")
    assert [label_maps.kitti_type_to_eval(t, classes) for t in ("Car", "Pedestrian", "Person_sitting", "Cyclist", "Van", "Truck", "Tram", "Misc",
                                                                "DontCare")] == [0, 1, 1, -1, -1, -1, -1, -1, -1]
    assert label_maps.kitti_type_to_eval("Cyclist", ("car", "bicyclist")) == 1
    assert label_maps.parse_classes("car, Traffic_Sign,other-ground") == ("car", "traffic-sign", "other-ground")


# ----------------------------------------------------------------------------- synthetic scenes
def _scene(rng, car_at=(10.0, 0.0), person_at=(6.0, 4.0), name="s0", group="g0") -> LabelledScan:
    """A ground plane, a wall, a 4 x 1.8 x 1.5 m box car and a 0.5 x 1.8 m person, points on their surfaces; sensor at 1.7 m."""
    ground = np.column_stack([rng.uniform(-30, 30, 20000), rng.uniform(-30, 30, 20000), np.full(20000, -1.7)])
    wall = np.column_stack([rng.uniform(-20, 20, 4000), np.full(4000, 15.0), rng.uniform(-1.7, 3.0, 4000)])
    u = rng.uniform(-0.5, 0.5, (3000, 3))
    face = rng.integers(0, 3, 3000)
    u[np.arange(3000), face] = np.sign(u[np.arange(3000), face]) * 0.5  # on the box's faces
    car = u * (4.0, 1.8, 1.5) + (*car_at, -1.7 + 0.75 + 0.2)
    angle = rng.uniform(0, 2 * np.pi, 800)
    person = np.column_stack([person_at[0] + 0.25 * np.cos(angle), person_at[1] + 0.25 * np.sin(angle), rng.uniform(-1.7, 0.1, 800)])
    points = np.concatenate([ground, wall, car, person]).astype(np.float32)
    labels = np.concatenate([np.full(24000, 2), np.zeros(3000), np.ones(800)]).astype(np.int64)
    labels[:200] = -1  # some ignored points
    return LabelledScan(name, group, points, labels, labelled.object_ids(points, labels, ("car", "person")), ("car", "person"))


def test_iou_is_one_for_the_truth_and_drops_when_labels_are_shuffled():
    rng = np.random.default_rng(0)
    scans = [_scene(rng), _scene(rng, (12.0, -5.0), (8.0, 6.0), "s1")]
    truth = [s.labels.copy() for s in scans]
    perfect = metrics.score(scans, truth, ("car", "person"), seed=0)
    for c in ("car", "person"):
        r = perfect["classes"][c]
        assert r["iou"] == 1.0 and r["interval"] == [1.0, 1.0] and r["fp"] == r["fn"] == 0
        assert r["objects"] == r["objects_found"] == 2
    shuffled = [np.where(s.labels >= 0, rng.permutation(np.clip(s.labels, 0, None)), -1) for s in scans]
    worse = metrics.score(scans, shuffled, ("car", "person"), seed=0)
    for c in ("car", "person"):
        r = worse["classes"][c]
        assert r["iou"] < 0.2 and r["interval"][1] < 0.5 and r["false_positive_regions"] > 0
    # the same seed, the same interval; another seed, another draw
    assert metrics.score(scans, shuffled, ("car", "person"), seed=0)["classes"]["car"]["interval"] == worse["classes"]["car"]["interval"]


def test_bootstrap_interval_is_over_objects():
    units = np.array([[10, 0, 0], [0, 0, 10]])  # one object found whole, one missed whole
    lo, hi = metrics.bootstrap_interval(units, np.random.default_rng(0), 1000)
    assert lo == 0.0 and hi == 1.0  # resampling two objects: either can be drawn twice
    many = np.tile(units, (200, 1))
    lo, hi = metrics.bootstrap_interval(many, np.random.default_rng(0), 1000)
    assert 0.4 < lo < 0.5 < hi < 0.6


def test_false_positives_are_named_by_their_true_class():
    rng = np.random.default_rng(1)
    scan = _scene(rng)
    scan.truth = np.where(scan.labels == 2, 9, np.where(scan.labels == 0, 1, np.where(scan.labels == 1, 6, 0)))  # road, car, person
    pred = scan.labels.clip(0, None).copy()
    pred[scan.points[:, 1] > 14.9] = 1  # the wall's points called person: they are "road" in this toy truth
    fps = metrics.false_positive_truth([scan], [pred], 1)
    assert list(fps) == ["road"] and fps["road"] == int(((scan.points[:, 1] > 14.9) & (scan.labels == 2)).sum())


def test_features_are_finite_named_and_tell_objects_apart():
    rng = np.random.default_rng(2)
    scan = _scene(rng)
    f = point_features(scan.points)
    assert f.shape == (len(scan), len(FEATURE_NAMES)) and f.dtype == np.float32 and np.isfinite(f).all()
    h = f[:, FEATURE_NAMES.index("height_m")]
    assert abs(np.median(h[scan.labels == 2][:20000])) < 0.05  # the ground is at height 0
    length = f[:, FEATURE_NAMES.index("cluster_length_m")]
    assert 3.5 < np.median(length[scan.labels == 0]) < 4.6 and np.median(length[scan.labels == 1]) < 0.8
    assert np.array_equal(f, point_features(scan.points))  # deterministic


def test_model_learns_the_toy_world_and_is_deterministic():
    rng = np.random.default_rng(3)
    train = [_scene(rng, (8 + 3 * i, -4 + 2 * i), (5 + i, 3 - i), f"t{i}", f"g{i}") for i in range(3)]
    test = _scene(rng, (15.0, 6.0), (4.0, -6.0), "test", "gt")
    model = fit(train, ("car", "person"), seed=0, max_points_per_scan=3000)
    pred = model.predict(test)
    report = metrics.score([test], [pred], ("car", "person"))
    assert report["classes"]["car"]["iou"] > 0.8 and report["classes"]["person"]["iou"] > 0.6
    again = fit(train, ("car", "person"), seed=0, max_points_per_scan=3000).predict(test)
    assert np.array_equal(pred, again)


@pytest.mark.parametrize("model_name", ["lgbm", "forest"])
def test_a_training_set_without_one_class_trains_and_never_predicts_it(model_name):
    """Training data that hold no person (a matched highway, say) still train a model: it finds cars and calls nothing a person."""
    rng = np.random.default_rng(4)
    train = []
    for i in range(2):
        scan = _scene(rng, (8 + 3 * i, -4 + 2 * i), (5 + i, 3 - i), f"t{i}", f"g{i}")
        scan.labels[scan.labels == 1] = 2  # the person's points become background
        train.append(scan)
    test = _scene(rng, (15.0, 6.0), (4.0, -6.0), "test", "gt")
    model = fit(train, ("car", "person"), seed=0, max_points_per_scan=3000, model=model_name)
    pred = model.predict(test)
    assert (pred != 1).all() and metrics.score([test], [pred], ("car", "person"))["classes"]["car"]["iou"] > 0.8


def test_leave_one_group_out_never_trains_on_the_test_group():
    rng = np.random.default_rng(4)
    scans = [_scene(rng, (8 + i, 0), (5, 3), f"a{i}", "a") for i in range(2)] + [_scene(rng, (12, 3), (6, -2), "b0", "b")]
    report = evaluate(scans, scans, ("car", "person"), reference=scans, max_points_per_scan=2000, draws=100)
    folds = {f["test_group"]: f["train"] for f in report["real_reference"]["folds"]}
    assert folds == {"a": ["b0"], "b": ["a0", "a1"]}
    assert set(report["ratio"]) == {"car", "person", "miou"}


# ----------------------------------------------------------------------------- real scans
def _independent_kitti_count(bin_path: Path, label_path: Path, calib_path: Path):
    """Per box of KITTI frame: (type, mask of points inside it and in the camera's view), with plain numpy."""
    points = np.fromfile(bin_path, np.float32).reshape(-1, 4)[:, :3].astype(np.float64)
    calib = {}
    for line in calib_path.read_text().splitlines():
        if ":" in line:
            key, values = line.split(":", 1)
            calib[key] = np.array(values.split(), float)
    tr = np.vstack([calib["Tr_velo_to_cam"].reshape(3, 4), [0, 0, 0, 1]])
    r0 = np.eye(4)
    r0[:3, :3] = calib["R0_rect"].reshape(3, 3)
    cam = (r0 @ tr @ np.column_stack([points, np.ones(len(points))]).T).T  # (n, 4) rectified camera, homogeneous
    img = (calib["P2"].reshape(3, 4) @ cam.T).T
    with np.errstate(divide="ignore", invalid="ignore"):
        u, v = img[:, 0] / img[:, 2], img[:, 1] / img[:, 2]
    view = (cam[:, 2] > 0) & (u >= 0) & (u < 1242) & (v >= 0) & (v < 375)
    boxes = []
    for line in label_path.read_text().splitlines():
        f = line.split()
        h, w, l, x, y, z, ry = map(float, f[8:15])
        # the box's own frame: origin at its centre, x along its length; camera y points down, so the centre is h/2 above the bottom
        rot = np.array([[np.cos(ry), 0, np.sin(ry)], [0, 1, 0], [-np.sin(ry), 0, np.cos(ry)]])  # object -> camera
        local = (cam[:, :3] - np.array([x, y - h / 2, z])) @ rot  # = rot.T applied to each row
        inside = (np.abs(local[:, 0]) <= l / 2) & (np.abs(local[:, 1]) <= h / 2) & (np.abs(local[:, 2]) <= w / 2)
        boxes.append((f[0], inside & view))
    return view, boxes


def test_kitti_004747_box_labels_match_an_independent_count(real_scan):
    bin_path = real_scan("kitti_hdl64e_004747.bin")
    scan = load_scans([bin_path], ("car", "person"))[0]
    view, boxes = _independent_kitti_count(bin_path, real_scan("kitti_004747_label_2.txt"), real_scan("kitti_004747_calib.txt"))
    in_view = [(t, m) for t, m in boxes if m.any()]
    assert sorted(t for t, _ in in_view) == ["Car"] * 4 + ["Cyclist"] * 3 + ["Pedestrian"] * 13  # the README's count
    car = np.logical_or.reduce([m for t, m in boxes if t == "Car"])
    person = np.logical_or.reduce([m for t, m in boxes if t in ("Pedestrian", "Person_sitting")])
    cyclist = np.logical_or.reduce([m for t, m in boxes if t == "Cyclist"])
    assert np.array_equal(scan.labels == 0, car) and car.sum() > 100
    assert np.array_equal(scan.labels == 1, person & ~car) and person.sum() > 1000
    assert np.array_equal(scan.labels == -1, ~view | (cyclist & ~car & ~person))  # outside the view, and cyclists: ignored
    assert scan.instances[scan.labels >= 0].max() + 1 == 4 + 13  # one object per box with points
    counts = sorted(np.bincount(scan.instances[scan.labels == 0]).tolist())
    assert counts == sorted(int(m.sum()) for t, m in boxes if t == "Car")


def test_real_npy_and_semantickitti_readers(real_scan, tmp_path):
    scan = load_scans([real_scan("semantickitti_000700_points.npy")], ("car", "person"))[0]
    raw = np.load(real_scan("semantickitti_000700_labels.npy")).ravel()
    assert scan.group == "semantickitti" and (scan.labels == 0).sum() == (raw == 1).sum() == 1654 and (scan.labels == 1).sum() == 53
    assert (scan.labels == -1).sum() == (raw == 0).sum()
    sample = load_scans([real_scan("semantickitti_sample.bin")], ("car", "person"))[0]
    lab = np.fromfile(real_scan("semantickitti_sample.label"), np.uint32)
    assert np.array_equal(sample.labels, label_maps.raw_to_eval(lab & 0xFFFF, ("car", "person")))


# ----------------------------------------------------------------------------- the command
def _write_npy_pair(folder: Path, stem: str, n=100, labels_n=None):
    rng = np.random.default_rng(0)
    np.save(folder / f"{stem}_points.npy", rng.normal(size=(n, 3)).astype(np.float32))
    np.save(folder / f"{stem}_labels.npy", rng.integers(0, 20, (labels_n or n, 1)).astype(np.int32))


@pytest.mark.parametrize("case", ["missing_label", "length", "classes", "empty_train", "kitti_calib", "bin_no_labels", "steps"])
def test_bad_input_one_line_exit_2(tmp_path, capsys, case):
    _write_npy_pair(tmp_path, "good")
    good = str(tmp_path / "good_points.npy")
    out = str(tmp_path / "r.json")
    args = {"classes": ["--train", good, "--test", good, "--classes", "car,tree"]}.get(case)
    if case == "steps":  # the trees take no steps
        args, named = ["--train", good, "--test", good, "--steps", "5"], "--steps"
    elif case == "missing_label":
        np.save(tmp_path / "lonely_points.npy", np.zeros((5, 3), np.float32))
        args, named = ["--train", good, "--test", str(tmp_path / "lonely_points.npy")], "lonely_labels.npy"
    elif case == "length":
        _write_npy_pair(tmp_path, "short", 100, 90)
        args, named = ["--train", str(tmp_path / "short_points.npy"), "--test", good], "short_labels.npy"
    elif case == "classes":
        named = "--classes"
    elif case == "empty_train":
        (tmp_path / "empty").mkdir()
        args, named = ["--train", str(tmp_path / "empty"), "--test", good], "empty"
    elif case == "kitti_calib":
        np.zeros((10, 4), np.float32).tofile(tmp_path / "kitti_000042.bin")
        (tmp_path / "kitti_000042_label_2.txt").write_text("Car 0 0 0 0 0 10 10 1.5 1.6 3.9 0 1.7 10 0\n")
        args, named = ["--train", good, "--test", str(tmp_path / "kitti_000042.bin")], "calib"
    else:
        np.zeros((10, 4), np.float32).tofile(tmp_path / "lonely.bin")
        args, named = ["--train", good, "--test", str(tmp_path / "lonely.bin")], "lonely.bin"
    code = main(["evaluate", *args, "--out", out])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and named in err[0], err
    assert not Path(out).exists()


@pytest.mark.bpy
def test_evaluate_command_end_to_end_on_a_generated_street(tmp_path):
    data = tmp_path / "street"
    made = subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(data), "--frames", "2", "--set", "scene.builder=street",
                           "--set", "sensor.preset=hdl64e", "--set", "sensor.position=[0, 0, 1.73]", "--set", "sensor.horizontal_resolution_deg=0.4",
                           "--set", "output.formats=[ply]", "--set", "output.preview=false"], capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    # a tiny "real" file: frame 1 written as a SemanticKITTI .bin + .label, raw ids through the class table's semantickitti section
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.labels import semantickitti_ids

    cloud = read_ply(data / "ply" / "000001.ply")
    to_raw = semantickitti_ids()
    names = load_class_table().names
    raw = np.array([to_raw[names[int(s)]] for s in cloud["semantic"]], np.uint32)
    real = tmp_path / "real"
    real.mkdir()
    np.column_stack([cloud["x"], cloud["y"], cloud["z"], cloud["intensity"]]).astype(np.float32).tofile(real / "000001.bin")
    (raw | (cloud["instance"].astype(np.uint32) << 16)).astype(np.uint32).tofile(real / "000001.label")
    out = tmp_path / "report.json"
    result = subprocess.run([sys.executable, "-m", "bpy_pipeline", "evaluate", "--train", str(data), "--max-frames", "1", "--test", str(real / "000001.bin"),
                             "--classes", "car,person", "--out", str(out), "--max-points-per-scan", "5000"], cwd=ROOT, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    assert "car" in result.stdout and "person" in result.stdout and "IoU" in result.stdout
    report = json.loads(out.read_text())
    assert report["train"] == ["street/000000"] and report["test"] == ["000001"]
    car = report["synthetic"]["classes"]["car"]
    assert car["objects"] > 0 and 0.0 <= car["interval"][0] <= car["iou"] <= car["interval"][1] <= 1.0
    assert car["iou"] > 0.1  # one coarse training frame of the same world: far above chance (a few cars; about 0.26 measured)
