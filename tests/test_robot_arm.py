"""The six-axis arm: TX90L parameters, forward kinematics, limits, self-collision, and the Blender chain."""

import numpy as np
import pytest
import yaml

from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry import kinematics
from bpy_pipeline.geometry.collision import segment_distance

# ROS-Industrial staubli_experimental, staubli_tx90_support/urdf/tx90l_macro.xacro: joint limits in radians
URDF_LIMITS = [(-3.14159, 3.14159), (-2.268928, 2.574360), (-2.530727, 2.530727), (-4.712389, 4.712389), (-2.007129, 2.443461), (-4.712389, 4.712389)]


def test_the_model_holds_the_tx90l_limits_and_reach():
    arm = kinematics.load_arm()
    assert arm.joints == 6
    np.testing.assert_allclose(np.column_stack([arm.lower, arm.upper]), URDF_LIMITS, atol=2e-5)
    # reach between axes 1 and 6 (the datasheet's 1200 mm): shoulder offset + upper arm + forearm + wrist
    stretched = kinematics.forward(arm, np.array([0.0, np.pi / 2, 0, 0, 0, 0]))
    np.testing.assert_allclose(stretched[-1, :3, 3], [0.05 + 0.5 + 0.55 + 0.1, 0.05, 0.478], atol=1e-12)


def test_forward_kinematics_against_hand_computed_poses():
    arm = kinematics.load_arm()
    upright = kinematics.forward(arm, np.zeros(6))
    np.testing.assert_allclose(upright[-1, :3, 3], [0.05, 0.05, 0.478 + 0.5 + 0.55 + 0.1], atol=1e-12)
    turned = kinematics.forward(arm, np.array([np.pi / 2, 0, 0, 0, 0, 0]))
    np.testing.assert_allclose(turned[-1, :3, 3], [-0.05, 0.05, 1.628], atol=1e-12)
    # joints 4 and 6 turn about the axis they lie on: the flange position does not move
    wrist = kinematics.forward(arm, np.array([0, 0, 0, 1.0, 0, 2.0]))
    np.testing.assert_allclose(wrist[-1, :3, 3], upright[-1, :3, 3], atol=1e-12)
    # a batch gives the same frames as one by one, and a base pose moves everything rigidly
    q = np.random.default_rng(0).uniform(arm.lower, arm.upper, (5, 6))
    base = np.eye(4)
    base[:3, 3] = [3.0, -2.0, 0.0]
    batch = kinematics.forward(arm, q, base)
    for k in range(5):
        np.testing.assert_allclose(batch[k], kinematics.forward(arm, q[k], base), atol=1e-12)
        np.testing.assert_allclose(batch[k, :, :3, 3] - [3.0, -2.0, 0.0], kinematics.forward(arm, q[k])[:, :3, 3], atol=1e-12)


def test_random_configurations_lie_within_the_limits_and_do_not_collide():
    arm = kinematics.load_arm()
    rng = np.random.default_rng(1)
    configurations = np.array([kinematics.random_configuration(arm, rng, floor_z=0.0) for _ in range(200)])
    assert kinematics.within_limits(arm, configurations).all()
    frames = kinematics.forward(arm, configurations)
    assert (kinematics.self_collision_gaps(arm, frames) >= arm.clearance).all()
    assert (kinematics.floor_gap(arm, frames) >= arm.clearance).all()
    # they spread over the range: every joint uses most of its span
    span = (configurations.max(axis=0) - configurations.min(axis=0)) / (arm.upper - arm.lower)
    assert (span > 0.6).all(), span


def test_self_collision_and_limits_are_detected():
    arm = kinematics.load_arm()
    assert kinematics.is_valid(arm, np.zeros(6), floor_z=0.0)
    folded_wrist = np.radians([0, 0, 0, 0, 140, 0])  # the flange folds back into the forearm
    assert kinematics.self_collision_gaps(arm, kinematics.forward(arm, folded_wrist)).min() < 0
    assert not kinematics.is_valid(arm, folded_wrist)
    down = np.radians([0, -130, 0, 0, 0, 0])  # the upper arm swings into the base and the floor
    assert kinematics.floor_gap(arm, kinematics.forward(arm, down)) < 0
    assert not kinematics.is_valid(arm, down, floor_z=0.0)
    beyond = np.radians([0, 150, 0, 0, 0, 0])  # joint 2 stops at 147.5 degrees
    assert not kinematics.within_limits(arm, beyond)


def test_a_bad_arm_file_names_the_key(tmp_path):
    data = yaml.safe_load(kinematics.ARM_PATH.read_text())
    data["joints"][2]["limits_deg"] = [30, -30]
    path = tmp_path / "arm.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError, match=r"joints\[2\]\.limits_deg: lower must be below upper"):
        kinematics.load_arm(path)
    data["joints"][2]["limits_deg"] = [-30, 30]
    data["joints"][4]["axis"] = [0, 0]
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError, match=r"joints\[4\]\.axis: expected a list of 3 numbers"):
        kinematics.load_arm(path)


@pytest.mark.bpy
def test_blender_chain_evaluates_to_the_forward_kinematics(bpy_scene):
    import bpy

    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.blender.mesh_objects import scene_collection
    from bpy_pipeline.blender.robot_arm import RobotArm

    arm = kinematics.load_arm()
    robot = RobotArm(arm, scene_collection(), 0)
    rng = np.random.default_rng(5)
    base = np.eye(4)
    c, s = np.cos(0.7), np.sin(0.7)
    base[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    base[:3, 3] = [1.5, -0.5, 0.0]
    q = kinematics.random_configuration(arm, rng, base, floor_z=0.0)
    robot.show(base, q, 7)
    bpy.context.view_layer.update()
    frames = robot.world_frames()
    np.testing.assert_allclose(frames, kinematics.forward(arm, q, base), atol=1e-5)
    # the joint angles Blender's chain holds (child relative to parent, about the joint axis) lie within the limits
    for i in range(6):
        relative = np.linalg.inv(frames[i]) @ frames[i + 1]
        axis = arm.axes[i]
        assert np.allclose(relative[:3, 3], arm.origins[i], atol=1e-5)
        rotated = relative[:3, :3]
        u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        angle = np.arctan2(np.dot(np.cross(u, rotated @ u), axis), np.dot(u, rotated @ u))
        assert np.isclose(np.angle(np.exp(1j * (angle - q[i]))), 0.0, atol=1e-5)
        assert arm.lower[i] <= q[i] <= arm.upper[i]
    # every exported vertex of a link lies inside (on) that link's capsules, and all carry the class and instance
    buffers = export_scene(load_class_table())
    a, b, r = kinematics.capsules_world(arm, kinematics.forward(arm, q, base))
    for link in range(7):
        row = buffers.objects.names.index(robot.links[link].name)
        assert buffers.objects.class_names[row] == "robot arm" and buffers.objects.instance[row] == 7
        vertices = buffers.vertices[np.unique(buffers.triangles[buffers.triangle_object == row])]
        mine = np.flatnonzero(arm.capsule_link == link)
        gap = np.min([segment_distance(vertices, vertices, np.broadcast_to(a[k], vertices.shape), np.broadcast_to(b[k], vertices.shape)) - r[k] for k in mine],
                     axis=0)
        assert gap.max() < 1e-5
