"""Car glass and cabins at 905 nm (lidar/effects/materials.py CarGlass, scene.car_glass of the real_scan builder): Fresnel and
tint against their closed forms, a pane in the trace passing beams with its round-trip transmission, an inserted car's
windows letting fewer beams through at oblique incidence, the default, and bad values."""

import math

import numpy as np
import pytest

from bpy_pipeline import cli
from bpy_pipeline.buffers import ObjectTable, SceneBuffers
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.objects import PARTS, ObjectPart, car_object
from bpy_pipeline.lidar.effects.materials import CarGlass, fresnel_reflectance, glass_round_trip, glass_transmission, pane_internal, pane_transmission
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.scanner import MirrorGlassRules, trace_beams
from bpy_pipeline.mixing.cast import glass_rules, object_buffers, object_parts
from bpy_pipeline.mixing.placement import Placement
from bpy_pipeline.mixing.section import RealScanScene
from bpy_pipeline.schema import check_ranges


def test_fresnel_and_tint_against_their_closed_forms():
    n = 1.52
    assert fresnel_reflectance([1.0], n)[0] == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-12)  # 4.26 %
    i = np.radians([10.0, 30.0, 45.0, 60.0, 80.0])
    t = np.arcsin(np.sin(i) / n)
    rs, rp = np.sin(i - t) ** 2 / np.sin(i + t) ** 2, np.tan(i - t) ** 2 / np.tan(i + t) ** 2  # the sine and tangent forms
    np.testing.assert_allclose(fresnel_reflectance(np.cos(i), n), (rs + rp) / 2, rtol=1e-10)
    brewster = math.atan(n)
    assert fresnel_reflectance([math.cos(brewster)], n)[0] == pytest.approx(0.5 * math.cos(2 * brewster) ** 2, rel=1e-9)  # rp = 0, rs = cos^2(2 i_B)
    assert fresnel_reflectance([0.0], n)[0] == 1.0  # grazing: everything reflects
    # a pane: two surfaces, and the tint along the refracted path (1 / cos t of the normal's thickness)
    np.testing.assert_allclose(pane_transmission(np.cos(i), 0.4, n), (1 - (rs + rp) / 2) ** 2 * 0.4 ** (1 / np.cos(t)), rtol=1e-10)
    assert pane_transmission([1.0], 1.0, n)[0] == pytest.approx((1 - 0.0426) ** 2, abs=1e-4)  # clear glass: 91.7 %
    np.testing.assert_allclose(glass_round_trip(np.cos(i), 0.4, n), pane_transmission(np.cos(i), 0.4, n) ** 2)
    assert np.all(np.diff(glass_round_trip(np.cos(np.radians([0, 30, 60, 75, 85])), 0.5)) < 0)  # falls with incidence


def one_pane(tau: float):
    """A 4 x 4 m pane at x = 5 (normal x) in front of a diffuse wall at x = 8, as scene buffers; the pane's rules."""
    quad = np.array([[0, -2, -2], [0, 2, -2], [0, 2, 2], [0, -2, 2]], float)
    tri = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    vertices = np.concatenate([quad + [5, 0, 0], quad * [1, 20, 20] + [8, 0, 0]])
    table = ObjectTable(["pane", "wall"], ["", ""], ["car", "wall"], np.array([1, 2], np.uint16), np.array([1, 2], np.uint32),
                        np.array([2, 0], np.uint8), np.array([0.08, 0.5], np.float32))  # glass, diffuse
    buffers = SceneBuffers(vertices, np.concatenate([tri, tri + 4]), np.array([0, 0, 1, 1], np.int32), table)
    glass = CarGlass(tinted=tau)
    rules = MirrorGlassRules(glass_transmission=glass_transmission(pane_internal(["tinted_glass", "diffuse"], glass), glass))
    return buffers, rules


@pytest.mark.parametrize("incidence_deg", [0.0, 40.0, 70.0])
def test_a_pane_passes_beams_with_its_round_trip_transmission(incidence_deg):
    buffers, rules = one_pane(0.5)
    n = 20000
    a = math.radians(incidence_deg)
    d = np.tile([math.cos(a), math.sin(a), 0.0], (n, 1))
    origin = np.array([5.0, 0.0, 0.0]) - 2.0 * d[0]  # every beam meets the pane at its centre
    beams = trace_beams(RayCaster(buffers, frame=np.eye(4)), buffers, origin, d, 0.0, 100.0, surfaces=rules, rng=np.random.default_rng(3))
    expected = glass_round_trip([math.cos(a)], 0.5)[0]
    share = len(beams.ray) / n
    assert abs(share - expected) <= 4 * math.sqrt(expected * (1 - expected) / n), (share, expected)
    assert np.all(buffers.triangle_object[beams.triangle] == 1) and np.all(beams.gain == 1.0)  # on the wall, gain unchanged
    before = trace_beams(RayCaster(buffers, frame=np.eye(4)), buffers, origin, d, 0.0, 100.0)
    assert len(before.ray) == n and np.allclose(before.gain, 0.92)  # no model: every beam passes, gain 1 - reflectivity


def car_through_side_window(incidence_deg: float, glass: CarGlass | None, n: int = 4000) -> float:
    """Share of beams aimed at an inserted car's side window centre (8 m off, ``incidence_deg`` from its normal in the
    ground plane) that come back from anything (a diffuse wall 3 m beyond the car's centre stops every beam)."""
    placement = Placement("car", "car", np.zeros(3), np.array([4.5, 1.8, 1.5]), 0.0)
    wall = ObjectPart(np.array([[-40, -3, -5], [40, -3, -5], [40, -3, 5], [-40, -3, 5]], float), np.array([[0, 1, 2], [0, 2, 3]], np.int32), "diffuse", 0.5)
    parts = [object_parts(placement, np.random.default_rng(0), "classic", glass) + [wall]]
    buffers = object_buffers([placement], parts, [1], [1])
    side = parts[0][PARTS.index("windows")]
    corners = side.vertices[side.triangles]
    left = corners[:, :, 1].mean(axis=1) > 0.3  # the left side's panes (normal +y)
    aim = corners[left].mean(axis=(0, 1)) + [0.05, 0.0, 0.0]
    a = math.radians(incidence_deg)
    d = np.tile([math.sin(a), -math.cos(a), 0.0], (n, 1))
    beams = trace_beams(RayCaster(buffers, frame=np.eye(4)), buffers, aim - 8.0 * d[0], d, 0.0, 100.0, surfaces=glass_rules(parts, glass),
                        rng=np.random.default_rng(1))
    return len(beams.ray) / n


def test_an_inserted_cars_window_lets_fewer_returns_through_at_oblique_incidence():
    glass = CarGlass(enabled=True)
    normal, oblique = car_through_side_window(5.0, glass), car_through_side_window(70.0, glass)
    assert oblique < 0.6 * normal, (normal, oblique)
    assert normal <= glass_round_trip([math.cos(math.radians(5.0))], glass.tinted)[0] + 0.03  # no more than the first pane lets back
    # the windows of before: every beam passes whatever the angle, and the cabin, the far side or the wall returns it
    assert car_through_side_window(5.0, CarGlass(enabled=False)) == 1.0 and car_through_side_window(70.0, CarGlass(enabled=False)) == 1.0


def test_the_default_for_inserted_cars_and_builder_cars_unchanged():
    # the default (benchmarks/bench_materials.py --insertion): plates and lamps on; the glass model opt-in (on the held-out
    # frame it put no more cars within 0.7-1.4x), its fitted values ready
    section = RealScanScene()
    assert section.car_glass == CarGlass() and not section.car_glass.enabled and section.car_fittings
    placement = Placement("car", "car", np.zeros(3), np.array([4.5, 1.8, 1.5]), 0.0)
    default = object_parts(placement, np.random.default_rng(0), "classic", section.car_glass, section.car_fittings)
    assert [p.material for p in default] == ["diffuse", "glass", "diffuse", "diffuse", "retroreflector", "glossy_paint"]
    assert glass_rules([default], section.car_glass).glass_transmission is None
    assert len(object_buffers([placement], [default], [1], [1]).objects.surface) == 6  # the plate's and lamps' models ride along
    parts = object_parts(placement, np.random.default_rng(0), "classic", CarGlass(enabled=True), True)
    names = [p.material for p in parts]
    assert names[: len(PARTS)] == ["diffuse", "tinted_glass", "diffuse", "diffuse"] and "windshield_glass" in names
    assert parts[PARTS.index("interior")].reflectivity == CarGlass().interior
    windshield = parts[names.index("windshield_glass")]
    normals = np.cross(*(windshield.vertices[windshield.triangles][:, k] - windshield.vertices[windshield.triangles][:, 0] for k in (1, 2)))
    assert np.all(np.abs(normals[:, 0]) > np.abs(normals[:, 1]))  # the front pane only
    # the same draws: the car's body and paint are those of before; disabled: the parts of before, byte for byte
    before = car_object(np.random.default_rng(0), placement.size)
    assert parts[0].reflectivity == before[0].reflectivity and np.array_equal(parts[0].vertices, before[0].vertices)
    off = object_parts(placement, np.random.default_rng(0), "classic", CarGlass(enabled=False))
    assert [p.material for p in off] == ["diffuse", "glass", "diffuse",
                                         "diffuse"] and all(np.array_equal(a.triangles, b.triangles) for a, b in zip(off, before))
    # builders' cars (geometry/objects.py car_object without the insertion's glass) keep plain glass and their cabin
    assert [p.material for p in before] == ["diffuse", "glass", "diffuse", "diffuse"]


@pytest.mark.parametrize("key, value", [("tinted", 1.5), ("windshield", -0.1), ("interior", "dark"), ("index", 0.5)])
def test_bad_car_glass_values_are_one_line_and_exit_2(tmp_path, capsys, key, value):
    with pytest.raises(InputError, match=rf"^scene\.car_glass\.{key}: (must lie in|expected a number)"):  # built in Python
        check_ranges(CarGlass(**{key: value}), "scene.car_glass")
    config = tmp_path / "c.yaml"
    config.write_text(f"scene:\n  builder: real_scan\n  path: nowhere.bin\n  car_glass: {{{key}: {value!r}}}\n".replace("'", '"'))
    try:
        code = cli.main(["run.py", "--config", str(config), "--out", str(tmp_path / "out")])
    except SystemExit as exit_:
        code = exit_.code
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and f"scene.car_glass.{key}" in err[0], err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
