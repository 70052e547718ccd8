"""Sidebar panels (3D Viewport > Sidebar > LiDAR): a view on ``scene.lidar``, drawn from the generated groups."""

from __future__ import annotations

import bpy

from . import cloud
from . import settings as panel
from .bpy_pipeline.labels import load_class_table


def draw_group(layout, group, view, skip=()) -> None:
    """Every shown field of a generated group; a nested group named after a ``model`` choice shows only when chosen."""
    models = next((fv.items for fv in view.fields if fv.attr == "model" and fv.kind == "enum"), ())
    for fv in view.fields:
        if fv.attr in skip:
            continue
        if fv.kind != "group":
            layout.prop(group, fv.attr, expand=fv.kind == "flags")
        elif fv.attr not in models:
            box = layout.box()
            box.label(text=fv.attr.replace("_", " ").capitalize())
            draw_group(box, getattr(group, fv.attr), fv.group)
        elif group.model == fv.attr:
            draw_group(layout.column(), getattr(group, fv.attr), fv.group)


def other_geometry(scene) -> int:
    """Renderable geometry outside the built scene and the clouds: export scans it too (run.py starts empty)."""
    from .bpy_pipeline.export import GEOMETRY_TYPES
    from .bpy_pipeline.scenes.objects import COLLECTION

    own = {o.name for name in (COLLECTION, cloud.COLLECTION) if (c := bpy.data.collections.get(name)) for o in c.all_objects}
    return sum(1 for o in scene.objects if o.type in GEOMETRY_TYPES and not o.hide_render and o.name not in own)


class LidarPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "LiDAR"

    @classmethod
    def poll(cls, context):
        return context.scene is not None and hasattr(context.scene, "lidar")


class LIDAR_PT_run(LidarPanel, bpy.types.Panel):
    bl_label = "LiDAR"
    bl_order = 0

    def draw(self, context):
        settings = context.scene.lidar
        layout = self.layout
        row = layout.row(align=True)
        row.operator("lidar.scan", icon="OUTLINER_OB_LIGHTPROBE")
        row.operator("lidar.show_cloud", icon="OUTLINER_OB_POINTCLOUD")
        row = layout.row(align=True)
        row.prop(settings, "frames")
        row.operator("lidar.generate", icon="RENDER_ANIMATION")
        row = layout.row(align=True)
        row.operator("lidar.config_load", icon="FILE_FOLDER")
        row.operator("lidar.config_save", icon="FILE_TICK")
        row.operator("lidar.config_reset", text="", icon="LOOP_BACK")
        if settings.status:
            layout.label(text=settings.status, icon="INFO")


class LIDAR_PT_scene(LidarPanel, bpy.types.Panel):
    bl_label = "Scene"
    bl_order = 1

    def draw(self, context):
        settings = context.scene.lidar
        layout = self.layout
        layout.prop(settings, "builder")
        if settings.builder == panel.MY_SCENE:
            layout.label(text=bpy.data.filepath or "Save the .blend: the config names it", icon="FILE_BLEND")
            return
        view = panel.VIEWS.builders[settings.builder]
        draw_group(layout.column(), getattr(settings, f"scene_{settings.builder}"), view)
        base = panel.base_dict(settings)["scene"]
        hidden = sorted(k for k in base if k != "builder" and k not in {fv.key for fv in view.fields}) if base.get("builder") == settings.builder else []
        if hidden:
            layout.label(text=f"From the loaded config: {', '.join(hidden)}")
        layout.operator("lidar.build_scene", icon="SCENE_DATA")
        others = other_geometry(context.scene)
        if others:
            layout.label(text=f"{others} other object(s) of this scene are scanned too", icon="INFO")


class LIDAR_PT_sensor(LidarPanel, bpy.types.Panel):
    bl_label = "Sensor"
    bl_order = 2

    def draw(self, context):
        settings = context.scene.lidar
        layout = self.layout
        draw_group(layout.column(), settings.sensor, panel.VIEWS.sensor)
        layout.prop(settings, "pose_source", expand=True)
        if settings.pose_source == "OBJECT":
            layout.prop(settings, "pose_object")
        elif settings.pose_source == "TRAJECTORY":
            layout.prop(settings, "trajectory_curve")
            draw_group(layout.column(), settings.trajectory, panel.VIEWS.trajectory)
            layout.prop(settings.pose, "rotation_deg")
        else:
            draw_group(layout.column(), settings.pose, panel.VIEWS.pose)


class LIDAR_PT_effects(LidarPanel, bpy.types.Panel):
    bl_label = "Effects"
    bl_order = 3
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_group(self.layout, context.scene.lidar.effects, panel.VIEWS.effects)


class LIDAR_PT_labels(LidarPanel, bpy.types.Panel):
    bl_label = "Labels"
    bl_order = 4
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = context.scene.lidar
        layout = self.layout
        layout.prop(settings, "label_class")
        layout.prop(settings, "label_material")
        layout.prop(settings, "label_reflectivity")
        row = layout.row(align=True)
        row.operator("lidar.tag_selected", icon="BOOKMARKS")
        row.operator("lidar.clear_tags", icon="X")
        obj = context.active_object
        if obj is None:
            return
        if "lidar_class" in obj:
            layout.label(text=f"{obj.name}: {obj['lidar_class']} (tag)", icon="OBJECT_DATA")
            return
        names, parent = [], obj
        while parent is not None:
            names.append(parent.name)
            parent = parent.parent
        layout.label(text=f"{obj.name}: {load_class_table().classify(names)} (name rules)", icon="OBJECT_DATA")


class LIDAR_PT_output(LidarPanel, bpy.types.Panel):
    bl_label = "Output"
    bl_order = 5

    def draw(self, context):
        settings = context.scene.lidar
        layout = self.layout
        layout.prop(settings, "out_dir")
        if not settings.out_dir:
            layout.label(text="Empty: the extension's user folder, output/")
        draw_group(layout.column(), settings.output, panel.VIEWS.output)
        layout.prop(settings, "seed")


CLASSES = (LIDAR_PT_run, LIDAR_PT_scene, LIDAR_PT_sensor, LIDAR_PT_effects, LIDAR_PT_labels, LIDAR_PT_output)
