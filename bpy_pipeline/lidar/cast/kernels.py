"""The scan's diffuse path fused into one compiled pass with Embree (numba, optional).

Once Embree has found a ray's triangle, a direct return from a diffuse surface needs: the
float64 plane solve, the trust test against Embree's float32 distance, the range limits, the
object's labels and the record. :func:`trace_fill` does all of it per ray, in firing order, right
after calling Embree itself for a block of 64 rays, eight at a time (on the scenes embreex built, through
Embree's own ``rtcIntersect8``: the same hits as embreex's ``rtcIntersect1``); :func:`fill_diffuse` does it in one pass over an answer
embreex gave (re-traced rays, and where Embree's library cannot be called directly). The numpy
path makes some 27 passes over ray-sized arrays and 91 over hit-sized ones. The kernels
(:mod:`.numba_kernels`) compute exactly what the numpy path computes, operation for operation
in the same order (no fused multiply-add, no reassociation), so all give the same bytes
(``tests/test_scan_kernel.py`` runs them all).

Numba is optional (the ``fast`` extra): :func:`compiled` returns ``None`` when it is not
importable, and the scanner then takes the numpy path. Rays whose first hit is glass or a
mirror's front face are only listed here: :func:`.scanner.trace_beams` continues them; slipped
rays are traced again by :meth:`.raycast.RayCaster.retrace` and the pass repeated over the moved rays.
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace

import numpy as np

from ...compiled import numba_available

IDENTITY = np.zeros(0, np.int64)  # a primitive map that is the identity
NO_RAYS = np.zeros(0, np.bool_)


@cache
def compiled() -> SimpleNamespace | None:
    """The compiled kernels (:mod:`.numba_kernels`, compiled on first use and cached on disk), or ``None`` without numba.

    ``traces`` is False where Embree's library cannot be called directly (another embreex build):
    the scanner then has Embree's answer from embreex and runs the pass after it.
    """
    if not numba_available():
        return None
    from . import numba_kernels as nk

    traced = nk.register_embree()
    return SimpleNamespace(fill_diffuse=nk.fill_diffuse, trace_rays=nk.trace_rays, traces=traced, back_face_rays=nk.back_face_rays,
                           triangle_planes=nk.triangle_planes, cone_pairs=nk.cone_pairs, cone_blocks=nk.cone_blocks)


NO_PARTS = (np.zeros(0, np.uint64), (IDENTITY, IDENTITY), np.zeros((0, 3)), np.zeros(0, np.float32))  # handles, part maps, shifts, limits: Embree not called


def fill_diffuse(kernels: SimpleNamespace, tfar, prim, prim_triangle, moved, origins, directions, caster, objects, ring, time, min_range, max_distance, points,
                 beam, ray, ray_base: int = 0):
    """Records of the diffuse returns from Embree's answer ``tfar``, ``prim`` (n,); returns ``(count, front, back, specular)``.

    Records go into the first ``count`` rows of ``points`` and ``beam`` (room for n), their ray
    indices (+ ``ray_base``) into ``ray``; ``front``, ``back`` (k,) bool flag the objects hit from
    the front and from behind; ``specular`` (s,) int64 the rays left to the numpy path (glass, mirrors).
    """
    return _fill(kernels, False, *NO_PARTS, tfar, prim, prim_triangle, moved, origins, directions, caster, objects, ring, time, min_range, max_distance, points,
                 beam, ray, ray_base)


def trace_fill(kernels: SimpleNamespace, caster, far, origins, directions, objects, ring, time, min_range, max_distance, points, beam, ray, tfar, prim,
               ray_base: int = 0):
    """:func:`fill_diffuse` with Embree called inside the pass, on the caster's scenes; Embree's answer goes into ``tfar``, ``prim``.

    far : (n,) float32 the rays' limits; origins (1, 3) or (n, 3), directions (n, 3) float64, local
    frame. Needs ``kernels.traces`` and ``caster.embree_handles``.
    """
    prim_triangle = IDENTITY if caster.embree_triangle is None else caster.embree_triangle
    return _fill(kernels, True, caster.embree_handles, caster.part_triangle, caster.part_shift, far, tfar, prim, prim_triangle, NO_RAYS, origins, directions,
                 caster, objects, ring, time, min_range, max_distance, points, beam, ray, ray_base)


def _fill(kernels, trace, handles, part_triangle, part_shift, far, tfar, prim, prim_triangle, moved, origins, directions, caster, objects, ring, time,
          min_range, max_distance, points, beam, ray, ray_base):
    """``kernels.fill_diffuse`` (:func:`.numba_kernels.fill_diffuse`) with the caster's and objects' arrays; returns ``(count, front, back, specular)``."""
    front, back = np.zeros(len(objects), np.bool_), np.zeros(len(objects), np.bool_)
    specular = np.empty(len(directions), np.int64)
    scene = (caster.plane_normal, caster.plane_offset, caster.triangle_object, objects.material, objects.semantic, objects.instance, objects.reflectivity)
    count, m = kernels.fill_diffuse(trace, handles, part_triangle, part_shift, far, tfar, prim, prim_triangle, moved, origins, directions, scene, ring, time,
                                    float(min_range), float(max_distance), int(ray_base), points, beam, ray, front, back, specular)  # fmt: skip
    return count, front, back, specular[:m]


def back_face_rays(kernels: SimpleNamespace, prim, prim_triangle, directions, caster, both) -> np.ndarray:
    """``(s,)`` int64 rays whose hit is a back face of an object flagged in ``both`` (``kernels.back_face_rays``)."""
    out = np.empty(len(prim), np.int64)
    return out[: kernels.back_face_rays(prim, prim_triangle, directions, caster.plane_normal, caster.triangle_object, both, out)]
