"""Triangle meshes of simple solids, centred on the origin, outward-facing winding. Pure numpy.

Every function returns ``(vertices (n, 3) float64 metres, triangles (m, 3) int32)``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np


def plane(size_x: float, size_y: float):
    """A rectangle in z = 0, normal +z."""
    hx, hy = size_x / 2, size_y / 2
    vertices = np.array([[-hx, -hy, 0], [hx, -hy, 0], [hx, hy, 0], [-hx, hy, 0]], float)
    return vertices, np.array([[0, 1, 2], [0, 2, 3]], np.int32)


UNIT_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])  # (8, 3) a unit box's corners
UNIT_CORNERS.flags.writeable = False
BOX_TRIANGLES = np.array([t for a, b, c, d in [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
                          for t in ((a, b, c), (a, c, d))], np.int32)  # (12, 3) its faces, two triangles each
BOX_TRIANGLES.flags.writeable = False


def box(size_x: float, size_y: float, size_z: float):
    """An axis-aligned box: ``(vertices (8, 3), triangles (12, 3))``, new arrays."""
    return UNIT_CORNERS * [size_x, size_y, size_z], BOX_TRIANGLES.copy()


def prism(profile_yz: np.ndarray, x0: float, x1: float):
    """A convex profile (k, 2) in the y-z plane, counter-clockwise, extruded from x0 to x1, capped."""
    profile = np.asarray(profile_yz, float)
    k = len(profile)
    vertices = np.concatenate([np.column_stack([np.full(k, x), profile]) for x in (x0, x1)])
    i = np.arange(k)
    j = (i + 1) % k
    sides = np.concatenate([np.stack([i, j, k + j], 1), np.stack([i, k + j, k + i], 1)])  # wound outwards, as the caps are
    fan = np.arange(1, k - 1)
    caps = np.concatenate([np.stack([np.zeros_like(fan), fan + 1, fan], 1), np.stack([np.full_like(fan, k), k + fan, k + fan + 1], 1)])
    return vertices, np.concatenate([sides, caps]).astype(np.int32)


def uv_sphere(radius: float, segments: int = 64):
    """A UV sphere with ``segments`` meridians and ``segments // 2`` rings."""
    rings = max(segments // 2, 2)
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    body = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    vertices = np.concatenate([[[0, 0, 1]], body, [[0, 0, -1]]]) * radius
    s = segments
    j = np.arange(s)
    top = np.stack([np.zeros(s, int), 1 + j, 1 + (j + 1) % s], 1)
    last = len(vertices) - 1
    base = 1 + (rings - 2) * s
    bottom = np.stack([np.full(s, last), base + (j + 1) % s, base + j], 1)
    r = np.arange(rings - 2)[:, None]
    a, b = 1 + r * s + j, 1 + r * s + (j + 1) % s
    quads = np.concatenate([np.stack([a, a + s, b + s], -1).reshape(-1, 3), np.stack([a, b + s, b], -1).reshape(-1, 3)])
    return vertices, np.concatenate([top, quads, bottom]).astype(np.int32)


def cylinder(radius: float, height: float, segments: int = 64):
    """A capped cylinder along z."""
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.column_stack([np.cos(phi), np.sin(phi)]) * radius
    profile_vertices = np.concatenate([np.column_stack([ring, np.full(segments, z)]) for z in (-height / 2, height / 2)])
    vertices = np.concatenate([profile_vertices, [[0, 0, -height / 2], [0, 0, height / 2]]])
    return vertices, capped_ring_triangles(segments)


def capped_ring_triangles(sides: int) -> np.ndarray:
    """``(4 sides, 3)`` int32 triangles of a capped tube whose vertices are: the ``sides`` points of
    the first ring, those of the second ring (same order, counter-clockwise seen from the second
    end), the first end's centre, the second end's centre. Faces point outwards."""
    j = np.arange(sides)
    k = (j + 1) % sides
    s = sides
    walls = np.concatenate([np.stack([j, k, s + k], 1), np.stack([j, s + k, s + j], 1)])
    caps = np.concatenate([np.stack([np.full(s, 2 * s), k, j], 1), np.stack([np.full(s, 2 * s + 1), s + j, s + k], 1)])
    return np.concatenate([walls, caps]).astype(np.int32)


def merge(parts):
    """Concatenate ``[(vertices, triangles), ...]`` into one mesh."""
    vertices, triangles, offset = [], [], 0
    for v, t in parts:
        vertices.append(v)
        triangles.append(t + offset)
        offset += len(v)
    return np.concatenate(vertices), np.concatenate(triangles).astype(np.int32)


def translated(mesh, offset):
    """``(vertices + offset, triangles)``."""
    return mesh[0] + np.asarray(offset, float), mesh[1]


def box_mesh(x0, x1, y0, y1, z0, z1) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box from its bounds (m)."""
    return translated(box(x1 - x0, y1 - y0, z1 - z0), ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2))


def boxes_mesh(low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned boxes from their ``(k, 3)`` low and high corners (m), one mesh: ``merge`` of each one's
    :func:`box_mesh`, the same vertices, made at once."""
    low, high = np.asarray(low, float).reshape(-1, 3), np.asarray(high, float).reshape(-1, 3)
    corners, triangles = box(1.0, 1.0, 1.0)
    vertices = corners * (high - low)[:, None] + ((low + high) / 2)[:, None]
    return vertices.reshape(-1, 3), (triangles + 8 * np.arange(len(low), dtype=np.int32)[:, None, None]).reshape(-1, 3).astype(np.int32)


def wheel_mesh(x: float, y: float, radius: float, width: float, sides: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A wheel (a short cylinder, axis along y) touching the ground at ``(x, y)``."""
    v, t = wheel_shape(float(radius), float(width), int(sides))
    return v + [x, y, radius], t.copy()


def wheels_mesh(xy, radius: float, width: float, sides: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Wheels of one size touching the ground at ``xy`` ((k, 2) m), one mesh: ``merge`` of each one's :func:`wheel_mesh`,
    the same vertices, made at once."""
    v, t = wheel_shape(float(radius), float(width), int(sides))
    xy = np.asarray(xy, float).reshape(-1, 2)
    at = np.column_stack([xy, np.full(len(xy), radius)])  # (k, 3): what each wheel's vertices are moved by
    return (v[None] + at[:, None]).reshape(-1, 3), (t[None] + len(v) * np.arange(len(xy), dtype=np.int32)[:, None, None]).reshape(-1, 3).astype(np.int32)


def quads_mesh(quads) -> tuple[np.ndarray, np.ndarray]:
    """Quads from their corners ``(k, 4, 3)`` (m), one mesh: ``merge`` of each one's :func:`quad_mesh`."""
    corners = np.asarray(quads, float).reshape(-1, 4, 3)
    triangles = np.array([[0, 1, 2], [0, 2, 3]], np.int32)[None] + 4 * np.arange(len(corners), dtype=np.int32)[:, None, None]
    return corners.reshape(-1, 3), triangles.reshape(-1, 3).astype(np.int32)


@lru_cache(maxsize=64)
def wheel_shape(radius: float, width: float, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A wheel's cylinder with its axis along y, centred on the origin: ``(vertices (n, 3), triangles (m, 3))``, read only.

    Cached: a road user's wheels come in a few sizes, and every vehicle of a street frame has four.
    """
    v, t = cylinder(radius, width, sides)
    v, t = v[:, [0, 2, 1]], t[:, ::-1].copy()
    v.flags.writeable = t.flags.writeable = False
    return v, t


def beam_mesh(p0, p1, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """A square beam of ``thickness`` (m) from ``p0`` to ``p1`` (3,).

    Lengths are ``np.linalg.norm``'s numbers (the root of the vector's dot with itself), cross products ``np.cross``'s
    (:func:`~.collision._cross3`), without their general-shape set-up: a frame's bicycles have six beams each.
    """
    from .collision import _cross3

    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    axis = p1 - p0
    length = math.sqrt(axis.dot(axis))
    w = axis / length
    u = _cross3(w, np.array([0.0, 1.0, 0.0] if abs(w[1]) < 0.9 else [1.0, 0.0, 0.0]))
    u /= math.sqrt(u.dot(u))
    v, t = box(thickness, thickness, length)
    return v @ np.column_stack([u, _cross3(w, u), w]).T + (p0 + p1) / 2, t


def beams_mesh(p0, p1, thickness) -> tuple[np.ndarray, np.ndarray]:
    """Square beams from ``p0`` to ``p1`` ((n, 3) m each), ``thickness`` (m, a number or (n,)), one mesh: ``merge`` of each
    one's :func:`beam_mesh` (the same vertices up to rounding), made at once."""
    p0, p1 = np.asarray(p0, float).reshape(-1, 3), np.asarray(p1, float).reshape(-1, 3)
    n = len(p0)
    thickness = np.broadcast_to(np.asarray(thickness, float), (n,))
    axis = p1 - p0
    length = np.linalg.norm(axis, axis=1)
    w = axis / length[:, None]
    u = np.cross(w, np.where((np.abs(w[:, 1]) < 0.9)[:, None], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]))
    u /= np.linalg.norm(u, axis=1)[:, None]
    corners, triangles = box(1.0, 1.0, 1.0)
    local = corners[None] * np.column_stack([thickness, thickness, length])[:, None]  # (n, 8, 3) in each beam's axes
    vertices = local[..., :1] * u[:, None] + local[..., 1:2] * np.cross(w, u)[:, None] + local[..., 2:] * w[:, None] + ((p0 + p1) / 2)[:, None]
    return vertices.reshape(-1, 3), (triangles + 8 * np.arange(n, dtype=np.int32)[:, None, None]).reshape(-1, 3).astype(np.int32)


def quad_mesh(a, b, c, d) -> tuple[np.ndarray, np.ndarray]:
    return np.array([a, b, c, d], float), np.array([[0, 1, 2], [0, 2, 3]], np.int32)


def transformed(mesh: tuple[np.ndarray, np.ndarray], centre_xy, yaw: float, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``mesh`` turned by ``yaw`` about z and moved to ``(centre_xy, z)``."""
    c, s = math.cos(yaw), math.sin(yaw)
    v = mesh[0] @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) + [centre_xy[0], centre_xy[1], z]
    return v, mesh[1]


def transformed_parts(meshes: list[tuple[np.ndarray, np.ndarray]], centre_xy, yaw: float, z: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each of ``meshes`` :func:`transformed`, the same numbers: one product for all their vertices (a row of a
    product with a 3 x 3 matrix is the same however many rows it has)."""
    moved = transformed((np.concatenate([v for v, _ in meshes]), None), centre_xy, yaw, z)[0]
    out, start = [], 0
    for v, t in meshes:
        out.append((moved[start : start + len(v)], t))
        start += len(v)
    return out
