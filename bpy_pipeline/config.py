"""YAML -> typed, validated configuration. Every default of the pipeline lives in this file.

A config is a tree of frozen dataclasses. :func:`load_config` reads YAML, applies ``--set``
overrides, and checks every key against the dataclass fields: an unknown key, a wrong type or
a value outside what is allowed raises :class:`~bpy_pipeline.errors.InputError` whose message
starts with the dotted key path (``sensor.max_range: ...``). :func:`config_to_dict` gives the
resolved config back as plain data (for the manifest and for saving), and loading that again
gives an equal config.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import yaml

from .errors import InputError
from .lidar.divergence import Divergence, check_divergence
from .lidar.grid import check_grid, image_shape
from .lidar.mirror_sensor import check_reflector, load_edge_mask
from .lidar.platform import Trajectory
from .lidar.sensors import SensorSpec, frame_time, mount_offset, resolve_sensor
from .schema import convert, from_dict, key_of

Vec3 = tuple[float, float, float]
DEFAULT_SENSOR = {"preset": "railway_tls", "sampling_factor": 0.25}
MATERIALS = ("diffuse", "mirror", "glass", "absorber")
Material = Literal["diffuse", "mirror", "glass", "absorber"]


# ----------------------------------------------------------------------------- scene builders
@dataclass(frozen=True)
class Shape:
    """One shape of the ``primitives`` builder.

    ``size``: plane and box, edge length (a number, or [x, y] / [x, y, z]); sphere, radius;
    cylinder, [radius, height]. A plane's normal is +Z before rotation; rotations are
    Blender's XYZ Euler angles in degrees. ``segments`` tessellates spheres and cylinders.
    """

    type: Literal["plane", "box", "sphere", "cylinder"]
    size: float | list[float] = 1.0
    position: Vec3 = (0.0, 0.0, 0.0)
    rotation_deg: Vec3 = (0.0, 0.0, 0.0)
    class_name: str = field(default="unlabeled", metadata={"key": "class"})
    material: Material = "diffuse"
    reflectivity: float = 0.5
    segments: int = 64
    name: str = ""


@dataclass(frozen=True)
class PrimitivesScene:
    """``scene.builder: primitives``: a ground plane, a box and a sphere unless shapes are given."""

    shapes: list[Shape] = field(
        default_factory=lambda: [
            Shape("plane", [40.0, 40.0], class_name="ground", name="ground"),
            Shape("box", [2.0, 2.0, 2.0], (8.0, 0.0, 1.0), class_name="wall", name="box"),
            Shape("sphere", 1.0, (0.0, 8.0, 1.0), class_name="person", reflectivity=0.8, name="sphere"),
        ]
    )


@dataclass(frozen=True)
class RailwayScene:
    """``scene.builder: railway``: a straight single track with sleepers, ballast, masts and wires."""

    length: float = 60.0  # m, track length centred on the origin along +x
    gauge: float = 1.435  # m, between the rail heads' inner edges
    sleeper_spacing: float = 0.6  # m
    ballast_height: float = 0.35  # m
    ballast_shoulder: float = 0.5  # m beyond the sleeper ends
    span: float = 50.0  # m between the two masts
    mast_offset: float = 3.2  # m, lateral distance of the masts from the track centre
    mast_height: float = 8.0  # m
    contact_wire_height: float = 5.5  # m above the rail head
    system_height: float = 1.4  # m, messenger wire above the contact wire at the supports
    contact_wire_sag: float = 0.0  # m at mid-span (contact wires are pre-sagged to ~0)
    messenger_wire_sag: float = 0.5  # m at mid-span
    contact_wire_diameter: float = 0.012  # m
    messenger_wire_diameter: float = 0.011  # m
    stagger: float = 0.2  # m, lateral zig-zag of the contact wire at the supports
    dropper_spacing: float = 5.0  # m


@dataclass(frozen=True)
class BlendScene:
    """``scene.builder: blend``: scan the user's own .blend file."""

    path: str = ""


BUILDERS = {"railway": RailwayScene, "primitives": PrimitivesScene, "blend": BlendScene}


@dataclass(frozen=True)
class SceneConfig:
    builder: str = "railway"
    params: RailwayScene | PrimitivesScene | BlendScene = field(default_factory=RailwayScene)


# ----------------------------------------------------------------------------- sensor, effects, output
@dataclass(frozen=True)
class TrajectoryConfig:
    """``sensor.trajectory``: a moving sensor (``lidar/platform.py``); replaces ``sensor.position``.

    The path is ``waypoints`` or the scene's curve object named ``curve`` (its evaluated,
    world-space polyline); its clock a constant ``speed`` or one of ``times`` per waypoint.
    The optical centre rides ``height`` (plus the preset's mount_height) above the path.
    """

    waypoints: list[Vec3] = field(default_factory=list)  # m, world
    curve: str = ""  # name of a curve object of the scene, instead of waypoints
    speed: float = 0.0  # m/s along the path (0: give times)
    times: list[float] = field(default_factory=list)  # s at each waypoint, instead of speed
    height: float = 0.0  # m above the path
    heading: bool = True  # the sensor's x axis follows the path's yaw; rotation_deg turns it from there
    start_distance: float = 0.0  # m along the path where frame 0 starts (with speed)
    start_time: float = 0.0  # s after the path's start where frame 0 starts


@dataclass(frozen=True)
class EdgeDropConfig:
    """``sensor.reflector.edge_drop``: returns lost where a beam splits on a mirror edge (lidar/mirror_sensor.py)."""

    mask: str = "generated"  # generated | none | path of a measured (rows, columns) .npy of drop probabilities
    probability: float = 0.95  # generated: drop probability where the footprint straddles an edge (the paper: > 90 %)
    beam_diameter: float = 0.01  # m, generated: the beam's width where it meets the mirror (assumed; measure it)


@dataclass(frozen=True)
class ReflectorConfig:
    """``sensor.reflector``: the super-resolution LiDAR's own ring of mirrors (lidar/mirror_sensor.py has the geometry).

    Defaults: the human-robot paper's eight segments at 34 deg, around an Ouster OS1-128.
    """

    enabled: bool = False
    segments: int = 8
    inclination_deg: float = 34.0  # between each mirror and the spin axis: horizontal beams leave 2x this below the horizon
    azimuth_deg: float = 0.0  # azimuth of segment 0's centre
    distance: float = 0.1  # m, optical centre to each mirror along its central horizontal beam
    bottom: float = 0.09  # m along the slope from that central point down to the segment's lower edge
    top: float = 0.05  # m along the slope up to its upper edge
    width: float = 0.0  # m, each segment's width; 0 = full facets meeting edge to edge
    edge_drop: EdgeDropConfig = field(default_factory=EdgeDropConfig)


@dataclass(frozen=True)
class SensorConfig:
    """The sensor: a preset resolved with field-by-field overrides, its pose or trajectory, its beam footprint."""

    spec: SensorSpec
    position: Vec3 = (0.0, -4.0, 0.0)  # m, world (the station point; the preset's mount_height is added)
    rotation_deg: Vec3 = (0.0, 0.0, 0.0)  # roll, pitch, yaw
    trajectory: TrajectoryConfig | None = None  # a moving sensor instead of the static position
    divergence: Divergence = field(default_factory=Divergence)  # off unless rays > 1
    reflector: ReflectorConfig = field(default_factory=ReflectorConfig)  # the sensor's own mirrors; off by default


@dataclass(frozen=True)
class IntensityConfig:
    """``effects.intensity`` (lidar/effects.py): what a point's intensity (0..1) says."""

    model: Literal["reflectance", "lidar", "carla"] = "reflectance"  # rho cos g | lidar equation | CARLA exp(-a R)
    alpha: float = 0.0  # 1/m atmospheric extinction, two-way exp(-2 alpha R): `lidar` intensity and `threshold` drop
    reference_range: float = 10.0  # m: `lidar`, a target of reference_reflectivity at normal incidence here reads 1
    reference_reflectivity: float = 1.0
    attenuation_rate: float = 0.004  # 1/m: `carla`, CARLA's atmosphere_attenuation_rate


@dataclass(frozen=True)
class NoiseConfig:
    """``effects.noise``: Gaussian range noise along the beam, per-ring bias, angular jitter."""

    model: Literal["constant", "range", "table"] = "constant"  # table: from effects.model_file
    sigma: float = 0.0  # m, Gaussian along the beam (`range`: at zero range)
    sigma_per_metre: float = 0.0  # m of sigma per m of range (`range`)
    ring_bias: list[float] = field(default_factory=list)  # m added to every range of ring k (one per ring, or none)
    angular_jitter_deg: float = 0.0  # one sigma, in azimuth and in elevation


@dataclass(frozen=True)
class CarlaDrop:
    """CARLA's RayCastLidar drop-off, with CARLA's defaults."""

    general_rate: float = 0.45  # dropoff_general_rate: rays lost whatever they hit
    intensity_limit: float = 0.8  # dropoff_intensity_limit: above it, never lost
    zero_intensity: float = 0.4  # dropoff_zero_intensity: probability of losing a zero-intensity point
    attenuation_rate: float = 0.004  # atmosphere_attenuation_rate: intensity exp(-a R), 1/m


@dataclass(frozen=True)
class ThresholdDrop:
    """A detection threshold from a datasheet's ranges (normal incidence, 50 % detection)."""

    range_at_10: float = 40.0  # m for a 10 % reflectivity target (Ouster OS1: 40; sparse 3D camera: 10)
    range_at_80: float = 120.0  # m for an 80 % target (0: unknown, the lidar equation's R^2 decides)
    softness: float = 0.1  # width of the transition in ln(received power); 0 for a hard cut


@dataclass(frozen=True)
class DropConfig:
    model: Literal["none", "uniform", "carla", "threshold", "table"] = "none"  # table: from effects.model_file
    probability: float = 0.0  # for `uniform`
    carla: CarlaDrop = field(default_factory=CarlaDrop)
    threshold: ThresholdDrop = field(default_factory=ThresholdDrop)


@dataclass(frozen=True)
class GlassConfig:
    """``effects.mirrors.glass``: how beams meet ``glass`` objects (car windows), lidar/scanner.py."""

    normal_return_deg: float = 5.0  # met this close to normal incidence, the glass itself returns the beam
    reflect_fraction: float = 0.0  # share of the other beams that reflect like a mirror instead of passing through
    max_passes: int = 8  # glass surfaces a beam may pass through; one more loses it


@dataclass(frozen=True)
class GlassConfig:
    """``effects.mirrors.glass``: how beams meet ``glass`` objects (car windows), lidar/scanner.py."""

    normal_return_deg: float = 5.0  # met this close to normal incidence, the glass itself returns the beam
    reflect_fraction: float = 0.0  # share of the other beams that reflect like a mirror instead of passing through
    max_passes: int = 8  # glass surfaces a beam may pass through; one more loses it


@dataclass(frozen=True)
class MirrorConfig:
    """``effects.mirrors``: specular surfaces of the scene (``mirror`` and ``glass`` objects), lidar/scanner.py."""

    max_bounces: int = 3  # reflections before a beam is given up (0..255)
    label: Literal["target", "reflection"] = "target"  # class of points seen through a mirror
    ideal: bool = False  # report mirrored points at the true hit instead of behind the mirror
    normal_return_deg: float = 0.5  # a mirror met this close to normal incidence returns the beam itself
    glass: GlassConfig = field(default_factory=GlassConfig)


@dataclass(frozen=True)
class EffectsConfig:
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    drop: DropConfig = field(default_factory=DropConfig)
    mirrors: MirrorConfig = field(default_factory=MirrorConfig)
    intensity: IntensityConfig = field(default_factory=IntensityConfig)
    # A file of `python -m bpy_pipeline fit`: the uniform, threshold and table drop models and the
    # range and table noise models take their parameters from it (relative paths: from the working folder)
    model_file: str = ""


FORMATS = ("ply", "semantickitti", "las", "npy", "range_image")


@dataclass(frozen=True)
class OutputConfig:
    formats: list[Literal["ply", "semantickitti", "las", "npy", "range_image"]] = field(default_factory=lambda: ["ply", "semantickitti"])
    frame: Literal["sensor", "world"] = "sensor"
    preview: bool = True
    sequence: int = 0  # SemanticKITTI sequence number (sequences/SS/)


@dataclass(frozen=True)
class LabelsConfig:
    """Extra name rules, tried before those of assets_manifest/labels.yaml."""

    name_rules: list[dict] = field(default_factory=list)


@dataclass(frozen=True)
class Config:
    seed: int = 0
    frames: int = 1
    scene: SceneConfig = field(default_factory=SceneConfig)
    # The default job: the railway thesis's terrestrial scanner (table 4.3) 2 m above a station
    # point 4 m beside the track, at 0.2 x 0.2 degrees (1.4 M rays) so it runs in seconds.
    sensor: SensorConfig = field(default_factory=lambda: SensorConfig(resolve_sensor(DEFAULT_SENSOR, "sensor")))
    effects: EffectsConfig = field(default_factory=EffectsConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    labels: LabelsConfig = field(default_factory=LabelsConfig)


# ----------------------------------------------------------------------------- validation
def _check_positive(value: float, path: str, allow_zero: bool = False) -> None:
    if value < 0 or (value == 0 and not allow_zero):
        raise InputError(f"{path}: must be {'>= 0' if allow_zero else '> 0'}, got {value}")


def _scene_from_dict(data) -> SceneConfig:
    data = dict(data or {})
    builder = data.pop("builder", "railway")
    if builder not in BUILDERS:
        raise InputError(f"scene.builder: unknown builder {builder!r}; allowed: {', '.join(BUILDERS)}")
    params = from_dict(BUILDERS[builder], data, "scene")
    if isinstance(params, PrimitivesScene):
        for i, shape in enumerate(params.shapes):
            where = f"scene.shapes[{i}]"
            sizes = [shape.size] if isinstance(shape.size, float) else shape.size
            want = {"plane": (1, 2), "box": (1, 3), "sphere": (1,), "cylinder": (2,)}[shape.type]
            if len(sizes) not in want or any(s <= 0 for s in sizes):
                raise InputError(f"{where}.size: a {shape.type} takes {' or '.join(map(str, want))} positive number(s), got {shape.size}")
            if not 0 <= shape.reflectivity <= 1:
                raise InputError(f"{where}.reflectivity: must lie in 0..1, got {shape.reflectivity}")
            if shape.segments < 3:
                raise InputError(f"{where}.segments: must be >= 3, got {shape.segments}")
    elif isinstance(params, BlendScene) and not params.path:
        raise InputError("scene.path: the blend builder needs the path of a .blend file")
    elif isinstance(params, RailwayScene):
        for f in dataclasses.fields(RailwayScene):
            _check_positive(getattr(params, f.name), f"scene.{f.name}", allow_zero=f.name.endswith(("sag", "stagger")))
    return SceneConfig(builder, params)


def effects_from_dict(data, spec: SensorSpec | None = None) -> EffectsConfig:
    """Validate an ``effects`` mapping on its own (as written under ``effects:`` in a config);
    ``spec``, when given, is the sensor whose rings ``noise.ring_bias`` must match."""
    effects = from_dict(EffectsConfig, data, "effects")
    _check_effects(effects, spec)
    return effects


def _check_effects(effects: EffectsConfig, spec: SensorSpec | None) -> None:
    """Ranges of the effects' parameters, and that a model file holds the models asked of it."""
    from .lidar.effects import read_model_file

    noise, drop, intensity = effects.noise, effects.drop, effects.intensity
    for key in ("sigma", "sigma_per_metre", "angular_jitter_deg"):
        _check_positive(getattr(noise, key), f"effects.noise.{key}", allow_zero=True)
    rings = None if spec is None else spec.channels if spec.pattern in ("spinning", "terrestrial", "pinhole", "grid") else 1
    if noise.ring_bias and rings is not None and len(noise.ring_bias) != rings:
        raise InputError(f"effects.noise.ring_bias: one value per ring ({rings} for this sensor), got {len(noise.ring_bias)}")
    probabilities = {"effects.drop.probability": drop.probability, "effects.drop.carla.general_rate": drop.carla.general_rate, "effects.drop.carla.zero_intensity": drop.carla.zero_intensity}
    for key, value in probabilities.items():
        if not 0 <= value <= 1:
            raise InputError(f"{key}: must lie in 0..1, got {value}")
    if not 0 < drop.carla.intensity_limit <= 1:
        raise InputError(f"effects.drop.carla.intensity_limit: must lie in (0, 1], got {drop.carla.intensity_limit}")
    _check_positive(drop.carla.attenuation_rate, "effects.drop.carla.attenuation_rate", allow_zero=True)
    _check_positive(drop.threshold.range_at_10, "effects.drop.threshold.range_at_10")
    _check_positive(drop.threshold.softness, "effects.drop.threshold.softness", allow_zero=True)
    if drop.threshold.range_at_80 and drop.threshold.range_at_80 <= drop.threshold.range_at_10:
        raise InputError(f"effects.drop.threshold.range_at_80: must exceed range_at_10 ({drop.threshold.range_at_10} m), or be 0, got {drop.threshold.range_at_80}")
    for key in ("alpha", "attenuation_rate"):
        _check_positive(getattr(intensity, key), f"effects.intensity.{key}", allow_zero=True)
    _check_positive(intensity.reference_range, "effects.intensity.reference_range")
    if not 0 < intensity.reference_reflectivity <= 1:
        raise InputError(f"effects.intensity.reference_reflectivity: must lie in (0, 1], got {intensity.reference_reflectivity}")
    models = read_model_file(effects.model_file) if effects.model_file else None
    needs = {"drop_table": drop.model == "table", "noise_table": noise.model == "table"}
    for attr, needed in needs.items():
        if needed and (models is None or getattr(models, attr) is None):
            what = "drop" if attr == "drop_table" else "noise"
            raise InputError(f"effects.model_file: the table {what} model needs a model file with a {what} table (python -m bpy_pipeline fit), got {effects.model_file or 'none'}")


def _check_mirrors(mirrors: MirrorConfig) -> None:
    if not 0 <= mirrors.max_bounces <= 255:
        raise InputError(f"effects.mirrors.max_bounces: must lie in 0..255 (a point's bounces is uint8), got {mirrors.max_bounces}")
    for key, angle in (("normal_return_deg", mirrors.normal_return_deg), ("glass.normal_return_deg", mirrors.glass.normal_return_deg)):
        if not 0 <= angle < 90:
            raise InputError(f"effects.mirrors.{key}: must lie in 0..90 degrees (0 = never), got {angle}")
    if not 0 <= mirrors.glass.reflect_fraction <= 1:
        raise InputError(f"effects.mirrors.glass.reflect_fraction: must lie in 0..1, got {mirrors.glass.reflect_fraction}")
    if not 0 <= mirrors.glass.max_passes <= 65535:
        raise InputError(f"effects.mirrors.glass.max_passes: must lie in 0..65535, got {mirrors.glass.max_passes}")


def _check_reflector(reflector: ReflectorConfig, spec: SensorSpec) -> None:
    if not reflector.enabled:
        return
    where = "sensor.reflector"
    check_reflector(reflector, where)
    edge = reflector.edge_drop
    if not 0 <= edge.probability <= 1:
        raise InputError(f"{where}.edge_drop.probability: must lie in 0..1, got {edge.probability}")
    if edge.beam_diameter < 0:
        raise InputError(f"{where}.edge_drop.beam_diameter: must be >= 0 m, got {edge.beam_diameter}")
    if edge.mask != "none":
        check_grid(spec, f"{where}.edge_drop.mask")
        if edge.mask != "generated":
            load_edge_mask(edge.mask, image_shape(spec), f"{where}.edge_drop.mask")


def sensor_trajectory(sensor: SensorConfig, path=None) -> Trajectory | None:
    """The configured :class:`~.lidar.platform.Trajectory`, ``None`` for a static sensor.

    path : (k, 3) float64 world polyline of ``trajectory.curve`` (``scenes.curves.curve_polyline``);
        needed only when the trajectory follows a curve of the scene
    """
    section = sensor.trajectory
    if section is None:
        return None
    if section.curve and path is None:
        raise ValueError("sensor_trajectory: a curve trajectory needs the curve's polyline (scenes.curves.curve_polyline)")
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


def config_from_dict(data) -> Config:
    """Validate a plain config mapping (as read from YAML) into a :class:`Config`."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"config: expected a mapping at the top level, got {type(data).__name__}")
    data = dict(data)
    scene = _scene_from_dict(data.pop("scene", None))
    sensor_data = dict(data.pop("sensor", None) or {})
    hints = typing.get_type_hints(SensorConfig)
    trajectory = _trajectory_from_dict(sensor_data.pop("trajectory", None), sensor_data)
    divergence = from_dict(Divergence, sensor_data.pop("divergence", None) or {}, "sensor.divergence")
    reflector = from_dict(ReflectorConfig, sensor_data.pop("reflector", None) or {}, "sensor.reflector")
    check_divergence(divergence, "sensor.divergence")
    pose = {k: convert(sensor_data.pop(k), hints[k], f"sensor.{k}") for k in ("position", "rotation_deg") if k in sensor_data}
    base = {} if "preset" in sensor_data else DEFAULT_SENSOR  # overrides without a preset refine the default
    sensor = SensorConfig(resolve_sensor(base | sensor_data, "sensor"), **pose, trajectory=trajectory, divergence=divergence, reflector=reflector)
    _check_reflector(reflector, sensor.spec)
    config = from_dict(Config, data, "")
    config = dataclasses.replace(config, scene=scene, sensor=sensor)
    if config.frames < 1:
        raise InputError(f"frames: must be >= 1, got {config.frames}")
    if config.seed < 0:
        raise InputError(f"seed: must be >= 0, got {config.seed}")
    if trajectory is not None and trajectory.waypoints:  # a curve's path is checked once the scene is built
        sensor_trajectory(sensor).check_frames(config.frames, frame_time(sensor.spec))
    _check_effects(config.effects, config.sensor.spec)
    _check_mirrors(config.effects.mirrors)
    if "range_image" in config.output.formats:
        check_grid(config.sensor.spec, "output.formats: range_image")
    if not config.output.formats and not config.output.preview:
        raise InputError(f"output.formats: name at least one of {', '.join(FORMATS)}")
    return config


def config_to_dict(config: Config) -> dict:
    """The resolved config as plain YAML-ready data; ``config_from_dict`` of it gives ``config`` back."""

    def plain(value):
        if dataclasses.is_dataclass(value):
            return {key_of(f): plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        return value

    out = plain(config)
    out["scene"] = {"builder": config.scene.builder, **out["scene"]["params"]}
    sensor = out["sensor"]
    if config.sensor.trajectory is not None:
        del sensor["position"]  # a trajectory replaces it
    out["sensor"] = {**sensor.pop("spec"), **sensor}
    return out


# ----------------------------------------------------------------------------- files and overrides
def apply_override(data: dict, assignment: str) -> None:
    """Apply one ``key.path=value`` (value parsed as YAML) to the raw config mapping in place."""
    key, sep, text = assignment.partition("=")
    if not sep or not key.strip():
        raise InputError(f"--set {assignment!r}: expected key.path=value")
    try:
        value = yaml.safe_load(text)
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
    """Raw mapping from a YAML file; ``InputError`` naming the file when missing or malformed."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise InputError(f"{path}: cannot read the config file ({err.strerror or err})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise InputError(f"{path}: not valid YAML{where}") from None
    if data is not None and not isinstance(data, dict):
        raise InputError(f"{path}: expected a mapping of config keys at the top level")
    return data or {}


def load_config(path: str | Path | None = None, overrides: list[str] = ()) -> Config:
    """Read ``path`` (or the embedded defaults when ``None``), apply ``key=value`` overrides, validate."""
    data = read_config_file(path) if path else {}
    for assignment in overrides:
        apply_override(data, assignment)
    return config_from_dict(data)


def save_config(config: Config, path: str | Path) -> None:
    """Write the resolved config as YAML (atomically)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(yaml.safe_dump(config_to_dict(config), sort_keys=False))
    tmp.replace(path)
