"""Blender's evaluated depsgraph -> :class:`~bpy_pipeline.buffers.SceneBuffers`.

Modifiers, Geometry Nodes and instances are included (everything ``depsgraph.object_instances``
lists), world transforms applied in float64 numpy; mesh data is read with ``foreach_get`` once
per distinct mesh and every instance of it is transformed in one batched matrix product.

Labels come from the custom properties of the object that owns the geometry: the object itself,
or for instances the instanced object if it is tagged, else the instancer. Untagged objects get
a class from the name rules (their name, then their ancestors' names) or ``unlabeled``.
Geometry Nodes may label what they make through the named attribute ``lidar_instance`` (INT, see
:data:`INSTANCE_ATTRIBUTE`): on an instancer's instances (each instance's own from Blender 5.3,
the group's ``Instance`` input before: :func:`~bpy_pipeline.blender.compat.instance_attribute`) or on a mesh's faces or points; a value > 0 is the
instance id of that geometry (its class
stays its owner's), so one object may carry many instances, realized or not.
An object with a ``lidar_parts`` list of names may label faces or points with the named attribute
``lidar_part`` (INT, :data:`PART_ATTRIBUTE`): p > 0 makes them the row named ``lidar_parts[p - 1]``, labelled
as an object of that name with the owner's tags would be (the railway's instanced masts keep their
per-support rows and automatic instance ids).
"""

from __future__ import annotations

import itertools
from collections import defaultdict

import bpy
import numpy as np

from ..buffers import MATERIAL_ID, MATERIALS, ObjectTable, SceneBuffers
from .compat import instance_attribute
from ..errors import InputError
from ..labels import ClassTable
from ..lidar.effects.materials import MATERIAL_MODELS, model_from_material, model_id

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}
VIRTUAL_DEFORM = ("ARMATURE", "LATTICE", "CURVE")  # parent types that deform a child's mesh without a modifier
INSTANCE_ATTRIBUTE = "lidar_instance"  # INT named attribute: the instance id of the instance, face or point (0: the owner's)
PART_ATTRIBUTE = "lidar_part"  # INT named attribute of faces or points: p > 0 labels them as the row named ``owner["lidar_parts"][p - 1]``


def _triangle_values(mesh, name: str, triangles: np.ndarray, faces: np.ndarray | None) -> np.ndarray | None:
    """``(m,)`` int32: the INT named attribute ``name`` of each loop triangle's face (``faces`` (m,); None: read from the
    loop triangles) or first point (``triangles`` (m, 3)); None where the mesh has none."""
    attribute = mesh.attributes.get(name)
    if attribute is None or attribute.data_type != "INT" or attribute.domain not in ("FACE", "POINT"):
        return None
    values = np.empty(len(attribute.data), np.int32)
    attribute.data.foreach_get("value", values)
    if attribute.domain == "POINT":
        return values[triangles[:, 0]]
    if faces is None:
        faces = np.empty(len(mesh.loop_triangles), np.int32)
        mesh.loop_triangles.foreach_get("polygon_index", faces)
    return values[faces]


def _loop_triangles(mesh) -> tuple[np.ndarray, np.ndarray | None]:
    """``(triangles (m, 3) int32 vertex indices, faces (m,) int32 or None)``: the mesh's loop triangles and the face of
    each (None: not read; :func:`_triangle_values` reads it where a face attribute needs it).

    A mesh whose faces are all triangles (as many corners as three times its faces; the builders' meshes) is
    its own tessellation: each face's corners in order, read through the ``.corner_vert`` attribute in one
    copy. Others are tessellated by Blender and read per triangle (slower: ``loop_triangles`` has no array path).
    """
    if len(mesh.loops) == 3 * len(mesh.polygons):
        corners = np.empty(len(mesh.loops), np.int32)
        if len(corners):
            mesh.attributes[".corner_vert"].data.foreach_get("value", corners)
        return corners.reshape(-1, 3), np.arange(len(mesh.polygons), dtype=np.int32)
    mesh.calc_loop_triangles()
    triangles = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", triangles)
    return triangles.reshape(-1, 3), None


def _mesh_arrays(obj) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(vertices (n, 3) float64 local, triangles (m, 3) int32, ids (m,) int32 or None, parts (m,) int32 or None)`` of an
    evaluated object; ``ids`` is the :data:`INSTANCE_ATTRIBUTE` and ``parts`` the :data:`PART_ATTRIBUTE` of each triangle
    where the mesh has them."""
    mesh = obj.to_mesh()
    try:
        vertices = np.empty(len(mesh.vertices) * 3, np.float32)
        if len(vertices):  # positions in one copy (``vertices.co`` goes value by value)
            mesh.attributes["position"].data.foreach_get("vector", vertices)
        triangles, faces = _loop_triangles(mesh)
        ids = _triangle_values(mesh, INSTANCE_ATTRIBUTE, triangles, faces)
        parts = _triangle_values(mesh, PART_ATTRIBUTE, triangles, faces) if "lidar_parts" in obj.original else None
    finally:
        obj.to_mesh_clear()
    return vertices.reshape(-1, 3).astype(np.float64), triangles, ids, parts


def _ancestors(obj) -> list[str]:
    names = []
    while obj is not None:
        names.append(obj.name)
        obj = obj.parent
    return names


def _owner(instance):
    """The original object whose custom properties label this depsgraph instance, and its name chain."""
    obj = instance.object.original
    if not instance.is_instance:
        return obj, _ancestors(obj)
    parent = instance.parent.original
    if obj is not parent and "lidar_class" in obj:
        return obj, _ancestors(obj) + _ancestors(parent)
    return parent, _ancestors(parent)


DEFAULT_REFLECTIVITY = 0.5  # an object with neither lidar_reflectivity nor a material


def _reflectivity(owner, where: str) -> float:
    """The object's lidar reflectivity (0..1): its ``lidar_reflectivity`` custom property (the override),
    else the albedo of its first material's base colour, else :data:`DEFAULT_REFLECTIVITY`.

    Near-infrared assumption: a lidar sees 905 nm (or 1550 nm), not visible light; the base colour's
    albedo (the mean of its linear R, G, B: Principled BSDF ``Base Color`` when not linked to a
    texture, else the viewport ``diffuse_color``) stands in for the NIR reflectance. That holds
    roughly for greys, concrete, asphalt and most paints; it underestimates vegetation (bright in
    NIR) and some dark paints, and says nothing about retro-reflectors: set ``lidar_reflectivity``
    on such objects.
    """
    if "lidar_reflectivity" not in owner:
        material = next((slot.material for slot in getattr(owner, "material_slots", ()) if slot.material is not None), None)
        return DEFAULT_REFLECTIVITY if material is None else _albedo(material)
    try:
        reflectivity = float(owner["lidar_reflectivity"])
    except (TypeError, ValueError):
        reflectivity = -1.0
    if not 0.0 <= reflectivity <= 1.0:
        raise InputError(f"{where}: lidar_reflectivity must be a number in 0..1, got {owner.get('lidar_reflectivity')!r}")
    return reflectivity


def _surface(owner, where: str) -> str:
    """The reflectance model (lidar/effects/materials.py, ``""`` for none) the object's ``lidar_material``, else its first
    material's ``lidar_material`` custom property, else that material's Principled BSDF roughness and metallic
    (when not linked to a texture) select (:func:`~.lidar.effects.materials.model_from_material`)."""
    if "lidar_material" in owner:
        return model_from_material(owner["lidar_material"], None, None, where)
    material = next((slot.material for slot in getattr(owner, "material_slots", ()) if slot.material is not None), None)
    if material is None:
        return ""
    if "lidar_material" in material:
        return model_from_material(material["lidar_material"], None, None, f"{where}: material {material.name!r}")
    inputs = {}
    tree = getattr(material, "node_tree", None) if getattr(material, "use_nodes", False) else None
    for node in tree.nodes if tree is not None else ():
        if node.type == "BSDF_PRINCIPLED":
            inputs = {k: node.inputs[k].default_value for k in ("Roughness", "Metallic") if k in node.inputs and not node.inputs[k].is_linked}
            break
    else:  # no node tree: the viewport's values
        inputs = {"Roughness": material.roughness, "Metallic": material.metallic}
    return model_from_material(None, inputs.get("Roughness"), inputs.get("Metallic"), f"{where}: material {material.name!r}")


def _albedo(material) -> float:
    """Mean of the linear R, G, B of a material's base colour, clipped to 0..1."""
    rgba = material.diffuse_color
    tree = getattr(material, "node_tree", None)
    if tree is not None:
        for node in tree.nodes:
            socket = node.inputs.get("Base Color") if node.type == "BSDF_PRINCIPLED" else None
            if socket is not None and not socket.is_linked:
                rgba = socket.default_value
                break
    return float(min(max((rgba[0] + rgba[1] + rgba[2]) / 3.0, 0.0), 1.0))


class _Labeller:
    """Builds the object table: one row per owner object, validated against the class table."""

    def __init__(self, table: ClassTable, extra_rules=()):
        self.table = table
        self.rules = tuple(extra_rules)
        self.rows: dict[str, dict] = {}

    def row(self, owner, names: list[str], instance: int = 0) -> int:
        """The row of ``owner``; of its geometry labelled ``instance`` (> 0, from a named attribute) when that differs from its tag."""
        split = instance > 0 and instance != owner.get("lidar_instance")
        key = f"{owner.name_full}#{instance}" if split else owner.name_full
        if key not in self.rows:
            described = self._describe(owner, names)
            if split:
                described |= {"name": f"{owner.name}#{instance}", "instance": int(instance)}
            self.rows[key] = described | {"index": len(self.rows)}
        return self.rows[key]["index"]

    def part_row(self, owner, names: list[str], part: str) -> int:
        """The row of ``owner``'s geometry named ``part`` (:data:`PART_ATTRIBUTE`): labelled as an object ``part`` of
        ``owner``'s tags would be (its own automatic instance id, by its name)."""
        key = f"{owner.name_full}/{part}"
        if key not in self.rows:
            self.rows[key] = self._describe(owner, names) | {"name": part, "index": len(self.rows)}
        return self.rows[key]["index"]

    def _describe(self, owner, names: list[str]) -> dict:
        where = f"object {owner.name!r}"
        if "lidar_class" in owner:
            class_name = str(owner["lidar_class"])
            semantic = self.table.id_of(class_name, f"{where}: lidar_class")
        else:
            class_name = next((r.class_name for r in self.rules if r.applies(names)), None) or self.table.classify(names)
            semantic = self.table.id_of(class_name, where)
        material = str(owner.get("lidar_material", "diffuse"))
        surface = _surface(owner, where)
        if material in MATERIAL_MODELS:  # a reflectance model on a diffuse surface (lidar/effects/materials.py)
            material = "diffuse"
        if material not in MATERIAL_ID:
            raise InputError(f"{where}: lidar_material {material!r} is not one of {', '.join(MATERIALS + tuple(MATERIAL_MODELS))}")
        reflectivity = _reflectivity(owner, where)
        instance = owner.get("lidar_instance")
        if instance is not None and (not isinstance(instance, int) or instance < 1):
            raise InputError(f"{where}: lidar_instance must be a positive integer, got {instance!r}")
        parent = names[1] if len(names) > 1 else ""
        return {
            "name": owner.name,
            "parent": parent,
            "class": self.table.names[semantic],
            "semantic": semantic,
            "instance": instance,
            "material": MATERIAL_ID[material],
            "reflectivity": reflectivity,
            "surface": model_id(surface),
        }

    def table_out(self) -> ObjectTable:
        rows = sorted(self.rows.values(), key=lambda r: r["index"])
        taken = {r["instance"] for r in rows if r["instance"] is not None}
        auto = (i for i in range(1, len(rows) + len(taken) + 2) if i not in taken)
        # Automatic instance ids follow the object names, so they do not depend on evaluation order.
        for r in sorted((r for r in rows if r["instance"] is None), key=lambda r: r["name"]):
            r["instance"] = next(auto)
        return ObjectTable(
            names=[r["name"] for r in rows],
            parents=[r["parent"] for r in rows],
            class_names=[r["class"] for r in rows],
            semantic=np.array([r["semantic"] for r in rows], np.uint16),
            instance=np.array([r["instance"] for r in rows], np.uint32),
            material=np.array([r["material"] for r in rows], np.uint8),
            reflectivity=np.array([r["reflectivity"] for r in rows], np.float32),
            surface=np.array([r["surface"] for r in rows], np.uint8),
        )


def export_scene(table: ClassTable, extra_rules=(), depsgraph=None, keep_within=None, only: str | None = None, skip: str | None = None) -> SceneBuffers:
    """Triangles of every visible, renderable object of the evaluated scene, in world coordinates.

    table : the class table (``labels.load_class_table()``)
    extra_rules : name rules tried before the table's own
    keep_within : optional ``(centre (3,), radius)`` in metres; objects whose bounds lie wholly
        farther than ``radius`` from ``centre`` are not exported (beyond the sensor's range)
    only, skip : the name of a collection: export only the geometry whose owner (the object that labels it) is in it
        (or in a collection inside it), or all but that geometry; a builder's objects placed anew every frame
        (:attr:`~bpy_pipeline.builders.base.BuildResult.dynamic`) and the rest, exported once
    """
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    chosen = {name: {obj.name_full for obj in bpy.data.collections[name].all_objects} for name in (only, skip) if name is not None}
    labeller = _Labeller(table, extra_rules)
    meshes: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    placements: dict[tuple, list[np.ndarray]] = defaultdict(list)  # (mesh key, row) -> world matrices
    instancers: dict[str, list] = {}  # instancer -> [its instances' id by index, or None; instances seen]
    bounds: dict[tuple, np.ndarray] = {}  # mesh key -> (8, 3) local bound box corners
    drawn_as_instance = _drawn_as_instance(depsgraph)
    for instance in depsgraph.object_instances:
        obj = instance.object
        if not instance.is_instance and obj.name_full in drawn_as_instance:
            continue  # a curve or text: its mesh comes again as its own instance, read there, once
        labelled = 0
        if instance.is_instance:  # the instancer's instances come in their order; its attribute read once, at the first
            seen = instancers.get(instance.parent.name_full)
            if seen is None:
                seen = instancers[instance.parent.name_full] = [instance_attribute(instance.parent, INSTANCE_ATTRIBUTE, "Instance"), 0]
            if seen[0] is not None:
                labelled = seen[0](seen[1])
            seen[1] += 1
        if obj.type not in GEOMETRY_TYPES or (not instance.is_instance and not instance.show_self):
            continue
        owner, names = _owner(instance)
        if owner.hide_render or (only is not None and owner.name_full not in chosen[only]) or (skip is not None and owner.name_full in chosen[skip]):
            continue
        matrix = np.array(instance.matrix_world, np.float64)
        key = _mesh_key(obj, instance.is_instance)
        if keep_within is not None:
            corners = bounds.get(key)
            if corners is None:  # read once per distinct evaluated mesh: the instances of a prototype share it
                corners = bounds[key] = np.array(obj.bound_box, np.float64)
            if not _near_corners(corners, matrix, *keep_within):
                continue
        if key not in meshes:
            meshes[key] = _mesh_arrays(obj)
        local, tris, ids, parts = meshes[key]
        if parts is not None and not labelled:  # named parts (a group's realized instances): one row per part, as if each were an object
            part_names = list(owner["lidar_parts"])
            for value in np.unique(parts).tolist():
                sub = (key, "part", value)
                if sub not in meshes:
                    chosen = tris[parts == value]
                    meshes[sub] = (local, chosen, None, None)
                    used = local[np.unique(chosen)]
                    bounds[sub] = np.array(list(itertools.product(*zip(used.min(axis=0), used.max(axis=0)))), np.float64)
                if keep_within is not None and not _near_corners(bounds[sub], matrix, *keep_within):
                    continue  # a part beyond the sensor's range, as an object of its own would be
                name = part_names[value - 1] if 0 < value <= len(part_names) else None
                placements[(sub, labeller.row(owner, names) if name is None else labeller.part_row(owner, names, name))].append(matrix)
        elif ids is not None and not labelled:  # faces labelled one by one: one part per id
            for value in np.unique(ids).tolist():
                if (key, value) not in meshes:
                    meshes[(key, value)] = (local, tris[ids == value], None, None)
                placements[((key, value), labeller.row(owner, names, value))].append(matrix)
        elif len(tris):
            placements[(key, labeller.row(owner, names, labelled))].append(matrix)

    return _assembled(meshes, placements, labeller)


class _Tags(dict):
    """The ``lidar_*`` properties of an object that is not in Blender (:func:`parts_buffers`), read as an object's are."""

    def __init__(self, name: str, properties: dict):
        super().__init__(properties)
        self.name = self.name_full = name


def parts_buffers(table: ClassTable, parts, extra_rules=(), keep_within=None) -> SceneBuffers:
    """What :func:`export_scene` gives for plain mesh objects with no parent, modifier or transform, tagged by
    :func:`~.mesh_objects.tag` and filled by :func:`~.mesh_objects.fill_mesh`, from their arrays: the same rows
    and bytes without reading them back from Blender (a builder's objects placed every frame, ``tests/test_street_users.py``).

    parts : ``[(name, lidar properties {"lidar_class": ..., ...}, vertices (n, 3) world, triangles (m, 3))]`` in the
        objects' order; vertices are rounded to float32 as a mesh stores them
    keep_within : as :func:`export_scene`

    The parts' vertices are rounded, bounded and joined as one array (a street frame's 150 parts: one pass each, not
    a dozen array calls a part); the rows, their order and the bytes are those of one part at a time.
    """
    labeller = _Labeller(table, extra_rules)
    parts = [part for part in parts if len(part[3])]
    vertices = [np.asarray(v, np.float32).reshape(-1, 3) for _, _, v, _ in parts]
    counts = np.array([len(v) for v in vertices], np.int64)
    if not parts or not counts.all() or len({part[0] for part in parts}) < len(parts):
        return _parts_one_by_one(labeller, parts, keep_within)  # nothing to join, a part without vertices, or two of one name
    every = np.concatenate(vertices).astype(np.float64)  # (n, 3) the parts' float32 vertices, one after another
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    kept = np.ones(len(parts), bool)
    if keep_within is not None:
        kept = _near_bounds_each(np.minimum.reduceat(every, starts), np.maximum.reduceat(every, starts), *keep_within)
    rows = []
    for (name, properties, _, _), keep in zip(parts, kept.tolist()):
        if keep:
            rows.append(labeller.row(_Tags(name, properties), [name]))
    if not rows:
        return _assembled({}, {}, labeller)
    chosen = np.flatnonzero(kept)
    triangles = [np.asarray(parts[i][3], np.int32).reshape(-1, 3) for i in chosen]
    sizes = np.array([len(t) for t in triangles], np.int64)
    offsets = np.cumsum(counts[chosen]) - counts[chosen]  # each kept part's first row among the kept vertices
    # placed by the identity: the world vertices are the local ones plus 0.0, the bits an identity placement's einsum
    # gives finite coordinates (each times 1 plus the others times 0: exact, and a -0.0 comes out +0.0; a
    # non-finite vertex is refused by SceneBuffers.check either way, naming the same object)
    joined = every if kept.all() else every[np.repeat(kept, counts)]
    joined += 0.0
    return SceneBuffers(joined, np.concatenate(triangles) + np.repeat(offsets, sizes).astype(np.int32)[:, None],
                        np.repeat(np.array(rows, np.int32), sizes), labeller.table_out())


def _parts_one_by_one(labeller: _Labeller, parts, keep_within) -> SceneBuffers:
    """:func:`parts_buffers` a part at a time: a part without vertices (refused by :meth:`SceneBuffers.check`, naming it),
    or parts of one name (one object: the first one's row, the last one's mesh)."""
    meshes: dict[tuple, tuple] = {}
    placements: dict[tuple, list[np.ndarray] | None] = {}
    for name, properties, vertices, triangles in parts:
        local = np.asarray(vertices, np.float32).reshape(-1, 3).astype(np.float64)
        if keep_within is not None and not _near_bounds(local.min(axis=0, initial=np.inf), local.max(axis=0, initial=-np.inf), *keep_within):
            continue
        local += 0.0
        meshes[(name, "")] = (local, np.asarray(triangles, np.int32).reshape(-1, 3), None, None)
        placements[((name, ""), labeller.row(_Tags(name, properties), [name]))] = None
    return _assembled(meshes, placements, labeller)


def _assembled(meshes: dict, placements: dict, labeller: _Labeller) -> SceneBuffers:
    """The buffers of ``placements`` ({(mesh key, row): [world matrices (4, 4)]}, or ``None`` for a mesh whose vertices
    are world already) of ``meshes`` ({key: (local vertices, triangles, ...)})."""
    vertices, triangles, triangle_object, offset = [], [], [], 0
    for (key, row), matrices in placements.items():
        local, tris = meshes[key][:2]
        if matrices is None:
            vertices.append(local)
            triangles.append(tris + np.int32(offset))
            triangle_object.append(np.full(len(tris), row, np.int32))
            offset += len(local)
            continue
        stack = np.asarray(matrices)  # (g, 4, 4)
        world = np.einsum("gij,nj->gni", stack[:, :3, :3], local) + stack[:, None, :3, 3]
        vertices.append(world.reshape(-1, 3))
        copies = tris[None] + (np.arange(len(stack)) * len(local))[:, None, None]
        triangles.append(copies.reshape(-1, 3) + offset)
        triangle_object.append(np.full(len(stack) * len(tris), row, np.int32))
        offset += len(stack) * len(local)
    objects = labeller.table_out()
    if not vertices:
        return SceneBuffers(np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros(0, np.int32), objects)
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32, copy=False), np.concatenate(triangle_object), objects)


def _drawn_as_instance(depsgraph) -> set[str]:
    """Names of the non-mesh objects (a bevelled curve, an extruded text, a curve with a Geometry Nodes
    modifier) whose evaluated mesh the depsgraph lists twice: as the object itself (``to_mesh`` gives that
    mesh) and as an instance of the object's own geometry (instance object named as its instancer). Read
    only as the instance, so its triangles are not in the scene twice (42 % of a default railway's
    triangles were: its wires; every bevelled curve and text of a user's .blend was)."""
    candidates = {obj.name_full for obj in depsgraph.scene_eval.objects if obj.type in GEOMETRY_TYPES - {"MESH"}}
    if not candidates:
        return set()
    return {
        instance.parent.name_full
        for instance in depsgraph.object_instances
        if instance.is_instance
        and instance.parent.name_full in candidates
        and instance.object.type == "MESH"
        and instance.object.name_full == instance.parent.name_full
    }


def _mesh_key(obj, is_instance: bool) -> tuple:
    """The key of an evaluated object's geometry: objects with equal keys have equal evaluated meshes (read once a frame).

    An instance's: its evaluated data. An object's own: its evaluated data and its name, since modifiers,
    shape keys and deforming parents make one mesh evaluate differently per object; a mesh object with none
    evaluates to its mesh (objects sharing a mesh share its evaluated copy), so it shares its data's key with
    every object of that data (the parking's car slots of one style: read once a frame, not once a car).
    """
    pointer = obj.data.as_pointer()
    if is_instance:
        return (pointer, "")
    original = obj.original
    # not an armature, lattice or curve child: Blender deforms those by a virtual modifier the list does not show
    if obj.type == "MESH" and not original.modifiers and getattr(original.data, "shape_keys", None) is None and original.parent_type not in VIRTUAL_DEFORM:
        return (pointer, "")
    return (pointer, obj.name_full)


def _near(obj, matrix: np.ndarray, centre, radius: float) -> bool:
    """Whether ``obj``'s bounds placed by ``matrix`` (4, 4) come within ``radius`` m of ``centre`` (3,)."""
    return _near_corners(np.array(obj.bound_box, np.float64), matrix, centre, radius)


def _near_corners(local: np.ndarray, matrix: np.ndarray, centre, radius: float) -> bool:
    """:func:`_near` of an object's bound box corners ``local`` (8, 3) in its own frame."""
    corners = local @ matrix[:3, :3].T + matrix[:3, 3]
    return _near_bounds(corners.min(axis=0), corners.max(axis=0), centre, radius)


def _near_bounds(low: np.ndarray, high: np.ndarray, centre, radius: float) -> bool:
    """Whether the world bounds ``low``, ``high`` (3,) come within ``radius`` m of ``centre`` (3,)."""
    nearest = np.minimum(np.maximum(np.asarray(centre, float), low), high)  # np.clip's values, without its dispatch
    return float(np.linalg.norm(nearest - centre)) <= radius


def _near_bounds_each(low: np.ndarray, high: np.ndarray, centre, radius: float) -> np.ndarray:
    """``(k,)`` bool: :func:`_near_bounds` of each of ``k`` bounds ``low``, ``high`` (k, 3), in one pass; the few whose
    distance lies within a rounding of ``radius`` are asked of :func:`_near_bounds` itself (its norm may round apart)."""
    centre = np.asarray(centre, float)
    gap = np.minimum(np.maximum(centre, low), high) - centre
    distance = np.sqrt(np.einsum("ij,ij->i", gap, gap))
    near = distance <= radius
    for k in np.flatnonzero(~(np.abs(distance - radius) > 1e-9 * max(abs(radius), 1.0))):  # nan too
        near[k] = _near_bounds(low[k], high[k], centre, radius)
    return near
