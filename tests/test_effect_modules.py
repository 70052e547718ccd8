"""The effect modules one by one: the effect interface (lidar/effects/base.py), the fitted-model files (models.py),
range noise (noise.py), ray drop (ray_drop.py and each drop model of drop/), and each weather module (weather/kind.py,
particles.py, fog.py, rain.py, snow.py) against its closed form."""

import math

import numpy as np
import pytest

from bpy_pipeline.config import effects_from_dict
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.effects import base, models, noise, ray_drop
from bpy_pipeline.lidar.effects.apply import apply_effects
from bpy_pipeline.lidar.effects.drop import DROP_MODELS, DropModel, carla, none, table, uniform  # noqa: F401  (each model's module)
from bpy_pipeline.lidar.effects.drop import base as drop_base
from bpy_pipeline.lidar.effects.weather import WEATHER_KINDS, WeatherConfig, fog, kind, particles, rain, snow
from bpy_pipeline.lidar.points import BEAM_DTYPE, empty_points
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
from bpy_pipeline.schema import check_ranges

Z = 4.0  # binomial and normal intervals at 4 sigma


def cloud(n, seed=0, range_m=None, reflectivity=0.5, rings=1):
    """n points in random directions (sensor frame) at ``range_m`` (default 1..80 m), and their beam facts."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(1.0, 80.0, n) if range_m is None else np.full(n, float(range_m))
    points = empty_points(n)
    points["x"], points["y"], points["z"] = (d * r[:, None]).T
    points["range"], points["ring"] = r, np.arange(n) % rings
    beam = np.zeros(n, BEAM_DTYPE)
    beam["cos_incidence"], beam["reflectivity"], beam["gain"], beam["direction"] = 1.0, reflectivity, 1.0, d
    return points, beam


def a_table(values=((0.1, 0.2), (0.3, np.nan))):
    values = np.array(values, float)
    return models.BinnedTable(np.array([0.0, 10.0, 20.0]), np.array([0.0, 45.0, 90.0]), values, np.where(np.isnan(values), 0, 50))


# ----------------------------------------------------------------------------- base: the effect interface
def test_effects_run_in_their_order_and_a_name_registers_once():
    assert [e.name for e in base.ordered_effects()] == ["materials", "intensity", "drop", "weather", "noise"]
    assert all(e.section and e.config is not None for e in base.ordered_effects())
    with pytest.raises(ValueError, match="noise"):
        base.register_effect(noise.Noise())


def test_chunk_copies_the_callers_records_once_and_keeps_rows_of_everything():
    points, beam = cloud(6)
    original = points.copy()
    chunk = base.Chunk(points, beam, None, {}, detection=np.arange(6, dtype=np.float32))
    chunk.intensity = np.linspace(0, 1, 6, dtype=np.float32)
    chunk.keep(np.array([True, False, True, False, True, True]))
    assert points.tobytes() == original.tobytes()  # the caller's records are never written
    assert len(chunk.points) == len(chunk.beam) == len(chunk.intensity) == 4 and list(chunk.detection) == [0, 2, 4, 5]
    records = chunk.records
    assert np.allclose(records["intensity"], np.linspace(0, 1, 6)[[0, 2, 4, 5]]) and chunk.intensity is None
    assert np.array_equal(records["range"], original["range"][[0, 2, 4, 5]])
    chunk.keep(None)
    assert chunk.records is records


def test_a_toy_effect_runs_at_its_order_and_draws_after_those_before_it():
    class Halve(base.Effect):
        name, section, order = "halve_range", "noise", 60

        def apply(self, chunk, rng):
            chunk.records["range"] *= np.float32(0.5)

    points, beam = cloud(100)
    eff = effects_from_dict({"noise": {"sigma": 0.01}})
    before = apply_effects(points, beam, eff, np.random.default_rng(3))
    base.register_effect(Halve())
    try:
        after = apply_effects(points, beam, eff, np.random.default_rng(3))
    finally:
        base.EFFECTS.unregister("halve_range")
    assert np.array_equal(after["range"], before["range"] * np.float32(0.5))


# ----------------------------------------------------------------------------- models: fitted model files
def test_binned_table_is_exact_at_bin_centres_and_fills_empty_bins_from_neighbours():
    t = a_table()
    assert np.allclose(t.bilinear(np.array([5.0, 15.0, 5.0]), np.array([22.5, 22.5, 67.5])), [0.1, 0.3, 0.2])
    assert math.isclose(t.filled[1, 1], (0.2 + 0.3) / 2)
    assert math.isclose(t.bilinear(np.array([10.0]), np.array([22.5]))[0], 0.2)  # halfway between 0.1 and 0.3
    r, inc = np.array([3.0, 12.0, 17.0]), np.array([10.0, 40.0, 80.0])
    assert np.allclose(t.lookup(r, np.cos(np.radians(inc))), t.bilinear(r, inc), atol=0.01)


def test_binned_table_check_names_what_is_malformed():
    with pytest.raises(InputError, match="^w.range_edges: need at least 2 increasing"):
        models.BinnedTable(np.array([5.0, 1.0, 2.0]), np.array([0.0, 45.0, 90.0]), np.zeros((2, 2)), np.zeros((2, 2))).check("w")
    with pytest.raises(InputError, match="^w: every bin is empty"):
        a_table(np.full((2, 2), np.nan)).check("w")


def test_model_file_round_trips_and_check_model_file_names_each_mistake(tmp_path):
    path = tmp_path / "m.yaml"
    models.write_model_file(path, models.FittedModels(uniform=0.25, drop_table=a_table(), noise_range=(0.01, 0.002)))
    back = models.read_model_file(path)
    assert back.uniform == 0.25 and back.noise_range == (0.01, 0.002) and back.threshold is None
    assert np.allclose(back.drop_table.filled, a_table().filled)
    drop = effects_from_dict({"drop": {"model": "table", "model_file": str(path)}}).drop
    models.check_model_file("drop", drop, {"table": ("drop_table", False, "")})
    with pytest.raises(InputError, match="^effects.drop.model_file: .* holds no table drop model"):
        models.check_model_file("drop", drop, {"table": ("threshold", False, "")})
    with pytest.raises(InputError, match="^effects.drop.probability: give either inline parameters"):
        models.check_model_file("drop", drop, {"table": ("drop_table", True, "probability")})
    with pytest.raises(InputError, match="^effects.noise.model_file: the mlp noise model needs a model file"):
        models.check_model_file("noise", noise.NoiseConfig(model="mlp"), {})


# ----------------------------------------------------------------------------- noise
def test_constant_noise_moves_each_point_along_its_beam_by_sigma():
    points, beam = cloud(20000, range_m=30.0)
    moved = points.copy()
    noise.perturb(moved, beam, noise.NoiseConfig(sigma=0.05), np.random.default_rng(1))
    step = moved["range"].astype(float) - 30.0
    assert abs(step.std() - 0.05) < Z * 0.05 / math.sqrt(2 * 20000) and abs(step.mean()) < Z * 0.05 / math.sqrt(20000)
    xyz = np.stack([moved[k] for k in "xyz"], axis=1).astype(float)
    assert np.allclose(xyz, beam["direction"] * moved["range"][:, None], atol=1e-4)


def test_ring_bias_adds_its_ring_value_and_names_a_short_list():
    points, beam = cloud(8, range_m=10.0, rings=4)
    noise.perturb(points, beam, noise.NoiseConfig(ring_bias=[0.0, 0.1, 0.2, 0.3]), np.random.default_rng(0))
    assert np.allclose(points["range"], 10.0 + 0.1 * (np.arange(8) % 4), atol=1e-6)
    with pytest.raises(InputError, match="^effects.noise.ring_bias: 2 values but the scan has ring 3"):
        noise.perturb(points, beam, noise.NoiseConfig(ring_bias=[0.0, 0.1]), np.random.default_rng(0))


def test_range_noise_sigma_grows_with_range_and_the_check_counts_rings():
    points, beam = cloud(3)
    sigma = noise.noise_sigma(points, beam, noise.NoiseConfig(model="range", sigma=0.01, sigma_per_metre=0.001))
    assert np.allclose(sigma, 0.01 + 0.001 * points["range"])
    with pytest.raises(InputError, match=r"^effects.noise.ring_bias: one value per ring \(16 for this sensor\), got 2"):
        noise.Noise().check(effects_from_dict({"noise": {"ring_bias": [0.0, 0.1]}}), resolve_sensor({"preset": "vlp16"}))


# ----------------------------------------------------------------------------- ray drop and the drop models
def test_drop_models_are_registered_once_and_none_drops_nothing():
    assert set(DROP_MODELS.names()) >= {"none", "uniform", "carla", "threshold", "table", "mlp"}
    with pytest.raises(ValueError):
        drop_base.register_drop_model("none", DropModel(lambda *a: None))
    points, beam = cloud(50)
    assert ray_drop.drop_mask(points, beam, effects_from_dict({}), np.random.default_rng(0)) is None


def test_uniform_drops_its_share_and_a_model_files_probability_wins():
    points, beam = cloud(40000)
    eff = effects_from_dict({"drop": {"model": "uniform", "probability": 0.3}})
    kept = int(ray_drop.drop_mask(points, beam, eff, np.random.default_rng(2)).sum())
    assert abs(kept - 0.7 * 40000) <= Z * math.sqrt(40000 * 0.21)
    assert np.all(uniform.probability(points[:3], beam[:3], eff, models.FittedModels(uniform=0.05)) == np.float32(0.05))


def test_carla_keeps_by_its_two_draws():
    assert np.allclose(carla.carla_keep_probability(np.array([0.0, 0.4, 0.9], np.float32), 0.8, 0.4), [0.6, 0.8, 1.0])
    points, beam = cloud(40000, range_m=100.0)  # intensity exp(-0.4) = 0.67, below the limit 0.8
    eff = effects_from_dict({"drop": {"model": "carla"}})
    p_keep = 0.55 * (0.4 / 0.8 * math.exp(-0.004 * 100) + 0.6)
    kept = int(carla.mask(points, beam, eff, np.random.default_rng(4), None).sum())
    assert abs(kept - p_keep * 40000) <= Z * math.sqrt(40000 * p_keep * (1 - p_keep))
    assert np.allclose(carla.probability(points[:2], beam[:2], eff, None), 1 - p_keep)


def test_table_drop_needs_a_model_and_reads_its_table():
    points, beam = cloud(5, range_m=5.0)
    beam["cos_incidence"] = math.cos(math.radians(22.5))
    with pytest.raises(InputError, match="^effects.drop.model_file: the table drop model needs a model file"):
        table.probability(points, beam, None, None)
    assert np.allclose(table.probability(points, beam, None, models.FittedModels(drop_table=a_table())), 0.1, atol=0.01)


def test_the_drop_decision_sees_the_detection_reflectivities_when_given():
    points, beam = cloud(2000, range_m=60.0, reflectivity=0.9)
    eff = effects_from_dict({"drop": {"model": "threshold", "threshold": {"range_at_10": 40.0, "range_at_80": 120.0, "softness": 0.0}}})
    seen = apply_effects(points, beam, eff, np.random.default_rng(0))
    dark = apply_effects(points, beam, eff, np.random.default_rng(0), detection=np.full(2000, 0.02, np.float32))
    assert len(seen) == 2000 and len(dark) == 0  # bright at 60 m returns; a 2 % target there does not


# ----------------------------------------------------------------------------- weather: the kinds and their interface
def test_weather_config_has_one_section_per_registered_kind():
    assert WEATHER_KINDS.names() == ("fog", "rain", "snow")
    assert [f for f in WeatherConfig.__dataclass_fields__] == ["fog", "rain", "snow", "divergence_mrad"]
    assert not WeatherConfig().active and WeatherConfig(snow=snow.SnowConfig(wet_ground=True)).active
    assert [WEATHER_KINDS.get(n).label for n in WEATHER_KINDS] == ["fog", "rain", "snow"]


def test_returns_offer_by_kind_name_and_the_stronger_scatterer_wins():
    n = 3
    medium = particles._Medium(np.ones(n), np.full(n, 10.0), np.zeros(n), np.full(n, -1, np.int8), np.full(n, np.nan))
    returns = kind.Returns(None, None, None, np.full(n, 10.0), np.ones(n), medium, 0.003, None, None)
    returns.offer("rain", np.array([0, 1]), np.array([5.0, 5.0]), np.array([0.1, 0.1]))
    returns.offer("snow", np.array([1, 2]), np.array([5.0, 2.0]), np.array([0.05, 0.1]))
    assert list(medium.kind) == [1, 1, 2]  # row 1: the weaker snow flake loses to the drop
    assert np.allclose(medium.range, [5.0, 5.0, 2.0])
    assert np.allclose(kind.WeatherKind().range_noise(None, np.arange(3.0), np.ones(3, bool), None), np.arange(3.0))


def test_particles_overlap_tail_and_draws():
    assert np.allclose(particles.overlap(np.array([0.5, 0.95, 2.0])), [0.0, 0.5, 1.0])
    medium = particles._Particles(100.0, 0.001, 0.002, 0.006, 0.5)
    assert np.allclose(medium.tail(np.array([0.0, 0.001, 0.006])), [1.0, 1.0, 0.0])
    d = medium.draw_above(np.full(10000, 0.003), np.random.default_rng(0))
    assert d.min() >= 0.003 and d.max() <= 0.006
    assert np.array_equal(particles._strongest(np.array([0, 0, 1, 1, 1]), np.array([1.0, 3.0, 2.0, 2.0, 1.0])), [1, 2])


def test_fog_extinction_is_five_percent_one_way_at_the_visibility_and_checks_name_the_key():
    alpha = fog.fog_alpha(50.0)
    assert math.isclose(math.exp(-alpha * 50.0), 0.05)
    r0, integral, distance = fog.fog_soft_table(alpha, 20.0)
    assert r0[0] == 0 and np.all(np.diff(r0) > 0) and integral.shape == r0.shape == distance.shape and integral[-1] > 0
    with pytest.raises(InputError, match=r"^w.visibility: must be 0 \(no fog\) or 1..100000 m"):
        fog.Fog().check(fog.FogConfig(visibility=0.5), "w")


def test_rain_closed_forms():
    assert math.isclose(rain.rain_alpha(25.0), 0.01 * 25.0**0.6)
    z = rain.rain_max_range(100.0, 25.0)
    assert math.isclose(z * z * math.exp(2 * rain.rain_alpha(25.0) * z), 100.0**2, rel_tol=1e-6)
    assert np.allclose(rain.rain_range_sigma(np.array([10.0]), 5.0), 0.02 * 10.0 * (1 - math.exp(-5.0)) ** 2)
    drops = rain._rain_particles(rain.RainConfig(rate=10.0))
    lam = rain.marshall_palmer_lambda(10.0)
    assert math.isclose(lam, 4.1 * 10.0**-0.21) and math.isclose(drops.per_m3, 8000 / lam * math.exp(-lam * 0.5))
    with pytest.raises(InputError, match=r"^w.rate: must lie in 0..300 mm/h, got 301.0$"):  # the field's range, one source
        check_ranges(rain.RainConfig(rate=301.0), "w")


def test_snow_closed_forms_and_a_wet_ground_is_darker():
    assert math.isclose(snow.snow_occupancy(3.6, 1.0, 0.1), 3.6 / (3.6e6 * 0.1))
    assert snow.snow_extinction(snow.SnowConfig(rate=2.0)) > snow.snow_extinction(snow.SnowConfig(rate=0.5)) > 0
    factor = snow.wet_ground_factor(np.array([0.0, 0.3, 0.3]), np.array([1.0, 1.0, 0.2]))
    r = ((1 - 1.33) / (1 + 1.33)) ** 2
    internal = 1 - (1 - 0.066) / 1.33**2
    assert math.isclose(factor[0], (1 - r) * (1 - internal)) and 0 < factor[2] < factor[1] < 1
    points, beam = cloud(4)
    from bpy_pipeline.labels import load_class_table

    table = load_class_table()
    points["semantic"] = [table.id_of("road"), table.id_of("car"), table.id_of("road"), table.id_of("car")]
    medium = particles._Medium(np.ones(4), np.ones(4), np.zeros(4), np.full(4, -1, np.int8), np.full(4, np.nan))
    snow.Snow().surface(snow.SnowConfig(wet_ground=True), kind.Returns(points, beam, None, None, None, medium, 0.003, None, table))
    assert medium.transmit[0] < 1 and medium.transmit[2] < 1 and medium.transmit[1] == medium.transmit[3] == 1
