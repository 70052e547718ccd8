"""The street's junction kinds (``scene.junction_mix``): a four-arm intersection, a T-junction and a straight street.

Pure layout tests (no Blender): each kind builds with its arms, a straight street has no road along y and parked cars
line both its sides at the four-arm street's density per metre, the missing arm's corner becomes plots and ground,
the kind is drawn per ``layout_seed`` and the same seed gives the same bytes; bad shares fail in one line. With
Blender: each kind's street is built and exported as its pure parts.
"""

import dataclasses
import hashlib

import numpy as np
import pytest

from bpy_pipeline.builders.street import layout as street
from bpy_pipeline.builders.street.params import StreetScene, check
from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.placement import Distribution

KINDS = tuple(street.JUNCTIONS)
BUSY = dict(vehicles=Distribution("normal", 16.0, 0.0, 0.0, 40.0), parked=Distribution("normal", 40.0, 0.0, 0.0, 80.0),
            pedestrians=Distribution("normal", 16.0, 0.0, 0.0, 40.0))


def _street(kind: str, seed: int = 0, **changes):
    params = StreetScene(junction_mix={kind: 1.0}, layout_seed=seed, **(BUSY | changes))
    check(params, "scene")
    return params, street.street_layout(params, np.random.default_rng(seed))


def _part(layout, name):
    return next(p for p in layout.parts if p.name == name)


def test_the_default_is_the_four_arm_intersection_for_every_seed():
    assert StreetScene().junction_mix == {"cross": 1.0}
    assert {street.junction(StreetScene(layout_seed=seed)) for seed in range(30)} == {street.FOUR_ARMS}


def test_the_kind_is_drawn_per_layout_seed_by_its_shares():
    mix = {"straight": 0.5, "t_junction": 0.25, "cross": 0.25}
    drawn = [street.junction(StreetScene(junction_mix=mix, layout_seed=seed)) for seed in range(200)]
    assert drawn == [street.junction(StreetScene(junction_mix=mix, layout_seed=seed)) for seed in range(200)]
    counts = {kind: sum(j.kind == kind for j in drawn) for kind in KINDS}
    assert 70 <= counts["straight"] <= 130 and 25 <= counts["t_junction"] <= 75 and 25 <= counts["cross"] <= 75, counts
    assert {j.arms for j in drawn if j.kind == "t_junction"} == {(-1,), (1,)}  # a T-junction's arm on either side
    assert {street.junction(StreetScene(junction_mix={"straight": 1.0, "cross": 0.0}, layout_seed=s)).kind for s in range(20)} == {"straight"}


@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_builds_its_arms(kind):
    params, layout = _street(kind)
    j = layout.junction
    assert j.kind == kind and len(j.arms) == {"cross": 2, "t_junction": 1, "straight": 0}[kind]
    R, A = layout.half_road, params.arm_length
    road = _part(layout, "street_road").mesh[0]
    for sign in (-1, 1):
        reaches = (road[:, 1] * sign > R + 1.0).any()
        assert reaches == (sign in j.arms)  # the road along y only where the junction has its arm
        assert layout.on_road((0.0, sign * (R + 1.0))) == (sign in j.arms)
    assert layout.on_road((A - 1.0, 0.0)) and layout.on_road((-A + 1.0, 0.0))  # the road along x whole in every kind
    lights = [p for p in layout.parts if p.class_name == "traffic light"]
    assert len(lights) == 2 * len(j.arms)  # at the corners beside the road along y's arms: none without one
    assert len(layout.crossings) == len(j.crossings) == {"cross": 4, "t_junction": 3, "straight": 1}[kind]
    for lane in layout.lanes:
        assert lane.road == 0 or {np.sign(lane.start[1]), np.sign(lane.end[1])} <= set(j.arms)
        for s in np.linspace(0.0, lane.length, 9):
            assert layout.on_road(lane.at(s))


def test_a_straight_street_has_no_road_along_y():
    params, layout = _street("straight")
    R, inner = layout.half_road, layout.walk_inner
    assert not [lane for lane in layout.lanes if lane.road == 1]
    for name in ("street_road", "street_kerbs", "street_sidewalks"):
        assert (np.abs(_part(layout, name).mesh[0][:, 1]) <= layout.walk_outer + 1e-9).all(), name
    assert np.abs(_part(layout, "street_road").mesh[0][:, 1]).max() == pytest.approx(R)
    assert len(layout.walks) == 2 and all(x0 == -params.arm_length and x1 == params.arm_length for x0, x1, _, _ in layout.walks)
    assert layout.on_sidewalk((0.0, inner + 1.0)) and layout.on_sidewalk((0.0, -inner - 1.0))  # the sidewalks run through
    assert [(axis, sign) for axis, sign, _, _ in layout.crossings] == [(0, 1)]  # one mid-block zebra crossing


def test_parked_cars_line_both_sides_of_a_straight_street_at_the_four_arm_density():
    params, layout = _street("straight")
    _, four = _street("cross")
    strips = [lane for lane in layout.lanes if lane.kind == "parking"]
    assert {np.sign(lane.start[1]) for lane in strips} == {-1.0, 1.0}
    length = sum(lane.length for lane in strips)
    four_length = sum(lane.length for lane in four.lanes if lane.kind == "parking")
    assert layout.scale["parking"] == pytest.approx(length / four_length) and 0.4 < layout.scale["parking"] < 0.7
    sides = {-1: [], 1: []}
    for frame in range(3):
        placement = street.place_users(params, layout, np.random.default_rng([7, frame]))
        assert placement.wanted["parked"] == round(40 * layout.scale["parking"])  # as many per metre as with four arms
        for user in placement.users:
            if user.where.startswith("parking:"):
                sides[int(np.sign(user.centre[1]))].append(user.centre[0])
    for side, xs in sides.items():
        assert len(xs) >= 15, side
        assert min(xs) < -params.arm_length / 2 and max(xs) > params.arm_length / 2, side  # along the whole street


@pytest.mark.parametrize("kind", ["t_junction", "straight"])
def test_where_the_arm_is_missing_the_blocks_hold_plots_and_ground(kind):
    params, layout = _street(kind, seed=1)
    missing = [sign for sign in (-1, 1) if sign not in layout.junction.arms]
    outer = layout.walk_outer
    terrain = np.concatenate([p.mesh[0] for p in layout.parts if p.class_name == "terrain"])
    for sign in missing:
        near = terrain[(np.abs(terrain[:, 0]) < 2.0) & (terrain[:, 1] * sign > outer + 5.0)]
        assert len(near), sign  # ground where the arm would be, no hole
        through = [(x0, x1) for x0, x1, y0, y1 in layout.yards.rects if y0 * sign > 0 and min(abs(x0), abs(x1)) <= 1.0 + 1e-9]
        assert len(through) == 2, sign  # the plots along the road along x run through x = 0, from either side
    assert not (np.abs(terrain[:, :2]) < [layout.walk_outer - 1e-9, layout.walk_outer - 1e-9]).all(axis=1).any()  # none on the roads


def _digest(kind: str, seed: int) -> str:
    params, layout = _street(kind, seed)
    h = hashlib.sha256()
    for part in layout.parts:
        h.update(part.name.encode() + part.mesh[0].tobytes() + part.mesh[1].tobytes())
    for user in street.place_users(params, layout, np.random.default_rng([3, seed])).users:
        h.update(user.kind.encode() + user.centre.tobytes() + user.size.tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("kind", KINDS)
def test_same_seed_same_bytes(kind):
    assert _digest(kind, 2) == _digest(kind, 2)
    assert _digest(kind, 2) != _digest(kind, 3)


@pytest.mark.parametrize("mix", [{}, {"roundabout": 1.0}, {"cross": -1.0}, {"cross": 0.0, "straight": 0}, {"straight": "a"}, ["cross"]])
def test_bad_shares_fail_in_one_line_naming_the_key(mix):
    with pytest.raises(InputError, match=r"^scene\.junction_mix: expected shares >= 0 \(not all 0\) of cross, t_junction, straight, got"):
        check(dataclasses.replace(StreetScene(), junction_mix=mix), "scene")


def test_the_mix_is_set_from_the_command_line():
    config = load_config({"scene": {"builder": "street"}}, ["scene.junction_mix={straight: 1, t_junction: 0.5}"])
    assert config.scene.params.junction_mix == {"straight": 1, "t_junction": 0.5}


@pytest.mark.bpy
@pytest.mark.parametrize("kind", ["t_junction", "straight"])
def test_blender_builds_each_kind_as_its_pure_parts(kind):
    """The street of each kind built with the bpy module (its "Street Road" group at the kind's Junction) exports
    every static part with the pure layout's class and triangle count, and the swept parts at its vertices."""
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.stages.scene import build_frame_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config({"seed": 0, "frames": 1, "scene": {"builder": "street", "junction_mix": {kind: 1.0}, "layout_seed": 1},
                          "output": {"formats": ["ply"], "preview": False}})
    build_frame_scene(config, 0)
    params = config.scene.params
    layout = street.street_layout(params, np.random.default_rng(params.layout_seed))
    assert layout.junction.kind == kind
    buffers = export_scene(load_class_table())
    objects = buffers.objects
    for part in layout.parts:
        if part.scatter is not None:
            continue  # instanced: tests/test_street_nodes.py
        r = objects.names.index(part.name)
        assert objects.class_names[r] == part.class_name, part.name
        t = buffers.triangles[buffers.triangle_object == r]
        assert len(t) == len(part.mesh[1]), part.name
        if part.name in ("street_road", "street_kerbs", "street_sidewalks"):
            got = np.unique(np.round(buffers.vertices[np.unique(t)], 3), axis=0)
            assert np.array_equal(got, np.unique(np.round(part.mesh[0], 3), axis=0)), part.name
