"""scene.population: surfaces found in static geometry, collision-free placement checked on exported geometry,
same frame whatever came before, bad keys named."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.geometry import human, primitives
from bpy_pipeline.population.placer import Placer, meshes_cross, person_shape, place_on_spots, placement_matrix, segments_cross
from bpy_pipeline.geometry.surfaces import find_surfaces, floor_and_seats, on_surface

ROOT = Path(__file__).resolve().parents[1]


def room():
    """A 10 x 10 m floor, a desk 2 x 1 x 0.72 m at (2, 0), a closed pillar 0.6 x 0.6 x 3 m at (-2, -2)."""
    floor = primitives.plane(10, 10)
    desk = primitives.translated(primitives.box(2, 1, 0.72), (2, 0, 0.36))
    pillar = primitives.translated(primitives.box(0.6, 0.6, 3), (-2, -2, 1.5))
    return primitives.merge([floor, desk, pillar])


# ----------------------------------------------------------------------------- pure geometry
def test_surfaces_are_found_by_height_and_spots_avoid_what_stands_on_them():
    v, t = room()
    surfaces = find_surfaces(v, t, cell=0.1)
    assert [round(s.z, 3) for s in surfaces] == [0.0, 0.72, 3.0]
    floor, desk, _ = surfaces
    assert floor.area == pytest.approx(100.0) and desk.area == pytest.approx(2.0)
    # 100 x 100 grid nodes on the floor, less those under the desk (20 x 10) and inside the pillar (6 x 6)
    assert len(floor.spots) == 100 * 100 - 20 * 10 - 6 * 6
    under = (np.abs(floor.spots[:, 0] - 2) < 1) & (np.abs(floor.spots[:, 1]) < 0.5)
    inside = (np.abs(floor.spots[:, 0] + 2) < 0.3) & (np.abs(floor.spots[:, 1] + 2) < 0.3)
    assert not under.any() and not inside.any()
    floors, seats = floor_and_seats(surfaces)
    assert [s.z for s in floors] == [floor.z] and [round(s.z, 2) for s in seats] == [0.72]
    # the desk's edge spots lie on its border and point away from it
    assert len(desk.edges) == 2 * (20 + 10)
    np.testing.assert_allclose(np.abs(desk.edges[:, 0] - 2) * np.abs(desk.outward[:, 0]), np.abs(desk.outward[:, 0]) * 1.0, atol=1e-9)


def test_a_tilted_surface_is_no_floor_and_a_room_without_one_has_no_spots():
    v, t = primitives.plane(4, 4)
    tilt = np.radians(30)
    v = v @ np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]]).T
    assert find_surfaces(v, t) == []
    assert find_surfaces(np.zeros((0, 3)), np.zeros((0, 3), int)) == []


def test_mesh_crossing_counts_crossings_not_touching():
    a = primitives.box(1, 1, 1)
    assert meshes_cross(*a, *primitives.translated(a, (0.5, 0.2, 0.1)))  # overlapping boxes
    assert not meshes_cross(*a, *primitives.translated(a, (1.0, 0.0, 0.0)))  # faces touching
    assert not meshes_cross(*a, *primitives.translated(a, (3.0, 0.0, 0.0)))
    big = primitives.box(1, 1, 1)
    small = (big[0] * 0.2, big[1])
    assert not meshes_cross(*big, *small)  # one inside the other: no surface crossing (spots rule that out)
    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    assert segments_cross(np.array([[0.2, 0.2, -1.0]]), np.array([[0.2, 0.2, 1.0]]), tri)
    assert not segments_cross(np.array([[0.2, 0.2, 0.0]]), np.array([[0.2, 0.2, 1.0]]), tri)  # ends on the plane
    assert not segments_cross(np.array([[0.0, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]), tri)  # in the plane


def test_the_placer_refuses_bodies_through_furniture_and_too_close_to_each_other():
    v, t = room()
    placer = Placer(v, t, keep_out=0.3)
    floor = find_surfaces(v, t)[0]
    shape = person_shape(human.sample_pose("standing", np.random.default_rng(0)), 1.75, 1.0, "standing")
    support = (v, t[floor.triangles])
    assert placer.fits("person", shape, placement_matrix((2.0, 0.0), 0.0, 0.01), support) is None  # inside the desk
    assert placer.rejections["off_surface"] + placer.rejections["static"] == 1
    assert placer.fits("person", shape, placement_matrix((2.0, 0.55), 0.0, 0.01), support) is None  # half under the desk top
    assert placer.rejections["static"] >= 1
    ok = placer.fits("person", shape, placement_matrix((-3.0, 3.0), 0.0, 0.01), support)
    assert ok is not None
    placer.commit(ok)
    assert placer.fits("person", shape, placement_matrix((-3.0, 3.3), 0.0, 0.01), support) is None
    assert placer.rejections["keep_out"] == 1
    assert placer.fits("person", shape, placement_matrix((-3.0, 5.5), 0.0, 0.01), support) is None  # off the floor's edge
    assert placer.rejections["off_surface"] >= 1


def test_people_sit_on_seat_edges_and_stand_on_floors():
    v, t = room()
    surfaces = find_surfaces(v, t)
    floors, seats = floor_and_seats(surfaces)
    placer = Placer(v, t)
    spots = [(s, s.spots, None) for s in floors] + [(s, s.edges, s.outward) for s in seats]
    rng = np.random.default_rng(3)
    for pose in ("sitting", "sitting", "standing", "crouching"):
        placed = place_on_spots("person", lambda r, p=pose: person_shape(human.sample_pose(p, r), 1.7, 1.0, p), rng, placer, spots, 60,
                                lambda s: (v, t[s.triangles]))
        assert placed is not None, placer.rejections
        lowest = placed.vertices[placed.vertices[:, 2].argmin()]
        if pose == "sitting":  # thighs on the desk top, feet hanging in front of its edge
            assert placed.matrix[2, 3] == pytest.approx(0.73)
            assert placed.vertices[:, 2].min() > 0.0
        else:
            assert on_surface(lowest[None], v, t[floors[0].triangles]).all()
        assert not meshes_cross(placed.vertices, placed.shape.triangles, v, t)


# ----------------------------------------------------------------------------- in Blender
def _hall(tmp_path):
    """The worked example's hall .blend, built by its own script."""
    sys.path.insert(0, str(ROOT / "examples" / "hall_twin"))
    try:
        from make_hall import build_hall
    finally:
        sys.path.pop(0)
    return build_hall(tmp_path / "hall.blend")


def _config(blend, extra=(), population=None):
    from bpy_pipeline.config import load_config

    population = population or {"person": {"count": 5, "poses": {"standing": 0.3, "walking": 0.3, "sitting": 0.4}}, "robot_arm": {"count": 1},
                                "car": {"count": 1}}
    return load_config({"seed": 2, "frames": 3, "scene": {"builder": "blend", "path": str(blend), "population": population},
                        "sensor": {"preset": "vlp16", "position": [0, 0, 2.5]}, "output": {"formats": ["ply"], "preview": False}}, list(extra))


def _instances(buffers):
    """{instance: (vertices, triangles)} of the exported scene."""
    out = {}
    inst = buffers.objects.instance[buffers.triangle_object]
    for i in np.unique(inst):
        tri = buffers.triangles[inst == i]
        used, local = np.unique(tri, return_inverse=True)
        out[int(i)] = (buffers.vertices[used], local.reshape(-1, 3))
    return out


@pytest.mark.bpy
def test_placed_objects_never_cross_each_other_or_the_hall_and_stand_on_allowed_surfaces(bpy_scene, tmp_path):
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.geometry import kinematics
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.stages.scene import build_frame_scene

    config = _config(_hall(tmp_path))
    keep, seated, counts = {}, 0, []
    arm = kinematics.load_arm()
    for frame in range(4):
        result = build_frame_scene(config, frame, keep=keep)
        info = result.info["population"]
        assert info["surfaces"] == "lidar_walkable" and info["seats"] == [0.46]
        buffers = export_scene(load_class_table())
        parts = _instances(buffers)
        placed = [i for i in parts if i >= 10000]
        assert sorted(placed) == sorted(result.headings)
        counts.append(len(placed))
        static_rows = buffers.objects.instance < 10000
        static = buffers.triangles[static_rows[buffers.triangle_object]]
        walk = np.array([name == "floor" for name in buffers.objects.names])[buffers.triangle_object]
        seat = np.array([name.startswith("bench") for name in buffers.objects.names])[buffers.triangle_object]
        for i in placed:
            v, t = parts[i]
            assert not meshes_cross(v, t, buffers.vertices, static), f"instance {i} crosses the hall in frame {frame}"
            for j in placed:
                if j > i:
                    assert not meshes_cross(v, t, *parts[j]), f"instances {i} and {j} cross in frame {frame}"
            placed_i = keep["population"][1].last[i]
            if placed_i.shape.seat_offset is None:  # standing: its lowest point on the floor
                lowest = v[v[:, 2].argmin()]
                assert on_surface(lowest[None], buffers.vertices, buffers.triangles[walk])[0], f"instance {i} floats or sinks in frame {frame}"
            else:  # seated: its origin (below the hips) on a bench top, feet hanging in front of the edge
                seated += 1
                assert on_surface(placed_i.matrix[:3, 3][None], buffers.vertices, buffers.triangles[seat])[0]
                assert v[:, 2].min() > 0.0
            if placed_i.kind == "person":
                assert human.within_limits(placed_i.shape.detail["angles"])
            if placed_i.kind == "robot_arm":
                assert kinematics.within_limits(arm, placed_i.shape.detail["q"]).all()
        for obj in bpy.data.objects:  # the arm's links as posed in Blender are within their limits too
            if "joint_limits_deg" in obj and not obj.hide_render:
                lo, hi = obj["joint_limits_deg"]
                assert lo - 1e-6 <= np.degrees(obj.rotation_axis_angle[0]) <= hi + 1e-6
    assert min(counts) >= 5 and seated >= 1


@pytest.mark.bpy
def test_frame_k_after_k_minus_1_is_frame_k_alone(bpy_scene, tmp_path):
    from bpy_pipeline.plan import run_frames

    config = _config(_hall(tmp_path))
    for _ in run_frames(config, tmp_path / "all"):
        pass
    for _ in run_frames(config, tmp_path / "alone", frames=[2]):
        pass
    for name in ("ply/000002.ply",):
        assert (tmp_path / "all" / name).read_bytes() == (tmp_path / "alone" / name).read_bytes()
    labels = "openpcdet/labels/000002.txt"
    assert (tmp_path / "all" / labels).read_text() == (tmp_path / "alone" / labels).read_text()
    assert (tmp_path / "all" / labels).read_text().count("Person") >= 1
    assert (tmp_path / "all" / "ply/000001.ply").read_bytes() != (tmp_path / "all" / "ply/000002.ply").read_bytes()


@pytest.mark.bpy
def test_population_works_on_a_procedural_builder(bpy_scene):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.stages.scene import build_frame_scene

    config = load_config(None, ["scene.builder=parking", "scene.cars={kind: normal, mean: 3, std: 0, min: 0, max: 9}",
                                "scene.population={person: {count: 4, poses: {standing: 1}}}"])
    keep = {}
    result = build_frame_scene(config, 0, keep=keep)
    assert result.info["population"]["person"]["placed"] == 4 and result.info["cars_placed"] == 3
    assert result.info["population"]["surfaces"] == "walkable_classes"  # the level's floor, not its ramp
    buffers = export_scene(load_class_table())
    parts = _instances(buffers)
    floor = np.array([c == "floor" for c in buffers.objects.class_names])[buffers.triangle_object]
    for i in (i for i in parts if i >= 10000):
        v = parts[i][0]
        assert on_surface(v[v[:, 2].argmin()][None], buffers.vertices, buffers.triangles[floor])[0]
    cars = [i for i in parts if 100 <= i < 10000]
    static = buffers.triangles[(buffers.objects.instance < 10000)[buffers.triangle_object]]
    for i in (i for i in parts if i >= 10000):
        assert not meshes_cross(*parts[i], buffers.vertices, static)
    assert len(cars) == 3


def test_bad_population_keys_exit_2_with_one_line_naming_the_key(tmp_path):
    cases = {
        "scene.population={persn: {count: 1}}": "scene.population.persn: unknown key; allowed: person, robot_arm, car, placement",
        "scene.population={person: {count: -1}}": "scene.population.person.count: must be >= 0",
        "scene.population={person: {count: {min: 4, max: 2}}}": "scene.population.person.count.min: must not exceed max",
        "scene.population={person: {poses: {flying: 1}}}": "scene.population.person.poses: expected weights",
        "scene.population={car: {height: {min: 1.5, max: 9}}}": "scene.population.car.height.max: must be <= 5.0",
        "scene.population={placement: {keep_out: -1}}": "scene.population.placement.keep_out: must be >= 0",
        "scene.population={person: {count: 2, colour: red}}": "scene.population.person.colour: unknown key",
        "scene.population=[person]": "scene.population: expected a mapping",
        "scene.population={robot_arm: {positions: [[0, 0]]}}": "scene.population.robot_arm.positions[0]: expected a list of 3 numbers",
        "scene.population={placement: {min_visible: 2}}": "scene.population.placement.min_visible: must lie in 0..1, got 2",
        "scene.population={placement: {walkable_classes: [lava]}}": "scene.population.placement.walkable_classes[0]: unknown class 'lava'",
    }
    for assignment, message in cases.items():
        result = subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(tmp_path / "o"), "--set", "scene.builder=primitives", "--set", assignment],
                                cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert result.returncode == 2, (assignment, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0], (assignment, result.stderr)


def test_a_scene_without_blender_refuses_a_population():
    from bpy_pipeline.config import load_config
    from bpy_pipeline.errors import InputError

    # real_scan, the one built-in scene without Blender, has its own population keys (people on floors, arms on desks
    # found in the scan's points: docs/population.md); the Blender population's keys are refused naming the key
    with pytest.raises(InputError, match=r"^scene.population.person: unknown key; allowed: people, arms"):
        load_config({"scene": {"builder": "real_scan", "path": "x.bin", "population": {"person": {"count": 1}}}})


def test_population_round_trips_through_the_saved_config():
    from bpy_pipeline.config import config_from_dict, config_to_dict, load_config

    config = load_config(None, ["scene.builder=primitives",
                                "scene.population={person: {count: {min: 1, max: 5}}, robot_arm: {count: 1, positions: [[0, 0, 90]]}, car: {count: 2}}"])
    again = config_from_dict(config_to_dict(config))
    assert again.scene.population == config.scene.population
    assert config.scene.population.kinds[0][1].count.kind == "uniform" and config.output.boxes.formats == ["kitti", "openpcdet"]


def test_the_visibility_rule_refuses_hidden_objects_and_objects_that_hide_others():
    floor = primitives.plane(20, 20)
    wall = primitives.translated(primitives.box(0.2, 10, 3), (2.0, 0, 1.5))
    v, t = primitives.merge([floor, wall])
    support = (v, t[:2])
    sensor = np.array([0.0, 0.0, 1.0])
    shape = person_shape(human.neutral_angles(), 1.75, 1.0, "standing")
    placer = Placer(v, t, keep_out=0.1, sensor=sensor, min_visible=0.6)
    assert placer.fits("person", shape, placement_matrix((4.0, 0.0), 0.0, 0.01), support) is None  # behind the wall
    assert placer.rejections["hidden"] == 1
    far = placer.fits("person", shape, placement_matrix((-4.0, 0.0), 0.0, 0.01), support)
    assert far is not None and placer.visible_fraction(far.vertices) > 0.9
    placer.commit(far)
    assert placer.fits("person", shape, placement_matrix((-1.2, 0.0), 0.0, 0.01), support) is None  # in front of it
    assert placer.rejections["hides"] == 1
    assert placer.fits("person", shape, placement_matrix((0.0, -2.0), 0.0, 0.01), support) is not None  # beside: both seen
    without = Placer(v, t, keep_out=0.1)  # the rule off: the hidden spot is taken
    assert without.fits("person", shape, placement_matrix((4.0, 0.0), 0.0, 0.01), support) is not None


def test_keep_out_is_the_gap_between_footprints():
    from bpy_pipeline.population.placer import footprint

    v, t = room()
    floor = find_surfaces(v, t)[0]
    support = (v, t[floor.triangles])
    shape = person_shape(human.neutral_angles(), 1.75, 1.0, "standing")
    centre, half, _, _, _ = footprint(shape, placement_matrix((0.0, 0.0), 0.0, 0.0))
    width = 2 * half[1]
    for gap, fits in ((0.25, False), (0.35, True)):
        placer = Placer(v, t, keep_out=0.3)
        placer.commit(placer.fits("person", shape, placement_matrix((-3.0, 3.0), 0.0, 0.01), support))
        assert (placer.fits("person", shape, placement_matrix((-3.0, 3.0 - width - gap), 0.0, 0.01), support) is not None) == fits
