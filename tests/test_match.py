"""``bpy-pipeline match``: object statistics of labelled real frames written as the builder's placement
distributions (bpy_pipeline/cli/match.py), and the ``histogram`` Distribution they use.

The contract "the matched run's histograms sit within 10 % of the real ones" is checked on the
placement distributions the matched config gives, sampled directly as the real_scan builder's
parking rule samples them (sample_count, sample): a full real-scan run places objects where they
fit (collision, ground and visibility checks), which benchmarks/bench_match.py measures over real
runs. Pure: no bpy."""

import numpy as np
import pytest
import yaml

from bpy_pipeline.cli.commands import main
from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.placement import Distribution, check_distribution, sample, sample_count
from bpy_pipeline.cli.match import DISTANCE_EDGES, HEADING_EDGES, heading_of, histogram

REAL = ["semantickitti_000700_points.npy", "semantickitti_seq01_000000_points.npy", "semantickitti_seq01_000001_points.npy",
        "semantickitti_seq01_000002_points.npy", "kitti_hdl64e_004747.bin"]


def total_variation(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return 0.5 * float(np.abs(a / a.sum() - b / b.sum()).sum())


def test_histogram_distribution_draws_its_weights_and_counts():
    rng = np.random.default_rng(0)
    d = Distribution("histogram", edges=[0.0, 5.0, 10.0, 20.0], weights=[1, 0, 3])
    values = sample(d, rng, 40_000)
    assert ((values >= 0) & (values < 20)).all() and not ((values >= 5) & (values < 10)).any()
    assert abs((values >= 10).mean() - 0.75) < 0.01
    counts = Distribution("histogram", edges=[0.0, 1.0, 2.0, 3.0], weights=[2, 0, 2])
    drawn = [sample_count(counts, rng) for _ in range(4000)]
    assert set(drawn) == {0, 2} and abs(np.mean(drawn) - 1.0) < 0.06
    same = [sample(d, np.random.default_rng(5)) for _ in range(2)]
    assert same[0] == same[1]
    for bad, key in ((Distribution("histogram", edges=[0.0, 0.0], weights=[1]), "d.edges"),
                     (Distribution("histogram", edges=[0.0, 1.0], weights=[1, 2]), "d.weights"),
                     (Distribution("histogram", edges=[0.0, 1.0], weights=[0]), "d.weights")):
        with pytest.raises(InputError, match=key):
            check_distribution(bad, "d")


def test_heading_is_the_long_axis_against_the_bearing():
    rng = np.random.default_rng(1)
    along = np.column_stack([rng.uniform(-2, 2, 200), rng.uniform(-0.8, 0.8, 200)])
    for bearing, yaw in ((0.0, 0.0), (90.0, 0.0), (45.0, 75.0), (-120.0, 10.0)):
        c, s = np.cos(np.radians(yaw)), np.sin(np.radians(yaw))
        centre = 20 * np.array([np.cos(np.radians(bearing)), np.sin(np.radians(bearing))])
        xy = along @ np.array([[c, s], [-s, c]]) + centre
        expected = (yaw - bearing + 90) % 180 - 90
        assert abs((heading_of(xy, centre) - expected + 90) % 180 - 90) < 3


@pytest.fixture(scope="module")
def matched(tmp_path_factory, real_scans_folder):
    paths = [real_scans_folder / name for name in REAL]
    if not all(p.exists() for p in paths):
        pytest.skip(f"real scans {', '.join(REAL)} are not all in {real_scans_folder} (set BPY_PIPELINE_REAL_SCANS to their folder)")
    folder = tmp_path_factory.mktemp("match")
    base = folder / "base.yaml"
    base.write_text(yaml.safe_dump({"frames": 4, "sensor": {"preset": "hdl64e"}, "output": {"formats": ["ply"]},
                                    "scene": {"builder": "real_scan", "path": str(paths[-1]), "parking_rule": {"enabled": True, "max_real_points": 7}}}))
    out, report = folder / "matched.yaml", folder / "stats.json"
    assert main(["match", *map(str, paths), "--config", str(base), "--out", str(out), "--report", str(report)]) == 0
    import json

    return load_config(str(out)), json.loads(report.read_text()), folder


def test_matched_placement_distributions_sit_within_10_percent_of_the_real_histograms(matched):
    config, report, _ = matched
    scene = config.scene.params
    rules = {r.type: r for r in [scene.parking_rule, *scene.parking_rules]}
    assert set(rules) == {"car", "person"} | ({"cyclist"} & set(rules))  # a cyclist only where the object type exists
    assert rules["car"].max_real_points == 7  # the base rule's other keys are kept
    rng = np.random.default_rng(2)
    for cls, kind in (("car", "car"), ("person", "person")):
        real, rule = report["classes"][cls], rules[kind]
        assert rule.enabled and rule.count.kind == rule.distance.kind == rule.heading.kind == "histogram"
        counts = np.array([sample_count(rule.count, rng) for _ in range(20_000)])
        assert abs(counts.mean() - real["mean_per_frame"]) <= 0.1 * real["mean_per_frame"], cls
        real_counts = np.bincount(real["count_per_frame"])
        assert total_variation(np.bincount(counts, minlength=len(real_counts))[: len(real_counts)], real_counts) <= 0.10
        assert counts.max() < len(real_counts)
        for key, edges in (("distance", DISTANCE_EDGES), ("heading", HEADING_EDGES)):
            drawn = sample(getattr(rule, key), rng, 20_000)
            tv = total_variation(histogram(drawn, edges)["weights"], real[key]["weights"])
            assert tv <= 0.10, (cls, key, tv)
    car = report["classes"]["car"]
    assert car["objects"] >= 10 and car["points_per_object"]["power_law"]["b"] > 0  # fewer points farther away


def test_match_refuses_what_it_cannot_match(matched, tmp_path, capsys, real_scans_folder):
    _, _, folder = matched
    street = tmp_path / "street.yaml"
    street.write_text("scene: {builder: street}\n")
    real = str(real_scans_folder / REAL[0])
    assert main(["match", real, "--config", str(street), "--out", str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err
    assert "scene.builder" in err and "real_scan" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "m.yaml").exists()
    assert main(["match", real, "--config", str(folder / "base.yaml"), "--out", str(tmp_path / "m.yaml"), "--classes", "car,banana"]) == 2
    assert "banana" in capsys.readouterr().err
    bad = yaml.safe_load((folder / "matched.yaml").read_text())
    bad["scene"]["parking_rule"]["distance"]["weights"] = [0] * len(bad["scene"]["parking_rule"]["distance"]["weights"])
    with pytest.raises(InputError, match="scene.parking_rule.distance.weights"):
        load_config(bad)


def test_parking_builder_gets_car_count_and_distance(tmp_path, real_scans_folder):
    paths = [real_scans_folder / name for name in REAL[:2]]
    if not all(p.exists() for p in paths):
        pytest.skip(f"real scans are absent from {real_scans_folder}")
    base = tmp_path / "parking.yaml"
    base.write_text("scene: {builder: parking}\n")
    assert main(["match", *map(str, paths), "--config", str(base), "--out", str(tmp_path / "m.yaml")]) == 0
    params = load_config(str(tmp_path / "m.yaml")).scene.params
    assert params.cars.kind == params.car_distance.kind == "histogram"
