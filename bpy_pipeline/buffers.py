"""Scene buffers: the one type that crosses the bpy boundary (docs/layout.md, "A frame's path through the stages").

``blender/export.py`` fills them from Blender's evaluated depsgraph; everything after that (scanner,
effects, writers) reads only these numpy arrays and never imports bpy.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

MATERIALS = ("diffuse", "mirror", "glass", "absorber")
MATERIAL_ID = {name: i for i, name in enumerate(MATERIALS)}


@dataclass
class ObjectTable:
    """One row per exported object (``k`` rows).

    names, parents, class_names : list[str] of length k (parent ``""`` for none)
    semantic : (k,) uint16 raw class id (assets_manifest/labels.yaml)
    instance : (k,) uint32 instance id (>= 1)
    material : (k,) uint8 index into :data:`MATERIALS`
    reflectivity : (k,) float32 in 0..1
    surface : (k,) uint8 reflectance model of each object (lidar/effects/materials.py ``model_id``: 0 none), or None
    """

    names: list[str]
    parents: list[str]
    class_names: list[str]
    semantic: np.ndarray
    instance: np.ndarray
    material: np.ndarray
    reflectivity: np.ndarray
    surface: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.names)

    def rows(self) -> list[dict]:
        """The table as a list of plain dicts (for the manifest)."""
        return [
            {
                "name": self.names[i],
                "parent": self.parents[i],
                "class": self.class_names[i],
                "semantic": int(self.semantic[i]),
                "instance": int(self.instance[i]),
                "material": MATERIALS[self.material[i]],
                "reflectivity": round(float(self.reflectivity[i]), 6),
            }
            for i in range(len(self))
        ]


@dataclass
class SceneBuffers:
    """Triangles of the evaluated scene in world coordinates.

    vertices : (n, 3) float64, metres, world frame
    triangles : (m, 3) int32 indices into ``vertices``
    triangle_object : (m,) int32 row of :attr:`objects` each triangle belongs to
    objects : :class:`ObjectTable`
    leading : the buffers these begin with when :meth:`joined` made them (their rows first, as they are), else ``None``;
        :meth:`check` checks them on their own once (a static world joined to each frame's moving objects), then only the rest
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_object: np.ndarray
    objects: ObjectTable
    leading: "SceneBuffers | None" = field(default=None, repr=False, compare=False)
    checked_alone: bool = field(default=False, repr=False, compare=False)  # set once a check of joined buffers checked these on their own

    @classmethod
    def from_meshes(cls, meshes: dict, reflectivity: float = 0.5) -> "SceneBuffers":
        """Buffers of named numpy meshes, one object each, for scenes built without Blender (tests, benchmarks).

        meshes : {name: (vertices (n, 3) float64 world metres, triangles (m, 3) int indices)}, in object order
        Every object is ``unlabeled`` (semantic 0), ``diffuse``, of ``reflectivity``; instance ids 1..k.
        """
        names = list(meshes)
        vertices, triangles, rows, offset = [], [], [], 0
        for row, (v, t) in enumerate(meshes.values()):
            v, t = np.asarray(v, np.float64).reshape(-1, 3), np.asarray(t, np.int64).reshape(-1, 3)
            vertices.append(v)
            triangles.append(t + offset)
            rows.append(np.full(len(t), row, np.int32))
            offset += len(v)
        k = len(names)
        objects = ObjectTable(
            names, [""] * k, ["unlabeled"] * k, np.zeros(k, np.uint16), np.arange(1, k + 1, dtype=np.uint32),
            np.full(k, MATERIAL_ID["diffuse"], np.uint8), np.full(k, reflectivity, np.float32),
        )
        if not names:
            return cls(np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros(0, np.int32), objects)
        return cls(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(rows), objects)

    def joined(self, other: "SceneBuffers") -> "SceneBuffers":
        """These buffers, then ``other``'s: vertices, triangles and object rows of ``other`` after these (its indices
        moved past them). Instance ids are kept as each table has them. These buffers are the result's :attr:`leading`
        ones: they must not change in place while it is used (a check of them is remembered on them)."""
        a, b = self.objects, other.objects
        surface = None if a.surface is None or b.surface is None else np.concatenate([a.surface, b.surface])
        objects = ObjectTable(a.names + b.names, a.parents + b.parents, a.class_names + b.class_names, np.concatenate([a.semantic, b.semantic]),
                              np.concatenate([a.instance, b.instance]), np.concatenate([a.material, b.material]),
                              np.concatenate([a.reflectivity, b.reflectivity]), surface)
        return SceneBuffers(np.concatenate([self.vertices, other.vertices]),
                            np.concatenate([self.triangles, other.triangles + np.int32(len(self.vertices))]).astype(np.int32, copy=False),
                            np.concatenate([self.triangle_object, other.triangle_object + np.int32(len(a))]).astype(np.int32, copy=False), objects,
                            leading=self)

    def check(self) -> None:
        """``InputError`` for an empty scene, non-finite vertices or triangle indices out of range (naming the object).

        Buffers :meth:`joined` made check their :attr:`leading` buffers on their own the first time (remembered on
        those: :attr:`checked_alone`), then only their own triangles and vertices after those: a valid leading part
        stays valid with rows added after it."""
        m = len(self.triangles)
        if m == 0:
            raise InputError("scene: nothing to scan (no object with triangles); add geometry or check scene.builder")
        first, done = self.leading, (0, 0)  # triangles and vertices at the front known valid
        if first is not None and len(first.triangles):
            if not first.checked_alone:
                first.check()
                first.checked_alone = True
            done = (len(first.triangles), len(first.vertices))
        rows = np.asarray(self.triangle_object)
        rest = rows[done[0] :]
        if rows.shape != (m,) or rest.min(initial=0) < 0 or rest.max(initial=0) >= len(self.objects):
            raise InputError(f"scene buffers: triangle_object must give each of the {m} triangles a row of the {len(self.objects)}-row object table")
        triangles, vertices = self.triangles[done[0] :], self.vertices[done[1] :]
        if triangles.min(initial=0) < 0 or triangles.max(initial=0) >= len(self.vertices):
            out_of_range = (self.triangles < 0) | (self.triangles >= len(self.vertices))
            bad_triangle, corner = (int(i[0]) for i in np.nonzero(out_of_range))
            name = self.objects.names[rows[bad_triangle]]
            raise InputError(
                f"object {name!r}: a triangle refers to vertex {int(self.triangles[bad_triangle, corner])}, "
                f"but the scene has vertices 0..{len(self.vertices) - 1}; fix or remove its mesh"
            )
        if not np.isfinite(vertices.min(initial=0.0) + vertices.max(initial=0.0)):  # a NaN or an infinity spreads to one of them
            bad_vertex = ~np.isfinite(self.vertices).all(axis=1)
            bad_triangles = np.flatnonzero(bad_vertex[self.triangles].any(axis=1))
            if not len(bad_triangles):
                raise InputError(f"scene buffers: vertex {int(np.flatnonzero(bad_vertex)[0])} (in no triangle) has NaN or infinite coordinates; leave it out")
            name = self.objects.names[self.triangle_object[bad_triangles[0]]]
            raise InputError(f"object {name!r}: has NaN or infinite vertex coordinates; fix or remove it")
