"""What can be inserted into a real scan: the object-type registry and mesh files. Pure numpy (no bpy, no trimesh).

An object's ``type`` is a procedural type of :data:`~bpy_pipeline.geometry.objects.OBJECT_TYPES`
(``car``, ``person``, ``cyclist``, ``robot_arm``, ``box``) or the path of a mesh file, read by
the reader :data:`MESH_READERS` holds for its suffix (``.glb``, ``.gltf``, ``.obj``, ``.ply``).

A mesh file becomes up to two parts: a ``glass`` part (the faces whose material name contains
``glass`` or ``window``, any case, or whose glTF material has ``KHR_materials_transmission``) and
a diffuse part (every other face). PLY files name no materials: all diffuse.

Axes: glTF files are read in the glTF convention (+Y up, the asset's front +Z) and turned into the
insertion frame (x forward, y left, z up); OBJ and PLY files are read as they are (x forward, z up).
A file's class (``scene.objects[].class`` unset) comes from its name by the class table's name
rules (``car_sedan.glb``: car; ``pedestrian.obj``: person), else ``unlabeled``; its nominal size
(``size`` unset) is the file's own bounding box in metres.
"""

from __future__ import annotations

import base64
import json
import re
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from ..errors import InputError, require
from ..io.confined import readable_inside
from ..geometry.checks import check_mesh
from ..geometry.objects import GLASS_REFLECTIVITY, OBJECT_TYPES, ObjectPart, fit_to_box

GLASS_NAME = re.compile("glass|window", re.IGNORECASE)
# glTF (x right-of-viewer / the asset's left, y up, z the asset's front) -> insertion frame (x front, y left, z up)
GLTF_TO_SENSOR = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

MAX_BUFFER_BYTES = 1 << 30  # a glTF buffer file larger than this is refused (no mesh to insert into a scan needs a GB)
Group = tuple[np.ndarray, list, str]  # vertices (n, 3) float64, faces (lists of vertex indices), material name ("glass" if glass)


# ----------------------------------------------------------------------------- readers: path -> [(vertices, faces, material)]
def read_ply_groups(p: Path) -> list[Group]:
    """A PLY mesh (``vertex`` x y z and ``face`` vertex indices) as one diffuse group."""
    PlyData = require("plyfile", "mixing", f"{p}: reading a PLY mesh").PlyData

    try:
        ply = PlyData.read(str(p))
        vertex, face = ply["vertex"], ply["face"]
        v = np.column_stack([vertex[k] for k in "xyz"]).astype(np.float64)
        faces = [np.asarray(f, np.int64) for f in face.data[face.data.dtype.names[0]]]
    except Exception as err:  # plyfile raises many types on a lying header or short data
        raise InputError(
            f"{p}: not a readable PLY mesh with vertex x y z and faces ({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})"
        ) from None
    return [(v, faces, "")]


def read_obj_groups(p: Path) -> list[Group]:
    """Vertices and faces of an OBJ (``v`` and ``f`` lines; 1-based or negative relative indices), grouped by ``usemtl``."""
    verts, groups, material = [], {}, ""
    try:
        text = p.read_text(errors="replace")
    except OSError as err:
        raise InputError(f"{p}: cannot read ({err.strerror or err})") from None
    for number, line in enumerate(text.splitlines(), 1):
        words = line.split()
        try:
            if words[:1] == ["v"]:
                verts.append([float(x) for x in words[1:4]])
                if len(verts[-1]) != 3:
                    raise ValueError
            elif words[:1] == ["usemtl"]:
                material = " ".join(words[1:])
            elif words[:1] == ["f"]:
                face = []
                for w in words[1:]:
                    k = int(w.split("/")[0])
                    if k == 0:
                        raise ValueError
                    face.append(k - 1 if k > 0 else len(verts) + k)  # OBJ: 1-based, or negative from the last vertex
                groups.setdefault(material, []).append(np.array(face, np.int64))
        except ValueError:
            raise InputError(f"{p}: line {number}: malformed {words[0]!r} line {line.strip()[:60]!r}") from None
    v = np.asarray(verts, float).reshape(-1, 3)
    return [(v, faces, name) for name, faces in groups.items()] or [(v, [], "")]


_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _gltf_document(p: Path) -> tuple[dict, list[bytes]]:
    """The JSON document of a .glb or .gltf and its buffers' bytes (GLB's BIN chunk, data URIs, files beside it)."""
    data = p.read_bytes()
    chunk = None
    if p.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise ValueError("no glTF binary header")
        version, _ = struct.unpack_from("<II", data, 4)
        if version != 2:
            raise ValueError(f"glTF version {version} (2 is read)")
        offset, doc = 12, None
        while offset + 8 <= len(data):
            length, kind = struct.unpack_from("<II", data, offset)
            body = data[offset + 8 : offset + 8 + length]
            if len(body) != length:
                raise ValueError("a chunk runs past the end of the file")
            if kind == 0x4E4F534A:
                doc = json.loads(body.decode("utf-8"))
            elif kind == 0x004E4942 and chunk is None:
                chunk = bytes(body)
            offset += 8 + length
        if doc is None:
            raise ValueError("no JSON chunk")
    else:
        doc = json.loads(data.decode("utf-8"))
    buffers = []
    for k, buf in enumerate(doc.get("buffers", [])):
        uri = buf.get("uri")
        if uri is None:
            if chunk is None:
                raise ValueError(f"buffer {k} has no uri and the file no BIN chunk")
            buffers.append(chunk)
        elif uri.startswith("data:"):
            buffers.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            found, why = readable_inside(p.parent, unquote(str(uri)), MAX_BUFFER_BYTES)
            if found is None:
                raise InputError(f"{p}: buffers[{k}].uri {uri!r} is {why}; a glTF's buffers are data URIs or files in its folder")
            buffers.append(found.read_bytes())
    return doc, buffers


def _accessor(doc: dict, buffers: list[bytes], index: int) -> np.ndarray:
    """Accessor ``index`` as an array ``(count, width)`` (or ``(count,)`` for scalars)."""
    acc = doc["accessors"][index]
    if "sparse" in acc or "bufferView" not in acc:
        raise ValueError(f"accessor {index}: sparse or view-less accessors are not read")
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = np.dtype(_COMPONENT[acc["componentType"]]).newbyteorder("<")
    width, count = _WIDTH[acc["type"]], int(acc["count"])
    start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
    stride = int(view.get("byteStride", 0)) or width * dtype.itemsize
    raw = buffers[view["buffer"]]
    end = start + stride * (count - 1) + width * dtype.itemsize if count else start
    if end > len(raw) or end - int(view.get("byteOffset", 0)) > int(view["byteLength"]):
        raise ValueError(f"accessor {index} runs past its buffer view")
    rows = np.frombuffer(raw, np.uint8, count=end - start, offset=start) if count else np.zeros(0, np.uint8)
    out = np.lib.stride_tricks.as_strided(rows, (count, width * dtype.itemsize), (stride, 1)) if count else np.zeros((0, width * dtype.itemsize), np.uint8)
    values = np.ascontiguousarray(out).view(dtype).reshape(count, width)
    return values[:, 0] if acc["type"] == "SCALAR" else values


def _node_matrix(node: dict) -> np.ndarray:
    """``(4, 4)`` local transform of a glTF node (``matrix``, column-major, or translation, rotation xyzw, scale)."""
    if "matrix" in node:
        return np.asarray(node["matrix"], float).reshape(4, 4).T
    x, y, z, w = node.get("rotation", (0.0, 0.0, 0.0, 1.0))
    rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = rotation * np.asarray(node.get("scale", (1.0, 1.0, 1.0)), float)
    m[:3, 3] = node.get("translation", (0.0, 0.0, 0.0))
    return m


def _triangles(mode: int, idx: np.ndarray) -> np.ndarray:
    """``(t, 3)`` triangles of a primitive of ``mode`` (4 list, 5 strip, 6 fan); points and lines give none."""
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if mode == 5:
        k = np.arange(max(len(idx) - 2, 0))
        tri = np.stack([idx[k], idx[k + 1], idx[k + 2]], 1)
        tri[k % 2 == 1] = tri[k % 2 == 1][:, [1, 0, 2]]  # every other strip triangle flips to keep the winding
        return tri
    if mode == 6:
        k = np.arange(1, max(len(idx) - 1, 1))
        return np.stack([np.full(len(k), idx[0]), idx[k], idx[k + 1]], 1) if len(idx) >= 3 else np.zeros((0, 3), np.int64)
    return np.zeros((0, 3), np.int64)


def read_gltf_groups(p: Path) -> list[Group]:
    """The triangles of a glTF 2.0 file (.glb or .gltf) in the default scene, node transforms applied, turned into the
    insertion frame (:data:`GLTF_TO_SENSOR`), grouped by material (glass: the name, or ``KHR_materials_transmission``)."""
    try:
        doc, buffers = _gltf_document(p)
        materials = doc.get("materials", [])
        glass = [bool(GLASS_NAME.search(m.get("name", ""))) or "KHR_materials_transmission" in m.get("extensions", {}) for m in materials]
        nodes = doc.get("nodes", [])
        scenes = doc.get("scenes", [])
        if scenes:
            roots = list(scenes[int(doc.get("scene", 0))].get("nodes", []))
        else:
            children = {c for n in nodes for c in n.get("children", [])}
            roots = [k for k in range(len(nodes)) if k not in children]
        groups: dict[bool, tuple[list, list, int]] = {}
        stack, seen = [(k, np.eye(4), 0) for k in roots], set()
        while stack:
            k, parent, depth = stack.pop()
            if depth > 64:
                raise ValueError("node hierarchy deeper than 64 (a cycle?)")
            if k in seen:  # glTF's nodes are trees: a node reached twice would be walked once per path to it
                raise ValueError(f"node {k} is reached twice; a node has at most one parent")
            seen.add(k)
            node = nodes[k]
            world = parent @ _node_matrix(node)
            stack.extend((c, world, depth + 1) for c in node.get("children", []))
            if "mesh" not in node:
                continue
            for prim in doc["meshes"][node["mesh"]]["primitives"]:
                position = _accessor(doc, buffers, prim["attributes"]["POSITION"]).astype(np.float64)
                idx = _accessor(doc, buffers, prim["indices"]).astype(np.int64) if "indices" in prim else np.arange(len(position))
                tri = _triangles(int(prim.get("mode", 4)), idx)
                if not len(tri):
                    continue
                v = (position @ world[:3, :3].T + world[:3, 3]) @ GLTF_TO_SENSOR.T
                if np.linalg.det(world[:3, :3]) < 0:
                    tri = tri[:, [0, 2, 1]]  # a mirroring node keeps the faces' outward winding
                is_glass = "material" in prim and glass[int(prim["material"])]
                verts, faces, offset = groups.get(is_glass, ([], [], 0))
                verts.append(v)
                faces.append(tri + offset)
                groups[is_glass] = (verts, faces, offset + len(v))
    except InputError:
        raise
    except OSError as err:
        raise InputError(f"{p}: cannot read ({err.strerror or err})") from None
    except Exception as err:  # JSON, keys, indices, struct: a lying file, one line
        raise InputError(f"{p}: not a readable glTF 2.0 mesh ({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})") from None
    return [(np.concatenate(v), list(np.concatenate(f)), "glass" if g else "") for g, (v, f, _) in sorted(groups.items())]


# suffix -> reader(path) -> [(vertices (n, 3), faces, material name)]
MESH_READERS = {".ply": read_ply_groups, ".obj": read_obj_groups, ".glb": read_gltf_groups, ".gltf": read_gltf_groups}


def _mesh_file(path: str, where: str) -> Path:
    p = Path(path)
    if p.suffix.lower() not in MESH_READERS:
        raise InputError(f"{where}: {path!r} is neither one of {', '.join(OBJECT_TYPES)} nor a mesh file ({', '.join(MESH_READERS)})")
    if not p.is_file():
        raise InputError(f"{where}: {path!r} is neither one of {', '.join(OBJECT_TYPES)} nor an existing mesh file")
    return p


def _file_parts(p: Path) -> list[ObjectPart]:
    """The parts of a mesh file at its own size and place (diffuse, then glass when it has glass), each holding
    only the vertices its faces use."""
    groups = MESH_READERS[p.suffix.lower()](p)
    parts = {}
    for v, faces, material in groups:
        if any(len(f) < 3 for f in faces):
            raise InputError(f"{p}: a face with fewer than 3 vertices")
        triangles = np.array([[f[0], f[k], f[k + 1]] for f in faces for k in range(1, len(f) - 1)], np.int64).reshape(-1, 3)
        if not len(triangles):
            continue
        v, triangles = check_mesh(v, triangles, str(p))
        used, triangles = np.unique(triangles, return_inverse=True)
        v, triangles = v[used], triangles.reshape(-1, 3)
        kind = "glass" if GLASS_NAME.search(material) else "diffuse"
        parts.setdefault(kind, []).append((v, triangles))
    if not parts:
        raise InputError(f"scene.objects.type: {str(p)!r} has no faces")
    out = []
    for kind in sorted(parts):  # diffuse, glass
        vs, ts, offset = [], [], 0
        for v, t in parts[kind]:
            vs.append(v)
            ts.append(t + offset)
            offset += len(v)
        out.append(ObjectPart(np.concatenate(vs), np.concatenate(ts).astype(np.int32), kind, GLASS_REFLECTIVITY if kind == "glass" else 0.5))
    return out


def file_parts(path: str, where: str = "scene.objects.type") -> list[ObjectPart]:
    """A mesh file's parts at the file's own size and place (see the module notes); ``InputError`` naming ``where``."""
    p = _mesh_file(path, where)
    return _file_parts(p)


def mesh_file_parts(path: str, size) -> list[ObjectPart]:
    """A user mesh (.glb, .gltf, .obj or .ply) as a diffuse part and a glass part (when it has glass) scaled to the
    box ``size``; a file whose header, indices or values lie is refused with one line naming it."""
    return fit_to_box(file_parts(path), size)


# ----------------------------------------------------------------------------- the registry's questions
def check_type(kind: str, where: str) -> None:
    """``InputError`` naming ``where`` unless ``kind`` is a procedural type or a readable mesh file."""
    if kind not in OBJECT_TYPES:
        file_parts(kind, where)


def type_class(kind: str) -> str:
    """The class an object of ``kind`` gets when none is given: the type's, or a file's by its name (module notes)."""
    if kind in OBJECT_TYPES:
        return OBJECT_TYPES[kind][0]
    from ..labels import load_class_table

    return load_class_table().classify([Path(kind).stem])


def type_size(kind: str) -> np.ndarray:
    """``(3,)`` nominal length, width, height (m): the type's, or a mesh file's own bounding box (1 m cube if unreadable)."""
    if kind in OBJECT_TYPES:
        return np.asarray(OBJECT_TYPES[kind][2], float)
    try:
        v = np.concatenate([part.vertices for part in file_parts(kind)])
    except InputError:
        return np.ones(3)
    return np.maximum(v.max(axis=0) - v.min(axis=0), 1e-3)
