"""3D box labels: fitting, occlusion levels of constructed cases, truncation, point thresholds, KITTI and OpenPCDet files."""


import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.io import read_dataset

from bpy_pipeline.buffers import ObjectTable, SceneBuffers
from bpy_pipeline.geometry import human, primitives
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.geometry import boxes as gb
from bpy_pipeline.io import boxes as bx
from bpy_pipeline.lidar.cast import visibility as vis
from bpy_pipeline.lidar.points import empty_points
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.scanner import scan
from bpy_pipeline.lidar.sensor.sensors import iter_pattern, resolve_sensor

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))  # visibility_reference: the per-object cast

SENSOR = resolve_sensor({"preset": "vlp16", "rotation_hz": 5.0}, "sensor")  # 0.1 deg columns
POSE = pose_matrix([0.0, 0.0, 1.2], [0.0, 0.0, 0.0])


def scene(parts):
    """Buffers of ``[(name, class, instance, (vertices, triangles)[, material, reflectivity]), ...]`` (diffuse at 0.5 unless given)."""
    vertices, triangles, owner, offset = [], [], [], 0
    for row, (_, _, _, (v, t), *_) in enumerate(parts):
        vertices.append(v)
        triangles.append(t + offset)
        owner.append(np.full(len(t), row, np.int32))
        offset += len(v)
    k = len(parts)
    material = np.array([p[4] if len(p) > 4 else 0 for p in parts], np.uint8)
    reflectivity = np.array([p[5] if len(p) > 5 else 0.5 for p in parts], np.float32)
    objects = ObjectTable([p[0] for p in parts], [""] * k, [p[1] for p in parts], np.zeros(k, np.uint16), np.array([p[2] for p in parts], np.uint32), material,
                          reflectivity)
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(owner), objects)


def standing(x, y, yaw=np.pi):
    person = human.pose_person(human.neutral_angles(), 1.75, 1.0, "standing", (x, y), yaw)
    return person, human.body_mesh(person.a, person.b, person.radius)[:2]


def upright_box(size, centre_xy, yaw, bottom=0.0):
    v, t = primitives.box(*size)
    c, s = np.cos(yaw), np.sin(yaw)
    return v @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [centre_xy[0], centre_xy[1], bottom + size[2] / 2], t


def people_and_pillar(extra=()):
    """Three people 8 m away facing the sensor: in the open, half behind a pillar, behind a wall up to the eyes
    (and ``extra`` parts, as :func:`scene` takes them)."""
    floor = primitives.translated(primitives.box(60, 60, 0.2), (0, 0, -0.1))
    parts = [("floor", "floor", 1, floor)]
    people = {}
    for instance, (x, y) in ((10, (8.0, 0.0)), (11, (8.0, 4.0)), (12, (8.0, -4.0))):
        person, mesh = standing(x, y)
        people[instance] = person
        parts.append((f"person_{instance}", "person", instance, mesh))
    # the pillar: its edge on the ray to the middle of person 11, hiding its left half (seen from the sensor)
    az = np.arctan2(4.0, 8.0)
    along, across = np.array([np.cos(az), np.sin(az)]), np.array([-np.sin(az), np.cos(az)])
    parts.append(("pillar", "pillar", 2, upright_box((0.3, 1.0, 3.0), 5.0 * along + 0.5 * across, az, -0.2)))
    # the wall: 5 m away in front of person 12, its top on the line from the sensor to the person's eyes
    az = np.arctan2(-4.0, 8.0)
    eyes = 0.93 * 1.75
    top = 1.2 + (eyes - 1.2) * 5.0 / np.hypot(8.0, 4.0)
    parts.append(("wall", "wall", 3, upright_box((0.2, 3.0, top + 0.2), 5.0 * np.array([np.cos(az), np.sin(az)]), az, -0.2)))
    return scene(parts + list(extra)), people


def test_occlusion_levels_of_constructed_cases():
    buffers, people = people_and_pillar()
    boxes = gb.fit_boxes(buffers, ["person"], {k: p.yaw for k, p in people.items()})
    vis.visibility(buffers, boxes, iter_pattern(SENSOR, 1 << 18), POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5)
    fraction = boxes["visible"] / boxes["unoccluded"]
    levels = vis.occlusion_levels(boxes["visible"], boxes["unoccluded"], (0.8, 0.4, 0.1))
    by_instance = dict(zip(boxes["instance"].tolist(), zip(fraction, levels)))
    assert by_instance[10][0] == 1.0 and by_instance[10][1] == 0  # in the open
    assert 0.4 < by_instance[11][0] < 0.6 and by_instance[11][1] == 1  # half behind the pillar
    assert (boxes["unoccluded"] > 100).all() and (boxes["truncation"] == 0).all()
    # behind the wall: the person's own returns (traced alone) whose ray clears the wall's top, counted by hand
    rows = [r for r in range(len(buffers.objects)) if buffers.objects.instance[r] == 12]
    keep = np.isin(buffers.triangle_object, rows)
    alone = SceneBuffers(buffers.vertices, buffers.triangles[keep], buffers.triangle_object[keep], buffers.objects)
    hits, _ = scan(RayCaster(alone, frame=POSE), alone, iter_pattern(SENSOR, 1 << 18), POSE, SENSOR.min_range, SENSOR.max_range)
    xyz = np.column_stack([hits["x"], hits["y"], hits["z"]]).astype(np.float64)  # sensor frame
    normal = np.array([np.cos(np.arctan2(-4.0, 8.0)), np.sin(np.arctan2(-4.0, 8.0))])
    top = 1.2 + (0.93 * 1.75 - 1.2) * 5.0 / np.hypot(8.0, 4.0) - 1.2  # the wall's top, sensor frame
    clears = np.ones(len(xyz), bool)
    for face in (4.9, 5.1):
        t = face / (xyz[:, :2] @ normal)
        clears &= t * xyz[:, 2] > top
    assert len(hits) == boxes["unoccluded"][boxes["instance"] == 12][0]
    assert abs(int(clears.sum()) - int(boxes["visible"][boxes["instance"] == 12][0])) <= 1
    assert by_instance[12][0] < 0.2 and by_instance[12][1] >= 2  # only the top of the head shows


@pytest.mark.parametrize("kernel", ["numba", "numpy"])  # numba: the scene cast goes through the compiled scan
def test_one_cast_for_all_objects_equals_a_caster_per_object(kernel, monkeypatch):
    from bpy_pipeline.lidar.cast.visibility import visibility
    from visibility_reference import visibility_per_object

    if kernel == "numba":
        pytest.importorskip("numba")
    monkeypatch.setenv("BPY_PIPELINE_SCAN_KERNEL", kernel)

    buffers, people = people_and_pillar()
    headings = {k: p.yaw for k, p in people.items()}
    ours = gb.fit_boxes(buffers, ["person", "pillar", "wall"], headings)
    reference = ours.copy()
    visibility(buffers, ours, iter_pattern(SENSOR, 1 << 16), POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5)
    visibility_per_object(buffers, reference, iter_pattern(SENSOR, 1 << 16), POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5)
    assert (reference["unoccluded"] > 0).all() and (reference["visible"] < reference["unoccluded"]).any()
    np.testing.assert_array_equal(ours["visible"], reference["visible"])
    np.testing.assert_array_equal(ours["unoccluded"], reference["unoccluded"])
    np.testing.assert_allclose(ours["truncation"], reference["truncation"], atol=1e-12)


def test_every_box_contains_its_instances_points():
    buffers, people = people_and_pillar()
    boxes = gb.fit_boxes(buffers, ["person", "pillar", "wall"], {k: p.yaw for k, p in people.items()})
    points, _ = scan(RayCaster(buffers, frame=POSE), buffers, iter_pattern(SENSOR, 1 << 18), POSE, SENSOR.min_range, SENSOR.max_range)
    in_sensor = gb.boxes_in_frame(boxes, POSE)
    xyz = np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64)
    for box in in_sensor:
        mine = points["instance"] == box["instance"]
        assert mine.sum() >= 10 and gb.points_in_box(xyz[mine], box, 1e-4).all()
        # and it is tight: the object's vertices touch all six faces
        rows = [r for r in range(len(buffers.objects)) if buffers.objects.instance[r] == box["instance"]]
        vertices = buffers.vertices[np.unique(buffers.triangles[np.isin(buffers.triangle_object, rows)])]
        local = (vertices - POSE[:3, 3]) @ POSE[:3, :3] - box["centre"]
        c, s = np.cos(box["heading"]), np.sin(box["heading"])
        along = np.column_stack([c * local[:, 0] + s * local[:, 1], -s * local[:, 0] + c * local[:, 1], local[:, 2]])
        np.testing.assert_allclose(along.max(axis=0), box["size"] / 2, atol=1e-9)
        np.testing.assert_allclose(along.min(axis=0), -box["size"] / 2, atol=1e-9)
    person = in_sensor[in_sensor["instance"] == 10][0]
    assert np.isclose(person["size"][2], 1.75, atol=0.02) and np.isclose(abs(person["heading"]), np.pi)
    # headings the builder does not give come from the footprint: the pillar and the wall are rotated boxes
    turned = in_sensor[in_sensor["class_name"] == "pillar"][0]
    assert np.isclose(np.cos(2 * (turned["heading"] - np.arctan2(4.0, 8.0))) ** 2, 1.0, atol=1e-6)
    np.testing.assert_allclose(np.sort(turned["size"][:2]), [0.3, 1.0], atol=1e-6)


def test_truncation_is_the_share_outside_the_field_of_view():
    # a 2 m tall panel 3 m in front of a VLP-16 at 1.2 m: the lowest beam (-15 deg) meets it at 1.2 - 3 tan 15 = 0.396 m
    panel = upright_box((0.1, 1.0, 2.0), (3.0, 0.0), 0.0)
    far_panel = upright_box((0.1, 1.0, 2.0), (150.0, 0.0), 0.0)  # beyond the 100 m range
    buffers = scene([("panel", "car", 5, panel), ("far", "car", 6, far_panel)])
    boxes = gb.fit_boxes(buffers, ["car"], {5: 0.0, 6: 0.0})
    vis.visibility(buffers, boxes, iter_pattern(SENSOR, 1 << 18), POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.0)
    near, far = boxes[boxes["instance"] == 5][0], boxes[boxes["instance"] == 6][0]
    hidden_below = (1.2 - 3.0 * np.tan(np.radians(15.0))) / 2.0  # of the panel's height (its faces: mostly front and back)
    assert abs(near["truncation"] - hidden_below) < 0.08, near["truncation"]
    assert far["truncation"] == 1.0 and far["unoccluded"] == 0
    assert vis.occlusion_levels(far["visible"], far["unoccluded"])[()] == 3


def test_thin_boxes_are_dropped_by_their_class_minimum():
    boxes = np.zeros(4, gb.BOX_DTYPE)
    boxes["class_name"] = ["car", "car", "person", "robot arm"]
    boxes["points"] = [12, 11, 6, 5]
    kept = gb.keep_boxes(boxes, {"car": 12}, default=6)
    assert kept["class_name"].tolist() == ["car", "person"] and kept["points"].tolist() == [12, 6]
    points = np.zeros(7, [("instance", "<u4")])
    points["instance"] = [3, 3, 3, 9, 9, 0, 0]
    boxes = np.zeros(3, gb.BOX_DTYPE)
    boxes["instance"] = [3, 9, 4]
    gb.count_points(boxes, points)
    assert boxes["points"].tolist() == [3, 2, 0]


def sample_boxes(rng, n=5, ahead=True):
    boxes = np.zeros(n, gb.BOX_DTYPE)
    boxes["class_name"] = ["car", "person", "robot arm", "car", "person"][:n]
    boxes["instance"] = np.arange(1, n + 1)
    boxes["centre"] = rng.uniform(-20, 20, (n, 3))
    if ahead:  # in front of the camera, inside its 81 deg field of view
        boxes["centre"][:, 0] = rng.uniform(8, 25, n)
        boxes["centre"][:, 1] = rng.uniform(-0.5, 0.5, n) * boxes["centre"][:, 0]
        boxes["centre"][:, 2] = rng.uniform(-1, 0.5, n)
    boxes["size"] = rng.uniform(0.3, 5, (n, 3))
    boxes["heading"] = rng.uniform(-np.pi, np.pi, n)
    boxes["truncation"] = rng.uniform(0, 0.5, n)
    boxes["occlusion"] = [0, 1, 2, 3, 0][:n]
    return boxes


def box_points(boxes):
    """Three points at each box's centre carrying its instance."""
    points = empty_points(3 * len(boxes))
    for k, box in enumerate(boxes):
        for name, value in zip("xyz", box["centre"]):
            points[name][3 * k : 3 * k + 3] = value
        points["instance"][3 * k : 3 * k + 3] = box["instance"]
    return points


def test_kitti_and_openpcdet_files_round_trip(tmp_path):
    from bpy_pipeline.config import CameraConfig
    from bpy_pipeline.io import kitti, openpcdet

    boxes = sample_boxes(np.random.default_rng(2))
    points = box_points(boxes)
    lut = np.zeros((64, 3), np.uint8)
    written = kitti.write_frame(tmp_path, "000007", points, boxes, CameraConfig(), lut, {"person": "Pedestrian"}) + openpcdet.write_frame(
        tmp_path, "000007", points, boxes, {"person": "Pedestrian"}
    )
    assert {p.relative_to(tmp_path).as_posix() for p in written} == {"kitti/training/label_2/000007.txt", "kitti/training/calib/000007.txt",
                                                                     "kitti/training/velodyne/000007.bin", "kitti/training/planes/000007.txt",
                                                                     "kitti/training/image_2/000007.png", "openpcdet/labels/000007.txt",
                                                                     "openpcdet/points/000007.npy"}
    tr = np.array((tmp_path / "kitti/training/calib/000007.txt").read_text().splitlines()[5].split()[1:], float).reshape(3, 4)
    read_kitti = bx.read_kitti_labels(tmp_path / "kitti/training/label_2/000007.txt", tr)
    pcdet = bx.read_openpcdet_labels(tmp_path / "openpcdet/labels/000007.txt")
    assert read_kitti["class_name"].tolist() == ["Car", "Pedestrian", "Misc", "Car", "Pedestrian"]  # labels.yaml kitti_names, names override
    assert pcdet["class_name"].tolist() == ["Car", "Pedestrian", "RobotArm", "Car", "Pedestrian"]
    for read in (read_kitti, pcdet):
        np.testing.assert_allclose(read["centre"], boxes["centre"], atol=1e-4)
        np.testing.assert_allclose(read["size"], boxes["size"], atol=1e-4)
        np.testing.assert_allclose(np.cos(read["heading"] - boxes["heading"]), 1.0, atol=1e-7)
    assert read_kitti["occlusion"].tolist() == [0, 1, 2, 3, 0]
    # KITTI's camera convention as OpenPCDet reads it: location = bottom centre, heading = -(rotation_y + pi / 2)
    first = (tmp_path / "kitti/training/label_2/000007.txt").read_text().splitlines()[0].split()
    x, y, z = map(float, first[11:14])
    np.testing.assert_allclose([z, -x, -y + float(first[8]) / 2], boxes["centre"][0], atol=1e-4)
    assert np.isclose(np.cos(-(float(first[14]) + np.pi / 2) - boxes["heading"][0]), 1.0)
    left, top, right, bottom = map(float, first[4:8])
    assert 0 <= left <= right < 1242 and 0 <= top <= bottom < 375  # the points' pixel, not zeros
    assert np.load(tmp_path / "openpcdet/points/000007.npy").shape == (15, 4)


def test_kitti_camera_pose_and_frames_without_objects(tmp_path):
    from bpy_pipeline.config import CameraConfig
    from bpy_pipeline.io import kitti

    boxes = sample_boxes(np.random.default_rng(3), 2)
    boxes["centre"][:, :2] = [[0.0, 10.0], [-10.0, 0.0]]  # left of the sensor, behind it
    points = box_points(boxes)
    ahead = kitti.label_lines(boxes, points, CameraConfig())
    assert ahead == [kitti.DONT_CARE]  # nothing in the forward camera: KITTI's placeholder, so loaders read the file
    left = kitti.label_lines(boxes, points, CameraConfig(rotation_deg=(0.0, 0.0, 90.0)))
    assert len(left) == 1 and left[0].startswith("Car")
    k, tr = kitti.camera_matrices(CameraConfig(rotation_deg=(0.0, 0.0, 90.0)))
    path = tmp_path / "l.txt"
    path.write_text(left[0] + "\n")
    read = bx.read_kitti_labels(path, tr)
    np.testing.assert_allclose(read["centre"][0], boxes["centre"][0], atol=1e-4)
    np.testing.assert_allclose(np.cos(read["heading"][0] - boxes["heading"][0]), 1.0, atol=1e-7)


def test_a_tilted_frame_cannot_hold_upright_boxes():
    from bpy_pipeline.errors import InputError

    boxes = np.zeros(1, gb.BOX_DTYPE)
    with pytest.raises(InputError, match="output.frame"):
        gb.boxes_in_frame(boxes, pose_matrix([0, 0, 3], [0, 90, 0]))


@pytest.mark.bpy
def test_pipeline_writes_boxes_that_hold_the_hall_points(tmp_path):
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["scene.builder=industrial_hall", "frames=2", "sensor.columns=1024", "output.formats=[ply]", "output.preview=false",
                                "sensor.reflector.edge_drop.mask=none", "effects.ideal=true"])
    run(config, tmp_path, log=lambda *_: None)
    manifest = read_dataset(tmp_path)
    checked = 0
    for frame in manifest["frames"]:
        points = read_ply(tmp_path / "ply" / f"{frame['index']:06d}.ply")
        labels = bx.read_openpcdet_labels(tmp_path / "openpcdet" / "labels" / f"{frame['index']:06d}.txt")
        kitti = bx.read_kitti_labels(tmp_path / "kitti" / "training" / "label_2" / f"{frame['index']:06d}.txt")
        assert len(labels) == len(frame["boxes"]) >= 2 and len(kitti) <= len(labels) and "boxes" in frame["timings_s"]  # KITTI: the camera's view only
        xyz = np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64)
        for box, entry in zip(labels, frame["boxes"]):
            mine = points["instance"] == entry["instance"]
            assert mine.sum() == entry["points"] >= 6
            assert gb.points_in_box(xyz[mine], box, 1e-3).all()
            assert entry["points"] == entry["visible"] <= entry["unoccluded"]  # no effects: every visible ray is a point
            checked += 1
    assert checked >= 4


def scan_with_direct_returns(caster, buffers, rays, **options):
    """``(points, direct_returns)``: the scan of ``rays`` (chunks) from ``POSE`` and, per ray, the instance of its return
    that met no mirror, -1 for none (what the effects stage keeps for the boxes: ``frame.direct_returns``)."""
    from bpy_pipeline.lidar.cast.scanner import scan_chunks
    from bpy_pipeline.stages.scan import add_direct_returns

    points, direct = [], np.full(100, -1, np.int64)  # short: the table grows
    for p, _, ray in scan_chunks(caster, buffers, rays, POSE, SENSOR.min_range, SENSOR.max_range, with_rays=True, **options):
        hit = p["bounces"] == 0
        points.append(p.copy())
        direct = add_direct_returns(direct, ray[hit], p["instance"][hit])
    assert len(direct) <= sum(len(r) for r in rays)
    return np.concatenate(points), direct


def people_pillar_mirror_and_glass():
    """:func:`people_and_pillar` with a mirror 3 m behind the sensor that sends beams back into the scene and a glass
    pane in front of person 10, part of its instance (as a car's windows are the car's)."""
    from bpy_pipeline.lidar.cast.scanner import GLASS, MIRROR

    mirror = ("mirror", "mirror", 4, primitives.translated(primitives.box(0.05, 12.0, 4.0), (-3.0, 0.0, 1.5)), MIRROR, 0.9)
    pane = ("pane", "glass", 10, primitives.translated(primitives.box(0.02, 1.5, 2.5), (6.0, 0.0, 1.0)), GLASS, 0.1)
    return people_and_pillar([mirror, pane])


@pytest.mark.parametrize("kernel", ["numba", "numpy"])
@pytest.mark.parametrize("glass_reflect", [0.0, 1.0])
def test_visible_counts_from_the_scans_direct_returns_are_the_traced_ones(kernel, glass_reflect, monkeypatch):
    """The boxes' ``visible`` counted from the scan's returns that met no mirror is what tracing the rays that pass
    the boxes again gives, with a mirror in the scene and a box's glass passed or reflected (no draw either way)."""
    from bpy_pipeline.lidar.cast.scanner import MirrorGlassRules
    from bpy_pipeline.lidar.cast.visibility import counts_per_instance, visibility

    if kernel == "numba":
        pytest.importorskip("numba")
    monkeypatch.setenv("BPY_PIPELINE_SCAN_KERNEL", kernel)
    buffers, people = people_pillar_mirror_and_glass()
    surfaces = MirrorGlassRules(mirror_return_deg=0.5, glass_return_deg=5.0, glass_reflect=glass_reflect)
    rays = list(iter_pattern(SENSOR, 1 << 14))
    caster = RayCaster(buffers, frame=POSE)
    points, direct = scan_with_direct_returns(caster, buffers, rays, max_bounces=3, surfaces=surfaces, rng=np.random.default_rng(0))
    ghosts = points["bounces"] > 0
    assert (ghosts & (points["instance"] == 4)).sum() > 1000  # the mirror's returns
    traced = gb.fit_boxes(buffers, ["person", "pillar", "wall", "glass"], {k: p.yaw for k, p in people.items()})  # each box holds its instance
    counted = traced.copy()
    visibility(buffers, traced, rays, POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5, caster=caster, surfaces=surfaces, rng=np.random.default_rng(1))
    visibility(buffers, counted, rays, POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5, caster=caster, surfaces=surfaces, rng=np.random.default_rng(1),
               direct_returns=direct)  # fmt: skip
    assert (traced["visible"] > 0).all() and (traced["visible"] < traced["unoccluded"]).any()
    np.testing.assert_array_equal(counted["visible"], traced["visible"])
    np.testing.assert_array_equal(counted["unoccluded"], traced["unoccluded"])
    np.testing.assert_array_equal(counted["truncation"], traced["truncation"])
    if glass_reflect == 1.0:  # the pane's reflected returns carry its box's instance: counting them too would not be the trace's
        assert (ghosts & (points["instance"] == 10)).sum() > 20
        every = counts_per_instance(traced["instance"], points["instance"].astype(np.int64))
        assert (every > traced["visible"]).any()


def test_a_ray_counted_from_the_scan_is_never_traced_alone(monkeypatch):
    """A (ray, box) pair whose ray's return in the scan met no mirror and lies on the box's object counts as unoccluded
    from the scan; only the other pairs whose ray meets the box are traced alone, so ``visible <= unoccluded`` always."""
    from bpy_pipeline.lidar.cast.scanner import MirrorGlassRules

    buffers, people = people_pillar_mirror_and_glass()
    surfaces = MirrorGlassRules(mirror_return_deg=0.5, glass_return_deg=5.0, glass_reflect=0.0)
    rays = list(iter_pattern(SENSOR, 1 << 14))
    caster = RayCaster(buffers, frame=POSE)
    _, direct = scan_with_direct_returns(caster, buffers, rays, max_bounces=3, surfaces=surfaces)
    boxes = gb.fit_boxes(buffers, ["person", "pillar", "wall", "glass"], {k: p.yaw for k, p in people.items()})
    traced = []
    alone_counts = vis.alone_counts

    def recorded(*args):
        directions, box = args[7], args[8]
        traced.append((directions.copy(), box.copy()))
        return alone_counts(*args)

    monkeypatch.setattr(vis, "alone_counts", recorded)
    vis.visibility(buffers, boxes, rays, POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5, caster=caster, surfaces=surfaces, direct_returns=direct)
    ray_of = {d.tobytes(): i for i, d in enumerate(np.concatenate([r.directions for r in rays]))}
    directions, box = (np.concatenate(a) for a in zip(*traced))
    ray = np.array([ray_of[d.tobytes()] for d in directions])
    assert len(ray) > 100 and (boxes["visible"] > 0).all()
    assert not (direct[ray] == boxes["instance"][box]).any()
    assert (boxes["visible"] <= boxes["unoccluded"]).all() and (boxes["visible"] < boxes["unoccluded"]).any()
    # and what the scan answers is what tracing every pair alone gives
    plain = gb.fit_boxes(buffers, ["person", "pillar", "wall", "glass"], {k: p.yaw for k, p in people.items()})
    vis.visibility(buffers, plain, rays, POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5, caster=caster, surfaces=surfaces)
    np.testing.assert_array_equal(boxes["unoccluded"], plain["unoccluded"])


def test_meets_boxes_keeps_every_ray_that_meets_an_object():
    """The rays whose line misses an object's box (grown by BOX_MARGIN) are left out of the trace alone: none of them
    meets the object, even aimed at its corners and edges; of rays aimed about it, many miss."""
    mesh = upright_box((4.0, 1.8, 1.5), (12.0, -3.0), 0.7)
    buffers = scene([("car", "car", 5, mesh)])
    boxes = gb.fit_boxes(buffers, ["car"], {5: 0.7})
    pose = pose_matrix([1.0, 2.0, 1.7], [2.0, -3.0, 20.0])
    rng = np.random.default_rng(4)
    v, t = mesh
    edges = np.concatenate([(v[t[:, i]] + v[t[:, (i + 1) % 3]]) / 2 for i in range(3)])
    targets = np.concatenate([v, edges, boxes["centre"] + rng.uniform(-1.0, 1.0, (20000, 3)) * boxes["size"]])
    sensor = (targets - pose[:3, 3]) @ pose[:3, :3]
    directions = sensor / np.linalg.norm(sensor, axis=1)[:, None]
    origins = np.zeros_like(directions)
    meets = vis.meets_boxes(boxes, pose, origins, directions, np.zeros(len(directions), np.int64))
    hit = np.zeros(len(directions), bool)
    hit[RayCaster(buffers, frame=pose).intersect(origins, directions).ray] = True
    assert hit.sum() > 1000 and meets[hit].all()
    assert (~meets).sum() > 5000
    assert meets[: len(v) + len(edges)].all()
    # a line in the plane of a face grown by the margin (a 0/0 in the slab test) is kept
    cube = np.zeros(1, gb.BOX_DTYPE)
    cube["size"] = 2.0
    edge = vis.meets_boxes(cube, np.eye(4), np.array([[1.0 + vis.BOX_MARGIN, 0.0, -5.0]]), np.array([[0.0, 0.0, 1.0]]), np.zeros(1, np.int64))
    assert edge.all()


def test_counts_per_instance():
    from bpy_pipeline.lidar.cast.visibility import counts_per_instance

    values = np.array([7, 3, 3, 9, 12, 7, 7, 0, 100], np.int64)
    np.testing.assert_array_equal(counts_per_instance(np.array([7, 100, 3, 5]), values), [3, 1, 2, 0])
    np.testing.assert_array_equal(counts_per_instance(np.array([200]), values), [0])
    assert counts_per_instance(np.zeros(0, np.int64), values).shape == (0,)
    np.testing.assert_array_equal(counts_per_instance(np.array([3, 7]), np.zeros(0, np.int64)), [0, 0])


def test_a_box_short_of_its_instance_keeps_the_trace():
    """A rider's box fitted without the motorcycle it shares an instance with does not hold it: returns from the
    motorcycle outside the box's sphere are not the trace's, so the boxes take the trace (``boxes_hold_their_instances``)."""
    from bpy_pipeline.lidar.cast.visibility import visibility
    from bpy_pipeline.stages.annotate import boxes_hold_their_instances

    buffers, people = people_and_pillar()
    # beside person 10, outside its box's sphere, its instance
    whole, _ = people_and_pillar([("cart", "motorcycle", 10, upright_box((1.0, 1.6, 1.0), (8.0, 1.6), 0.0))])
    classes = ["person", "pillar", "wall"]
    boxes = gb.fit_boxes(whole, classes, {k: p.yaw for k, p in people.items()})
    assert not boxes_hold_their_instances(whole, boxes, classes)
    assert boxes_hold_their_instances(whole, boxes, classes + ["motorcycle"]) and boxes_hold_their_instances(buffers, gb.fit_boxes(buffers, classes), classes)
    rays = list(iter_pattern(SENSOR, 1 << 14))
    caster = RayCaster(whole, frame=POSE)
    points, direct = scan_with_direct_returns(caster, whole, rays)
    traced, counted = boxes.copy(), boxes.copy()
    visibility(whole, traced, rays, POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5, caster=caster)
    visibility(whole, counted, rays, POSE, SENSOR.min_range, SENSOR.max_range, cell_deg=2.5, caster=caster, direct_returns=direct)
    ten = boxes["instance"] == 10
    assert counted["visible"][ten] > traced["visible"][ten]  # why the guard is there
    # the annotate stage's boxes with the scan's returns given are the trace's: it keeps the trace for this scene
    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages.annotate import world_boxes

    config = load_config(None, ["sensor.preset=vlp16", "output.boxes.formats=[kitti]", "output.boxes.classes=[person]"])
    given = world_boxes(whole, config, POSE, points, {k: p.yaw for k, p in people.items()}, caster=caster, direct_returns=direct)
    plain = world_boxes(whole, config, POSE, points, {k: p.yaw for k, p in people.items()}, caster=caster)
    assert len(given) == 3 and given.tobytes() == plain.tobytes()


def test_the_scan_keeps_its_direct_returns_only_where_the_boxes_trace_would_cast_its_rays():
    from bpy_pipeline.config import load_config
    from bpy_pipeline.frame import Frame
    from bpy_pipeline.stages.scan import counts_direct_returns

    def kept(overrides, moving=False):
        config = load_config(None, ["scene.builder=parking"] + overrides)
        frame = Frame(0, config, np.random.default_rng(0))
        if moving:
            frame.trajectory = object()
        return counts_direct_returns(config, frame)

    assert kept([]) and kept(["effects.mirrors.glass.reflect_fraction=1.0"])
    assert not kept(["output.boxes.formats=[]"])  # no boxes
    assert not kept([], moving=True)  # the boxes trace from the frame's first pose
    assert not kept(["effects.mirrors.glass.reflect_fraction=0.5"])  # glass draws: the trace would draw again
    assert not kept(["sensor.divergence.rays=7", "sensor.divergence.mrad=3.0"])  # a firing's sub-rays


@pytest.mark.bpy
def test_a_garage_run_counts_visible_from_its_scan_with_the_traces_boxes(bpy_scene, tmp_path, monkeypatch):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import run_frames
    from bpy_pipeline.stages import scan as scan_stages

    config = load_config(None, ["scene.builder=parking", "frames=3", "seed=2"])
    boxes, kept = {}, {}
    for counted in (True, False):
        if not counted:
            monkeypatch.setattr(scan_stages, "counts_direct_returns", lambda config, frame: False)
        bpy_scene.ops.wm.read_factory_settings(use_empty=True)
        frames = list(run_frames(config, tmp_path / str(counted)))
        boxes[counted] = [f.boxes for f in frames]
        kept[counted] = [f.direct_returns is not None for f in frames]
    assert kept == {True: [True] * 3, False: [False] * 3}
    assert sum(len(b) for b in boxes[True]) > 5 and all((b["visible"] > 0).any() for b in boxes[True])
    for ours, traced in zip(boxes[True], boxes[False]):
        assert (ours["visible"] <= ours["unoccluded"]).all()
        # the unoccluded rays counted from the scan rather than traced alone: the same but where the two casts round apart
        # (a ray grazing an edge), one ray here and there
        assert np.abs(ours["unoccluded"].astype(np.int64) - traced["unoccluded"]).max() <= 2
        for name in set(ours.dtype.names) - {"unoccluded", "occlusion"}:
            assert ours[name].tobytes() == traced[name].tobytes(), name


def test_road_plane_is_kittis_and_holds_the_ground_for_any_sensor_pose_and_points_frame():
    """planes/NNNNNN.txt as KITTI's: ``a b c d`` in the rectified camera frame, normal up (b < 0), d the camera's height
    above the road; every world ground point (z = 0) lies on it, whatever the sensor's tilt, the points' frame
    (sensor, world, kitti) or the camera's offset from the LiDAR."""
    from bpy_pipeline.config import CameraConfig
    from bpy_pipeline.geometry.transforms import output_pose, pose_matrix, sensor_to_output
    from bpy_pipeline.io import kitti

    rng = np.random.default_rng(4)
    ground = np.c_[rng.uniform(-30, 30, (50, 2)), np.zeros(50), np.ones(50)]  # world
    for pose in (pose_matrix([0, 0, 1.73], [0, 0, 0]), pose_matrix([5, -3, 4.5], [2, 8, 130])):
        for camera in (CameraConfig(), CameraConfig(position=(-7.0, 0.5, -2.8), rotation_deg=(0.0, 0.0, 20.0))):
            for frame in ("sensor", "world", "kitti"):
                to_points = sensor_to_output(frame, pose, camera.position)
                k, tr = kitti.camera_matrices(camera, to_points)
                plane = kitti.road_plane(tr, kitti.points_ground(pose, frame, None, camera.position))
                text = kitti.plane_text(plane).splitlines()
                assert text[:3] == ["# Matrix", "WIDTH 4", "HEIGHT 1"]
                read = np.array(text[3].split(), float)
                assert np.linalg.norm(read[:3]) == pytest.approx(1.0) and read[1] < 0
                camera_world = pose @ np.append(camera.position, 1.0)
                assert read[3] == pytest.approx(camera_world[2], abs=1e-5)  # the camera's height above the road
                points = (np.linalg.inv(output_pose(frame, pose, camera.position)) @ ground.T).T  # the ground in the points' frame
                cam = points[:, :3] @ tr[:, :3].T + tr[:, 3]
                np.testing.assert_allclose(cam @ read[:3] + read[3], 0.0, atol=1e-5)


def test_kitti_frame_is_level_with_the_ground_173_m_below_under_the_camera():
    from bpy_pipeline.geometry.transforms import output_pose, pose_matrix, sensor_to_output

    pose = pose_matrix([5, -3, 4.5], [3, 10, 130])  # a tilted sensor 4.5 m up
    frame = output_pose("kitti", pose, (-7.0, 0.0, -2.77))
    np.testing.assert_allclose(frame[:3, 2], [0, 0, 1], atol=1e-12)  # level: boxes stay upright
    camera_world = pose @ np.array([-7.0, 0.0, -2.77, 1.0])
    np.testing.assert_allclose(frame[:3, 3], [camera_world[0], camera_world[1], 1.73])
    np.testing.assert_allclose(np.degrees(np.arctan2(frame[1, 0], frame[0, 0])), 130.0, atol=2.0)  # the sensor's heading (its tilted x projected)
    np.testing.assert_allclose(sensor_to_output("kitti", pose, (-7.0, 0.0, -2.77)), np.linalg.inv(frame) @ pose, atol=1e-12)
    assert sensor_to_output("sensor", pose) is None and np.array_equal(sensor_to_output("world", pose), pose)
    tilted = gb.boxes_in_frame(sample_boxes(np.random.default_rng(1), 2), frame)  # no InputError: the kitti frame is level
    assert len(tilted) == 2


def test_dont_care_boxes_are_kitti_regions_after_the_boxes():
    from bpy_pipeline.config import CameraConfig
    from bpy_pipeline.io import kitti

    boxes = sample_boxes(np.random.default_rng(2))
    boxes["centre"][:, 0] = np.abs(boxes["centre"][:, 0]) + 5  # ahead of the camera
    boxes["centre"][:, 1] = 0.0
    lines = kitti.label_lines(boxes, box_points(boxes), CameraConfig(), names={"car": "DontCare"})
    kinds = [line.split()[0] for line in lines]
    assert kinds == ["Pedestrian", "Misc", "Pedestrian", "DontCare", "DontCare"]  # the boxed objects first, as the loaders need
    fields = lines[-1].split()
    assert fields[1:4] == ["-1", "-1", "-10"] and fields[8:] == ["-1", "-1", "-1", "-1000", "-1000", "-1000",
                                                                 "-10"] and float(fields[6]) >= float(fields[4]) >= 0


def test_kitti_difficulty_is_what_both_samplers_keep():
    from bpy_pipeline.io.train_configs import kitti_difficulty

    def line(trunc, occ, top, bottom):
        return f"Car {trunc} {occ} 0 10 {top} 50 {bottom} 1.5 1.6 3.9 0 1.7 10 0".split()

    assert [kitti_difficulty(line(0, 0, 0, 41)), kitti_difficulty(line(0.2, 1, 0, 30)), kitti_difficulty(line(0.45, 2, 0, 30))] == [0, 1, 2]
    assert kitti_difficulty(line(0, 0, 0, 25)) == -1  # 25 px: mmdetection3d's hard needs more (OpenPCDet's would keep it)
    assert kitti_difficulty(line(0.6, 0, 0, 100)) == -1 and kitti_difficulty(line(0, 3, 0, 100)) == -1
