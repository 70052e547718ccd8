"""The frame and the run: the values a frame plan's stages pass along (:mod:`bpy_pipeline.plan`).

A stage is ``stage(frame, run) -> None``: it fills in its part of the :class:`Frame` (pose, scene
buffers, points, boxes, ...) and may use what the :class:`Run` keeps across frames (the current
built scene, the sensor's rays, the static caster). A frame holds everything its writers and its
record need, so a stage is testable alone and a frame range needs no hidden state.
"""

from __future__ import annotations

import platform
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Iterable, Protocol

import numpy as np

from . import _version
from .builders.base import BuildResult
from .labels import ClassTable, load_class_table, parse_rules
from .geometry.clearance import SensorPoses
from .lidar.sensor.platform import Trajectory
from .lidar.cast.raycast import CasterCache
from .lidar.sensor.sensor_rays import SensorRays

if TYPE_CHECKING:
    from .buffers import SceneBuffers
    from .config import Config
    from .lidar.cast.raycast import RayCaster
    from .rig import RigFrame


def frame_rng(seed: int, frame: int) -> np.random.Generator:
    """The generator of frame ``frame`` of a run seeded with ``seed``."""
    return np.random.default_rng(np.random.SeedSequence([seed, frame]))


def versions() -> dict:
    """Versions of everything that shapes the output."""
    import embreex

    out = {"bpy_pipeline": _version.__version__, "python": platform.python_version(), "numpy": np.__version__}
    out["embreex"] = getattr(embreex, "__version__", "unknown")
    out["blender"] = blender_version()
    return out


def blender_version() -> str | None:
    """The Blender frames are made with, ``"major.minor.patch"``: the loaded bpy's, else the installed bpy module's
    (read from its package, without starting a Blender: a ``--workers`` run's own process makes no frame), else None."""
    bpy = sys.modules.get("bpy")
    if bpy is not None:
        return ".".join(map(str, bpy.app.version))
    from importlib import metadata

    try:
        return metadata.version("bpy")
    except metadata.PackageNotFoundError:
        return None


@dataclass(frozen=True)
class StaticPose:
    """``pose_at`` of a sensor that does not move during the frame: ``pose_at(t (n,) s) -> (n, 4, 4)``, every row ``pose``."""

    pose: np.ndarray

    def __call__(self, t) -> np.ndarray:
        return np.broadcast_to(self.pose, (len(np.atleast_1d(t)), 4, 4)).copy()


def _identity() -> np.ndarray:
    return np.eye(4)


@dataclass
class Frame:
    """One frame of a run.

    index : frame index in the run (0-based)
    config : the run's :class:`~bpy_pipeline.config.Config` (a rig member's frame: that sensor's)
    rng : the frame's generator (:func:`frame_rng`); every random draw of the frame
    scene : the :class:`~bpy_pipeline.builders.base.BuildResult` of the scene the frame scans (built for
        this frame or for an earlier one it shares with; empty for the user's scene as it is)
    built : True when this frame built ``scene`` (its warnings are this frame's)
    pose : (4, 4) float64 sensor-to-world transform at the frame's start (mount height included)
    pose_at : ``pose_at(t (n,) s) -> (n, 4, 4)`` sensor-to-world poses at firing times (a static sensor's: ``pose``)
    trajectory : the moving sensor's :class:`~bpy_pipeline.lidar.sensor.platform.Trajectory`, ``None`` when static
    buffers : the exported :class:`~bpy_pipeline.buffers.SceneBuffers` (a real scan's: its inserted objects)
    caster : the scan's :class:`~bpy_pipeline.lidar.cast.raycast.RayCaster` of ``buffers`` at ``pose`` (the boxes reuse it)
    chunks : the scan's ``(points, beam)`` chunks, consumed by the effects stage
    direct_returns : (n,) int64 per ray of the scan, the instance of its return that met no mirror (before the effects),
        -1 for none, when the boxes take their counts from them (:func:`~bpy_pipeline.stages.scan.counts_direct_returns`); else ``None``
    points : (p,) POINT_DTYPE records in the output frame (sensor, world or kitti; a rig's: RIG_POINT_DTYPE)
    boxes : (b,) BOX_DTYPE box labels in the output frame, ``None`` when no box format is asked for
    thin_boxes : (t,) BOX_DTYPE boxes of the box classes with some points but fewer than their minimum (KITTI's DontCare
        regions), ``None`` where the frame's boxes do not say (a rig's, a real scan's)
    images : {name: (h, w, 3) uint8} camera renderings (KITTI's ``image_2``)
    flash : {file suffix: (returns, rows, columns) FLASH_IMAGE_DTYPE} flash cameras' images (``flash_image``)
    rig : a sensor rig's per-sensor frames (:class:`~bpy_pipeline.rig.RigFrame`), ``None`` for one sensor
    mixed : a real-scan frame's working state (:class:`~bpy_pipeline.mixing.frame.MixState`), ``None`` otherwise
    files, record : the frame's files (relative to the output folder) and record, once committed
    timings : seconds per timed stage
    shared : what the frame's writers make once and share while it is committed ({"xyzi": the x y z intensity block
        several files hold, :func:`bpy_pipeline.io.formats._xyzi`})
    """

    index: int
    config: Config
    rng: np.random.Generator
    scene: BuildResult = field(default_factory=BuildResult)
    built: bool = False
    pose: np.ndarray = field(default_factory=_identity)
    pose_at: Callable[[np.ndarray], np.ndarray] | None = None
    trajectory: Trajectory | None = None
    buffers: SceneBuffers | None = None
    caster: RayCaster | None = None
    chunks: Iterable | None = None
    direct_returns: np.ndarray | None = None
    points: np.ndarray | None = None
    boxes: np.ndarray | None = None
    thin_boxes: np.ndarray | None = None
    files: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    record: dict = field(default_factory=dict)
    images: dict[str, np.ndarray] = field(default_factory=dict)
    flash: dict[str, np.ndarray] = field(default_factory=dict)
    rig: RigFrame | None = None
    mixed: object = None
    shared: dict = field(default_factory=dict)

    def __post_init__(self):
        self.pose = np.asarray(self.pose, np.float64)
        if self.pose.shape != (4, 4):
            raise ValueError(f"Frame.pose: expected a (4, 4) transform, got shape {self.pose.shape}")
        if self.pose_at is None:
            self.pose_at = StaticPose(self.pose)

    def place(self, pose: np.ndarray, pose_at: Callable[[np.ndarray], np.ndarray] | None = None, trajectory: Trajectory | None = None) -> None:
        """Set the sensor's pose at the frame's start (4, 4), and ``pose_at`` (a moving sensor's; a static one's otherwise)."""
        self.pose = np.asarray(pose, np.float64).reshape(4, 4)
        self.pose_at = StaticPose(self.pose) if pose_at is None else pose_at
        self.trajectory = trajectory

    @property
    def moving(self) -> bool:
        """True when the sensor moves during the frame (each ray cast from its own pose)."""
        return self.trajectory is not None

    @property
    def stem(self) -> str:
        """``NNNNNN``: the six-digit file stem of the frame."""
        return f"{self.index:06d}"


class StageFunction(Protocol):
    """What a stage does: fills in its part of the frame (:class:`bpy_pipeline.plan.Stage` names and times it)."""

    def __call__(self, frame: Frame, run: "Run") -> None: ...


@dataclass
class Run:
    """What one run keeps across its frames (never the module).

    config : the run's config; build : build ``config.scene`` (``False``: scan the open scene as it is)
    table, rules : the class table and the name rules objects are labelled by
    keep : the builder's state across frames (:class:`~bpy_pipeline.builders.base.BuildContext`)
    rays : the sensor's rays (:class:`~bpy_pipeline.lidar.sensor.sensor_rays.SensorRays`)
    result : the :class:`~bpy_pipeline.builders.base.BuildResult` of the scene built now (every frame's ``scene``)
    scene_frame : the frame whose scene is built now (``None``: none yet)
    trajectory : the moving sensor's path in the built scene (``None`` for a static sensor)
    threads : ray-casting threads (``None``: the cores available)
    log : where warnings and the lines of long stages go (``None``: nowhere)
    members : a rig's sensors, one single-sensor :class:`Run` each (made by the rig stage on its first frame, :mod:`bpy_pipeline.stages.rig`)
    casters : the static objects' caster kept from frame to frame (:class:`~bpy_pipeline.lidar.cast.raycast.CasterCache`)
    sensor_poses : every sensor pose of the run (:class:`~bpy_pipeline.geometry.clearance.SensorPoses`), made by the
        build stage before its first build: what the builders keep their solids clear of
    static_world : ``(token, buffers, bounds)``: the builder's static world exported once (``BuildResult.static_world``,
        ``.dynamic``; :func:`~bpy_pipeline.stages.scene.export_stage`) and its vertices' ``(low, high)`` (``None``: no vertex);
        ``None`` before the first export
    in_blender : the stages after the build read each frame's objects from Blender (``BuildContext.in_blender``);
        ``False`` (:func:`~bpy_pipeline.plan.run_frames`, when they read the builder's arrays only): Blender's copy of
        the frame's road users waits for the run's end (``BuildResult.show``)
    """

    config: Config
    build: bool = True
    table: ClassTable = field(default_factory=load_class_table)
    rules: list = field(default_factory=list)
    keep: dict = field(default_factory=dict)
    rays: SensorRays | None = None
    result: BuildResult = field(default_factory=BuildResult)
    scene_frame: int | None = None
    trajectory: Trajectory | None = None
    threads: int | None = None
    log: Callable[[str], None] | None = None
    members: list["Run"] = field(default_factory=list)
    casters: CasterCache | None = None
    sensor_poses: SensorPoses | None = None
    static_world: tuple | None = None
    in_blender: bool = True

    def __post_init__(self):
        self.rules = parse_rules(self.config.labels.name_rules, "labels.name_rules", self.table.names)
        self.rays = self.rays or SensorRays(self.config)
        self.threads = self.threads or self.config.threads or None
        self.casters = self.casters or CasterCache(self.threads)
