"""The scan's diffuse path fused into one compiled pass after Embree (numba, optional).

After Embree has found each ray's triangle, a direct return from a diffuse surface needs: the
float64 plane solve, the trust test against Embree's float32 distance, the range limits, the
object's labels and the record. :func:`fill_diffuse` does all of it per ray, in firing order,
in one pass over Embree's output (the numpy path makes some 27 passes over ray-sized arrays
and 91 over hit-sized ones). It computes exactly what the numpy path computes, operation for
operation in the same order (no fused multiply-add, no reassociation), so both give the same
bytes (``tests/test_scan_kernel.py`` runs both).

Numba is optional (the ``fast`` extra): :func:`compiled` returns ``None`` when it is not
importable, and the scanner then takes the numpy path. Rays whose first hit is glass or a
mirror's front face are only listed here: :func:`.scanner.trace_beams` continues them; slipped
rays are traced again by :meth:`.raycast.RayCaster.retrace` and the pass repeated.
"""

from __future__ import annotations

import importlib.util
from functools import cache
from types import SimpleNamespace

import numpy as np

from ..buffers import MATERIAL_ID

DIFFUSE, MIRROR, GLASS, ABSORBER = (MATERIAL_ID[name] for name in ("diffuse", "mirror", "glass", "absorber"))


def numba_available() -> bool:
    """Whether numba can be imported (without importing it)."""
    return importlib.util.find_spec("numba") is not None


def _fill_diffuse(
    tfar, prim, prim_triangle, moved, origins, directions,
    plane_normal, plane_offset, triangle_object, material, semantic, instance, reflectivity,
    ring, time, min_range, max_distance, ray_base,
    x, y, z, intensity, semantic_out, instance_out, ring_out, time_out, range_out, bounces_out,
    cos_out, reflectivity_out, gain_out, direction_out, ray_out, front, back, specular_out,
):  # fmt: skip
    """Records of the rays whose hit returns from a diffuse surface; returns ``(records, specular rays)``.

    tfar : (n,) float32 Embree distances; prim : (n,) int32 Embree primitive, -1 for a miss
    prim_triangle : (p,) int64 buffer triangle of each primitive, or (0,) for the identity
    moved : (n,) bool rays whose hit came from a moved (re-traced) ray, or (0,) for none
    origins : (n, 3) float64 or (1, 3) shared; directions : (n, 3) float64 unit, local frame
    plane_normal (m, 3), plane_offset (m,) float64; triangle_object (m,); per object row:
    material, semantic, instance, reflectivity
    ring (n,), time (n,): the rays' channel and firing time; ray_base : added to the ray indices written
    The outputs (x ... direction_out, ray_out) have room for n records; ``front`` and ``back``
    (k,) bool are set for the objects hit from the front (d.n < 0) and from behind (d.n > 0).
    specular_out : (n,) int64, receives the rays (ray_base + i) whose hit within range is glass or
    a mirror's front face: no record for them here; the numpy path continues them.
    """
    n = tfar.shape[0]
    shared = origins.shape[0] != n or n == 1
    identity = prim_triangle.shape[0] == 0
    any_moved = moved.shape[0] != 0
    k = 0
    m = 0
    for i in range(n):
        p = prim[i]
        if p < 0:
            continue
        t = p if identity else prim_triangle[p]
        nx, ny, nz = plane_normal[t, 0], plane_normal[t, 1], plane_normal[t, 2]
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        denom = (dx * nx + dz * nz) + dy * ny  # raycast.dot3's order
        row = triangle_object[t]
        if denom < 0.0:
            front[row] = True
        elif denom > 0.0:
            back[row] = True
        j = 0 if shared else i
        ox, oy, oz = origins[j, 0], origins[j, 1], origins[j, 2]
        o_dot_n = (ox * nx + oz * nz) + oy * ny
        coarse = np.float64(tfar[i])
        exact = (plane_offset[t] - o_dot_n) / denom
        if any_moved and moved[i]:
            trust = np.isfinite(exact) and abs(denom) > 1e-6
        else:
            trust = abs(exact - coarse) <= 1e-4 * (1.0 + coarse)
        distance = exact if trust else coarse
        if distance < 0.0:
            distance = 0.0
        if not distance <= max_distance:
            continue
        kind = material[row]
        if kind == ABSORBER:
            continue
        if kind == GLASS or (kind == MIRROR and denom < 0.0):  # d.n < 0: the mirror's front face
            specular_out[m] = ray_base + i
            m += 1
            continue
        path = distance + 0.0  # the numpy path's total path length (0.0 added: -0.0 becomes 0.0)
        if path < min_range:
            continue
        x[k] = np.float32(ox + distance * dx)
        y[k] = np.float32(oy + distance * dy)
        z[k] = np.float32(oz + distance * dz)
        cos = abs(-denom)
        value = np.float64(reflectivity[row]) * cos * 1.0
        intensity[k] = np.float32(min(max(value, 0.0), 1.0))
        semantic_out[k] = semantic[row]
        instance_out[k] = instance[row]
        ring_out[k] = ring[i]
        time_out[k] = time[i]
        range_out[k] = np.float32(path)
        bounces_out[k] = 0
        cos_out[k] = np.float32(cos)
        reflectivity_out[k] = reflectivity[row]
        gain_out[k] = np.float32(1.0)
        direction_out[k, 0] = np.float32(dx)
        direction_out[k, 1] = np.float32(dy)
        direction_out[k, 2] = np.float32(dz)
        ray_out[k] = ray_base + i
        k += 1
    return k, m


def _back_face_rays(prim, prim_triangle, directions, plane_normal, triangle_object, both, out):
    """Rays whose hit is a back face (d.n > 0) of an object flagged in ``both`` (k,) bool; returns how many, in ``out``."""
    identity = prim_triangle.shape[0] == 0
    k = 0
    for i in range(prim.shape[0]):
        p = prim[i]
        if p < 0:
            continue
        t = p if identity else prim_triangle[p]
        if not both[triangle_object[t]]:
            continue
        denom = (directions[i, 0] * plane_normal[t, 0] + directions[i, 2] * plane_normal[t, 2]) + directions[i, 1] * plane_normal[t, 1]
        if denom > 0.0:
            out[k] = i
            k += 1
    return k


def _triangle_planes(vertices, triangles, normal, offset):
    """Unit normals and offsets n . v0 of ``triangles`` (m, 3) over ``vertices`` (n, 3) float64, into ``normal`` (m, 3), ``offset`` (m,).

    The operations of :func:`.raycast.triangle_planes` (numpy's cross product, norm and
    einsum) in their order: the same bits.
    """
    for i in range(triangles.shape[0]):
        a, b, c = triangles[i, 0], triangles[i, 1], triangles[i, 2]
        x0, y0, z0 = vertices[a, 0], vertices[a, 1], vertices[a, 2]
        e1x, e1y, e1z = vertices[b, 0] - x0, vertices[b, 1] - y0, vertices[b, 2] - z0
        e2x, e2y, e2z = vertices[c, 0] - x0, vertices[c, 1] - y0, vertices[c, 2] - z0
        cx = e1y * e2z - e1z * e2y
        cy = e1z * e2x - e1x * e2z
        cz = e1x * e2y - e1y * e2x
        area = np.sqrt((cx * cx + cy * cy) + cz * cz)
        scale = area if area > 0 else 1.0
        nx, ny, nz = cx / scale, cy / scale, cz / scale
        normal[i, 0], normal[i, 1], normal[i, 2] = nx, ny, nz
        offset[i] = ((0.0 + nx * x0) + nz * z0) + ny * y0  # einsum starts from +0.0 (a -0.0 product becomes 0.0)


@cache
def compiled() -> SimpleNamespace | None:
    """The compiled kernels (numba, compiled on first use and cached on disk), or ``None`` without numba."""
    if not numba_available():
        return None
    import numba

    jit = numba.njit(nogil=True, cache=True, error_model="numpy", fastmath=False)
    return SimpleNamespace(fill_diffuse=jit(_fill_diffuse), back_face_rays=jit(_back_face_rays), triangle_planes=jit(_triangle_planes))


def fill_diffuse(kernels: SimpleNamespace, tfar, prim, prim_triangle, moved, origins, directions, caster, objects, ring, time, min_range, max_distance, points, beam, ray, ray_base: int = 0):
    """Run :func:`_fill_diffuse` with the record arrays' fields; returns ``(count, front, back, specular)``."""
    front, back = np.zeros(len(objects), np.bool_), np.zeros(len(objects), np.bool_)
    specular = np.empty(len(prim), np.int64)
    count, m = kernels.fill_diffuse(
        tfar, prim, prim_triangle, moved, origins, directions,
        caster.plane_normal, caster.plane_offset, caster.triangle_object, objects.material, objects.semantic, objects.instance, objects.reflectivity,
        ring, time, float(min_range), float(max_distance), int(ray_base),
        points["x"], points["y"], points["z"], points["intensity"], points["semantic"], points["instance"], points["ring"], points["time"], points["range"], points["bounces"],
        beam["cos_incidence"], beam["reflectivity"], beam["gain"], beam["direction"], ray, front, back, specular,
    )  # fmt: skip
    return count, front, back, specular[:m]


def back_face_rays(kernels: SimpleNamespace, prim, prim_triangle, directions, caster, both) -> np.ndarray:
    """``(s,)`` int64 rays whose hit is a back face of an object flagged in ``both`` (:func:`_back_face_rays`)."""
    out = np.empty(len(prim), np.int64)
    return out[: kernels.back_face_rays(prim, prim_triangle, directions, caster.plane_normal, caster.triangle_object, both, out)]
