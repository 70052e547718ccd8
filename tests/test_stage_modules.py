"""The stages no other test calls directly: a flash camera's images (lidar/cast/flash_returns.py and stages/flash.py),
the real-scan stages (stages/mixing.py) and the KITTI camera stage (stages/camera.py, a Blender rendering)."""

import numpy as np
import pytest

from bpy_pipeline.buffers import ObjectTable, SceneBuffers
from bpy_pipeline.config import load_config
from bpy_pipeline.frame import Frame, Run, frame_rng
from bpy_pipeline.io.rig_outputs import FLASH_IMAGE_DTYPE, FLASH_RETURNS
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.cast import flash_returns
from bpy_pipeline.lidar.sensor.patterns import camera as camera_pattern
from bpy_pipeline.stages import flash as flash_stages
from bpy_pipeline.stages import mixing as mixing_stages

TABLE = load_class_table()


def walls(*specs):
    """Scene buffers of walls facing the sensor: ``(x, y0, y1, class, reflectivity)`` each, the plane x = const, 40 m high."""
    vertices, triangles, owner = [], [], []
    for i, (x, y0, y1, _, _) in enumerate(specs):
        vertices.append(np.array([[x, y0, -20], [x, y1, -20], [x, y1, 20], [x, y0, 20]], float))
        triangles.append(np.array([[0, 1, 2], [0, 2, 3]], np.int32) + 4 * i)
        owner.append(np.full(2, i, np.int32))
    k = len(specs)
    objects = ObjectTable([f"w{i}" for i in range(k)], [""] * k, [s[3] for s in specs], np.array([TABLE.id_of(s[3]) for s in specs], np.uint16),
                          np.arange(1, k + 1, dtype=np.uint32), np.zeros(k, np.uint8), np.array([s[4] for s in specs], np.float32))
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles), np.concatenate(owner), objects)


# ----------------------------------------------------------------------------- flash returns
def test_a_wall_square_to_the_camera_is_one_return_per_pixel_at_its_depth():
    config = load_config({"sensor": {"preset": "flash96x16"}})
    spec = config.sensor.spec
    images = flash_returns.flash_images(walls((10.0, -50, 50, "wall", 0.6)), spec, np.eye(4), sub=3, max_returns=2)
    rows, columns = spec.channels, spec.columns
    assert images.depth.shape == (2, rows, columns) and (images.returns_per_pixel == 1).all()
    # depth along the pixel's ray: 10 m over the cosine of the pixel centre's angle to x (the sub-rays' mean, within 0.5 %)
    y, z = np.meshgrid(camera_pattern.pinhole_y(spec), camera_pattern.pinhole_z(spec))
    assert np.allclose(images.depth[0], 10.0 * np.sqrt(1 + y**2 + z**2), rtol=5e-3)
    assert (images.semantic[0] == TABLE.id_of("wall")).all() and (images.instance[0] == 1).all() and (images.depth[1] == 0).all()
    assert np.allclose(images.intensity[0], 0.6 / np.sqrt(1 + y**2 + z**2), rtol=1e-2)  # 0.6 x the cosine of incidence


def test_a_pixel_straddling_two_walls_holds_both_nearest_first():
    config = load_config({"sensor": {"preset": "flash96x16"}})
    spec = config.sensor.spec
    k = spec.columns // 4
    edge = 5.0 * camera_pattern.pinhole_y(spec)[k]  # the near wall ends in the middle of column k
    images = flash_returns.flash_images(walls((5.0, edge, 50, "car", 0.5), (20.0, -50, 50, "wall", 0.5)), spec, np.eye(4), sub=4, max_returns=2)
    two = images.returns_per_pixel == 2
    assert two[:, k].all() and two.sum() == spec.channels  # column k only
    near, far = images.depth[0][:, k], images.depth[1][:, k]
    assert np.all((near > 5) & (near < 5.5) & (far > 20) & (far < 22))
    assert (images.semantic[0][:, k] == TABLE.id_of("car")).all() and (images.semantic[1][:, k] == TABLE.id_of("wall")).all()
    assert np.all(images.intensity[0][:, k] < images.intensity[0][:, k - 1])  # half a pixel's return


def test_the_flash_stage_writes_the_frames_image_of_the_run_sensor():
    config = load_config({"sensor": {"preset": "flash96x16"}})
    frame = Frame(0, config, frame_rng(0, 0))
    frame.place(np.eye(4))
    frame.buffers = walls((8.0, -50, 50, "wall", 0.4))
    flash_stages.flash_stage(frame, Run(config))
    image = frame.flash[""]
    assert image.dtype == FLASH_IMAGE_DTYPE and image.shape == (FLASH_RETURNS, config.sensor.spec.channels, config.sensor.spec.columns)
    assert (image["depth"][0] >= 8.0).all() and (image["instance"][0] == 1).all()


# ----------------------------------------------------------------------------- real-scan stages
@pytest.fixture
def real_scan_config(real_scan):
    path = real_scan("nuscenes_hdl32e_sweep.bin")

    def make(frame="sensor"):
        scene = {"builder": "real_scan", "path": str(path), "objects": [{"type": "box", "center": [12.0, 0.0, 0.0], "size": [0.5, 8.0, 3.0]}]}
        return load_config({"scene": scene,
                            "output": {"frame": frame, "boxes": {"formats": ["kitti"], "classes": ["box"] if "box" in TABLE.names else ["car"]}},
                            "sensor": {"position": [100.0, 50.0, 0.0], "rotation_deg": [0, 0, 90]}})

    return make


def run_stages(config):
    frame, run = Frame(0, config, frame_rng(config.seed, 0)), Run(config)
    mixing_stages.real_scan_stage(frame, run)
    return frame, run


def test_the_real_scan_stages_give_mix_frames_points_and_world_frames_move_them(real_scan_config):
    from bpy_pipeline.mixing import mix_frame

    config = real_scan_config()
    frame, run = run_stages(config)
    mixed = mix_frame(config.scene.params, frame_rng(config.seed, 0), config.effects, None, run.table)
    assert frame.points.tobytes() == mixed.points.tobytes() and frame.built and frame.mixed.inserted.sum() > 100
    world, _ = run_stages(real_scan_config("world"))
    xyz = np.column_stack([frame.points[k] for k in "xyz"]).astype(np.float64)
    moved = xyz @ frame.pose[:3, :3].T + frame.pose[:3, 3]
    assert np.allclose(np.column_stack([world.points[k] for k in "xyz"]), moved, atol=1e-3)
    assert not np.allclose(frame.pose, np.eye(4))


def test_kept_scan_reads_a_file_once_while_frames_share_it(real_scan_config):
    section = real_scan_config().scene.params
    keep = {}
    first = mixing_stages.kept_scan(section, 0, keep)
    again = mixing_stages.kept_scan(section, 1, keep)  # one file: every frame uses it
    assert again[0] is first[0] and again[1] is first[1]
    keep["real_scan"] = (("other",), None, None)
    assert mixing_stages.kept_scan(section, 0, keep)[0] is not first[0]


# ----------------------------------------------------------------------------- the KITTI camera stage (Blender)
@pytest.mark.bpy
def test_the_camera_stage_renders_each_object_in_its_class_colour(blender_renders, bpy_scene):
    from bpy_pipeline.geometry import primitives
    from bpy_pipeline.blender.mesh_objects import mesh_object, scene_collection
    from bpy_pipeline.stages.camera import camera_stage

    config = load_config({"output": {"kitti": {"camera": {"resolution": [160, 60]}}}})
    v, t = primitives.box(2.0, 2.0, 2.0)
    mesh_object("cube", (v + np.array([8.0, 0.0, 0.0]), t), scene_collection())
    objects = ObjectTable(["cube"], [""], ["car"], np.array([TABLE.id_of("car")], np.uint16), np.array([1], np.uint32), np.zeros(1, np.uint8),
                          np.ones(1, np.float32))
    frame = Frame(0, config, frame_rng(0, 0))
    frame.place(np.eye(4))
    frame.buffers = SceneBuffers(np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros(0, np.int32), objects)
    run = Run(config)
    camera_stage(frame, run)
    image = frame.images["image_2"]
    assert image.shape == (60, 160, 3)
    colour = run.table.color_lut()[TABLE.id_of("car")]
    painted = np.all(np.abs(image.astype(int) - colour.astype(int)) <= 2, axis=2)
    assert painted.sum() > 100 and painted[:, 70:90].any()  # the cube straight ahead, in the car class's colour
