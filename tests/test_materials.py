"""Material reflectance models (lidar/effects/materials.py): glossy paint against incidence, retro-reflectors, dark paint,
wet surfaces; opt-in; bad names. Pure: no bpy."""

import math

import numpy as np
import pytest

from bpy_pipeline.config import effects_from_dict
from bpy_pipeline.errors import InputError
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.effects.apply import apply_effects
from bpy_pipeline.lidar.effects.materials import GlossyPaint, MaterialsConfig, apply_materials, glossy_paint
from bpy_pipeline.lidar.points import BEAM_DTYPE, empty_points

TABLE = load_class_table()


def returns(range_m, incidence_deg, cls, reflectivity=0.5, n_each=200):
    """``n_each`` returns of class ``cls`` at each incidence angle (deg), at ``range_m``; ``time`` holds the angle."""
    angles = np.repeat(np.asarray(incidence_deg, float), n_each)
    points = empty_points(len(angles))
    points["x"], points["range"], points["time"], points["semantic"] = range_m, range_m, angles, TABLE.id_of(cls)
    beam = np.zeros(len(angles), BEAM_DTYPE)
    beam["cos_incidence"], beam["reflectivity"], beam["gain"], beam["direction"] = np.cos(np.radians(angles)), reflectivity, 1.0, (1.0, 0.0, 0.0)
    return points, beam


def effects(**materials):
    """The HDL-64E's datasheet floor (hard), intensity rho cos^0 as its profile reads it, no noise."""
    return effects_from_dict({"drop": {"model": "threshold", "threshold": {"range_at_10": 50.0, "range_at_80": 120.0, "softness": 0.0}},
                              "intensity": {"incidence_exponent": 0.0}, "materials": materials})


def test_a_glossy_car_loses_returns_at_oblique_incidence_a_matte_one_does_not():
    angles = [0, 5, 10, 20, 30, 45, 60, 70]
    points, beam = returns(30.0, angles, "car")
    matte = apply_effects(points, beam, effects(), np.random.default_rng(0))
    glossy = apply_effects(points, beam, effects(classes={"car": "glossy_paint"}), np.random.default_rng(0))
    kept = {a: int((glossy["time"] == a).sum()) for a in angles}
    assert len(matte) == len(points)  # 50 % diffuse paint at 30 m: seen at every incidence
    assert kept[0] == kept[5] == 200 and kept[45] == kept[60] == kept[70] == 0, kept
    # near normal the coat returns more than the diffuse paint, at oblique incidence far less
    i_glossy = {a: glossy["intensity"][glossy["time"] == a] for a in (0,)}
    assert i_glossy[0].min() > 0.5
    p = GlossyPaint()
    expected = p.diffuse * math.cos(math.radians(20)) + p.specular * math.exp(-0.5 * (20 / p.lobe_deg) ** 2)
    np.testing.assert_allclose(glossy_paint(0.5, np.array([math.cos(math.radians(20))]), p), expected)


def test_retroreflectors_are_seen_far_beyond_a_white_diffuse_target():
    points, beam = returns(200.0, [0, 30], "traffic sign", reflectivity=0.8)
    diffuse = apply_effects(points, beam, effects(), np.random.default_rng(1))
    retro = apply_effects(points, beam, effects(classes={"traffic sign": "retroreflector"}), np.random.default_rng(1))
    assert len(diffuse) == 0 and len(retro) == len(points)
    assert np.all(retro["intensity"] == 1.0)  # the receiver saturates


def test_dark_paint_and_wet_surfaces_return_less():
    points, beam = returns(45.0, [0], "road", reflectivity=0.12)
    dry = apply_effects(points, beam, effects(), np.random.default_rng(2))
    wet = apply_effects(points, beam, effects(classes={"road": "wet"}), np.random.default_rng(2))
    assert len(dry) == len(points) and len(wet) == 0
    cars, beam = returns(10.0, [0], "car", reflectivity=0.7)
    black = apply_effects(cars, beam, effects(classes={"car": "dark_paint"}), np.random.default_rng(3))
    np.testing.assert_allclose(black["intensity"], 0.05, rtol=1e-6)


def test_materials_are_opt_in_and_leave_other_classes_alone():
    points, beam = returns(20.0, [0, 40], "car")
    assert apply_materials(points, beam, MaterialsConfig(), 0.0) is beam
    walls, wall_beam = returns(20.0, [0, 40], "wall")
    assert apply_materials(walls, wall_beam, MaterialsConfig(classes={"car": "glossy_paint"}), 0.0) is wall_beam
    out = apply_materials(points, beam, MaterialsConfig(classes={"car": "glossy_paint"}), 1.0)
    assert out is not beam and np.array_equal(beam["reflectivity"], np.full(len(beam), 0.5, np.float32))  # the caller's facts untouched
    # with a Lambertian intensity model (k = 1) the reflectivity is set so that rho cos is the model's value
    np.testing.assert_allclose(out["reflectivity"] * out["cos_incidence"], glossy_paint(None, beam["cos_incidence"], GlossyPaint()), rtol=1e-5)


@pytest.mark.parametrize("materials, expected", [
    ({"classes": {"lava": "glossy_paint"}}, "effects.materials.classes: unknown class 'lava'"),
    ({"classes": {"car": "chrome"}}, "effects.materials.classes.car: unknown material model 'chrome'"),
    ({"glossy_paint": {"lobe_deg": 0}}, "effects.materials.glossy_paint.lobe_deg: must lie in 0.1..90"),
])
def test_bad_materials_name_the_key(materials, expected):
    with pytest.raises(InputError) as err:
        effects_from_dict({"materials": materials})
    assert str(err.value).startswith(expected), str(err.value)


def test_an_intensity_offset_reads_weak_returns_as_zero():
    points, beam = returns(10.0, [0], "wall", reflectivity=0.04)
    bright, bright_beam = returns(10.0, [0], "wall", reflectivity=0.10)
    eff = effects_from_dict({"intensity": {"incidence_exponent": 0.0, "scale": 6.0, "offset": 0.3, "steps": 100}})
    assert np.all(apply_effects(points, beam, eff, np.random.default_rng(0))["intensity"] == 0.0)  # 6 x 0.04 - 0.3 < 0
    np.testing.assert_allclose(apply_effects(bright, bright_beam, eff, np.random.default_rng(0))["intensity"], 0.30, atol=1e-6)
    with pytest.raises(InputError, match="effects.intensity.offset: must lie in 0..1"):
        effects_from_dict({"intensity": {"offset": -0.1}})
