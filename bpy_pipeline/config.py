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
from .schema import convert, from_dict, to_plain

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
class RailProfile:
    """A simplified flat-bottom rail: three stacked rectangles (m). The default weighs about 60 kg/m
    (7.63e-3 m^2 of steel; UIC 60: 172 mm high, 150 mm foot, 72 mm head, 16.5 mm web)."""

    foot_width: float = 0.150
    foot_height: float = 0.018
    web_width: float = 0.0165
    web_height: float = 0.111
    head_width: float = 0.072
    head_height: float = 0.043


@dataclass(frozen=True)
class RailwayTrack:
    """``scene.track``: the railway thesis's table 4.1, in metres (the thesis gives no values; these are
    European standard-gauge ones). The alignment is the arc through start, mid and end (straight when
    they are collinear), at formation level (the underside of the ballast); tracks are spread evenly
    across it, track 0 the rightmost in the direction of travel."""

    start: Vec3 = (-75.0, 0.0, 0.0)
    mid: Vec3 = (0.0, 0.0, 0.0)
    end: Vec3 = (75.0, 0.0, 0.0)
    gauge: float = 1.435  # between the inner faces of the rail heads
    rail: RailProfile = field(default_factory=RailProfile)
    sleeper_spacing: float = 0.6
    sleeper_length: float = 2.6  # concrete monoblock sleeper (B70-like): across the track
    sleeper_width: float = 0.26  # along the track
    sleeper_height: float = 0.22
    ballast_height: float = 0.35  # under the sleepers
    ballast_shoulder: float = 0.5  # beyond the sleeper ends
    ballast_slope: float = 1.5  # horizontal per vertical
    tracks: int = 1  # 1..5
    track_spacing: float = 4.0  # between neighbouring track centrelines
    embankment_height: float = 0.0  # formation above the surrounding ground
    embankment_slope: float = 1.5  # horizontal per vertical
    embankment_berm: float = 1.0  # flat formation beyond the ballast toe
    ground_width: float = 80.0  # flat ground strip along the alignment


@dataclass(frozen=True)
class RailwaySupports:
    """``scene.supports``: masts (H-section or lattice) with cantilevers and registration arms, or portal
    gantries, every ``span`` +- ``span_jitter`` metres along the alignment (the thesis: 40 to 65 m).
    ``layout``: ``single`` one mast per support on ``side`` carrying up to two tracks; ``both_sides`` a mast
    on each side, each carrying the nearer half of the tracks (up to four); ``gantry`` a portal over
    2 to 5 tracks; ``auto`` single for one track, single or both_sides (even odds) for two, gantry beyond.
    On a curve of radius R (in plan) spans shorten to sqrt(8 R (stagger + 0.4 m)), so the contact wire,
    pulled outwards at every support, strays at most 0.4 m inside the track at mid-span."""

    layout: Literal["auto", "single", "both_sides", "gantry"] = "auto"
    side: Literal["right", "left"] = "right"
    span: float = 50.0
    span_jitter: float = 5.0
    mast_type: Literal["h_section", "lattice", "mixed"] = "h_section"
    mast_offset: float = 3.2  # from the centreline of the nearest track
    mast_height: float = 8.5  # above the ground it stands on


@dataclass(frozen=True)
class RailwayCatenary:
    """``scene.catenary``: the catenary manager of the thesis (table 4.2), in metres. Sag of a wire over a
    span L: f(L) = <wire>_sag (L / sag_reference_length) ^ sag_exponent; droppers n = max(1, floor(L /
    dropper_spacing)) per contact wire. ``points_per_10m`` samples the wires when ``scene.detail.mode`` is
    ``fixed``; the sensor-driven default samples them as finely as the sensor can tell apart."""

    enabled: bool = True  # ENABLE_CATENARY: contact and messenger wires, droppers
    feeders: bool = True  # ENABLE_FEEDERS
    earth_wire: bool = True  # ENABLE_CdPA
    contact_wire_height: float = 5.5  # above the rail heads
    system_height: float = 1.4  # messenger above the contact wire at the supports (1.1-1.8)
    stagger: float = 0.2  # contact wire zig-zag at the supports, +- (0.2-0.3)
    double_contact_probability: float = 0.0  # FC_DOUBLE_PROBABILITY, per track
    double_contact_spacing: float = 0.04  # FC_DOUBLE_SPACING: between the two contact wires
    sag_reference_length: float = 50.0  # SAG_REFERENCE_LENGTH
    sag_exponent: float = 2.0  # SAG_EXPONENT_ALPHA (2: sag grows with L^2 at a fixed tension)
    contact_wire_sag: float = 0.05  # SAG_* at the reference length (contact wire: pre-sag, 1/1000 of the span)
    messenger_wire_sag: float = 0.5
    feeder_sag: float = 1.0
    earth_wire_sag: float = 0.8
    contact_wire_diameter: float = 0.012  # DIAM_*: 107 mm^2 grooved copper
    messenger_wire_diameter: float = 0.011
    feeder_diameter: float = 0.024
    earth_wire_diameter: float = 0.012
    dropper_diameter: float = 0.005
    dropper_spacing: float = 5.0  # PENDULUM_SPACING
    dropper_jitter: float = 0.2  # PENDULUM_JITTER, +- along the span
    points_per_10m: int = 20  # CURVE_RESOLUTION_POINTS_PER_10M, for scene.detail.mode fixed


@dataclass(frozen=True)
class RailwayStations:
    """``scene.stations``: static scanner stations beside the track, ``offset`` metres beyond the outermost
    track on ``side``, on the ground there, facing along the track (the preset's mount_height lifts the
    sensor above it: 2 m for railway_tls). Frame k scans from station k mod n, and one built line serves
    n frames in a row (frames = stations scans one line from every station). ``chainages`` (m from the
    start point) place them; else ``count`` stations sit at the middles of equal parts of the line.
    ``count: 0`` uses sensor.position instead."""

    count: int = 1
    chainages: list[float] = field(default_factory=list)
    side: Literal["right", "left"] = "left"  # the masts stand on the right: the scanner sees them across the track
    offset: float = 4.0


@dataclass(frozen=True)
class RailwayDetail:
    """``scene.detail``: ``sensor`` (the default) models no finer than the scanner resolves: wire sampling
    and cross-sections within half the beam spacing at their distance, ballast stones of ``stone_size``
    only where two beams fall on one, nothing beyond the sensor's range. ``fixed`` samples wires at
    catenary.points_per_10m, builds the whole line and no stones."""

    mode: Literal["sensor", "fixed"] = "sensor"
    stones: bool = True
    stone_size: float = 0.045  # m, ballast grading 31.5/63 mm


@dataclass(frozen=True)
class RailwayScene:
    """``scene.builder: railway``: tracks on an arc or a straight line, supports, catenary, scanner stations."""

    track: RailwayTrack = field(default_factory=RailwayTrack)
    supports: RailwaySupports = field(default_factory=RailwaySupports)
    catenary: RailwayCatenary = field(default_factory=RailwayCatenary)
    stations: RailwayStations = field(default_factory=RailwayStations)
    detail: RailwayDetail = field(default_factory=RailwayDetail)

    @property
    def place_sensor(self) -> bool:
        """True when the stations place the sensor (then sensor.position is not used, nor saved)."""
        return self.stations.count > 0 or bool(self.stations.chainages)


@dataclass(frozen=True)
class BlendScene:
    """``scene.builder: blend``: scan the user's own .blend file."""

    path: str = ""


@dataclass(frozen=True)
class Distribution:
    """A random quantity: ``normal`` (``mean``, ``std``; truncated to ``[min, max]`` by redrawing, a
    count rounded and clipped instead) or ``uniform`` on ``[min, max]`` (geometry/placement.py)."""

    kind: Literal["normal", "uniform"] = "normal"
    mean: float = 0.0
    std: float = 1.0
    min: float = 0.0
    max: float = 1.0


@dataclass(frozen=True)
class ParkingScene:
    """``scene.builder: parking``: one level of an underground car park (the parking paper, seed 000), in metres.

    A driveway along x with parking bays on both sides, a pillar between every ``pillar_every``
    bays on the bays' front line, walls, floor and ceiling slabs, a ramp to the next level in
    place of the last bays on the +y side (``ramp_length`` 0: none). The sensor rides a cleaning
    robot along the driveway centre: ``sensor_height`` above the floor (the paper's VLP-16:
    1.51 m), ``sensor_start`` from the driveway's start at frame 0, ``sensor_step`` further each
    frame, back to the start past the end. Cars per frame follow the paper's insertion rule
    (geometry/placement.py): ``cars`` of them (N(5, 4) clipped at 0), each at a distance from the
    sensor drawn from ``car_distance`` (the paper: N(10, 20) m up to 20 m), height from
    ``car_height`` (U(1.55, 1.70) m), a random yaw, turned ``rotation_step_deg`` about the sensor up
    to ``rotations`` times; ``max_consecutive_failures`` objects in a row that fit nowhere end it.
    A car closer than ``near_rejection_distance`` is refused outright with
    ``near_rejection_probability`` (the paper's refinement: 10 % under 5 m). A car must keep
    ``car_clearance`` from pillars, ramp and other cars and show at least ``min_visible_fraction``
    of its sensor-facing side, without hiding more than that of any car placed before it.
    ``placement: bays`` snaps each candidate into the nearest free bay instead of placing it freely.
    """

    length: float = 60.0
    driveway_width: float = 6.5
    bay_width: float = 2.5
    bay_depth: float = 5.0
    ceiling_height: float = 2.6
    slab_thickness: float = 0.3
    wall_thickness: float = 0.3
    pillar_size: float = 0.6
    pillar_every: int = 3
    ramp_length: float = 16.0
    place_sensor: bool = True
    sensor_height: float = 1.51
    sensor_start: float = 4.0
    sensor_step: float = 2.0
    cars: Distribution = field(default_factory=lambda: Distribution("normal", 5.0, 4.0, 0.0, 40.0))
    car_distance: Distribution = field(default_factory=lambda: Distribution("normal", 10.0, 20.0, 2.5, 20.0))
    car_height: Distribution = field(default_factory=lambda: Distribution("uniform", 1.625, 0.0, 1.55, 1.70))
    near_rejection_distance: float = 5.0
    near_rejection_probability: float = 0.1
    placement: Literal["free", "bays"] = "free"
    rotation_step_deg: float = 10.0
    rotations: int = 36
    max_consecutive_failures: int = 10
    min_visible_fraction: float = 0.3
    car_clearance: float = 0.3


@dataclass(frozen=True)
class IndustrialHallScene:
    """``scene.builder: industrial_hall``: a factory hall watched from above (the human-robot paper, seed 002), in metres.

    Floor, walls and ceiling; ``desk_rows`` x ``desks_per_row`` desks (``desk_size`` length x depth,
    ``desk_height`` high: the paper finds seats at about 0.7 m) west of the centre, ``shelves``
    shelf racks (``shelf_size`` length x depth x height, ``shelf_levels`` boards) along the +y wall.
    The sensor hangs at ``sensor_height`` above the hall's centre (``place_sensor``). Per frame,
    within ``area_radius`` of the point below it (0: anywhere; the default mirror sensor sees a
    cone of 44.5 degrees around the nadir, a floor disc of 4.4 m radius from 4.5 m):
    ``robots`` six-axis arms (assets_manifest/robot_arm.yaml, or ``robot_model``) on the floor with
    random joint angles within their limits and no self-collision, then ``people`` persons of
    heights drawn from ``person_height``, in poses drawn with ``poses`` weights (standing, walking,
    sitting on a desk edge, crouching), on walkable floor or desk tops, ``person_clearance`` apart
    from each other, the robots and the furniture. ``assets``: a manifest of external person
    meshes (empty: assets_manifest/assets.yaml); the procedural people are used when it lists none.
    """

    length: float = 16.0
    width: float = 12.0
    height: float = 5.0
    wall_thickness: float = 0.3
    desk_rows: int = 2
    desks_per_row: int = 3
    desk_size: tuple[float, float] = (1.6, 0.8)
    desk_height: float = 0.72
    shelves: int = 3
    shelf_size: tuple[float, float, float] = (2.0, 0.6, 2.2)
    shelf_levels: int = 4
    place_sensor: bool = True
    sensor_height: float = 4.5
    area_radius: float = 4.5  # people and robots stand within this of the point below the sensor (0: anywhere)
    robots: int = 1
    robot_model: str = ""
    people: Distribution = field(default_factory=lambda: Distribution("normal", 4.4, 2.0, 0.0, 12.0))
    person_height: Distribution = field(default_factory=lambda: Distribution("normal", 1.72, 0.09, 1.50, 1.98))
    poses: dict = field(default_factory=lambda: {"standing": 0.35, "walking": 0.35, "sitting": 0.15, "crouching": 0.15})
    person_clearance: float = 0.05
    placement_tries: int = 60
    assets: str = ""


BUILDERS = {"railway": RailwayScene, "primitives": PrimitivesScene, "blend": BlendScene, "parking": ParkingScene, "industrial_hall": IndustrialHallScene}
# What a builder brings along when the config leaves it out: the sensor of its paper (used when
# `sensor` names no preset; fields given refine it) and its box labels.
BUILDER_SENSORS = {
    "parking": {"preset": "vlp16", "rotation_hz": 20.0},  # 0.4 deg, 16 channels, +-15 deg: the paper's table 1
    "industrial_hall": {"preset": "os1_128", "columns": 2048, "reflector": {"enabled": True}},  # 128 x 2048 through 8 mirrors
}
BOX_BUILDERS = ("parking", "industrial_hall")


@dataclass(frozen=True)
class SceneConfig:
    builder: str = "railway"
    params: RailwayScene | PrimitivesScene | BlendScene | ParkingScene | IndustrialHallScene = field(default_factory=RailwayScene)


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

    model: Literal["constant", "range", "table"] = "constant"
    sigma: float = 0.0  # m, Gaussian along the beam (`range`: at zero range)
    sigma_per_metre: float = 0.0  # m of sigma per m of range (`range`)
    model_file: str = ""  # a file of `python -m bpy_pipeline fit`: `range` and `table` take their parameters from it
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
    model: Literal["none", "uniform", "carla", "threshold", "table"] = "none"
    probability: float = 0.0  # for `uniform`
    carla: CarlaDrop = field(default_factory=CarlaDrop)
    threshold: ThresholdDrop = field(default_factory=ThresholdDrop)
    model_file: str = ""  # a file of `python -m bpy_pipeline fit`: `uniform`, `threshold` and `table` take their parameters from it


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


FORMATS = ("ply", "semantickitti", "las", "npy", "range_image")


@dataclass(frozen=True)
class BoxesConfig:
    """``output.boxes``: 3D box labels per frame (io/boxes.py), in the frame of the points.

    ``formats``: ``kitti`` and/or ``openpcdet``; ``auto`` is both for the parking and
    industrial_hall builders and none otherwise. Boxes of ``classes`` with fewer labeled points
    than ``min_points[class]`` (else ``min_points_default``) are dropped (the sparse-camera
    thesis: 12 for cars, 6 for the rest). ``occlusion_levels`` (t0, t1, t2): visible / unoccluded
    point fraction from which a box is occlusion level 0, 1, 2 (below t2: 3). ``names`` maps a
    class to its label-file type (default: its words capitalised and joined, robot arm -> RobotArm).
    """

    formats: list[Literal["kitti", "openpcdet"]] | Literal["auto"] = "auto"
    classes: list[str] = field(default_factory=lambda: ["car", "person", "robot arm"])
    names: dict = field(default_factory=dict)
    min_points: dict = field(default_factory=lambda: {"car": 12})
    min_points_default: int = 6
    occlusion_levels: tuple[float, float, float] = (0.8, 0.4, 0.1)


@dataclass(frozen=True)
class OutputConfig:
    formats: list[Literal["ply", "semantickitti", "las", "npy", "range_image"]] = field(default_factory=lambda: ["ply", "semantickitti"])
    frame: Literal["sensor", "world"] = "sensor"
    preview: bool = True
    sequence: int = 0  # SemanticKITTI sequence number (sequences/SS/)
    boxes: BoxesConfig = field(default_factory=BoxesConfig)


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


def _stations_or_sensor(scene: SceneConfig, raw_scene, sensor_data: dict) -> SceneConfig:
    """A sensor.position or trajectory given explicitly replaces the railway's default stations;
    stations configured explicitly as well are an error (one of them places the sensor)."""
    if not any(sensor_data.get(k) is not None for k in ("position", "trajectory")):
        return scene
    given = sensor_data.get("trajectory") is not None and "trajectory" or "position"
    stations = (raw_scene or {}).get("stations") if isinstance(raw_scene, dict) else None
    if isinstance(stations, dict) and (stations.get("count", 0) or stations.get("chainages")):
        raise InputError(f"sensor.{given}: scene.stations place the scanner of this railway; give one of them (scene.stations.count: 0 to use sensor.{given})")
    params = dataclasses.replace(scene.params, stations=dataclasses.replace(scene.params.stations, count=0, chainages=[]))
    return SceneConfig(scene.builder, params)


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
        from .geometry.railway_layout import check_railway

        check_railway(params, "scene")
    elif isinstance(params, (ParkingScene, IndustrialHallScene)):
        _check_indoor_scene(params)
    return SceneConfig(builder, params)


def _check_distribution(d: Distribution, where: str, low: float | None = None, high: float | None = None) -> None:
    if d.min > d.max:
        raise InputError(f"{where}.min: must not exceed max ({d.max}), got {d.min}")
    _check_positive(d.std, f"{where}.std", allow_zero=True)
    if low is not None and d.min < low:
        raise InputError(f"{where}.min: must be >= {low}, got {d.min}")
    if high is not None and d.max > high:
        raise InputError(f"{where}.max: must be <= {high}, got {d.max}")


def _check_indoor_scene(params) -> None:
    """Sizes positive, counts and probabilities in range, for the parking and industrial_hall builders."""
    may_be_zero = {"ramp_length", "sensor_start", "sensor_step", "near_rejection_distance", "car_clearance", "person_clearance", "min_visible_fraction", "near_rejection_probability", "robots", "shelves", "max_consecutive_failures", "desk_rows", "desks_per_row", "area_radius"}
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if isinstance(value, bool) or not isinstance(value, (int, float, tuple)):
            continue
        for v in value if isinstance(value, tuple) else (value,):
            _check_positive(v, f"scene.{f.name}", allow_zero=f.name in may_be_zero)
    if isinstance(params, ParkingScene):
        for key in ("near_rejection_probability", "min_visible_fraction"):
            if getattr(params, key) > 1:
                raise InputError(f"scene.{key}: must lie in 0..1, got {getattr(params, key)}")
        _check_distribution(params.cars, "scene.cars", low=0.0)
        _check_distribution(params.car_distance, "scene.car_distance", low=0.0)
        _check_distribution(params.car_height, "scene.car_height", low=0.5, high=4.0)
        if params.ramp_length > params.length - 8.0:
            raise InputError(f"scene.ramp_length: must leave at least 8 m of the level's length ({params.length} m) for the driveway, got {params.ramp_length}")
        if params.sensor_height >= params.ceiling_height:
            raise InputError(f"scene.sensor_height: must be below the ceiling ({params.ceiling_height} m), got {params.sensor_height}")
    else:
        _check_distribution(params.people, "scene.people", low=0.0)
        _check_distribution(params.person_height, "scene.person_height", low=0.5, high=2.5)
        from .geometry.human import POSES

        if not params.poses or any(k not in POSES for k in params.poses):
            raise InputError(f"scene.poses: expected weights for some of {', '.join(POSES)}, got {params.poses!r}")
        if any(isinstance(w, bool) or not isinstance(w, (int, float)) or w < 0 for w in params.poses.values()) or sum(params.poses.values()) <= 0:
            raise InputError(f"scene.poses: weights must be numbers >= 0, not all zero, got {params.poses!r}")
        if params.sensor_height >= params.height:
            raise InputError(f"scene.sensor_height: must be below the ceiling ({params.height} m), got {params.sensor_height}")


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
    # fitted models: the file must hold the model asked of it, and replaces its inline parameters
    fitted = {
        "drop": (drop, {"uniform": ("uniform", drop.probability != DropConfig.probability, "probability"),
                        "threshold": ("threshold", drop.threshold != ThresholdDrop(), "threshold"),
                        "table": ("drop_table", False, "")}),
        "noise": (noise, {"range": ("noise_range", (noise.sigma, noise.sigma_per_metre) != (0.0, 0.0), "sigma / sigma_per_metre"),
                          "table": ("noise_table", False, "")}),
    }
    for name, (section, uses) in fitted.items():
        where = f"effects.{name}.model_file"
        if section.model == "table" and not section.model_file:
            raise InputError(f"{where}: the table {name} model needs a model file (python -m bpy_pipeline fit ... --out FILE.yaml)")
        if not section.model_file or section.model not in uses:
            continue
        attr, inline, keys = uses[section.model]
        if inline:
            raise InputError(f"effects.{name}.{keys.split()[0]}: give either inline parameters ({keys}) or a model_file for the {section.model} model, not both")
        models = read_model_file(section.model_file, where)
        if getattr(models, attr) is None:
            raise InputError(f"{where}: {section.model_file} holds no {section.model} {name} model")


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


def config_from_dict(data) -> Config:
    """Validate a plain config mapping (as read from YAML) into a :class:`Config`."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"config: expected a mapping at the top level, got {type(data).__name__}")
    data = dict(data)
    raw_scene = data.get("scene")
    scene = _scene_from_dict(data.pop("scene", None))
    sensor_data = dict(data.pop("sensor", None) or {})
    if isinstance(scene.params, RailwayScene):
        scene = _stations_or_sensor(scene, raw_scene, sensor_data)
    if "preset" not in sensor_data and scene.builder in BUILDER_SENSORS:  # the builder's own sensor, refined by the fields given
        defaults = BUILDER_SENSORS[scene.builder]
        sensor_data = {**defaults, **sensor_data, **({"reflector": {**defaults["reflector"], **(sensor_data.get("reflector") or {})}} if "reflector" in defaults else {})}
    if getattr(scene.params, "place_sensor", False):
        for key in ("position", "trajectory"):
            if sensor_data.get(key) is not None:
                raise InputError(f"sensor.{key}: the {scene.builder} scene places the sensor itself; set scene.place_sensor: false to use sensor.{key}")
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
    return _check_boxes(config)


def _check_boxes(config: Config) -> Config:
    """Resolve ``output.boxes.formats: auto`` and check the box classes and thresholds."""
    from .labels import load_class_table

    boxes = config.output.boxes
    if boxes.formats == "auto":
        boxes = dataclasses.replace(boxes, formats=["kitti", "openpcdet"] if config.scene.builder in BOX_BUILDERS else [])
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
    _check_positive(boxes.min_points_default, "output.boxes.min_points_default", allow_zero=True)
    t0, t1, t2 = boxes.occlusion_levels
    if not 1 >= t0 >= t1 >= t2 >= 0:
        raise InputError(f"output.boxes.occlusion_levels: expected three fractions 1 >= t0 >= t1 >= t2 >= 0, got {list(boxes.occlusion_levels)}")
    names = {table.names[table.id_of(k)]: v for k, v in boxes.names.items()}
    min_points = {table.names[table.id_of(k)]: v for k, v in boxes.min_points.items()}
    boxes = dataclasses.replace(boxes, classes=classes, names=names, min_points=min_points)
    return dataclasses.replace(config, output=dataclasses.replace(config.output, boxes=boxes))


def config_to_dict(config: Config) -> dict:
    """The resolved config as plain YAML-ready data; ``config_from_dict`` of it gives ``config`` back."""
    out = to_plain(config)
    out["scene"] = {"builder": config.scene.builder, **out["scene"]["params"]}
    sensor = out["sensor"]
    if config.sensor.trajectory is not None or getattr(config.scene.params, "place_sensor", False):
        del sensor["position"]  # a trajectory, or the scene, places the sensor
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
