"""``scene.builder: parking``: an underground car park level with cars placed by the parking paper's rule (bpy).

The level (floor and ceiling slabs, walls, a pillar grid, a ramp, bays along the driveway;
``geometry/indoor.py``) is built once per run, each piece an object running the "Parking Level"
Geometry Nodes group (:mod:`.parking_nodes`) with the level's dimensions as its inputs. Each frame places cars around the sensor with the
paper's insertion rule (``geometry/placement.py``): the count from N(5, 4), a distance from the
sensor, a random yaw, turned 10 degrees about the sensor on failure up to 36 times, 10
consecutive failures end it; a car is refused where it collides with the structure or another
car, or where it or a car before it would be hidden (visibility traced against the level's
meshes and the cars' boxes). Cars are a pool of parametric bodies moved, scaled and recoloured
each frame, never rebuilt.

A car is four objects sharing one instance id, class ``car``: the body (its paint colour's
reflectivity), the windows (``lidar_material: glass``, so the scan can see the seats through
them as a real LiDAR does), the interior (dashboard and seats) and the tyres; and, unless
``car_fittings: false``, two more: its licence plates (``retroreflector``) and lamps
(``glossy_paint``), which ``effects.materials.objects: true`` gives their models. Three body styles
(sedan, hatchback, estate), each a nominal mesh scaled to the drawn height (the paper:
1.55-1.70 m), with length and width following the style's proportions (+-3 %).
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from ...buffers import MATERIAL_ID, ObjectTable, SceneBuffers
from ...geometry.clearance import NO_POSES
from ...geometry.objects import COLOURS, STYLES, car_meshes, car_surfaces, style_size
from ...geometry.indoor import parking_station
from ...geometry.placement import FloorBoxPlacer, insert_sequentially, sample, sample_count, turn_about
from ...lidar.cast.raycast import RayCaster
from ...blender import box_nodes
from ...blender.mesh_objects import mesh_data, scene_collection, tag
from . import level_nodes as parking_nodes
from .layout import level_layout

INSTANCE = {"floor": 1, "ceiling": 2, "wall": 3, "pillar": 4, "ramp": 5, "car": 100}
STATIC_REFLECTIVITY = {"floor": 0.25, "ceiling": 0.45, "wall": 0.5, "pillar": 0.5, "ramp": 0.3}


@dataclass
class Car:
    """One car drawn for insertion: its style, size (3,) m, paint, and where it is tried first."""

    style: int
    size: np.ndarray
    colour: int
    distance: float
    angle: float  # radians about the sensor
    yaw: float  # radians


# ----------------------------------------------------------------------------- Blender objects
class CarSlot:
    """The objects of one car, one per part of ``meshes`` (the body the parent of the others), reused frame after frame."""

    def __init__(self, collection, index: int, meshes: dict, paints: list):
        self.objects = {}
        self.paints = paints
        for part in meshes:
            obj = bpy.data.objects.new(f"car_{index:03d}" + ("" if part == "body" else f"_{part}"), meshes[part])
            collection.objects.link(obj)
            if part != "body":
                obj.parent = self.objects["body"]
            self.objects[part] = obj
        self.objects["body"].material_slots[0].link = "OBJECT"

    def show(self, meshes: dict, car: Car, centre_xy, yaw: float, instance: int) -> None:
        body = self.objects["body"]
        for part in self.objects:  # assigned only when it changes: every assignment has the depsgraph rebuild relations
            if self.objects[part].data != meshes[car.style][part]:
                self.objects[part].data = meshes[car.style][part]
        body.location = (float(centre_xy[0]), float(centre_xy[1]), 0.0)
        body.rotation_euler = (0.0, 0.0, float(yaw))
        body.scale = tuple(float(s) for s in car.size / style_size(STYLES[car.style]))
        slot = body.material_slots[0]
        if slot.link != "OBJECT":
            slot.link = "OBJECT"
        if slot.material != self.paints[car.colour]:
            slot.material = self.paints[car.colour]
        surfaces = car_surfaces(COLOURS[car.colour][3])
        for part, obj in self.objects.items():
            tag(obj, "car", *surfaces[part], instance)
        self.set_hidden(False)

    def set_hidden(self, hidden: bool) -> None:
        for obj in self.objects.values():  # only what changes (see show)
            if obj.hide_render != hidden:
                obj.hide_render = hidden
            if obj.hide_viewport != hidden:
                obj.hide_viewport = hidden


class ParkingGarage:
    """The built level and its car pool; :meth:`randomize` places the cars of a frame."""

    def __init__(self, params, check=None):
        """``check(params, where)`` refuses an edited level in one line (the builder's ``check``; None: no check)."""
        self.built = self.params = params  # built: the YAML's level; params: the level as its modifiers hold it now (:meth:`follow_edits`)
        self.check = check
        self.layout = level_layout(params)
        self.collection = scene_collection()
        meshes = self.layout.meshes()
        prototypes = box_nodes.prototypes(self.collection)  # the level's pieces through the "Parking Level" group
        self.static = [tag(parking_nodes.level_object(name, name, params, self.collection, prototypes, INSTANCE[name]), name,
                           reflectivity=STATIC_REFLECTIVITY[name], instance=INSTANCE[name])
                       for name in meshes]
        self.caster = RayCaster(_buffers(meshes), frame=np.eye(4))
        self.paints = []
        for name, rgb, _, _ in COLOURS:
            material = bpy.data.materials.get(f"LiDAR car paint {name}") or bpy.data.materials.new(f"LiDAR car paint {name}")
            material.diffuse_color = (*rgb, 1.0)
            self.paints.append(material)
        self.meshes = []
        for style in STYLES:
            parts = {}
            for part, (vertices, triangles) in car_meshes(style, params.car_fittings).items():
                mesh = bpy.data.meshes.get(f"LiDAR car {style.name} {part}") or mesh_data(f"LiDAR car {style.name} {part}", vertices, triangles)
                if part == "body" and not mesh.materials:
                    mesh.materials.append(None)
                parts[part] = mesh
            self.meshes.append(parts)
        self.slots: list[CarSlot] = []
        self.last = None  # the last frame's insertion log (geometry.placement.InsertionLog)
        bpy.context.view_layer.update()

    def alive(self) -> bool:
        try:
            return all(obj.name in bpy.data.objects for obj in self.static)
        except ReferenceError:
            return False

    def follow_edits(self) -> None:
        """Take the level's dimensions from its pieces' "Parking Level" modifiers (a user may have edited them since
        the build): where they changed, the layout (bays, pillars, ramp: what placement avoids and snaps to) and
        the visibility meshes become the pure ones of the edited values. Unedited: nothing changes."""
        params = parking_nodes.edited_params(self.static, self.built)
        if params == self.params:
            return
        if self.check is not None:
            self.check(params, f"the {parking_nodes.GROUP!r} modifier inputs of the parking level")
        self.params, self.layout = params, level_layout(params)
        self.caster = RayCaster(_buffers(self.layout.meshes()), frame=np.eye(4))

    def static_distance(self, origin):
        """``f(directions (n, 3)) -> (n,)`` distance from ``origin`` to the level's first surface (inf: none)."""

        def distance(directions):
            hits = self.caster.intersect(np.asarray(origin, float), directions)
            out = np.full(len(directions), np.inf)
            out[hits.ray] = hits.distance
            return out

        return distance

    def _draw_car(self, rng) -> Car | None:
        p = self.params
        style = int(rng.integers(len(STYLES)))
        height = float(sample(p.car_height, rng))
        size = style_size(STYLES[style], height) * [rng.uniform(0.97, 1.03), rng.uniform(0.97, 1.03), 1.0]
        shares = np.array([c[2] for c in COLOURS])
        colour = int(rng.choice(len(COLOURS), p=shares / shares.sum()))
        distance = float(sample(p.car_distance, rng))
        angle = float(rng.uniform(-np.pi, np.pi))
        yaw = float(rng.uniform(-np.pi, np.pi))
        refused = distance < p.near_rejection_distance and rng.random() < p.near_rejection_probability
        return None if refused else Car(style, size, colour, distance, angle, yaw)

    def _in_bay(self, centre_xy, yaw: float) -> tuple[np.ndarray, float]:
        """The centre of the bay nearest ``centre_xy`` and the bay's yaw, nose-in or reversed as ``yaw`` is closer to."""
        bays = self.layout.bays
        if len(bays) == 0:
            return np.asarray(centre_xy, float), yaw
        k = int(np.argmin(np.linalg.norm(bays[:, :2] - centre_xy, axis=1)))
        bay_yaw = bays[k, 2] if np.cos(yaw - bays[k, 2]) >= 0 else bays[k, 2] + np.pi
        return bays[k, :2].copy(), float(np.angle(np.exp(1j * bay_yaw)))

    def randomize(self, rng: np.random.Generator, view=None, sensor_poses=NO_POSES):
        """This frame's cars; none comes within ``sensor_poses.radius`` of a sensor pose of the run."""
        from ..base import BuildResult

        self.follow_edits()
        p = self.params
        # where the sensor is this frame (a moving sensor's view is None: the first station stands in)
        sensor = np.asarray(view.positions[0], float) if view is not None and len(view.positions) else parking_station(p, 0)[:3, 3]
        placer = FloorBoxPlacer(
            sensor, (self.layout.low, self.layout.high), self.layout.obstacles, self.static_distance(sensor),
            clearance=p.car_clearance, min_visible=p.min_visible_fraction, keep_out=1.0, clear=sensor_poses,
        )

        def try_at(car: Car, angle_deg: float):
            start = sensor[:2] + car.distance * np.array([np.cos(car.angle), np.sin(car.angle)])
            centre, yaw = turn_about(sensor[:2], start, car.yaw, angle_deg)
            if p.placement == "bays":
                centre, yaw = self._in_bay(centre, yaw)
            box = placer.try_place(centre, yaw, car.size / 2)
            if box is None:
                return None
            placer.commit(box)
            return car, box

        wanted = sample_count(p.cars, rng)
        log = insert_sequentially(wanted, lambda: self._draw_car(rng), try_at, p.rotations, p.rotation_step_deg, p.max_consecutive_failures)
        while len(self.slots) < len(log.placed):
            self.slots.append(CarSlot(self.collection, len(self.slots), self.meshes[0], self.paints))
        headings = {}
        for k, slot in enumerate(self.slots):
            if k < len(log.placed):
                car, box = log.placed[k]
                slot.show(self.meshes, car, box.centre[:2], box.yaw, INSTANCE["car"] + k)
                headings[INSTANCE["car"] + k] = box.yaw
            else:
                slot.set_hidden(True)
        bpy.context.view_layer.update()
        info = {
            "cars_wanted": wanted,
            "cars_placed": len(log.placed),
            "cars_tried": log.objects_tried,
            "attempts": log.attempts,
            "stopped": log.stopped,
            "rejections": dict(placer.rejections),
            "cars": [
                {"instance": INSTANCE["car"] + k, "style": STYLES[car.style].name, "colour": COLOURS[car.colour][0], "size": np.round(car.size, 4).tolist(),
                 "visible_fraction": round(box.visible_fraction, 4)}
                for k, (car, box) in enumerate(log.placed)
            ],
        }
        self.last = log
        return BuildResult(headings=headings, info=info)


def _buffers(meshes: dict) -> SceneBuffers:
    """Scene buffers of the level's static meshes (for the placement's visibility rays)."""
    vertices, triangles, owner, offset = [], [], [], 0
    for row, (v, t) in enumerate(meshes.values()):
        vertices.append(v)
        triangles.append(t + offset)
        owner.append(np.full(len(t), row, np.int32))
        offset += len(v)
    k = len(meshes)
    objects = ObjectTable(list(meshes), [""] * k, list(meshes), np.zeros(k, np.uint16), np.arange(1, k + 1, dtype=np.uint32),
                          np.full(k, MATERIAL_ID["diffuse"], np.uint8), np.full(k, 0.5, np.float32))
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(owner), objects)
