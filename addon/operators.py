"""The panel's buttons. Each reads the config the panel shows and calls the pipeline.

A value the config does not allow is reported as one line naming its key (``InputError``) and
the operator is cancelled; any other error propagates (Blender shows its traceback).
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from pathlib import Path

import bpy
import numpy as np
from bpy_extras.io_utils import ExportHelper, ImportHelper

from . import cloud
from . import settings as panel
from .bpy_pipeline import config as cfg
from .bpy_pipeline.errors import InputError
from .bpy_pipeline.labels import load_class_table, normalise

LIDAR_KEYS = ("lidar_class", "lidar_material", "lidar_reflectivity", "lidar_instance")


def remember_frame(last, points: np.ndarray, pose: np.ndarray, output_frame: str, out_dir: Path) -> None:
    """Keep a frame on ``last`` (``WindowManager.lidar_last``): ``points`` the ``(n,)`` records, ``pose`` 4x4 (metres): the
    points' frame in the world (:func:`~bpy_pipeline.geometry.transforms.output_pose`).

    The records go to ``last.points_file``, a ``.npy`` file in the system's temporary folder made for
    this session on its first frame and replaced whole (write, then rename) by every later one.
    """
    if not last.points_file or not Path(last.points_file).parent.is_dir():
        handle, name = tempfile.mkstemp(prefix="lidar_pipeline-last-", suffix=".npy")
        os.close(handle)
        last.points_file = name
    partial = Path(last.points_file).with_suffix(".partial")
    with open(partial, "wb") as file:
        np.save(file, points, allow_pickle=False)
    os.replace(partial, last.points_file)
    last.pose = np.asarray(pose, np.float64).ravel().tolist()
    last.output_frame, last.out_dir = output_frame, str(out_dir)


def recall_frame(last) -> tuple[np.ndarray, np.ndarray] | None:
    """The frame kept on ``last``: ``(points, pose)``, the pose the points' frame in the world; ``None`` when none is."""
    if not last.points_file or not Path(last.points_file).is_file():
        return None
    return np.load(last.points_file, allow_pickle=False), np.asarray(last.pose, np.float64).reshape(4, 4)


def forget_frame(last) -> None:
    """Drop the frame kept on ``last`` and its file (Show cloud then reads the output folder)."""
    if last.points_file:
        Path(last.points_file).unlink(missing_ok=True)
    last.points_file = ""


def output_dir(settings) -> Path:
    """The chosen output folder, or ``output`` in the extension's user folder when none is chosen."""
    if not settings.out_dir:
        return Path(bpy.utils.extension_path_user(__package__, path="output", create=True))
    if settings.out_dir.startswith("//") and not bpy.data.filepath:
        raise InputError(f"output folder: {settings.out_dir} is relative to the .blend file; save the file or choose an absolute folder")
    return Path(bpy.path.abspath(settings.out_dir))


class FrameJob:
    """The frames of a config, generated one :meth:`step` at a time; :meth:`cancel` keeps those done."""

    def __init__(self, config: cfg.Config, out_dir: Path, build: bool, last=None):
        """``last``: where each finished frame is remembered (``WindowManager.lidar_last``), or ``None``."""
        from .bpy_pipeline.plan import run_frames

        self.total, self.done, self.out_dir = config.frames, 0, out_dir
        self.output_frame, self.kitti_origin = config.output.frame, config.output.kitti.camera.position
        self.points = 0
        self.last = last
        # the panel's output folder holds its latest scan or frames: each Scan and Generate replaces it
        self._frames = run_frames(config, out_dir, build, mode="overwrite")

    def step(self) -> bool:
        """Generate, write and remember the next frame; ``False`` when every frame is done."""
        try:
            frame = next(self._frames)
        except StopIteration:
            return False
        self.done += 1
        self.points = len(frame.points)
        if frame.scene.show is not None:  # the viewport shows the road users as the frames go
            frame.scene.show()
        if self.last is not None:
            from .bpy_pipeline.geometry.transforms import output_pose

            remember_frame(self.last, frame.points, output_pose(self.output_frame, frame.pose, self.kitti_origin), self.output_frame, self.out_dir)
        return True

    def cancel(self) -> None:
        self._frames.close()

    def message(self) -> str:
        return f"{self.done}/{self.total} frames ({self.points} points in the last) in {self.out_dir}"


def scene_built() -> bool:
    from .bpy_pipeline.blender.mesh_objects import COLLECTION

    collection = bpy.data.collections.get(COLLECTION)
    return collection is not None and len(collection.all_objects) > 0


OTHERS_ITEMS = [
    ("LEAVE_OUT", "Leave them out", "Scan only the built scene (as run.py does): the other objects are hidden from the scan while it runs"),
    ("SCAN", "Scan them too", "The other objects are part of the scan, labelled by their tags or names"),
]


def others_to_leave_out(context, choice: str) -> list:
    """The objects outside the built scene that ``choice`` leaves out (none for My scene)."""
    from .panels import other_geometry

    if choice != "LEAVE_OUT" or context.scene.lidar.builder == panel.MY_SCENE:
        return []
    return other_geometry(context.scene)


def hide(objects: list, hidden: bool) -> None:
    """Hide ``objects`` from the scan (``hide_render``: what export skips) or show them again."""
    for obj in objects:
        obj.hide_render = hidden


def start_job(context, frames: int | None = None, build: bool | None = None) -> FrameJob:
    """A job for the panel's config (``frames`` overrides its frame count); ``build`` defaults to every builder but My scene."""
    settings = context.scene.lidar
    config = panel.settings_config(settings)
    if frames is not None:
        config = dataclasses.replace(config, frames=frames)
    if build is None:
        build = settings.builder != panel.MY_SCENE
    return FrameJob(config, output_dir(settings), build, context.window_manager.lidar_last)


class LIDAR_OT_build_scene(bpy.types.Operator):
    """Build the chosen scene into the "LiDAR Scene" collection (replacing what it holds)"""

    bl_idname = "lidar.build_scene"
    bl_label = "Build scene"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .bpy_pipeline.stages.scene import build_frame_scene

        settings = context.scene.lidar
        if settings.builder == panel.MY_SCENE:
            self.report({"INFO"}, "My scene is scanned as it is: nothing to build")
            return {"CANCELLED"}
        try:
            config = panel.settings_config(settings)
            build_frame_scene(config, 0)
        except InputError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        settings.status = f"built {config.scene.builder}"
        return {"FINISHED"}


class LIDAR_OT_scan(bpy.types.Operator):
    """Scan the scene as it is (building the chosen scene first if nothing is built) and write frame 0"""

    bl_idname = "lidar.scan"
    bl_label = "Scan"
    bl_options = {"REGISTER", "UNDO"}  # Ctrl+Z takes back the scene it built, not the files it wrote (docs/panel.md)

    others: bpy.props.EnumProperty(name="Other objects", items=OTHERS_ITEMS, default="LEAVE_OUT")

    def invoke(self, context, event):
        if context.window is not None and others_to_leave_out(context, "LEAVE_OUT"):
            return context.window_manager.invoke_props_dialog(self, width=420)
        return self.execute(context)

    def draw(self, context):  # the dialog Scan opens when the scene holds objects outside the built scene
        others = others_to_leave_out(context, "LEAVE_OUT")
        layout = self.layout
        layout.label(text=f"{len(others)} object(s) are not part of the built scene:", icon="ERROR")
        layout.label(text=", ".join(o.name for o in others[:6]) + (" ..." if len(others) > 6 else ""))
        layout.prop(self, "others", expand=True)

    def execute(self, context):
        settings = context.scene.lidar
        left_out = others_to_leave_out(context, self.others)
        hide(left_out, True)
        try:
            build = settings.builder != panel.MY_SCENE and not scene_built()
            job = start_job(context, frames=1, build=build)
            job.step()
        except InputError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        finally:
            hide(left_out, False)
        settings.status = f"scan: {job.points} points in {job.out_dir}"
        self.report({"INFO"} if job.points else {"WARNING"}, settings.status if job.points else "scan: no points (nothing in range?)")
        return {"FINISHED"}


class LIDAR_OT_generate(bpy.types.Operator):
    """Generate the configured number of frames, rebuilding the scene for each (Esc cancels; finished frames stay)"""

    bl_idname = "lidar.generate"
    bl_label = "Generate frames"
    bl_options = {"REGISTER", "UNDO"}  # one undo step when every frame is done (docs/panel.md)

    # for scripts only: hidden, so the Adjust Last Operation panel offers nothing that would re-run every frame
    others: bpy.props.EnumProperty(name="Other objects", items=OTHERS_ITEMS, default="LEAVE_OUT", options={"HIDDEN", "SKIP_SAVE"})

    def execute(self, context):  # scripts and background mode: every frame, blocking
        left_out = others_to_leave_out(context, self.others)
        hide(left_out, True)
        try:
            job = start_job(context)
            while job.step():
                pass
        except InputError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        finally:
            hide(left_out, False)
        context.scene.lidar.status = job.message()
        self.report({"INFO"}, job.message())
        return {"FINISHED"}

    def invoke(self, context, event):
        if context.window is None:
            return self.execute(context)
        self._left_out = others_to_leave_out(context, self.others)
        hide(self._left_out, True)
        try:
            self._job = start_job(context)
        except InputError as err:
            hide(self._left_out, False)
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, self._job.total)
        self._show(context, f"LiDAR: frame 1/{self._job.total} (Esc to cancel)")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC":
            job.cancel()
            self._end(context)
            self.report({"WARNING"}, f"cancelled: kept {job.message()}")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            more = job.step()
        except InputError as err:
            self._end(context)
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        except BaseException:
            self._end(context)
            raise
        if not more:
            self._end(context)
            self.report({"INFO"}, job.message())
            return {"FINISHED"}
        context.window_manager.progress_update(job.done)
        self._show(context, f"LiDAR: {job.done}/{job.total} frames done (Esc to cancel)")
        return {"RUNNING_MODAL"}

    def _show(self, context, text: str) -> None:
        context.workspace.status_text_set(text)
        context.scene.lidar.status = text
        for area in context.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()

    def _end(self, context) -> None:
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        context.scene.lidar.status = self._job.message()
        hide(self._left_out, False)


class LIDAR_OT_show_cloud(bpy.types.Operator):
    """Show the last scanned frame as point-cloud objects coloured by class (ghost points apart)"""

    bl_idname = "lidar.show_cloud"
    bl_label = "Show cloud"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        try:
            points, pose = self._last_frame(context)
        except InputError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        table = load_class_table()
        objects = cloud.show_frame(points, pose, table.color_lut(), table.names)
        fill_legend(context.scene.lidar, points, table)
        space = context.space_data
        if space is not None and space.type == "VIEW_3D" and space.shading.type == "SOLID":
            space.shading.color_type = "OBJECT"  # one object per class, coloured by the class table
        ghosts = int((points["bounces"] > 0).sum())
        self.report({"INFO"}, f"{len(points)} points ({ghosts} ghost) in {len(objects)} objects, one per class (legend: LiDAR tab)")
        return {"FINISHED"}

    @staticmethod
    def _last_frame(context) -> tuple[np.ndarray, np.ndarray]:
        """This session's last frame, else the last frame of the output folder's PLY files."""
        kept = recall_frame(context.window_manager.lidar_last)
        if kept is not None:
            return kept
        from .bpy_pipeline.io import read_dataset, read_ply

        out = output_dir(context.scene.lidar)
        manifest = read_dataset(out) if (out / "manifest.json").is_file() else {"frames": []}
        if not manifest["frames"]:
            raise InputError(f"show cloud: nothing scanned yet (no frame in {out}); press Scan first")
        frame = manifest["frames"][-1]
        ply = next((f for f in frame["files"] if f.endswith(".ply")), None)
        if ply is None:
            raise InputError(f"show cloud: the last frame in {out} has no PLY file; press Scan or add ply to the formats")
        from .bpy_pipeline.geometry.transforms import output_pose

        output = manifest["config"]["output"]
        camera = ((output.get("kitti") or {}).get("camera") or {}).get("position", (0.0, 0.0, 0.0))
        return read_ply(out / ply), output_pose(output["frame"], np.asarray(frame["sensor_pose"], np.float64), camera)  # the points' frame in the world


def fill_legend(settings, points: np.ndarray, table) -> None:
    """The legend of the shown cloud: each class present, its table colour (sRGB) and point count."""
    settings.legend.clear()
    ids, counts = np.unique(points["semantic"], return_counts=True)
    lut = table.color_lut()
    for class_id, count in zip(ids.tolist(), counts.tolist()):
        entry = settings.legend.add()
        entry.name = table.names.get(class_id, f"class {class_id}")
        entry.class_id, entry.points = class_id, count
        entry.color = tuple(float(c) / 255.0 for c in lut[class_id])


class LIDAR_OT_config_load(bpy.types.Operator, ImportHelper):
    """Show a YAML config (as run.py reads it) in the panel"""

    bl_idname = "lidar.config_load"
    bl_label = "Load config"
    filename_ext = ".yaml"
    filter_glob: bpy.props.StringProperty(default="*.yaml;*.yml", options={"HIDDEN"})

    def execute(self, context):
        try:
            notes = panel.settings_from_dict(context.scene.lidar, cfg.read_config_file(self.filepath))
        except InputError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        for note in notes:
            self.report({"WARNING"}, note)
        context.scene.lidar.status = f"loaded {self.filepath}"
        return {"FINISHED"}


class LIDAR_OT_config_save(bpy.types.Operator, ExportHelper):
    """Save the panel as a resolved YAML config: python run.py --config FILE runs the same job"""

    bl_idname = "lidar.config_save"
    bl_label = "Save config"
    filename_ext = ".yaml"
    filter_glob: bpy.props.StringProperty(default="*.yaml;*.yml", options={"HIDDEN"})

    def execute(self, context):
        settings = context.scene.lidar
        try:
            cfg.save_config(panel.settings_config(settings), self.filepath)
        except InputError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        if settings.builder == panel.MY_SCENE and bpy.data.is_dirty:
            self.report({"WARNING"}, f"{bpy.data.filepath} has unsaved changes; run.py scans the file as saved")
        settings.status = f"saved {self.filepath}"
        return {"FINISHED"}


class LIDAR_OT_config_reset(bpy.types.Operator):
    """Show the default config in the panel (forgets the loaded config)"""

    bl_idname = "lidar.config_reset"
    bl_label = "Reset config"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        settings = context.scene.lidar
        settings.loaded = ""
        panel.settings_from_dict(settings, {})
        settings.status = "default config"
        return {"FINISHED"}


class LIDAR_OT_tag_selected(bpy.types.Operator):
    """Set lidar_class, lidar_material and lidar_reflectivity on the selected objects"""

    bl_idname = "lidar.tag_selected"
    bl_label = "Tag selected"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return bool(context.selected_objects)

    def execute(self, context):
        from .bpy_pipeline.blender.mesh_objects import tag

        settings = context.scene.lidar
        for obj in context.selected_objects:
            tag(obj, normalise(settings.label_class), settings.label_material, settings.label_reflectivity)
        self.report({"INFO"}, f"tagged {len(context.selected_objects)} object(s) {normalise(settings.label_class)!r}")
        return {"FINISHED"}


class LIDAR_OT_clear_tags(bpy.types.Operator):
    """Remove the lidar_* properties of the selected objects: their names' rules label them again"""

    bl_idname = "lidar.clear_tags"
    bl_label = "Clear tags"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return bool(context.selected_objects)

    def execute(self, context):
        for obj in context.selected_objects:
            for key in LIDAR_KEYS:
                if key in obj:
                    del obj[key]
        return {"FINISHED"}


CLASSES = (
    LIDAR_OT_build_scene,
    LIDAR_OT_scan,
    LIDAR_OT_generate,
    LIDAR_OT_show_cloud,
    LIDAR_OT_config_load,
    LIDAR_OT_config_save,
    LIDAR_OT_config_reset,
    LIDAR_OT_tag_selected,
    LIDAR_OT_clear_tags,
)
