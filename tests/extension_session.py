"""One Blender session with the extension installed from its zip (run by tests/test_extension.py).

``python tests/extension_session.py ZIP WORK`` with ``HOME`` and ``BLENDER_USER_RESOURCES``
pointing into ``WORK``: installs ZIP with ``bpy.ops.extensions.package_install_files``, runs
every operator of the panel on small scenes, cycles register / unregister, and writes what it
saw to ``WORK/report.json`` for the test to check. embreex and yaml may only be
imported from the wheels the extension installed (the venv's copies are hidden), so the
bundled wheels are what runs, against this Python's numpy.
"""

from __future__ import annotations

import importlib.machinery
import json
import os
import sys
from pathlib import Path

BUNDLED = {"embreex", "yaml", "_yaml"}
SITE = Path(os.environ["BLENDER_USER_RESOURCES"]) / "extensions" / ".local" / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"


class OnlyBundled:
    """Import finder: the bundled distributions come from the extension's wheels or not at all."""

    def find_spec(self, name, path=None, target=None):
        if path is None and name == "bpy_pipeline":  # inside Blender it is bl_ext.<repo>.lidar_pipeline.bpy_pipeline
            raise ImportError("bpy_pipeline: not importable by that name inside the extension; import it relatively")
        if path is None and name in BUNDLED:
            spec = importlib.machinery.PathFinder.find_spec(name, [str(SITE)])
            if spec is None:
                raise ImportError(f"{name}: not among the extension's installed wheels ({SITE})")
            return spec
        return None


sys.meta_path.insert(0, OnlyBundled())

import bpy  # noqa: E402  (puts Blender's scripts/modules on sys.path)
import addon_utils  # noqa: E402
import numpy as np  # noqa: E402

MODULE = "bl_ext.user_default.lidar_pipeline"
ZIP, WORK = Path(sys.argv[-2]), Path(sys.argv[-1])
report: dict = {"blender": bpy.app.version_string, "numpy": np.__version__}


def raise_error(ex):
    raise ex


def files_under(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts}


def lidar_classes() -> list[str]:
    return sorted(name for name in dir(bpy.types) if name.startswith("LIDAR_"))


def frame_files(out: Path) -> dict[str, str]:
    import hashlib

    return {
        str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.name != "manifest.json" and p.parent.name != "records"
    }  # records hold timings


class FakeLayout:
    """Records a panel's draw calls and checks every property and operator it names exists."""

    def __init__(self, log):
        self.log = log

    def prop(self, data, name, **_):
        if name not in data.bl_rna.properties:
            raise AttributeError(f"draw: {type(data).__name__} has no property {name!r}")
        self.log.append(f"prop {name}")

    def operator(self, idname, **_):
        module, name = idname.split(".")
        if not hasattr(getattr(bpy.ops, module), name) or getattr(getattr(bpy.ops, module), name).idname() not in dir(bpy.types):
            raise AttributeError(f"draw: no operator {idname}")
        self.log.append(f"operator {idname}")

    def label(self, text="", **_):
        self.log.append(f"label {text}")

    def separator(self, **_):
        pass

    def _sub(self, *_, **__):
        return FakeLayout(self.log)

    row = column = box = split = _sub


class FakePanel:
    def __init__(self, log):
        self.layout = FakeLayout(log)


def draw_all_panels() -> list[str]:
    log: list[str] = []
    for cls in (getattr(bpy.types, n) for n in lidar_classes() if "_PT_" in n):
        if cls.poll(bpy.context):
            cls.draw(FakePanel(log), bpy.context)
    return log


# ----------------------------------------------------------------------------- install and enable
for obj in list(bpy.data.objects):  # the startup file's cube, camera and light: run.py starts empty
    bpy.data.objects.remove(obj)
result = bpy.ops.extensions.package_install_files(filepath=str(ZIP), repo="user_default", enable_on_install=True)
report["install"] = sorted(result)
report["enabled"] = MODULE in bpy.context.preferences.addons
extension_dir = Path(next(r.directory for r in bpy.context.preferences.extensions.repos if r.module == "user_default")) / "lidar_pipeline"
report["extension_files"] = sorted(files_under(extension_dir))
before = files_under(extension_dir)
import embreex  # noqa: E402
import yaml  # noqa: E402

report["bundled"] = {m.__name__: str(Path(m.__file__).resolve().is_relative_to(SITE.resolve())) for m in (embreex, yaml)}
report["classes"] = lidar_classes()

package = sys.modules[MODULE]
panel, operators = package.settings, package.operators
cfg = sys.modules[f"{MODULE}.bpy_pipeline.config"]
read_dataset = sys.modules[f"{MODULE}.bpy_pipeline.io"].read_dataset
settings = bpy.context.scene.lidar
report["builders"] = sorted(settings.bl_rna.properties["builder"].enum_items.keys())
report["fresh_panel_is_default_config"] = cfg.config_from_dict(panel.settings_to_dict(settings)) == cfg.config_from_dict({})
settings.sensor.preset = "hdl32e"  # its own effects profile (range-proportional noise) replaces the default preset's
report["preset_brings_its_profile"] = (
    cfg.config_from_dict(panel.settings_to_dict(settings)).effects == cfg.config_from_dict({"sensor": {"preset": "hdl32e"}}).effects
)
settings.sensor.preset = cfg.config_to_dict(cfg.config_from_dict({}))["sensor"]["preset"]
report["preset_back_brings_default_effects"] = cfg.config_from_dict(panel.settings_to_dict(settings)).effects == cfg.config_from_dict({}).effects
settings.effects.ideal = True  # the panel's Ideal: the preset's noise and drop go, as ideal: true does in a config
report["panel_ideal_is_config_ideal"] = (
    cfg.config_from_dict(panel.settings_to_dict(settings)).effects == cfg.config_from_dict({"effects": {"ideal": True}}).effects
)
sigma = settings.effects.noise.sigma
settings.effects.noise.sigma = 0.05  # a value the user set stays
report["panel_ideal_keeps_what_the_user_set"] = cfg.config_from_dict(panel.settings_to_dict(settings)).effects.noise.sigma == 0.05
settings.effects.ideal, settings.effects.noise.sigma = False, sigma
report["panel_back_to_realistic"] = cfg.config_from_dict(panel.settings_to_dict(settings)).effects == cfg.config_from_dict({}).effects

# ----------------------------------------------------------------------------- load a config; generate as run.py does
job_yaml = WORK / "job.yaml"
job_yaml.write_text(
    """seed: 5
frames: 2
scene:
  builder: primitives
  shapes:
    - {type: plane, size: [30, 30], class: ground}
    - {type: box, size: [2, 2, 2], position: [6, 0, 1], class: wall}
    - {type: plane, size: [4, 3], position: [0, 6, 1.5], rotation_deg: [90, 0, 0], class: wall, material: mirror, reflectivity: 0.9}
    - {type: sphere, size: 0.8, position: [0, -5, 1], class: person}
sensor:
  preset: vlp16
  sampling_factor: 0.25
  position: [0, 0, 1.2]
  max_range: 40.0
effects:
  noise: {sigma: 0.01}
  mirrors: {max_bounces: 2}
output:
  formats: [ply, semantickitti]
"""
)
out_dir = WORK / "out_panel"
settings.out_dir = str(out_dir)
report["load"] = sorted(bpy.ops.lidar.config_load(filepath=str(job_yaml)))
report["loaded_equals_file"] = panel.settings_config(settings) == cfg.load_config(job_yaml)
report["generate"] = sorted(bpy.ops.lidar.generate())
report["generate_files"] = frame_files(out_dir)
report["generate_manifest_frames"] = len(read_dataset(out_dir)["frames"])
settings.out_dir = str(WORK / "out_invoke")  # invoked without a window (background): runs like execute
report["generate_invoke"] = sorted(bpy.ops.lidar.generate("INVOKE_DEFAULT"))
report["generate_invoke_files"] = frame_files(WORK / "out_invoke")
settings.out_dir = str(out_dir)
saved_yaml = WORK / "saved.yaml"
report["save"] = sorted(bpy.ops.lidar.config_save(filepath=str(saved_yaml)))
report["saved_equals_file"] = cfg.load_config(saved_yaml) == cfg.load_config(job_yaml)
resaved = WORK / "resaved.yaml"
bpy.ops.lidar.config_load(filepath=str(saved_yaml))
bpy.ops.lidar.config_save(filepath=str(resaved))
report["resave_is_byte_identical"] = resaved.read_bytes() == saved_yaml.read_bytes()

# ----------------------------------------------------------------------------- build, scan, show the cloud
scan_dir = WORK / "out_scan"
settings.out_dir = str(scan_dir)
report["build_scene"] = sorted(bpy.ops.lidar.build_scene())
report["scene_objects"] = sorted(o.name for o in bpy.data.collections["LiDAR Scene"].all_objects)
report["scan"] = sorted(bpy.ops.lidar.scan())
scan_manifest = read_dataset(scan_dir)
report["scan_points"] = scan_manifest["frames"][0]["points"]
report["scan_files"] = sorted(frame_files(scan_dir))
report["show_cloud"] = sorted(bpy.ops.lidar.show_cloud())
clouds = {}
for obj in bpy.data.collections["LiDAR Clouds"].objects:
    data = obj.data
    count = len(data.vertices) if obj.type == "MESH" else len(data.points)
    color = np.empty(count * 4, np.float32)
    data.attributes["Col"].data.foreach_get("color", color)
    bounces = np.empty(count, np.int32)
    data.attributes["bounces"].data.foreach_get("value", bounces)
    semantic = np.empty(count, np.int32)
    data.attributes["semantic"].data.foreach_get("value", semantic)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    clouds[obj.name] = {
        "type": obj.type,
        "points": count,
        "bounces": sorted(set(bounces.tolist())),
        "classes": sorted(set(semantic.tolist())),
        "colors": len(np.unique(color.reshape(-1, 4), axis=0)),
        "object_color": [round(c, 5) for c in obj.color],
        "material": obj.data.materials[0].name if len(obj.data.materials) else None,
        "matrix_is_pose": np.allclose(np.array(obj.matrix_world), scan_manifest["frames"][0]["sensor_pose"], atol=1e-5),
        "drawn_as_points": evaluated.data.__class__.__name__ == "PointCloud" or any(m.type == "NODES" for m in obj.modifiers),
    }
report["clouds"] = clouds
operators.forget_frame(bpy.context.window_manager.lidar_last)  # Show cloud from the files on disk
report["show_cloud_from_disk"] = sorted(bpy.ops.lidar.show_cloud())
report["cloud_points_from_disk"] = sum(len(o.data.vertices) if o.type == "MESH" else len(o.data.points) for o in bpy.data.collections["LiDAR Clouds"].objects)

# ----------------------------------------------------------------------------- a cancelled run keeps its finished frames
cancel_dir = WORK / "out_cancel"
settings.out_dir = str(cancel_dir)
job = operators.start_job(bpy.context, frames=4)
job.step(), job.step()
job.cancel()
report["cancel"] = {
    "manifest_frames": [f["index"] for f in read_dataset(cancel_dir)["frames"]],
    "ply": sorted(p.name for p in (cancel_dir / "ply").iterdir()),
    "leftovers": sorted(p.name for p in cancel_dir.iterdir() if p.name.startswith(".")),
    "step_after_cancel": job.step(),
}

# ----------------------------------------------------------------------------- labels for the user's own objects
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 3, 0.5))
crate = bpy.context.active_object
crate.name = "Crate"
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(3, 3, 0.5))
wall = bpy.context.active_object
wall.name = "Garden wall"
crate.select_set(True)
wall.select_set(False)
bpy.context.view_layer.objects.active = crate
settings.label_class, settings.label_material, settings.label_reflectivity = "car", "glass", 0.25
report["tag"] = sorted(bpy.ops.lidar.tag_selected())
report["crate_tags"] = {k: crate[k] for k in ("lidar_class", "lidar_material", "lidar_reflectivity")}
report["draw_with_tagged_active"] = [line for line in draw_all_panels() if line.startswith("label Crate")]
report["clear"] = sorted(bpy.ops.lidar.clear_tags())
report["crate_keys_after_clear"] = sorted(k for k in crate.keys() if k.startswith("lidar_"))
bpy.context.view_layer.objects.active = wall
report["draw_with_untagged_active"] = [line for line in draw_all_panels() if line.startswith("label Garden")]

# ----------------------------------------------------------------------------- sensor pose from an Empty and a Camera
from mathutils import Euler, Matrix  # noqa: E402

geometry = sys.modules[f"{MODULE}.bpy_pipeline.geometry.transforms"]
sensors = sys.modules[f"{MODULE}.bpy_pipeline.lidar.sensor.sensors"]
poses = {}
for kind in ("EMPTY", "CAMERA"):
    data = None if kind == "EMPTY" else bpy.data.cameras.new("cam")
    carrier = bpy.data.objects.new(f"carrier {kind}", data)
    bpy.context.scene.collection.objects.link(carrier)
    carrier.matrix_world = Matrix.Translation((3.0, -2.0, 4.5)) @ Euler((0.3, -0.2, 1.1), "XYZ").to_matrix().to_4x4()
    settings.pose_source, settings.pose_object = "OBJECT", carrier
    config = panel.settings_config(settings)
    pose = geometry.pose_matrix(np.add(config.sensor.position, sensors.mount_offset(config.sensor.spec)), config.sensor.rotation_deg)
    carrier_matrix = np.array(carrier.matrix_world)
    forward = carrier_matrix[:3, 0] if kind == "EMPTY" else -carrier_matrix[:3, 2]
    up = carrier_matrix[:3, 2] if kind == "EMPTY" else carrier_matrix[:3, 1]
    poses[kind] = {
        "origin_error": float(np.abs(pose[:3, 3] - carrier_matrix[:3, 3]).max()),
        "forward_error": float(np.abs(pose[:3, 0] - forward).max()),
        "up_error": float(np.abs(pose[:3, 2] - up).max()),
    }
report["object_poses"] = poses
settings.pose_source = "FIXED"
report["trajectory_offered"] = "TRAJECTORY" in settings.bl_rna.properties["pose_source"].enum_items.keys()
if report["trajectory_offered"]:
    curve = bpy.data.curves.new("track path", "CURVE")
    spline = curve.splines.new("POLY")
    spline.points.add(2)
    spline.points.foreach_set("co", [0, -10, 0, 1, 0, 0, 0, 1, 0, 10, 0, 1])
    path = bpy.data.objects.new("track path", curve)
    bpy.context.scene.collection.objects.link(path)
    settings.pose_source, settings.trajectory_curve, settings.trajectory.speed = "TRAJECTORY", path, 5.0
    data = panel.settings_to_dict(settings)
    trajectory = cfg.config_from_dict(data).sensor.trajectory
    report["trajectory"] = {"curve": trajectory.curve, "speed": trajectory.speed, "position_given": "position" in data["sensor"]}
    report["trajectory_drawn"] = "prop trajectory_curve" in draw_all_panels()
    settings.pose_source, settings.trajectory_curve = "FIXED", None
    panel.settings_from_dict(settings, data)
    report["trajectory_loaded"] = [settings.pose_source, settings.trajectory_curve.name if settings.trajectory_curve else None]
    bpy.data.objects.remove(path)
    settings.pose_source = "FIXED"
settings.out_dir = ""
report["default_output"] = str(operators.output_dir(settings))
report["default_output_in_user_folder"] = Path(report["default_output"]).is_relative_to(os.environ["BLENDER_USER_RESOURCES"]) and not Path(
    report["default_output"]
).is_relative_to(extension_dir)

# ----------------------------------------------------------------------------- a bad value: one line naming the key
settings.sensor.max_range = 0.1  # below the preset's min_range
try:
    report["bad_scan"] = sorted(bpy.ops.lidar.scan())
except RuntimeError as err:  # reports of level ERROR raise in background mode
    report["bad_scan"] = str(err).strip().splitlines()[-1]
settings.sensor.max_range = 40.0

# ----------------------------------------------------------------------------- My scene: the open .blend, scanned as it is
blend = WORK / "mine.blend"
bpy.ops.wm.save_as_mainfile(filepath=str(blend))
settings = bpy.context.scene.lidar
settings.builder = "my_scene"
mine_dir = WORK / "out_mine"
settings.out_dir = str(mine_dir)
kept = sorted(o.name for o in bpy.data.collections["LiDAR Scene"].all_objects)
report["mine_scan"] = sorted(bpy.ops.lidar.scan())
report["mine_scene_untouched"] = kept == sorted(o.name for o in bpy.data.collections["LiDAR Scene"].all_objects)
mine_objects = {row["name"]: row["class"] for row in read_dataset(mine_dir)["frames"][0]["objects"]}
report["mine_objects"] = mine_objects
mine_yaml = WORK / "mine.yaml"
bpy.ops.lidar.config_save(filepath=str(mine_yaml))
report["mine_yaml_scene"] = cfg.read_config_file(mine_yaml)["scene"]
report["panels_drawn"] = len(draw_all_panels())

# ----------------------------------------------------------------------------- register / unregister cycles
report["extension_dir_unchanged"] = files_under(extension_dir) == before
counts = []
for _ in range(3):
    addon_utils.disable(MODULE, default_set=True, handle_error=raise_error)
    counts.append((len(lidar_classes()), hasattr(bpy.types.Scene, "lidar")))
    addon_utils.enable(MODULE, default_set=True, handle_error=raise_error)
    counts.append((len(lidar_classes()), hasattr(bpy.types.Scene, "lidar")))
report["cycles"] = counts
report["after_cycles_build"] = sorted(bpy.ops.lidar.build_scene()) if bpy.context.scene.lidar.builder != "my_scene" else "my_scene"
report["after_cycles_scan"] = sorted(bpy.ops.lidar.scan())

# A failing registration propagates its error and leaves nothing registered; enabling again works.
addon_utils.disable(MODULE, default_set=True, handle_error=raise_error)
settings_module = sys.modules[f"{MODULE}.settings"]
original = settings_module.make_views


def broken():
    views = original()
    views.classes.append(views.classes[0])  # registering a class twice fails half-way through
    return views


settings_module.make_views = broken
try:
    addon_utils.enable(MODULE, default_set=True, handle_error=raise_error)
    report["registration_error"] = None
except Exception as err:  # the error itself is what is checked
    report["registration_error"] = type(err).__name__
report["after_failed_registration"] = (lidar_classes(), hasattr(bpy.types.Scene, "lidar"))
settings_module.make_views = original
addon_utils.enable(MODULE, default_set=True, handle_error=raise_error)
report["after_retry"] = (len(lidar_classes()), hasattr(bpy.types.Scene, "lidar"))

settings = bpy.context.scene.lidar
report["reset"] = sorted(bpy.ops.lidar.config_reset())
report["reset_is_default"] = panel.settings_config(settings) == cfg.config_from_dict({}) and settings.builder == "railway"
builders = {}
for builder in settings.bl_rna.properties["builder"].enum_items.keys():
    if builder != "my_scene":
        settings.builder = builder
        drawn = [line for line in draw_all_panels() if line.startswith("prop ")]
        try:
            built = sorted(bpy.ops.lidar.build_scene()) == ["FINISHED"] and len(bpy.data.collections["LiDAR Scene"].all_objects) >= 3
        except RuntimeError as err:  # a builder that needs the user's input (real_scan: a scan file) says which key
            built = str(err).strip().splitlines()[-1]
        if isinstance(built, str):
            builders[builder] = [True, len(drawn), built]  # its defaults are not a valid config on their own
            continue
        builders[builder] = [panel.settings_config(settings).scene == cfg.config_from_dict({"scene": {"builder": builder}}).scene, len(drawn), built]
report["every_builder"] = builders
kept = Path(bpy.utils.extension_path_user(MODULE, path="node_groups"))  # the built groups, kept in the extension's own folder
report["kept_groups"] = sorted(path.name.split(".v")[0] for path in kept.rglob("*.blend")) if kept.is_dir() else []

# ----------------------------------------------------------------------------- the street's road users in the viewport as frames go
street_yaml = WORK / "street.yaml"
street_yaml.write_text("seed: 0\nframes: 3\nscene: {builder: street}\nsensor: {preset: hdl64e, sampling_factor: 0.25, position: [0.0, -1.75, 1.73]}\n"
                       "output: {formats: [semantickitti]}\n")
settings = bpy.context.scene.lidar
bpy.ops.lidar.config_load(filepath=str(street_yaml))
settings.out_dir = str(WORK / "out_street")
job = operators.start_job(bpy.context)
shown = []
while job.step():  # each step leaves Blender holding road users (a run that reads only arrays would wait for its end)
    shown.append(sum(len(o.data.vertices) for o in bpy.data.collections["LiDAR Street Users"].objects))
report["street_users_shown_per_step"] = shown

(WORK / "report.json").write_text(json.dumps(report, indent=1, default=str))
print("session done")
