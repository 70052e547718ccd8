"""Embree ray casting over scene buffers, with float64 hit refinement.

Geometry goes to Embree as float32 *in a local frame* (the sensor's: its position is the
origin, its axes the axes), so a scene far from the world origin keeps its precision and a
sensor's rays go to Embree without being transformed. Embree finds which triangle a ray hits;
the distance is then recomputed in float64 against that triangle's plane (precomputed once per
scene), so hit points lie on the surface to ~1e-9 m instead of float32's ~1e-5 m at 150 m.

Where Embree fails, and what is done about it (``tests/test_scan_failures.py``):

- Zero-area triangles (repeated or collinear corners, in float64) have no surface: they are
  left out of the Embree scene and never hit.
- Embree's robust mode (embreex's default) is watertight along shared edges but not at shared
  vertices: a float32 ray passing within a few ulps of a vertex (a ray aimed exactly at one)
  can slip between the triangles around it: about 1 % of rays aimed exactly at the vertices
  of a closed mesh from outside do (rays not aimed at vertices practically never). A ray that
  slipped into a closed mesh leaves it through a back face, so a back-face hit on an object
  the same query also hit from the front, and a miss while the origin is enclosed by a closed
  mesh (seen only from inside), are traced again with the ray moved across by :data:`JITTER`
  (radians, and metres per metre of origin coordinate) four ways; the nearest hit wins and its
  distance is solved along the original ray. Scenes seen
  from outside have no such rays and pay nothing; a ray that slips out of an enclosing mesh
  and then hits another object, or slips through an open mesh, is not caught.
- Grazing rays (parallel to a plane) keep Embree's distance where the plane solve is
  ill-conditioned; distances are never negative and never NaN.
- Non-finite vertices or triangle indices out of range raise ``InputError`` naming the
  object (:meth:`SceneBuffers.check`), and so do vertices farther than
  :data:`MAX_COORDINATE` from the local origin (an object scaled to infinity, which Blender
  clamps to 3.4e38): Embree's float32 arithmetic overflows from about 5e18 m and misses them silently.
"""

from __future__ import annotations

import os
import weakref
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from ..buffers import SceneBuffers
from ..errors import InputError

FAR = 1e30  # stands for "no limit" in Embree's float32 tfar
JITTER = 2.0**-18  # radians (and metres per metre of origin coordinate) a re-traced ray is moved by: 64 float32 ulps
MAX_COORDINATE = 1e9  # metres from the local origin; far beyond any scene (Embree overflows and loses triangles from ~5e18 m)
PLANE_CHUNK = 1 << 20  # triangles per step when computing the planes (bounds the float64 temporaries)


@dataclass
class Hits:
    """The rays that hit something, in compact form (h of n rays).

    ray : (h,) int64 index of the ray among the n queried
    distance : (h,) float64 metres along the (unit) direction, >= 0
    triangle : (h,) int64 triangle index into the buffers
    normal : (h, 3) float64 unit geometric normal of the triangle (winding order)
    """

    ray: np.ndarray
    distance: np.ndarray
    triangle: np.ndarray
    normal: np.ndarray


def default_threads() -> int:
    return os.cpu_count() or 1


def closed_surface(triangles: np.ndarray) -> bool:
    """Whether ``(m, 3)`` vertex indices form closed, consistently wound surfaces.

    Every directed edge must appear once and its reverse once (each edge shared by exactly two
    triangles that wind it in opposite directions). Several disjoint closed parts count as closed.
    """
    t = np.asarray(triangles, np.int64)
    if len(t) == 0:
        return False
    a, b = t.reshape(-1), t[:, [1, 2, 0]].reshape(-1)
    if (a == b).any():
        return False
    span = int(max(a.max(), b.max())) + 1
    forward = np.sort(a * span + b)
    if (forward[1:] == forward[:-1]).any():
        return False
    return bool(np.array_equal(forward, np.sort(b * span + a)))


class RayCaster:
    """Nearest-hit queries against :class:`SceneBuffers`, in a local frame.

    frame : (4, 4) float64 local-to-world transform (a sensor pose); default: a translation to
        the centre of the vertices' bounds. ``intersect`` takes and returns local coordinates.
    threads : threads for Embree (default: every core); embreex releases the GIL while tracing
    chunk : rays per embreex call
    ``InputError`` (naming the object) for non-finite vertices, bad triangle indices, or vertices
    farther than :data:`MAX_COORDINATE` from the local origin.
    """

    def __init__(self, buffers: SceneBuffers, frame=None, threads: int | None = None, chunk: int = 32768):
        if len(buffers.triangles):
            buffers.check()
        vertices = np.asarray(buffers.vertices, np.float64)
        if frame is None:
            frame = np.eye(4)
            frame[:3, 3] = (vertices.min(axis=0) + vertices.max(axis=0)) / 2 if len(vertices) else 0.0
        self.frame = np.asarray(frame, np.float64)
        self.origin = self.frame[:3, 3]
        self.threads = threads or default_threads()
        self.chunk = chunk
        local = self.to_local(vertices)
        triangles = np.ascontiguousarray(buffers.triangles, np.int32)
        check_extent(local, triangles, buffers)
        self.triangle_object = np.asarray(buffers.triangle_object)
        self.objects = len(buffers.objects)
        self.plane_normal, self.plane_offset = triangle_planes(local, triangles)  # (m, 3), (m,) local frame
        solid = np.flatnonzero(self.plane_normal.any(axis=1))
        # Zero-area triangles have no surface: leave them out; Embree's primID indexes the rest.
        self.embree_triangle = None if len(solid) == len(triangles) else solid
        self.scene = rtcore_scene.EmbreeScene()
        if len(solid):
            TriangleMesh(self.scene, np.ascontiguousarray(local, np.float32), triangles if self.embree_triangle is None else triangles[solid])
        # Embree commits the scene on the first query: do it once here, before threads share it.
        self.scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32), output=1)
        self._pool = None
        self._closed: dict[int, bool] = {}
        self._buffers_triangles = buffers.triangles

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """``(n, 3)`` world points into the local frame."""
        return (np.asarray(points, np.float64) - self.origin) @ self.frame[:3, :3]

    def closed(self, row: int) -> bool:
        """Whether object ``row``'s triangles form closed surfaces (:func:`closed_surface`); cached."""
        if row not in self._closed:
            self._closed[row] = closed_surface(self._buffers_triangles[self.triangle_object == row])
        return self._closed[row]

    def _embree(self, origins32: np.ndarray, directions32: np.ndarray, far: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Embree alone, chunked over the thread pool: ``(tfar, primID, geomID)`` per ray.

        Only Embree runs in the worker threads: embreex takes the GIL back after every ray,
        so numpy work on another thread would stall it.
        """

        def run(start):
            s = slice(start, start + self.chunk)
            out = self.scene.run(origins32[s], directions32[s], dists=far[s], output=1)
            return out["tfar"], out["primID"], out["geomID"]

        starts = range(0, len(directions32), self.chunk)
        if self.threads > 1 and len(starts) > 1:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(self.threads)
                weakref.finalize(self, self._pool.shutdown)
            parts = list(self._pool.map(run, starts))
        else:
            parts = [run(start) for start in starts]
        if len(parts) == 1:
            return parts[0]
        return tuple(np.concatenate(column) for column in zip(*parts)) if parts else (np.zeros(0, np.float32), np.zeros(0, np.int32), np.zeros(0, np.int32))

    def intersect(self, origins, directions, max_distance=FAR, directions32=None) -> Hits:
        """Nearest hit of each ray (Embree on every core, then float64 refinement), local frame.

        origins : (n, 3) or (3,) float64 local coordinates, metres ((3,): one shared origin)
        directions : (n, 3) float64 unit vectors, local frame
        max_distance : float or (n,) float64; hits beyond are misses
        directions32 : the same directions as float32, when the caller already has them
        """
        directions = np.asarray(directions, np.float64)
        n = len(directions)
        local = np.asarray(origins, np.float64)
        shared = local.ndim == 1
        if shared and not local.any():
            origins32 = np.zeros((n, 3), np.float32)
        else:
            origins32 = np.ascontiguousarray(np.broadcast_to(local, (n, 3)), np.float32)
        far = np.empty(n, np.float32)
        far[:] = np.minimum(max_distance, FAR)
        if directions32 is None:
            directions32 = np.ascontiguousarray(directions, np.float32)
        tfar, prim, geom = self._embree(origins32, directions32, far)
        ray = np.flatnonzero(geom >= 0)
        triangle = self._triangles(prim[ray])
        normal = self.plane_normal[triangle]
        denom = np.einsum("ij,ij->i", directions[ray], normal)
        suspect = self._slipped(ray, triangle, denom, geom)
        moved = None
        if len(suspect):
            tfar, prim, geom = tfar.copy(), prim.copy(), geom.copy()
            moved = np.zeros(n, bool)
            moved[self._retrace(suspect, local, directions, far, tfar, prim, geom)] = True
            ray = np.flatnonzero(geom >= 0)
            triangle = self._triangles(prim[ray])
            normal = self.plane_normal[triangle]
            denom = np.einsum("ij,ij->i", directions[ray], normal)
        o_dot_n = normal @ local if shared else np.einsum("ij,ij->i", local[ray], normal)
        coarse = tfar[ray].astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            exact = (self.plane_offset[triangle] - o_dot_n) / denom
        # Keep Embree's distance where the plane solve is ill-conditioned (grazing rays; NaN fails the test).
        trust = np.abs(exact - coarse) <= 1e-4 * (1.0 + coarse)
        if moved is not None:  # a re-traced ray's Embree distance is along the turned ray: solve along the original
            m = moved[ray]
            trust[m] = np.isfinite(exact[m]) & (np.abs(denom[m]) > 1e-6)
        distance = np.maximum(np.where(trust, exact, coarse), 0.0)
        limit = max_distance if np.ndim(max_distance) == 0 else np.asarray(max_distance)[ray]
        inside = distance <= limit
        if not inside.all():
            ray, distance, triangle, normal = ray[inside], distance[inside], triangle[inside], normal[inside]
        return Hits(ray, distance, triangle, normal)

    def _triangles(self, prim: np.ndarray) -> np.ndarray:
        """Buffer triangle indices (int64) of Embree primitive ids."""
        return prim.astype(np.int64) if self.embree_triangle is None else self.embree_triangle[prim]

    def _slipped(self, ray: np.ndarray, triangle: np.ndarray, denom: np.ndarray, geom: np.ndarray) -> np.ndarray:
        """Rays that may have slipped through a vertex (see the module notes): indices among the n queried.

        denom : d.n of each hit, > 0 where the ray met the triangle's back face
        """
        back = denom > 0
        if not back.any():
            return np.zeros(0, np.int64)
        obj = self.triangle_object[triangle]
        seen_front = np.bincount(obj[denom < 0], minlength=self.objects) > 0
        suspect = [ray[back & seen_front[obj]]]
        inside_of = np.unique(obj[back & ~seen_front[obj]])
        if any(self.closed(int(row)) for row in inside_of):  # the origin is enclosed: no ray can miss
            suspect.append(np.flatnonzero(geom < 0))
        return np.concatenate(suspect)

    def _retrace(self, rays, local, directions, far, tfar, prim, geom) -> np.ndarray:
        """Trace ``rays`` again, moved by :data:`JITTER` four ways across; keep the nearest hit
        (updates tfar, prim, geom in place). Returns the rays whose hit now comes from a moved ray.

        Four ways (two crossed axes, both senses), since a ray that slipped in where it only just
        enters the mesh can be moved out of it by one of them.
        """
        d = directions[rays]
        o = np.broadcast_to(local, (len(directions), 3))[rays]
        # Two unit vectors across each ray: u = d x (the axis d is least aligned with), and d x u.
        axis = np.zeros_like(d)
        axis[np.arange(len(d)), np.argmin(np.abs(d), axis=1)] = 1.0
        u = np.cross(d, axis)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        shift = JITTER * (1.0 + np.abs(o).max(axis=1))
        far = np.ascontiguousarray(far[rays])
        best_t, best_p, best_g = tfar[rays].copy(), prim[rays].copy(), geom[rays].copy()
        moved = np.zeros(len(rays), bool)
        for across in (u, -u, np.cross(d, u), -np.cross(d, u)):
            turned = d + JITTER * across
            turned /= np.linalg.norm(turned, axis=1, keepdims=True)
            o32 = np.ascontiguousarray(o + shift[:, None] * across, np.float32)
            t2, p2, g2 = self._embree(o32, np.ascontiguousarray(turned, np.float32), far)
            better = (g2 >= 0) & ((best_g < 0) | (t2 < best_t))
            best_t[better], best_p[better], best_g[better] = t2[better], p2[better], g2[better]
            moved |= better
        take = rays[moved]
        tfar[take], prim[take], geom[take] = best_t[moved], best_p[moved], best_g[moved]
        return take


def check_extent(local: np.ndarray, triangles: np.ndarray, buffers: SceneBuffers) -> None:
    """``InputError`` naming the first object with a vertex beyond :data:`MAX_COORDINATE` of the local origin."""
    too_far = np.abs(local).max(axis=1, initial=0.0) > MAX_COORDINATE
    if too_far.any():
        bad = np.flatnonzero(too_far[triangles].any(axis=1))
        if len(bad):
            name = buffers.objects.names[buffers.triangle_object[bad[0]]]
            raise InputError(
                f"object {name!r}: has vertices more than {MAX_COORDINATE:.0e} m from the local origin (the sensor) "
                f"({np.abs(local[triangles[bad[0]]]).max():.3g} m); check its scale and location"
            )


def triangle_planes(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals ``(m, 3)`` float64 (winding order; zero for zero-area triangles) and offsets ``(m,)`` n . v0.

    vertices : (n, 3) float64; triangles : (m, 3) int indices. Computed in steps of
    :data:`PLANE_CHUNK` triangles so the temporaries stay small for 10-million-triangle scenes.
    """
    m = len(triangles)
    normal, offset = np.empty((m, 3)), np.empty(m)
    for start in range(0, m, PLANE_CHUNK):
        s = slice(start, start + PLANE_CHUNK)
        v0, v1, v2 = (vertices[triangles[s, k]] for k in range(3))
        cross = np.cross(v1 - v0, v2 - v0)
        area2 = np.linalg.norm(cross, axis=1)
        normal[s] = cross / np.where(area2 > 0, area2, 1.0)[:, None]
        offset[s] = np.einsum("ij,ij->i", normal[s], v0)
    return normal, offset
