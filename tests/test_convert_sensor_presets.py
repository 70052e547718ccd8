"""flash96x16 is the sparse-camera thesis's depth camera (no drop, intensity 0, 35 m); CARLA's ray-cast model keeps its own preset."""

import numpy as np

from bpy_pipeline.config import load_config
from bpy_pipeline.lidar.effects.apply import apply_effects
from bpy_pipeline.lidar.points import BEAM_DTYPE, POINT_DTYPE


def effects_on(preset: str, n: int = 20_000):
    config = load_config(None, [f"sensor.preset={preset}"])
    rng = np.random.default_rng(0)
    points, beam = np.zeros(n, POINT_DTYPE), np.zeros(n, BEAM_DTYPE)
    r = rng.uniform(1.0, 34.0, n)
    points["x"], points["range"] = r, r
    beam["cos_incidence"], beam["reflectivity"], beam["gain"] = rng.uniform(0.1, 1.0, n), rng.uniform(0.05, 0.9, n), 1.0
    beam["direction"] = (1.0, 0.0, 0.0)
    return config, points, apply_effects(points.copy(), beam, config.effects, rng)


def test_flash96x16_is_the_theses_depth_camera():
    config, points, out = effects_on("flash96x16")
    spec = config.sensor.spec
    assert (spec.pattern, spec.columns, spec.channels, spec.max_range, spec.rotation_hz) == ("pinhole", 96, 16, 35.0, 5.0)
    assert len(out) == len(points)  # no ray drop
    assert (out["intensity"] == 0).all()  # intensity written as 0
    np.testing.assert_array_equal(out["range"], points["range"])  # exact depth


def test_carlas_ray_cast_model_stays_its_own_preset():
    config, points, out = effects_on("flash96x16_carla")
    assert config.sensor.spec.pattern == "grid" and config.effects.drop.model == "carla"
    assert 0.3 < 1 - len(out) / len(points) < 0.6  # CARLA's drop-off (general rate 0.45)
    assert (out["intensity"] > 0).all()  # CARLA's exp(-0.004 R)
