"""Weather (lidar/effects/weather/) against each paper's closed form on flat walls; the hdl64e's share of returns kept
in fog; rain's maximum range and range noise against Goodin et al.'s curves; snow along beams; labelled clutter;
determinism; ``ideal``; bad values. Pure: no bpy (the command-line case runs run.py in a subprocess)."""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.api import scan
from bpy_pipeline.config import effects_from_dict, load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.boxes import count_points
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.effects.drop.threshold import ThresholdModel
from bpy_pipeline.lidar.effects.apply import apply_effects
from bpy_pipeline.lidar.points import BEAM_DTYPE, empty_points

ROOT = Path(__file__).resolve().parents[1]
TABLE = load_class_table()
FOG, RAIN, SNOW = (TABLE.id_of(name) for name in ("fog", "rain", "snow"))
C = 299_792_458.0
HDL64E_FLOOR = ThresholdModel.from_datasheet(50.0, 120.0)  # the hdl64e profile's datasheet threshold, hard (softness 0)


def wall(ranges, n_each, reflectivity=0.5, cos=1.0, semantic=0, seed=0):
    """``n_each`` returns at each range (m) of a flat target, facing the sensor, in random directions; ``time`` holds the row."""
    rng = np.random.default_rng(seed)
    r = np.repeat(np.asarray(ranges, float), n_each)
    d = rng.normal(size=(len(r), 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    points = empty_points(len(r))
    points["x"], points["y"], points["z"] = (d * r[:, None]).T
    points["range"], points["time"], points["semantic"], points["instance"] = r, np.arange(len(r)), semantic, 7
    points["intensity"] = reflectivity
    beam = np.zeros(len(r), BEAM_DTYPE)
    beam["cos_incidence"], beam["reflectivity"], beam["gain"], beam["direction"] = cos, reflectivity, 1.0, d
    return points, beam


def effects(softness=0.0, **weather):
    """No clear-weather drop or noise; the noise floor is the HDL-64E's datasheet threshold; intensity rho (exponent 0)."""
    return effects_from_dict({"drop": {"model": "none", "threshold": {"range_at_10": 50.0, "range_at_80": 120.0, "softness": softness}},
                              "intensity": {"incidence_exponent": 0.0}, "weather": weather})


# ----------------------------------------------------------------------------- fog: the paper's closed form
def soft_integral(r0: float, alpha: float, tau: float = 20e-9) -> tuple[float, float]:
    """The fog paper's soft-target integral, computed here from its formula: ``(max_R I, argmax R - c tau / 2)``."""
    t = np.linspace(0.0, 2 * tau, 401)
    R = np.arange(0.0, min(r0, 20.0) + C * tau, 0.02)[:, None]
    u = R - C * t[None, :] / 2
    xi = np.clip((u - 0.9) / 0.1, 0, 1)
    f = np.where((u > 0.9) & (u <= r0), np.sin(np.pi * t / (2 * tau)) ** 2 * np.exp(-2 * alpha * u) * xi / np.maximum(u, 1e-9) ** 2, 0.0)
    v = ((f[:, 1:] + f[:, :-1]) / 2 * np.diff(t)).sum(axis=1)
    k = int(np.argmax(v))
    return float(v[k]), float(R[k, 0] - C * tau / 2)


@pytest.mark.parametrize("visibility", [50.0, 100.0])
def test_fog_on_flat_walls_follows_the_papers_closed_form(visibility):
    ranges = [5.0, 10.0, 20.0, 30.0, 45.0, 60.0, 90.0]
    points, beam = wall(ranges, 500)
    out = apply_effects(points, beam, effects(fog={"visibility": visibility}), np.random.default_rng(1))
    alpha = math.log(20) / visibility
    for r0 in ranges:
        mine = out[points["range"][out["time"].astype(int)] == r0]
        transmit = math.exp(-2 * alpha * r0)
        integral, peak = soft_integral(r0, alpha)
        factor = r0**2 * (0.046 / visibility) / (1e-6 / math.pi) * integral  # i_soft / i_clear
        if abs(math.log(factor / transmit)) < 0.05:
            continue  # too near the crossing to tell from the table's 0.1 m steps
        if factor > transmit:  # the fog's back-scatter wins: every return is a fog point behind the soft peak
            assert (mine["semantic"] == FOG).all(), (r0, np.unique(mine["semantic"]))
            # seen where the soft return clears the floor: its power is factor x the clear one's, read at its own range
            seen = [0.5 * factor / r0**2 * at**2 / at**HDL64E_FLOOR.exponent >= HDL64E_FLOOR.sensitivity for at in (peak, peak + 10.0)]
            if all(seen) or not any(seen):
                assert len(mine) == (500 if all(seen) else 0), (r0, len(mine), seen)
            if len(mine):
                assert mine["range"].min() >= peak - 0.15 and mine["range"].max() <= peak + 10.0, (r0, peak, mine["range"].min(), mine["range"].max())
                np.testing.assert_allclose(mine["intensity"], 0.5 * factor, rtol=0.03)
                assert (mine["instance"] == 0).all()
        else:  # the attenuated hard target: seen while it clears the floor, its intensity i exp(-2 alpha R)
            assert (mine["semantic"] == 0).all()
            seen = 0.5 * transmit / r0**HDL64E_FLOOR.exponent >= HDL64E_FLOOR.sensitivity
            assert len(mine) == (500 if seen else 0), (r0, len(mine), seen)
            np.testing.assert_allclose(mine["intensity"], 0.5 * transmit, rtol=1e-5)
            np.testing.assert_allclose(mine["range"], r0, rtol=1e-6)


def street(visibility_m=None):
    """Walls at 8-110 m around an HDL-64E and a road, each with its reflectivity."""
    def quad(centre, normal_az, width, height, refl, cls):
        a = math.radians(normal_az)
        t = np.array([-math.sin(a), math.cos(a), 0.0])
        c = np.asarray(centre, float)
        v = np.array([c - t * width / 2, c + t * width / 2, c + t * width / 2 + [0, 0, height], c - t * width / 2 + [0, 0, height]])
        return (v, np.array([[0, 1, 2], [0, 2, 3]]), cls, "diffuse", refl)

    meshes = {"road": (np.array([[-150, -150, -1.73], [150, -150, -1.73], [150, 150, -1.73], [-150, 150, -1.73]], float), np.array([[0, 1, 2], [0, 2, 3]]),
                       "road", "diffuse", 0.1)}
    for k, (dist, refl) in enumerate([(8, 0.3), (15, 0.6), (25, 0.2), (40, 0.5), (60, 0.8), (85, 0.4), (110, 0.7)]):
        az = k * 51.0
        meshes[f"wall{k}"] = quad([dist * math.cos(math.radians(az)), dist * math.sin(math.radians(az)), -1.73], az, dist * 0.6, 12.0, refl, "wall")
    return meshes


def expected_kept_share(clear: np.ndarray, reflectivity: np.ndarray, visibility: float, floor: ThresholdModel) -> float:
    """The fog model's expected share of the clear scan's returns still seen (hard target or fog), from the closed forms."""
    alpha = math.log(20) / visibility
    grid = np.concatenate([np.arange(0.0, 12.0, 0.2), [20.0, 30.0]])  # past a few metres the target no longer cuts the integral
    table = np.array([soft_integral(g, alpha) for g in grid])
    r = clear["range"].astype(float)
    integral = np.interp(r, grid, table[:, 0])
    at = np.interp(r, grid, table[:, 1]) + 10.0 * 2.0 / 22.0  # the soft peak plus the mean of 10 Beta(2, 20)
    transmit = np.exp(-2 * alpha * r)
    factor = r**2 * (0.046 / visibility) / (1e-6 / math.pi) * integral
    fog_wins = factor > transmit
    apparent = np.where(fog_wins, reflectivity * factor * at**2 / r**2, reflectivity * transmit)
    where = np.where(fog_wins, np.minimum(at, r), r)
    p_clear = floor.detection_probability(reflectivity, r).astype(float)
    p_now = floor.detection_probability(apparent, where).astype(float)
    keep = np.where(p_now >= p_clear, 1.0, p_now / np.maximum(p_clear, 1e-30))
    return float(keep.mean())


@pytest.mark.parametrize("visibility", [20.0, 50.0, 100.0, 200.0])
def test_fog_share_of_returns_kept_follows_the_model_for_the_hdl64e(visibility):
    meshes = street()
    clear = scan(meshes, {"preset": "hdl64e", "horizontal_resolution_deg": 0.5}, effects={})
    foggy = scan(meshes, {"preset": "hdl64e", "horizontal_resolution_deg": 0.5}, effects={"weather": {"fog": {"visibility": visibility}}})
    names = {TABLE.id_of(name): name for name in ("road", "wall")}
    reflect = {"road": 0.1}
    # each wall's reflectivity from its range band (the clear scan's wall points, nearest wall)
    walls = [(8, 0.3), (15, 0.6), (25, 0.2), (40, 0.5), (60, 0.8), (85, 0.4), (110, 0.7)]
    az = np.degrees(np.arctan2(clear["y"], clear["x"])) % 360
    centres = np.array([k * 51.0 for k in range(len(walls))])
    nearest = np.argmin(np.abs((az[:, None] - centres[None, :] + 180) % 360 - 180), axis=1)
    rho = np.where(clear["semantic"] == TABLE.id_of("road"), reflect["road"], np.array([w[1] for w in walls])[nearest]).astype(np.float32)
    profile = ThresholdModel.from_datasheet(50.0, 120.0, 0.3)  # the hdl64e profile's threshold
    model = expected_kept_share(clear, rho, visibility, profile)
    share = len(foggy) / len(clear)
    assert set(np.unique(clear["semantic"])) <= set(names)
    assert abs(share - model) <= 0.1 * model, (visibility, share, model)
    if visibility <= 50:
        fog = foggy[foggy["semantic"] == FOG]
        assert len(fog) > 0 and fog["range"].max() < 15.0  # fog points near the sensor
    # nothing beyond the range the model allows: hard returns end where the back-scatter wins
    alpha = math.log(20) / visibility
    saturated = soft_integral(25.0, alpha)[0]  # the crossing lies beyond 12 m, where the target no longer cuts the integral
    crossing = next(r for r in np.arange(12.0, 200.0, 0.5) if r**2 * (0.046 / visibility) / (1e-6 / math.pi) * saturated > math.exp(-2 * alpha * r))
    hard = foggy[foggy["semantic"] != FOG]
    assert hard["range"].max() <= crossing + 1.0, (hard["range"].max(), crossing)


# ----------------------------------------------------------------------------- rain: Goodin et al.'s curves
def goodin_max_range(z_max: float, rate: float) -> float:
    """Goodin et al.: ``z = z_max exp(-alpha z)`` with ``alpha = 0.01 rate^0.6`` (fixed-point iteration)."""
    alpha, z = 0.01 * rate**0.6, z_max
    for _ in range(500):
        z = 0.5 * z + 0.5 * z_max * math.exp(-alpha * z)
    return z


@pytest.mark.parametrize("rate", [1.0, 5.0, 10.0, 25.0, 50.0])
def test_rain_maximum_range_follows_goodins_curve(rate):
    ranges = np.arange(2.0, 120.0, 0.25)  # within the clear range: beyond it the clear scan has already lost them
    points, beam = wall(ranges, 20, reflectivity=0.8)
    rainy = apply_effects(points, beam, effects(rain={"rate": rate}), np.random.default_rng(0))
    z_clear = HDL64E_FLOOR.range_at(0.8)  # clear air: the datasheet's 120 m for an 80 % target
    assert abs(z_clear - 120.0) < 0.01
    hard = rainy[rainy["semantic"] != RAIN]
    z = points["range"][hard["time"].astype(int)].max()  # the farthest target still seen (its true range: rain adds range noise)
    expected = goodin_max_range(z_clear, rate)
    assert abs(z - expected) <= 0.15 * expected, (rate, z, expected)


@pytest.mark.parametrize("rate", [0.5, 1.0, 2.0, 5.0])
def test_rain_range_noise_follows_goodins_sigma(rate):
    points, beam = wall([20.0], 20000, reflectivity=0.8)
    out = apply_effects(points, beam, effects(rain={"rate": rate}), np.random.default_rng(2))
    hard = out[out["semantic"] != RAIN]
    sigma = float(np.std(hard["range"] - 20.0))
    expected = 0.02 * 20.0 * (1 - math.exp(-rate)) ** 2
    assert abs(sigma - expected) <= 0.15 * expected, (rate, sigma, expected)
    # the points moved along their beams
    back = points[hard["time"].astype(int)]
    cos = (hard["x"] * back["x"] + hard["y"] * back["y"] + hard["z"] * back["z"]) / (np.maximum(hard["range"], 1e-6) * 20.0)
    assert np.all(cos > 0.99999)


def test_rain_drops_return_near_the_sensor_along_beams():
    points, beam = wall([30.0], 50000, reflectivity=0.3)
    out = apply_effects(points, beam, effects(rain={"rate": 25.0}), np.random.default_rng(3))
    drops = out[out["semantic"] == RAIN]
    assert 0 < len(drops) and drops["range"].max() < 10.0 and drops["range"].min() >= 0.9
    assert (drops["instance"] == 0).all()


# ----------------------------------------------------------------------------- snow: Hahner et al.'s snowfall
def test_snow_points_lie_along_beams_and_grow_with_the_rate():
    points, beam = wall([25.0], 60000, reflectivity=0.5)
    counts = []
    for rate in (1.0, 2.5, 5.0, 10.0):  # (from 0.1 to about 1.5 mm/h the count is flat: the flakes grow but fewer, docs/effects.md)
        out = apply_effects(points, beam, effects(snow={"rate": rate}), np.random.default_rng(4))
        flakes = out[out["semantic"] == SNOW]
        counts.append(len(flakes))
        back = points[flakes["time"].astype(int)]
        cos = (flakes["x"] * back["x"] + flakes["y"] * back["y"] + flakes["z"] * back["z"]) / (flakes["range"] * 25.0)
        assert np.all(cos > 0.99999) and np.all(flakes["range"] < 25.0) and np.all(flakes["range"] >= 0.9)
        assert (flakes["instance"] == 0).all()
    assert counts[0] > 0 and all(b > a for a, b in zip(counts, counts[1:])), counts
    # what the flakes occlude per metre grows with the rate at every rate
    from bpy_pipeline.lidar.effects.weather import SnowConfig, snow_extinction

    shares = [snow_extinction(SnowConfig(rate=rate)) for rate in (0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0)]
    assert all(b > a for a, b in zip(shares, shares[1:])), shares


def test_wet_ground_returns_less():
    road = TABLE.id_of("road")
    points, beam = wall([20.0, 40.0], 2000, reflectivity=0.1, cos=0.2, semantic=road)
    dry = apply_effects(points, beam, effects(), np.random.default_rng(5))
    wet = apply_effects(points, beam, effects(snow={"wet_ground": True}), np.random.default_rng(5))
    assert len(dry) == 4000
    near, far = wet["range"] < 30, wet["range"] >= 30
    assert near.sum() == 2000 and far.sum() == 0  # 40 m: pushed under the floor
    assert np.all(wet["intensity"][near] < 0.1 * 0.6)  # a water film over 10 % asphalt reads about half


# ----------------------------------------------------------------------------- labels, boxes, determinism, ideal
def scene_with_a_car():
    def box(centre, size, cls, refl):
        c, s = np.asarray(centre, float), np.asarray(size, float) / 2
        v = np.array([[c[0] + sx * s[0], c[1] + sy * s[1], c[2] + sz * s[2]] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
        return (v, f, cls, "diffuse", refl)

    return {"car": box([12, 0, -1.0], [4.2, 1.8, 1.5], "car", 0.3), "ground": box([0, 0, -1.8], [200, 200, 0.1], "road", 0.1)}


def test_weather_classes_present_never_an_instance_and_left_out_of_boxes():
    meshes = scene_with_a_car()
    sensor = {"preset": "hdl64e", "horizontal_resolution_deg": 0.4}
    for weather, cls in (({"fog": {"visibility": 20}}, FOG), ({"rain": {"rate": 40}}, RAIN), ({"snow": {"rate": 2.5}}, SNOW)):
        points = scan(meshes, sensor, effects={"weather": weather})
        mine = points["semantic"] == cls
        assert mine.sum() > 0, weather
        assert (points["instance"][mine] == 0).all()
        car = TABLE.id_of("car")
        instance = int(np.bincount(points["instance"][points["semantic"] == car]).argmax())
        boxes = np.zeros(1, [("instance", "<u4"), ("points", "<i8")])
        boxes["instance"] = instance
        count_points(boxes, points)
        assert boxes["points"][0] == int(((points["instance"] == instance) & (points["semantic"] == car)).sum())


def test_weather_is_deterministic_and_equal_across_threads():
    points, beam = wall(np.linspace(2, 100, 70), 1000, reflectivity=0.4)  # 70,000 returns: two chunks
    eff = effects(softness=0.3, fog={"visibility": 60}, rain={"rate": 8}, snow={"rate": 1.5, "wet_ground": True})
    a = apply_effects(points, beam, eff, np.random.default_rng(11), threads=1)
    b = apply_effects(points, beam, eff, np.random.default_rng(11), threads=4)
    c = apply_effects(points, beam, eff, np.random.default_rng(12), threads=1)
    assert a.tobytes() == b.tobytes()
    assert a.tobytes() != c.tobytes()
    assert {FOG, RAIN, SNOW} <= set(np.unique(a["semantic"]))


def test_ideal_turns_weather_off_exactly():
    meshes = scene_with_a_car()
    sensor = {"preset": "hdl64e", "horizontal_resolution_deg": 0.8}
    exact = scan(meshes, sensor, effects={"ideal": True})
    weather = {"fog": {"visibility": 30}, "rain": {"rate": 20}, "snow": {"rate": 3, "wet_ground": True}}
    assert scan(meshes, sensor, effects={"ideal": True, "weather": weather}).tobytes() == exact.tobytes()
    assert scan(meshes, sensor, effects={"weather": weather}).tobytes() != exact.tobytes()


# ----------------------------------------------------------------------------- bad values
@pytest.mark.parametrize("key, value, expected", [
    ("fog.visibility", -5, "effects.weather.fog.visibility: must be 0 (no fog) or 1..100000 m"),
    ("rain.rate", 1e9, "effects.weather.rain.rate: must lie in 0..300 mm/h"),
    ("snow.rate", 1e9, "effects.weather.snow.rate: must lie in 0..20 mm/h"),
    ("snow.wet_classes", ["lava"], "effects.weather.snow.wet_classes: unknown class 'lava'"),
    ("haze", 3, "effects.weather.haze: unknown key"),
])
def test_bad_weather_values_name_the_key(key, value, expected):
    section, _, leaf = key.rpartition(".")
    weather = {section: {leaf: value}} if section else {leaf: value}
    with pytest.raises(InputError) as err:
        load_config({"effects": {"weather": weather}})
    assert str(err.value).startswith(expected), str(err.value)
    assert "\n" not in str(err.value)


def test_bad_weather_value_on_the_command_line_is_one_line_exit_2(tmp_path):
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--set", "effects.weather.rain.rate=1e9"],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: effects.weather.rain.rate: "), result.stderr
    assert not out.exists() or not any(p.is_file() for p in out.rglob("*"))


def test_weather_frames_alone_and_over_workers_give_the_full_runs_bytes(tmp_path):
    """Frames 1-2 of a foggy, snowy parking run alone, and the run over two workers, write the full run's bytes."""
    weather = ["--set", "scene.builder=parking", "--set", "output.formats=[ply]", "--seed", "5", "--frames", "3",
               "--set", "effects.weather.fog.visibility=30", "--set", "effects.weather.snow.rate=2", "--set", "effects.weather.rain.rate=10"]

    def run(out, *extra):
        done = subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(out), *weather, *extra], cwd=ROOT, capture_output=True, text=True,
                              timeout=600)
        assert done.returncode == 0, done.stderr
        return {p.name: p.read_bytes() for p in sorted((out / "ply").glob("*.ply"))}

    full = run(tmp_path / "full")
    alone = run(tmp_path / "part", "--frames-range", "1:3")
    workers = run(tmp_path / "workers", "--workers", "2")
    assert sorted(alone) == ["000001.ply", "000002.ply"] and alone == {k: full[k] for k in alone}
    assert workers == full
    from bpy_pipeline.io import read_ply

    cloud = read_ply(tmp_path / "full" / "ply" / "000000.ply")
    assert {FOG, SNOW} <= set(np.unique(cloud["semantic"]))
