"""The KITTI camera: Blender's rendering from output.kitti.camera agrees with the calib file's projection."""

import numpy as np
import pytest

from bpy_pipeline.config import CameraConfig
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.io import kitti


@pytest.mark.bpy
@pytest.mark.parametrize("camera", [CameraConfig(), CameraConfig(resolution=(640, 240), fov_deg=70.0, position=(0.2, -0.1, 0.3),
                                                                 rotation_deg=(0.0, 5.0, 20.0))])
def test_rendered_box_lies_where_calib_projects_it(blender_renders, bpy_scene, camera):
    bpy = bpy_scene
    from bpy_pipeline.blender.camera_render import render_camera
    from bpy_pipeline.blender.mesh_objects import mesh_object, scene_collection
    from bpy_pipeline.geometry import primitives

    pose = pose_matrix([3.0, -2.0, 1.5], [0.0, 0.0, 30.0])  # sensor to world
    k, tr = kitti.camera_matrices(camera)
    # a 1 m cube 8 m in front of the camera's optical axis, in the world
    sensor_point = np.linalg.solve(tr[:, :3], np.array([0.0, 0.0, 8.0]) - tr[:, 3])  # camera (0, 0, 8) in the sensor frame
    world = pose[:3, :3] @ sensor_point + pose[:3, 3]
    v, t = primitives.box(1.0, 1.0, 1.0)
    mesh_object("cube", (v + world, t), scene_collection())
    image = render_camera(camera, pose, {"cube": (255, 0, 0)})
    width, height = camera.resolution
    assert image.shape == (height, width, 3) and image.dtype == np.uint8
    red = (image[:, :, 0] > 200) & (image[:, :, 1] < 60) & (image[:, :, 2] < 60)
    assert red.sum() > 50
    rows, cols = np.nonzero(red)
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]) + world
    uv, depth = kitti.project((corners - pose[:3, 3]) @ pose[:3, :3], k, tr)
    assert (depth > 0).all()
    # the red pixels lie inside the projected corners' extent (one pixel of slack), and fill most of it
    assert cols.min() >= uv[:, 0].min() - 1.5 and cols.max() <= uv[:, 0].max() + 0.5
    assert rows.min() >= uv[:, 1].min() - 1.5 and rows.max() <= uv[:, 1].max() + 0.5
    assert abs(np.mean(cols) - np.mean(uv[:, 0])) < 0.1 * (uv[:, 0].max() - uv[:, 0].min()) + 1
    assert "cube" in bpy.data.objects and bpy.context.scene.camera is None  # the scene is left as it was


@pytest.mark.bpy
def test_a_run_renders_image_2_when_asked(blender_renders, bpy_scene, tmp_path):
    """output.kitti.camera.render: the parking frame's image_2 is Blender's rendering (class colours of the
    scene's objects), not the projection of the points; its timing is recorded; without it, no rendering."""
    from PIL import Image

    from bpy_pipeline.config import load_config
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.plan import run

    images, timings = {}, {}
    for render in (True, False):
        bpy_scene.ops.wm.read_factory_settings(use_empty=True)
        overrides = ["scene.builder=parking", "frames=1", "output.formats=[ply]", "output.preview=false", "output.boxes.formats=[kitti]",
                     "output.kitti.camera.resolution=[320, 120]", f"output.kitti.camera.render={str(render).lower()}"]
        out = tmp_path / str(render)
        manifest = run(load_config(None, overrides), out, log=lambda *_: None)
        images[render] = np.asarray(Image.open(out / "kitti" / "training" / "image_2" / "000000.png").convert("RGB"))
        timings[render] = manifest["frames"][0]["timings_s"]
    assert images[True].shape == images[False].shape == (120, 320, 3)
    assert "camera" in timings[True] and "camera" not in timings[False]
    lut = load_class_table().color_lut()
    classes = {tuple(int(v) for v in lut[k]) for k in range(1, len(lut))}

    def in_class_colours(image):  # share of pixels exactly in a class's colour
        return float(np.mean([tuple(c) in classes for c in image.reshape(-1, 3)]))

    # the garage's surfaces fill the rendering, each in its class's colour; the projection is mostly background
    assert in_class_colours(images[True]) > 0.95 and in_class_colours(images[False]) < 0.6
    assert len({tuple(c) for c in images[True].reshape(-1, 3)} & classes) >= 4
