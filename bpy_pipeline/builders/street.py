"""``scene.builder: street``: an urban intersection with road users placed along its lanes, sidewalks and crossings."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import InputError
from .base import Builder, BuildContext, BuildResult, Distribution, check_distribution, check_sizes, register_builder


@dataclass(frozen=True)
class StreetScene:
    """``scene.builder: street``: two roads crossing (geometry/street.py has the layout and the rules), in metres.

    Static scene (drawn once from ``layout_seed``, the same in every frame): ``lanes_per_direction``
    drive lanes of ``lane_width`` each way, a ``parking_width`` strip by each kerb (0: none), kerbs
    ``kerb_width`` x ``kerb_height``, sidewalks ``sidewalk_width`` wide, zebra crossings
    ``crossing_width`` wide ``crossing_offset`` from the intersection, four traffic lights, ``signs``
    traffic signs, and buildings (``building_width``, ``building_height`` drawn uniformly,
    ``building_depth`` deep) along the sidewalks; each road reaches ``arm_length`` from the centre.

    Road users, drawn every frame from the frame's generator: ``vehicles`` moving along the drive
    lanes (mix of car, van, truck, bus by ``vehicle_mix``), following the last vehicle of their lane
    with probability ``platoon_probability`` at a gap from ``platoon_gap``; ``parked`` cars and vans
    in the parking strips; ``bicycles`` and ``motorcycles`` with riders near the right edge of the
    rightmost lanes; ``pedestrians`` on the sidewalks or, a share ``crossing_share`` of them, on the
    crossings. Footprints keep ``clearance`` from each other and from poles. With ``fov_aware``, a
    candidate is kept only if one sensor of the run sees at least ``min_in_view`` of its box's
    sample points (within its field of view and range), so a narrow flash camera sees what is placed.
    """

    arm_length: float = 40.0
    lanes_per_direction: int = 1
    lane_width: float = 3.5
    parking_width: float = 2.2
    kerb_width: float = 0.15
    kerb_height: float = 0.15
    sidewalk_width: float = 3.5
    crossing_width: float = 4.0
    crossing_offset: float = 1.0
    signs: int = 4
    building_depth: float = 10.0
    building_width: tuple[float, float] = (8.0, 16.0)
    building_height: tuple[float, float] = (6.0, 20.0)
    layout_seed: int = 0
    vehicles: Distribution = field(default_factory=lambda: Distribution("normal", 8.0, 3.0, 0.0, 40.0))
    vehicle_mix: dict = field(default_factory=lambda: {"car": 0.7, "van": 0.15, "truck": 0.08, "bus": 0.07})
    platoon_probability: float = 0.5
    platoon_gap: Distribution = field(default_factory=lambda: Distribution("uniform", 7.0, 0.0, 3.0, 12.0))
    parked: Distribution = field(default_factory=lambda: Distribution("normal", 6.0, 3.0, 0.0, 40.0))
    bicycles: Distribution = field(default_factory=lambda: Distribution("normal", 2.0, 1.5, 0.0, 20.0))
    motorcycles: Distribution = field(default_factory=lambda: Distribution("normal", 1.0, 1.0, 0.0, 20.0))
    pedestrians: Distribution = field(default_factory=lambda: Distribution("normal", 8.0, 4.0, 0.0, 60.0))
    crossing_share: float = 0.3
    clearance: float = 0.5
    fov_aware: bool = True
    min_in_view: float = 0.3


MAY_BE_ZERO = {"parking_width", "signs", "layout_seed", "crossing_offset", "platoon_probability", "crossing_share", "clearance", "min_in_view"}


def check(params: StreetScene, where: str) -> None:
    check_sizes(params, where, MAY_BE_ZERO)
    for key in ("platoon_probability", "crossing_share", "min_in_view"):
        if getattr(params, key) > 1:
            raise InputError(f"{where}.{key}: must lie in 0..1, got {getattr(params, key)}")
    for key in ("building_width", "building_height"):
        lo, hi = getattr(params, key)
        if lo > hi:
            raise InputError(f"{where}.{key}: expected [min, max] with min <= max, got {[lo, hi]}")
    half_road = params.lanes_per_direction * params.lane_width + params.parking_width
    reach = half_road + params.kerb_width + params.crossing_offset + params.crossing_width + 10.0
    if params.arm_length < reach:
        raise InputError(f"{where}.arm_length: must be at least {reach:.1f} m (the road's half width, kerb, crossing and 10 m of lane), got {params.arm_length}")
    from ..geometry.street import VEHICLES

    unknown = [k for k in params.vehicle_mix if k not in VEHICLES]
    if unknown or not params.vehicle_mix or any(not isinstance(v, (int, float)) or v < 0 for v in params.vehicle_mix.values()) or sum(params.vehicle_mix.values()) <= 0:
        raise InputError(f"{where}.vehicle_mix: expected shares >= 0 (not all 0) of {', '.join(VEHICLES)}, got {params.vehicle_mix}")
    for key in ("vehicles", "parked", "bicycles", "motorcycles", "pedestrians", "platoon_gap"):
        check_distribution(getattr(params, key), f"{where}.{key}", low=0.0)


def build(params: StreetScene, context: BuildContext) -> BuildResult:
    """The static intersection once per run, then this frame's road users."""
    from ..scenes.street import Intersection

    return context.kept("street", params, lambda: Intersection(params)).populate(context.rng, context.view)


# The sparse-camera thesis: three flash cameras on a 2 m post at a corner of the intersection,
# looking across it (the platform's yaw 45 deg points the middle camera at the centre).
register_builder("street", Builder(StreetScene, build, check, sensor={"rig": "flash_post_240", "position": [-7.6, -7.6, 0.15], "rotation_deg": [0.0, 0.0, 45.0]}, boxes=True))
