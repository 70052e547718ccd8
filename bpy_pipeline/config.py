"""YAML -> typed, validated configuration: the tree of sections, their precedence and checks.

The sections' dataclasses live here and beside the code they configure (the sensor's spec in lidar/sensor,
the weather and materials in lidar/effects, each builder's parameters in its package). A field's unit, range
and meaning are its metadata (:func:`bpy_pipeline.schema.meta`); docs/config.md is generated from them.

A config is a tree of frozen dataclasses. :func:`load_config` reads YAML, applies ``--set``
overrides, and checks every key against the dataclass fields: an unknown key, a wrong type or
a value outside what is allowed raises :class:`~bpy_pipeline.errors.InputError` whose message
starts with the dotted key path (``sensor.max_range: ...``). :func:`config_to_dict` gives the
resolved config back as plain data (for the manifest and for saving), and loading that again
gives an equal config.
"""

from __future__ import annotations

import dataclasses
import os
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import yaml

from .errors import InputError
from .lidar.effects.divergence import Divergence, check_divergence, check_return_mode
from .lidar.effects.apply import ordered_effects
from .lidar.effects.intensity import IntensityConfig
from .lidar.effects.noise import NoiseConfig
from .lidar.effects.ray_drop import DropConfig
from .lidar.sensor.grid import check_grid, image_shape
from .lidar.sensor.mirror_sensor import check_reflector, load_edge_mask
from .lidar.sensor.platform import Trajectory
from .lidar.sensor.sensors import SensorSpec, frame_time, mount_offset, resolve_sensor
from .lidar.effects.materials import MaterialsConfig
from .lidar.effects.weather import WeatherConfig

from .builders import BUILDERS as BUILDER_REGISTRY
from .population.params import population_from_dict, population_to_dict
from .builders.railway.params import RailwayScene
from .io.writers import frame_writers
from .schema import convert, from_dict, meta, reference, to_plain
from .yaml_text import MAX_DEPTH, MAX_VALUES, read_yaml_file, read_yaml_text

Vec3 = tuple[float, float, float]
DEFAULT_SENSOR = {"preset": "railway_tls", "sampling_factor": 0.25}


# ----------------------------------------------------------------------------- scene
# builder name -> its parameters dataclass (the panel's list); the registry itself is builders.BUILDERS
BUILDER_PARAMS = {name: entry.params for name, entry in BUILDER_REGISTRY.items()}


@dataclass(frozen=True)
class SceneConfig:
    """``scene``: the builder's name and its parameters (:mod:`bpy_pipeline.builders` owns both)."""

    builder: str = "railway"
    params: typing.Any = field(default_factory=RailwayScene, metadata={"inline": True})  # its keys are scene's (scene.track_gauge)
    population: typing.Any = None  # population.params.Population: people, arms, cars placed per frame (None: none)


# ----------------------------------------------------------------------------- sensor, effects, output
@dataclass(frozen=True)
class TrajectoryConfig:
    """``sensor.trajectory``: a moving sensor (``lidar/sensor/platform.py``); replaces ``sensor.position``.

    The path is ``waypoints`` or the scene's curve object named ``curve`` (its evaluated,
    world-space polyline); its clock a constant ``speed`` or one of ``times`` per waypoint.
    The optical centre rides ``height`` (plus the preset's mount_height) above the path.
    """

    waypoints: list[Vec3] = field(default_factory=list, metadata=meta("m", help="world"))
    curve: str = field(default="", metadata=meta(help="name of a curve object of the scene, instead of waypoints"))
    speed: float = field(default=0.0, metadata=meta("m/s", help="along the path (0: give times)"))
    times: list[float] = field(default_factory=list, metadata=meta("s", help="at each waypoint, instead of speed"))
    height: float = field(default=0.0, metadata=meta("m", help="above the path"))
    heading: bool = field(default=True, metadata=meta(help="the sensor's x axis follows the path's yaw; rotation_deg turns it from there"))
    start_distance: float = field(default=0.0, metadata=meta("m", low=0, help="along the path where frame 0 starts (with speed)"))
    start_time: float = field(default=0.0, metadata=meta("s", low=0, help="after the path's start where frame 0 starts"))


@dataclass(frozen=True)
class EdgeDropConfig:
    """``sensor.reflector.edge_drop``: returns lost where a beam splits on a mirror edge (lidar/sensor/mirror_sensor.py)."""

    mask: str = field(default="generated", metadata=meta(help="generated | none | path of a measured (rows, columns) .npy of drop probabilities"))
    probability: float = field(default=0.95,
                               metadata=meta("", 0, 1, help="generated: drop probability where the footprint straddles an edge (the paper: > 90 %)"))
    beam_diameter: float = field(default=0.01, metadata=meta("m", low=0, help="generated: the beam's width where it meets the mirror (assumed; measure it)"))


@dataclass(frozen=True)
class ReflectorConfig:
    """``sensor.reflector``: the super-resolution LiDAR's own ring of mirrors (lidar/sensor/mirror_sensor.py has the geometry).

    Defaults: the human-robot paper's eight segments at 34 deg, around an Ouster OS1-128.
    """

    enabled: bool = False
    segments: int = field(default=8, metadata=meta("", low=1, help="mirror segments around the spin axis"))
    inclination_deg: float = field(default=34.0,
                                   metadata=meta("deg", 0, 90, low_open=True, high_open=True,
                                                 help="between each mirror and the spin axis: horizontal beams leave 2x this below the horizon"))
    azimuth_deg: float = field(default=0.0, metadata=meta("deg", help="azimuth of segment 0's centre"))
    distance: float = field(default=0.1, metadata=meta("m", low=0, low_open=True, help="optical centre to each mirror along its central horizontal beam"))
    bottom: float = field(default=0.09, metadata=meta("m", low=0, help="along the slope from that central point down to the segment's lower edge"))
    top: float = field(default=0.05, metadata=meta("m", low=0, help="along the slope up to its upper edge (top + bottom > 0)"))
    width: float = field(default=0.0, metadata=meta("m", low=0, help="each segment's width; 0 = full facets meeting edge to edge"))
    edge_drop: EdgeDropConfig = field(default_factory=EdgeDropConfig)


@dataclass(frozen=True)
class SensorConfig:
    """The sensor: a preset resolved with field-by-field overrides, its pose or trajectory, its beam footprint."""

    spec: SensorSpec = field(metadata={"inline": True})  # its keys are sensor's (sensor.max_range)
    position: Vec3 = field(default=(0.0, -4.0, 0.0), metadata=meta("m", help="world (the station point; the preset's mount_height is added)"))
    rotation_deg: Vec3 = field(default=(0.0, 0.0, 0.0), metadata=meta("deg", help="roll, pitch, yaw"))
    trajectory: TrajectoryConfig | None = None  # a moving sensor instead of the static position
    divergence: Divergence = field(default_factory=Divergence)  # off unless rays > 1
    reflector: ReflectorConfig = field(default_factory=ReflectorConfig)  # the sensor's own mirrors; off by default
    rig: tuple = field(default=(),
                       metadata=meta(help="sensor rig (bpy_pipeline/rig.py): RigSensor s on the platform placed by position/rotation_deg; spec is the first's"))


@dataclass(frozen=True)
class GlassConfig:
    """``effects.mirrors.glass``: how beams meet ``glass`` objects (car windows), lidar/cast/scanner.py."""

    normal_return_deg: float = field(default=5.0,
                                     metadata=meta("deg", 0, 90, high_open=True,
                                                   help="met this close to normal incidence, the glass itself returns the beam (0: never)"))
    reflect_fraction: float = field(default=0.0, metadata=meta("", 0, 1, help="share of the other beams that reflect like a mirror instead of passing through"))
    max_passes: int = field(default=8, metadata=meta("", 0, 65535, help="glass surfaces a beam may pass through; one more loses it"))


@dataclass(frozen=True)
class MirrorConfig:
    """``effects.mirrors``: specular surfaces of the scene (``mirror`` and ``glass`` objects), lidar/cast/scanner.py."""

    max_bounces: int = field(default=3, metadata=meta("", 0, 255, help="reflections before a beam is given up (a point's bounces is uint8)"))
    label: Literal["target", "reflection"] = field(default="target", metadata=meta(help="class of points seen through a mirror"))
    ideal: bool = field(default=False, metadata=meta(help="report mirrored points at the true hit instead of behind the mirror"))
    normal_return_deg: float = field(default=0.5,
                                     metadata=meta("deg", 0, 90, high_open=True,
                                                   help="a mirror met this close to normal incidence returns the beam itself (0: never)"))
    glass: GlassConfig = field(default_factory=GlassConfig)


@dataclass(frozen=True)
class EffectsConfig:
    """``effects``: what the sensor adds to the exact trace. Unless ``ideal``, the sensor preset's profile
    (``effects`` in lidar/sensor/sensors.yaml) fills the sections and keys the config does not give
    (:func:`realistic_effects`); ``ideal: true`` leaves the profile out, so only the keys given apply
    (none given: the exact, noise-free scan)."""

    ideal: bool = False
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    drop: DropConfig = field(default_factory=DropConfig)
    mirrors: MirrorConfig = field(default_factory=MirrorConfig)
    intensity: IntensityConfig = field(default_factory=IntensityConfig)
    weather: WeatherConfig = field(default_factory=WeatherConfig)  # fog, rain, snow (lidar/effects/weather/); off under ideal
    materials: MaterialsConfig = field(default_factory=MaterialsConfig)  # reflectance model per class (lidar/effects/materials.py); opt-in


BOX_CLASSES = ("car", "van", "truck", "bus", "bicycle", "motorcycle", "person", "rider", "motorcyclist", "robot arm")
# every vehicle class and every road user (a two-wheeler's box takes its rider's class, geometry/boxes.RIDER_CLASSES)


@dataclass(frozen=True)
class BoxesConfig:
    """``output.boxes``: 3D box labels per frame (io/boxes.py), in the frame of the points.

    ``formats``: ``kitti`` and/or ``openpcdet``; ``auto`` is both for the parking and
    industrial_hall builders and none otherwise. Boxes of ``classes`` with fewer labeled points
    than ``min_points[class]`` (else ``min_points_default``) are dropped (the sparse-camera
    thesis: 12 for cars, here also vans, trucks and buses; 6 for the rest). ``occlusion_levels`` (t0, t1, t2): visible / unoccluded
    point fraction from which a box is occlusion level 0, 1, 2 (below t2: 3). ``names`` maps a
    class to its label-file type (default: its words capitalised and joined, robot arm -> RobotArm; KITTI's
    types from labels.yaml ``kitti_names``; ``DontCare`` marks a class's boxes as KITTI's DontCare regions).
    The default ``classes`` (:data:`BOX_CLASSES`) box every vehicle class, as KITTI does (Van, Truck, Misc).
    """

    formats: list[str] | Literal["auto"] = field(default="auto", metadata=meta(help="box writers (io/writers.py)"))
    classes: list[str] = field(default_factory=lambda: list(BOX_CLASSES),
                               metadata=meta(help="classes that get a box: every vehicle class, person, rider (a cyclist), motorcyclist and robot arm"))
    names: dict = field(default_factory=dict)
    min_points: dict = field(default_factory=lambda: {"car": 12, "van": 12, "truck": 12, "bus": 12})
    min_points_default: int = field(default=6, metadata=meta("", low=0, help="labelled points a box needs when min_points does not name its class"))
    occlusion_levels: tuple[float, float, float] = field(
        default=(0.8, 0.4, 0.1), metadata=meta("", 0, 1, help="visible / unoccluded point fractions from which a box is occlusion level 0, 1, 2 (below t2: 3)")
    )


@dataclass(frozen=True)
class CameraConfig:
    """``output.kitti.camera``: the pinhole camera of the KITTI layout (``image_2``, ``calib`` P2), fixed to the LiDAR.

    ``resolution`` [width, height] px; ``fov_deg`` horizontal field of view (square pixels, principal
    point at the image centre; KITTI's own P2: 81.4 deg on 1242 px); ``position`` (m) and
    ``rotation_deg`` (Blender XYZ Euler, degrees) in the sensor frame: with zeros it looks along the
    sensor's x axis from the sensor's origin. ``render``: ``image_2`` rendered by Blender (Workbench,
    each object in its class colour; about 1 s a frame at 1242 x 375 on two cores); false: the
    labelled points projected into the image (milliseconds; what a LiDAR-only loader needs).
    """

    resolution: tuple[int, int] = field(default=(1242, 375), metadata=meta("px", low=1, help="[width, height]"))
    fov_deg: float = field(default=81.4,
                           metadata=meta("deg", 0, 180, low_open=True, high_open=True, help="horizontal field of view (KITTI's own P2: 81.4 deg on 1242 px)"))
    position: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), metadata=meta("m", help="in the sensor frame"))
    rotation_deg: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), metadata=meta("deg", help="Blender XYZ Euler angles in the sensor frame"))
    render: bool = False


@dataclass(frozen=True)
class KittiConfig:
    """``output.kitti``: the KITTI object layout's camera.

    ``val_fraction`` (older configs): the val share of ``output.split``, train the rest, no test.
    """

    val_fraction: float | None = field(default=None,
                                      metadata=meta("", 0, 1, high_open=True, help="older configs: the val share of output.split, train the rest, no test"))
    camera: CameraConfig = field(default_factory=CameraConfig)


@dataclass(frozen=True)
class SplitConfig:
    """``output.split``: train, val and test by scene, block of frames or contiguous fold (io/splits.py), never
    frame by frame by default. ``by``: auto (scene where the run has several, else block) | scene | block |
    frame | fold; ``train val test``: fractions (by scene, block, frame); ``block``: frames per block (0: 10);
    ``folds``, ``fold``: contiguous folds, fold ``fold`` (-1: the last) is val; ``seed``: draws where the
    split's sequence starts (null: its start). Every format and index follows it."""

    by: Literal["auto", "scene", "block", "frame", "fold"] = "auto"
    train: float = field(default=0.7, metadata=meta("", 0, 1, help="share of scenes, blocks or frames in train"))
    val: float = field(default=0.15, metadata=meta("", 0, 1, help="share in val"))
    test: float = field(default=0.15, metadata=meta("", 0, 1, help="share in test"))
    block: int = field(default=0, metadata=meta("", low=0, help="frames per block (0: 10)"))
    folds: int = field(default=5, metadata=meta(help="contiguous folds (by: fold)"))
    fold: int = field(default=-1, metadata=meta(help="the fold that is val (-1: the last)"))
    seed: int | None = field(default=None, metadata=meta("", low=0, help="draws where the split's sequence starts (null: its start)"))


@dataclass(frozen=True)
class SemanticKittiOutput:
    """``output.semantickitti``: ``labels``: semantickitti (SemanticKITTI's raw ids, labels.yaml's
    ``semantickitti:`` table, so stock loaders read the right classes) | project (the project's own ids)."""

    labels: Literal["semantickitti", "project"] = "semantickitti"


@dataclass(frozen=True)
class OutputConfig:
    formats: list[str] = field(default_factory=lambda: ["ply", "semantickitti"], metadata=meta(help="writers of io/writers.py"))
    frame: Literal["sensor", "world", "kitti"] = field(
        default="sensor", metadata=meta(help="the points' frame; kitti: level, ground at z = -1.73 m (geometry/transforms.output_pose)")
    )
    preview: bool = True
    sequence: int = field(default=0, metadata=meta(help="older configs only: SemanticKITTI sequences follow output.split (0 is accepted)"))
    boxes: BoxesConfig = field(default_factory=BoxesConfig)
    skip_empty: bool = field(default=False, metadata=meta(help="a frame with fewer than min_objects labelled objects is recorded as skipped, no files"))
    min_objects: int = field(default=1, metadata=meta("", low=0, help="objects of output.boxes.classes with their minimum points (skip_empty)"))
    frames_kept: bool = field(default=False, metadata=meta(help="skip_empty: `frames` counts kept frames; indices go on past it (full runs only)"))
    kitti: KittiConfig = field(default_factory=KittiConfig)  # KITTI layout camera
    split: SplitConfig = field(default_factory=SplitConfig)  # train/val/test of every format and index
    class_map: dict = field(default_factory=dict, metadata=meta(help="{task class: [classes] | rest, ignore: [classes]}: training ids for a task"))
    semantickitti: SemanticKittiOutput = field(default_factory=SemanticKittiOutput)


@dataclass(frozen=True)
class LabelsConfig:
    """Extra name rules, tried before those of assets_manifest/labels.yaml."""

    name_rules: list[dict] = field(default_factory=list)


@dataclass(frozen=True)
class LimitsConfig:
    """``limits``: the most work a run may ask for; above any, the run is refused before Blender builds
    anything, with the estimate's figures and the key to raise (bpy_pipeline/estimate.py). Never
    changes a frame's bytes (not part of the run key)."""

    rays_per_frame: float = field(default=5e7,
                                  metadata=meta("", low=0, low_open=True,
                                                help="every ray of every sensor of a frame (the thesis scanner at full resolution: 2.3e7)"))
    triangles: float = field(default=5e7, metadata=meta("", low=0, low_open=True, help="triangles of a frame's scene, estimated from the config"))
    objects: float = field(default=1e4, metadata=meta("", low=0, low_open=True, help="objects of a frame's scene (placed people, cars, shapes, ...)"))
    seconds: float = field(default=7 * 86400.0, metadata=meta("s", low=0, low_open=True, help="estimated seconds of the selected frames in one process"))
    bytes: float = field(default=1e12, metadata=meta("", low=0, low_open=True, help="estimated bytes written by the selected frames"))
    particles: float = field(default=1e9,
                             metadata=meta("", low=0, low_open=True, help="rain drops and snow flakes drawn a frame, at most (145 ns each: 2.4 min a frame)"))


MAX_FRAMES = 10**9  # frame indices are 6+ digit file names and records; a billion frames is centuries of scanning


@dataclass(frozen=True)
class Config:
    seed: int = field(default=0, metadata=meta("", low=0, help="the run's seed: every frame's generator derives from (seed, frame index)"))
    frames: int = field(default=1, metadata=meta("", 1, MAX_FRAMES,
                                                 help="frames to make (a billion is centuries of scanning; run parts of a larger set as separate runs)"))
    threads: int = field(default=0, metadata=meta("", low=0, help="ray-casting threads per process (0: the cores available); never changes the output"))
    scene: SceneConfig = field(default_factory=SceneConfig)
    # The default job: the railway thesis's terrestrial scanner (table 4.3) 2 m above a station
    # point 4 m beside the track, at 0.2 x 0.2 degrees (1.4 M rays) so it runs in seconds.
    sensor: SensorConfig = field(default_factory=lambda: SensorConfig(resolve_sensor(DEFAULT_SENSOR, "sensor")))
    effects: EffectsConfig = field(default_factory=EffectsConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    labels: LabelsConfig = field(default_factory=LabelsConfig)
    limits: LimitsConfig = field(default_factory=LimitsConfig)


# ----------------------------------------------------------------------------- reference
REFERENCE_SECTIONS = (("", None), ("sensor", SensorConfig), ("effects", EffectsConfig), ("output", OutputConfig), ("limits", LimitsConfig))


def config_reference() -> str:
    """docs/config.md: every key of the config's sensor, effects, output and limits sections, the top-level
    scalars and each builder's ``scene`` keys, with its type, default, unit, allowed range and meaning, read from the dataclasses' fields and their
    metadata (:func:`bpy_pipeline.schema.meta`). ``python -m bpy_pipeline config --reference`` prints it."""
    lines = ["# Config reference", "",
             "Generated from the config's dataclasses (`python -m bpy_pipeline config --reference > docs/config.md`;",
             "`tests/test_field_metadata.py` fails when this file and the code differ). Unit, range and meaning come from each",
             "field's metadata (`bpy_pipeline/schema.py`, `meta`); a value outside the range is refused with the key's",
             "name. A preset's values are listed by `python -m bpy_pipeline sensors show NAME`; what each builder builds",
             "is docs/builders.md.", ""]
    sections = [(f"`{section}`" if section else "Top level", cls, section) for section, cls in REFERENCE_SECTIONS]
    sections.insert(2, ("`sensor`: the preset's fields, each overridable (defaults: `custom`, no preset)", SensorSpec, "sensor"))
    sections += [(f"`scene` (builder: {name})", BUILDER_REGISTRY.get(name).params, "scene") for name in sorted(BUILDER_REGISTRY.names())]
    for title, cls, section in sections:
        rows = [r for r in reference(Config) if "." not in r[0]] if cls is None else reference(cls, section)
        rows = [r for r in rows if not r[0].startswith("sensor.spec")]
        lines += [f"## {title}", "", "| key | type | default | unit | range | meaning |", "| --- | --- | --- | --- | --- | --- |"]
        lines += ["| " + " | ".join(str(cell).replace("|", "\\|") for cell in (f"`{key}`", *rest)) + " |" for key, *rest in rows]
        lines.append("")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- validation
def _mapping(data, key: str, what: str) -> dict:
    """A config section that must be a mapping (``{}`` when absent)."""
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError(f"{key}: expected a mapping ({what}), got {type(data).__name__} {data!r}")
    return data


def scene_places_sensor(scene: SceneConfig) -> bool:
    """True when the scene places the sensor (railway stations, the parking robot, the hall's mount)."""
    return BUILDER_REGISTRY.get(scene.builder).station(scene.params, 0) is not None


def _scene_from_dict(data) -> SceneConfig:
    data = dict(_mapping(data, "scene", "builder: NAME and its parameters"))
    name = data.pop("builder", "railway")
    builder = BUILDER_REGISTRY.get(name)
    own = "population" in {f.name for f in dataclasses.fields(builder.params)}  # a builder with its own population keys (real_scan)
    population = None if own else population_from_dict(data.pop("population", None))
    if population is not None and not builder.blender_scene:  # no Blender scene to place into
        raise InputError(f"scene.population: the {name} scene makes its points without a Blender scene; place objects with its own keys (scene.objects)")
    params = from_dict(builder.params, data, "scene")
    builder.check(params, "scene")
    return SceneConfig(name, params, population)


def sensor_trajectory(sensor: SensorConfig, path=None) -> Trajectory | None:
    """The configured :class:`~.lidar.sensor.platform.Trajectory`, ``None`` for a static sensor.

    path : (k, 3) float64 world polyline of ``trajectory.curve`` (``blender.curves.curve_polyline``);
        needed only when the trajectory follows a curve of the scene
    """
    section = sensor.trajectory
    if section is None:
        return None
    if section.curve and path is None:
        raise ValueError("sensor_trajectory: a curve trajectory needs the curve's polyline (blender.curves.curve_polyline)")
    points = path if section.curve else section.waypoints
    return Trajectory(
        points,
        speed=None if section.times else section.speed,
        times=section.times or None,
        heading=section.heading,
        rotation_deg=sensor.rotation_deg,
        offset=mount_offset(sensor.spec) + [0.0, 0.0, section.height],
        start_distance=section.start_distance,
        start_time=section.start_time,
        where=f"sensor.trajectory{'.curve' if section.curve else '.waypoints'}",
    )


def _trajectory_from_dict(data, sensor_data: dict) -> TrajectoryConfig | None:
    if data is None:
        return None
    where = "sensor.trajectory"
    section = from_dict(TrajectoryConfig, data, where)
    if "position" in sensor_data:
        raise InputError("sensor.position: a trajectory replaces the static position; give one of them")
    if bool(section.waypoints) == bool(section.curve):
        raise InputError(f"{where}: give either waypoints (a list of [x, y, z]) or curve (the name of a curve object of the scene)")
    if section.curve and section.times:
        raise InputError(f"{where}.times: per-waypoint times need waypoints; a curve takes a speed")
    if section.times and section.speed:
        raise InputError(f"{where}.speed: give either a speed or times, not both")
    if not section.times and not section.speed > 0:
        raise InputError(f"{where}.speed: must be > 0 m/s (or give times per waypoint), got {section.speed}")
    return section


def _rig_from_dict(sensor_data: dict) -> tuple:
    """``sensor.rig`` (popped from ``sensor_data``): a rig name or list (bpy_pipeline/rig.py); ``()`` when absent."""
    data = sensor_data.pop("rig", None)
    if data is None or data == []:
        return ()
    from .rig import rig_from_data

    if sensor_data:  # position, rotation_deg and trajectory are popped already: they place the platform
        extra = sorted(sensor_data)[0]
        raise InputError(
            f"sensor.{extra}: with sensor.rig, give each sensor's preset and fields in its rig entry (sensor.rig[k].{extra}); sensor keeps position, "
            "rotation_deg and trajectory"
        )
    return rig_from_data(data, "sensor.rig")


def effects_from_dict(data, spec: SensorSpec | None = None) -> EffectsConfig:
    """Validate an ``effects`` mapping on its own (as written under ``effects:`` in a config);
    ``spec``, when given, is the sensor whose rings ``noise.ring_bias`` must match."""
    effects = from_dict(EffectsConfig, data, "effects")
    _check_effects(effects, spec)
    return effects


def realistic_effects(data, spec: SensorSpec | None) -> dict | object:
    """The config's raw ``effects`` mapping over the profile of its sensor's preset (lidar/sensor/sensors.yaml).

    Unless ``ideal: true``: each section the profile has (noise, drop, intensity) is the profile's,
    with the config's keys of that section replacing the profile's one by one; a config section
    that names another ``model`` (or a ``model_file``) replaces the profile's section whole.
    Merging a resolved config again changes nothing (``config_to_dict`` round trips).
    Anything but a mapping is returned as given, for validation to name.
    """
    from .lidar.sensor.sensors import preset_effects

    if data is not None and not isinstance(data, dict):
        return data
    data = dict(data or {})
    if data.get("ideal") is True or spec is None:
        return data
    for section, profile in preset_effects(spec.name).items():
        given = data.get(section)
        if given is None:
            data[section] = profile
        elif isinstance(given, dict) and isinstance(profile, dict):
            other_model = "model_file" in given or given.get("model", profile.get("model")) != profile.get("model")
            data[section] = dict(given) if other_model else _merged(profile, given)
    return data


def _merged(base: dict, over: dict) -> dict:
    out = dict(base)
    for key, value in over.items():
        out[key] = _merged(base[key], value) if isinstance(value, dict) and isinstance(base.get(key), dict) else value
    return out


def _check_effects(effects: EffectsConfig, spec: SensorSpec | None) -> None:
    """Each registered effect's check of its section (lidar/effects/base.py), in the order the effects run."""
    for effect in ordered_effects():
        effect.check(effects, spec)


def _check_reflector(reflector: ReflectorConfig, spec: SensorSpec) -> None:
    if not reflector.enabled:
        return
    where = "sensor.reflector"
    check_reflector(reflector, where)
    edge = reflector.edge_drop
    if edge.mask != "none":
        check_grid(spec, f"{where}.edge_drop.mask")
        if edge.mask != "generated":
            load_edge_mask(edge.mask, image_shape(spec), f"{where}.edge_drop.mask")


def config_from_dict(data) -> Config:
    """Validate a plain config mapping (as read from YAML) into a :class:`Config`."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"config: expected a mapping at the top level, got {type(data).__name__}")
    data = dict(data)
    raw_scene = _mapping(data.get("scene"), "scene", "builder: NAME and its parameters")
    scene = _scene_from_dict(data.pop("scene", None))
    builder = BUILDER_REGISTRY.get(scene.builder)
    sensor_data = dict(_mapping(data.pop("sensor", None), "sensor", "preset: NAME and its fields"))
    if builder.release_sensor is not None:
        scene = SceneConfig(scene.builder, builder.release_sensor(scene.params, raw_scene, sensor_data), scene.population)
    if "preset" not in sensor_data and builder.sensor:  # the builder's own sensor, refined by the fields given
        defaults = builder.sensor
        given = sensor_data
        if "rig" in given:  # a rig of the config's own: the builder's sensor fields do not apply to it
            defaults = {k: v for k, v in defaults.items() if k in ("position", "rotation_deg")}
        sensor_data = {**defaults, **sensor_data,
                       **({"reflector": {**defaults["reflector"], **(sensor_data.get("reflector") or {})}} if "reflector" in defaults else {})}
        if "trajectory" in given and "position" not in given:  # a trajectory given replaces the builder's position
            sensor_data.pop("position", None)
    if builder.output is not None:  # the builder's output defaults, under the config's
        data["output"] = _merged(builder.output(scene.params), _mapping(data.get("output"), "output", "formats, boxes, kitti, ..."))
    hints = typing.get_type_hints(SensorConfig)
    trajectory = _trajectory_from_dict(sensor_data.pop("trajectory", None), sensor_data)
    divergence = from_dict(Divergence, sensor_data.pop("divergence", None) or {}, "sensor.divergence")
    reflector = from_dict(ReflectorConfig, sensor_data.pop("reflector", None) or {}, "sensor.reflector")
    check_divergence(divergence, "sensor.divergence")
    pose = {k: convert(sensor_data.pop(k), hints[k], f"sensor.{k}") for k in ("position", "rotation_deg") if k in sensor_data}
    rig = _rig_from_dict(sensor_data)
    base = {} if "preset" in sensor_data else DEFAULT_SENSOR  # overrides without a preset refine the default
    spec = rig[0].spec if rig and "preset" not in sensor_data else resolve_sensor(base | sensor_data, "sensor")
    check_return_mode(divergence, spec, "sensor.divergence")
    sensor = SensorConfig(spec, **pose, trajectory=trajectory, divergence=divergence, reflector=reflector, rig=rig)
    _check_reflector(reflector, sensor.spec)
    data["effects"] = realistic_effects(data.get("effects"), spec)  # the preset's effects profile unless effects.ideal
    config = from_dict(Config, data, "")
    config = dataclasses.replace(config, scene=scene, sensor=sensor)
    if trajectory is not None and trajectory.waypoints:  # a curve's path is checked once the scene is built
        sensor_trajectory(sensor).check_frames(config.frames, frame_time(sensor.spec))
    _check_effects(config.effects, config.sensor.spec)
    weather = config.effects.weather
    if weather.divergence_mrad == 0 and config.sensor.divergence.mrad > 0:  # the weather's particles see the sensor's beam
        weather = dataclasses.replace(weather, divergence_mrad=config.sensor.divergence.mrad)
        config = dataclasses.replace(config, effects=dataclasses.replace(config.effects, weather=weather))
    config = _check_boxes(config)
    config = _check_split(config)
    _check_writers(config)
    if config.output.frame == "kitti" and (config.sensor.rig or BUILDER_REGISTRY.get(config.scene.builder).plan != "scene"):
        raise InputError("output.frame: kitti stands on a builder's ground under one sensor; a sensor rig or a real scan writes sensor or world")
    if config.output.frames_kept and not config.output.skip_empty:
        raise InputError("output.frames_kept: counts kept frames, so it needs output.skip_empty: true")
    return config


def _check_writers(config: Config) -> None:
    """Every writer named exists, in the right list, and accepts the config."""
    from .io import WRITERS

    point_writers = [name for name, w in WRITERS.items() if not w.boxes and name != "preview"]
    for key, names, boxes in (("output.formats", config.output.formats, False), ("output.boxes.formats", config.output.boxes.formats, True)):
        for i, name in enumerate(names):
            if name not in WRITERS or WRITERS.get(name).boxes != boxes or name == "preview":
                allowed = [n for n, w in WRITERS.items() if w.boxes] if boxes else point_writers
                raise InputError(f"{key}[{i}]: unknown format {name!r}; allowed: {', '.join(allowed)}")
    if not config.output.formats and not config.output.preview:
        raise InputError(f"output.formats: name at least one of {', '.join(point_writers)}")
    for name in frame_writers(config):
        WRITERS.get(name).check(config)


def _check_split(config: Config) -> Config:
    """Resolve ``output.split`` (io/splits.py: by the builder's scenes) and check ``output.class_map`` and ``output.sequence``."""
    from .io.class_maps import task_training
    from .io.splits import resolve

    output = config.output
    if output.sequence != 0:
        raise InputError(f"output.sequence: SemanticKITTI sequences follow output.split now (train 00-07, 09, 10; val 08; test 11-21), got {output.sequence}")
    task_training(output.class_map)
    split = resolve(output.split, config.frames, BUILDER_REGISTRY.get(config.scene.builder).frames_per_scene(config.scene.params), output.kitti.val_fraction)
    kitti = dataclasses.replace(output.kitti, val_fraction=None)
    return dataclasses.replace(config, output=dataclasses.replace(output, split=split, kitti=kitti))


def _check_boxes(config: Config) -> Config:
    """Resolve ``output.boxes.formats: auto`` and check the box classes and thresholds."""
    from .labels import load_class_table

    boxes = config.output.boxes
    if boxes.formats == "auto":
        boxed = BUILDER_REGISTRY.get(config.scene.builder).boxes or config.scene.population is not None  # placed objects get boxes
        boxes = dataclasses.replace(boxes, formats=["kitti", "openpcdet"] if boxed else [])
    table = load_class_table()
    classes = [table.names[table.id_of(c, f"output.boxes.classes[{i}]")] for i, c in enumerate(boxes.classes)]
    for key in ("names", "min_points"):
        for name in getattr(boxes, key):
            table.id_of(name, f"output.boxes.{key}")
    for name, value in boxes.min_points.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise InputError(f"output.boxes.min_points.{name}: expected an integer >= 0, got {value!r}")
    for name, value in boxes.names.items():
        if not isinstance(value, str) or not value or any(c.isspace() for c in value):
            raise InputError(f"output.boxes.names.{name}: expected one word (label files split on spaces), got {value!r}")
    t0, t1, t2 = boxes.occlusion_levels
    if not t0 >= t1 >= t2:  # each a fraction 0..1: the field's metadata
        raise InputError(f"output.boxes.occlusion_levels: expected three fractions t0 >= t1 >= t2, got {list(boxes.occlusion_levels)}")
    names = {table.names[table.id_of(k)]: v for k, v in boxes.names.items()}
    min_points = {table.names[table.id_of(k)]: v for k, v in boxes.min_points.items()}
    boxes = dataclasses.replace(boxes, classes=classes, names=names, min_points=min_points)
    return dataclasses.replace(config, output=dataclasses.replace(config.output, boxes=boxes))


def config_to_dict(config: Config) -> dict:
    """The resolved config as plain YAML-ready data; ``config_from_dict`` of it gives ``config`` back."""
    out = to_plain(config)
    out["scene"] = {"builder": config.scene.builder, **out["scene"]["params"]}
    if config.scene.population is not None:
        out["scene"]["population"] = population_to_dict(config.scene.population)
    sensor = out["sensor"]
    if config.sensor.trajectory is not None or scene_places_sensor(config.scene):
        del sensor["position"]  # a trajectory, or the scene, places the sensor
    if config.sensor.rig:  # each sensor's fields in its entry (bpy_pipeline/rig.py)
        sensor.pop("spec")
        sensor["rig"] = [{**entry.pop("spec"), **entry} for entry in sensor["rig"]]
        out["sensor"] = sensor
    else:
        sensor.pop("rig", None)
        out["sensor"] = {**sensor.pop("spec"), **sensor}
    return out


# ----------------------------------------------------------------------------- files and overrides
def apply_override(data: dict, assignment: str) -> None:
    """Apply one ``key.path=value`` (value parsed as YAML) to the raw config mapping in place."""
    key, sep, text = assignment.partition("=")
    if not sep or not key.strip():
        raise InputError(f"--set {assignment!r}: expected key.path=value")
    try:
        value = read_yaml_text(text, f"--set {key}")
    except yaml.YAMLError:
        raise InputError(f"--set {key}: the value {text!r} is not valid YAML") from None
    parts = key.strip().split(".")
    node = data
    for i, part in enumerate(parts[:-1]):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict):
            node = node.setdefault(part, {})
        else:
            raise InputError(f"--set {key}: {'.'.join(parts[:i + 1])} is not a mapping")
    last = parts[-1]
    if isinstance(node, list) and last.isdigit() and int(last) < len(node):
        node[int(last)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        raise InputError(f"--set {key}: {'.'.join(parts[:-1])} is not a mapping")


def read_config_file(path: str | Path) -> dict:
    """Raw mapping from a YAML file, read through the one guard (:func:`~.yaml_text.read_yaml_file`: size, nesting,
    values with aliases expanded); ``InputError`` naming the file when missing or malformed."""
    data = read_yaml_file(path, "config file")
    if data is not None and not isinstance(data, dict):
        raise InputError(f"{path}: expected a mapping of config keys at the top level")
    return data or {}


def check_tree_depth(data, where: str = "config") -> None:
    """``InputError`` when a config mapping nests deeper than :data:`MAX_DEPTH` (iterative; a cycle counts as deep)
    or holds more than :data:`~.yaml_text.MAX_VALUES` values, a shared one counted wherever it is (as a YAML file's aliases)."""
    stack, values = [(data, 1)], 0
    while stack:
        node, depth = stack.pop()
        values += 1 + (len(node) if isinstance(node, dict) else 0)  # keys count, as in a file
        if values > MAX_VALUES:
            raise InputError(f"{where}: holds more than {MAX_VALUES:,} values (shared ones counted each time), not a config")
        if isinstance(node, (dict, list, tuple)):
            if depth > MAX_DEPTH:
                raise InputError(f"{where}: nested deeper than {MAX_DEPTH} levels, not a config")
            stack.extend((child, depth + 1) for child in (node.values() if isinstance(node, dict) else node))


def load_config(path_or_dict: str | Path | dict | None = None, overrides: list[str] = ()) -> Config:
    """The validated config of a YAML file, or of a mapping as read from one (``None``: the defaults),
    with ``key.path=value`` overrides applied (values parsed as YAML)."""
    import copy

    if path_or_dict is not None and not isinstance(path_or_dict, (str, os.PathLike, dict)):
        raise InputError(f"config: expected a YAML file path or a mapping, got {type(path_or_dict).__name__}")
    if isinstance(overrides, (str, bytes)) or not all(isinstance(o, str) for o in overrides):
        raise InputError(f"overrides: expected a list of 'key.path=value' strings, got {overrides!r}")
    if isinstance(path_or_dict, dict):
        check_tree_depth(path_or_dict)
        data = copy.deepcopy(path_or_dict)
    else:
        data = read_config_file(path_or_dict) if path_or_dict else {}
    for assignment in overrides:
        apply_override(data, assignment)
    return config_from_dict(data)


def save_config(config: Config, path: str | Path) -> None:
    """Write the resolved config as YAML (atomically)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(yaml.safe_dump(config_to_dict(config), sort_keys=False))
    tmp.replace(path)
