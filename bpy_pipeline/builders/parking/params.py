"""``scene.builder: parking``: one level of an underground car park with cars placed by the parking paper's rule."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ...schema import meta
from ...errors import InputError
from ...geometry.clearance import CLEARANCE
from ..base import Builder, BuildContext, BuildResult, refuse_sensor_placement, register_builder
from ...geometry.placement import Distribution, check_distribution


@dataclass(frozen=True)
class ParkingScene:
    """``scene.builder: parking``: one level of an underground car park (the parking paper, seed 000), in metres.

    A driveway along x with parking bays on both sides, a pillar between every ``pillar_every``
    bays on the bays' front line, walls, floor and ceiling slabs, a ramp to the next level in
    place of the last bays on the +y side (``ramp_length`` 0: none). Each long wall has
    ``wall_openings`` doorways, ``opening_width`` by ``opening_height``, evenly spaced along it
    (0: none; :func:`.layout.level_layout`). The sensor rides a cleaning
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
    ``car_fittings``: each car's licence plates and lamps (geometry/objects.py ``car_fittings``), tagged
    ``retroreflector`` and ``glossy_paint``; ``false`` leaves them out.
    """

    length: float = field(default=60.0, metadata=meta("m", low=1, high=10000))
    driveway_width: float = field(default=6.5, metadata=meta("m", low=0, high=100, low_open=True))
    bay_width: float = field(default=2.5, metadata=meta("m", low=0.1, high=100))
    bay_depth: float = field(default=5.0, metadata=meta("m", low=0, high=100, low_open=True))
    ceiling_height: float = field(default=2.6, metadata=meta("m", low=0.1, high=100))
    slab_thickness: float = field(default=0.3, metadata=meta("m", low=0, high=10, low_open=True))
    wall_thickness: float = field(default=0.3, metadata=meta("m", low=0, high=10, low_open=True))
    pillar_size: float = field(default=0.6, metadata=meta("m", low=0, high=10, low_open=True))
    pillar_every: int = field(default=3, metadata=meta("", low=1, high=1000))
    ramp_length: float = field(default=16.0, metadata=meta("m", low=0, high=1000))
    wall_openings: int = field(default=0, metadata=meta("", low=0, high=1000))
    opening_width: float = field(default=1.2, metadata=meta("m", low=0, high=100, low_open=True))
    opening_height: float = field(default=2.1, metadata=meta("m", low=0, high=100, low_open=True))
    place_sensor: bool = True
    sensor_height: float = field(default=1.51, metadata=meta("m", low=0, low_open=True))
    sensor_start: float = field(default=4.0, metadata=meta("m", low=0))
    sensor_step: float = field(default=2.0, metadata=meta("m", low=0))
    cars: Distribution = field(default_factory=lambda: Distribution("normal", 5.0, 4.0, 0.0, 40.0))
    car_distance: Distribution = field(default_factory=lambda: Distribution("normal", 10.0, 20.0, 2.5, 20.0))
    car_height: Distribution = field(default_factory=lambda: Distribution("uniform", 1.625, 0.0, 1.55, 1.70))
    near_rejection_distance: float = field(default=5.0, metadata=meta("m", low=0))
    near_rejection_probability: float = field(default=0.1, metadata=meta("", 0, 1))
    placement: Literal["free", "bays"] = "free"
    rotation_step_deg: float = field(default=10.0, metadata=meta("deg", low=0, low_open=True))
    rotations: int = field(default=36, metadata=meta("", low=0, low_open=True))
    max_consecutive_failures: int = field(default=10, metadata=meta("", low=0))
    min_visible_fraction: float = field(default=0.3, metadata=meta("", 0, 1))
    car_clearance: float = field(default=0.3, metadata=meta("m", low=0))
    car_fittings: bool = True



def check(params: ParkingScene, where: str) -> None:
    """``InputError`` naming the key of a rule between the fields (each field's range is its metadata's, the schema's)."""
    check_distribution(params.cars, f"{where}.cars", low=0.0)
    check_distribution(params.car_distance, f"{where}.car_distance", low=0.0)
    check_distribution(params.car_height, f"{where}.car_height", low=0.5, high=4.0)
    if params.rotations * params.rotation_step_deg >= 360.0 + params.rotation_step_deg:  # a car's turns past one whole turn repeat its headings
        raise InputError(f"{where}.rotations: at most {math.ceil(360.0 / params.rotation_step_deg)} (one whole turn in steps of rotation_step_deg, "
                         f"{params.rotation_step_deg:g} deg), got {params.rotations}")
    if params.ramp_length > params.length - 8.0:
        raise InputError(f"{where}.ramp_length: must leave at least 8 m of the level's length ({params.length} m) for the driveway, got {params.ramp_length}")
    if params.opening_height >= params.ceiling_height:
        raise InputError(f"{where}.opening_height: must be below the ceiling ({params.ceiling_height} m), got {params.opening_height}")
    if params.wall_openings and params.opening_width >= params.length / (params.wall_openings + 1):
        raise InputError(
            f"{where}.opening_width: {params.wall_openings} doorways a wall leave no wall between them unless under "
            f"{params.length / (params.wall_openings + 1):.3f} m (length / (wall_openings + 1)), got {params.opening_width}"
        )
    if params.place_sensor and params.sensor_height > params.ceiling_height - CLEARANCE:
        raise InputError(
            f"{where}.sensor_height: must be below the ceiling ({params.ceiling_height} m) by at least {CLEARANCE} m (the sensor keeps clear of every solid), "
            f"got {params.sensor_height}"
        )
    if params.place_sensor and params.driveway_width < 2 * CLEARANCE:
        raise InputError(
            f"{where}.driveway_width: at least {2 * CLEARANCE:g} m (the sensor robot drives along its middle, {CLEARANCE} m clear of the pillars), got "
            f"{params.driveway_width}"
        )


def station(params: ParkingScene, frame: int) -> np.ndarray | None:
    """The cleaning robot's pose along the driveway in frame ``frame`` (``place_sensor``)."""
    from ...geometry.indoor import parking_station

    return parking_station(params, frame) if params.place_sensor else None


def build(params: ParkingScene, context: BuildContext) -> BuildResult:
    """The static level once per run, then cars drawn and placed for this frame."""
    from .scene import ParkingGarage

    return context.kept("parking", params, lambda: ParkingGarage(params, check)).randomize(context.rng, context.view, context.sensor_poses)


# the paper's VLP-16 at 20 Hz: 0.4 deg, 16 channels, +-15 deg (its table 1)
register_builder("parking", Builder(ParkingScene, build, check, station, sensor={"preset": "vlp16", "rotation_hz": 20.0}, boxes=True,
                                    release_sensor=refuse_sensor_placement("parking")))
