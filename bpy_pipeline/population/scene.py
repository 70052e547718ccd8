"""``scene.population`` in Blender (bpy): pools of people, robot arms and cars moved into a built scene per frame.

The scene's own geometry (what the builder built, or the user's .blend) is exported once with the
population hidden; its horizontal surfaces are found once (``geometry/surfaces.py``) and kept while
that geometry stays the same (a digest of its triangles). Each frame then draws the objects from
the frame's generator, places them with ``population/placer.py`` against the exported triangles,
and shows them: pool objects are moved, posed, relabelled, shown or hidden, never rebuilt, so frame
k after frame k - 1 is the same as frame k alone.

Each kind has a side here (:data:`SIDES`, keyed like :data:`~bpy_pipeline.population.params.KINDS`)
that loads what its draws need (the arm's model, asset meshes) and owns its pool of objects.
"""

from __future__ import annotations

import abc
import dataclasses
import hashlib

import bpy
import numpy as np
from mathutils import Matrix

from .params import KINDS, count_of
from ..geometry import human
from ..geometry.clearance import NO_POSES
from ..geometry.objects import COLOURS, STYLES, car_meshes, car_surfaces
from .placer import Placer, place_on_spots
from ..geometry.surfaces import find_surfaces, floor_and_seats
from ..blender.mesh_objects import mesh_data, scene_collection, tag
from ..blender.people import PersonRig

COLLECTION = "LiDAR Population"
KEY = "population"  # where the run's BuildContext.keep holds the pools


def _matrix(m: np.ndarray) -> Matrix:
    return Matrix(np.asarray(m, float).tolist())


class PartsSlot:
    """One placed object made of parts (``{part: (mesh, material, reflectivity)}``), the first part the parent."""

    def __init__(self, collection, name: str, parts: list[str]):
        self.objects = {}
        for k, part in enumerate(parts):
            obj = bpy.data.objects.new(name if k == 0 else f"{name}_{part}", bpy.data.meshes.new(f"{name}_{part}_empty"))
            collection.objects.link(obj)
            if k:
                obj.parent = self.objects[parts[0]]
            self.objects[part] = obj

    def show(self, world: np.ndarray, parts: dict, class_name: str, instance: int) -> None:
        """Place the parent at ``world`` (4, 4, scale included) and give each part its mesh and tags."""
        first = next(iter(self.objects))
        self.objects[first].matrix_world = _matrix(world)
        for part, obj in self.objects.items():
            mesh, material, reflectivity = parts[part]
            obj.data = mesh
            tag(obj, class_name, material, reflectivity, instance)
        self.set_hidden(False)

    def set_hidden(self, hidden: bool) -> None:
        for obj in self.objects.values():
            obj.hide_render = obj.hide_viewport = hidden

    def alive(self) -> bool:
        try:
            return all(obj.name in bpy.data.objects for obj in self.objects.values())
        except ReferenceError:
            return False


class Side(abc.ABC):
    """What one kind needs in Blender: ``models`` for its draws, a pool of slots, ``show`` per placement."""

    def __init__(self, name: str, params, collection, manifest: str = ""):
        self.name, self.params, self.collection, self.manifest = name, params, collection, manifest
        self.slots: list = []
        self.models = self.load()

    def load(self):
        """What the kind's draws need (asset models, the arm's model); ``None`` for procedural models."""
        return None

    @abc.abstractmethod
    def new_slot(self, index: int, placed):
        """A new pool object able to show ``placed``."""

    @abc.abstractmethod
    def show_one(self, slot, placed, instance: int, rng) -> None:
        """Move, pose and tag ``slot`` as ``placed`` with ``instance``."""

    def slot_for(self, index: int, placed):
        while len(self.slots) <= index:
            self.slots.append(self.new_slot(len(self.slots), placed))
        return self.slots[index]

    def show(self, placements: list, base: int, rng) -> dict:
        """Show ``placements`` with instance ids from ``base``, hide the rest of the pool; ``{instance: yaw}``."""
        headings = {}
        for k, placed in enumerate(placements):
            self.show_one(self.slot_for(k, placed), placed, base + k, rng)
            headings[base + k] = placed.yaw
        for slot in self.slots[len(placements):]:
            slot.set_hidden(True)
        return headings

    def hide(self) -> None:
        for slot in self.slots:
            slot.set_hidden(True)

    def alive(self) -> bool:
        return all(slot.alive() for slot in self.slots)


def _asset_models(params, kind_name: str, manifest: str):
    """The asset models of ``params.assets`` (a set of the assets manifest), or ``None`` (procedural)."""
    if not params.assets:
        return None
    from ..blender.asset_models import load_models

    return load_models(params.assets, KINDS.get(kind_name).manifest_kind, f"scene.population.{kind_name}.assets", manifest or None)


class PersonSide(Side):
    def load(self):
        return _asset_models(self.params, "person", self.manifest)

    def new_slot(self, index, placed):
        if self.models:
            from ..blender.asset_models import AssetSlot

            return AssetSlot(self.collection, f"person_{index:03d}")
        return PersonRig(self.collection, index)

    def show_one(self, slot, placed, instance, rng):
        lo, hi = self.params.reflectivity
        reflectivity = float(rng.uniform(lo, hi))
        d = placed.shape.detail
        if self.models:
            slot.show(self.models[d["asset"]], placed, "person", instance, reflectivity)
            return
        xy, yaw, z = placed.matrix[:2, 3], placed.yaw, placed.matrix[2, 3]
        person = human.pose_person(d["angles"], d["height"], d["build"], d["pose"], xy, yaw, z)
        slot.show(person, d["build_name"], instance, reflectivity)


class RobotArmSide(Side):
    def load(self):
        from ..geometry import kinematics

        if self.params.assets:
            return _asset_models(self.params, "robot_arm", self.manifest)
        if self.params.model.lower().endswith(".urdf"):  # the robot's own link meshes (ROS-Industrial style)
            from ..blender.robot_arm import load_urdf_arm

            return load_urdf_arm(self.params.model)
        return kinematics.load_arm(self.params.model) if self.params.model else kinematics.load_arm()

    def new_slot(self, index, placed):
        if isinstance(self.models, list):
            from ..blender.asset_models import AssetSlot

            return AssetSlot(self.collection, f"robot_{index:03d}")
        from ..geometry.urdf import MeshedArm
        from ..blender.robot_arm import RobotArm

        if isinstance(self.models, MeshedArm):
            return RobotArm(self.models.model, self.collection, 50 + index, self.models.meshes)
        return RobotArm(self.models, self.collection, 50 + index)

    def show_one(self, slot, placed, instance, rng):
        if isinstance(self.models, list):
            slot.show(self.models[placed.shape.detail["asset"]], placed, "robot arm", instance, float(self.params.reflectivity))
            return
        base = placed.matrix.copy()
        base[2, 3] += placed.shape.detail["lift"]
        slot.show(base, placed.shape.detail["q"], instance)
        for obj in slot.links:
            obj["lidar_reflectivity"] = float(self.params.reflectivity)


class CarSide(Side):
    def load(self):
        models = _asset_models(self.params, "car", self.manifest)
        if models is not None:
            return models
        meshes = []
        for style in STYLES:
            parts = {}
            for part, (vertices, triangles) in car_meshes(style, self.params.fittings).items():
                name = f"LiDAR car {style.name} {part}"
                parts[part] = bpy.data.meshes.get(name) or mesh_data(name, vertices, triangles)
            meshes.append(parts)
        self.meshes = meshes
        return None

    def new_slot(self, index, placed):
        if self.models:
            from ..blender.asset_models import AssetSlot

            return AssetSlot(self.collection, f"car_{index:03d}")
        return PartsSlot(self.collection, f"car_{index:03d}", list(self.meshes[0]))

    def show_one(self, slot, placed, instance, rng):
        d = placed.shape.detail
        if self.models:
            slot.show(self.models[d["asset"]], placed, "car", instance, None)
            return
        world = placed.matrix @ np.diag([*d["scale"], 1.0])
        meshes = self.meshes[d["style"]]
        surfaces = car_surfaces(COLOURS[d["colour"]][3])
        slot.show(world, {part: (mesh, *surfaces[part]) for part, mesh in meshes.items()}, "car", instance)


SIDES = {"person": PersonSide, "robot_arm": RobotArmSide, "car": CarSide}


def _custom_property_rows(buffers, prop: str) -> np.ndarray:
    """``(m,)`` bool: triangles of objects whose custom property ``prop`` is set (true)."""
    flagged = {obj.name for obj in bpy.context.scene.objects if obj.get(prop)}
    rows = np.array([name in flagged for name in buffers.objects.names], bool)
    return rows[buffers.triangle_object] if len(rows) else np.zeros(len(buffers.triangles), bool)


@dataclasses.dataclass
class StandingPlaces:
    """The standing places of one static geometry: ``floors`` and ``seats`` (lists of :class:`~.surfaces.Surface`)."""

    floors: list
    seats: list
    source: str  # "lidar_walkable", "detected"


def _class_rows(buffers, names) -> np.ndarray:
    """``(m,)`` bool: triangles of objects whose class is one of ``names``."""
    wanted = {n.lower() for n in names}
    rows = np.array([c.lower() in wanted for c in buffers.objects.class_names], bool)
    return rows[buffers.triangle_object] if len(rows) else np.zeros(len(buffers.triangles), bool)


def find_places(buffers, rules) -> StandingPlaces:
    """Floors and seats of the exported static scene: objects marked ``lidar_walkable`` / ``lidar_seat``, else
    objects of ``walkable_classes`` / ``seat_classes``, else the surfaces detected in all its triangles."""
    v, t = buffers.vertices, buffers.triangles
    common = {"cell": rules.cell, "min_area": rules.min_area}
    detected = find_surfaces(v, t, **common)
    floors, seats = floor_and_seats(detected, tuple(rules.seat_height), rules.floor_band)
    source = "detected"
    for mask, name in ((_custom_property_rows(buffers, "lidar_walkable"), "lidar_walkable"),
                       (_class_rows(buffers, rules.walkable_classes), "walkable_classes")):
        found = find_surfaces(v, t, mask, **common) if mask.any() else []
        if found:
            floors, source = found, name
            break
    for mask in (_custom_property_rows(buffers, "lidar_seat"), _class_rows(buffers, rules.seat_classes)):
        found = find_surfaces(v, t, mask, headroom=0.4, **common) if mask.any() else []
        if found:
            seats = found
            break
    return StandingPlaces(floors, seats, source)


class PopulationScene:
    """The pools of one population over one built scene; :meth:`randomize` places a frame's objects."""

    def __init__(self, population):
        self.population = population
        self.collection = scene_collection(COLLECTION)
        self.sides = {name: SIDES[name](name, params, self.collection, population.placement.manifest) for name, params in population.kinds}
        self.cached: tuple = (None, None)  # (digest of the static triangles, StandingPlaces)
        self.last: dict = {}

    def alive(self) -> bool:
        try:
            return self.collection.name in bpy.data.collections and all(side.alive() for side in self.sides.values())
        except ReferenceError:
            return False

    def static_scene(self):
        """The scene without the population, exported (world, m), and its standing places (kept while unchanged)."""
        from ..blender.export import export_scene
        from ..labels import load_class_table

        for side in self.sides.values():
            side.hide()
        bpy.context.view_layer.update()
        buffers = export_scene(load_class_table())
        digest = hashlib.sha256(np.ascontiguousarray(buffers.vertices, np.float64).tobytes() + np.ascontiguousarray(buffers.triangles).tobytes()).hexdigest()
        if self.cached[0] != digest:
            self.cached = (digest, find_places(buffers, self.population.placement))
        return buffers, self.cached[1]

    def randomize(self, rng: np.random.Generator, view=None, sensor_poses=NO_POSES):
        """Draw, place and show this frame's objects: ``(headings {instance: yaw}, info, warnings)``.

        view : the frames' :class:`~bpy_pipeline.geometry.lod.SensorView` (its first position is the sensor the
            visibility rule looks from), or ``None``
        sensor_poses : every sensor pose of the run (:class:`~bpy_pipeline.geometry.clearance.SensorPoses`), kept clear
        """
        rules = self.population.placement
        buffers, places = self.static_scene()
        positions = getattr(view, "positions", None)
        sensor = np.asarray(positions[0], float) if positions is not None and len(positions) else None
        placer = Placer(buffers.vertices, buffers.triangles, rules.keep_out, sensor, rules.min_visible, sensor_poses)
        floor_spots = [(s, s.spots, None) for s in places.floors]
        seat_spots = [(s, s.edges, s.outward) for s in places.seats]

        def surface_mesh(surface):
            return buffers.vertices, buffers.triangles[surface.triangles]

        placed_by_instance = {}
        headings, info, warnings = {}, {"surfaces": places.source, "floors": [round(s.z, 3) for s in places.floors],
                                        "seats": [round(s.z, 3) for s in places.seats]}, []
        for k, (name, params) in enumerate(self.population.kinds):
            kind, side = KINDS.get(name), self.sides[name]
            wanted = count_of(params, rng)
            fixed = None
            if getattr(params, "positions", None):
                fixed = np.array([[x, y, np.radians(yaw)] for x, y, yaw in params.positions], float)
            placements = []
            for _ in range(wanted):
                spots = floor_spots + (seat_spots if name == "person" else [])
                placed = place_on_spots(name, lambda r: kind.draw(params, side.models, r), rng, placer, spots, rules.tries, surface_mesh, fixed)
                if placed is not None:
                    placements.append(placed)
            base = rules.instance_base + 1000 * k
            headings.update(side.show(placements, base, rng))
            placed_by_instance.update({base + i: p for i, p in enumerate(placements)})
            info[name] = {"wanted": wanted, "placed": len(placements), "instances": [base + i for i in range(len(placements))],
                          "poses": [p.shape.detail.get("pose", "") for p in placements]}
            if len(placements) < wanted:
                warnings.append(
                    f"scene.population.{name}: placed {len(placements)} of {wanted}; no free spot fit the rest in {rules.tries} tries each (rejections: "
                    f"{dict(placer.rejections)})"
                )
        if not any(len(s.spots) for s in places.floors):
            warnings.append("scene.population: the scene has no floor to stand on (no lidar_walkable object and no horizontal surface found)")
        info["rejections"] = dict(placer.rejections)
        bpy.context.view_layer.update()
        self.last = placed_by_instance  # {instance: population.placer.Placed} of this frame
        return headings, info, tuple(warnings)


def populate(population, context, result):
    """Place ``population`` into the scene the builder just built; the builder's result with the placed objects' headings."""
    held = context.keep.get(KEY)
    if held is None or held[0] != population or not held[1].alive():
        held = context.keep[KEY] = (population, PopulationScene(population))
    headings, info, warnings = held[1].randomize(context.rng, context.view, context.sensor_poses)
    return dataclasses.replace(
        result,
        headings={**result.headings, **headings},
        info={**(result.info or {}), "population": info},
        warnings=tuple(result.warnings) + warnings,
    )
