"""Articulated people and the industrial hall: joint limits, poses, and no intersections in the built scene."""

import hashlib

import numpy as np
import pytest

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.geometry import human, kinematics
from bpy_pipeline.lidar.cast.raycast import RayCaster


# ----------------------------------------------------------------------------- the body model
def test_every_pose_lies_within_the_joint_limits_without_self_intersection():
    rng = np.random.default_rng(0)
    for kind in human.POSES:
        for _ in range(60):
            angles = human.sample_pose(kind, rng)
            assert human.within_limits(angles), (kind, angles)
            assert human.self_gap(angles, 1.0, max(human.BUILDS.values())) >= 0.0
    assert not human.within_limits(np.where(np.arange(len(human.DOFS)) == human.DOF_INDEX["shank_l.flexion"], 170.0, 0.0))


def test_the_smallest_gap_is_segment_distances_minimum_bit_for_bit():
    """:func:`~bpy_pipeline.geometry.collision.smallest_gap` (the compiled loop where numba is) gives the numbers of
    ``(segment_distance - r_i - r_j).min()``: on the self pairs of drawn poses of every family, and pair by pair on random
    segments, some of them points (zero length) or almost, some parallel."""
    from bpy_pipeline.geometry.collision import segment_distance, smallest_gap

    rng = np.random.default_rng(7)
    build = max(human.BUILDS.values())
    i, j = human.SELF_PAIRS[:, 0], human.SELF_PAIRS[:, 1]
    for kind in human.POSES:
        for _ in range(200):
            a, b, r = human.capsules(human.segment_frames(human._draw_pose(kind, rng), 1.0), 1.0, build)
            assert smallest_gap(a, b, r, human.SELF_PAIRS) == float((segment_distance(a[i], b[i], a[j], b[j]) - r[i] - r[j]).min())
    a = rng.normal(size=(300, 3))
    b = a + rng.normal(size=(300, 3)) * rng.choice([0.0, 1e-10, 1.0], (300, 1))
    b[:20] = a[:20] + (a[20:40] - b[20:40])  # parallel to others
    r = rng.uniform(0.0, 0.1, 300)
    pairs = rng.integers(0, 300, (3000, 2))
    every = segment_distance(a[pairs[:, 0]], b[pairs[:, 0]], a[pairs[:, 1]], b[pairs[:, 1]]) - r[pairs[:, 0]] - r[pairs[:, 1]]
    assert [smallest_gap(a, b, r, pairs[k : k + 1]) for k in range(len(pairs))] == every.tolist()


def _frames_one_at_a_time(angles, height, placement=None):
    """The segments' frames as the module's docstring writes them: every rotation and product one at a time."""
    per_dof = kinematics.axis_rotations(human.DOF_AXIS, np.radians(angles))
    rotations = np.repeat(np.eye(3)[None], len(human.SEGMENTS), axis=0)
    for k, s in enumerate(human.DOF_SEGMENT):
        rotations[s] = rotations[s] @ per_dof[k]
    frames = np.empty((len(human.SEGMENTS), 4, 4))
    for s, parent in enumerate(human.PARENT):
        local = np.eye(4)
        local[:3, :3] = rotations[s]
        local[:3, 3] = (human.JOINT[s] - (human.JOINT[parent] if parent >= 0 else 0.0)) * height
        frames[s] = (frames[parent] if parent >= 0 else (np.eye(4) if placement is None else placement)) @ local
    return per_dof, rotations, frames


def test_stacked_rotations_and_frames_are_the_products_one_at_a_time_bit_for_bit():
    """The degrees of freedom's rotations (one array expression), the joints' (one stacked product per round), the frames
    (one per level) and the levelled feet (each foot's chain) are the numbers of the one-at-a-time products."""
    rng = np.random.default_rng(8)
    for k in range(300):
        angles = rng.uniform(human.LOWER, human.UPPER)
        angles[rng.integers(len(angles), size=6)] = (0.0, -0.0, 90.0, -90.0, 180.0, 45.0)[k % 6]  # signed zeros, exact angles
        placement = np.eye(4)
        placement[:3, :3] = kinematics.axis_rotations(np.array([0.0, 0.0, 1.0]), rng.uniform(-4, 4))
        placement[:3, 3] = rng.normal(size=3) * 40
        height = rng.uniform(1.2, 2.0)
        per_dof, rotations, frames = _frames_one_at_a_time(angles, height, placement)
        assert human.dof_rotations(angles).tobytes() == per_dof.tobytes()
        assert human.joint_rotations(angles).tobytes() == rotations.tobytes()
        assert human.segment_frames(angles, height, placement).tobytes() == frames.tobytes()
        assert human.segment_frames(angles, height).tobytes() == _frames_one_at_a_time(angles, height)[2].tobytes()
        levelled = angles.copy()
        for side in "lr":
            foot = human.DOF_INDEX[f"foot_{side}.flexion"]
            levelled[foot] = 0.0
            forward = _frames_one_at_a_time(levelled, 1.0)[2][human.SEGMENT_INDEX[f"foot_{side}"], :3, 0]
            levelled[foot] = np.clip(-np.degrees(np.arctan2(-forward[2], np.hypot(forward[0], forward[1]))), human.LOWER[foot], human.UPPER[foot])
        assert human._level_feet(angles).tobytes() == levelled.tobytes()


def test_segment_lengths_follow_the_height():
    frames = human.segment_frames(np.zeros(len(human.DOFS)), 1.8)
    joint = {name: frames[human.SEGMENT_INDEX[name], :3, 3] for name in human.SEGMENT_NAMES}
    assert np.isclose(joint["thigh_l"][2] - joint["shank_l"][2], (0.52 - 0.285) * 1.8)
    assert np.isclose(joint["upper_arm_r"][2] - joint["forearm_r"][2], 0.186 * 1.8)
    a, b, r = human.capsules(frames, 1.8)
    top = max(a[:, 2].max(), b[:, 2].max()) + 0  # capsule axis tops
    assert abs((np.maximum(a[:, 2], b[:, 2]) + r).max() - 1.8) < 0.02 * 1.8 and top < 1.8


def test_poses_rest_on_their_support():
    rng = np.random.default_rng(3)
    for kind in ("standing", "walking", "crouching"):
        person = human.pose_person(human.sample_pose(kind, rng), 1.7, 1.0, kind, (2.0, -1.0), 0.4)
        low = np.minimum(person.a[:, 2], person.b[:, 2]) - person.radius
        assert np.isclose(low.min(), 0.0) and np.isclose(person.support[2], 0.0)
    angles = human.sample_pose("sitting", rng)
    seated = human.pose_person(angles, 1.7, 1.0, "sitting", (0.0, 0.0), 0.0, 0.72)
    low = np.minimum(seated.a[:, 2], seated.b[:, 2]) - seated.radius
    on_desk = np.isin(human.CAPSULE_SEGMENT, [human.SEGMENT_INDEX[s] for s in human.SEATED_SEGMENTS])
    assert np.isclose(low[on_desk].min(), 0.72) and low.min() > 0.05  # feet hang above the floor
    edge = human.seat_offset(angles, 1.7, 1.0)
    hanging = np.isin(human.CAPSULE_SEGMENT, [human.SEGMENT_INDEX[s] for s in ("shank_l", "shank_r", "foot_l", "foot_r")])
    assert (np.minimum(seated.a[hanging, 0], seated.b[hanging, 0]) - seated.radius[hanging]).min() > edge  # in front of the desk edge


# ----------------------------------------------------------------------------- the built hall
def _crossings(buffers: SceneBuffers, rows_a, rows_b) -> int:
    """Edges of the triangles of ``rows_a`` that pass through a triangle of ``rows_b`` (Embree)."""
    keep = np.isin(buffers.triangle_object, rows_b)
    if not keep.any() or not len(rows_a):
        return 0
    other = SceneBuffers(buffers.vertices, buffers.triangles[keep], buffers.triangle_object[keep], buffers.objects)
    caster = RayCaster(other, frame=np.eye(4))
    triangles = buffers.triangles[np.isin(buffers.triangle_object, rows_a)]
    edges = np.unique(np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1), axis=0)
    start, end = buffers.vertices[edges[:, 0]], buffers.vertices[edges[:, 1]]
    length = np.linalg.norm(end - start, axis=1)
    hits = caster.intersect(start, (end - start) / length[:, None], length)
    return len(hits.ray)


def _bounds(buffers: SceneBuffers, rows) -> tuple[np.ndarray, np.ndarray]:
    vertices = buffers.vertices[np.unique(buffers.triangles[np.isin(buffers.triangle_object, rows)])]
    return vertices.min(axis=0), vertices.max(axis=0)


def _rows_by_instance(buffers: SceneBuffers) -> dict:
    out = {}
    for row, instance in enumerate(buffers.objects.instance):
        out.setdefault(int(instance), []).append(row)
    return out


def _hall(seed: int, **params):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.scene import build_frame_scene

    sets = ["scene.builder=industrial_hall"] + [f"scene.{k}={v}" for k, v in params.items()]
    config = load_config(None, sets)
    keep = {}
    state = build_frame_scene(config, 0, frame_rng(seed, 0), keep)
    return config, state, export_scene(load_class_table()), keep["industrial_hall"][1]


@pytest.mark.bpy
def test_no_person_intersects_another_person_the_robot_or_furniture(bpy_scene):
    poses = 0
    for seed in range(3):
        config, state, buffers, hall = _hall(seed, people="{kind: normal, mean: 9, std: 0, min: 0, max: 12}")
        rows = _rows_by_instance(buffers)
        classes = {int(buffers.objects.instance[r]): buffers.objects.class_names[r] for r in range(len(buffers.objects))}
        people = [i for i, c in classes.items() if c == "person"]
        solids = [i for i, c in classes.items() if c in ("person", "robot arm", "desk", "shelf", "wall")]
        assert len(people) >= 6, state.info  # a crowded hall: the test means something
        bounds = {j: _bounds(buffers, rows[j]) for j in solids}
        for i in people:  # i's edges through anything near it, their edges through i
            low, high = bounds[i]
            others = [r for j in solids if j != i and (bounds[j][0] <= high).all() and (low <= bounds[j][1]).all() for r in rows[j]]
            assert _crossings(buffers, rows[i], others) == 0 and _crossings(buffers, others, rows[i]) == 0, (seed, i, state.info)
        for person, _, _ in hall.last["people"]:
            assert human.within_limits(person.angles)
            poses += 1
        for _, q, _ in hall.last["robots"]:
            assert kinematics.within_limits(hall.arm, q)
    assert poses >= 18


@pytest.mark.bpy
def test_people_stand_on_walkable_floor_or_sit_on_desks(bpy_scene):
    from bpy_pipeline.geometry.indoor import hall_layout

    kinds = set()
    for seed in range(3):
        config, state, buffers, hall = _hall(seed, people="{kind: normal, mean: 8, std: 0, min: 0, max: 12}",
                                             poses="{standing: 1, walking: 1, sitting: 2, crouching: 1}")
        layout = hall_layout(config.scene.params)
        desks = [f for f in layout.furniture if f.class_name == "desk"]
        footprints = [f.footprint for f in layout.furniture]
        rows = _rows_by_instance(buffers)
        for entry in state.info["people"]:
            vertices = buffers.vertices[np.unique(buffers.triangles[np.isin(buffers.triangle_object, rows[entry["instance"]])])]
            low = vertices[np.argmin(vertices[:, 2])]
            kinds.add(entry["pose"])
            if entry["pose"] == "sitting":
                assert low[2] > 0.05  # the feet hang
                seat = vertices[vertices[:, 2] < desks[0].top + 0.04]
                seat = seat[seat[:, 2] > desks[0].top]
                assert len(seat) and any(((lo <= seat[:, :2] + 1e-9) & (seat[:, :2] <= hi)).all(axis=1).any() for lo, hi in (d.footprint for d in desks))
                assert vertices[:, 2].min() > 0 and (vertices[:, 2] > desks[0].top).sum() > len(vertices) / 2
            else:
                assert -1e-6 <= low[2] <= 0.01, entry  # on the floor
                assert ((layout.low <= low[:2]) & (low[:2] <= layout.high)).all()
                assert not any(((lo <= low[:2]) & (low[:2] <= hi)).all() for lo, hi in footprints), entry
        robot = [i for i in rows if buffers.objects.class_names[rows[i][0]] == "robot arm"]
        for i in robot:
            vertices = buffers.vertices[np.unique(buffers.triangles[np.isin(buffers.triangle_object, rows[i])])]
            assert abs(vertices[:, 2].min()) < 1e-6  # the base stands on the floor
    assert kinds == set(human.POSES)


@pytest.mark.bpy
def test_a_new_frame_reposes_without_rebuilding(bpy_scene):
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.scene import build_frame_scene

    config = load_config(None, ["scene.builder=industrial_hall"])
    keep = {}
    first = build_frame_scene(config, 0, frame_rng(0, 0), keep)
    hall = keep["industrial_hall"][1]
    pointers = {obj.name: obj.as_pointer() for obj in bpy.data.objects}
    second = build_frame_scene(config, 1, frame_rng(0, 1), keep)
    assert keep["industrial_hall"][1] is hall
    survivors = {obj.name: obj.as_pointer() for obj in bpy.data.objects if obj.name in pointers}
    assert survivors == pointers  # the hall, the robot and the people of frame 0 are the same objects
    assert first.info != second.info


@pytest.mark.bpy
def test_assets_in_the_manifest_replace_the_procedural_people(bpy_scene, tmp_path):
    from bpy_pipeline.errors import InputError
    from bpy_pipeline.blender.people import load_assets

    obj = tmp_path / "mannequin.obj"
    corners = [(x, y, z) for x in (-0.2, 0.2) for y in (0.0, 1.7) for z in (-0.12, 0.12)]  # OBJ is y-up
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    obj.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "".join("f " + " ".join(map(str, f)) + "\n" for f in faces))
    digest = hashlib.sha256(obj.read_bytes()).hexdigest()
    manifest = tmp_path / "assets.yaml"
    manifest.write_text(f"assets:\n  - {{name: mannequin, kind: person, path: mannequin.obj, sha256: {digest}, licence: CC0-1.0}}\n")
    assert [a.name for a in load_assets(manifest)] == ["mannequin"]
    config, state, buffers, hall = _hall(0, assets=str(manifest), people="{kind: normal, mean: 4, std: 0, min: 0, max: 12}")
    people = [r for r in range(len(buffers.objects)) if buffers.objects.class_names[r] == "person"]
    assert len(people) >= 3
    for row in people:
        vertices = buffers.vertices[np.unique(buffers.triangles[buffers.triangle_object == row])]
        assert len(vertices) == 8  # the mannequin's box, scaled to each person's height
        height = vertices[:, 2].max() - vertices[:, 2].min()
        assert 1.5 <= height <= 1.98 and abs(vertices[:, 2].min()) < 1e-6
    manifest.write_text(manifest.read_text().replace(digest, "0" * 64))
    with pytest.raises(InputError, match="sha256"):
        load_assets(manifest)
    assert load_assets(tmp_path / "absent.yaml") == []
    # the same mannequin written Z up lies down when read Y up: one clear error, not a hall of people "not placed"
    lying = tmp_path / "lying.obj"
    lying.write_text("".join(f"v {x} {z} {y}\n" for x, y, z in corners) + "".join("f " + " ".join(map(str, f)) + "\n" for f in faces))
    manifest.write_text(
        f"assets:\n  - {{name: lying, kind: person, path: lying.obj, sha256: {hashlib.sha256(lying.read_bytes()).hexdigest()}, licence: CC0-1.0}}\n"
    )
    with pytest.raises(InputError, match=r"^asset 'lying': lying.obj does not stand upright as a person when read Y up"):
        _hall(0, assets=str(manifest), people="{kind: normal, mean: 4, std: 0, min: 0, max: 12}")


def test_the_intersection_check_sees_overlapping_bodies():
    from bpy_pipeline.buffers import ObjectTable

    angles = human.neutral_angles()
    parts = []
    for x in (0.0, 0.25, 3.0):  # the first two overlap, the third stands apart
        person = human.pose_person(angles, 1.75, 1.0, "standing", (x, 0.0), 0.0)
        parts.append(human.body_mesh(person.a, person.b, person.radius)[:2])
    offsets = np.cumsum([0] + [len(v) for v, _ in parts])
    buffers = SceneBuffers(
        np.concatenate([v for v, _ in parts]),
        np.concatenate([t + o for (_, t), o in zip(parts, offsets)]).astype(np.int32),
        np.concatenate([np.full(len(t), k, np.int32) for k, (_, t) in enumerate(parts)]),
        ObjectTable(["a", "b", "c"], [""] * 3, ["person"] * 3, np.full(3, 21, np.uint16), np.arange(1, 4, dtype=np.uint32), np.zeros(3, np.uint8),
                    np.full(3, 0.5, np.float32)),
    )
    assert _crossings(buffers, [0], [1]) > 0 and _crossings(buffers, [1], [0]) > 0
    assert _crossings(buffers, [0], [2]) == 0 and _crossings(buffers, [2], [1]) == 0
