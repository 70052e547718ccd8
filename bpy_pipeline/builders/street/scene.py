"""``scene.builder: street``: the intersection and its road users as Blender objects (bpy).

The static intersection (road, markings, kerbs, sidewalks, traffic lights and signs, buildings;
``builders/street/layout.py``) is built once per run from the scene's ``layout_seed``, so every frame
scans the same street whichever frame a run starts at. Its scattered items (trunks, crowns and
bushes, lamps and bollards, bins, bicycle stands, cones, barriers) are one object per kind whose
live "Street Scatter" Geometry Nodes modifier instances the kind's prototypes on the object's
points (builders/street/scatter_nodes.py); the carriageway, kerbs and sidewalks are objects whose
edges are the roads' centre lines and whose live "Street Road" modifier sweeps their profiles along them
(builders/street/road_nodes.py); each building is its facade line along its plot, swept to its
depth and height by a live "Street Facade" modifier (builders/street/facade_nodes.py); a user can
edit their inputs or move their points and rescan; the ground of the yards, ``street_yard_trees``,
has a live "Street Planting" modifier distributing ``scene.yard_trees`` more trees over it
(builders/street/planting_nodes.py).
Each frame removes the last frame's road users and places new ones from the frame's generator
(lane following, platoons, parked cars, pedestrians on sidewalks and crossings, field-of-view
aware when the run's sensors are known).

A road user is one object per part (a vehicle's body, glass, tyres, plates and lamps; a two-wheeler's frame,
wheels and rider) sharing one instance id, so its 3D box holds all of it; the rider's points are
labelled by what it rides (``rider`` on a bicycle, ``motorcyclist`` on a motorcycle), and the box takes the
rider's class (:data:`~bpy_pipeline.geometry.boxes.RIDER_CLASSES`: KITTI's Cyclist is rider and bicycle in one box).
"""

from __future__ import annotations

import bpy
import numpy as np

from ...blender.mesh_objects import fill_mesh, mesh_object, scene_collection, tag
from . import layout as street
from .facade_nodes import facade_object
from .planting_nodes import planting_object
from .road_nodes import road_object
from .scatter_nodes import prototypes_collection, scatter_object

USER_INSTANCE = 1000  # road users' instance ids start here; static parts use 1 .. 999
USERS_COLLECTION = "LiDAR Street Users"
SWEPT = {"street_road": "road", "street_kerbs": "kerbs", "street_sidewalks": "sidewalks"}  # parts the "Street Road" group builds


class Intersection:
    """The built intersection; :meth:`populate` places one frame's road users."""

    def __init__(self, params, sensor_poses=street.NO_POSES):
        self.params = params
        self.sensor_poses = sensor_poses  # every sensor pose of the run: the layout and the road users keep clear of them
        self.layout = street.street_layout(params, np.random.default_rng(params.layout_seed), sensor_poses)
        self.collection = scene_collection()
        prototypes = prototypes_collection(self.collection)
        self.static = [tag(self._static_object(part, prototypes), part.class_name, part.material, part.reflectivity, part.instance)
                       for part in self.layout.parts]
        planting_instance = max((part.instance or 0 for part in self.layout.parts), default=0) + 1  # after every static part's id
        trunks = next((obj for obj in self.static if obj.name == "street_trunks"), None)
        self.static.append(planting_object(self.layout.yards, params, self.collection, prototypes, planting_instance, trunks))
        self.users = bpy.data.collections.new(USERS_COLLECTION)
        self.collection.children.link(self.users)
        self.unshown = None  # the last frame's parts while Blender's objects do not hold them (populate's in_blender)
        bpy.context.view_layer.update()

    def _static_object(self, part, prototypes) -> bpy.types.Object:
        """``part``'s object: swept by "Street Road" (road, kerbs, sidewalks) or "Street Facade" (buildings),
        scattered by "Street Scatter", else its mesh."""
        if part.name in SWEPT:
            return road_object(part.name, SWEPT[part.name], self.params, self.collection, part.instance or 0)
        if part.front is not None:
            return facade_object(part.name, part.front, self.collection, part.instance or 0)
        if part.scatter is not None:
            return scatter_object(part.name, part.scatter, self.collection, prototypes, part.instance or 0)
        return mesh_object(part.name, part.mesh, self.collection)

    def alive(self) -> bool:
        try:
            return all(obj.name in bpy.data.objects for obj in self.static) and self.users.name in bpy.data.collections
        except ReferenceError:
            return False

    def _show_users(self, parts: list[tuple[str, str, str, float, int, tuple[np.ndarray, np.ndarray]]]) -> None:
        """The frame's road users' ``parts`` ``(name, class, material, reflectivity, instance, mesh (world))``, in order,
        on the objects the users' collection kept from earlier frames (more made as needed; the rest emptied).

        Each kept object is renamed and its mesh refilled in place: objects and meshes made and removed every
        frame made Blender rebuild the whole scene's relations twice a frame (about 40 ms of a street frame).
        The objects stay in the collection's order, so the export sees the parts in the order of ``parts``.
        Only objects and meshes whose name changes are renamed (a rename costs Blender a pass over its names): those
        holding a name another part takes first to names no part takes, then each to its own. The spares
        are ``street_user_kept_K`` by their place.
        """
        kept = list(self.users.objects)
        while len(kept) < len(parts):
            name = f"street_user_kept_{len(kept):03d}"
            kept.append(bpy.data.objects.new(name, bpy.data.meshes.new(name)))
            self.users.objects.link(kept[-1])
        names = [part[0] for part in parts] + [f"street_user_kept_{k:03d}" for k in range(len(parts), len(kept))]
        renamed = [(obj, obj.name, obj.data.name, name) for obj, name in zip(kept, names) if obj.name != name or obj.data.name != name]
        wanted = {name for *_, name in renamed}
        for k, (obj, held, held_data, name) in enumerate(renamed):  # out of the way: names another object or mesh takes
            if held != name and held in wanted:
                obj.name = f"street_user_renamed_{k:03d}"
            if held_data != name and held_data in wanted:
                obj.data.name = f"street_user_renamed_{k:03d}"
        for obj, held, held_data, name in renamed:
            if held != name:
                obj.name = name
            if held_data != name:
                obj.data.name = name
        for obj, (name, class_name, material, reflectivity, instance, mesh) in zip(kept, parts):
            fill_mesh(obj.data, *mesh)
            tag(obj, class_name, material, reflectivity, instance)
        for obj in kept[len(parts) :]:  # an empty mesh exports nothing
            fill_mesh(obj.data, np.zeros((0, 3)), np.zeros((0, 3), np.int32))

    def show(self) -> None:
        """The last frame's road users into Blender's objects, where :meth:`populate` left them out (``in_blender``
        false); nothing once they are there, or when the user has removed the street's objects."""
        if self.unshown is not None and self.alive():
            parts, self.unshown = self.unshown, None
            self._show_users(parts)

    def populate(self, rng: np.random.Generator, view=None, in_blender: bool = True):
        """This frame's road users, drawn from ``rng``: placed, meshed, given to the export as arrays
        (``dynamic_parts``) and, with ``in_blender``, put into Blender's objects now; else by the result's ``show``
        (a run whose stages read only the arrays fills Blender once, at its end: about 8 ms a street frame)."""
        from ..base import BuildResult

        views = tuple(getattr(view, "fields", ()) or ())
        # the ego car under the roof sensor: its footprint and its headway stay free
        reserved = [street.ego_keep_free(self.params, v.pose) for v in views] if self.params.ego_vehicle else []
        placement = street.place_users(self.params, self.layout, rng, views, reserved=reserved, clear=self.sensor_poses)
        headings, parts = {}, []
        for k, (user, meshes) in enumerate(zip(placement.users, street.users_meshes(placement.users, rng, self.params.car_fittings))):
            instance = USER_INSTANCE + k
            for part, class_name, material, reflectivity, mesh in meshes:
                name = f"street_user_{k:03d}_{user.kind}_{part}" if part != "rider" else f"street_user_{k:03d}_{user.kind}_~rider"
                parts.append((name, class_name, material, reflectivity, instance, mesh))
            headings[instance] = float(user.yaw)
        self.unshown = parts
        if in_blender:  # Blender evaluates them when something reads the scene (an export, a render, the viewport)
            self.show()
        kinds = {}
        for user in placement.users:
            kinds[user.kind] = kinds.get(user.kind, 0) + 1
        info = {
            "users": kinds,
            "wanted": placement.wanted,
            "out_of_view": placement.out_of_view,
            "collisions_refused": placement.collisions,
            "near_sensor_refused": placement.near_sensor,
            "platooning": placement.platoons,
            "fov_aware": bool(views) and bool(self.params.fov_aware),
            "placed": [
                {"instance": USER_INSTANCE + k, "kind": u.kind, "where": u.where, "centre": np.round(u.centre, 3).tolist(), "yaw": round(float(u.yaw), 4),
                 "size": np.round(u.size, 3).tolist()}
                for k, u in enumerate(placement.users)
            ],
        }
        arrays = tuple((name, {"lidar_class": class_name, "lidar_material": material, "lidar_reflectivity": float(reflectivity),
                               "lidar_instance": int(instance)}, *mesh)
                       for name, class_name, material, reflectivity, instance, mesh in parts)  # as parts_buffers takes them
        return BuildResult(headings=headings, info=info, dynamic=self.users.name, static_world=self, dynamic_parts=arrays, show=self.show)
