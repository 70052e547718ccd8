"""What a scene builder is: its config dataclass, its build function and what it tells the run.

A builder turns its ``scene`` section into tagged objects of the current Blender scene. The
entry itself is pure (config validation needs no Blender); its ``build`` imports the bpy code
when called. A frame's scene is built by :func:`build_scene`, which hands the builder a
:class:`BuildContext`; the builder answers with a :class:`BuildResult`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..errors import InputError
from ..geometry.clearance import NO_POSES, SensorPoses
from ..registry import Registry


@dataclass
class BuildContext:
    """What a builder gets besides its parameters.

    rng : the generator the scene is drawn from (the frame's, or the first frame's of a scene that
        serves several frames)
    view : :class:`~bpy_pipeline.geometry.lod.SensorView` of the frames the scene serves (where it is
        scanned from and how finely); for a moving sensor a :class:`~bpy_pipeline.geometry.lod.PlannedPath`
        when the builder ``follows_path``, else ``None`` (fixed detail)
    keep : state the run owns across frames; a builder that re-randomises in place keeps its static
        scene here (and must give the same result as when built from nothing)
    sensor_poses : :class:`~bpy_pipeline.geometry.clearance.SensorPoses`, every optical centre of the run (all frames,
        rig members, a path); every solid the builder places keeps their ``radius`` from them
    in_blender : the frame's objects are wanted in Blender as the build returns (``False``: a builder that gives
        them as arrays, ``BuildResult.dynamic_parts``, may leave Blender's copy to ``BuildResult.show``)
    """

    rng: np.random.Generator
    view: Any = None
    keep: dict = field(default_factory=dict)
    sensor_poses: SensorPoses = field(default_factory=lambda: NO_POSES)
    in_blender: bool = True

    def kept(self, key: str, params, make: Callable[[], Any]):
        """The object kept under ``key`` for ``params`` while it is alive, else a new one from ``make()``."""
        held = self.keep.get(key)
        if held is None or held[0] != params or not held[1].alive():
            self.keep.clear()
            held = self.keep[key] = (params, make())
        return held[1]


@dataclass(frozen=True)
class BuildResult:
    """What a builder reports about the scene it built.

    headings : {instance id: yaw in radians} of the objects that get 3D boxes
    info : plain data for the frame's record (counts, placement log)
    scene : the builder's own description of what it built (the railway's layout), for callers
        that want it; never written
    warnings : lines for the user (a placement loop that gave up, say), printed by the run
    dynamic : the name of the Blender collection holding every object the builder placed for this frame, when all
        the rest of the scene (its static world) stays as it is while ``static_world`` is the same object: the export
        stage then exports the static world once, whole, and this collection every frame (``None``: the whole scene
        every frame)
    static_world : a token the builder keeps while its static world is unchanged (a new one for a world built anew)
    dynamic_parts : the ``dynamic`` collection's objects as arrays, in its order, when they are plain tagged meshes
        (:func:`~bpy_pipeline.blender.export.parts_buffers`): the export stage then takes them as they are instead of reading
        them back from Blender (the same buffers); ``None``: read from Blender
    show : puts ``dynamic_parts`` into Blender's objects where the build left them out (``BuildContext.in_blender``
        false); does nothing once they are there. ``None``: the build put everything in Blender
    """

    headings: dict = field(default_factory=dict)
    info: dict | None = None
    scene: Any = None
    warnings: tuple[str, ...] = ()
    dynamic: str | None = None
    static_world: Any = None
    dynamic_parts: tuple | None = None
    show: Callable[[], None] | None = None


def no_check(params, where: str) -> None:
    """Parameters that need no check beyond their types and their fields' metadata ranges (the schema checks both)."""


def no_station(params, frame: int) -> None:
    """A scene that does not place the sensor."""
    return None


def one_frame(params) -> int:
    return 1


def no_stations(params) -> int:
    return 0


@dataclass(frozen=True)
class Builder:
    """A scene builder's registry entry.

    params : the dataclass of its ``scene`` section (the keys after ``builder``)
    build : ``build(params, context) -> BuildResult``; builds the scene in the current Blender scene
    check : ``check(params, where)``: ``InputError`` naming the key when the parameters cannot build a scene (the
        rules between fields; each field's own range is its metadata's, checked by the schema)
    station : ``station(params, frame) -> (4, 4) | None``: the level frame the scene places the sensor
        at in frame ``frame`` (the sensor's rotation and mount height are applied on top), ``None``
        where the config's ``sensor.position`` applies
    frames_per_scene : ``frames_per_scene(params) -> n``: one built scene serves n frames in a row
        (frame k scans the scene built for frame k - k mod n)
    stations : ``stations(params) -> n``: how many fixed stations ``station`` cycles through (frame k
        scans from station k mod n, recorded as the frame's ``station``); 0 where it places none
    sensor : the builder's own sensor, used when the config's ``sensor`` names no preset (fields given refine it)
    boxes : whether 3D box labels are written by default (``output.boxes.formats: auto``)
    release_sensor : ``release_sensor(params, raw_scene, sensor_data) -> params``: when the config places
        the sensor itself (sensor.position or trajectory), the parameters that stop the scene placing it
        (``InputError`` where both do)
    output : ``output(params) -> {key: value}``: the builder's defaults for the ``output`` section, under the config's
        (the industrial hall's KITTI camera at KITTI's height above the floor); ``None``: none
    plan : how its frames are made (:data:`bpy_pipeline.plan.PLANS`): ``scene`` (a Blender scene scanned by one
        sensor or a rig) or ``real_scan`` (a real scan as the background, objects cast in by its firings)
    follows_path : a moving sensor's scene is graded along its path: ``build`` gets a
        :class:`~bpy_pipeline.geometry.lod.PlannedPath` as ``context.view`` (else ``None``)
    """

    params: type
    build: Callable[[Any, BuildContext], BuildResult]
    check: Callable[[Any, str], None] = no_check
    station: Callable[[Any, int], np.ndarray | None] = no_station
    frames_per_scene: Callable[[Any], int] = one_frame
    stations: Callable[[Any], int] = no_stations
    sensor: dict = field(default_factory=dict)
    boxes: bool = False
    release_sensor: Callable[[Any, dict, dict], Any] | None = None
    follows_path: bool = False
    plan: str = "scene"
    output: Callable[[Any], dict] | None = None

    @property
    def blender_scene(self) -> bool:
        """True when its frames scan a Blender scene (so a population can be placed in it)."""
        return self.plan == "scene"


BUILDERS: Registry[Builder] = Registry("scene builder", "scene.builder")


def register_builder(name: str, builder: Builder) -> Builder:
    """Make ``scene.builder: name`` build with ``builder``."""
    return BUILDERS.register(name, builder)


def build_scene(builder: str, params, context: BuildContext) -> BuildResult:
    """Build scene ``builder`` with ``params`` in the current Blender scene."""
    return BUILDERS.get(builder).build(params, context)


def refuse_sensor_placement(name: str) -> Callable[[Any, dict, dict], Any]:
    """``release_sensor`` of a scene whose ``place_sensor`` flag places the sensor: a position or trajectory
    given as well is an error unless ``place_sensor`` is false."""

    def release(params, raw_scene: dict, sensor_data: dict):
        if getattr(params, "place_sensor", False):
            for key in ("position", "trajectory"):
                if sensor_data.get(key) is not None:
                    raise InputError(f"sensor.{key}: the {name} scene places the sensor itself; set scene.place_sensor: false to use sensor.{key}")
        return params

    return release
