"""The panel's settings: one ``PropertyGroup`` on the scene (``scene.lidar``) that mirrors the config.

The groups are generated at registration from the config dataclasses (:mod:`.fields`), so
the builders of ``config.BUILDER_PARAMS``, the effects and the output options a panel shows are
the ones the installed pipeline has. :func:`settings_to_dict` turns the panel into plain
config data and :func:`settings_from_dict` shows config data in it; both go through
``config.config_from_dict`` / ``config.config_to_dict``, and keys the panel does not show
(primitive shapes, name rules, waypoints, ...) pass through from the last loaded config
(``settings.loaded``, JSON).

Panel-only choices and what they become in the config:

- builder "My scene": ``scene: {builder: blend, path: <this .blend>}``; scanned as it is, not reopened.
- sensor pose from an Empty or a Camera: ``sensor.position`` / ``rotation_deg`` of the object's
  world transform (the optical centre at the object's origin: the preset's mount height is taken
  off the position); an Empty's axes are the sensor's (x forward, z up), a Camera looks along its
  view direction with its up vector as the sensor's z.
- a trajectory curve: ``sensor.trajectory.curve: <object name>``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import bpy
from mathutils import Matrix, Vector

from . import fields
from .bpy_pipeline import config as cfg
from .bpy_pipeline.buffers import MATERIALS
from .bpy_pipeline.errors import InputError
from .bpy_pipeline.schema import to_plain
from .bpy_pipeline.labels import load_class_table
from .bpy_pipeline.lidar.sensor import sensors

MY_SCENE = "my_scene"
SENSOR_FIELDS = ("min_range", "max_range", "sampling_factor")  # shown; any other override passes through
POSE_KEYS = ("position", "rotation_deg", "trajectory")
# The sensor's axes (x forward, y left, z up) as columns in a camera's frame (it looks along -z, y up).
SENSOR_IN_CAMERA = Matrix(((0.0, -1.0, 0.0), (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0)))


@dataclass
class Views:
    """The generated groups of one registration."""

    builders: dict[str, fields.GroupView]
    sensor: fields.GroupView
    pose: fields.GroupView
    trajectory: fields.GroupView | None
    effects: fields.GroupView
    output: fields.GroupView
    defaults: dict
    settings: type | None = None
    classes: list[type] = field(default_factory=list)


VIEWS: Views | None = None


def has_trajectory() -> bool:
    """Whether the installed config knows ``sensor.trajectory``."""
    return "trajectory" in {f.name for f in dataclasses.fields(cfg.SensorConfig)}


def _is_pose_object(_settings, obj) -> bool:
    return obj.type in {"EMPTY", "CAMERA"}


def _is_curve(_settings, obj) -> bool:
    return obj.type == "CURVE"


def _preset_changed(sensor_group, context) -> None:
    """A new preset shows its own ranges and sampling, and its effects profile (noise, drop, intensity;
    ``ideal`` stays as set): overrides of the old one do not carry over."""
    values = sensors.spec_fields(sensors.resolve_sensor({"preset": sensor_group.preset}))
    fields.write(sensor_group, VIEWS.sensor, values, "sensor")
    if sensor_group.preset != "custom":
        effects = context.scene.lidar.effects
        profile = cfg.config_to_dict(cfg.config_from_dict({"sensor": {"preset": sensor_group.preset}}))["effects"]
        fields.write(effects, VIEWS.effects, profile | {"ideal": effects.ideal}, "effects")


def _enum_items(names) -> list[tuple[str, str, str]]:
    return [(n, n.replace("_", " ").capitalize(), "") for n in names]


class LIDAR_PG_legend_entry(bpy.types.PropertyGroup):
    """One class of the shown cloud: its colour in the class table (sRGB, as labels.yaml gives it) and point count."""

    class_id: bpy.props.IntProperty(name="Class id")
    points: bpy.props.IntProperty(name="Points")
    color: bpy.props.FloatVectorProperty(name="Colour", subtype="COLOR_GAMMA", size=3, min=0.0, max=1.0)


class LIDAR_PG_last_frame(bpy.types.PropertyGroup):
    """The last frame Scan or Generate made in this Blender session (``WindowManager.lidar_last``).

    A window manager's properties live as long as the session and are never written to a .blend
    file nor into an undo step: Show cloud finds the frame after Ctrl+Z, and a saved file carries no
    points. The ``(n,)`` point records are in ``points_file`` (``operators.remember_frame``), since no
    property holds megabytes of bytes: RNA strings and long bytes ID properties stop at the first NUL.
    """

    points_file: bpy.props.StringProperty(name="Points file", subtype="FILE_PATH", description="The frame's point records (.npy, in the temporary folder)")
    out_dir: bpy.props.StringProperty(name="Output folder", description="Where the frame was written")
    output_frame: bpy.props.StringProperty(name="Output frame", description="sensor, world or kitti: the frame the points are in")
    pose: bpy.props.FloatVectorProperty(name="Points' frame", size=16, description="4x4 points-frame-to-world matrix, row-major (metres)")


def make_views() -> Views:
    """Generate every ``PropertyGroup`` class from the installed config (call from ``register``)."""
    defaults = cfg.config_to_dict(cfg.config_from_dict({}))
    builders = {}
    for name, params in cfg.BUILDER_PARAMS.items():
        if name == "blend":
            continue  # "My scene" instead: the open file
        try:
            builder_defaults = to_plain(params())
        except TypeError:  # a builder without defaults for every field: nothing to show
            builder_defaults = {}
        builders[name] = fields.group_view(params, f"LIDAR_PG_scene_{name}", builder_defaults)
    presets = sensors.presets()
    preset_items = [(n, n, str(p.get("description", "")).strip()) for n, p in presets.items()]
    preset_items.append(("custom", "custom", "No preset: every field from the loaded config"))
    preset = bpy.props.EnumProperty(name="Preset", items=preset_items, default=defaults["sensor"]["preset"], update=_preset_changed)
    sensor = fields.group_view(sensors.SensorSpec, "LIDAR_PG_sensor", defaults["sensor"], only=SENSOR_FIELDS, extra={"preset": preset})
    pose = fields.group_view(cfg.SensorConfig, "LIDAR_PG_pose", defaults["sensor"], only=("position", "rotation_deg"))
    trajectory = None
    if has_trajectory():
        trajectory_cls = cfg.TrajectoryConfig
        trajectory = fields.group_view(trajectory_cls, "LIDAR_PG_trajectory", to_plain(trajectory_cls()), skip=("waypoints", "times", "curve"))
    effects = fields.group_view(cfg.EffectsConfig, "LIDAR_PG_effects", defaults["effects"])
    output = fields.group_view(cfg.OutputConfig, "LIDAR_PG_output", defaults["output"])
    views = Views(builders, sensor, pose, trajectory, effects, output, defaults)

    table = load_class_table()
    pose_items = [("FIXED", "Position", "The position and rotation below"), ("OBJECT", "Object", "An Empty or a Camera of the scene")]
    if trajectory is not None:
        pose_items.append(("TRAJECTORY", "Trajectory", "A curve the sensor moves along"))
    groups = [*builders.values(), sensor, pose, *([trajectory] if trajectory else []), effects, output]
    annotations = {
        "seed": bpy.props.IntProperty(name="Seed", min=0, default=defaults["seed"]),
        "frames": bpy.props.IntProperty(name="Frames", min=1, default=defaults["frames"]),
        "builder": bpy.props.EnumProperty(
            name="Builder",
            items=[*_enum_items(builders),
                   (MY_SCENE, "My scene", "The open scene as it is: not rebuilt; objects carry lidar_* tags or get a class from their names")],
            default=defaults["scene"]["builder"] if defaults["scene"]["builder"] in builders else MY_SCENE,
        ),
        **{f"scene_{name}": bpy.props.PointerProperty(type=view.property_group) for name, view in builders.items()},
        "sensor": bpy.props.PointerProperty(type=sensor.property_group),
        "pose_source": bpy.props.EnumProperty(name="Pose", items=pose_items, default="FIXED"),
        "pose": bpy.props.PointerProperty(type=pose.property_group),
        "pose_object": bpy.props.PointerProperty(name="Object", type=bpy.types.Object, poll=_is_pose_object),
        "effects": bpy.props.PointerProperty(type=effects.property_group),
        "output": bpy.props.PointerProperty(type=output.property_group),
        "out_dir": bpy.props.StringProperty(name="Folder", subtype="DIR_PATH", description="Output folder (empty: the extension's user folder)"),
        "label_class": bpy.props.EnumProperty(name="Class",
                                              items=[(n.replace(" ", "_"), n.capitalize(), f"class id {i}") for i, n in sorted(table.names.items())],
                                              default="ground"),
        "label_material": bpy.props.EnumProperty(name="Material", items=_enum_items(MATERIALS), default="diffuse"),
        "label_reflectivity": bpy.props.FloatProperty(name="Reflectivity", min=0.0, max=1.0, default=0.5),
        "loaded": bpy.props.StringProperty(options={"HIDDEN"}, description="The last loaded config (JSON)"),
        "status": bpy.props.StringProperty(name="Status", options={"SKIP_SAVE"}),
        "legend": bpy.props.CollectionProperty(type=LIDAR_PG_legend_entry, description="The classes of the shown cloud"),
    }
    if trajectory is not None:
        annotations["trajectory"] = bpy.props.PointerProperty(type=trajectory.property_group)
        annotations["trajectory_curve"] = bpy.props.PointerProperty(name="Curve", type=bpy.types.Object, poll=_is_curve)
    views.settings = type("LIDAR_PG_settings", (bpy.types.PropertyGroup,), {"__annotations__": annotations})
    views.classes = [c for group in groups for c in group.classes()] + [LIDAR_PG_legend_entry, views.settings]
    return views


# ----------------------------------------------------------------------------- panel <-> config data
def base_dict(settings) -> dict:
    """The last loaded config (resolved), or the default config."""
    return json.loads(settings.loaded) if settings.loaded else json.loads(json.dumps(VIEWS.defaults))


def object_pose(obj, spec: sensors.SensorSpec) -> dict:
    """``position`` / ``rotation_deg`` that put the sensor's optical centre and axes on ``obj`` (world)."""
    matrix = obj.matrix_world
    rotation = matrix.to_3x3().normalized()
    if obj.type == "CAMERA":
        rotation = rotation @ SENSOR_IN_CAMERA
    position = matrix.translation - Vector(sensors.mount_offset(spec))
    angles = rotation.to_euler("XYZ")
    return {
        "position": [fields.exact_float(v) for v in position],
        "rotation_deg": [fields.exact_float(math.degrees(a)) for a in angles],
    }


def _scene_dict(settings, base: dict) -> dict:
    if settings.builder == MY_SCENE:
        if not bpy.data.filepath:
            raise InputError("scene: 'My scene' is written to the config as this .blend file; save the file first")
        return {"builder": "blend", "path": bpy.data.filepath}
    section = base if base.get("builder") == settings.builder else {"builder": settings.builder}
    return fields.read(getattr(settings, f"scene_{settings.builder}"), VIEWS.builders[settings.builder], section)


def _overrides(name: str, resolved: dict, preset: dict) -> dict:
    """The fewest fields that turn preset ``name`` (its fields: ``preset``) into ``resolved``.

    Derived fields (``channels`` from a vertical resolution, ...) are left out, so changing
    what derives them in the panel cannot contradict a stale copy.
    """
    given = {k: v for k, v in resolved.items() if k in preset and k != "preset"}
    target = sensors.resolve_sensor({"preset": name, **given})

    def gives_target(section: dict) -> bool:
        try:
            return sensors.resolve_sensor({"preset": name, **section}) == target
        except InputError:
            return False

    overrides = {k: v for k, v in given.items() if v != preset[k]}
    for key in list(overrides):
        fewer = {k: v for k, v in overrides.items() if k != key}
        if gives_target(fewer):
            overrides = fewer
    return overrides if gives_target(overrides) else given


def _sensor_dict(settings, base: dict) -> dict:
    group = settings.sensor
    preset = sensors.spec_fields(sensors.resolve_sensor({"preset": group.preset}))
    reference = base if base.get("preset") == group.preset else preset
    overrides = _overrides(group.preset, reference, preset)
    shown = {fv.key: reference[fv.key] for fv in VIEWS.sensor.fields}
    section = fields.read(group, VIEWS.sensor, {"preset": group.preset, **overrides, **shown})
    section |= {k: v for k, v in base.items() if k not in preset and k not in POSE_KEYS}  # divergence, ...
    pose = fields.read(settings.pose, VIEWS.pose, {k: base[k] for k in ("position", "rotation_deg") if k in base})
    if settings.pose_source == "OBJECT":
        if settings.pose_object is None:
            raise InputError("sensor.position: pick the Empty or Camera that carries the sensor (Pose: Object)")
        pose = object_pose(settings.pose_object, sensors.resolve_sensor({k: v for k, v in section.items() if k in preset}))
    elif settings.pose_source == "TRAJECTORY":
        trajectory = fields.read(settings.trajectory, VIEWS.trajectory, base.get("trajectory") or {})
        if settings.trajectory_curve is not None:
            trajectory |= {"curve": settings.trajectory_curve.name, "waypoints": []}
        elif not trajectory.get("waypoints"):
            raise InputError("sensor.trajectory.curve: pick the curve the sensor moves along (Pose: Trajectory)")
        return section | {"rotation_deg": pose["rotation_deg"], "trajectory": trajectory}
    return section | pose


PROFILE_SECTIONS = ("noise", "drop", "intensity")  # what a preset's effects profile sets (lidar/sensor/sensors.yaml)


def _effects_dict(settings, base: dict) -> dict:
    """The panel's effects. The panel shows the preset's profile as fields; with Ideal ticked, a profile
    section the user left as the preset gives it is left out, so that ``ideal`` removes it as it does in a
    config file (``ideal: true`` keeps only what the config gives)."""
    effects = fields.read(settings.effects, VIEWS.effects, base)
    if not effects.get("ideal") or settings.sensor.preset == "custom":
        return effects
    profile = cfg.config_to_dict(cfg.config_from_dict({"sensor": {"preset": settings.sensor.preset}}))["effects"]
    return {k: v for k, v in effects.items() if k not in PROFILE_SECTIONS or v != profile.get(k)}


def settings_to_dict(settings) -> dict:
    """The panel as plain config data (what ``config_from_dict`` takes and Save config writes)."""
    base = base_dict(settings)
    data = dict(base)
    data["seed"], data["frames"] = settings.seed, settings.frames
    data["scene"] = _scene_dict(settings, base["scene"])
    data["sensor"] = _sensor_dict(settings, base["sensor"])
    data["effects"] = _effects_dict(settings, base["effects"])
    data["output"] = fields.read(settings.output, VIEWS.output, base["output"])
    return data


def settings_config(settings) -> cfg.Config:
    """The panel's config, validated: ``InputError`` naming the key when a value is not allowed."""
    return cfg.config_from_dict(settings_to_dict(settings))


def settings_from_dict(settings, data: dict) -> list[str]:
    """Validate plain config data and show it in the panel; returns notes for the user (may be empty)."""
    resolved = cfg.config_to_dict(cfg.config_from_dict(data))
    notes = []
    for key in ("seed", "frames"):
        try:
            setattr(settings, key, resolved[key])
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{key}: the panel holds values up to 2147483647, got {resolved[key]}") from None
    scene = resolved["scene"]
    if scene["builder"] == "blend":
        settings.builder = MY_SCENE
        if os.path.abspath(scene["path"]) != os.path.abspath(bpy.data.filepath or "."):
            notes.append(f"scene.path: the config scans {scene['path']}; the panel scans the open scene (open that file to scan it here)")
    else:
        settings.builder = scene["builder"]
        fields.write(getattr(settings, f"scene_{scene['builder']}"), VIEWS.builders[scene["builder"]], scene, "scene")
    sensor = resolved["sensor"]
    settings.sensor.preset = sensor["preset"]
    fields.write(settings.sensor, VIEWS.sensor, sensor, "sensor")
    fields.write(settings.pose, VIEWS.pose, sensor, "sensor")
    trajectory = sensor.get("trajectory")
    if trajectory and VIEWS.trajectory is not None:
        settings.pose_source = "TRAJECTORY"
        fields.write(settings.trajectory, VIEWS.trajectory, trajectory, "sensor.trajectory")
        settings.trajectory_curve = bpy.data.objects.get(trajectory.get("curve", "")) if trajectory.get("curve") else None
        if trajectory.get("curve") and settings.trajectory_curve is None:
            notes.append(f"sensor.trajectory.curve: no object {trajectory['curve']!r} in this file")
    else:
        settings.pose_source = "FIXED"
    fields.write(settings.effects, VIEWS.effects, resolved["effects"], "effects")
    fields.write(settings.output, VIEWS.output, resolved["output"], "output")
    settings.loaded = json.dumps(resolved)
    return notes


# ----------------------------------------------------------------------------- registration
def register() -> list[type]:
    """Generate and register the groups, attach ``Scene.lidar``; returns the registered classes."""
    global VIEWS
    VIEWS = make_views()
    return [*VIEWS.classes, LIDAR_PG_last_frame]


def attach() -> None:
    """``Scene.lidar`` (the panel's config, saved with the file) and ``WindowManager.lidar_last`` (this session's last frame)."""
    bpy.types.Scene.lidar = bpy.props.PointerProperty(type=VIEWS.settings)
    bpy.types.WindowManager.lidar_last = bpy.props.PointerProperty(type=LIDAR_PG_last_frame)


def detach() -> None:
    global VIEWS
    if hasattr(bpy.types.WindowManager, "lidar_last"):
        for wm in getattr(bpy.data, "window_managers", ()):  # the frame's file goes with the extension
            if wm.lidar_last.points_file:
                Path(wm.lidar_last.points_file).unlink(missing_ok=True)
            wm.property_unset("lidar_last")
        del bpy.types.WindowManager.lidar_last
    if hasattr(bpy.types.Scene, "lidar"):
        del bpy.types.Scene.lidar
    VIEWS = None
