"""Builders never crash on a seed and never put the sensor inside a solid (issue 51, part 7).

The property tests build every builder's pure layout (no Blender) over 1,000 seeds, each seed drawing random valid
parameters and sensor poses (tests/layout_cases.py), and assert its invariants: no exception, no intersecting solids,
no solid within 0.5 m of any sensor pose. A loop over seeds, so every run checks the same 1,000 cases. The
distance functions the builders keep clear with are checked against brute force by hypothesis (derandomized).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import layout_cases
from bpy_pipeline.geometry.clearance import SensorPoses, enclosing_instance, sample_path

SEEDS = range(1000)
REFUSED_AT_MOST = 0.5  # of a builder's drawn cases may be refused by its check (so the property is not vacuous)


def check_seeds(builder: str, seeds: range) -> None:
    """Every seed of ``seeds`` builds ``builder``'s layout with its invariants (an exception fails, naming the seed in
    its traceback); at most :data:`REFUSED_AT_MOST` of them are refused by the builder's check."""
    case = layout_cases.CASES[builder]
    broken, refused = {}, 0
    for seed in seeds:
        lines = case(seed)
        if lines is None:
            refused += 1
        elif lines:
            broken[seed] = lines
    assert not broken, f"{len(broken)} of {len(seeds)} seeds break {builder}'s invariants, e.g. {dict(list(broken.items())[:3])}"
    assert refused <= REFUSED_AT_MOST * len(seeds), f"{builder}: {refused} of {len(seeds)} drawn cases refused; the drawn parameters miss what it builds"


@pytest.mark.slow  # 1,000 seeds a builder: about 40 s of CPU for the five
@pytest.mark.parametrize("builder", sorted(layout_cases.CASES))
def test_every_builder_builds_every_seed_with_its_invariants(builder):
    check_seeds(builder, SEEDS)


@pytest.mark.parametrize("builder", sorted(layout_cases.CASES))
def test_every_builder_builds_its_first_seeds_with_its_invariants(builder):
    """The fast lane's share of the property test above: its first 20 seeds."""
    check_seeds(builder, range(20))


def test_street_layout_seeds_13_and_188_build():
    """The issue's two seeds (every other key at its default) drew a yard's plants from an empty range."""
    from bpy_pipeline.builders.street.layout import street_layout
    from bpy_pipeline.builders.street.params import StreetScene

    for seed in (13, 188):
        layout = street_layout(StreetScene(layout_seed=seed), np.random.default_rng(seed))
        assert layout.yards.rects and all(x0 <= x1 and y0 <= y1 for x0, x1, y0, y1 in layout.yards.rects)


def test_a_trajectory_along_a_lane_keeps_every_road_user_clear_of_the_sensor():
    """The issue's run: a trajectory along a lane, height 1.73, layout seed 11. With run seed 1, frame 0's sensor stood
    inside a truck (all 133,200 returns on it, before this rule). Now no road user of any frame comes within 0.5 m of
    the path the run's sensor takes."""
    import bpy_pipeline as bp
    from bpy_pipeline.builders.street.layout import NO_POSES, place_users, street_layout
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.view import sensor_poses

    config = bp.load_config({"seed": 1, "scene": {"builder": "street", "layout_seed": 11}, "frames": 20,
                             "sensor": {"preset": "hdl64e", "trajectory": {"waypoints": [[1.75, -38, 0], [1.75, 38, 0]], "height": 1.73, "speed": 10.0}}})
    poses = sensor_poses(config)
    assert poses.step > 0 and np.allclose(poses.points[:, [0, 2]], [1.75, 1.73]) and poses.points[:, 1].min() == -38.0
    start = SensorPoses(poses.points[poses.points[:, 1] == -38.0])
    params = config.scene.params
    inside, near = {}, {}
    for clear in (NO_POSES, poses):
        layout = street_layout(params, np.random.default_rng(params.layout_seed), clear)
        frames = [place_users(params, layout, frame_rng(config.seed, f), clear=clear).users for f in range(config.frames)]
        inside[clear is poses] = [u.kind for u in frames[0] if start.box_distance(u.centre, u.half, u.yaw, u.z, u.z + u.size[2]) == 0.0]
        near[clear is poses] = sum(poses.box_distance(u.centre, u.half, u.yaw, u.z, u.z + u.size[2]) < 0.5 for users in frames for u in users)
    assert inside[False] == ["truck"] and near[False] > 0  # without the rule: the sensor inside a truck, users on its path
    assert inside[True] == [] and near[True] == 0


def test_sensor_poses_of_a_run_hold_every_frame_and_rig_member():
    import bpy_pipeline as bp
    from bpy_pipeline.stages.view import sensor_pose, sensor_poses

    parking = bp.load_config({"scene": {"builder": "parking"}, "frames": 5})
    expected = np.array([sensor_pose(parking, f)[:3, 3] for f in range(5)])
    assert np.allclose(np.sort(sensor_poses(parking).points, axis=0), np.sort(expected, axis=0))
    street = bp.load_config({"scene": {"builder": "street"}, "frames": 2})  # the builder's rig of three flash cameras
    members = street.sensor.rig
    poses = sensor_poses(street).points
    want = {tuple(np.round((sensor_pose(street, f) @ m.matrix())[:3, 3], 6)) for f in range(2) for m in members}
    assert {tuple(p) for p in np.round(poses, 6)} == want


# ----------------------------------------------------------------------------- the distances, against brute force
def _surface_samples(centre, half, yaw, z0, z1, n=21):
    """Points filling an upright box (its surface and inside), for a brute-force distance."""
    g = np.linspace(-1.0, 1.0, n)
    a, b, c = np.meshgrid(g, g, np.linspace(0.0, 1.0, n), indexing="ij")
    local = np.column_stack([a.ravel() * half[0], b.ravel() * half[1]])
    cy, sy = math.cos(yaw), math.sin(yaw)
    xy = local @ np.array([[cy, sy], [-sy, cy]]) + centre
    return np.column_stack([xy, z0 + c.ravel() * (z1 - z0)])


coordinate = st.floats(-5.0, 5.0, allow_nan=False)
size = st.floats(0.05, 3.0, allow_nan=False)


@settings(derandomize=True, max_examples=150, deadline=None)
@given(st.tuples(coordinate, coordinate, coordinate), st.tuples(coordinate, coordinate), st.tuples(size, size), st.floats(-math.pi, math.pi),
       st.floats(-1.0, 1.0), size)
def test_box_distance_is_the_distance_to_the_nearest_point_of_the_box(point, centre, half, yaw, z0, height):
    poses = SensorPoses(np.array([point]))
    got = poses.box_distance(centre, half, yaw, z0, z0 + height)
    samples = _surface_samples(np.array(centre), np.array(half), yaw, z0, z0 + height)
    brute = np.linalg.norm(samples - point, axis=1).min()
    spacing = 2.0 * max(*half, height) / 20  # the samples' grid step bounds their error
    assert got <= brute + 1e-9 and got >= brute - spacing


@settings(derandomize=True, max_examples=150, deadline=None)
@given(st.tuples(coordinate, coordinate, coordinate), st.tuples(coordinate, coordinate, coordinate), st.tuples(coordinate, coordinate, coordinate), size)
def test_capsule_distance_is_the_distance_to_the_capsule(point, a, b, radius):
    poses = SensorPoses(np.array([point]))
    t = np.linspace(0.0, 1.0, 2001)[:, None]
    axis = np.array(a) + t * (np.array(b) - np.array(a))
    brute = max(np.linalg.norm(axis - point, axis=1).min() - radius, 0.0)
    assert poses.capsule_distance([a], [b], [radius]) == pytest.approx(brute, abs=np.linalg.norm(np.subtract(b, a)) / 2000 + 1e-9)


@settings(derandomize=True, max_examples=100, deadline=None)
@given(st.lists(st.tuples(coordinate, coordinate, coordinate), min_size=2, max_size=6), st.floats(0.05, 1.0))
def test_a_sampled_path_keeps_its_corners_and_no_gap_wider_than_the_step(corners, step):
    corners = np.array(corners)
    path = sample_path(corners, step)
    assert np.linalg.norm(np.diff(path, axis=0), axis=1).max() <= step + 1e-9
    for corner in corners:
        assert np.linalg.norm(path - corner, axis=1).min() < 1e-9


def test_a_solid_clear_of_the_samples_keeps_the_radius_from_the_whole_path():
    path = np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 1.0]])
    poses = SensorPoses(sample_path(path, 0.4), step=0.4)
    assert poses.reach == pytest.approx(0.7)
    # a thin post between two samples, 0.55 m beside the path: 0.55 m from the path, but more from each sample
    assert not poses.clear_of_circle((0.2, 0.6), 0.05)
    assert poses.clear_of_circle((0.2, 0.75), 0.05)


# ----------------------------------------------------------------------------- a scan from inside a solid
def test_a_scan_from_inside_one_object_is_enclosed_and_an_open_scan_is_not():
    rng = np.random.default_rng(0)
    rays = 10000
    inside = enclosing_instance(rng.uniform(0.5, 2.5, rays), np.full(rays, 7), rays)  # every ray on instance 7, metres away
    assert inside == (7, 1.0)
    road = enclosing_instance(rng.uniform(2.0, 60.0, 6000), np.full(6000, 1), rays)  # an open street: 60 % hit, far
    assert road is None
    floor = enclosing_instance(rng.uniform(4.5, 6.0, rays), np.full(rays, 1), rays)  # a hall's floor below an overhead sensor
    assert floor is None
    mixed = enclosing_instance(rng.uniform(0.5, 2.0, rays), rng.integers(1, 4, rays), rays)  # a small room of three objects
    assert mixed is None
    fog = enclosing_instance(rng.uniform(0.5, 2.0, rays), np.zeros(rays, np.uint32), rays)  # dense fog: returns of no object
    assert fog is None
    ranges = np.float32(np.nextafter(np.float32(3.0), np.float32(0.0))) + np.zeros(rays, np.float32)  # float32 records, just under 3 m
    assert enclosing_instance(ranges, np.full(rays, 7), rays) == (7, 1.0)
    assert enclosing_instance(ranges, np.full(rays, 7), rays, near=float(ranges[0])) is None  # compared in float32 where exact
    assert enclosing_instance(ranges, np.full(rays, 7), rays, near=2.9999998) == (7, 1.0)  # in float64 where not (float32 rounds it to the ranges)


@pytest.mark.slow
@pytest.mark.bpy
def test_a_frame_whose_sensor_stands_inside_a_box_is_warned_about_with_its_index(tmp_path):
    import bpy_pipeline as bp

    shapes = [{"type": "plane", "size": [40, 40], "class": "ground", "name": "ground"},
              {"type": "box", "size": [4, 3, 3], "position": [0, 0, 1.5], "class": "bus", "name": "bus_around_the_sensor"}]
    lines = []
    config = bp.load_config({"scene": {"builder": "primitives", "shapes": shapes}, "sensor": {"preset": "vlp16", "position": [0, 0, 1.5]}, "frames": 1})
    bp.run(config, tmp_path / "inside", log=lines.append)
    warned = [line for line in lines if "enclosed" in line]
    assert len(warned) == 1 and warned[0].startswith("warning: frame 0: ") and "bus_around_the_sensor" in warned[0], lines
    lines.clear()
    bp.run(bp.load_config({"scene": {"builder": "primitives"}, "sensor": {"preset": "vlp16", "position": [0, 0, 1.5]}, "frames": 1}), tmp_path / "open",
           log=lines.append)
    assert not [line for line in lines if "enclosed" in line], lines
