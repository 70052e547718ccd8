"""``bpy-pipeline realism``: generated scans against real ones, per class. Built scans with known differences
(saturated intensity, persons with more points) must come out as the report's figures and its first findings;
the BEV JSD / MMD against hand computations; the command writes a JSON and a PNG; SqueezeSeg's labels map."""

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("scipy", reason="the realism report needs scipy (pip install '.[evaluate]')")

from bpy_pipeline.cli.commands import main
from bpy_pipeline.evaluate import realism
from bpy_pipeline.evaluate.labelled import LabelledScan, load_scans

CLASSES = ("car", "person", "road")


def _scan(rng, name, person_points, remission_of, person_at=(12.0, 3.0)):
    """A road disc, one car and one person (``person_points`` points) at ``person_at``; remission from ``remission_of(n)``."""
    road = np.column_stack([rng.uniform(-40, 40, (6000, 2)), np.full(6000, -1.7)])
    car = rng.uniform([-2, -0.9, -1.7], [2, 0.9, -0.2], (400, 3)) + (15.0, -4.0, 0)
    person = rng.uniform([-0.3, -0.3, -1.7], [0.3, 0.3, 0.05], (person_points, 3)) + (*person_at, 0)
    points = np.concatenate([road, car, person]).astype(np.float32)
    labels = np.r_[np.full(6000, 2), np.zeros(400, np.int64), np.ones(person_points, np.int64)]
    instances = np.r_[np.full(6000, -1), np.zeros(400, np.int64), np.ones(person_points, np.int64)]
    return LabelledScan(name, name, points, labels, instances, CLASSES, remission=remission_of(len(points)))


def test_the_report_shows_saturated_intensity_and_persons_with_too_many_points(tmp_path):
    rng = np.random.default_rng(0)
    generated = [_scan(rng, f"g{i}", 157, lambda n: np.ones(n, np.float32)) for i in range(3)]
    real = [_scan(rng, f"r{i}", 100, lambda n: rng.uniform(0.1, 0.6, n).astype(np.float32)) for i in range(3)]
    report = realism.realism_report(generated, real, CLASSES, plot=tmp_path / "realism.png")
    person = report["intensity"]["person"]
    assert person["generated"]["saturated"] == 1.0 and person["real"]["saturated"] == 0.0
    assert person["generated"]["distinct"] == 1 and person["wasserstein"] == pytest.approx(1.0 - 0.35, abs=0.03)
    assert report["points_per_object"]["person"]["ratio"] == pytest.approx(1.57, abs=0.01)  # 157 / 100 in the 10-20 m band
    assert report["points_per_object"]["car"]["ratio"] == pytest.approx(1.0)
    top = [f["what"] for f in report["findings"][:3]]
    assert set(top) == {"intensity car", "intensity person", "intensity road"}, top
    person_line = next(f["text"] for f in report["findings"] if f["what"] == "points per object person")
    assert "1.57x" in person_line and "more" in person_line
    assert (tmp_path / "realism.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert report["bev"]["jsd"] < 0.05  # the same layout on both sides


def test_bev_jsd_and_mmd_against_hand_computations():
    p, q = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    assert realism.jsd(p, q) == pytest.approx(1.0) and realism.jsd(p, p) == 0.0
    a = np.array([[1.0, 0.0], [1.0, 0.0]])
    b = np.array([[0.0, 2.0]])
    k = np.exp(-2.0 / (2 * realism.MMD_SIGMA**2))  # |(1, 0) - (0, 1)|^2 = 2
    assert realism.mmd(a, b) == pytest.approx(1 + 1 - 2 * k)
    assert realism.mmd(a, a) == pytest.approx(0.0, abs=1e-12)


def test_the_command_prints_the_findings_and_writes_json_and_png(tmp_path, capsys):
    rng = np.random.default_rng(1)
    folder = tmp_path / "real"
    folder.mkdir()
    for name, person in (("gen", 150), ("real", 100)):
        scan = _scan(rng, name, person, lambda n: rng.uniform(0, 1, n).astype(np.float32))
        truth = np.array([1, 6, 9])[scan.labels]  # car, person, road as SemanticKITTI training ids
        np.save(folder / f"{name}_points.npy", np.column_stack([scan.points, scan.remission]))
        np.save(folder / f"{name}_labels.npy", truth)
    code = main(["realism", "--generated", str(folder / "gen_points.npy"), "--real", str(folder / "real_points.npy"),
                 "--classes", "car,person,road", "--out", str(tmp_path / "r.json")])
    out = capsys.readouterr().out
    assert code == 0 and "What differs most" in out and (tmp_path / "r.png").is_file()
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["classes"] == ["car", "person", "road"] and len(report["returns_per_row"]["real"]) == 64


def test_squeezeseg_labels_map_to_car_person_bicyclist_and_count_for_those_only(tmp_path):
    points = np.array([[5, 0, -1, 0.2], [6, 0, -1, 0.3], [7, 0, -1, 0.4], [8, 0, -1, 0.5]], np.float32)
    np.save(tmp_path / "squeezeseg_drive_0000000010_points.npy", points)
    np.save(tmp_path / "squeezeseg_drive_0000000010_labels.npy", np.array([0, 1, 2, 3], np.int32))
    (scan,) = load_scans([tmp_path / "squeezeseg_drive_0000000010_points.npy"], ("car", "person", "road"))
    assert scan.labels.tolist() == [3, 0, 1, -1]  # background is "other", the cyclist (not requested) ignored
    assert scan.known == ("car", "person") and not scan.knows("road")
    assert scan.remission.tolist() == pytest.approx([0.2, 0.3, 0.4, 0.5])


def test_real_scans_read_with_remission_where_they_carry_it():
    real = Path(__file__).resolve().parents[2] / "shared" / "real_scans"
    if not (real / "semantickitti_seq08_000720.bin").is_file():
        pytest.skip(f"the real scans are not at {real}")
    scans = load_scans([real / "semantickitti_seq08_000720.bin", real / "semantickitti_000700_points.npy", real / "kitti_hdl64e_004747.bin"],
                       realism.DEFAULT_CLASSES)
    assert [s.remission is not None for s in scans] == [True, False, True]
    assert scans[2].known == ("car", "person", "bicyclist") and scans[0].known is None


def test_a_missing_input_is_one_line_and_exit_2(tmp_path, capsys):
    code = main(["realism", "--generated", str(tmp_path / "nothing"), "--real", str(tmp_path / "nothing"), "--out", str(tmp_path / "r.json")])
    err = capsys.readouterr().err
    assert code == 2 and "nothing: no such file or folder" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r.json").exists() and not (tmp_path / "r.png").exists()


def test_per_class_figures_read_the_field_every_real_source_labels():
    """A generated car beside the sensor (where KITTI's box-labelled frames label nothing) moves no per-class figure;
    the same car ahead does."""
    rng = np.random.default_rng(1)
    real = [_scan(rng, f"r{i}", 100, lambda n: rng.uniform(0.1, 0.6, n).astype(np.float32)) for i in range(3)]

    def with_car_at(scan, where):
        car = rng.uniform([-2, -0.9, -1.7], [2, 0.9, -0.2], (400, 3)).astype(np.float32) + np.array([*where, 0], np.float32)
        return LabelledScan(scan.name, scan.group, np.concatenate([scan.points, car]), np.r_[scan.labels, np.zeros(400, np.int64)],
                            np.r_[scan.instances, np.full(400, 7)], CLASSES, remission=np.r_[scan.remission, np.full(400, 0.3, np.float32)])

    beside = [with_car_at(s, (0.0, -4.0)) for s in real]
    ahead = [with_car_at(s, (5.0, -1.0)) for s in real]
    same = realism.realism_report(beside, real, CLASSES)
    assert same["range_wasserstein_m"]["car"] == pytest.approx(0.0, abs=1e-9)
    assert same["points_per_object"]["car"]["generated_objects"] == same["points_per_object"]["car"]["real_objects"]
    moved = realism.realism_report(ahead, real, CLASSES)
    assert moved["range_wasserstein_m"]["car"] > 1.0
    assert moved["points_per_object"]["car"]["generated_objects"] > moved["points_per_object"]["car"]["real_objects"]
