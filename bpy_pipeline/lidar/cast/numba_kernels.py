"""The compiled kernels of :mod:`.kernels` (numba; imported only by :func:`.kernels.compiled`).

Every kernel computes exactly what the numpy path computes, operation for operation in the same
order (no fused multiply-add, no reassociation), so both give the same bytes
(``tests/test_scan_kernel.py``). :func:`trace_fill` also calls Embree itself, eight consecutive
rays at a time (``rtcIntersect8`` of the library embreex is linked to, on the scenes embreex made,
each ray rounded as embreex's own loop rounds it): the same hits as ``EmbreeScene.run``'s
``rtcIntersect1``, with the records written while a block's answers are still in cache instead of
in a second pass over Embree's answer. A sensor's consecutive rays leave one origin side by side,
so a packet walks Embree's hierarchy together: the railway's labelled scan went from 0.83 to 1.20 times
the speed of embreex's bare trace (``docs/performance.md``, round twenty-five).

``scene`` is the tuple ``(plane_normal (m, 3) float64, plane_offset (m,) float64,
triangle_object (m,), material, semantic, instance, reflectivity)``, the last four per object row.
"""

from __future__ import annotations

import ctypes

import llvmlite.binding as llvm
import numba
import numpy as np
from numba import types

from ...buffers import MATERIAL_ID
from . import embree

DIFFUSE, MIRROR, GLASS, ABSORBER = (MATERIAL_ID[name] for name in ("diffuse", "mirror", "glass", "absorber"))
NO_HIT = 0xFFFFFFFF  # Embree's invalid geometry and primitive id
PACKET = 8  # rays per Embree query (rtcIntersect8)
BLOCK = 8 * PACKET  # rays traced per call before the pass fills their records (a call costs about what a packet does)
# RTCRayHit8 (Embree 4, 32-byte aligned), in blocks of PACKET 4-byte words, one word per ray: ray org 0-2, tnear 3,
# dir 4-6, time 7, tfar 8, mask 9, id 10, flags 11; hit Ng 12-14, u 15, v 16, primID 17, geomID 18, instID[0] 19,
# instPrimID[0] 20
ORG, DIR, TFAR, MASK, PRIM_ID, GEOM_ID, INST_ID = 0, 4, 8, 9, 17, 18, 19
PACKET_WORDS = 21 * PACKET
ALIGN = 64  # bytes: a cache line (Embree asks for 32)

rtc_intersect8 = types.ExternalFunction("rtcIntersect8", types.void(types.uintp, types.uintp, types.uintp, types.uintp))


@ctypes.CFUNCTYPE(None, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t)
def _no_embree(valid, scene, rayhit, arguments):  # never called: stands in for the linker where Embree cannot be called directly
    raise RuntimeError("rtcIntersect8 called without Embree's library")


def register_embree() -> bool:
    """Make ``rtcIntersect8`` of embreex's Embree library known to numba's linker; whether it could be.

    Where it cannot (another embreex build), a stand-in is linked instead and ``trace`` must stay False.
    """
    lib = embree._library()
    found = lib is not None and embree.shared_buffers_supported()
    llvm.add_symbol("rtcIntersect8", ctypes.cast(lib.rtcIntersect8 if found else _no_embree, ctypes.c_void_p).value)
    return found


jit = numba.njit(nogil=True, cache=True, error_model="numpy", fastmath=False)


@jit
def fill_diffuse(trace, handles, part_triangle, part_shift, far, tfar, prim, prim_triangle, moved, origins, directions, scene, ring, time, min_range,
                 max_distance, ray_base, points, beam, ray, front, back, specular_out):
    """Records of the rays whose hit returns from a diffuse surface; returns ``(records, specular rays)``.

    trace : False: ``tfar`` (n,) float32 and ``prim`` (n,) int32 hold Embree's answer (-1: a miss);
        True: Embree is called here (:func:`nearest_hits`, blocks of :data:`BLOCK` rays), on the scenes ``handles`` ((q,) uint64, q <= 2:
        the static part, then the moving one; ``part_triangle``: two (p,) int64 maps of their
        primitives to buffer triangles, (0,) for the identity; ``part_shift``: (q, 3) float64 added to a ray's
        origin for that part, :attr:`.raycast.RayCaster.part_shift`) up to ``far`` (n,) float32, and its
        answer written into ``tfar`` and ``prim`` as :meth:`.raycast.RayCaster._embree` gives it
        (with two parts, the nearer hit's buffer triangle)
    prim_triangle : (p,) int64 buffer triangle of each primitive of ``prim``, or (0,) for the identity
    moved : (n,) bool rays whose hit came from a moved (re-traced) ray, or (0,) for none
    origins : (n, 3) float64 or (1, 3) shared; directions : (n, 3) float64 unit, local frame
    ring (n,), time (n,): the rays' channel and firing time; ray_base : added to the ray indices written
    Records go into the first rows of ``points`` (:data:`bpy_pipeline.lidar.points.POINT_DTYPE`) and ``beam``
    (:data:`bpy_pipeline.lidar.points.BEAM_DTYPE`), their ray indices (+ ``ray_base``) into ``ray``; ``front``, ``back`` (k,) bool are set for the objects
    hit from the front (d.n < 0) and from behind (d.n > 0); ``specular_out`` (n,) int64 receives the
    rays (ray_base + i) whose hit within range is glass or a mirror's front face: no record for them
    here, the numpy path continues them.
    """
    plane_normal, plane_offset, triangle_object, material, semantic, instance, reflectivity = scene
    n = directions.shape[0]
    shared = origins.shape[0] != n or n == 1
    identity = prim_triangle.shape[0] == 0
    any_moved = moved.shape[0] != 0
    packet = ray_packet()
    k = 0
    m = 0
    for i in range(n):
        j = 0 if shared else i
        ox, oy, oz = origins[j, 0], origins[j, 1], origins[j, 2]
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        if trace and i % BLOCK == 0:
            nearest_hits(handles, part_triangle, part_shift, packet, far, origins, directions, i, min(n, i + BLOCK), tfar, prim)
        p = prim[i]
        if p < 0:
            continue
        # unsigned indices from here: numba then skips its negative-index handling on every access
        t = np.uint64(p) if identity else np.uint64(prim_triangle[np.uint64(p)])
        nx, ny, nz = plane_normal[t, 0], plane_normal[t, 1], plane_normal[t, 2]
        denom = (dx * nx + dz * nz) + dy * ny  # raycast.dot3's order
        row = np.uint64(triangle_object[t])
        if denom < 0.0:
            front[row] = True
        elif denom > 0.0:
            back[row] = True
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
        u = np.uint64(i)
        record = points[np.uint64(k)]  # whole records: one address per record, not one per field (6 ns a ray less)
        record.x = np.float32(ox + distance * dx)
        record.y = np.float32(oy + distance * dy)
        record.z = np.float32(oz + distance * dz)
        cos = abs(-denom)
        value = np.float64(reflectivity[row]) * cos * 1.0
        record.intensity = np.float32(min(max(value, 0.0), 1.0))
        record.semantic = semantic[row]
        record.instance = instance[row]
        record.ring = ring[u]
        record.time = time[u]
        record.range = np.float32(path)
        record.bounces = 0
        fact = beam[np.uint64(k)]
        fact.cos_incidence = np.float32(cos)
        fact.reflectivity = reflectivity[row]
        fact.gain = np.float32(1.0)
        fact.direction[0] = np.float32(dx)
        fact.direction[1] = np.float32(dy)
        fact.direction[2] = np.float32(dz)
        ray[np.uint64(k)] = ray_base + i
        k += 1
    return k, m


@jit
def ray_packet():
    """Embree's record of :data:`PACKET` rays and hits (``RTCRayHit8``) on a :data:`ALIGN`-byte boundary, and its lanes'
    valid flags, set for a query (tnear, time, id and flags 0, every geometry in the mask), and room for the lanes'
    nearest primitives so far: ``(word (PACKET_WORDS,) uint32, the same words as float32, its address, valid (PACKET,)
    int32, their address, nearest (PACKET,) int64)``."""
    words = np.empty(PACKET_WORDS + PACKET + ALIGN // 4, np.uint32)  # the record, then the flags (PACKET_WORDS * 4 bytes: 32-aligned)
    first = ((ALIGN - words.ctypes.data % ALIGN) % ALIGN) // 4
    word = words[first : first + PACKET_WORDS]
    word[:] = 0
    word[MASK * PACKET : (MASK + 1) * PACKET] = NO_HIT
    valid = words[first + PACKET_WORDS : first + PACKET_WORDS + PACKET].view(np.int32)
    return word, word.view(np.float32), word.ctypes.data, valid, valid.ctypes.data, np.empty(PACKET, np.int64)


@jit
def nearest_hits(handles, part_triangle, part_shift, packet, far, origins, directions, start, stop, tfar, prim):
    """The nearest hits of rays ``start`` .. ``stop`` - 1 up to ``far`` (float32) on the scenes ``handles``, :data:`PACKET`
    consecutive rays at a time: one ``rtcIntersect8`` per part in the record ``packet`` of :func:`ray_packet` (each
    origin and direction rounded to float32), into ``tfar``, ``prim`` (``far``, -1 for a miss). With two parts, the
    moving one is asked up to the static hit, and the primitive is the nearer hit's buffer triangle (``part_triangle``:
    each part's map, (0,) for the identity), as :meth:`.raycast.RayCaster._embree` merges them. A part with a shift
    ((3,) float64 of ``part_shift``, not all zero) gets the origin rounded to float32, plus the shift in float64, rounded
    again (:meth:`.raycast.RayCaster.part_origins`' arithmetic). origins : (n, 3), or (1, 3) shared.
    Callers ask for blocks of several packets: a call costs about as much as a packet's own work."""
    word, real, address, valid, valid_address, nearest = packet
    shared = origins.shape[0] != directions.shape[0] or directions.shape[0] == 1
    q = handles.shape[0]
    for first in range(start, stop, PACKET):
        lanes = min(stop - first, PACKET)
        for lane in range(PACKET):
            valid[lane] = -1 if lane < lanes else 0
        for lane in range(lanes):  # no hit yet (nor with no part at all); a later part is asked up to the hit found so far
            real[TFAR * PACKET + lane] = far[first + lane]
            nearest[lane] = -1
        for part in range(q):
            sx, sy, sz = part_shift[part, 0], part_shift[part, 1], part_shift[part, 2]
            unshifted = sx == 0.0 and sy == 0.0 and sz == 0.0
            for lane in range(lanes):
                i = first + lane
                j = 0 if shared else i
                if unshifted:
                    x, y, z = np.float32(origins[j, 0]), np.float32(origins[j, 1]), np.float32(origins[j, 2])
                else:
                    x = np.float32(np.float64(np.float32(origins[j, 0])) + sx)
                    y = np.float32(np.float64(np.float32(origins[j, 1])) + sy)
                    z = np.float32(np.float64(np.float32(origins[j, 2])) + sz)
                real[ORG * PACKET + lane], real[(ORG + 1) * PACKET + lane], real[(ORG + 2) * PACKET + lane] = x, y, z
                real[DIR * PACKET + lane] = np.float32(directions[i, 0])
                real[(DIR + 1) * PACKET + lane] = np.float32(directions[i, 1])
                real[(DIR + 2) * PACKET + lane] = np.float32(directions[i, 2])
                word[PRIM_ID * PACKET + lane] = NO_HIT  # primID, geomID, instID[0]: no hit of this part yet
                word[GEOM_ID * PACKET + lane] = NO_HIT
                word[INST_ID * PACKET + lane] = NO_HIT
            rtc_intersect8(valid_address, handles[part], address, 0)
            mapping = part_triangle[part]
            identity = q == 1 or mapping.shape[0] == 0  # one part: Embree's primitive, mapped by the caller
            for lane in range(lanes):
                hit = word[PRIM_ID * PACKET + lane]
                if hit != NO_HIT:
                    nearest[lane] = np.int64(hit) if identity else mapping[hit]
        for lane in range(lanes):
            tfar[first + lane] = real[TFAR * PACKET + lane]
            prim[first + lane] = nearest[lane]


@jit
def trace_rays(handles, part_triangle, part_shift, far, origins, directions, tfar, prim):
    """Embree's nearest hit of each ray, as :meth:`.raycast.RayCaster._embree` has it from embreex, into ``tfar`` (n,)
    float32 and ``prim`` (n,) int32: :func:`fill_diffuse`'s trace without the records.

    handles, part_triangle, part_shift, far : as :func:`fill_diffuse` takes them; origins (n, 3) or (1, 3) shared, directions
    (n, 3), float32 or float64 (rounded to float32 as numpy's ``astype`` does). A miss keeps ``far`` and gets -1.
    """
    nearest_hits(handles, part_triangle, part_shift, ray_packet(), far, origins, directions, 0, directions.shape[0], tfar, prim)


@jit
def back_face_rays(prim, prim_triangle, directions, plane_normal, triangle_object, both, out):
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


@jit
def triangle_planes(vertices, triangles, normal, offset):
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


CONE_RAYS = 256  # rays per block of cone_pairs' prune: consecutive rays of a pattern point close together
CONE_SLACK = 1e-6  # radians added to every angle of the prune: far beyond the error of acos near 1 (about 1.5e-8)
CONE_UNIT = 1e-14  # |v.v - 1| up to which a direction counts as unit for the prune (float64 unit vectors: about 4e-16)


@jit
def cone_blocks(directions, axes, limit):
    """``(b, k)`` bool: which boxes' cones any ray of each block of :data:`CONE_RAYS` consecutive ``directions`` (n, 3)
    unit may fall in (:func:`cone_pairs`' test: dot with ``axes[box]`` (k, 3) unit at least ``limit[box]`` (k,)).

    Each block is bounded by a cone about its rays' summed direction ``c``, of half-angle ``beta = acos(min d.c)`` (its
    farthest ray); a box's cone has half-angle ``alpha = acos(limit)``. A ray within ``beta`` of ``c`` is at least
    ``angle(c, box axis) - beta`` from the box's axis (the triangle inequality on the sphere), so a box whose axis is
    farther than ``alpha + beta`` from ``c`` can take none of the block's rays: kept are the boxes with
    ``a.c >= cos(alpha + beta + 3 slack)`` (expanded as ``cos alpha cos(beta + 3 slack) - sin alpha sin(...)``), and every
    box where that angle reaches pi. The :data:`CONE_SLACK` on each of the three angles drops only pairs the test
    itself refuses, whatever acos, cos and sin round to. Angles stand for dot products only between unit vectors, so a
    block with a ray, or a box with an axis, farther than :data:`CONE_UNIT` from unit length is never pruned."""
    n, k = directions.shape[0], axes.shape[0]
    blocks = (n + CONE_RAYS - 1) // CONE_RAYS
    keep = np.ones((blocks, k), np.bool_)
    alpha, cos_alpha, sin_alpha = np.empty(k), np.empty(k), np.empty(k)
    for j in range(k):
        unit = abs(axes[j, 0] * axes[j, 0] + axes[j, 1] * axes[j, 1] + axes[j, 2] * axes[j, 2] - 1.0) <= CONE_UNIT
        alpha[j] = np.arccos(min(max(limit[j], -1.0), 1.0)) if unit else np.pi
        cos_alpha[j], sin_alpha[j] = np.cos(alpha[j]), np.sin(alpha[j])
    for b in range(blocks):
        start, stop = b * CONE_RAYS, min(n, (b + 1) * CONE_RAYS)
        cx, cy, cz = 0.0, 0.0, 0.0
        unit = True
        for i in range(start, stop):
            dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
            cx += dx
            cy += dy
            cz += dz
            unit = unit and abs(dx * dx + dy * dy + dz * dz - 1.0) <= CONE_UNIT
        norm = np.sqrt(cx * cx + cy * cy + cz * cz)
        if not unit or norm < 1e-3 * (stop - start):  # rays all round the sphere: no axis bounds them usefully (none at norm 0)
            continue
        cx, cy, cz = cx / norm, cy / norm, cz / norm
        nearest = 1.0
        for i in range(start, stop):
            nearest = min(nearest, directions[i, 0] * cx + directions[i, 1] * cy + directions[i, 2] * cz)
        spread = np.arccos(min(max(nearest, -1.0), 1.0)) + 3.0 * CONE_SLACK
        cos_spread, sin_spread = np.cos(spread), np.sin(spread)
        for j in range(k):
            if alpha[j] + spread < np.pi:
                keep[b, j] = axes[j, 0] * cx + axes[j, 1] * cy + axes[j, 2] * cz >= cos_alpha[j] * cos_spread - sin_alpha[j] * sin_spread
    return keep


@jit
def cone_pairs(directions, axes, limit):
    """``(ray, box)`` int64 pairs, ray-major (``np.nonzero``'s order), of ``directions`` (n, 3) whose dot product with
    ``axes[box]`` (k, 3) is at least ``limit[box]`` (k,): a count pass, then a fill pass (no (n, k) matrix). Each ray is
    tested against the boxes :func:`cone_blocks` keeps for its block only, in box order: the same pairs as testing every box."""
    n, k = directions.shape[0], axes.shape[0]
    keep = cone_blocks(directions, axes, limit)
    index, near, bound = np.empty(k, np.int64), np.empty((k, 3)), np.empty(k)  # the kept boxes of the block at hand
    out = np.empty(0, np.int64), np.empty(0, np.int64)
    for fill in (False, True):
        at = 0
        for b in range(keep.shape[0]):
            m = 0
            for j in range(k):
                if keep[b, j]:
                    index[m], bound[m] = j, limit[j]
                    near[m, 0], near[m, 1], near[m, 2] = axes[j, 0], axes[j, 1], axes[j, 2]
                    m += 1
            if m == 0:
                continue
            for i in range(b * CONE_RAYS, min(n, (b + 1) * CONE_RAYS)):
                dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
                for q in range(m):
                    if dx * near[q, 0] + dy * near[q, 1] + dz * near[q, 2] >= bound[q]:
                        if fill:
                            out[0][at], out[1][at] = i, index[q]
                        at += 1
        if not fill:
            out = np.empty(at, np.int64), np.empty(at, np.int64)
    return out
