"""The street builder: layout, lane-following placement, platoons, field-of-view awareness, no intersections, same seed same bytes."""

import dataclasses
import json
import math

import numpy as np
import pytest

from bpy_pipeline.geometry.placement import Distribution
from bpy_pipeline.builders.street.params import StreetScene
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry import primitives
from bpy_pipeline.builders.street import layout as street
from bpy_pipeline.geometry.collision import rectangles_overlap
from bpy_pipeline.geometry.field_of_view import in_view_fraction
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
from bpy_pipeline.rig import field_of_view

BOX_CLASSES = ["car", "van", "truck", "bus", "person", "bicycle", "motorcycle", "rider"]
BUSY = dict(vehicles=Distribution("normal", 12.0, 0.0, 0.0, 40.0), parked=Distribution("normal", 8.0, 0.0, 0.0, 40.0),
            bicycles=Distribution("normal", 3.0, 0.0, 0.0, 10.0), motorcycles=Distribution("normal", 2.0, 0.0, 0.0, 10.0),
            pedestrians=Distribution("normal", 12.0, 0.0, 0.0, 40.0))


def _placed(seed=0, views=(), **changes):
    params = dataclasses.replace(StreetScene(**BUSY), **changes)
    layout = street.street_layout(params, np.random.default_rng(params.layout_seed))
    return params, layout, street.place_users(params, layout, np.random.default_rng(seed), views)


def _camera_views(yaws=(0.0,), position=(-7.6, -7.6, 2.15), platform_yaw=45.0, preset="flash96x16_carla"):
    spec = resolve_sensor({"preset": preset})
    return [field_of_view(spec, pose_matrix(position, (0.0, 0.0, platform_yaw + yaw))) for yaw in yaws]


# ----------------------------------------------------------------------------- layout and placement (pure)
def test_layout_areas_are_apart_and_lanes_lie_on_the_road():
    params = StreetScene()
    layout = street.street_layout(params, np.random.default_rng(0))
    R = layout.half_road
    assert R == pytest.approx(params.lanes_per_direction * params.lane_width + params.parking_width)
    assert layout.on_road((0.0, 0.0)) and layout.on_road((30.0, R - 0.1)) and not layout.on_road((30.0, R + 0.1))
    assert layout.on_sidewalk((30.0, layout.walk_inner + 1.0)) and not layout.on_sidewalk((30.0, R - 1.0))
    assert layout.on_sidewalk((-layout.walk_inner - 0.5, -layout.walk_inner - 0.5))  # the corner where the post stands
    for lane in layout.lanes:
        for s in np.linspace(0.0, lane.length, 7):
            for side in (-1, 1):
                assert layout.on_road(lane.at(s, side * (lane.width / 2 - 1e-6)))
    classes = {p.class_name for p in layout.parts}
    assert {"road", "kerb", "sidewalk", "traffic light", "traffic sign", "building"} <= classes
    assert {"terrain", "vegetation", "trunk", "fence", "pole"} <= classes  # what real streets hold (street_dressing)


def test_users_keep_to_their_lanes_sidewalks_and_crossings_and_never_overlap():
    params, layout, placement = _placed(seed=3)
    users = placement.users
    kinds = {u.kind for u in users}
    assert {"car", "person", "bicycle", "motorcycle"} <= kinds
    for u in users:
        area, _, index = u.where.partition(":")
        if area in ("lane", "parking"):
            lane = layout.lanes[int(index)]
            assert lane.kind == ("drive" if area == "lane" else "parking")
            assert math.isclose(math.cos(u.yaw - lane.heading), 1.0, abs_tol=1e-9)  # heading along the traffic
            d = (lane.end - lane.start) / lane.length
            r = u.centre - lane.start
            lateral = abs(float(d[0] * r[1] - d[1] * r[0]))  # 2-D cross product (np.cross of 2-vectors is gone in NumPy 2)
            assert lateral + u.size[1] / 2 <= lane.width / 2 + 1e-6  # the whole footprint inside its lane
            assert u.z == street.MARKING_THICKNESS
        elif area == "sidewalk":
            assert u.kind == "person" and layout.on_sidewalk(u.centre) and u.z == params.kerb_height
        else:
            assert area == "crossing" and u.kind == "person" and layout.on_crossing(u.centre)
    for i, a in enumerate(users):
        for b in users[i + 1 :]:
            assert not rectangles_overlap(a.centre, a.half, a.yaw, b.centre, b.half, b.yaw, params.clearance - 1e-6)
        for x, y, r in layout.poles:
            assert not rectangles_overlap(a.centre, a.half, a.yaw, (x, y), (r, r), 0.0)


def test_platoons_follow_their_leader_at_the_drawn_gap():
    gap = Distribution("uniform", 5.0, 0.0, 4.0, 6.0)
    params, layout, placement = _placed(seed=1, platoon_probability=1.0, platoon_gap=gap, parked=Distribution("normal", 0.0, 0.0, 0.0, 0.0))
    assert placement.platoons >= 3
    moving = [u for u in placement.users if u.where.startswith("lane:") and u.kind in street.VEHICLES]
    followers = 0
    for u in moving:
        lane = layout.lanes[int(u.where.split(":")[1])]
        d = (lane.end - lane.start) / lane.length
        ahead = [v for v in moving if v is not u and v.where == u.where and np.dot(v.centre - u.centre, d) > 0]
        if ahead:
            leader = min(ahead, key=lambda v: np.dot(v.centre - u.centre, d))
            clear = float(np.dot(leader.centre - u.centre, d)) - (leader.size[0] + u.size[0]) / 2
            followers += 4.0 - 1e-6 <= clear <= 6.0 + 1e-6
    assert followers >= placement.platoons - 1  # a platoon broken only where a later vehicle fitted into a gap


def test_field_of_view_aware_placement_puts_users_where_the_camera_sees_them():
    views = _camera_views((80.0, 0.0, -80.0))
    params, layout, placement = _placed(seed=5, views=views)
    assert placement.users and sum(placement.out_of_view.values()) > 0
    for u in placement.users:
        assert in_view_fraction(views, u.centre, u.half, u.yaw, u.size[2], u.z) >= params.min_in_view
    _, _, blind = _placed(seed=5, views=views, fov_aware=False)
    seen = [in_view_fraction(views, u.centre, u.half, u.yaw, u.size[2], u.z) >= params.min_in_view for u in blind.users]
    assert not all(seen)  # without the rule, some users stand where no camera looks


def test_field_of_view_counts_azimuth_elevation_and_range():
    (view,) = _camera_views(position=(0.0, 0.0, 2.0), platform_yaw=0.0)
    ahead = [[10.0, 0.0, 2.0], [10.0, 0.0, 0.0], [40.0, 0.0, 2.0], [10.0, 9.0, 2.0], [-10.0, 0.0, 2.0], [10.0, 0.0, 1.0]]
    assert view.contains(np.array(ahead)).tolist() == [True, False, False, False, False, True]  # 11.3 deg down is out, 5.7 in


def test_field_of_view_answers_as_numpys_norm_and_clip_would():
    """``FieldOfView.contains`` spells out ``np.linalg.norm(axis=1)`` and ``np.clip``: the same answer for every point,
    its elevation on an edge, at the sensor itself, straight above it, or not finite."""
    from bpy_pipeline.geometry.field_of_view import FieldOfView

    def by_numpy(view, points):
        local = (points - view.pose[:3, 3]) @ view.pose[:3, :3]
        r = np.linalg.norm(local, axis=1)
        el = np.degrees(np.arcsin(np.clip(local[:, 2] / np.maximum(r, 1e-12), -1, 1)))
        inside = (el >= view.elevation[0]) & (el <= view.elevation[1]) & (r >= view.min_range) & (r <= view.max_range)
        az = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
        return inside if view.azimuth[1] - view.azimuth[0] >= 360.0 else inside & (az >= view.azimuth[0]) & (az <= view.azimuth[1])

    rng = np.random.default_rng(5)
    for k in range(400):
        pose = np.eye(4)
        pose[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        pose[:3, 3] = rng.normal(size=3) * 10
        low = float(rng.uniform(-30, 0))
        view = FieldOfView(pose, (-180.0, 180.0) if k % 2 else (-45.0, 45.0), (low, low + float(rng.uniform(0, 30))), 0.5, 100.0)
        points = pose[:3, 3] + rng.normal(size=(27, 3)) * 20
        points[:4] = pose[:3, 3] + [[0, 0, 0], [0, 0, 5], [np.nan, 0, 0], [np.inf, 1, 1]]
        edge = np.radians(low)
        points[4] = pose[:3, 3] + pose[:3, :3] @ [10 * np.cos(edge), 0.0, 10 * np.sin(edge)]
        with np.errstate(invalid="ignore"):  # the infinite point's inf / inf, both ways
            assert np.array_equal(view.contains(points), by_numpy(view, points))


def test_meshes_that_cross_are_found_and_touching_ones_are_not():
    a = primitives.box_mesh(0, 1, 0, 1, 0, 1)
    assert street.meshes_intersect(a, primitives.box_mesh(0.5, 1.5, 0.2, 0.8, 0.2, 0.8))
    assert not street.meshes_intersect(a, primitives.box_mesh(1, 2, 0, 1, 0, 1))  # sharing a face
    assert not street.meshes_intersect(a, primitives.box_mesh(1.01, 2, 0, 1, 0, 1))
    pole = primitives.translated(primitives.cylinder(0.1, 3.0, 8), (0.5, 0.5, 1.5))
    assert street.meshes_intersect(a, pole)


@pytest.mark.parametrize("change, key", [
    ({"arm_length": 15.0}, "scene.arm_length"),
    ({"vehicle_mix": {"tram": 1.0}}, "scene.vehicle_mix"),
    ({"platoon_probability": 1.5}, "scene.platoon_probability"),
    ({"building_height": [20.0, 6.0]}, "scene.building_height"),
    ({"yard_trees": 1e9}, "scene.yard_trees"),
    ({"yard_trees": -1.0}, "scene.yard_trees"),
    ({"yard_tree_clearance": 0.1}, "scene.yard_tree_clearance"),
    ({"yard_tree_height": [14.0, 4.0]}, "scene.yard_tree_height"),
])
def test_bad_street_parameters_name_their_key(change, key):
    from bpy_pipeline.config import load_config

    with pytest.raises(InputError, match=key.replace(".", r"\.")):
        load_config({"scene": {"builder": "street", **change}})


# ----------------------------------------------------------------------------- in Blender
def _config(frames=1, seed=0, **scene):
    from bpy_pipeline.config import load_config

    return load_config({"seed": seed, "frames": frames, "scene": {"builder": "street", **BUSY_RAW, **scene},
                        "output": {"formats": ["ply"], "preview": False, "boxes": {"formats": ["openpcdet"], "classes": BOX_CLASSES}}})


BUSY_RAW = {k: {"kind": d.kind, "mean": d.mean, "std": d.std, "min": d.min, "max": d.max} for k, d in BUSY.items()}


@pytest.mark.bpy
def test_exported_street_has_no_intersections_and_users_stand_on_their_ground(bpy_scene):
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.stages.scene import build_frame_scene

    config = _config(seed=2)
    result = build_frame_scene(config, 0)
    buffers = export_scene(load_class_table())
    objects = buffers.objects
    meshes = {}
    for row in range(len(objects)):
        tris = buffers.triangles[buffers.triangle_object == row]
        used, inverse = np.unique(tris, return_inverse=True)
        meshes[row] = (buffers.vertices[used].astype(np.float64), inverse.reshape(-1, 3))
    users = [r for r in range(len(objects)) if objects.instance[r] >= 1000]
    assert len({int(objects.instance[r]) for r in users}) == len(result.info["placed"]) > 20
    crossing = []
    for r in users:
        for other in range(len(objects)):
            if objects.instance[other] == objects.instance[r] or (other in users and other < r):
                continue  # the parts of one user (a rider on their bicycle) touch by design
            if street.meshes_intersect(meshes[r], meshes[other]):
                crossing.append((objects.names[r], objects.names[other]))
    assert crossing == []
    kerb = config.scene.params.kerb_height
    for placed in result.info["placed"]:
        rows = [r for r in users if objects.instance[r] == placed["instance"]]
        low = min(meshes[r][0][:, 2].min() for r in rows)
        ground = kerb if placed["where"] == "sidewalk" else street.MARKING_THICKNESS
        assert low == pytest.approx(ground, abs=2e-3), placed
        assert objects.class_names[rows[0]] == ("person" if placed["kind"] == "person" else placed["kind"])
    riders = [r for r in users if objects.class_names[r] in ("rider", "motorcyclist")]
    rides = {"rider": "bicycle", "motorcyclist": "motorcycle"}  # a rider is labelled by what it rides
    assert riders and all(
        objects.class_names[min(x for x in users if objects.instance[x] == objects.instance[r])] == rides[objects.class_names[r]] for r in riders
    )


@pytest.mark.bpy
def test_same_seed_same_bytes_whatever_frame_a_run_starts_at(bpy_scene, tmp_path):
    from bpy_pipeline.plan import run

    config = _config(frames=2, seed=7)
    run(config, tmp_path / "a", log=lambda s: None)
    run(config, tmp_path / "b", log=lambda s: None)
    run(config, tmp_path / "c", log=lambda s: None, frames=[1])
    for index in range(2):
        a = json.loads((tmp_path / "a" / "records" / f"{index:06d}.json").read_text())
        b = json.loads((tmp_path / "b" / "records" / f"{index:06d}.json").read_text())
        assert a["sha256"] == b["sha256"] and a["points"] > 0
    c = json.loads((tmp_path / "c" / "records" / "000001.json").read_text())
    assert c["sha256"] == json.loads((tmp_path / "a" / "records" / "000001.json").read_text())["sha256"]
    boxes = {b["class"] for i in range(2) for b in json.loads((tmp_path / "a" / "records" / f"{i:06d}.json").read_text()).get("boxes", [])}
    assert "car" in boxes


@pytest.mark.bpy
def test_road_users_kept_across_frames_are_the_frames_parts_and_the_spares_export_nothing(bpy_scene):
    """The users' objects are kept and refilled frame after frame: after a frame with more parts than the next, the
    next frame's objects carry exactly its parts (names, tags, vertices), and the spare ones export no triangle."""
    from bpy_pipeline.builders.street.scene import Intersection
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    street_scene = Intersection(_config().scene.params)

    def parts(count: int, shift: float):
        box = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float), np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]], np.int32))
        return [(f"street_user_{k:03d}_car_body", "car", "diffuse", 0.3, 1000 + k,
                 (box[0] * (k + 1) + [shift + 10 * k, 50.0, 0.0], box[1])) for k in range(count)]

    street_scene._show_users(parts(5, 0.0))
    second = parts(2, 3.0)
    street_scene._show_users(second)
    bpy_scene.context.view_layer.update()
    kept = list(street_scene.users.objects)
    assert [o.name for o in kept[:2]] == [name for name, *_ in second]
    assert all(len(o.data.vertices) == 0 for o in kept[2:]) and len(kept) == 5
    for obj, (name, class_name, _, reflectivity, instance, (vertices, _)) in zip(kept, second):
        co = np.empty(len(obj.data.vertices) * 3, np.float32)
        obj.data.vertices.foreach_get("co", co)
        assert np.array_equal(co.reshape(-1, 3), vertices.astype(np.float32))
        assert (obj["lidar_class"], obj["lidar_instance"], obj["lidar_reflectivity"]) == (class_name, instance, reflectivity)
    buffers = export_scene(load_class_table())
    users = [r for r in range(len(buffers.objects)) if buffers.objects.instance[r] >= 1000]
    assert sorted(buffers.objects.names[r] for r in users) == [name for name, *_ in second]


# ----------------------------------------------------------------------------- what real streets hold (street_dressing)
def test_dressing_is_present_labelled_and_drawn_from_the_layout_seed_alone():
    from bpy_pipeline.labels import load_class_table

    params = StreetScene()
    first = street.street_layout(params, np.random.default_rng(params.layout_seed))
    again = street.street_layout(params, np.random.default_rng(params.layout_seed))
    other = street.street_layout(params, np.random.default_rng(params.layout_seed + 1))
    assert [(p.name, p.class_name) for p in first.parts] == [(p.name, p.class_name) for p in again.parts]
    assert all(np.array_equal(a.mesh[0], b.mesh[0]) and np.array_equal(a.mesh[1], b.mesh[1]) for a, b in zip(first.parts, again.parts))
    assert first.dressing == again.dressing and first.dressing != other.dressing
    table = load_class_table()
    for part in first.parts:
        table.id_of(part.class_name)  # every class is in labels.yaml
    classes = {p.class_name for p in first.parts}
    assert {"terrain", "vegetation", "trunk", "fence", "pole", "bin", "bicycle stand"} <= classes
    for what in ("trees", "bushes", "hedges", "fences", "lamps"):
        assert first.dressing.get(what, 0) > 0, what
    # the roads reach the sensor's range: terrain and buildings out to the arm's end
    terrain = np.vstack([p.mesh[0] for p in first.parts if p.class_name == "terrain"])
    assert np.abs(terrain[:, :2]).max() == pytest.approx(params.arm_length)
    # the terrain leaves the sidewalk at its height and stays gentle
    assert terrain[:, 2].min() > params.kerb_height - 0.6 and terrain[:, 2].max() < params.kerb_height + 0.04 * params.arm_length + 1.0


def test_street_trees_clear_the_traffic_and_obstacles_keep_users_off_the_furniture():
    from bpy_pipeline.builders.street.vegetation import tree

    trunk, crown = tree((0.0, 0.0, 0.15), 9.0, 3.0, "round", np.random.default_rng(0), clear_below=4.5)
    assert crown[0][:, 2].min() >= 0.15 + 4.5 - 0.3  # cards reach half their edge below their centres
    assert trunk[0][:, 2].min() < 0.15  # the trunk goes into the ground
    params, layout, placement = _placed(seed=4)
    for user in placement.users:
        for x, y, r in layout.poles:
            assert not rectangles_overlap(user.centre, user.half, user.yaw, (x, y), (r, r), 0.0), (user.kind, x, y)
        for centre, half, yaw in layout.blocks:
            assert not rectangles_overlap(user.centre, user.half, user.yaw, centre, half, yaw), user.kind


def test_ego_vehicle_places_the_roof_sensor_in_its_lane_and_keeps_its_footprint_free():
    from bpy_pipeline.builders.street.params import ego_station
    from bpy_pipeline.builders.street.layout import EGO_HALF, ego_keep_free

    params = StreetScene(ego_vehicle=True, **BUSY)
    poses = [ego_station(params, k) for k in range(20)]
    xs = [p[0, 3] for p in poses]
    assert len(set(np.round(xs, 6))) == 20 and all(-params.ego_span <= x <= params.ego_span for x in xs)  # 7.3 m steps cycling over 120 m
    assert all(p[1, 3] == -params.lane_width / 2 and p[2, 3] == params.ego_height for p in poses)
    layout = street.street_layout(params, np.random.default_rng(0))
    reserved = [ego_keep_free(params, poses[3])]
    centre, half, yaw = reserved[0]
    assert yaw == 0.0 and np.allclose(half, (EGO_HALF[0] + params.ego_headway / 2, EGO_HALF[1]))
    assert np.isclose(centre[0] + half[0], poses[3][0, 3] + EGO_HALF[0] + params.ego_headway)  # the headway ahead of the front
    placement = street.place_users(params, layout, np.random.default_rng(1), reserved=reserved)
    assert placement.users
    for user in placement.users:
        assert not rectangles_overlap(user.centre, user.half, user.yaw, *reserved[0], params.clearance)
    ahead = [u for u in placement.users if abs(u.centre[1] - poses[3][1, 3]) < 1.0 and 0 < u.centre[0] - poses[3][0, 3] < EGO_HALF[0] + params.ego_headway]
    assert not ahead  # nobody in the ego's lane within its headway
    assert ego_station(StreetScene(), 0) is None


def test_a_vehicles_parts_of_other_materials_never_share_a_reflectivity():
    """The material models tell a point's object by (instance, reflectivity): a body whose paint draw is clipped at its
    brightest must not read like its retroreflective plates (a street with effects.materials.objects refused to run)."""
    params, _, placement = _placed(seed=2)
    vehicles = [u for u in placement.users if u.kind in street.VEHICLES]
    rng = np.random.default_rng(0)
    for _ in range(60):  # about 2,000 bodies: some 12 paint draws reach the clip
        for user in vehicles:
            parts = street.user_meshes(user, rng)
            seen = {}
            for _, _, material, reflectivity, _ in parts:
                assert seen.setdefault(reflectivity, material) == material, (user.kind, reflectivity)
