"""Sensor effects: drop rates against binomial intervals, noise sigma, intensity physics,
per-ring bias, angular jitter, determinism, config errors. Pure: no bpy."""

import math

import numpy as np
import pytest

from bpy_pipeline.config import effects_from_dict
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.effects.apply import (
    CHUNK_POINTS,
    BinnedTable,
    FittedModels,
    ThresholdModel,
    apply_effects,
    carla_intensity,
    compute_intensity,
    drop_probability,
    lidar_intensity,
    write_model_file,
)
from bpy_pipeline.lidar.points import BEAM_DTYPE, empty_points
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor

Z = 4.0  # binomial intervals at 4 sigma: a correct model fails one check in ~16,000


def cloud(n, rng, range_m=None, reflectivity=0.5, cos=1.0, rings=1):
    """n points in random directions (sensor frame) with their beam facts."""
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(1.0, 80.0, n) if range_m is None else np.broadcast_to(np.asarray(range_m, float), (n,))
    points = empty_points(n)
    points["x"], points["y"], points["z"] = (d * r[:, None]).T
    points["range"] = r
    points["ring"] = np.arange(n) % rings
    points["instance"] = np.arange(n)
    beam = np.zeros(n, BEAM_DTYPE)
    beam["cos_incidence"], beam["reflectivity"], beam["gain"] = cos, reflectivity, 1.0
    beam["direction"] = d
    return points, beam


def effects(**sections):
    return effects_from_dict(sections)


def within_binomial(kept: int, n: int, p_keep: float) -> bool:
    return abs(kept - n * p_keep) <= Z * math.sqrt(n * p_keep * (1 - p_keep)) + 1


def survivors(points, beam, eff, seed=0):
    out = apply_effects(points, beam, eff, np.random.default_rng(seed))
    kept = np.zeros(len(points), bool)
    kept[out["instance"]] = True
    return out, kept


# ----------------------------------------------------------------------------- drop rates
@pytest.mark.parametrize("probability", [0.003, 0.05, 0.5])  # 0.3 %: the parking paper's largest
def test_uniform_drop_rate_lies_within_a_binomial_interval(probability):
    points, beam = cloud(400_000, np.random.default_rng(1))
    out, _ = survivors(points, beam, effects(drop={"model": "uniform", "probability": probability}))
    assert within_binomial(len(out), len(points), 1 - probability)


def test_carla_drop_follows_carlas_formula_per_range():
    """General rate g before the trace, then keep above the intensity limit, else with
    probability (p0 / limit) I + 1 - p0, I = exp(-a R)."""
    g, limit, p0, a = 0.45, 0.8, 0.4, 0.004
    ranges = np.array([5.0, 40.0, 80.0, 150.0, 400.0])  # I = 0.98, 0.85 (above the limit), 0.73, 0.55, 0.20
    n = 100_000
    points, beam = cloud(n * len(ranges), np.random.default_rng(2), np.repeat(ranges, n))
    eff = effects(drop={"model": "carla", "carla": {"general_rate": g, "intensity_limit": limit, "zero_intensity": p0, "attenuation_rate": a}})
    _, kept = survivors(points, beam, eff)
    for k, r in enumerate(ranges):
        intensity = math.exp(-a * r)
        p_keep = (1 - g) * (1.0 if intensity > limit else p0 / limit * intensity + 1 - p0)
        assert within_binomial(int(kept[k * n : (k + 1) * n].sum()), n, p_keep), r
    expected = 1 - (1 - g) * np.where(np.exp(-a * points["range"]) > limit, 1.0, p0 / limit * np.exp(-a * points["range"]) + 1 - p0)
    np.testing.assert_allclose(drop_probability(points, beam, eff), expected, rtol=1e-5)


def test_carla_with_no_intensity_drop_keeps_the_general_rate_only():
    points, beam = cloud(200_000, np.random.default_rng(3))
    eff = effects(drop={"model": "carla", "carla": {"general_rate": 0.1, "zero_intensity": 0.0}})
    out, _ = survivors(points, beam, eff)
    assert within_binomial(len(out), len(points), 0.9)


def test_threshold_model_from_an_ouster_datasheet():
    """OS1: 40 m at 10 %, 120 m at 80 %: the exponent that puts both on the threshold."""
    model = ThresholdModel.from_datasheet(40.0, 120.0)
    assert model.exponent == pytest.approx(math.log(8) / math.log(3))
    assert model.range_at(0.1) == pytest.approx(40.0, rel=1e-9)
    assert model.range_at(0.8) == pytest.approx(120.0, rel=1e-9)
    one = ThresholdModel.from_datasheet(10.0)  # the sparse 3D camera: 10 m at 10 %, lidar equation R^2
    assert one.exponent == 2.0 and one.range_at(0.8) == pytest.approx(10.0 * math.sqrt(8.0))
    hazy = ThresholdModel.from_datasheet(40.0, 120.0, alpha=0.001)
    assert hazy.range_at(0.1) == pytest.approx(40.0, rel=1e-9) and hazy.range_at(0.8) == pytest.approx(120.0, rel=1e-9)


def test_hard_threshold_drops_dark_objects_nearer_than_bright_ones():
    ranges = np.array([39.0, 41.0, 119.0, 121.0])
    reflect = np.array([0.1, 0.1, 0.8, 0.8])
    points, beam = cloud(4, np.random.default_rng(4), ranges, reflectivity=reflect)
    out, kept = survivors(points, beam, effects(drop={"model": "threshold", "threshold": {"range_at_10": 40, "range_at_80": 120, "softness": 0}}))
    assert kept.tolist() == [True, False, True, False]
    beam["cos_incidence"] = 0.5  # half the power: a grazing dark target is lost at 39 m too
    _, kept = survivors(points, beam, effects(drop={"model": "threshold", "threshold": {"range_at_10": 40, "range_at_80": 120, "softness": 0}}))
    assert kept.tolist() == [False, False, False, False]


def test_soft_threshold_detection_rate_within_a_binomial_interval():
    n = 100_000
    eff = effects(drop={"model": "threshold", "threshold": {"range_at_10": 40, "range_at_80": 120, "softness": 0.3}})
    model = ThresholdModel.from_datasheet(40, 120, 0.3)
    for r, rho in [(40.0, 0.1), (30.0, 0.1), (60.0, 0.1), (100.0, 0.8)]:
        points, beam = cloud(n, np.random.default_rng(5), r, reflectivity=rho)
        out, _ = survivors(points, beam, eff)
        z = (math.log(rho / r**model.exponent) - math.log(model.sensitivity)) / 0.3
        assert within_binomial(len(out), n, 1 / (1 + math.exp(-z))), (r, rho)
    points, beam = cloud(n, np.random.default_rng(5), 40.0, reflectivity=0.1)
    assert within_binomial(len(survivors(points, beam, eff)[0]), n, 0.5)  # the datasheet range is the 50 % point


def test_table_drop_rate_per_bin_within_a_binomial_interval(tmp_path):
    table = BinnedTable([2.0, 10.0, 50.0], [0.0, 45.0, 90.0], [[0.01, 0.05], [0.2, np.nan]], [[500, 500], [500, 3]])
    path = tmp_path / "model.yaml"
    write_model_file(path, FittedModels(drop_table=table))
    eff = effects(drop={"model": "table", "model_file": str(path)})
    n = 100_000
    # bin centres: (6 m, 22.5 deg) -> 0.01, (6 m, 67.5 deg) -> 0.05, (30 m, 22.5 deg) -> 0.2, and the
    # discarded bin (30 m, 67.5 deg) takes the mean of its measured neighbours: (0.05 + 0.2) / 2
    for r, angle, p in [(6.0, 22.5, 0.01), (6.0, 67.5, 0.05), (30.0, 22.5, 0.2), (30.0, 67.5, 0.125), (18.0, 22.5, 0.105)]:
        points, beam = cloud(n, np.random.default_rng(6), r, cos=math.cos(math.radians(angle)))
        assert drop_probability(points, beam, eff)[0] == pytest.approx(p, abs=2e-3)
        assert within_binomial(len(survivors(points, beam, eff)[0]), n, 1 - p), (r, angle)


def test_table_lookup_follows_the_exact_bilinear_surface():
    rng = np.random.default_rng(7)
    table = BinnedTable(np.geomspace(2, 100, 9), np.linspace(0, 90, 5), rng.uniform(0, 0.3, (8, 4)), np.full((8, 4), 200))
    r, angle = rng.uniform(1, 120, 50_000), rng.uniform(0, 90, 50_000)
    fast = table.lookup(r, np.cos(np.radians(angle)))
    exact = table.bilinear(r, angle)
    rc = 0.5 * (table.range_edges[:-1] + table.range_edges[1:])
    per_m = np.abs(np.diff(table.values, axis=0) / np.diff(rc)[:, None]).max()
    per_deg = np.abs(np.diff(table.values, axis=1)).max() / 22.5
    half_node = 0.5 * (rc[-1] - rc[0]) / (BinnedTable.RASTER[0] - 1), 0.5 * 90 / (BinnedTable.RASTER[1] - 1)
    assert np.abs(fast - exact).max() <= per_m * half_node[0] + per_deg * half_node[1] + 1e-5
    assert np.abs(fast - exact).mean() < 0.25 * (per_m * half_node[0] + per_deg * half_node[1])


def test_no_drop_model_keeps_every_point_and_changes_nothing_else():
    points, beam = cloud(1000, np.random.default_rng(8), reflectivity=0.3, cos=0.5)
    out = apply_effects(points, beam, effects(), np.random.default_rng(0))
    for name in ("x", "y", "z", "range", "ring", "time", "semantic", "instance", "bounces"):
        assert (out[name] == points[name]).all()
    np.testing.assert_allclose(out["intensity"], 0.15, rtol=1e-6)  # reflectance: rho cos


# ----------------------------------------------------------------------------- noise
def test_range_noise_sigma_within_five_percent_on_a_large_sample():
    points, beam = cloud(200_000, np.random.default_rng(9), range_m=20.0)
    out = apply_effects(points, beam, effects(noise={"sigma": 0.02}), np.random.default_rng(1))
    error = out["range"].astype(float) - 20.0
    assert np.std(error) == pytest.approx(0.02, rel=0.05) and abs(np.mean(error)) < 5 * 0.02 / math.sqrt(len(error))
    radial = np.sqrt(out["x"].astype(float) ** 2 + out["y"] ** 2 + out["z"] ** 2)
    np.testing.assert_allclose(radial, out["range"], rtol=1e-5, atol=1e-5)  # the point moved along its beam
    direction_before = np.column_stack([points["x"], points["y"], points["z"]]) / 20.0
    direction_after = np.column_stack([out["x"], out["y"], out["z"]]) / radial[:, None]
    assert np.abs(direction_after - direction_before).max() < 1e-5


def test_railway_thesis_accuracy_two_millimetres():
    points, beam = cloud(200_000, np.random.default_rng(10), range_m=5.0)
    out = apply_effects(points, beam, effects(noise={"sigma": 0.002}), np.random.default_rng(2))
    assert np.std(out["range"].astype(float) - 5.0) == pytest.approx(0.002, rel=0.05)


def test_range_noise_grows_with_range():
    eff = effects(noise={"model": "range", "sigma": 0.005, "sigma_per_metre": 0.001})
    for r in (5.0, 50.0):
        points, beam = cloud(200_000, np.random.default_rng(11), range_m=r)
        out = apply_effects(points, beam, eff, np.random.default_rng(3))
        assert np.std(out["range"].astype(float) - r) == pytest.approx(0.005 + 0.001 * r, rel=0.05)


def test_noise_table_sigma_per_bin(tmp_path):
    table = BinnedTable([0.0, 20.0, 40.0], [0.0, 90.0], [[0.01], [0.04]], [[1000], [1000]])
    path = tmp_path / "noise.yaml"
    write_model_file(path, FittedModels(noise_table=table))
    eff = effects(noise={"model": "table", "model_file": str(path)})
    for r, sigma in [(10.0, 0.01), (30.0, 0.04), (20.0, 0.025)]:
        points, beam = cloud(200_000, np.random.default_rng(12), range_m=r)
        out = apply_effects(points, beam, eff, np.random.default_rng(4))
        assert np.std(out["range"].astype(float) - r) == pytest.approx(sigma, rel=0.05)


def test_per_ring_bias_shifts_each_ring_by_its_value():
    bias = [0.0, 0.05, -0.02, 0.1]
    points, beam = cloud(40_000, np.random.default_rng(13), range_m=10.0, rings=4)
    out = apply_effects(points, beam, effects(noise={"sigma": 0.001, "ring_bias": bias}), np.random.default_rng(5))
    for ring, b in enumerate(bias):
        shift = out["range"][out["ring"] == ring].astype(float) - 10.0
        assert np.mean(shift) == pytest.approx(b, abs=4 * 0.001 / math.sqrt(len(shift)) + 1e-6)
    with pytest.raises(InputError, match="ring_bias"):
        apply_effects(points, beam, effects(noise={"ring_bias": [0.0, 0.1]}), np.random.default_rng(5))


def test_angular_jitter_turns_points_by_its_sigma_keeping_their_range():
    rng = np.random.default_rng(14)
    n = 200_000
    azimuth, elevation = rng.uniform(-np.pi, np.pi, n), rng.uniform(-0.5, 0.5, n)
    points, beam = cloud(n, rng, range_m=30.0)
    d = np.column_stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)]) * 30.0
    points["x"], points["y"], points["z"] = d.T
    out = apply_effects(points, beam, effects(noise={"angular_jitter_deg": 0.1}), np.random.default_rng(6))
    new_az = np.arctan2(out["y"].astype(float), out["x"])
    new_el = np.arctan2(out["z"].astype(float), np.hypot(out["x"], out["y"]))
    d_az = (np.angle(np.exp(1j * (new_az - azimuth))) * np.cos(elevation))  # arc length on the sphere
    assert np.degrees(np.std(d_az)) == pytest.approx(0.1, rel=0.05)
    assert np.degrees(np.std(new_el - elevation)) == pytest.approx(0.1, rel=0.05)
    np.testing.assert_allclose(out["range"], 30.0)
    np.testing.assert_allclose(np.sqrt(out["x"].astype(float) ** 2 + out["y"] ** 2 + out["z"] ** 2), 30.0, rtol=1e-5)


# ----------------------------------------------------------------------------- determinism
ALL = {
    "intensity": {"model": "lidar", "alpha": 0.001},
    "drop": {"model": "carla"},
    "noise": {"model": "range", "sigma": 0.01, "sigma_per_metre": 0.001, "angular_jitter_deg": 0.05},
}


def test_same_seed_same_bytes_another_seed_differs():
    points, beam = cloud(50_000, np.random.default_rng(15), rings=1)
    eff = effects(**ALL)
    first = apply_effects(points, beam, eff, np.random.default_rng(42)).tobytes()
    assert apply_effects(points, beam, eff, np.random.default_rng(42)).tobytes() == first
    assert apply_effects(points, beam, eff, np.random.default_rng(43)).tobytes() != first
    before = points.tobytes()
    apply_effects(points, beam, eff, np.random.default_rng(42))
    assert points.tobytes() == before  # the input records are left alone


def test_bytes_do_not_depend_on_the_threads():
    points, beam = cloud(3 * CHUNK_POINTS + 123, np.random.default_rng(19))
    eff = effects(**ALL)
    one = apply_effects(points, beam, eff, np.random.default_rng(7), threads=1)
    assert apply_effects(points, beam, eff, np.random.default_rng(7), threads=3).tobytes() == one.tobytes()
    assert 0.4 * len(points) < len(one) < 0.7 * len(points)  # CARLA's drop ran on every chunk


def test_empty_scan_passes_through():
    points, beam = cloud(0, np.random.default_rng(16))
    assert len(apply_effects(points, beam, effects(**ALL), np.random.default_rng(0))) == 0


# ----------------------------------------------------------------------------- intensity
def test_lidar_intensity_falls_with_range_and_incidence_as_the_equation_says():
    alpha, ref = 0.002, 10.0
    ranges = np.array([10.0, 20.0, 40.0, 80.0])
    _, beam = cloud(4, np.random.default_rng(17), reflectivity=1.0)
    i = lidar_intensity(ranges, beam, alpha, ref)
    assert i[0] == pytest.approx(1.0)  # the reference target at the reference range
    for k in range(1, 4):  # doubling the range: a quarter of the power, times the extra two-way extinction
        assert i[k] / i[k - 1] == pytest.approx(0.25 * math.exp(-2 * alpha * (ranges[k] - ranges[k - 1])), rel=1e-5)
    beam["cos_incidence"] = [1.0, 0.5, 0.25, 0.0]
    i = lidar_intensity(np.full(4, 20.0), beam, 0.0, ref)
    np.testing.assert_allclose(i, 0.25 * np.array([1.0, 0.5, 0.25, 0.0]), rtol=1e-6)  # Lambertian: cos
    beam["cos_incidence"], beam["reflectivity"], beam["gain"] = 1.0, [0.1, 0.5, 0.9, 0.9], [1.0, 1.0, 1.0, 0.5]
    i = lidar_intensity(np.full(4, 20.0), beam, 0.0, ref)
    np.testing.assert_allclose(i, 0.25 * np.array([0.1, 0.5, 0.9, 0.45]), rtol=1e-6)  # reflectivity, mirror loss
    assert lidar_intensity(np.array([1.0]), beam[:1], 0.0, ref)[0] == 1.0  # saturates near the sensor


def test_intensity_models_chosen_in_the_config():
    points, beam = cloud(3, np.random.default_rng(18), np.array([5.0, 50.0, 100.0]), reflectivity=0.8, cos=0.5)
    lidar = compute_intensity(points["range"], beam, effects(intensity={"model": "lidar", "reference_range": 5.0}).intensity)
    np.testing.assert_allclose(lidar, 0.4 * np.array([1.0, 0.01, 0.0025]), rtol=1e-5)
    carla = compute_intensity(points["range"], beam, effects(intensity={"model": "carla"}).intensity)
    np.testing.assert_allclose(carla, np.exp(-0.004 * np.array([5.0, 50.0, 100.0])), rtol=1e-6)
    np.testing.assert_allclose(carla_intensity(np.array([250.0]), 0.004), math.exp(-1.0), rtol=1e-6)
    plain = apply_effects(points, beam, effects(), np.random.default_rng(0))["intensity"]
    np.testing.assert_allclose(plain, 0.4, rtol=1e-6)


# ----------------------------------------------------------------------------- config
def test_config_keys_and_errors(tmp_path):
    defaults = effects()
    assert defaults.drop.model == "none" and defaults.noise.sigma == 0.0 and defaults.intensity.model == "reflectance"
    with pytest.raises(InputError, match=r"^effects\.drop\.model: unknown drop model 'gaussian'; allowed: none, uniform"):
        effects(drop={"model": "gaussian"})
    with pytest.raises(InputError, match=r"^effects\.drop\.probability: must lie in 0\.\.1"):
        effects(drop={"model": "uniform", "probability": 1.5})
    with pytest.raises(InputError, match=r"^effects\.drop\.model_file: the table drop model needs a model file"):
        effects(drop={"model": "table"})
    with pytest.raises(InputError, match=r"^effects\.drop\.model_file: cannot read"):
        effects(drop={"model": "table", "model_file": str(tmp_path / "absent.yaml")})
    (tmp_path / "bad.yaml").write_text("format: something else\n")
    with pytest.raises(InputError, match=r"^effects\.noise\.model_file .*bad\.yaml: not a model file"):
        effects(noise={"model": "range", "model_file": str(tmp_path / "bad.yaml")})
    with pytest.raises(InputError, match=r"^effects\.drop\.threshold\.range_at_80: must exceed"):
        effects(drop={"model": "threshold", "threshold": {"range_at_10": 40, "range_at_80": 30}})
    with pytest.raises(InputError, match=r"^effects\.noise\.angular_jitter_deg: must be >= 0"):
        effects(noise={"angular_jitter_deg": -1})
    with pytest.raises(InputError, match=r"^effects\.intensity\.reference_range: must be > 0"):
        effects(intensity={"model": "lidar", "reference_range": 0})
    write_model_file(tmp_path / "drop_only.yaml", FittedModels(uniform=0.1))
    with pytest.raises(InputError, match=r"^effects\.noise\.model_file: .* holds no table noise model"):
        effects(noise={"model": "table", "model_file": str(tmp_path / "drop_only.yaml")})
    with pytest.raises(InputError, match=r"^effects\.drop\.probability: give either inline parameters"):
        effects(drop={"model": "uniform", "probability": 0.003, "model_file": str(tmp_path / "drop_only.yaml")})
    fitted = effects(drop={"model": "uniform", "model_file": str(tmp_path / "drop_only.yaml")})
    points, beam = cloud(10, np.random.default_rng(0))
    np.testing.assert_allclose(drop_probability(points, beam, fitted), 0.1)  # the file's probability


def test_ring_bias_must_match_the_sensor_rings():
    hdl32e = resolve_sensor({"preset": "hdl32e"})
    assert len(effects_from_dict({"noise": {"ring_bias": [0.01] * 32}}, hdl32e).noise.ring_bias) == 32
    with pytest.raises(InputError, match=r"^effects\.noise\.ring_bias: one value per ring \(32"):
        effects_from_dict({"noise": {"ring_bias": [0.0, 0.01]}}, hdl32e)
