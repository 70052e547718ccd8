"""Build a small factory hall as a user would in Blender, and save it as a .blend file.

    python examples/hall_twin/make_hall.py hall.blend          # with the bpy module
    blender --background --python examples/hall_twin/make_hall.py -- hall.blend

A 12 x 10 m hall (walls 3.5 m high): the floor is marked ``lidar_walkable`` (people, robot arms and
cars may stand on it), two desks with a bench each (benches marked ``lidar_seat``: seated people
sit on their edges), a shelf rack and a machine block. Nothing here is random; the population is
drawn per frame by ``scene.population`` (see hall_twin.yaml).
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy

HALL = (12.0, 10.0, 3.5)  # m: length, width, wall height
WALL = 0.2  # m
BOXES = [  # name, class, size (x, y, z) m, centre of the base (x, y), custom properties
    ("desk_1", "desk", (1.6, 0.8, 0.72), (2.5, 2.0), {}),
    ("bench_1", "desk", (1.6, 0.45, 0.46), (2.5, 1.1), {"lidar_seat": True}),
    ("desk_2", "desk", (1.6, 0.8, 0.72), (2.5, -2.0), {}),
    ("bench_2", "desk", (1.6, 0.45, 0.46), (2.5, -1.1), {"lidar_seat": True}),
    ("shelf", "shelf", (2.0, 0.6, 2.2), (-3.0, 4.3), {}),
    ("machine", "unlabeled", (1.5, 1.2, 1.4), (-3.5, -2.5), {}),
]


def box(name: str, size, base_xy, class_name: str, props: dict, collection) -> bpy.types.Object:
    """A box object ``size`` m standing on z = 0 at ``base_xy``, tagged with its class and ``props``."""
    mesh = bpy.data.meshes.new(name)
    x, y, z = (s / 2 for s in size)
    vertices = [(-x, -y, -z), (x, -y, -z), (x, y, -z), (-x, y, -z), (-x, -y, z), (x, -y, z), (x, y, z), (-x, y, z)]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]  # outward normals
    mesh.from_pydata(vertices, [], faces)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = (base_xy[0], base_xy[1], size[2] / 2)
    obj["lidar_class"] = class_name
    for key, value in props.items():
        obj[key] = value
    collection.objects.link(obj)
    return obj


def build_hall(path: str | Path) -> Path:
    """Empty the current file, build the hall and save it to ``path``."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    collection = bpy.context.scene.collection
    length, width, height = HALL
    floor = box("floor", (length, width, 0.1), (0.0, 0.0), "floor", {"lidar_walkable": True}, collection)
    floor.location.z = -0.05  # top at z = 0
    for name, size, xy in (
        ("wall_north", (length + 2 * WALL, WALL, height), (0.0, width / 2 + WALL / 2)),
        ("wall_south", (length + 2 * WALL, WALL, height), (0.0, -width / 2 - WALL / 2)),
        ("wall_east", (WALL, width, height), (length / 2 + WALL / 2, 0.0)),
        ("wall_west", (WALL, width, height), (-length / 2 - WALL / 2, 0.0)),
    ):
        box(name, size, xy, "wall", {}, collection)
    for name, class_name, size, xy, props in BOXES:
        box(name, size, xy, class_name, props, collection)
    path = Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    print(build_hall(args[0] if args else Path(__file__).with_name("hall.blend")))
