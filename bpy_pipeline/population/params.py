"""``scene.population``: people, robot arms and cars placed into any built scene, re-drawn every frame.

The section works on top of every builder (``blend``: the user's own file; the procedural ones)::

    scene:
      builder: blend
      path: hall.blend
      population:
        person: {count: {min: 1, max: 5}}          # a number, or a distribution ({min, max}: uniform integers)
        robot_arm: {count: 1, positions: [[0, 0, 90]]}   # [x, y, yaw_deg] bases; none: anywhere on the floor
        car: {count: 2, assets: my_cars}           # a set of assets_manifest/assets.yaml (none: procedural)
        placement: {keep_out: 0.3}

Each kind is a registry entry (:data:`KINDS`) owning its config dataclass and the function that draws
one candidate :class:`~bpy_pipeline.population.placer.Shape` from the frame's generator; the
Blender side (``population/scene.py``) owns the objects that show them. Where things may stand:
objects with the custom property ``lidar_walkable`` (people, arms and cars) and ``lidar_seat``
(seated people) when the scene has any, else the horizontal surfaces found in the static geometry
(``geometry/surfaces.py``: the floor, and seat-height tops for seated people).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..errors import InputError
from ..geometry.placement import sample_count
from ..registry import Registry
from ..schema import from_dict, to_plain, meta
from ..geometry.placement import Distribution, check_distribution


@dataclass(frozen=True)
class PersonPopulation:
    """``scene.population.person``: people, procedural (articulated mannequins) or from an asset set.

    count : people wanted per frame (a number or a distribution); height : m (drawn per person)
    poses : weights of standing, walking, sitting (on a seat edge), crouching (procedural people)
    assets : a set of ``assets_manifest/assets.yaml`` (kind person) instead of the procedural bodies
    reflectivity : clothing at 865-905 nm, uniform between (an assumption, as the hall's)
    """

    count: int | Distribution = 1
    height: Distribution = field(default_factory=lambda: Distribution("normal", 1.72, 0.09, 1.50, 1.98))
    poses: dict = field(default_factory=lambda: {"standing": 0.4, "walking": 0.4, "sitting": 0.1, "crouching": 0.1})
    assets: str = ""
    reflectivity: tuple[float, float] = field(default=(0.15, 0.6), metadata=meta("", 0, 1, help="[min, max] of the clothing's reflectivity"))


@dataclass(frozen=True)
class RobotArmPopulation:
    """``scene.population.robot_arm``: six-axis arms (``model``: a robot_arm.yaml capsule chain, default
    assets_manifest/robot_arm.yaml, or a URDF file whose links carry their own meshes)
    with joint angles drawn within their limits, no self-collision; ``positions``: ``[x, y, yaw_deg]`` bases to
    choose from (empty: anywhere on the floor). ``assets``: a set of robot meshes (kind robot) placed at
    their own size (``unit_scale``) instead."""

    count: int | Distribution = 1
    model: str = ""
    positions: list[tuple[float, float, float]] = field(default_factory=list)
    reflectivity: float = field(default=0.55, metadata=meta("", 0, 1))
    assets: str = ""


@dataclass(frozen=True)
class CarPopulation:
    """``scene.population.car``: cars, the procedural styles or an asset set, scaled to a height drawn from
    ``height`` (the parking paper: 1.55-1.70 m, uniform); a procedural car carries its licence plates and lamps
    (geometry/objects.py ``car_fittings``) unless ``fittings: false``."""

    count: int | Distribution = 1
    height: Distribution = field(default_factory=lambda: Distribution("uniform", 0.0, 0.0, 1.55, 1.70))
    assets: str = ""
    fittings: bool = True


@dataclass(frozen=True)
class PlacementRules:
    """``scene.population.placement``: how places are found and checked.

    keep_out : m between the footprints of placed objects; tries : spots tried per object
    cell : grid step of standing spots, m; seat_height : (min, max) m above the floor a seat top lies
    floor_band : m above the lowest surface a floor may lie; min_area : m^2, smallest surface used
    instance_base : the first instance id given to placed objects (kinds follow in blocks of 1000)
    manifest : the assets manifest the kinds' ``assets`` sets come from (empty: assets_manifest/assets.yaml)
    min_visible : the parking paper's visibility rule: an object is refused when less than this share of its
        sampled vertices is in the sensor's line of sight, or when it would leave one placed before below it
        (0: not checked; a moving sensor: its first position)
    walkable_classes, seat_classes : without ``lidar_walkable`` (``lidar_seat``) objects, the upward faces of
        objects of these classes are the floors (seats); none of them in the scene: surfaces are detected
    """

    keep_out: float = field(default=0.3, metadata=meta("m", low=0))
    tries: int = field(default=60, metadata=meta("", low=0, low_open=True))
    cell: float = field(default=0.1, metadata=meta("m", low=0, low_open=True))
    seat_height: tuple[float, float] = field(default=(0.35, 0.8), metadata=meta("m", low=0, help="[min, max]"))
    floor_band: float = field(default=0.3, metadata=meta("m", low=0))
    min_area: float = field(default=0.25, metadata=meta("m^2", low=0, low_open=True))
    instance_base: int = field(default=10000, metadata=meta("", low=0, low_open=True))
    manifest: str = ""
    min_visible: float = field(default=0.0, metadata=meta("", 0, 1))
    walkable_classes: list[str] = field(default_factory=lambda: ["floor", "ground", "road", "sidewalk", "platform"])
    seat_classes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class PopulationKind:
    """A kind of placed object.

    params : its config dataclass; class_name : its label (assets_manifest/labels.yaml)
    manifest_kind : the ``kind`` of its assets in assets.yaml
    draw : ``draw(params, models, rng) -> Shape | None``: one candidate from the frame's generator;
        ``models`` is what the Blender side loaded for it (asset meshes, the arm's model)
    check : ``check(params, where)``
    """

    params: type
    class_name: str
    manifest_kind: str
    draw: Callable[[Any, Any, np.random.Generator], Any]
    check: Callable[[Any, str], None]


KINDS: Registry[PopulationKind] = Registry("population kind", "scene.population")


def _check_common(params, where: str) -> None:
    count = params.count
    if isinstance(count, int):
        if count < 0:
            raise InputError(f"{where}.count: must be >= 0, got {count}")
    else:
        check_distribution(count, f"{where}.count", low=0.0, high=200.0)


def _check_person(params: PersonPopulation, where: str) -> None:
    from ..geometry.human import POSES

    _check_common(params, where)
    check_distribution(params.height, f"{where}.height", low=0.3, high=2.5)
    if not params.poses or any(k not in POSES for k in params.poses):
        raise InputError(f"{where}.poses: expected weights for some of {', '.join(POSES)}, got {params.poses!r}")
    if any(isinstance(w, bool) or not isinstance(w, (int, float)) or w < 0 for w in params.poses.values()) or sum(params.poses.values()) <= 0:
        raise InputError(f"{where}.poses: weights must be numbers >= 0, not all zero, got {params.poses!r}")
    lo, hi = params.reflectivity
    if lo > hi:
        raise InputError(f"{where}.reflectivity: expected [min, max] with min <= max, got {list(params.reflectivity)}")


def _check_arm(params: RobotArmPopulation, where: str) -> None:
    _check_common(params, where)


def _check_car(params: CarPopulation, where: str) -> None:
    _check_common(params, where)
    check_distribution(params.height, f"{where}.height", low=0.2, high=5.0)


def _draw_person(params: PersonPopulation, models, rng: np.random.Generator):
    """A procedural person in a pose drawn by the weights, or an asset person (``models``: asset models)."""
    from ..geometry import human
    from ..geometry.placement import sample
    from .placer import mesh_shape, person_shape

    height = float(sample(params.height, rng))
    if models:
        k = int(rng.integers(len(models)))
        vertices, triangles, detail = models[k].shape(rng)
        return mesh_shape(vertices, triangles, height, {"asset": k, "height": height, **detail}, support_fraction=0.3)
    kinds = list(params.poses)
    weights = np.array([params.poses[k] for k in kinds], float)
    pose = kinds[rng.choice(len(kinds), p=weights / weights.sum())]
    build = str(rng.choice(list(human.BUILDS)))
    angles = human.sample_pose(pose, rng)
    shape = person_shape(angles, height, human.BUILDS[build], pose)
    shape.detail["build_name"] = build
    return shape


def _draw_arm(params: RobotArmPopulation, models, rng: np.random.Generator):
    from ..geometry import kinematics
    from .placer import arm_shape, mesh_shape

    if isinstance(models, list):  # robot assets at their own size
        k = int(rng.integers(len(models)))
        vertices, triangles, detail = models[k].shape(rng)
        return mesh_shape(vertices, triangles, models[k].file_height * models[k].unit_scale, {"asset": k, **detail})
    from ..geometry.urdf import MeshedArm

    if isinstance(models, MeshedArm):  # a URDF arm: its own link meshes
        q = kinematics.random_configuration(models.model, rng, np.eye(4), floor_z=0.0)
        return arm_shape(models.model, q, models.posed(q))
    q = kinematics.random_configuration(models, rng, np.eye(4), floor_z=0.0)  # models: the arm's ArmModel
    return arm_shape(models, q)


def _draw_car(params: CarPopulation, models, rng: np.random.Generator):
    """A car of a procedural style (length and width +-3 % about the style's proportions) or an asset car, at a drawn height."""
    from ..geometry.objects import COLOURS, STYLES, car_meshes, style_size
    from ..geometry.placement import sample
    from .placer import Shape, box_support, mesh_shape
    from ..geometry.primitives import merge

    height = float(sample(params.height, rng))
    if models:
        k = int(rng.integers(len(models)))
        vertices, triangles, detail = models[k].shape(rng)
        return mesh_shape(vertices, triangles, height, {"asset": k, "height": height, **detail})
    style = int(rng.integers(len(STYLES)))
    size = style_size(STYLES[style], height) * [rng.uniform(0.97, 1.03), rng.uniform(0.97, 1.03), 1.0]
    shares = np.array([c[2] for c in COLOURS])
    colour = int(rng.choice(len(COLOURS), p=shares / shares.sum()))
    scale = size / style_size(STYLES[style])
    vertices, triangles = merge(list(car_meshes(STYLES[style], params.fittings).values()))
    vertices = vertices * scale
    return Shape(vertices, triangles, box_support(vertices, 0.7), {"style": style, "size": size, "colour": colour, "scale": scale})


KINDS.register("person", PopulationKind(PersonPopulation, "person", "person", _draw_person, _check_person))
KINDS.register("robot_arm", PopulationKind(RobotArmPopulation, "robot arm", "robot", _draw_arm, _check_arm))
KINDS.register("car", PopulationKind(CarPopulation, "car", "car", _draw_car, _check_car))


@dataclass(frozen=True)
class Population:
    """``scene.population``: ``kinds`` ((name, params), ...) in the order given, and the placement rules."""

    kinds: tuple = field(default=(), metadata={"inline": True})  # (name, params) pairs: their keys are the section's (scene.population.person)
    placement: PlacementRules = field(default_factory=PlacementRules)


def population_from_dict(data, where: str = "scene.population") -> Population | None:
    """The validated section (``None`` when absent); ``InputError`` naming the key."""
    if data is None:
        return None
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a mapping of kinds ({', '.join(KINDS)}) and placement, got {data!r}")
    kinds = []
    placement = PlacementRules()
    for key, value in data.items():
        if key == "placement":
            placement = from_dict(PlacementRules, value, f"{where}.placement")
            continue
        if key not in KINDS:
            raise InputError(f"{where}.{key}: unknown key; allowed: {', '.join(KINDS)}, placement")
        kind = KINDS.get(key)
        value = dict(value) if isinstance(value, dict) else value
        if isinstance(value, dict) and isinstance(value.get("count"), dict) and "kind" not in value["count"]:
            value["count"] = {"kind": "uniform", **value["count"]}  # {min, max}: uniform integers
        params = from_dict(kind.params, value, f"{where}.{key}")
        kind.check(params, f"{where}.{key}")
        kinds.append((key, params))
    p = placement
    from ..labels import load_class_table

    table = load_class_table()
    for key in ("walkable_classes", "seat_classes"):
        for i, name in enumerate(getattr(p, key)):
            table.id_of(name, f"{where}.placement.{key}[{i}]")
    if p.seat_height[0] > p.seat_height[1]:
        raise InputError(f"{where}.placement.seat_height: expected [min, max] with min <= max, got {list(p.seat_height)}")
    from ..assets import asset_set

    for key, params in kinds:  # the asset sets named exist (checked before any Blender work)
        if getattr(params, "assets", ""):
            asset_set(params.assets, KINDS.get(key).manifest_kind, f"{where}.{key}.assets", p.manifest or None)
    return Population(tuple(kinds), placement)


def population_to_dict(population: Population | None) -> dict | None:
    """The section as plain data (``population_from_dict`` of it gives it back)."""
    if population is None:
        return None
    out = {name: to_plain(params) for name, params in population.kinds}
    out["placement"] = to_plain(population.placement)
    return out


def count_of(params, rng: np.random.Generator) -> int:
    """How many of a kind a frame wants: the fixed count, or a draw of its distribution."""
    return params.count if isinstance(params.count, int) else sample_count(params.count, rng)


__all__ = ["KINDS", "Population", "PopulationKind", "population_from_dict", "population_to_dict"]
