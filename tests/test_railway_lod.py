"""Detail follows a moving sensor: wires and ballast graded by the distance to the sensor's path over the whole run."""

import math

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.builders.railway import catenary
from bpy_pipeline.geometry.lod import PathView, PlannedPath, section_error
from bpy_pipeline.builders.railway.layout import STONE_STRETCH, level_of_detail, plan
from bpy_pipeline.stages.view import scene_view

LINE = ["scene.track.start=[0, 0, 0]", "scene.track.mid=[300, 0, 0]", "scene.track.end=[600, 0, 0]", "scene.track.tracks=2"]


def mobile(speed=25.0, frames=4, *overrides):
    """A profiler on a train roof from x = 100 m, its path given as waypoints along the line."""
    return load_config(None, [*LINE, "sensor.preset=railway_profiler", f"frames={frames}",
                              f"sensor.trajectory={{waypoints: [[100, 0, 0], [600, 0, 0]], speed: {speed}, height: 4.2}}", *overrides])


def test_path_distance_is_to_the_nearest_point_of_the_polyline():
    rng = np.random.default_rng(1)
    path = np.cumsum(rng.normal(size=(6, 3)) * 5, axis=0)
    view = PathView(path, 0.001, 100.0)
    dense = view.samples(0.002)
    points = rng.normal(size=(40, 3)) * 10
    brute = np.sqrt(((points[:, None] - dense[None]) ** 2).sum(-1)).min(1)
    assert np.allclose(view.distance(points), brute, atol=1e-3)
    a, b = points[:20], points[20:]
    t = np.linspace(0, 1, 4001)[:, None]
    brute = [view.distance(a[i] + t * (b[i] - a[i])).min() for i in range(20)]  # the nearest of its points (checked above)
    assert np.allclose(view.segment_distance(a, b), brute, atol=5e-3)
    assert (view.segment_distance(a, b) <= np.array(brute) + 1e-9).all()
    assert view.distance([path[2]])[0] == pytest.approx(0.0, abs=1e-12)  # a vertex lies on it; a static view of the vertices only:
    midway = (path[2] + path[3]) / 2
    assert view.distance([midway])[0] == pytest.approx(0.0, abs=1e-9)
    # a straight path and wires along it: parallel, collinear and point-like segments
    straight = PathView(np.array([[5.0, 0, 0], [20, 0, 0]]), 0.001, 100.0)
    assert straight.segment_distance([[0, 1, 0], [0, 0, 0], [0, 0, 0], [-3, 0, 4]],
                                     [[10, 1, 0], [1, 0, 0], [-4, 0, 0], [-3, 0, 4]]).tolist() == pytest.approx([1, 4, 5, 8.944272], abs=1e-6)


def test_a_moving_sensor_gets_the_path_of_the_whole_run_whatever_the_frame_range():
    config = mobile()
    planned = scene_view(config, 0, 2**31 - 1)
    assert isinstance(planned, PlannedPath) and planned.frames == 4
    assert scene_view(config, 3, 2**31 - 1) == planned  # the scene serves every frame: one path for all ranges
    view = planned.following({})
    # 4 frames of 20 profiles at 200 Hz = 0.4 s at 25 m/s: 10 m of path, 4.2 m above the waypoints
    assert np.allclose(view.positions, [[100, 0, 4.2], [110, 0, 4.2]])
    assert view.step == pytest.approx(math.radians(0.0709)) and view.motion_spacing == pytest.approx(25 / 200)
    other = load_config(None, [*LINE, "sensor.preset=railway_profiler", "frames=2", "sensor.trajectory={curve: track_centreline, speed: 10, height: 4.2}"])
    assert scene_view(other, 0, 1).following({}) is None  # the curve is the builder's: fixed detail until it is known
    assert scene_view(load_config(None, ["scene.builder=parking", "scene.place_sensor=false",
                                         "sensor.trajectory={waypoints: [[0, 0, 0], [5, 0, 0]], speed: 1}"]), 0, 1) is None


def samples_per_metre(layout, detail, kind):
    return {i: s[0] / w.length for i, (w, s) in enumerate(zip(layout.wires, detail.wires)) if s is not None and w.kind == kind}


def test_wires_are_fine_near_the_path_and_coarse_far_from_it():
    config = mobile(frames=4)
    params = config.scene.params
    layout = plan(params, np.random.default_rng(0))
    view = scene_view(config, 0, 1).following({})
    detail = level_of_detail(layout, params, view)
    near_far = {}
    for i, (wire, setting) in enumerate(zip(layout.wires, detail.wires)):
        distance = float(view.segment_distance(wire.start, wire.end)[0])
        if setting is None:
            assert distance - wire.sag > view.max_range  # beyond the scanner's reach from anywhere on the path
            continue
        samples, sides = setting
        tolerance = max(0.5 * view.step * max(distance - wire.sag, 0.5), 1e-4)
        assert catenary.chord_error(wire.length, wire.sag, samples) + section_error(wire.diameter / 2, sides) <= tolerance
        if wire.kind == "messenger_wire":
            near_far[distance] = samples
    assert any(s is None for s in detail.wires)  # spans more than 119 m from the path are not built
    nearest, farthest = near_far[min(near_far)], near_far[max(near_far)]
    assert min(near_far) < 5 and max(near_far) > 80 and nearest >= 3 * farthest, near_far
    # the whole run, not its first frame: spans around the path's far end are as fine as those at its start
    start, end = view.positions[0], view.positions[-1]
    ends = {round(float(np.linalg.norm(w.points_at([0.5])[0][:2] - p[:2]))): s for w, s in zip(layout.wires, detail.wires) for p in (start, end)
            if s is not None and w.kind == "messenger_wire"}
    assert ends
    fixed = level_of_detail(layout, load_config(None, [*LINE, "scene.detail.mode=fixed"]).scene.params, view)
    assert all(s is not None for s in fixed.wires)


def test_stones_follow_a_slow_path_in_stretches_that_never_overlap():
    params = mobile().scene.params
    layout = plan(params, np.random.default_rng(0))
    fast = level_of_detail(layout, params, scene_view(mobile(25.0, 4), 0, 1).following({}))
    assert fast.stone_trims == [] and fast.stone_radius == 0  # 12.5 cm between profiles: no stone gets two of them
    slow_view = scene_view(mobile(0.5, 200), 0, 1).following({})  # a trolley at 0.5 m/s for 20 s: 10 m of path
    slow = level_of_detail(layout, params, slow_view)
    radius = 0.045 / (2 * math.radians(0.0709))
    assert slow.stone_radius == pytest.approx(radius)
    trims = [t for _, t in slow.stone_trims]
    assert len(trims) >= 2 and all(t1 - t0 <= STONE_STRETCH + 1e-9 for t0, t1 in trims)
    assert all(a[1] == pytest.approx(b[0]) for a, b in zip(trims[:-1], trims[1:]))  # they touch and never overlap
    reach = radius + layout.section.ballast_toe_half
    assert trims[0][0] >= 100 - reach - 2 and trims[-1][1] <= 110 + reach + 2  # only around the 10 m of path
    assert trims[0][0] <= 100 - radius and trims[-1][1] >= 110 + radius
    for centres in slow.stone_centres:
        assert np.allclose(slow_view.distance(centres), 0.0, atol=1e-9)  # the centres lie on the path


@pytest.mark.bpy
def test_a_mobile_run_builds_stones_and_fine_wires_along_its_path_only(tmp_path):
    import bpy

    from bpy_pipeline.io import read_ply
    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # a trolley at 0.5 m/s from 100 m along the line, its profiler coarsened to 0.5 deg so stones stay few
    config = load_config(None, [*LINE, "sensor.preset=railway_profiler", "sensor.horizontal_resolution_deg=0.5", "sensor.columns=20",
                                "sensor.rotation_deg=[0, 0, 30]",
                                "sensor.trajectory={curve: track_centreline, speed: 0.5, height: 1.5, start_distance: 100}", "frames=3", "effects.ideal=true",
                                "output.formats=[ply]", "output.preview=false", "output.frame=world"])
    manifest = run(config, tmp_path, log=lambda *_: None)
    path = np.array([f["sensor_pose"] for f in manifest["frames"]])[:, :3, 3]
    view = PathView(np.vstack([path, path[-1] + [0.05, 0, 0]]), math.radians(0.5), 119.0)  # the run's 0.15 m of path
    radius = 0.045 / (2 * math.radians(0.5))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    stones = [o for o in bpy.data.objects if o.name.startswith("ballast_stones.")]
    assert stones
    for obj in stones:
        mesh = obj.evaluated_get(depsgraph).to_mesh()
        points = np.array([obj.matrix_world @ v.co for v in mesh.vertices])
        obj.evaluated_get(depsgraph).to_mesh_clear()
        assert len(points) and view.distance(points).max() <= radius + 0.045  # stones only where two beams fall on one
    messengers = {}
    for obj in bpy.data.objects:
        if obj.name.endswith(".messenger_wire"):
            points = np.array([p.co[:3] for p in obj.data.splines[0].points])
            messengers[float(view.segment_distance(points[0], points[-1])[0])] = len(points) / np.linalg.norm(points[-1] - points[0])
    near, far = messengers[min(messengers)], messengers[max(messengers)]
    assert min(messengers) < 10 and max(messengers) > 80 and near >= 1.5 * far, messengers  # 0.5 deg: 2x here, 3x at the preset's 0.0709
    cloud = read_ply(tmp_path / "ply" / "000000.ply")
    names = {o["instance"]: o["name"] for o in manifest["frames"][0]["objects"]}
    assert any(names.get(int(i), "").startswith("ballast_stones.") for i in np.unique(cloud["instance"]))
