"""Export speed: triangles per second from Geometry Nodes scenes of about one million triangles.

Two shapes of scene, both made by Geometry Nodes and read through the evaluated depsgraph:
one large realised mesh (a grid), and many instances of a small mesh (icospheres on points),
which costs a Python step per instance in the depsgraph iterator.
Run: python benchmarks/bench_export.py [--small]
"""

from common import arguments, best_of, report

import bpy

from bpy_pipeline.blender.export import export_scene
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.blender.mesh_objects import mesh_object, scene_collection, tag


def gn_object(name: str, build) -> bpy.types.Object:
    """An empty mesh object whose Geometry Nodes modifier makes its geometry with ``build(nodes, links, out)``."""
    group = bpy.data.node_groups.new(name, "GeometryNodeTree")
    if hasattr(group, "is_modifier"):
        group.is_modifier = True
    group.interface.new_socket(name="Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    out = group.nodes.new("NodeGroupOutput")
    build(group.nodes, group.links, out)
    obj = mesh_object(name, ([[0, 0, 0]], [[0, 0, 0]]), bpy.data.collections.get("LiDAR Scene") or scene_collection())
    obj.modifiers.new(name, "NODES").node_group = group
    return tag(obj, "ground")


def grid(side: int):
    def build(nodes, links, out):
        node = nodes.new("GeometryNodeMeshGrid")
        node.inputs["Vertices X"].default_value = side
        node.inputs["Vertices Y"].default_value = side
        links.new(node.outputs["Mesh"], out.inputs["Geometry"])

    return build


def instances(count: int, subdivisions: int):
    def build(nodes, links, out):
        line = nodes.new("GeometryNodeMeshLine")
        line.inputs["Count"].default_value = count
        ico = nodes.new("GeometryNodeMeshIcoSphere")
        ico.inputs["Subdivisions"].default_value = subdivisions
        inst = nodes.new("GeometryNodeInstanceOnPoints")
        links.new(line.outputs["Mesh"], inst.inputs["Points"])
        links.new(ico.outputs["Mesh"], inst.inputs["Instance"])
        links.new(inst.outputs["Instances"], out.inputs["Geometry"])

    return build


def main():
    args = arguments(__doc__)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    table = load_class_table()
    scale = 0.05 if args.small else 1.0
    side = int(708 * scale**0.5)
    cases = {
        "one GN grid mesh": grid(side),
        "GN instances (320-triangle icospheres)": instances(max(1, int(3125 * scale)), 3),
    }
    rows = []
    for label, build in cases.items():
        scene_collection()
        gn_object("grid" if "grid" in label else "inst", build)
        buffers = export_scene(table)
        seconds = best_of(lambda: export_scene(table), repeat=3)
        rows.append({"scene": label, "triangles": len(buffers.triangles), "objects": len(buffers.objects), "export_s": seconds,
                     "triangles_per_s": len(buffers.triangles) / seconds})
        for group in list(bpy.data.node_groups):
            bpy.data.node_groups.remove(group)
    report("export" + ("_small" if args.small else ""), rows, args.out)


if __name__ == "__main__":
    main()
