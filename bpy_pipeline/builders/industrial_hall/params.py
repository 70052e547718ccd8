"""``scene.builder: industrial_hall``: a factory hall with desks, shelves, people and a robot arm, watched from above."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...schema import meta
from ...errors import InputError
from ...geometry.transforms import KITTI_SENSOR_HEIGHT
from ..base import Builder, BuildContext, BuildResult, refuse_sensor_placement, register_builder
from ...geometry.placement import Distribution, check_distribution


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

    length: float = field(default=16.0, metadata=meta("m", low=0.1, high=10000))
    width: float = field(default=12.0, metadata=meta("m", low=0.1, high=10000))
    height: float = field(default=5.0, metadata=meta("m", low=0.1, high=1000))
    wall_thickness: float = field(default=0.3, metadata=meta("m", low=0, high=10, low_open=True))
    desk_rows: int = field(default=2, metadata=meta("", low=0))
    desks_per_row: int = field(default=3, metadata=meta("", low=0))
    desk_size: tuple[float, float] = field(default=(1.6, 0.8), metadata=meta("m", low=0, low_open=True))
    desk_height: float = field(default=0.72, metadata=meta("m", low=0, low_open=True))
    shelves: int = field(default=3, metadata=meta("", low=0))
    shelf_size: tuple[float, float, float] = field(default=(2.0, 0.6, 2.2), metadata=meta("m", low=0, low_open=True))
    shelf_levels: int = field(default=4, metadata=meta("", low=1, high=100))
    place_sensor: bool = True
    sensor_height: float = field(default=4.5, metadata=meta("m", low=0, low_open=True))
    area_radius: float = field(default=4.5, metadata=meta("m", low=0, help="people and robots stand within this of the point below the sensor (0: anywhere)"))
    robots: int = field(default=1, metadata=meta("", low=0))
    robot_model: str = ""
    people: Distribution = field(default_factory=lambda: Distribution("normal", 4.4, 2.0, 0.0, 12.0))
    person_height: Distribution = field(default_factory=lambda: Distribution("normal", 1.72, 0.09, 1.50, 1.98))
    poses: dict = field(default_factory=lambda: {"standing": 0.35, "walking": 0.35, "sitting": 0.15, "crouching": 0.15})
    person_clearance: float = field(default=0.05, metadata=meta("m", low=0))
    placement_tries: int = field(default=60, metadata=meta("", low=0, low_open=True))
    max_consecutive_failures: int = field(default=10, metadata=meta("", low=0, low_open=True,
                                                                    help="people in a row that fit nowhere end the frame's placement (with a warning)"))
    assets: str = ""



MAX_PEOPLE = 500  # per frame: far more than a hall of 16 x 12 m holds, and placement tries grow with it


def check(params: IndustrialHallScene, where: str) -> None:
    from ...geometry.human import POSES

    check_distribution(params.people, f"{where}.people", low=0.0, high=MAX_PEOPLE)
    check_distribution(params.person_height, f"{where}.person_height", low=0.5, high=2.5)
    if not params.poses or any(k not in POSES for k in params.poses):
        raise InputError(f"{where}.poses: expected weights for some of {', '.join(POSES)}, got {params.poses!r}")
    if any(isinstance(w, bool) or not isinstance(w, (int, float)) or w < 0 for w in params.poses.values()) or sum(params.poses.values()) <= 0:
        raise InputError(f"{where}.poses: weights must be numbers >= 0, not all zero, got {params.poses!r}")
    if params.sensor_height >= params.height:
        raise InputError(f"{where}.sensor_height: must be below the ceiling ({params.height} m), got {params.sensor_height}")
    check_furniture(params, where)


def check_furniture(params: IndustrialHallScene, where: str) -> None:
    """``InputError`` when the desks and shelves overlap or reach past the walls, or when the hanging sensor
    (``place_sensor``) comes within :data:`~bpy_pipeline.geometry.clearance.CLEARANCE` of the ceiling or a piece of furniture."""
    from ...geometry.clearance import CLEARANCE, SensorPoses
    from ...geometry.indoor import hall_layout, hall_station

    rows = f"{params.desk_rows} row(s) of {params.desks_per_row} desk(s) and {params.shelves} shelf rack(s)"
    misfit = InputError(f"{where}.desks_per_row: {rows} do not fit the hall's {params.length:g} x {params.width:g} m floor without overlapping or "
                        f"reaching past its walls; use fewer desks (desk_rows, desks_per_row) or shelves, smaller desk_size or shelf_size, or a larger hall")
    desks, shelves = params.desk_rows * params.desks_per_row, params.shelves
    footprints = desks * params.desk_size[0] * params.desk_size[1] + shelves * params.shelf_size[0] * params.shelf_size[1]
    if footprints > params.length * params.width:  # more than the floor holds side by side: refused before any piece is laid out
        raise misfit
    layout = hall_layout(params)
    boxes = [item.footprint for item in layout.furniture]
    for k, (low, high) in enumerate(boxes):
        if (low < layout.low - 1e-9).any() or (high > layout.high + 1e-9).any() or any((np.minimum(high, h) - np.maximum(low, l) > 1e-9).all() for l,
                                                                                       h in boxes[:k]):
            raise misfit
    if not params.place_sensor:
        return
    if params.sensor_height > params.height - CLEARANCE:
        raise InputError(f"{where}.sensor_height: must stay {CLEARANCE} m below the ceiling ({params.height} m), got {params.sensor_height}")
    sensor = SensorPoses(hall_station(params)[:3, 3])
    for item in layout.furniture:
        low, high = item.footprint
        top = max(c[2] + h[2] for c, h in item.parts)
        if not sensor.clear_of_box((low + high) / 2, (high - low) / 2, 0.0, 0.0, top):
            raise InputError(
                f"{where}.sensor_height: the sensor {params.sensor_height} m above the hall's centre comes within {CLEARANCE} m of {item.name} "
                f"({top:.2f} m high); hang it higher or move the furniture (desk_rows, desks_per_row, shelves)"
            )


def station(params: IndustrialHallScene, frame: int) -> np.ndarray | None:
    """The sensor hanging above the hall's centre (``place_sensor``)."""
    from ...geometry.indoor import hall_station

    return hall_station(params) if params.place_sensor else None


def build(params: IndustrialHallScene, context: BuildContext) -> BuildResult:
    """The static hall once per run, then robots and people drawn and posed for this frame."""
    from .scene import IndustrialHall

    return context.kept("industrial_hall", params, lambda: IndustrialHall(params)).randomize(context.rng, context.view, context.sensor_poses)


# the human-robot paper's sensor: an OS1-128 at 2048 columns through its own ring of 8 mirrors
SENSOR = {"preset": "os1_128", "columns": 2048, "reflector": {"enabled": True}}


def output_defaults(params: IndustrialHallScene) -> dict:
    """The KITTI layout's camera: level (KITTI's boxes turn about the camera's y axis), 1 m from the -x wall at KITTI's
    LiDAR height above the floor, looking along +x over the whole hall, 1242 x 750 px (KITTI's width, twice its height).
    At the sensor, hung ``sensor_height`` up, it would look over the people's heads. ``output.frame: kitti`` puts the
    points' origin above it."""
    x = -(float(params.length) / 2 - 1.0)
    return {"kitti": {"camera": {"position": [round(x, 4), 0.0, round(KITTI_SENSOR_HEIGHT - float(params.sensor_height), 4)], "resolution": [1242, 750]}}}


register_builder("industrial_hall",
                 Builder(IndustrialHallScene, build, check, station, sensor=SENSOR, boxes=True, release_sensor=refuse_sensor_placement("industrial_hall"),
                                            output=output_defaults))
