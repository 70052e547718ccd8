"""A URDF arm (ROS-Industrial style): its chain with fixed turns, its own link meshes placed and posed in a scene."""

import re
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry import kinematics, primitives
from bpy_pipeline.geometry.urdf import arm_from_urdf, fit_capsule, read_urdf, rpy_matrix

ROOT = Path(__file__).resolve().parents[1]
URDF = """<?xml version="1.0"?>
<robot name="toy_arm">
  <link name="base_link"><visual><geometry><mesh filename="package://toy_arm/meshes/base.obj"/></geometry></visual></link>
  <link name="link_1"><visual><origin xyz="0 0 0.25"/><geometry><mesh filename="package://toy_arm/meshes/column.obj"/></geometry></visual></link>
  <link name="link_2"><visual><origin xyz="0 0 0.3"/><geometry><mesh filename="package://toy_arm/meshes/beam.obj" scale="1 1 1.2"/></geometry></visual></link>
  <link name="tool0"><visual><origin xyz="0 0 0.05"/><geometry><mesh filename="../meshes/tool.obj"/></geometry></visual></link>
  <joint name="joint_1" type="revolute"><parent link="base_link"/><child link="link_1"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
  <joint name="joint_2" type="revolute"><parent link="link_1"/><child link="link_2"/>
    <origin xyz="0 0 0.5" rpy="1.5707963267948966 0 0"/><axis xyz="1 0 0"/><limit lower="-0.6" upper="0.6" effort="1" velocity="1"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="link_2"/><child link="tool0"/><origin xyz="0 0 0.6"/></joint>
</robot>
"""


def _obj(path: Path, size, lift: float = 0.0) -> None:
    v, t = primitives.box(*size)
    v = v + [0.0, 0.0, lift]
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in v) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in t))


def toy_arm(folder: Path) -> Path:
    """A two-joint arm with a turned second joint and a fixed tool, its meshes in a ROS package layout."""
    meshes = folder / "toy_arm" / "meshes"
    meshes.mkdir(parents=True)
    _obj(meshes / "base.obj", (0.4, 0.4, 0.3), lift=0.15)  # the base from z = 0; the others centred, lifted by their visual origins
    _obj(meshes / "column.obj", (0.16, 0.16, 0.5))
    _obj(meshes / "beam.obj", (0.12, 0.12, 0.5))
    _obj(meshes / "tool.obj", (0.08, 0.08, 0.1))
    urdf = folder / "toy_arm" / "urdf" / "toy_arm.urdf"
    urdf.parent.mkdir()
    urdf.write_text(URDF)
    return urdf


def test_the_chain_folds_fixed_joints_and_keeps_each_joints_turn(tmp_path):
    arm = read_urdf(toy_arm(tmp_path))
    assert arm.name == "toy_arm" and arm.links == ["base_link", "link_1", "link_2"] and arm.joint_names == ["joint_1", "joint_2"]
    np.testing.assert_allclose(arm.turns[1], rpy_matrix((np.pi / 2, 0, 0)))
    np.testing.assert_allclose(arm.lower, [-2.5, -0.6]) and np.testing.assert_allclose(arm.upper, [2.5, 0.6])
    (beam, beam_origin, scale), (tool, tool_origin, _) = arm.visuals[2]
    assert beam.name == "beam.obj" and tool.name == "tool.obj" and list(scale) == [1, 1, 1.2]
    np.testing.assert_allclose(tool_origin[:3, 3], [0, 0, 0.65])  # the fixed joint's 0.6 m, then the visual's 0.05 m
    # forward kinematics with the fixed turn: frame 2 = frame 1 @ T(0, 0, 0.5) @ Rx(90 deg) @ R(x, q2)
    model = arm_from_urdf(arm, [np.zeros((0, 3)), primitives.box(0.1, 0.1, 0.5)[0], primitives.box(0.1, 0.1, 0.5)[0]])
    q = np.array([0.7, -0.4])
    frames = kinematics.forward(model, q)
    expected = frames[1] @ np.block([[rpy_matrix((np.pi / 2, 0, 0)) @ kinematics.axis_rotations(np.array([1.0, 0, 0]), np.array(-0.4)),
                                      np.array([[0], [0], [0.5]])], [np.zeros((1, 3)), np.ones((1, 1))]])
    np.testing.assert_allclose(frames[2], expected, atol=1e-12)


def test_a_fitted_capsule_holds_its_mesh():
    v, _ = primitives.box(0.2, 0.3, 1.5)
    a, b, r = fit_capsule(v @ rpy_matrix((0.3, 0.2, 0.1)).T + [1, 2, 3])
    from bpy_pipeline.geometry.collision import segment_distance

    points = v @ rpy_matrix((0.3, 0.2, 0.1)).T + [1, 2, 3]
    d = segment_distance(points, points, np.repeat(a[None], len(points), 0), np.repeat(b[None], len(points), 0))
    assert (d <= r + 1e-9).all() and np.linalg.norm(b - a) > 0.8


def test_bad_urdfs_are_named(tmp_path):
    path = tmp_path / "bad.urdf"
    cases = {
        "<robot name='x'><link name='a'/><link name='b'/><joint name='j' type='prismatic'><parent link='a'/><child link='b'/></joint></robot>":
            "joint 'j': joint type 'prismatic' cannot be posed",
        "<robot name='x'><link name='a'/><link name='b'/><joint name='j' type='revolute'><parent link='a'/><child link='b'/></joint></robot>":
            "joint 'j': a revolute joint needs <limit lower upper>",
        "<robot name='x'><link name='a'><visual><geometry><mesh filename='gone.stl'/></geometry></visual></link></robot>":
            "link 'a' visual[0]: mesh 'gone.stl' not found",
        "<robot name='x'><link name='a'/></robot>": "no revolute joint: nothing to pose",
        "<robot": "not valid XML",
    }
    for text, message in cases.items():
        path.write_text(text)
        with pytest.raises(InputError, match=re.escape(message)):
            read_urdf(path)


@pytest.mark.bpy
def test_a_urdf_arm_is_placed_with_its_own_meshes_posed_within_its_limits(bpy_scene, tmp_path):
    import sys

    from bpy_pipeline.config import load_config
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.population.placer import meshes_cross
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.stages.scene import build_frame_scene

    sys.path.insert(0, str(ROOT / "examples" / "hall_twin"))
    try:
        from make_hall import build_hall
    finally:
        sys.path.pop(0)
    urdf = toy_arm(tmp_path)
    hall = build_hall(tmp_path / "hall.blend")
    config = load_config({"scene": {"builder": "blend", "path": str(hall), "population": {"robot_arm": {"count": 2, "model": str(urdf)}}},
                          "sensor": {"preset": "vlp16", "position": [0, 0, 2.5]}})
    keep = {}
    for frame in range(3):
        result = build_frame_scene(config, frame, keep=keep)
        assert result.info["population"]["robot_arm"]["placed"] == 2
        scene = keep["population"][1]
        arm = scene.sides["robot_arm"].models
        base_mesh = arm.meshes[0][0]  # read in the file's own axes: the base box 0.4 x 0.4 x 0.3 from z = 0
        np.testing.assert_allclose(base_mesh.min(axis=0), [-0.2, -0.2, 0.0], atol=1e-6)
        np.testing.assert_allclose(base_mesh.max(axis=0), [0.2, 0.2, 0.3], atol=1e-6)
        np.testing.assert_allclose(arm.meshes[2][0][:, 2].max(), 0.7, atol=1e-6)  # the tool's top: 0.6 + 0.05 + 0.05 in link 2
        np.testing.assert_allclose(arm.meshes[2][0][:, 2].min(), 0.0, atol=1e-6)  # the beam, scaled 1.2 along z: 0.3 - 0.3
        buffers = export_scene(load_class_table())
        static = buffers.triangles[(buffers.objects.instance < 10000)[buffers.triangle_object]]
        for instance, placed in scene.last.items():
            q = placed.shape.detail["q"]
            assert kinematics.within_limits(arm.model, q)
            rows = buffers.objects.instance[buffers.triangle_object] == instance
            used, local = np.unique(buffers.triangles[rows], return_inverse=True)
            exported = buffers.vertices[used]
            v, t = arm.posed(q)  # the link meshes posed by the chain, placed where the shape was
            base = placed.matrix.copy()
            base[2, 3] += placed.shape.detail["lift"]
            expected = v @ base[:3, :3].T + base[:3, 3]
            assert len(exported) == len(np.unique(np.round(expected, 9), axis=0)) or len(exported) == len(expected)
            np.testing.assert_allclose(np.sort(exported, axis=0), np.sort(expected, axis=0), atol=1e-5)
            assert not meshes_cross(exported, local.reshape(-1, 3), buffers.vertices, static)
            assert exported[:, 2].min() == pytest.approx(0.01, abs=1e-5)
