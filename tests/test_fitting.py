"""Fitting drop and noise models to organised scans: recovery of known models from analytic
sweeps (one sweep with ego motion, repeated static sweeps), the model file round trip, the
``fit`` command, and the real nuScenes HDL-32E sweep. Pure: no bpy."""

import math

import numpy as np
import pytest

from bpy_pipeline.cli.commands import main
from bpy_pipeline.config import effects_from_dict
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.fit import fitting
from bpy_pipeline.lidar.effects.apply import drop_probability, read_model_file, write_model_file
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor

HEIGHT, WALL, WALL_TOP = 1.8, 40.0, 6.0  # m: sensor above flat ground, a round wall around it
EDGES = [2.0, 10.0, 25.0, 100.0]
TRUE_DROP = [0.01, 0.05, 0.15]  # per range bin


def true_drop(r):
    return np.asarray(TRUE_DROP)[np.clip(np.searchsorted(EDGES, r, side="right") - 1, 0, 2)]


def analytic_sweep(rng, sigma=0.005, columns=1084, ego=(0.0, -0.45, 0.0)):
    """One HDL-32E sweep of flat ground inside a round wall, with drops and range noise.

    Returns firing-ordered float32 records (x y z intensity ring) as nuScenes stores them:
    motion compensated to the end of the sweep, the sensor having travelled from ``ego`` to the
    origin, so an empty firing lands on the sensor's position at its time. Also the true range
    of each firing (rings, columns; inf for sky).
    """
    el = np.radians(resolve_sensor({"preset": "hdl32e"}).elevations_deg)
    az = np.radians(np.arange(columns) * -360.0 / columns)
    ground = np.where(el < 0, HEIGHT / np.sin(-np.minimum(el, -1e-9)), np.inf)
    wall = np.where(WALL * np.tan(el) < WALL_TOP, WALL / np.cos(el), np.inf)
    r_true = np.where(ground * np.cos(el) < WALL, ground, wall)[:, None] * np.ones(columns)
    direction = np.stack([np.cos(el)[:, None] * np.cos(az), np.cos(el)[:, None] * np.sin(az), np.sin(el)[:, None] * np.ones(columns)], -1)
    seen = np.isfinite(r_true)
    dropped = seen & (rng.random(r_true.shape) < true_drop(np.where(seen, r_true, 1.0)))
    r = np.where(seen & ~dropped, r_true + rng.normal(0, sigma, r_true.shape), 0.0)
    position = np.asarray(ego)[None] * (1.0 - np.arange(columns) / (columns - 1))[:, None]  # (columns, 3)
    xyz = position[None] + r[..., None] * direction
    intensity = np.where(r > 0, 20.0, 3.0)
    ring = np.broadcast_to(np.arange(len(el))[:, None], r.shape)
    records = np.concatenate([xyz, intensity[..., None], ring[..., None]], -1).transpose(1, 0, 2).reshape(-1, 5)
    return records.astype(np.float32), r_true


def test_sensor_track_and_ranges_of_a_motion_compensated_sweep():
    records, r_true = analytic_sweep(np.random.default_rng(0), sigma=0.0)
    scan = fitting.organise(records, 32, "sweep")
    assert (~scan.valid[0]).sum() == (records[:, 3] == 3.0).sum() > np.isinf(r_true).sum()  # sky and drops
    track, _ = fitting.sensor_track(np.asarray(records[:, :3], float).reshape(-1, 32, 3).transpose(1, 0, 2), ~scan.valid[0])
    np.testing.assert_allclose(track[[0, -1]], [[0, -0.45, 0], [0, 0, 0]], atol=1e-6)
    seen = scan.valid[0]
    np.testing.assert_allclose(np.linalg.norm(scan.xyz[0][seen], axis=1), r_true[seen], atol=1e-4)  # float32 file


def test_fit_recovers_a_known_drop_table_and_noise_from_one_sweep():
    records, r_true = analytic_sweep(np.random.default_rng(1), sigma=0.005)
    scan = fitting.organise(records, 32, "sweep")
    geometry = fitting.scan_geometry(scan)
    samples = fitting.drop_samples(scan, geometry)
    known = np.isfinite(r_true) & (r_true >= 2)
    assert len(samples) > 0.97 * known.sum()  # isolated drops are filled; only runs at the sky line are lost
    np.testing.assert_allclose(samples.range, r_true[samples.ring, samples.column], rtol=0.01)
    ground = samples.range * np.cos(np.radians(np.asarray(resolve_sensor({"preset": "hdl32e"}).elevations_deg)))[samples.ring] < WALL - 0.5
    expected_cos = np.where(ground, HEIGHT / samples.range, np.sqrt(np.maximum(1 - (HEIGHT / samples.range) ** 2, 0)))
    wall_cos = WALL / samples.range  # cos(el) for the wall
    expected_cos = np.where(ground, expected_cos, wall_cos)
    assert np.median(np.abs(samples.cos_incidence - expected_cos)) < 0.01
    table = fitting.fit_drop_table(samples, np.array(EDGES), fitting.incidence_edges(1), 100)
    for k, p in enumerate(TRUE_DROP):
        n = table.samples[k, 0]
        assert abs(table.values[k, 0] - p) <= 4 * math.sqrt(p * (1 - p) / n) + 0.003, (k, table.values[k, 0], p, n)
    overall = true_drop(samples.range).mean()
    assert abs(fitting.fit_uniform(samples) - overall) <= 4 * math.sqrt(overall * (1 - overall) / len(samples))
    noise = fitting.noise_samples(scan, geometry)
    assert fitting.robust_sigma(noise.residual) == pytest.approx(0.005, rel=0.05)


def test_fit_recovers_drop_and_noise_from_repeated_static_sweeps():
    rng = np.random.default_rng(2)
    sweeps = [fitting.organise(analytic_sweep(rng, sigma=0.02, ego=(0, 0, 0))[0], 32, f"sweep{k}") for k in range(6)]
    scan = fitting.stack_scans(sweeps)
    geometry = fitting.scan_geometry(scan)
    samples = fitting.drop_samples(scan, geometry)
    table = fitting.fit_drop_table(samples, np.array(EDGES), fitting.incidence_edges(1), 100)
    for k, p in enumerate(TRUE_DROP):
        n = table.samples[k, 0]
        assert abs(table.values[k, 0] - p) <= 4 * math.sqrt(p * (1 - p) / n), (k, table.values[k, 0], p, n)
    noise = fitting.noise_samples(scan, geometry)
    assert fitting.robust_sigma(noise.residual) == pytest.approx(0.02, rel=0.05)
    sigma, per_metre = fitting.fit_noise_range(noise, np.geomspace(2, 100, 5))
    assert sigma + per_metre * 20 == pytest.approx(0.02, rel=0.1) and per_metre < 2e-4  # constant noise: flat line


def test_threshold_fit_recovers_a_known_sensitivity():
    """Samples whose detection follows a known soft threshold on a / R^2: the fit finds it."""
    rng = np.random.default_rng(3)
    n = 60_000
    truth = fitting.ThresholdModel.from_datasheet(30.0, 0.0, softness=0.3)
    r, a = rng.uniform(3, 90, n), np.exp(rng.uniform(np.log(0.02), np.log(1.0), n))
    dropped = rng.random(n) >= truth.detection_probability(a, r)
    samples = fitting.Samples(r, np.ones(n), a, np.zeros(n, int), np.arange(n) % 1000, dropped)
    fitted = fitting.fit_threshold(samples)
    assert fitted.exponent == pytest.approx(2.0, abs=0.15)
    assert fitted.range_at(0.1) == pytest.approx(30.0, rel=0.05)
    assert fitted.softness == pytest.approx(0.3, rel=0.15)
    fixed = fitting.fit_threshold(samples, exponent=2.0)
    assert fixed.exponent == 2.0 and fixed.range_at(0.1) == pytest.approx(30.0, rel=0.03)


def test_a_saved_and_loaded_model_gives_the_same_probabilities(tmp_path):
    records, _ = analytic_sweep(np.random.default_rng(4))
    models, _ = fitting.fit_models(fitting.organise(records, 32, "sweep"), fitting.FitOptions(folds=0, range_bins=3, min_samples=50))
    path = tmp_path / "model.yaml"
    write_model_file(path, models)
    loaded = read_model_file(path)
    assert loaded.uniform == models.uniform and loaded.noise_range == models.noise_range
    assert loaded.threshold == models.threshold
    for mine, theirs in ((models.drop_table, loaded.drop_table), (models.noise_table, loaded.noise_table)):
        np.testing.assert_array_equal(mine.range_edges, theirs.range_edges)
        np.testing.assert_array_equal(mine.values, theirs.values)  # NaN (discarded bins) in the same places
        np.testing.assert_array_equal(mine.samples, theirs.samples)
    rng = np.random.default_rng(5)
    samples = fitting.Samples(rng.uniform(1, 120, 5000), rng.uniform(0, 1, 5000), rng.uniform(0, 1, 5000), np.zeros(5000, int), np.zeros(5000, int),
                              np.zeros(5000, bool))
    points, beam = fitting.samples_as_points(samples)
    for model in ("uniform", "threshold", "table"):
        effects = effects_from_dict({"drop": {"model": model, "model_file": str(path)}})
        from_file = drop_probability(points, beam, effects)
        in_memory = drop_probability(points, beam, effects, models)
        np.testing.assert_array_equal(from_file, in_memory)
        assert from_file.std() > 0 or model == "uniform"


def test_fit_command_writes_a_model_file_the_config_accepts(tmp_path, capsys):
    records, _ = analytic_sweep(np.random.default_rng(6))
    scan_path, out = tmp_path / "sweep.bin", tmp_path / "model.yaml"
    records.tofile(scan_path)
    assert main(["fit", str(scan_path), "--out", str(out), "--range-bins", "3", "--folds", "4"]) == 0
    printed = capsys.readouterr().out
    assert "held-out log-loss" in printed and "simplest within noise of the best" in printed
    effects = effects_from_dict({"drop": {"model": "table", "model_file": str(out)}, "noise": {"model": "table", "model_file": str(out)}})
    assert effects.drop.model_file == effects.noise.model_file == str(out)
    assert read_model_file(out).source["rings"] == 32


def test_fit_rejects_what_is_not_an_organised_scan(tmp_path, capsys):
    path = tmp_path / "short.bin"
    np.zeros((33, 5), np.float32).tofile(path)
    assert main(["fit", str(path), "--out", str(tmp_path / "m.yaml")]) == 2
    assert str(path) in capsys.readouterr().err
    records, _ = analytic_sweep(np.random.default_rng(7))
    records[5, 4] = 7  # a ring out of order
    with pytest.raises(InputError, match="not organised"):
        fitting.organise(records, 32, "sweep")
    assert main(["fit", str(tmp_path / "absent.bin"), "--out", str(tmp_path / "m.yaml")]) == 2


# ----------------------------------------------------------------------------- the real HDL-32E sweep
def test_real_sweep_empty_firings_and_sensor_track(real_samples):
    """Of the 5,196 records within 0.5 m of the origin, 4,393 lie on the sensor's track (empty
    firings); 803 are returns off it, from the vehicle's own body: about 4,000 returns lie
    0.5-1.2 m from the sensor, all in the 11 lowest rings."""
    scan, samples = real_samples
    assert (~scan.valid).sum() == 4393
    ranges = np.linalg.norm(scan.xyz[0], axis=2)
    near = scan.valid[0] & (ranges < 1.2)
    assert ranges[scan.valid[0]].min() > 0.49 and 3800 < near.sum() < 4200 and np.nonzero(near)[0].max() <= 10
    assert 25_000 < len(samples) < 30_000 and 0.03 < samples.dropped.mean() < 0.07


def test_real_sweep_table_beats_uniform_on_held_out_columns_and_reproduces_drop_against_range(real_samples, tmp_path):
    scan, samples = real_samples
    names = ["uniform", "table 4x2"]
    cv = fitting.cross_validate(samples, names, 8, scan.shape[1], {"range": (2.0, 100.0), "min_samples": 100})
    gain = cv["uniform"]["loss"] - cv["table 4x2"]["loss"]
    assert gain.mean() > 3 * gain.std(ddof=1) / math.sqrt(len(gain))
    # a scan simulated with the held-out fits (each column block by a table fitted on the others):
    # drop fraction per range bin within the binomial spread of both plus one percentage point
    fold = fitting.column_folds(samples, 8, scan.shape[1])
    simulated = np.zeros(len(samples), bool)
    for k in range(8):
        test = fold == k
        table = fitting.fit_drop_table(samples.subset(~test), np.geomspace(2, 100, 5), fitting.incidence_edges(2))
        path = tmp_path / f"fold{k}.yaml"
        write_model_file(path, fitting.FittedModels(drop_table=table))
        effects = effects_from_dict({"drop": {"model": "table", "model_file": str(path)}})
        simulated[test] = fitting.simulate_drops(samples.subset(test), effects, np.random.default_rng(k))
    edges = np.geomspace(2, 100, 6)
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (samples.range >= lo) & (samples.range < hi)
        real, sim = samples.dropped[m].mean(), simulated[m].mean()
        se = math.sqrt(2 * max(real * (1 - real), 1e-3) / m.sum())
        assert abs(sim - real) < 4 * se + 0.01, (lo, hi, real, sim)  # 1 point: the coarse table's resolution
