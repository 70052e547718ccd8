"""The reading model (``effects.intensity.reading``, lidar/effects/intensity.py): per-laser gain and offset, range
compensation, detection left to the drop models."""

import math

import numpy as np
import pytest

from bpy_pipeline import cli
from bpy_pipeline.config import effects_from_dict, load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.effects.apply import apply_effects
from bpy_pipeline.lidar.effects.intensity import MAX_RINGS, ReadingModel, laser_calibration, range_factor, read_out
from bpy_pipeline.lidar.points import BEAM_DTYPE, empty_points


def wall(range_m, reflectivity, n=4000, rings=64):
    """``n`` returns of a wall at ``range_m`` seen head-on, spread over ``rings`` lasers."""
    points = empty_points(n)
    points["x"], points["range"], points["ring"] = range_m, range_m, np.arange(n) % rings
    beam = np.zeros(n, BEAM_DTYPE)
    beam["cos_incidence"], beam["reflectivity"], beam["gain"], beam["direction"] = 1.0, reflectivity, 1.0, (1.0, 0.0, 0.0)
    return points, beam


def effects(drop=None, steps=0, **reading):
    intensity = {"incidence_exponent": 0.0, "scale": 4.5, "offset": 0.15, "steps": steps, "reading": {"enabled": True, **reading}}
    return effects_from_dict({"drop": drop or {"model": "none"}, "intensity": intensity})


def expected(range_m, reflectivity, unit_seed=0, gain_sd=0.16, offset_sd=0.0, rings=64, compensated_range=28.0, exponent=2.0):
    """The closed form ``clip(g_k a f(R) - o_k, 0, 1)`` per laser, from the unit's draw (no per-return noise)."""
    z = np.random.default_rng(unit_seed).standard_normal((2, MAX_RINGS))
    gain = 4.5 * np.exp(gain_sd * z[0][:rings])
    offset = np.maximum(0.15 + offset_sd * z[1][:rings], 0.0)
    f = min(1.0, (compensated_range / range_m) ** exponent)
    return np.clip(gain * reflectivity * f - offset, 0.0, 1.0)


@pytest.mark.parametrize("range_m, reflectivity", [(10.0, 0.1), (28.0, 0.05), (40.0, 0.1), (60.0, 0.3), (5.0, 0.02)])
def test_a_wall_reads_the_closed_form_and_its_zero_share(range_m, reflectivity):
    points, beam = wall(range_m, reflectivity)
    out = apply_effects(points, beam, effects(noise_sd=0.0, offset_sd=0.05), np.random.default_rng(1), threads=1)
    want = expected(range_m, reflectivity, offset_sd=0.05)[out["ring"]]
    assert np.allclose(out["intensity"], want, atol=2e-6)
    assert (out["intensity"] == 0).mean() == pytest.approx((want == 0).mean())


def test_range_compensation_then_the_lidar_equation():
    assert range_factor(np.array([1.0, 28.0]), 28.0, 2.0).tolist() == [1.0, 1.0]
    assert float(range_factor(np.array([56.0]), 28.0, 2.0)[0]) == pytest.approx(0.25)
    # a 10 % target head-on, one laser of gain 4.5 and offset 0.15: reads 0.30 up to 28 m, 0 from 28 sqrt(0.45 / 0.15) m
    flat = ReadingModel(enabled=True, gain_sd=0.0, noise_sd=0.0)
    r0 = 28.0 * math.sqrt(0.45 / 0.15)
    got = read_out(np.full(4, 0.1), np.array([10.0, 28.0, r0 * 0.99, r0 * 1.01]), np.zeros(4, int), flat, 4.5, 0.15, None)
    assert got[:2] == pytest.approx([0.30, 0.30], abs=1e-6)
    assert got[2] > 0 and got[3] == 0


def test_detection_stays_the_drop_models_a_far_dark_wall_is_kept_and_reads_zero():
    """At 45 m a 10 % wall is detected by the HDL-64E's datasheet floor (10 % seen to 50 m) yet reads 0 on every
    laser whose gain a f(R) stays under the offset: detection and reading apart."""
    drop = {"model": "threshold", "threshold": {"range_at_10": 50.0, "range_at_80": 120.0, "softness": 0.0}}
    points, beam = wall(45.0, 0.1)
    out = apply_effects(points, beam, effects(drop, noise_sd=0.0), np.random.default_rng(0), threads=1)
    assert len(out) == len(points)
    want = expected(45.0, 0.1)
    assert (want == 0).any() and (want > 0).any()
    assert (out["intensity"] == 0).mean() == pytest.approx((want[out["ring"]] == 0).mean())


def test_noise_spreads_the_reading_about_the_closed_form():
    points, beam = wall(10.0, 0.1, n=20000, rings=1)
    out = apply_effects(points, beam, effects(noise_sd=0.075, gain_sd=0.0), np.random.default_rng(3), threads=1)
    # (0.45 e^(0.075 e)) - 0.15: the log of (reading + offset) has the noise's sd
    spread = np.log(out["intensity"].astype(np.float64) + 0.15)
    assert spread.std() == pytest.approx(0.075, rel=0.05)
    assert np.median(out["intensity"]) == pytest.approx(0.30, abs=0.005)


def test_seeded_and_deterministic_across_chunks_and_threads():
    points, beam = wall(20.0, 0.1, n=200_000)
    config = effects(steps=100)
    one = apply_effects(points, beam, config, np.random.default_rng(7), threads=1)
    two = apply_effects(points, beam, config, np.random.default_rng(7), threads=2)
    assert one.tobytes() == two.tobytes()
    other_frame = apply_effects(points, beam, config, np.random.default_rng(8), threads=1)
    assert one.tobytes() != other_frame.tobytes()
    other_unit = apply_effects(points, beam, effects(steps=100, unit_seed=1), np.random.default_rng(7), threads=1)
    assert not np.array_equal(one["intensity"], other_unit["intensity"])


def test_one_unit_draws_its_lasers_once():
    a = laser_calibration(5, 4.5, 0.15, 0.16, 0.02)
    b = laser_calibration(5, 4.5, 0.15, 0.16, 0.02)
    assert a[0] is b[0] and a[0].shape == (MAX_RINGS,)
    assert np.median(a[0]) == pytest.approx(4.5, rel=0.03)
    assert (a[1] >= 0).all()


def test_off_by_default_leaves_the_intensity_as_it_was():
    points, beam = wall(40.0, 0.1)
    plain = effects_from_dict({"intensity": {"incidence_exponent": 0.0, "scale": 3.0, "steps": 100}})
    assert not plain.intensity.reading.enabled
    out = apply_effects(points, beam, plain, np.random.default_rng(0), threads=1)
    assert np.allclose(out["intensity"], 0.30)


@pytest.mark.parametrize("reading, fragment", [
    ({"gain_sd": -1}, "effects.intensity.reading.gain_sd: must lie in 0..2"),
    ({"compensated_range": 0}, "effects.intensity.reading.compensated_range: must lie in 0..10000 m (0 excluded), got 0"),
    ({"exponent": 1e9}, "effects.intensity.reading.exponent: must lie in 0..10"),
    ({"noise_sd": float("nan")}, "effects.intensity.reading.noise_sd: "),
    ({"unit_seed": -3}, "effects.intensity.reading.unit_seed: must be >= 0, got -3"),
    ({"colour": 1}, "effects.intensity.reading.colour: unknown key"),
])
def test_bad_values_are_one_line(reading, fragment):
    with pytest.raises(InputError) as info:
        effects_from_dict({"intensity": {"reading": reading}})
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_the_reading_model_needs_the_reflectance_model():
    with pytest.raises(InputError, match="effects.intensity.reading.enabled"):
        effects_from_dict({"intensity": {"model": "carla", "reading": {"enabled": True}}})


def test_a_bad_value_on_the_command_line_exits_2_in_one_line(tmp_path, capsys):
    config = tmp_path / "c.yaml"
    config.write_text("scene: {builder: primitives, shapes: [{type: plane, size: 4, position: [5, 0, 0]}]}\nsensor: {preset: hdl64e}\n")
    try:
        code = cli.main(["run.py", "--config", str(config), "--out", str(tmp_path / "out"), "--set", "effects.intensity.reading.gain_sd=-0.5"])
    except SystemExit as exit_:
        code = exit_.code
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip() and not line.startswith("note: estimate")]
    assert code == 2
    assert len(err) == 1 and "effects.intensity.reading.gain_sd" in err[0], err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


# ----------------------------------------------------------------------------- the receiver's response and the hdl64e profile
def test_a_compressing_response_reads_the_closed_form():
    points, beam = wall(10.0, 0.3, rings=64)
    out = apply_effects(points, beam, effects(noise_sd=0.0, response=0.225), np.random.default_rng(1), threads=1)
    z = np.random.default_rng(0).standard_normal((2, MAX_RINGS))
    want = np.clip(4.5 * np.exp(0.16 * z[0][:64]) * 0.3**0.225 - 0.15, 0.0, 1.0)[out["ring"]]
    assert np.allclose(out["intensity"], want, atol=2e-6)
    # beyond the compensated range the power falls first, then the response compresses it: (a (R_c / R)^e)^gamma
    far = read_out(np.array([0.3]), np.array([56.0]), np.zeros(1, int), ReadingModel(enabled=True, gain_sd=0.0, noise_sd=0.0, response=0.5), 1.0, 0.0, None)
    assert float(far[0]) == pytest.approx((0.3 * 0.25) ** 0.5, rel=1e-5)


@pytest.mark.parametrize("response", [0.0, -0.5, 4.5, float("nan")])
def test_a_response_out_of_range_is_refused_naming_its_key(response):
    with pytest.raises(InputError, match=r"effects\.intensity\.reading\.response"):
        effects(response=response)


def hdl64e_reading(reflectivity, range_m=10.0, n=20000):
    """The hdl64e profile's readings of a head-on diffuse wall on all 64 lasers."""
    points, beam = wall(range_m, reflectivity, n=n)
    profile = load_config({"sensor": {"preset": "hdl64e"}, "effects": {"drop": {"model": "none"}}}).effects
    return apply_effects(points, beam, profile, np.random.default_rng(0), threads=1)["intensity"]


def test_the_hdl64e_profile_reads_every_diffuse_surface_below_saturation_in_many_steps():
    """The profile before it (3 x reflectivity, clipped) read every surface brighter than 0.33 as 1.0, one value per
    material; the fitted reading keeps a white wall below the top and spreads each surface over many steps."""
    for rho in (0.05, 0.13, 0.4, 0.9):
        got = hdl64e_reading(rho)
        assert (got >= 0.99).mean() < 0.02, rho
        assert len(np.unique(got)) >= 20, rho
    assert np.median(hdl64e_reading(0.9)) > np.median(hdl64e_reading(0.4)) > np.median(hdl64e_reading(0.13))
    assert np.median(hdl64e_reading(0.4, 60.0)) < 0.5 * np.median(hdl64e_reading(0.4, 10.0))  # the reading falls beyond the compensated range


def test_the_hdl64e_reading_of_the_street_materials_meets_semantickitti_per_class(real_scan):
    """The street's fitted materials read through the profile at 5-20 m against SemanticKITTI seq08 000720's remission
    there, per class: medians within 0.08 (the fit's frame; bench_intensity.py measures the whole distribution)."""
    from bpy_pipeline.builders.street import dressing, layout
    from bpy_pipeline.evaluate import labelled

    path = real_scan("semantickitti_seq08_000720.bin")
    classes = ("road", "sidewalk", "building", "vegetation", "terrain")
    scan = labelled.load_scans([path], classes)[0]
    remission = np.fromfile(path, np.float32).reshape(-1, 4)[:, 3]
    near = (np.linalg.norm(scan.points, axis=1) >= 5) & (np.linalg.norm(scan.points, axis=1) < 20)
    ours = {"road": layout.REFLECTIVITY["road"], "sidewalk": layout.REFLECTIVITY["sidewalk"], "building": layout.BUILDING[0],
            "vegetation": dressing.REFLECTIVITY["vegetation"], "terrain": dressing.REFLECTIVITY["terrain"]}
    for k, name in enumerate(classes):
        real = float(np.median(remission[near & (scan.labels == k)]))
        assert abs(float(np.median(hdl64e_reading(ours[name], 12.0))) - real) <= 0.08, (name, real)


def test_street_road_users_draw_their_reflectivity_from_the_frame_generator():
    from bpy_pipeline.builders.street.layout import CLOTHING, PAINT, draw_reflectivity

    for law in (PAINT, CLOTHING):
        draws = [draw_reflectivity(np.random.default_rng(seed), law) for seed in range(200)]
        assert law[2] <= min(draws) and max(draws) <= law[3]
        assert np.median(draws) == pytest.approx(law[0], rel=0.25)
        assert len(set(draws)) > 150  # one object's value, not one per class
    assert draw_reflectivity(np.random.default_rng(7), PAINT) == draw_reflectivity(np.random.default_rng(7), PAINT)
