"""Underground parking: the paper's insertion rule, the level's layout, cars in the built scene, same seed same frame."""

import math
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.geometry.placement import Distribution
from bpy_pipeline.builders.parking.params import ParkingScene
from bpy_pipeline.geometry.collision import rectangles_overlap
from bpy_pipeline.geometry.indoor import parking_layout, parking_station
from bpy_pipeline.geometry.placement import FloorBoxPlacer, insert_sequentially, sample, sample_count, turn_about


# ----------------------------------------------------------------------------- the insertion rule
class Script:
    """Objects numbered 0, 1, ...; ``fits(obj, angle)`` decides; every try is recorded."""

    def __init__(self, fits):
        self.fits, self.made, self.tries = fits, 0, []

    def new(self):
        self.made += 1
        return self.made - 1

    def at(self, obj, angle):
        self.tries.append((obj, angle))
        return (obj, angle) if self.fits(obj, angle) else None


def test_nothing_fits_stops_after_ten_objects_turned_36_times():
    script = Script(lambda obj, angle: False)
    log = insert_sequentially(5, script.new, script.at)
    assert log.stopped == "failures" and log.placed == []
    assert log.objects_tried == 10 and log.attempts == [36] * 10
    assert [angle for obj, angle in script.tries if obj == 3] == [10.0 * k for k in range(36)]  # the whole circle in 10 degree steps


def test_a_success_resets_the_failure_count():
    # objects 0..8 fit nowhere, 9 fits at its 5th position, then nothing fits again
    script = Script(lambda obj, angle: obj == 9 and angle == 40.0)
    log = insert_sequentially(3, script.new, script.at)
    assert log.placed == [(9, 40.0)]
    assert log.attempts == [36] * 9 + [5] + [36] * 10
    assert log.stopped == "failures" and log.objects_tried == 20


def test_the_wanted_count_ends_insertion_and_refused_objects_count_as_failures():
    script = Script(lambda obj, angle: True)
    log = insert_sequentially(3, script.new, script.at)
    assert log.stopped == "count" and len(log.placed) == 3 and log.attempts == [1, 1, 1]
    refused = insert_sequentially(3, lambda: None, script.at, max_consecutive_failures=4)
    assert refused.stopped == "failures" and refused.attempts == [0] * 4
    assert insert_sequentially(0, script.new, script.at).objects_tried == 0


def test_counts_and_distances_follow_the_paper():
    rng = np.random.default_rng(0)
    counts = np.array([sample_count(Distribution("normal", 5.0, 4.0, 0.0, 40.0), rng) for _ in range(20000)])
    phi = lambda x: 0.5 * (1.0 + math.erf((x - 5.0) / (4.0 * math.sqrt(2.0))))  # noqa: E731 - the N(5, 4) CDF
    expected = [phi(0.5)] + [phi(k + 0.5) - phi(k - 0.5) for k in range(1, 16)]  # rounded, clipped at zero
    observed = [(counts == k).mean() for k in range(16)]
    np.testing.assert_allclose(observed, expected, atol=0.01)
    distances = sample(Distribution("normal", 10.0, 20.0, 2.5, 20.0), rng, 5000)
    assert distances.min() >= 2.5 and distances.max() <= 20.0
    heights = sample(ParkingScene().car_height, rng, 5000)
    assert 1.55 <= heights.min() and heights.max() <= 1.70 and abs(heights.mean() - 1.625) < 0.005
    turned, yaw = turn_about((1.0, 2.0), (4.0, 2.0), 0.5, 90.0)
    np.testing.assert_allclose(turned, [1.0, 5.0], atol=1e-12)
    assert np.isclose(yaw, 0.5 + np.pi / 2)


def test_a_box_is_refused_where_it_collides_or_hides():
    placer = FloorBoxPlacer((0.0, 0.0, 1.5), ((-20, -20), (20, 20)), obstacles=[(np.array([0.0, 8.0]), np.array([0.5, 0.5]), 0.0)], clearance=0.3,
                            min_visible=0.5, keep_out=1.0)
    half = np.array([2.2, 0.9, 0.8])
    first = placer.try_place((6.0, 0.0), 0.0, half)
    assert first is not None and first.visible_fraction == 1.0
    placer.commit(first)
    assert placer.try_place((6.5, 1.0), 0.0, half) is None and placer.rejections["collision"] == 1
    assert placer.try_place((0.0, 8.0), 0.0, half) is None and placer.rejections["obstacle"] == 1
    assert placer.try_place((0.5, 0.0), 0.0, half) is None and placer.rejections["outside"] == 1  # over the robot
    assert placer.try_place((19.5, 5.0), 0.0, half) is None and placer.rejections["outside"] == 2  # through the wall
    assert placer.try_place((11.0, 0.0), 0.0, half) is None and placer.rejections["occluded"] == 1  # right behind the first
    assert placer.try_place((2.5, -0.2), np.pi / 2, half) is None and placer.rejections["occludes"] == 1  # would hide the first
    beside = placer.try_place((6.0, -6.0), 0.0, half)
    assert beside is not None and beside.visible_fraction == 1.0


def test_the_layout_keeps_bays_pillars_and_ramp_apart_and_the_robot_on_the_driveway():
    params = ParkingScene()
    layout = parking_layout(params)
    assert len(layout.bays) >= 30 and len(layout.pillars) >= 10
    width, depth = layout.bay_size
    for x, y, yaw in layout.bays:
        for centre, half, o_yaw in layout.obstacles:
            assert not rectangles_overlap((x, y), (depth / 2, width / 2), yaw, centre, half, o_yaw)
        assert abs(y) - depth / 2 >= params.driveway_width / 2 - 1e-9
    for frame in range(40):
        station = parking_station(params, frame)
        assert layout.driveway[0] <= station[0, 3] <= layout.driveway[1] and station[1, 3] == 0.0 and station[2, 3] == params.sensor_height
    assert parking_station(params, 1)[0, 3] - parking_station(params, 0)[0, 3] == pytest.approx(params.sensor_step)


# ----------------------------------------------------------------------------- the built scene
def _frame(config, index, keep=None):
    """Build frame ``index`` (on the scene ``keep`` holds from earlier frames, when given) and export it."""
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.scene import build_frame_scene

    state = build_frame_scene(config, index, frame_rng(config.seed, index), keep)
    return state, export_scene(load_class_table())


@pytest.mark.bpy
def test_cars_stand_free_inside_the_level_with_glass_windows(bpy_scene):
    from bpy_pipeline.buffers import MATERIALS
    from bpy_pipeline.config import load_config

    config = load_config(None, ["scene.builder=parking", "frames=3", "scene.cars={kind: normal, mean: 10, std: 0, min: 0, max: 40}"])
    layout = parking_layout(config.scene.params)
    placed = 0
    for index in range(3):
        state, buffers = _frame(config, index)
        info = state.info
        assert info["stopped"] == ("count" if info["cars_placed"] == info["cars_wanted"] else "failures")
        if info["stopped"] == "failures":
            assert info["attempts"][-10:] == [36] * 10 or 0 in info["attempts"][-10:]
        objects = buffers.objects
        cars = {}
        for row in range(len(objects)):
            if objects.class_names[row] == "car":
                cars.setdefault(int(objects.instance[row]), []).append(row)
        assert len(cars) == info["cars_placed"] >= 3
        footprints = []
        for instance, rows in cars.items():
            materials = {MATERIALS[objects.material[r]] for r in rows}
            assert materials == {"diffuse", "glass"}
            vertices = buffers.vertices[np.unique(buffers.triangles[np.isin(buffers.triangle_object, rows)])]
            assert 1.55 - 1e-6 <= np.ptp(vertices[:, 2]) <= 1.70 + 1e-6 and abs(vertices[:, 2].min()) < 1e-6
            assert ((vertices[:, :2] >= layout.low).all()) and (vertices[:, :2] <= layout.high).all()
            yaw = state.headings[instance]
            local = vertices[:, :2] @ np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
            centre = (local.max(axis=0) + local.min(axis=0)) / 2
            footprints.append((np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]) @ centre, np.ptp(local, axis=0) / 2, yaw))
        for k, (c, h, y) in enumerate(footprints):
            for c2, h2, y2 in footprints[k + 1:]:
                assert not rectangles_overlap(c, h, y, c2, h2, y2)
            for o_centre, o_half, o_yaw in layout.obstacles:
                assert not rectangles_overlap(c, h, y, o_centre, o_half, o_yaw)
        assert all(car["visible_fraction"] >= config.scene.params.min_visible_fraction for car in info["cars"])
        placed += len(cars)
    assert placed >= 12


@pytest.mark.bpy
def test_same_seed_same_frame_whatever_came_before(bpy_scene, tmp_path):
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import run
    from bpy_pipeline.stages.scan import scan_buffers

    config = load_config(None, ["scene.builder=parking", "frames=2", "output.formats=[ply]", "output.preview=false"])
    # frame 1 built on top of frame 0's scene, and frame 1 built from nothing, scan the same
    keep = {}
    _frame(config, 0, keep)
    kept = {obj.name: obj.as_pointer() for obj in bpy.data.objects}
    state_after, buffers_after = _frame(config, 1, keep)
    assert {obj.name: obj.as_pointer() for obj in bpy.data.objects if obj.name in kept} == kept  # moved, not rebuilt
    points_after, _ = scan_buffers(buffers_after, config, np.random.default_rng(1), 1)
    state_fresh, buffers_fresh = _frame(config, 1, {})  # from nothing
    points_fresh, _ = scan_buffers(buffers_fresh, config, np.random.default_rng(1), 1)
    assert state_after.info == state_fresh.info
    assert points_after.tobytes() == points_fresh.tobytes()
    # a run twice (the second reuses the built level) writes the same bytes; another seed does not
    outputs = []
    for name, seed in (("a", 0), ("b", 0), ("c", 5)):
        run(config if seed == 0 else load_config(None, ["scene.builder=parking", "frames=2", "output.formats=[ply]", "output.preview=false", f"seed={seed}"]),
            tmp_path / name, log=lambda *_: None)
        outputs.append(
            {
                p.relative_to(tmp_path / name): p.read_bytes()
                for p in sorted((tmp_path / name).rglob("*"))
                if p.is_file() and p.name != "manifest.json" and p.parent.name != "records"
            }
        )
    assert outputs[0] == outputs[1] and outputs[0].keys() == outputs[2].keys()
    labels = Path("openpcdet/labels/000001.txt")
    assert outputs[0][labels] != outputs[2][labels]


@pytest.mark.bpy
def test_cars_park_in_bays_when_asked(bpy_scene):
    from bpy_pipeline.config import load_config
    config = load_config(None, ["scene.builder=parking", "scene.placement=bays", "scene.cars={kind: normal, mean: 8, std: 0, min: 0, max: 40}"])
    keep = {}
    state, _ = _frame(config, 0, keep)
    bays = parking_layout(config.scene.params).bays
    placed = keep["parking"][1].last.placed
    assert len(placed) >= 4
    for car, box in placed:
        k = int(np.argmin(np.linalg.norm(bays[:, :2] - box.centre[:2], axis=1)))
        np.testing.assert_allclose(box.centre[:2], bays[k, :2], atol=1e-9)
        assert np.isclose(np.sin(box.yaw - bays[k, 2]), 0.0, atol=1e-9)  # nose in or reversed in
    assert len({tuple(np.round(box.centre[:2], 6)) for _, box in placed}) == len(placed)  # one car a bay


def test_bad_scene_input_names_the_key():
    from bpy_pipeline.config import load_config
    from bpy_pipeline.errors import InputError

    cases = {
        "scene.ramp_length=58": "scene.ramp_length: must leave at least 8 m",
        "scene.cars={kind: normal, mean: 5, std: 4, min: 3, max: 1}": "scene.cars.min: must not exceed max",
        "scene.car_height={kind: uniform, min: 0.2, max: 1.7}": "scene.car_height.min: must be >= 0.5",
        "scene.sensor_height=2.8": "scene.sensor_height: must be below the ceiling",
        "scene.placement=anywhere": "scene.placement: expected 'free' | 'bays'",
        "sensor.position=[0, 0, 1]": "sensor.position: the parking scene places the sensor itself",
        "output.boxes.min_points={car: -1}": "output.boxes.min_points.car: expected an integer >= 0",
        # a 10^12 m level and a turn tried 2^31 times ran until killed; Blender's 32-bit input overflowed with a traceback
        "scene.length=1e12": "scene.length: must lie in 1..10000 m, got 1000000000000.0",
        "scene.rotations=2147483648": "scene.rotations: at most 36 ",
        "scene.pillar_every=2147483648": "scene.pillar_every: must lie in 1..1000, got 2147483648",
    }
    for assignment, message in cases.items():
        with pytest.raises(InputError, match=message.replace("(", r"\(").replace("|", r"\|")):
            load_config(None, ["scene.builder=parking", assignment])
    with pytest.raises(InputError, match="scene.poses: expected weights"):
        load_config(None, ["scene.builder=industrial_hall", "scene.poses={dancing: 1}"])
    assert load_config(None, ["scene.builder=parking", "scene.place_sensor=false", "sensor.position=[0, 0, 1.5]"]).sensor.position == (0.0, 0.0, 1.5)
