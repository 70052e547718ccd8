"""``scene.builder: street``: an urban street (an intersection, a T-junction or a straight street) with road users
placed along its lanes, sidewalks and crossings."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...schema import meta
from ...errors import InputError
from ..base import Builder, BuildContext, BuildResult, register_builder
from ...geometry.placement import Distribution, check_distribution


MAX_YARD_TREES = 100.0  # per 100 m^2: one tree a square metre (Distribute Points on Faces draws that many before thinning)


@dataclass(frozen=True)
class StreetScene:
    """``scene.builder: street``: a road along x, crossed by a road along y, met by one, or alone (builders/street/layout.py
    has the layout and the rules), in metres.

    Static scene (drawn once from ``layout_seed``, the same in every frame): the junction's kind by the shares
    ``junction_mix`` (``cross``: four arms; ``t_junction``: the road along x whole, the road
    along y on one side of it; ``straight``: the road along x alone, a residential street with one mid-block zebra
    crossing and no traffic lights; the road users' counts are for four arms, scaled to the lanes, parking strips and
    sidewalks the junction has, so there are as many per metre); ``lanes_per_direction``
    drive lanes of ``lane_width`` each way, a ``parking_width`` strip by each kerb (0: none), kerbs
    ``kerb_width`` x ``kerb_height``, sidewalks ``sidewalk_width`` wide, zebra crossings
    ``crossing_width`` wide ``crossing_offset`` from the junction, a traffic light at each corner it has, ``signs``
    traffic signs; each road reaches ``arm_length`` from the centre (100 m: a car-roof sensor's
    range). Beyond the sidewalks (builders/street/dressing.py): terrain rolling by
    ``terrain_relief`` (m) and rising by ``terrain_slope`` away from the road, on a ``terrain_step``
    (m) grid (``terrain: false`` leaves it out); plots ``building_width`` wide, each a building
    (``building_height``, ``building_depth`` deep) set back ``setback`` (m) behind a front yard,
    or, a share ``open_share``, open ground with trees and bushes ``plot_depth`` deep;
    ``yard_plants`` trees and bushes per 100 m^2 of yard, placed by the layout's generator, and
    ``yard_trees`` more trees per 100 m^2 (at most :data:`MAX_YARD_TREES`; 0: none) that the "Street
    Planting" Geometry Nodes group distributes over the yards, at least ``yard_tree_clearance`` (m)
    apart, ``yard_tree_height`` (m) tall; each plot's front a fence, hedge, low wall
    or nothing by ``boundary_mix``. On the sidewalks' kerb side: street trees ``tree_spacing``
    apart along a share ``street_trees`` of the arm sides, lamps every ``lamp_spacing`` m (0:
    none), ``furniture_per_100m`` bins, bicycle stands and bollards per side; with probability
    ``roadworks`` an arm side's parking strip holds cones and barriers.

    Road users, drawn every frame from the frame's generator: ``vehicles`` moving along the drive
    lanes (mix of car, van, truck, bus by ``vehicle_mix``), following the last vehicle of their lane
    with probability ``platoon_probability`` at a gap from ``platoon_gap``; ``parked`` cars and vans
    in the parking strips; ``bicycles`` and ``motorcycles`` with riders near the right edge of the
    rightmost lanes; ``pedestrians`` on the sidewalks or, a share ``crossing_share`` of them, on the
    crossings. Footprints keep ``clearance`` from each other and from poles. With ``fov_aware``, a
    candidate is kept only if one sensor of the run sees at least ``min_in_view`` of its box's
    sample points (within its field of view and range), so a narrow flash camera sees what is placed.

    ``ego_vehicle``: the sensor rides on the roof of a car in the right-hand lane of the road along
    x, ``ego_height`` (m) above the road (KITTI's HDL-64E: 1.73), heading +x; frame k places it
    ``k * ego_step`` metres further along, cycling over ``[-ego_span, ego_span]``, so consecutive
    frames see the street from different places. The ego car's footprint and ``ego_headway`` metres of its lane
    ahead of it are kept free of road users (15 m: about 1.4 s at 40 km/h, the time gap urban drivers keep; without
    it a car could stand a hand's width in front of the ego's bumper, which no recorded drive shows); its body is not
    built (recorded scans leave the ego vehicle out).

    ``car_fittings``: every vehicle's licence plates and lamps (geometry/vehicles.py ``vehicle_fittings``), tagged
    ``retroreflector`` and ``glossy_paint`` (applied with ``effects.materials.objects: true``); ``false`` leaves them out.
    """

    arm_length: float = field(default=100.0, metadata=meta("m", low=0, high=1000, low_open=True))
    junction_mix: dict = field(default_factory=lambda: {"cross": 1.0},
                               metadata=meta("", help="shares of the junction kinds drawn per layout: cross, t_junction, straight"))
    lanes_per_direction: int = field(default=1, metadata=meta("", low=1, high=16))
    lane_width: float = field(default=3.5, metadata=meta("m", low=0.5, high=10))
    parking_width: float = field(default=2.2, metadata=meta("m", low=0, high=10))
    kerb_width: float = field(default=0.15, metadata=meta("m", low=0.01, high=2))
    kerb_height: float = field(default=0.15, metadata=meta("m", low=0, high=1, low_open=True))
    sidewalk_width: float = field(default=3.5, metadata=meta("m", low=0.1, high=50))
    crossing_width: float = field(default=4.0, metadata=meta("m", low=0.8))  # a walking person, 0.4 m from either edge
    crossing_offset: float = field(default=1.0, metadata=meta("m", low=0))
    signs: int = field(default=4, metadata=meta("", low=0))
    building_depth: float = field(default=10.0, metadata=meta("m", low=0, low_open=True))
    building_width: tuple[float, float] = field(default=(8.0, 16.0), metadata=meta("m", low=0, low_open=True))
    building_height: tuple[float, float] = field(default=(6.0, 20.0), metadata=meta("m", low=0, low_open=True))
    setback: tuple[float, float] = field(default=(0.0, 8.0), metadata=meta("m", low=0))
    open_share: float = field(default=0.3, metadata=meta("", 0, 1))
    plot_depth: float = field(default=20.0, metadata=meta("m", low=0, low_open=True))
    boundary_mix: dict = field(default_factory=lambda: {"fence": 0.35, "hedge": 0.3, "wall": 0.15, "none": 0.2})
    street_trees: float = field(default=0.6, metadata=meta("", 0, 1))
    tree_spacing: tuple[float, float] = field(default=(8.0, 16.0), metadata=meta("m", low=0))
    yard_plants: float = field(default=1.5, metadata=meta("", low=0, high=100))
    yard_trees: float = field(default=0.0, metadata=meta("", 0, MAX_YARD_TREES, help="more trees per 100 m^2 of yard (0: none)"))
    yard_tree_clearance: float = field(default=4.0, metadata=meta("m", low=0.5, help="apart, at least a trunk's width"))
    yard_tree_height: tuple[float, float] = field(default=(4.0, 14.0), metadata=meta("m", low=2, help="[min, max]: their crowns clear 1.5 m"))
    lamp_spacing: float = field(default=28.0, metadata=meta("m", low=0))
    furniture_per_100m: float = field(default=3.0, metadata=meta("", low=0, high=100))
    roadworks: float = field(default=0.25, metadata=meta("", 0, 1))
    terrain: bool = True
    terrain_step: float = field(default=1.0, metadata=meta("m", low=0, low_open=True))
    terrain_relief: float = field(default=0.5, metadata=meta("m", low=0))
    terrain_slope: float = field(default=0.04, metadata=meta("", low=0))
    layout_seed: int = field(default=0, metadata=meta("", low=0, high=2**31 - 1))  # a Blender node seed: a 32-bit integer
    vehicles: Distribution = field(default_factory=lambda: Distribution("normal", 16.0, 5.0, 0.0, 60.0))
    vehicle_mix: dict = field(default_factory=lambda: {"car": 0.7, "van": 0.15, "truck": 0.08, "bus": 0.07})
    platoon_probability: float = field(default=0.5, metadata=meta("", 0, 1))
    platoon_gap: Distribution = field(default_factory=lambda: Distribution("uniform", 7.0, 0.0, 3.0, 12.0))
    parked: Distribution = field(default_factory=lambda: Distribution("normal", 20.0, 6.0, 0.0, 80.0))
    bicycles: Distribution = field(default_factory=lambda: Distribution("normal", 3.0, 2.0, 0.0, 20.0))
    motorcycles: Distribution = field(default_factory=lambda: Distribution("normal", 1.0, 1.0, 0.0, 20.0))
    pedestrians: Distribution = field(default_factory=lambda: Distribution("normal", 16.0, 6.0, 0.0, 80.0))
    crossing_share: float = field(default=0.3, metadata=meta("", 0, 1))
    clearance: float = field(default=0.5, metadata=meta("m", low=0))
    fov_aware: bool = True
    min_in_view: float = field(default=0.3, metadata=meta("", 0, 1))
    ego_vehicle: bool = False
    ego_height: float = field(default=1.73, metadata=meta("m", low=0, low_open=True))
    ego_span: float = field(default=60.0, metadata=meta("m", low=0))
    ego_step: float = field(default=7.3, metadata=meta("m", low=0, low_open=True))
    ego_headway: float = field(default=15.0,
                               metadata=meta("m", low=0, help="free lane ahead of the ego car's front: the gap a driver keeps to the vehicle ahead"))
    car_fittings: bool = True




def check(params: StreetScene, where: str) -> None:
    for key in ("building_width", "building_height", "setback", "tree_spacing", "yard_tree_height"):
        lo, hi = getattr(params, key)
        if lo > hi:
            raise InputError(f"{where}.{key}: expected [min, max] with min <= max, got {[lo, hi]}")
    half_road = params.lanes_per_direction * params.lane_width + params.parking_width
    reach = half_road + params.kerb_width + params.crossing_offset + params.crossing_width + 10.0
    if params.arm_length < reach:
        raise InputError(f"{where}.arm_length: must be at least {reach:.1f} m (the road's half width, kerb, crossing and 10 m of lane), "
                         f"got {params.arm_length}")
    from .layout import JUNCTIONS, VEHICLES
    from .dressing import BOUNDARIES

    _check_shares(params.junction_mix, tuple(JUNCTIONS), f"{where}.junction_mix")
    mix = params.boundary_mix
    if not mix or any(k not in BOUNDARIES for k in mix) or any(not isinstance(v, (int, float)) or v < 0 for v in mix.values()) or sum(mix.values()) <= 0:
        raise InputError(f"{where}.boundary_mix: expected shares >= 0 (not all 0) of {', '.join(BOUNDARIES)}, got {mix}")
    if params.tree_spacing[1] > 0 and params.tree_spacing[0] < 2.0:
        raise InputError(f"{where}.tree_spacing: street trees stand at least 2 m apart, got {list(params.tree_spacing)}")

    unknown = [k for k in params.vehicle_mix if k not in VEHICLES]
    if unknown or not params.vehicle_mix or any(not isinstance(v, (int, float)) or v < 0 for v in params.vehicle_mix.values()) \
            or sum(params.vehicle_mix.values()) <= 0:
        raise InputError(f"{where}.vehicle_mix: expected shares >= 0 (not all 0) of {', '.join(VEHICLES)}, got {params.vehicle_mix}")
    for key in ("vehicles", "parked", "bicycles", "motorcycles", "pedestrians", "platoon_gap"):
        check_distribution(getattr(params, key), f"{where}.{key}", low=0.0)


def _check_shares(mix, kinds, key: str) -> None:
    """``mix`` must map some of ``kinds`` to numbers >= 0, not all 0; else one line naming ``key``."""
    if not isinstance(mix, dict) or not mix or any(k not in kinds for k in mix) \
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0 for v in mix.values()) or sum(mix.values()) <= 0:
        raise InputError(f"{key}: expected shares >= 0 (not all 0) of {', '.join(kinds)}, got {mix}")


def ego_station(params: StreetScene, frame: int) -> np.ndarray | None:
    """The level frame ``(4, 4)`` of the ego car's roof sensor in frame ``frame``, or ``None`` without ``ego_vehicle``."""
    if not params.ego_vehicle:
        return None
    span = 2.0 * params.ego_span
    x = -params.ego_span + (frame * params.ego_step) % span if span > 0 else 0.0
    pose = np.eye(4)
    pose[:3, 3] = (x, -0.5 * params.lane_width, params.ego_height)
    return pose


def release_ego(params: StreetScene, raw_scene: dict, sensor_data: dict) -> StreetScene:
    """With ``ego_vehicle`` the scene places the sensor: a ``sensor.position`` or trajectory as well is an error."""
    if params.ego_vehicle:
        for key in ("position", "trajectory"):
            if sensor_data.get(key) is not None:
                raise InputError(f"sensor.{key}: scene.ego_vehicle places the sensor on the ego car's roof; "
                                 f"leave sensor.{key} out or set scene.ego_vehicle: false")
    return params


def build(params: StreetScene, context: BuildContext) -> BuildResult:
    """The static intersection once per run, then this frame's road users."""
    from .scene import Intersection

    intersection = context.kept("street", (params, context.sensor_poses), lambda: Intersection(params, context.sensor_poses))
    return intersection.populate(context.rng, context.view, context.in_blender)


# The sparse-camera thesis: three flash cameras on a 2 m post at a corner of the intersection,
# looking across it (the platform's yaw 45 deg points the middle camera at the centre).
register_builder("street", Builder(StreetScene, build, check, station=ego_station, release_sensor=release_ego,
                                   sensor={"rig": "flash_post_240", "position": [-7.6, -7.6, 0.15], "rotation_deg": [0.0, 0.0, 45.0]}, boxes=True))
