"""The range-image network of ``evaluate`` (``--model rangenet``): projection and back-projection, two tiny frames
trained and scored as the LightGBM model is, same seed same predictions, remission-less scans left out, scores per
class only on the scans that label it, and the one-line refusal without torch."""

import sys

import numpy as np
import pytest

pytest.importorskip("scipy", reason="evaluate needs the evaluate extra (pip install '.[evaluate]')")

from bpy_pipeline.errors import InputError
from bpy_pipeline.evaluate import metrics, projection
from bpy_pipeline.evaluate.labelled import LabelledScan
from bpy_pipeline.evaluate.run import evaluate, fold_groups

CLASSES = ("car", "road")


def _frame(rng, name, group, car_at=(8.0, 2.0), remission=True, known=None):
    """A flat road ring pattern around the sensor (1.7 m below it) and a 4 x 1.8 x 1.5 m box car: road 1, car 0."""
    elevations = np.radians(np.linspace(-24.0, -2.0, 40))
    azimuths = np.radians(np.arange(-180, 180, 1.0))
    el, az = np.meshgrid(elevations, azimuths, indexing="ij")
    r = 1.7 / np.tan(-el)
    road = np.column_stack([r * np.cos(el) * np.cos(az) / np.cos(el), r * np.sin(az), np.full(r.shape, -1.7)]).reshape(-1, 3)
    road = road[np.hypot(road[:, 0], road[:, 1]) < 40]
    cx, cy = car_at
    side = rng.uniform([-2, -0.9, -1.7], [2, 0.9, -0.2], size=(1500, 3)) + (cx, cy, 0)
    points = np.concatenate([road, side]).astype(np.float32)
    labels = np.r_[np.ones(len(road), np.int64), np.zeros(len(side), np.int64)]
    instances = np.r_[np.full(len(road), -1), np.zeros(len(side), np.int64)]
    values = np.r_[np.full(len(road), 0.3), np.full(len(side), 0.7)].astype(np.float32) if remission else None
    return LabelledScan(name, group, points, labels, instances, CLASSES, None, name, remission=values, known=known)


def test_projection_puts_points_at_their_elevation_and_azimuth_and_back_projects():
    points = np.array([[10.0, 0.0, 0.0], [0.0, 10.0, 10 * np.tan(np.radians(-24.9))], [-10.0, 0.0, 0.5]], np.float32)
    row, column = projection.pixels(points)
    fov = projection.FOV_UP_DEG - projection.FOV_DOWN_DEG
    assert row[0] == int(3.0 / fov * 64) and column[0] == projection.WIDTH // 2  # straight ahead: the middle column
    assert row[1] == 63 and column[1] == projection.WIDTH // 4  # to the left (azimuth +90): a quarter of the way
    assert column[2] in (0, projection.WIDTH - 1)  # straight behind: the edge
    scan = LabelledScan("a", "a", np.vstack([points, points[:1] * 2]), [0, 1, 1, 1], [0, -1, -1, -1], CLASSES, remission=[0.1, 0.2, 0.3, 0.9])
    image = projection.project(scan)
    assert image.image.shape == (6, 64, projection.WIDTH)
    first = image.pixel[0]
    assert image.pixel[3] == first  # the far point shares the pixel ...
    flat = image.image.reshape(6, -1)
    assert flat[3, first] == pytest.approx(10.0) and flat[4, first] == pytest.approx(0.1) and image.labels.reshape(-1)[first] == 0  # ... the near one wins
    assert flat[5].sum() == 3  # three pixels hold a return
    assert projection.project(scan, remission=False).image[4].sum() == 0


def test_fold_groups_deal_groups_round_robin():
    assert fold_groups(["b", "a", "c", "a"]) == [["a"], ["b"], ["c"]]
    assert fold_groups(["a", "b", "c", "d", "e"], 2) == [["a", "c", "e"], ["b", "d"]]


def test_scores_count_a_class_only_on_the_scans_that_label_it():
    rng = np.random.default_rng(0)
    full = _frame(rng, "full", "f")
    boxes = _frame(rng, "boxes", "b", known=("car",))  # its "road" points are only "not car"
    pred_full = full.labels.copy()
    pred_boxes = np.zeros(len(boxes), np.int64)  # everything called car: road IoU of this scan must not count
    report = metrics.score([full, boxes], [pred_full, pred_boxes], CLASSES, draws=50)
    assert report["classes"]["road"]["iou"] == 1.0 and report["classes"]["road"]["scans"] == 1
    assert report["classes"]["car"]["scans"] == 2 and report["classes"]["car"]["iou"] < 0.5
    assert report["miou"] == pytest.approx((report["classes"]["car"]["iou"] + 1.0) / 2)


def test_rangenet_trains_on_two_tiny_frames_scores_like_lgbm_and_repeats_itself(monkeypatch):
    pytest.importorskip("torch", reason="--model rangenet needs torch (pip install '.[network]')")
    import bpy_pipeline.evaluate.rangenet as rangenet

    rng = np.random.default_rng(1)
    train = [_frame(rng, "t0", "t", (8.0, 2.0)), _frame(rng, "t1", "t", (-6.0, -4.0))]
    test = [_frame(rng, "real0", "r", (5.0, -3.0)), _frame(rng, "dark", "d", remission=False)]
    monkeypatch.setattr(rangenet, "MIN_STEPS", 15)
    monkeypatch.setattr(rangenet, "WIDTH", 128)  # a quarter of the columns: four times faster, the same code
    report = evaluate(train, test, CLASSES, reference=train, model="rangenet", draws=50)
    again = evaluate(train, test, CLASSES, reference=train, model="rangenet", draws=50)
    assert report["left_out"] == ["dark"] and report["test"] == ["real0"]  # it reads remission: the frame without it is left out
    assert report["features"] == list(projection.CHANNELS)
    car = report["synthetic"]["classes"]["car"]
    assert car["tp"] + car["fn"] == 1500  # back-projected: every point of the car is scored
    assert report["synthetic"]["classes"]["road"]["iou"] > 0.8 and car["iou"] > 0.3, report["synthetic"]["classes"]
    assert [f["test_group"] for f in report["real_reference"]["folds"]] == ["all (no test group among the reference groups)"]  # one training
    assert again["synthetic"]["classes"] == report["synthetic"]["classes"] and again["real_reference"]["miou"] == report["real_reference"]["miou"]


def test_rangenet_without_torch_is_one_line_naming_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "torch", None)  # import torch raises ImportError
    rng = np.random.default_rng(2)
    scans = [_frame(rng, "a", "a")]
    with pytest.raises(InputError, match=r"bpy_pipeline\[network\]"):
        evaluate(scans, scans, CLASSES, model="rangenet")


def test_rangenet_steps_are_the_given_ones_and_the_reference_trains_as_long_as_the_model(monkeypatch):
    pytest.importorskip("torch", reason="--model rangenet needs torch (pip install '.[network]')")
    import bpy_pipeline.evaluate.rangenet as rangenet

    rng = np.random.default_rng(3)
    two = [_frame(rng, "a0", "a"), _frame(rng, "b0", "b", (-6.0, -4.0))]
    monkeypatch.setattr(rangenet, "WIDTH", 64)
    logged = []
    model = rangenet.fit_rangenet(two, CLASSES, steps=3, log=logged.append)
    assert model.steps == 3 and [m.split(",")[0] for m in logged] == ["rangenet: step 1/3", "rangenet: step 3/3"]
    monkeypatch.setattr(rangenet, "MIN_STEPS", 2)
    monkeypatch.setattr(rangenet, "EPOCHS", 4)  # default: 4 passes over the --train frames in batches of 4
    train = [*two, _frame(rng, "c0", "c", (7.0, -5.0)), _frame(rng, "d0", "d", (-8.0, 3.0)), _frame(rng, "e0", "e", (9.0, 1.0))]
    report = evaluate(train, two, CLASSES, reference=two, model="rangenet", draws=10)
    assert report["steps"] == rangenet.default_steps(5) == 5  # ceil(4 * 5 / 4); the reference folds hold 1 frame each
    assert [f["steps"] for f in report["real_reference"]["folds"]] == [5, 5]
    given = evaluate(two, two, CLASSES, reference=two, model="rangenet", draws=10, steps=2)
    assert given["steps"] == 2 and [f["steps"] for f in given["real_reference"]["folds"]] == [2, 2]
    for bad, model in ((0, "rangenet"), (2.5, "rangenet"), (3, "lgbm")):
        with pytest.raises(InputError, match="--steps"):
            evaluate(two, two, CLASSES, model=model, steps=bad)
