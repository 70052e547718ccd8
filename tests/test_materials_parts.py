"""A reflectance model per part of an inserted car (scene.car_paint, mixing/paint.py): each part gets its model, the body's
paint is drawn per car from a seeded generator of its own, a config naming one part changes that part's points only, the
default leaves the cars as they were, and bad values are one line and exit 2."""

from dataclasses import replace

import numpy as np
import pytest

import bpy_pipeline
from bpy_pipeline import cli
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.objects import PARTS
from bpy_pipeline.lidar.effects.materials import CarGlass
from bpy_pipeline.mixing import ObjectBox, RealScanScene
from bpy_pipeline.mixing.cast import car_part_names, object_parts
from bpy_pipeline.mixing.frame import MIX_STEPS, MixState
from bpy_pipeline.mixing.paint import CAR_PARTS, DEFAULT_PARTS, CarPaint, car_generator, part_model
from bpy_pipeline.mixing.placement import Placement
from bpy_pipeline.schema import check_ranges

PLACEMENT = Placement("car", "car", np.zeros(3), np.array([4.5, 1.8, 1.5]), 0.0)


def painted(paint: CarPaint, seed: int = 0):
    rng = np.random.default_rng(seed)
    return object_parts(PLACEMENT, rng, "classic", CarGlass(enabled=True), True, paint, car_generator(rng, 0))


def test_each_part_gets_its_model():
    paint = CarPaint(enabled=True, parts={"tyres": {"model": "dark_paint", "reflectivity": 0.03}, "plates": {"model": "retroreflector", "reflectivity": 50.0}})
    parts = painted(paint)
    names = car_part_names(True, CarGlass(enabled=True))
    assert names == [*PARTS, "plates", "lights", "windshield"] and len(parts) == len(names) + 1  # the upper body appended
    expected = {part: part_model(paint.spec(part), part) for part in CAR_PARTS if part != "body"}
    assert parts[names.index("tyres")].paint == expected["tyres"] and parts[names.index("plates")].paint == expected["plates"]
    assert parts[names.index("interior")].paint == expected["cabin"] and expected["cabin"].model == "dark_paint"
    assert parts[names.index("windows")].paint == parts[names.index("windshield")].paint == expected["glass"]
    assert parts[names.index("lights")].paint is None  # {}: the lamp keeps its material (glossy_paint through effects.materials)
    body, upper = parts[names.index("body")], parts[-1]
    assert upper.paint == expected["upper"] and body.paint.model == "glossy_paint" and body.paint.params.diffuse in [v[1] for v in paint.paints.values()]
    z = np.concatenate([p.vertices[:, 2] for p in parts[:4]])
    frac = lambda part: (part.vertices[part.triangles][:, :, 2].mean(axis=1) - z.min()) / np.ptp(z)  # noqa: E731
    assert np.all(frac(body) < paint.upper_from) and np.all(frac(upper) >= paint.upper_from) and len(upper.triangles) > 0
    before = object_parts(PLACEMENT, np.random.default_rng(0), "classic", CarGlass(enabled=True), True)
    assert len(body.triangles) + len(upper.triangles) == len(before[0].triangles)  # the body split, nothing lost
    for j in range(1, len(before)):  # the mesh, materials and reflectivities as before; only the model added
        assert np.array_equal(parts[j].vertices, before[j].vertices) and np.array_equal(parts[j].triangles, before[j].triangles)
        assert (parts[j].material, parts[j].reflectivity) == (before[j].material, before[j].reflectivity)


def test_disabled_paint_leaves_the_parts_as_before():
    rng = np.random.default_rng(0)
    off = object_parts(PLACEMENT, rng, "classic", CarGlass(), True, CarPaint(), car_generator(rng, 0))
    before = object_parts(PLACEMENT, np.random.default_rng(0), "classic", CarGlass(), True)
    assert len(off) == len(before) and all(p.paint is None for p in off)
    assert all(np.array_equal(a.vertices, b.vertices) and np.array_equal(a.triangles, b.triangles) and a.material == b.material for a, b in zip(off, before))
    assert RealScanScene().car_paint == CarPaint() and not CarPaint().enabled


def test_body_paint_is_drawn_per_car_seeded_and_deterministic():
    paint = CarPaint(enabled=True, paints={"black": [0.6, 0.01], "light": [0.4, 0.5]})
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    draws = [paint.draw_paint(car_generator(rng, k)) for k in range(400)]
    assert rng.bit_generator.state == state  # the frame's generator is not advanced
    again = np.random.default_rng(5)
    assert draws == [paint.draw_paint(car_generator(again, k)) for k in range(400)]  # same seed, same paints
    assert set(draws) == {0.01, 0.5}
    share = np.mean(np.array(draws) == 0.01)
    assert abs(share - 0.6) < 4 * np.sqrt(0.6 * 0.4 / 400)  # by the shares
    other = [paint.draw_paint(car_generator(np.random.default_rng(6), k)) for k in range(400)]
    assert other != draws  # another seed, other paints
    body = lambda seed: painted(paint, seed)[0].paint.params.diffuse  # noqa: E731
    assert body(3) == body(3)


def mixed(scan, paint: CarPaint):
    """The state of 000008 with one inserted car 8 m ahead (ideal effects: no drop, no noise), and its cars' painted rows."""
    section = RealScanScene(path=str(scan), format="kitti", preset="hdl64e", objects=[ObjectBox("car", (8.0, 0.5, -0.95), (4.5, 1.8, 1.5), 20.0)],
                            car_glass=CarGlass(enabled=True), car_paint=paint)
    effects = bpy_pipeline.load_config({"sensor": {"preset": "hdl64e"}, "effects": {"ideal": True}}).effects
    state = MixState(section, np.random.default_rng(0), effects, 1)
    for step in MIX_STEPS:
        step(state)
    return state


def test_a_part_named_changes_only_that_parts_points(real_scan):
    scan = real_scan("kitti_hdl64e_000008_frontfov.bin")
    base = mixed(scan, CarPaint(enabled=True))
    cabin = mixed(scan, CarPaint(enabled=True, parts={"cabin": {"model": "dark_paint", "reflectivity": 0.6}}))
    a, b = base.points, cabin.points
    assert len(a) == len(b) and np.array_equal(base.firing, cabin.firing)
    for key in ("x", "y", "z", "semantic", "instance", "ring"):
        assert np.array_equal(a[key], b[key])
    rows = np.full(len(base.firings), -1)
    rows[base.hits.firing] = base.hits.row
    row_of_point = rows[base.firing]
    interior = [r for r, name in enumerate(base.buffers.objects.names) if int(name.rsplit("_", 1)[1]) == PARTS.index("interior")]
    on_cabin = np.isin(row_of_point, interior) & base.inserted
    changed = a["intensity"] != b["intensity"]
    assert on_cabin.sum() > 0 and changed.any()
    assert np.all(on_cabin[changed])  # only the cabin's points read otherwise
    assert np.all(b["intensity"][on_cabin] >= a["intensity"][on_cabin])  # brighter (0.02 -> 0.6)
    # off: the frame of before, byte for byte
    off, named = mixed(scan, CarPaint()), mixed(scan, CarPaint(enabled=False, parts={"cabin": {"model": "dark_paint", "reflectivity": 0.6}}))
    assert off.points.tobytes() == named.points.tobytes() and all(m is None for m in off.paints)


@pytest.mark.parametrize("key, value, match", [
    ("upper_from", 1.5, r"^scene\.car_paint\.upper_from: must lie in 0\.\.1, got 1\.5$"),
    ("paints", {"black": [1.2, 0.05]}, r"^scene\.car_paint\.paints\.black: expected \[share"),
    ("parts", {"roof": {"model": "dark_paint"}}, r"^scene\.car_paint\.parts: unknown car part 'roof'|^scene\.car_paint\.parts.*roof"),
    ("parts", {"cabin": {"model": "velvet"}}, r"^scene\.car_paint\.parts\.cabin\.model: expected one of"),
    ("parts", {"upper": {"model": "glossy_paint", "lobe_deg": 500}}, r"^scene\.car_paint\.parts\.upper\.lobe_deg: must lie in"),
    ("parts", {"glass": {"model": "dark_paint", "shine": 1}}, r"^scene\.car_paint\.parts\.glass\.shine: unknown key"),
    ("parts", {"upper": {"model": "glossy_paint", "detection": 1.5}}, r"^scene\.car_paint\.parts\.upper\.detection: must be a reflectivity in 0\.\.1"),
    ("parts", {"cabin": {"model": "dark_paint", "detection": -0.1}}, r"^scene\.car_paint\.parts\.cabin\.detection: must be a reflectivity in 0\.\.1"),
    ("parts", {"glass": {"model": "wet", "detection": "bright"}}, r"^scene\.car_paint\.parts\.glass\.detection: must be a reflectivity in 0\.\.1"),
])
def test_bad_car_paint_values_are_one_line_and_exit_2(tmp_path, capsys, key, value, match):
    with pytest.raises(InputError, match=match):  # built in Python: its own rules, then its fields' ranges
        check_ranges(CarPaint(**{key: value}), "scene.car_paint")
    import json

    config = tmp_path / "c.yaml"
    config.write_text(f"scene:\n  builder: real_scan\n  path: nowhere.bin\n  car_paint: {{{key}: {json.dumps(value)}}}\n")
    try:
        code = cli.main(["run.py", "--config", str(config), "--out", str(tmp_path / "out")])
    except SystemExit as exit_:
        code = exit_.code
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and "scene.car_paint" in err[0], err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_the_default_parts_are_registered():
    assert set(DEFAULT_PARTS) == set(CAR_PARTS)  # one place names the parts
    for part in CAR_PARTS:
        part_model(DEFAULT_PARTS[part], part, 0.1)


def far_dark_returns(n: int = 2000):
    """n returns of one part 30 m away at cos 0.9, reflectivity 0.01, on 64 lasers; the hdl64e profile's drop model and
    the fitted reading model (scale 4.5, offset 0.15, range-compensated to 28 m)."""
    from bpy_pipeline.lidar.points import BEAM_DTYPE, POINT_DTYPE

    points = np.zeros(n, POINT_DTYPE)
    points["x"], points["range"], points["ring"] = 30.0, 30.0, np.arange(n) % 64
    beam = np.zeros(n, BEAM_DTYPE)
    beam["cos_incidence"], beam["reflectivity"], beam["gain"], beam["direction"] = 0.9, 0.01, 1.0, [1.0, 0.0, 0.0]
    # KITTI 000008's linear reading
    reading = {"enabled": True, "response": 1.0, "compensated_range": 28.0, "exponent": 2.0, "gain_sd": 0.16, "noise_sd": 0.075}
    effects = bpy_pipeline.load_config({"sensor": {"preset": "hdl64e"}, "effects": {"intensity": {"scale": 4.5, "offset": 0.15, "reading": reading}}}).effects
    return points, beam, effects


def test_a_part_dark_to_read_but_detectable_is_kept_at_30_m_and_reads_0():
    from bpy_pipeline.mixing.frame import _effects
    from bpy_pipeline.mixing.paint import detection_reflectivity

    points, beam, effects = far_dark_returns()
    rows = np.zeros(len(points), np.int64)
    dark = part_model({"model": "dark_paint", "reflectivity": 0.01}, "p")
    seen = part_model({"model": "dark_paint", "reflectivity": 0.01, "detection": 0.3}, "p")
    assert dark.detection is None and seen.detection == 0.3 and detection_reflectivity(beam, rows, [dark]) is None
    floor = detection_reflectivity(beam, rows, [seen])
    assert floor.dtype == np.float32 and np.all(floor == np.float32(0.3))
    # max(own, detection)
    assert np.all(detection_reflectivity(beam, rows, [part_model({"model": "dark_paint", "reflectivity": 0.01, "detection": 0.001}, "p")]) == np.float32(0.01))
    lost, _ = _effects(points.copy(), beam.copy(), effects, np.random.default_rng(0), None, [dark], rows)
    kept, kept_rows = _effects(points.copy(), beam.copy(), effects, np.random.default_rng(0), None, [seen], rows)
    assert len(lost) < 0.1 * len(points)  # as dark to the drop model as to the reading: dropped at 30 m
    assert len(kept) > 0.9 * len(points)  # the detection reflectivity keeps it ...
    assert np.all(kept["intensity"] == 0)  # ... and it still reads 0 (4.5 * 0.01 < 0.15)
    brighter = replace_reflectivity(beam, 0.3)
    read, _ = _effects(points.copy(), brighter, effects, np.random.default_rng(0), None, [part_model({"model": "dark_paint", "reflectivity": 0.3}, "p")], rows)
    assert np.mean(read["intensity"] > 0) > 0.9  # a part as bright as the detection value reads above 0: the reading is the part's own
    again, again_rows = _effects(points.copy(), beam.copy(), effects, np.random.default_rng(0), None, [seen], rows)
    assert again.tobytes() == kept.tobytes() and np.array_equal(again_rows, kept_rows)  # same seed, same bytes
    other, _ = _effects(points.copy(), beam.copy(), effects, np.random.default_rng(1), None, [seen], rows)
    assert other.tobytes() != kept.tobytes()  # another seed, other draws


def replace_reflectivity(beam, value):
    out = beam.copy()
    out["reflectivity"] = value
    return out


def test_detection_unset_leaves_the_frame_byte_identical(real_scan):
    scan = real_scan("kitti_hdl64e_000008_frontfov.bin")
    section = RealScanScene(path=str(scan), format="kitti", preset="hdl64e", objects=[ObjectBox("car", (8.0, 0.5, -0.95), (4.5, 1.8, 1.5), 20.0)],
                            car_glass=CarGlass(enabled=True), car_paint=CarPaint(enabled=True))
    # KITTI 000008's linear reading
    reading = {"enabled": True, "response": 1.0, "compensated_range": 28.0, "exponent": 2.0, "gain_sd": 0.16, "noise_sd": 0.075}
    effects = bpy_pipeline.load_config({"sensor": {"preset": "hdl64e"}, "effects": {"intensity": {"scale": 4.5, "offset": 0.15, "reading": reading}}}).effects

    def run(paint):
        state = MixState(replace(section, car_paint=paint), np.random.default_rng(0), effects, 1)
        for step in MIX_STEPS:
            step(state)
        return state.points

    base = run(CarPaint(enabled=True))
    zero = run(CarPaint(enabled=True, parts={"cabin": {**DEFAULT_PARTS["cabin"], "detection": 0.0}}))  # max(own, 0): nothing changes
    assert base.tobytes() == zero.tobytes()
    assert run(CarPaint(enabled=True)).tobytes() == base.tobytes()
