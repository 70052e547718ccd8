"""``scene.builder: industrial_hall``: a factory hall with desks and shelves, people and robot arms (bpy).

The hall (floor, walls, ceiling, desks about 0.72 m high, shelf racks) is built once per run, each
piece an object running the "Industrial Hall" Geometry Nodes group (:mod:`.hall_nodes`);
each frame re-poses what moves: the robot arms (base position and yaw, joint angles drawn within
the limits, rejected on self-collision) and the people (count, height, build, pose, position,
yaw), placed one after another so that nobody intersects another person, a robot, a desk, a
shelf or a wall, and everyone stands on the floor outside the furniture or sits on a desk edge.
The sensor hangs ``sensor_height`` above the hall's centre (the human-robot paper's overhead
super-resolution LiDAR; see ``config.IndustrialHallScene``). Coordinates: metres, the hall's
centre on the floor at the origin, x along its length.
"""

from __future__ import annotations

import bpy
import numpy as np

from ...geometry import human, kinematics
from ...geometry.clearance import NO_POSES
from ...geometry.collision import box_axes, capsule_box_gaps, capsule_gaps
from ...geometry.indoor import hall_layout
from ...geometry.placement import sample, sample_count
from ...geometry.transforms import pose_matrix
from ...blender import box_nodes
from ...blender.mesh_objects import scene_collection, tag
from ...blender.people import AssetPerson, PersonRig, import_asset, load_assets
from ...blender.robot_arm import RobotArm
from . import hall_nodes

INSTANCE = {"floor": 1, "wall": 2, "ceiling": 3, "desk": 10, "shelf": 40, "robot arm": 100, "person": 200}
PERSON_REFLECTIVITY = (0.15, 0.6)  # clothing at 865-905 nm, uniform between (an assumption)
STATIC_CLEARANCE = 0.01  # m between a body and furniture or walls
SEAT_GAP = 0.015  # m between a seated body and the desk top it rests on (above STATIC_CLEARANCE)


class IndustrialHall:
    """The built hall and its movable actors; :meth:`randomize` re-poses them for a frame."""

    def __init__(self, params):
        self.params = params
        self.sensor_poses = NO_POSES  # the run's, set by randomize: robots and people keep clear of them
        self.collection = scene_collection()
        self.layout = hall_layout(params)
        prototypes = box_nodes.prototypes(self.collection)  # every piece through the "Industrial Hall" group
        self.static = [
            tag(hall_nodes.hall_object("floor", "floor", params, self.collection, prototypes, INSTANCE["floor"]), "floor", reflectivity=0.3,
                instance=INSTANCE["floor"]),
            tag(hall_nodes.hall_object("ceiling", "ceiling", params, self.collection, prototypes, INSTANCE["ceiling"]), "ceiling", reflectivity=0.5,
                instance=INSTANCE["ceiling"]),
            tag(hall_nodes.hall_object("walls", "walls", params, self.collection, prototypes, INSTANCE["wall"]), "wall", reflectivity=0.5,
                instance=INSTANCE["wall"]),
        ]
        p = params
        for k, item in enumerate(self.layout.furniture):
            base = INSTANCE[item.class_name]
            obj = hall_nodes.furniture_object(item, params, self.collection, prototypes, base + k)
            self.static.append(tag(obj, item.class_name, reflectivity=0.35 if item.class_name == "desk" else 0.45, instance=base + k))
        self.arm = kinematics.load_arm(p.robot_model) if p.robot_model else kinematics.load_arm()
        self.robots = [RobotArm(self.arm, self.collection, r) for r in range(p.robots)]
        self.assets = [import_asset(a) for a in load_assets(p.assets or None, "person")]
        self.rigs: list = []
        self.last = {"robots": [], "people": []}  # the last frame's placements (kinematics and bodies)
        self.boxes = [(c, box_axes(0.0), h) for item in self.layout.furniture for c, h in item.parts] + [(c, box_axes(0.0), h) for c, h in self.layout.walls]
        bpy.context.view_layer.update()

    def alive(self) -> bool:
        try:
            return all(obj.name in bpy.data.objects for obj in self.static) and all(r.alive() for r in self.robots)
        except ReferenceError:
            return False

    # ------------------------------------------------------------------ placement
    def _in_area(self, xy) -> bool:
        p = self.params
        return p.area_radius <= 0 or float(np.hypot(xy[0], xy[1])) <= p.area_radius

    def _area_point(self, rng) -> np.ndarray:
        low, high = self.layout.low, self.layout.high
        for _ in range(100):
            xy = rng.uniform(low, high)
            if self._in_area(xy):
                return xy
        return np.zeros(2)

    def _hits_static(self, a, b, r, clearance: float) -> bool:
        """Capsules against furniture, walls and the room's bounds."""
        low = np.minimum(a, b) - r[:, None]
        high = np.maximum(a, b) + r[:, None]
        if (low[:, :2] < self.layout.low + clearance).any() or (high[:, :2] > self.layout.high - clearance).any():
            return True
        if (high[:, 2] > self.params.height - clearance).any():
            return True
        reach_low, reach_high = low.min(axis=0), high.max(axis=0)
        for centre, axes, half in self.boxes:
            if ((centre + half) < reach_low - clearance).any() or ((centre - half) > reach_high + clearance).any():
                continue
            if (capsule_box_gaps(a, b, r, centre, axes, half) < clearance).any():
                return True
        return False

    def _place_robot(self, rng, placed) -> tuple | None:
        for _ in range(self.params.placement_tries):
            xy = self._area_point(rng)
            base = pose_matrix([xy[0], xy[1], 0.0], [0.0, 0.0, np.degrees(rng.uniform(-np.pi, np.pi))])
            q = kinematics.random_configuration(self.arm, rng, base, floor_z=0.0)
            frames = kinematics.forward(self.arm, q, base)
            a, b, r = kinematics.capsules_world(self.arm, frames)
            if self._hits_static(a, b, r, 0.1) or not self.sensor_poses.clear_of_capsules(a, b, r):
                continue
            if any((capsule_gaps(a, b, r, *other[2]) < 0.2).any() for other in placed):
                continue
            return base, q, (a, b, r)
        return None

    def _desk_seat(self, rng, angles, height, build):
        """A seat on a desk edge inside the area: ``(origin_xy, yaw, top)`` or ``None``."""
        desks = [d for d in self.layout.furniture if d.class_name == "desk"]
        if not desks:
            return None
        item = desks[rng.integers(len(desks))]
        (centre, half), = item.parts[:1]
        side = rng.choice([-1.0, 1.0])
        along = rng.uniform(-half[0] + 0.3, half[0] - 0.3)
        edge = np.array([centre[0] + along, centre[1] + side * half[1]])
        outward = np.array([0.0, side])
        offset = human.seat_offset(angles, height, build)
        origin = edge - outward * offset
        yaw = float(np.arctan2(outward[1], outward[0]))
        return (origin, yaw, item.top) if self._in_area(edge) else None

    def _asset_person(self, asset: int, height: float, origin, yaw: float) -> human.Person:
        """An external mesh standing at ``origin``: collision by the vertical capsule around it."""
        _, (a, b, radius) = self.assets[asset]
        placement = pose_matrix([origin[0], origin[1], 0.0], [0.0, 0.0, np.degrees(yaw)])
        ends = np.array([a, b]) * height + placement[:3, 3]
        return human.Person(human.neutral_angles(), height, 1.0, "standing", placement, np.repeat(placement[None], len(human.SEGMENTS), 0), ends[:1], ends[1:],
                            np.array([radius * height]), placement[:3, 3].copy())

    def _place_person(self, rng, kind, robots, people, asset=None):
        p = self.params
        height = float(sample(p.person_height, rng))
        build_name = str(rng.choice(list(human.BUILDS)))
        build = human.BUILDS[build_name]
        for _ in range(p.placement_tries):
            if asset is not None:
                person = self._asset_person(asset, height, self._area_point(rng), float(rng.uniform(-np.pi, np.pi)))
            else:
                angles = human.sample_pose(kind, rng)
                if kind == "sitting":
                    seat = self._desk_seat(rng, angles, height, build)
                    if seat is None:
                        continue
                    origin, yaw, support = seat
                    support += SEAT_GAP
                else:
                    origin, yaw, support = self._area_point(rng), float(rng.uniform(-np.pi, np.pi)), 0.0
                person = human.pose_person(angles, height, build, kind, origin, yaw, support)
            if self._hits_static(person.a, person.b, person.radius,
                                 STATIC_CLEARANCE) or not self.sensor_poses.clear_of_capsules(person.a, person.b, person.radius):
                continue
            if kind != "sitting" and not self._walkable(person.support[:2]):
                continue
            if any((capsule_gaps(person.a, person.b, person.radius, *r[2]) < p.person_clearance).any() for r in robots):
                continue
            if any(human.people_overlap(person, other, p.person_clearance) for other, _, _ in people):
                continue
            return person, build_name
        return None

    def _walkable(self, xy) -> bool:
        """On the floor, inside the walls, outside every piece of furniture's footprint."""
        if (xy < self.layout.low).any() or (xy > self.layout.high).any():
            return False
        return not any(((low <= xy) & (xy <= high)).all() for low, high in (f.footprint for f in self.layout.furniture))

    # ------------------------------------------------------------------ a frame
    def randomize(self, rng: np.random.Generator, view=None, sensor_poses=NO_POSES):
        """This frame's robots and people; none comes within ``sensor_poses.radius`` of a sensor pose of the run."""
        from ..base import BuildResult

        self.sensor_poses = sensor_poses
        p = self.params
        robots = []
        for r in range(p.robots):
            placed = self._place_robot(rng, robots)
            if placed is not None:
                robots.append(placed)
        kinds = list(p.poses)
        weights = np.array([p.poses[k] for k in kinds], float)
        count = sample_count(p.people, rng)
        people = []
        missed = in_a_row = 0
        warnings = ()
        for wanted in range(count):
            kind = kinds[rng.choice(len(kinds), p=weights / weights.sum())]
            asset = int(rng.integers(len(self.assets))) if self.assets else None
            placed = self._place_person(rng, kind, robots, people, asset)
            if placed is None:
                missed, in_a_row = missed + 1, in_a_row + 1
                if in_a_row >= p.max_consecutive_failures:
                    missed += count - wanted - 1
                    warnings = (
                        f"scene.people: placed {len(people)} of {count} people; {in_a_row} in a row fit nowhere, so the rest were given up "
                        "(scene.max_consecutive_failures)",
                    )
                    break
            else:
                in_a_row = 0
                people.append((*placed, asset))
        reflectivity = rng.uniform(*PERSON_REFLECTIVITY, size=len(people))
        # apply: move and re-pose what exists, hide what this frame does not use
        headings = {}
        for r, robot in enumerate(self.robots):
            if r < len(robots):
                base, q, _ = robots[r]
                robot.show(base, q, INSTANCE["robot arm"] + r)
                headings[INSTANCE["robot arm"] + r] = kinematics.arm_heading(self.arm, kinematics.forward(self.arm, q, base))
            else:
                robot.set_hidden(True)
        while len(self.rigs) < len(people):
            self.rigs.append(AssetPerson(self.collection, len(self.rigs)) if self.assets else PersonRig(self.collection, len(self.rigs)))
        for k, rig in enumerate(self.rigs):
            if k >= len(people):
                rig.set_hidden(True)
                continue
            person, build, asset = people[k]
            instance = INSTANCE["person"] + k
            if asset is not None:
                mesh, _ = self.assets[asset]
                rig.show(mesh, person.height, person.placement[:2, 3], person.yaw, instance, float(reflectivity[k]))
            else:
                rig.show(person, build, instance, float(reflectivity[k]))
            headings[instance] = person.yaw
        bpy.context.view_layer.update()
        info = {
            "robots": [{"instance": INSTANCE["robot arm"] + r, "joints_deg": np.degrees(q).round(3).tolist(), "base": base[:3, 3].round(4).tolist()} for r,
                       (base, q, _) in enumerate(robots)],
            "people": [{"instance": INSTANCE["person"] + k, "pose": person.pose, "height": round(person.height, 4), "build": build} for k,
                       (person, build, _) in enumerate(people)],
            "people_wanted": count,
            "people_not_placed": missed,
        }
        self.last = {"robots": robots, "people": people}
        return BuildResult(headings=headings, info=info, warnings=warnings)
