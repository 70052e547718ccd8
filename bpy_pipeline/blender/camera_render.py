"""The KITTI layout's camera image (``image_2``): the scene rendered by Blender from the camera of
``output.kitti.camera``, fixed to the LiDAR.

Workbench (Blender's solid viewport engine: it runs headless with the bpy module, about a second
a frame at 1242 x 375 on two cores), flat lighting, no anti-aliasing, each object in its class colour from
``assets_manifest/labels.yaml``, so the image shows what the labels mean. The scene's render
settings, camera and object colours are restored afterwards. Returns the image as an array; the
KITTI writer (pure, :mod:`bpy_pipeline.io.kitti`) writes it, and falls back to a projection of the
labelled points where no rendered image is given.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import bpy
import numpy as np

from ..geometry.transforms import euler_xyz_matrix

CAMERA_NAME = "bpy_pipeline KITTI camera"
# Blender's camera looks along its -z with +y up; the KITTI camera body looks along the sensor's x with z up.
BODY_TO_BLENDER = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # columns: camera x, y, z in body axes


def camera_matrix_world(camera, pose: np.ndarray) -> np.ndarray:
    """``(4, 4)`` world matrix of the Blender camera for ``output.kitti.camera`` on a sensor at ``pose`` (sensor to world)."""
    local = np.eye(4)
    local[:3, :3] = euler_xyz_matrix(camera.rotation_deg) @ BODY_TO_BLENDER
    local[:3, 3] = camera.position
    return np.asarray(pose, float) @ local


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """sRGB components 0..1 (the class table's colours) to linear light, as Blender's colour properties hold them."""
    values = np.asarray(values, float)
    return np.where(values <= 0.04045, values / 12.92, ((values + 0.055) / 1.055) ** 2.4)


def render_camera(camera, pose: np.ndarray, colors: dict[str, tuple[int, int, int]] | None = None) -> np.ndarray:
    """``(height, width, 3) uint8``: the current scene seen by ``camera`` (``output.kitti.camera``) on a sensor at ``pose``.

    colors : {object name: RGB 0..255} drawn flat (objects not listed keep their own colour)
    """
    scene = bpy.context.scene
    width, height = (int(v) for v in camera.resolution)
    data = bpy.data.cameras.new(CAMERA_NAME)
    data.sensor_fit = "HORIZONTAL"
    data.angle_x = float(np.radians(camera.fov_deg))
    data.clip_start, data.clip_end = 0.1, 1000.0
    obj = bpy.data.objects.new(CAMERA_NAME, data)
    scene.collection.objects.link(obj)
    obj.matrix_world = camera_matrix_world(camera, pose).T.tolist()  # a nested sequence is read column by column
    render, shading, view = scene.render, scene.display.shading, scene.view_settings
    saved = {"camera": scene.camera, "engine": render.engine, "x": render.resolution_x, "y": render.resolution_y, "percent": render.resolution_percentage,
             "path": render.filepath, "format": render.image_settings.file_format, "light": shading.light, "color_type": shading.color_type,
             "aa": scene.display.render_aa, "view": view.view_transform, "look": view.look, "dither": render.dither_intensity}
    saved_colors = {}
    try:
        scene.camera = obj
        render.engine = "BLENDER_WORKBENCH"
        render.resolution_x, render.resolution_y, render.resolution_percentage = width, height, 100
        render.image_settings.file_format = "PNG"
        shading.light, shading.color_type = "FLAT", "OBJECT"
        scene.display.render_aa = "OFF"  # crisp class colours: each pixel is one object's
        view.view_transform, view.look = "Standard", "None"  # pixels in the table's sRGB, not a filmic curve's
        render.dither_intensity = 0.0  # exactly the class colours
        colors = dict(colors or {})
        for owner in bpy.data.objects:  # an object of named parts (lidar_parts: the railway's instanced masts) takes its parts' colour
            part = next((str(p) for p in owner.get("lidar_parts", ()) if str(p) in colors), None)
            if part is not None and owner.name not in colors:
                colors[owner.name] = colors[part]  # its parts share its class
        for name, rgb in colors.items():
            target = bpy.data.objects.get(name)
            if target is not None:
                saved_colors[name] = tuple(target.color)
                target.color = (*srgb_to_linear(np.asarray(rgb) / 255.0), 1.0)  # object colours are scene-linear
        with tempfile.TemporaryDirectory() as folder:
            render.filepath = str(Path(folder) / "image_2.png")
            bpy.ops.render.render(write_still=True)
            image = bpy.data.images.load(render.filepath)
            try:
                pixels = np.empty(width * height * 4, np.float32)
                image.pixels.foreach_get(pixels)
            finally:
                bpy.data.images.remove(image)
    finally:
        scene.camera = saved["camera"]
        render.engine, render.resolution_x, render.resolution_y = saved["engine"], saved["x"], saved["y"]
        render.resolution_percentage, render.filepath, render.image_settings.file_format = saved["percent"], saved["path"], saved["format"]
        shading.light, shading.color_type, scene.display.render_aa = saved["light"], saved["color_type"], saved["aa"]
        view.view_transform, view.look, render.dither_intensity = saved["view"], saved["look"], saved["dither"]
        for name, color in saved_colors.items():
            bpy.data.objects[name].color = color
        bpy.data.objects.remove(obj, do_unlink=True)
        bpy.data.cameras.remove(data)
    rgb = np.rint(pixels.reshape(height, width, 4)[::-1, :, :3] * 255.0).astype(np.uint8)  # Blender's rows run bottom up
    return rgb


def class_colors(buffers, color_lut: np.ndarray) -> dict[str, tuple[int, int, int]]:
    """{object name: RGB} of the exported objects from their class ids (``buffers.objects``)."""
    objects = buffers.objects
    return {str(name): tuple(int(c) for c in color_lut[min(int(k), len(color_lut) - 1)]) for name, k in zip(objects.names, objects.semantic)}
