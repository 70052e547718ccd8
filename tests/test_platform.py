"""Moving platforms: trajectories as poses over time, and a moving sensor scanning walls through Embree.

Analytic references: a sensor moving at v towards a wall at d0 sees a beam fired at time t,
at direction d (frame-start sensor frame), at range (d0 - v t) / d_x; motion-compensated points
of static walls lie on those walls (1e-4 m) whatever the motion, turning included.
"""

import math

import numpy as np
import pytest

from bpy_pipeline.buffers import ObjectTable, SceneBuffers
from bpy_pipeline.config import config_from_dict, config_to_dict, sensor_trajectory
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.sensor.platform import Trajectory
from bpy_pipeline.lidar.sensor.sensors import azimuth_step, azimuths, elevations, spherical_directions
from bpy_pipeline.frame import frame_rng


# ----------------------------------------------------------------------------- trajectories alone
from bpy_pipeline.stages.scan import scan_buffers


# ----------------------------------------------------------------------------- trajectories alone
def test_constant_speed_interpolates_by_arc_length_and_heads_along_the_path():
    trajectory = Trajectory([[0, 0, 1], [30, 40, 1], [30, 40, 11]], speed=10.0)  # 50 m diagonal, then 10 m up
    poses = trajectory.poses([0.0, 2.5, 5.0, 5.5])
    assert np.allclose(poses[:, :3, 3], [[0, 0, 1], [15, 20, 1], [30, 40, 1], [30, 40, 6]], atol=1e-12)
    heading = math.atan2(40, 30)
    assert np.allclose(poses[1, :3, 0], [math.cos(heading), math.sin(heading), 0], atol=1e-12)  # x forward along the path
    assert np.allclose(poses[3, :3, 0], poses[1, :3, 0], atol=1e-12)  # a vertical segment keeps the heading
    assert np.allclose(poses[:, :3, :3] @ poses[:, :3, :3].transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert trajectory.length == pytest.approx(60.0) and trajectory.duration == pytest.approx(6.0)


def test_per_waypoint_times_and_a_dwell():
    trajectory = Trajectory([[0, 0, 0], [10, 0, 0], [10, 0, 0], [10, 20, 0]], times=[5.0, 6.0, 8.0, 10.0])
    x = trajectory.poses([0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0])[:, :3, 3]
    assert np.allclose(x, [[0, 0, 0], [5, 0, 0], [10, 0, 0], [10, 0, 0], [10, 0, 0], [10, 10, 0], [10, 20, 0]], atol=1e-12)
    yaw = np.degrees(trajectory.yaw(trajectory.distance([0.0, 2.0, 5.0])))
    assert np.allclose(yaw, [0.0, 30.0, 90.0])  # the turn spreads between the segments' midpoints (arc 5 and 20 m)
    assert trajectory.duration == pytest.approx(5.0)


def test_heading_is_the_exact_tangent_of_a_uniformly_sampled_circle():
    angle = np.linspace(0.0, np.pi, 181)
    radius = 50.0
    trajectory = Trajectory(np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros_like(angle)]), speed=5.0)
    s = np.linspace(trajectory.knot_arc[0], trajectory.knot_arc[-1], 1000)
    along = s / trajectory.length * np.pi  # the polar angle of the point at arc length s (the chord polygon is uniform)
    assert np.allclose(trajectory.yaw(s), along + np.pi / 2, atol=1e-9)


def test_rotation_offset_and_start_along_the_path():
    trajectory = Trajectory([[0, 0, 0], [0, 100, 0]], speed=4.0, rotation_deg=[0, 0, -90], offset=[0, 0, 2.5], start_distance=10.0, start_time=1.5)
    pose = trajectory.poses([0.0])[0]
    assert np.allclose(pose[:3, 3], [0, 16.0, 2.5])  # 10 m + 1.5 s at 4 m/s, lifted 2.5 m
    assert np.allclose(pose[:3, 0], [1, 0, 0], atol=1e-12)  # heading +y, then yawed -90 deg: x points to +x (the right)
    fixed = Trajectory([[0, 0, 0], [0, 100, 0]], speed=4.0, heading=False)
    assert np.allclose(fixed.poses([3.0])[0, :3, :3], np.eye(3))


def test_frames_continue_along_the_path():
    trajectory = Trajectory([[0, 0, 0], [100, 0, 0]], speed=20.0)
    starts = np.array([trajectory.frame_poses(k, 0.1)(np.zeros(1))[0, 0, 3] for k in range(4)])
    assert np.allclose(starts, [0.0, 2.0, 4.0, 6.0])
    info = trajectory.frame_info(2, 0.1)
    assert info["distance_m"] == pytest.approx([4.0, 6.0]) and info["start_time_s"] == pytest.approx(0.2)
    assert trajectory.reach(2, 0.1) == pytest.approx(2.0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"points": [[0, 0, 0]], "speed": 1.0}, "at least 2 points"),
        ({"points": [[1, 2, 3], [1, 2, 3]], "speed": 1.0}, "zero length"),
        ({"points": [[0, 0, 0], [1, 0, 0]], "speed": 0.0}, "speed: must be > 0"),
        ({"points": [[0, 0, 0], [1, 0, 0]], "speed": -2.0}, "speed: must be > 0"),
        ({"points": [[0, 0, 0], [1, 0, 0]]}, "either a speed"),
        ({"points": [[0, 0, 0], [1, 0, 0]], "times": [0.0, 0.0]}, "increase strictly"),
        ({"points": [[0, 0, 0], [1, 0, 0]], "times": [0.0, 1.0, 2.0]}, "3 times for 2 points"),
        ({"points": [[0, 0, 0], [np.nan, 0, 0]], "speed": 1.0}, "point 1 is not finite"),
        ({"points": [[0, 0, 0], [1, 0, 0]], "speed": 1.0, "start_distance": 1.0}, "start_distance: must lie in"),
    ],
)
def test_bad_trajectories_raise_one_clear_error(kwargs, message):
    points = kwargs.pop("points")
    with pytest.raises(InputError, match=message) as err:
        Trajectory(points, **kwargs)
    assert str(err.value).startswith("sensor.trajectory") and "\n" not in str(err.value)


def test_times_past_the_path_end_are_an_error():
    trajectory = Trajectory([[0, 0, 0], [10, 0, 0]], speed=10.0)
    with pytest.raises(InputError, match="outside the path"):
        trajectory.poses([0.5, 1.5])
    with pytest.raises(InputError, match="^frames: 3 frame"):
        trajectory.check_frames(3, 0.4)


VLP_SECTION = {"preset": "vlp16"}


@pytest.mark.parametrize(
    "trajectory, extra, message",
    [
        ({"waypoints": [[0, 0, 0]], "speed": 5}, {}, "^sensor.trajectory.waypoints: a path needs at least 2"),
        ({"waypoints": [[0, 0, 0], [0, 0, 0]], "speed": 5}, {}, "zero length"),
        ({"waypoints": [[0, 0, 0], [9, 0, 0]]}, {}, "^sensor.trajectory.speed: must be > 0"),
        ({"waypoints": [[0, 0, 0], [9, 0, 0]], "speed": -1}, {}, "^sensor.trajectory.speed: must be > 0"),
        ({"curve": "track", "waypoints": [[0, 0, 0], [9, 0, 0]], "speed": 5}, {}, "^sensor.trajectory: give either waypoints"),
        ({"speed": 5}, {}, "^sensor.trajectory: give either waypoints"),
        ({"curve": "track", "times": [0, 1]}, {}, "^sensor.trajectory.times: per-waypoint times need waypoints"),
        ({"waypoints": [[0, 0, 0], [9, 0, 0]], "speed": 5, "times": [0, 1]}, {}, "^sensor.trajectory.speed: give either"),
        ({"waypoints": [[0, 0, 0], [9, 0, 0]], "speed": 5}, {"position": [1, 2, 3]}, "^sensor.position: a trajectory replaces"),
        ({"waypoints": [[0, 0, 0], [1, 0, 0]], "speed": 5}, {"frames": 3}, "^frames: 3 frame"),
        ({"waypoints": [[0, 0, 0], [9, 0, 0]], "speed": 5, "heading": "yes"}, {}, "^sensor.trajectory.heading: expected true or false"),
    ],
)
def test_bad_trajectory_config_names_its_key(trajectory, extra, message):
    frames = extra.pop("frames", 1)
    with pytest.raises(InputError, match=message):
        config_from_dict({"frames": frames, "sensor": {**VLP_SECTION, **extra, "trajectory": trajectory}})


def test_trajectory_config_round_trips_and_builds():
    config = config_from_dict({"frames": 2, "sensor": {"preset": "railway_tls", "rotation_deg": [0, 0, 90],
                                                       "trajectory": {"waypoints": [[0, 0, 0], [0, 100, 0]], "speed": 1.5, "height": 0.5}}})
    assert config_from_dict(config_to_dict(config)) == config
    assert "position" not in config_to_dict(config)["sensor"]
    pose = sensor_trajectory(config.sensor).poses([10.0])[0]
    assert np.allclose(pose[:3, 3], [0, 15.0, 2.5])  # railway_tls rides 2 m (mount) + 0.5 m above the path
    assert np.allclose(pose[:3, 0], [-1, 0, 0], atol=1e-12)  # heading +y, yawed 90 deg more


# ----------------------------------------------------------------------------- a moving sensor scanning walls
def wall_buffers(walls: list[np.ndarray]) -> SceneBuffers:
    """One object per wall; each wall a (4, 3) quad of world corners."""
    vertices = np.concatenate(walls)
    triangles = np.concatenate([np.array([[0, 1, 2], [0, 2, 3]]) + 4 * i for i in range(len(walls))]).astype(np.int32)
    k = len(walls)
    objects = ObjectTable(
        [f"wall_{i}" for i in range(k)], [""] * k, ["wall"] * k, np.full(k, 17, np.uint16),
        np.arange(1, k + 1, dtype=np.uint32), np.zeros(k, np.uint8), np.full(k, 0.5, np.float32),
    )
    return SceneBuffers(vertices, triangles, np.repeat(np.arange(k, dtype=np.int32), 2), objects)


def quad(axis: int, value: float, half: float = 200.0) -> np.ndarray:
    """A (4, 3) square wall in the plane ``coordinate[axis] = value``."""
    corners = np.array([[-half, -half], [half, -half], [half, half], [-half, half]], float)
    return np.insert(corners, axis, value, axis=1)


def quad_x(x: float) -> np.ndarray:
    return quad(0, x)


D0, SPEED = 40.0, 30.0
SPINNING = {"preset": "custom", "pattern": "spinning", "channels": 5, "vertical_fov_deg": [-10, 10], "horizontal_fov_deg": [-40, 40],
            "horizontal_resolution_deg": 0.5, "rotation_hz": 10.0, "spin": "ccw", "min_range": 0.5, "max_range": 150.0}


def moving_config(waypoints, speed=SPEED, sensor=SPINNING, **extra):
    return config_from_dict({"sensor": {**sensor, "trajectory": {"waypoints": waypoints, "speed": speed}}, **extra})


def xyz(points) -> np.ndarray:
    return np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64)


def test_moving_sensor_sees_the_analytic_skew_and_keeps_the_wall_flat():
    config = moving_config([[0, 0, 0], [100, 0, 0]])
    spec = config.sensor.spec
    points, pose = scan_buffers(wall_buffers([quad_x(D0)]), config, frame_rng(0, 0))
    assert np.allclose(pose, np.eye(4)) and len(points) == 5 * 161
    # each beam's direction from the sensor's own tables: column from the firing time, row from the ring
    column = np.rint(points["time"] / (azimuth_step(spec) / (360.0 * spec.rotation_hz))).astype(int)
    direction = spherical_directions(azimuths(spec)[column], elevations(spec)[points["ring"]])
    expected = (D0 - SPEED * points["time"]) / direction[:, 0]
    assert np.abs(points["range"] - expected).max() < 1e-4
    # the skew: seen from the frame-start pose without compensation (range along the beam), the wall
    # recedes by v t; compensated, every point lies on the wall
    naive = direction * points["range"][:, None].astype(np.float64)
    assert np.abs(naive[:, 0] - (D0 - SPEED * points["time"])).max() < 1e-4
    assert np.ptp(naive[:, 0]) > 0.6  # 80 deg of a 10 Hz sweep: 22 ms at 30 m/s
    assert np.abs(xyz(points)[:, 0] - D0).max() < 1e-4
    centre = (points["ring"] == 2) & (column == 80)  # elevation 0, azimuth 0: range d0 - v t exactly
    assert np.abs(points["range"][centre] - (D0 - SPEED * points["time"][centre])).max() < 1e-4


def test_turning_sensor_keeps_every_wall_of_a_room_in_place():
    angle = np.linspace(0.0, np.pi / 2, 91)
    path = np.column_stack([10 * np.cos(angle) - 10, 10 * np.sin(angle), np.full_like(angle, 1.5)])  # a quarter circle of 10 m
    planes = [(0, 30.0), (0, -30.0), (1, 25.0), (1, -25.0), (2, 12.0), (2, -8.0)]  # walls, ceiling, floor
    room = [quad(axis, value) for axis, value in planes]
    sensor = {**SPINNING, "channels": 16, "vertical_fov_deg": [-30, 30], "horizontal_fov_deg": [-180, 180], "horizontal_resolution_deg": 1.0}
    config = moving_config(path.tolist(), speed=40.0, sensor=sensor)  # 4 m of a 10 m radius in one 0.1 s sweep: 23 deg
    points, pose = scan_buffers(wall_buffers(room), config, frame_rng(0, 0))
    assert len(points) == 16 * 360
    world = xyz(points) @ pose[:3, :3].T + pose[:3, 3]
    for instance, (axis, value) in enumerate(planes, start=1):
        on = points["instance"] == instance
        assert on.sum() > 50
        assert np.abs(world[on, axis] - value).max() < 1e-4
    # the sensor turned during the sweep: the last beam was cast from a pose 22 deg away from the first
    last = sensor_trajectory(config.sensor).poses([points["time"].max()])[0]
    assert math.degrees(math.acos(np.clip(last[:3, 0] @ pose[:3, 0], -1, 1))) > 22.0


def test_successive_frames_continue_along_the_path_and_world_output_matches():
    buffers = wall_buffers([quad_x(D0)])
    config = moving_config([[0, 0, 0], [100, 0, 0]], frames=3)
    period = 1.0 / config.sensor.spec.rotation_hz
    first = []
    for k in range(3):
        points, pose = scan_buffers(buffers, config, frame_rng(0, k), frame=k)
        assert np.allclose(pose[:3, 3], [SPEED * period * k, 0, 0])
        assert np.abs(xyz(points)[:, 0] - (D0 - SPEED * period * k)).max() < 1e-4
        first.append(points["range"][(points["ring"] == 2) & (points["time"] == points["time"].min())][0])
    assert np.allclose(np.diff(first), -SPEED * period / math.cos(math.radians(40)), atol=1e-4)  # first column: azimuth -40 deg
    world_config = moving_config([[0, 0, 0], [100, 0, 0]], frames=3, output={"frame": "world"})
    world, _ = scan_buffers(buffers, world_config, frame_rng(0, 2), frame=2)
    assert np.abs(world["x"] - D0).max() < 1e-4
    with pytest.raises(InputError, match="^frames: 34 frame"):  # 100 m at 30 m/s: 33 frames of 0.1 s
        scan_buffers(buffers, config, frame_rng(0, 3), frame=33)


def test_a_static_config_scans_as_before():
    static = config_from_dict({"sensor": {**SPINNING, "position": [0, 0, 0]}})
    points, pose = scan_buffers(wall_buffers([quad_x(D0)]), static, frame_rng(0, 0))
    direction = xyz(points) / np.linalg.norm(xyz(points), axis=1, keepdims=True)
    assert np.allclose(pose, np.eye(4)) and np.abs(points["range"] - D0 / direction[:, 0]).max() < 1e-4


# ----------------------------------------------------------------------------- curves of the scene (bpy)
def curve_object(name, points, location=(0, 0, 0), rotation_z=0.0, cyclic=False, bevel=0.0):
    import bpy

    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = bevel
    spline = curve.splines.new("POLY")
    spline.points.add(len(points) - 1)
    spline.points.foreach_set("co", np.column_stack([points, np.ones(len(points))]).astype(np.float32).ravel())
    spline.use_cyclic_u = cyclic
    obj = bpy.data.objects.new(name, curve)
    obj.location, obj.rotation_euler = location, (0.0, 0.0, rotation_z)
    bpy.context.scene.collection.objects.link(obj)
    return obj


@pytest.mark.bpy
def test_curve_polyline_reads_the_evaluated_world_space_centreline():
    import bpy

    from bpy_pipeline.blender.curves import curve_polyline

    bpy.ops.wm.read_factory_settings(use_empty=True)
    square = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]], float)
    curve_object("loop", square, location=(500, 0, 2), rotation_z=np.pi / 2, cyclic=True, bevel=0.05)
    line = curve_polyline("loop")
    expected = np.column_stack([500 - square[:, 1], square[:, 0], np.full(4, 2.0)])
    assert np.abs(line - np.vstack([expected, expected[:1]])).max() < 1e-5  # closed, rotated, moved, without its bevel
    assert bpy.data.curves["loop"].bevel_depth == pytest.approx(0.05) and len(bpy.data.objects) == 1  # the user's object untouched
    bpy.data.meshes.new("box_mesh")
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("box", bpy.data.meshes["box_mesh"]))
    with pytest.raises(InputError, match="^sensor.trajectory.curve: no object 'track'.*curve objects: loop"):
        curve_polyline("track")
    with pytest.raises(InputError, match="^sensor.trajectory.curve: object 'box' is a mesh, not a curve"):
        curve_polyline("box")


@pytest.mark.bpy
def test_pipeline_follows_a_curve_of_the_scene(tmp_path):
    import bpy

    from bpy_pipeline.plan import run_frames
    from bpy_pipeline.blender.mesh_objects import mesh_data, tag

    bpy.ops.wm.read_factory_settings(use_empty=True)
    wall = bpy.data.objects.new("wall", mesh_data("wall", quad(0, 0.0, 100.0), np.array([[0, 1, 2], [0, 2, 3]])))
    wall.location = (2040.0, 0.0, 0.0)  # the plane x = 2040, 2 km from the world origin
    bpy.context.scene.collection.objects.link(wall)
    tag(wall, "wall")
    curve_object("track", np.array([[0, 0, 0], [30, 0, 0]], float), location=(2000.0, 0.0, 0.5))
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    config = config_from_dict({
        "frames": 2,
        "scene": {"builder": "blend", "path": str(blend)},
        "sensor": {**SPINNING, "trajectory": {"curve": "track", "speed": SPEED, "height": 1.0}},
        "output": {"formats": ["ply"], "preview": False},
    })
    frames = list(run_frames(config, tmp_path / "out"))
    for k, frame in enumerate(frames):
        entry = frame.record
        start = [2000.0 + SPEED * 0.1 * k, 0.0, 1.5]
        assert np.allclose(np.array(entry["sensor_pose"])[:3, 3], start, atol=1e-4)
        assert entry["trajectory"]["distance_m"] == pytest.approx([SPEED * 0.1 * k, SPEED * 0.1 * (k + 1)])
        assert len(frame.points) == 5 * 161
        assert np.abs(xyz(frame.points)[:, 0] + start[0] - 2040.0).max() < 1e-4  # sensor frame at frame start: the wall at x = 40 - 3 k
