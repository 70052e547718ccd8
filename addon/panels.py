"""Sidebar panels (3D Viewport > Sidebar > LiDAR): a view on ``scene.lidar``, drawn from the generated groups.

Each section shows its common fields first; every other field of the same generated group goes
into a collapsed "Advanced" subpanel. :data:`COMMON` only names which config keys come first:
the fields themselves (their labels, units, types) come from the config dataclasses, so a
field added to the config shows up under Advanced without touching this file.
"""

from __future__ import annotations

import bpy

from . import cloud, fields
from . import settings as panel
from .bpy_pipeline.labels import load_class_table

# Config key paths shown first, by section ("scene.<builder>", "sensor", "effects", "output"); a path
# also covers the fields under it ("cars" shows cars.kind, cars.mean, ...). A builder missing here
# shows its first FIRST_FIELDS top-level fields first.
COMMON = {
    "scene.railway": ("track.start", "track.mid", "track.end", "track.tracks", "supports.span", "catenary.enabled", "detail.mode"),
    "scene.parking": ("length", "bay_width", "ceiling_height", "cars", "place_sensor"),
    "scene.industrial_hall": ("length", "width", "height", "robots", "people"),
    "scene.street": ("arm_length", "lanes_per_direction", "vehicles", "pedestrians"),
    "sensor": (),
    "effects": ("ideal", "noise.sigma", "drop.model", "drop.probability", "mirrors.max_bounces"),
    "output": ("formats", "frame", "preview"),
}
FIRST_FIELDS = 4


def common_paths(section: str, view) -> tuple[str, ...]:
    if section in COMMON:
        return COMMON[section]
    return tuple(fv.key for fv in view.fields[:FIRST_FIELDS])


def _covered(path: str, paths) -> bool:
    return any(path == p or path.startswith(f"{p}.") for p in paths)


def draw_group(layout, group, view, keep=lambda path: True, prefix: str = "") -> int:
    """The fields of a generated group whose key path ``keep`` accepts; returns how many were drawn.

    A nested group named after a ``model`` choice (``drop.carla``) shows only while that model is chosen.
    """
    models = next((fv.items for fv in view.fields if fv.attr == "model" and fv.kind == "enum"), ())
    drawn = 0
    for fv in view.fields:
        path = f"{prefix}{fv.key}"
        if fv.kind != "group":
            if keep(path):
                layout.prop(group, fv.attr, expand=fv.kind == "flags")
                drawn += 1
            continue
        wanted = [p for p in fields.leaves(fv.group, f"{path}.") if keep(p)]
        if not wanted:
            continue
        if fv.attr not in models:
            box = layout.box()
            box.label(text=fv.attr.replace("_", " ").capitalize())
            box.use_property_split = True
            drawn += draw_group(box.column(), getattr(group, fv.attr), fv.group, keep, f"{path}.")
        elif group.model == fv.attr:
            drawn += draw_group(layout.column(), getattr(group, fv.attr), fv.group, keep, f"{path}.")
    return drawn


def draw_common(layout, group, view, section: str) -> int:
    paths = common_paths(section, view)
    return draw_group(layout, group, view, lambda p: _covered(p, paths))


def draw_advanced(layout, group, view, section: str) -> int:
    paths = common_paths(section, view)
    drawn = draw_group(layout, group, view, lambda p: not _covered(p, paths))
    if not drawn:
        layout.label(text="Nothing more to set")
    return drawn


def other_geometry(scene) -> list:
    """Renderable geometry outside the built scene and the clouds (the startup cube): export would scan it too."""
    from .bpy_pipeline.blender.export import GEOMETRY_TYPES
    from .bpy_pipeline.blender.mesh_objects import COLLECTION

    own = {o.name for name in (COLLECTION, cloud.COLLECTION) if (c := bpy.data.collections.get(name)) for o in c.all_objects}
    return [o for o in scene.objects if o.type in GEOMETRY_TYPES and not o.hide_render and o.name not in own]


def _split(layout):
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout


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
        row.scale_y = 1.3
        row.operator("lidar.build_scene", icon="SCENE_DATA")
        row.operator("lidar.scan", icon="OUTLINER_OB_LIGHTPROBE")
        layout.operator("lidar.show_cloud", icon="OUTLINER_OB_POINTCLOUD")
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
        layout = _split(self.layout)
        layout.prop(settings, "builder")
        if settings.builder == panel.MY_SCENE:
            layout.label(text=bpy.data.filepath or "Save the .blend: the config names it", icon="FILE_BLEND")
            return
        view = panel.VIEWS.builders[settings.builder]
        draw_common(layout.column(), getattr(settings, f"scene_{settings.builder}"), view, f"scene.{settings.builder}")
        base = panel.base_dict(settings)["scene"]
        hidden = sorted(k for k in base if k != "builder" and k not in {fv.key for fv in view.fields}) if base.get("builder") == settings.builder else []
        if hidden:
            layout.label(text=f"From the loaded config: {', '.join(hidden)}")
        layout.operator("lidar.build_scene", icon="SCENE_DATA")
        others = other_geometry(context.scene)
        if others:
            names = ", ".join(o.name for o in others[:3]) + (" ..." if len(others) > 3 else "")
            box = layout.box()
            box.label(text=f"Not part of the built scene: {names}", icon="ERROR")
            box.label(text="Scan asks whether to leave them out")


class LIDAR_PT_scene_advanced(LidarPanel, bpy.types.Panel):
    bl_label = "Advanced"
    bl_parent_id = "LIDAR_PT_scene"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return LidarPanel.poll(context) and context.scene.lidar.builder != panel.MY_SCENE

    def draw(self, context):
        settings = context.scene.lidar
        view = panel.VIEWS.builders[settings.builder]
        draw_advanced(_split(self.layout).column(), getattr(settings, f"scene_{settings.builder}"), view, f"scene.{settings.builder}")


class LIDAR_PT_sensor(LidarPanel, bpy.types.Panel):
    bl_label = "Sensor"
    bl_order = 2

    def draw(self, context):
        settings = context.scene.lidar
        layout = _split(self.layout)
        layout.prop(settings.sensor, "preset")
        draw_common(layout.column(), settings.sensor, panel.VIEWS.sensor, "sensor")
        layout.prop(settings, "pose_source", expand=True)
        if settings.pose_source == "OBJECT":
            layout.prop(settings, "pose_object")
        elif settings.pose_source == "TRAJECTORY":
            layout.prop(settings, "trajectory_curve")
            draw_group(layout.column(), settings.trajectory, panel.VIEWS.trajectory)
            layout.prop(settings.pose, "rotation_deg")
        else:
            draw_group(layout.column(), settings.pose, panel.VIEWS.pose)


class LIDAR_PT_sensor_advanced(LidarPanel, bpy.types.Panel):
    bl_label = "Advanced"
    bl_parent_id = "LIDAR_PT_sensor"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_advanced(_split(self.layout).column(), context.scene.lidar.sensor, panel.VIEWS.sensor, "sensor")


class LIDAR_PT_effects(LidarPanel, bpy.types.Panel):
    bl_label = "Effects"
    bl_order = 3

    def draw(self, context):
        draw_common(_split(self.layout).column(), context.scene.lidar.effects, panel.VIEWS.effects, "effects")


class LIDAR_PT_effects_advanced(LidarPanel, bpy.types.Panel):
    bl_label = "Advanced"
    bl_parent_id = "LIDAR_PT_effects"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_advanced(_split(self.layout).column(), context.scene.lidar.effects, panel.VIEWS.effects, "effects")


class LIDAR_PT_output(LidarPanel, bpy.types.Panel):
    bl_label = "Frames and output"
    bl_order = 4

    def draw(self, context):
        settings = context.scene.lidar
        layout = _split(self.layout)
        layout.prop(settings, "frames")
        layout.prop(settings, "seed")
        layout.prop(settings, "out_dir")
        if not settings.out_dir:
            layout.label(text="Empty: the extension's user folder, output/")
        draw_common(layout.column(), settings.output, panel.VIEWS.output, "output")


class LIDAR_PT_output_advanced(LidarPanel, bpy.types.Panel):
    bl_label = "Advanced"
    bl_parent_id = "LIDAR_PT_output"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_advanced(_split(self.layout).column(), context.scene.lidar.output, panel.VIEWS.output, "output")


class LIDAR_PT_legend(LidarPanel, bpy.types.Panel):
    """The classes of the shown cloud with the colours of the class table (assets_manifest/labels.yaml)."""

    bl_label = "Cloud legend"
    bl_parent_id = "LIDAR_PT_run"  # right under Show cloud

    @classmethod
    def poll(cls, context):
        return LidarPanel.poll(context) and len(context.scene.lidar.legend) > 0

    def draw(self, context):
        layout = self.layout
        for entry in context.scene.lidar.legend:
            row = layout.row(align=True)
            swatch = row.row()
            swatch.ui_units_x = 2
            swatch.prop(entry, "color", text="")  # the table's colour (Show cloud fills it again)
            row.label(text=f"{entry.class_id:>3}  {entry.name}")
            row.label(text=f"{entry.points} pts")


class LIDAR_PT_labels(LidarPanel, bpy.types.Panel):
    """Tags for the user's own objects (My scene, or objects added to a built scene)."""

    bl_label = "Labels"
    bl_order = 5

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


CLASSES = (
    LIDAR_PT_run,
    LIDAR_PT_legend,
    LIDAR_PT_scene,
    LIDAR_PT_scene_advanced,
    LIDAR_PT_sensor,
    LIDAR_PT_sensor_advanced,
    LIDAR_PT_effects,
    LIDAR_PT_effects_advanced,
    LIDAR_PT_output,
    LIDAR_PT_output_advanced,
    LIDAR_PT_labels,
)
