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
  slipped into a closed mesh leaves it through a back face, so a back-face hit on a closed object
  the same query also hit from the front, and a miss while the origin is enclosed by a closed
  mesh (seen only from inside), are traced again with the ray moved across by :data:`JITTER`
  (radians, and metres per metre of origin coordinate) four ways; the nearest hit wins and its
  distance is solved along the original ray. Scenes seen
  from outside have no such rays and pay nothing; a ray that slips out of an enclosing mesh
  and then hits another object, or slips through an open mesh, is not caught. An open object
  (a pane, a leaf, a fence) seen from both sides is not traced again: its back faces are seen
  by rays that slipped nowhere, and the nearest of four moved copies of such a ray may meet the
  edge of a nearer surface the ray itself only passes (the street's ego job re-traced about
  1,600 rays a frame so, and one point in about 90,000 moved up to 30 m nearer, onto an edge).
- Grazing rays (parallel to a plane) keep Embree's distance where the plane solve is
  ill-conditioned; distances are never negative and never NaN.
- Non-finite vertices or triangle indices out of range raise ``InputError`` naming the
  object (:meth:`SceneBuffers.check`), and so do vertices farther than
  :data:`MAX_COORDINATE` from the local origin (an object scaled to infinity, which Blender
  clamps to 3.4e38): Embree's float32 arithmetic overflows from about 5e18 m and misses them silently.

Set-up and reuse: Embree reads the float32 vertices and the indices where they lie
(:mod:`.embree`), so a caster costs Embree's own build plus a few numpy passes. A run that scans
many frames of one scene keeps the caster of the static objects in a :class:`CasterCache` and
builds a small one per frame for the objects that move; a :class:`RayCaster` traces both and
keeps the nearer hit. A sensor that drives through a static world without turning (the street's
ego car) keeps one Embree scene of it for the run (``CasterCache.caster(..., follow=True)``): its
local origin is the pose's position snapped to a grid of :data:`FOLLOW_GRID` m (the street's: the
world origin, the layout's centre; one fixed origin per layout), and each pose moves the rays into
it, not the scene. A street layout lies within about 100 m of that origin and a pose within 900 m,
so Embree's float32 copy keeps better than 0.1 mm; the static triangles' planes are kept in that
frame too, each pose moving their offsets into its own (nothing of the static world is redone per
frame but that one pass), and the distances are solved in float64 in each pose's own frame.
"""

from __future__ import annotations

import os
import sys
import threading
import weakref
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from embreex import rtcore_scene

from ...buffers import SceneBuffers
from ...compiled import KERNEL_VARIABLE
from ...errors import InputError
from . import kernels
from .embree import attach_triangles, commit_scene, scene_handle
from .sharing import share

FAR = 1e30  # stands for "no limit" in Embree's float32 tfar
JITTER = 2.0**-18  # radians (and metres per metre of origin coordinate) a re-traced ray is moved by: 64 float32 ulps
FOLLOW_GRID = 1024.0  # metres between the origins a static part following a sensor may be built at (anchored)
MAX_SHIFT = 1000.0  # metres a pose may stand from the frame a kept static part was built in (float32 keeps 0.1 mm there)
MAX_COORDINATE = 1e9  # metres from the local origin; far beyond any scene (Embree overflows and loses triangles from ~5e18 m)
PLANE_CHUNK = 1 << 20  # triangles per step when computing the planes (bounds the float64 temporaries)
KERNELS = ("auto", "numba", "numpy")


@dataclass
class Hits:
    """The rays that hit something, in compact form (h of n rays).

    ray : (h,) int64 index of the ray among the n queried
    distance : (h,) float64 metres along the (unit) direction, >= 0
    triangle : (h,) int64 triangle index into the buffers
    normal : (h, 3) float64 unit geometric normal of the triangle (winding order)
    direction : (h, 3) float64 the ray's direction (the query's, gathered once), or None
    """

    ray: np.ndarray
    distance: np.ndarray
    triangle: np.ndarray
    normal: np.ndarray
    direction: np.ndarray | None = None


def default_threads() -> int:
    """The cores this process may run on (``os.sched_getaffinity`` where the system has it)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of ``(h, 3)`` arrays (or one ``(3,)`` with ``(h, 3)``), float64.

    Always summed as ``(a0 b0 + a2 b2) + a1 b1``: the order numpy 1.26's einsum takes, written
    out so the compiled kernel (:mod:`.kernels`) and any numpy version give the same bits.
    """
    a, b = np.asarray(a), np.asarray(b)
    return (a[..., 0] * b[..., 0] + a[..., 2] * b[..., 2]) + a[..., 1] * b[..., 1]


def row_norms(a: np.ndarray) -> np.ndarray:
    """``(h,)`` lengths of the rows of an ``(h, 3)`` float64 array: ``np.linalg.norm(a, axis=1)`` bit for bit.

    numpy sums a row's squares as ``(a0^2 + a1^2) + a2^2`` (numpy 1.26 and 2.x); written out, without its
    ``(h, 3)`` reduction, it takes a sixth of the time.
    """
    total = a[:, 0] * a[:, 0]
    total += a[:, 1] * a[:, 1]
    total += a[:, 2] * a[:, 2]
    return np.sqrt(total, out=total)


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


@dataclass
class EmbreePart:
    """One Embree scene over some of the buffers' triangles.

    triangle : (p,) int64 buffer triangle of each Embree primitive; ``None`` for the identity
    keep : the arrays Embree reads in place (alive as long as the scene)
    handle : the committed ``RTCScene`` for the compiled pass to call Embree on (0: not known, see :func:`.embree.scene_handle`)
    """

    scene: rtcore_scene.EmbreeScene
    triangle: np.ndarray | None
    keep: tuple
    handle: int = 0


def embree_part(local: np.ndarray, triangles: np.ndarray, subset: np.ndarray | slice | None, normal: np.ndarray, build: str = "medium") -> EmbreePart | None:
    """The Embree scene of ``triangles[subset]`` (all when ``None``) without their zero-area ones, committed (``build``: its
    :data:`.embree.BUILD_QUALITY`).

    local : (n, 3) float64 vertices, local frame; subset : (s,) int triangle indices, or a slice of them;
    normal : (s, 3) the subset's plane normals (zero: no area). Embree is given the rows of ``local`` from the
    lowest to the highest vertex the chosen triangles use (their indices moved down to match): the same
    float32 corners and primitives, without a copy of the vertices no chosen triangle uses.
    """
    solid = np.flatnonzero((normal[:, 0] != 0) | (normal[:, 1] != 0) | (normal[:, 2] != 0))  # normal.any(axis=1), column by column: 7x faster
    if not len(solid):
        return None
    if subset is None:
        index = None if len(solid) == len(triangles) else solid
    elif isinstance(subset, slice):
        index = solid + subset.start
    else:
        index = subset[solid]
    chosen = triangles if index is None else triangles[index]
    low, high = int(chosen.min()), int(chosen.max())
    scene = rtcore_scene.EmbreeScene()
    keep = attach_triangles(scene, local[low : high + 1], chosen - np.int32(low) if low else chosen, build)
    commit_scene(scene)
    return EmbreePart(scene, None if index is None else index.astype(np.int64), keep, scene_handle(scene))


@dataclass
class StaticPart:
    """What :class:`CasterCache` keeps of the static objects: their Embree scene and planes, local frame.

    triangle : (s,) int64 buffer triangles of the static objects; normal (s, 3), offset (s,) their planes
    rows : (s,) the object row of each of them when it was kept (a copy), or ``None``; closed : whether each of those
        rows' triangles form closed surfaces (:meth:`RayCaster.closed`), filled by the casters that trace the part
        while their buffers give its triangles these rows
    """

    frame: np.ndarray
    triangle: np.ndarray
    geometry: object  # static_geometry's arrays (copies), or ("key", the caller's key)
    part: EmbreePart | None
    normal: np.ndarray
    offset: np.ndarray
    rows: np.ndarray | None = None
    closed: dict = field(default_factory=dict)

    @cached_property
    def objects(self) -> frozenset:
        """The object rows of its triangles (of :attr:`rows`; empty without them)."""
        return frozenset(np.unique(self.rows).tolist()) if self.rows is not None else frozenset()

    @cached_property
    def corners(self) -> np.ndarray | None:
        """``(s, 3, 3)`` float64 world corners of its triangles, from the geometry's copies; ``None`` for a caller's key."""
        if isinstance(self.geometry[0], str):
            return None
        index, span = self.geometry
        return span[index - index.min()] if len(index) else np.zeros((0, 3, 3))

    def at(self, triangle: np.ndarray) -> "StaticPart":
        """The same part with its triangles at the buffer positions ``triangle`` (s,) sorted (:func:`moved_in_buffers`):
        Embree's scene, the planes and the geometry kept, the primitives mapped to the new positions."""
        part = self.part
        if part is not None:
            within = np.arange(len(self.triangle)) if part.triangle is None else np.searchsorted(self.triangle, part.triangle)
            part = EmbreePart(part.scene, triangle[within].astype(np.int64), part.keep, part.handle)
        return StaticPart(self.frame, np.asarray(triangle), self.geometry, part, self.normal, self.offset)


class RayCaster:
    """Nearest-hit queries against :class:`SceneBuffers`, in a local frame.

    frame : (4, 4) float64 local-to-world transform (a sensor pose); default: a translation to
        the centre of the vertices' bounds. ``intersect`` takes and returns local coordinates.
    threads : threads for Embree (default: :func:`default_threads`); embreex releases the GIL while tracing
    chunk : rays per embreex call
    kernel : ``"auto"`` (the compiled diffuse path of :mod:`.kernels` when numba is importable),
        ``"numba"`` (required) or ``"numpy"``; default: the environment variable
        :data:`KERNEL_VARIABLE`, else ``"auto"``. Both give the same bytes.
    static : the static objects' part kept by a :class:`CasterCache` (use :meth:`CasterCache.caster`)
    record_pool : the :class:`RecordPool` its scans' records come from (default: its own; a cache shares one across frames)
    pool : the thread pool its work runs on beside the calling thread, ``threads - 1`` workers (default: its own,
        made on first use; a cache shares one across frames, so a frame's caster starts no threads)
    build : the :data:`.embree.BUILD_QUALITY` of the Embree scene it builds: ``"medium"`` (Embree's default), or ``"low"``
        for a caster few rays are traced through (:class:`.visibility.AloneCaster`): a third of the build's CPU, slower
        traces. Each ray's nearest hit is the same; only a ray meeting two triangles at one distance (through a shared
        edge) may be given the other one
    ``InputError`` (naming the object) for non-finite vertices, bad triangle indices, or vertices
    farther than :data:`MAX_COORDINATE` from the local origin.
    """

    def __init__(self, buffers: SceneBuffers, frame=None, threads: int | None = None, chunk: int = 32768, kernel: str | None = None, *,
                 static: StaticPart | None = None, record_pool: RecordPool | None = None, pool: ThreadPoolExecutor | None = None,
                 build: str = "medium"):
        if len(buffers.triangles):
            buffers.check()
        vertices = np.asarray(buffers.vertices, np.float64)
        if frame is None:
            frame = np.eye(4)
            frame[:3, 3] = (vertices.min(axis=0) + vertices.max(axis=0)) / 2 if len(vertices) else 0.0
        self.frame = np.asarray(frame, np.float64)
        self.origin = self.frame[:3, 3]
        self.world_to_local = np.linalg.inv(self.frame)  # (4, 4), once per caster
        self.threads = int(threads) if threads else default_threads()
        self.chunk = chunk
        self.kernels = choose_kernels(kernel)
        self.buffers = buffers
        triangles = np.ascontiguousarray(buffers.triangles, np.int32)
        self.triangle_object = np.asarray(buffers.triangle_object)
        self.objects = len(buffers.objects)
        shift = np.zeros(3)
        if static is not None and not np.array_equal(static.frame, self.frame):
            if not translated(static.frame, self.frame):
                raise ValueError("RayCaster: the static part was built for a frame turned against this one")
            shift = (self.origin - static.frame[:3, 3]) @ self.frame[:3, :3]  # this frame's origin in the part's frame
        if static is not None and len(static.triangle) == len(triangles) and not shift.any():
            # nothing moves: the kept planes as they are (read only); its vertices' extent was checked when it was built,
            # in this frame, from the same triangles and vertex rows (compared byte for byte by the cache, or the caller's key)
            self.plane_normal, self.plane_offset = static.normal, static.offset
            parts = [static.part]
        elif static is None:
            local = self.to_local(vertices)
            check_extent(local, triangles, buffers)
            self.plane_normal, self.plane_offset = triangle_planes(local, triangles, self.kernels)  # (m, 3), (m,) local frame
            parts = [embree_part(local, triangles, None, self.plane_normal, build)]
        else:
            m = len(triangles)
            kept, moving = as_block(static.triangle), complement(static.triangle, m)  # slices where they are blocks of rows
            local = self._moving_local(vertices, triangles, moving)  # the kept part's vertices were checked where it was built
            self.plane_normal, self.plane_offset = np.empty((m, 3)), np.empty(m)
            # the kept planes as they are, moved into this frame: n . x = offset in the part's frame is n . x = offset - n . shift here
            self.plane_normal[kept] = static.normal
            self.plane_offset[kept] = static.offset - dot3(shift, static.normal) if shift.any() else static.offset
            if isinstance(moving, slice):  # the moving triangles' planes, solved in this frame into this caster's rows
                triangle_planes(local, triangles[moving], self.kernels, out=(self.plane_normal[moving], self.plane_offset[moving]))
            else:
                self.plane_normal[moving], self.plane_offset[moving] = triangle_planes(local, triangles[moving], self.kernels)
            parts = [static.part, embree_part(local, triangles, moving, self.plane_normal[moving], build)]
        # (q, 3) float64 added to the rays' local origins for each part: the kept static part's Embree scene lies in the
        # frame it was built in, a translation of this one (CasterCache); Embree only chooses the triangle, solved here
        self.part_shift = np.array([shift if p is parts[0] and static is not None else np.zeros(3) for p in parts if p is not None]).reshape(-1, 3)
        self.parts = [p for p in parts if p is not None]
        # Embree's primID indexes the solid triangles; with one part, map them here, with two, in _embree
        self.embree_triangle = self.parts[0].triangle if len(self.parts) == 1 else None
        # For the compiled pass that calls Embree itself: the parts' scenes and primitive maps ((0,): the identity)
        handles = [p.handle for p in self.parts]
        self.embree_handles = np.array(handles, np.uint64) if all(handles) else None
        self.part_triangle = (tuple(p.triangle if p.triangle is not None else np.zeros(0, np.int64) for p in self.parts)
                              + (np.zeros(0, np.int64),) * (2 - len(self.parts)))
        self._pool = pool
        self._closed: dict[int, bool] = {}
        self._static = static
        self.record_pool = record_pool if record_pool is not None else RecordPool()

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """``(n, 3)`` world points into the local frame."""
        return (np.asarray(points, np.float64) - self.origin) @ self.frame[:3, :3]

    def _moving_local(self, vertices: np.ndarray, triangles: np.ndarray, moving) -> np.ndarray:
        """``(n, 3)`` float64 whose rows from the lowest to the highest vertex ``triangles[moving]`` use hold their local
        coordinates (:meth:`to_local`: each row's product alone, the same bits), the others unset; their extent checked.

        A street frame's moving objects use about 12,000 of its 145,000 vertices (the static world's come first)."""
        local = np.empty_like(vertices)
        chosen = triangles[moving]
        if len(chosen):
            low, high = int(chosen.min()), int(chosen.max())
            local[low : high + 1] = self.to_local(vertices[low : high + 1])
            check_extent(local[low : high + 1], chosen - np.int32(low), self.buffers, moving)
        return local

    def closed(self, row: int) -> bool:
        """Whether object ``row``'s triangles form closed surfaces (:func:`closed_surface`); kept per caster, and for
        the static objects in the kept static part (:attr:`StaticPart.closed`: for the run, while it is reused)."""
        if row not in self._closed:
            kept = self._kept_closed
            if kept is None:
                self._closed[row] = closed_surface(self._triangles_of(row, slice(None)))
            elif row in self._static.objects:
                if row not in kept:
                    kept[row] = closed_surface(self._triangles_of(row, slice(None)))
                self._closed[row] = kept[row]
            else:  # not a row of the static part's triangles: all its triangles are among the others
                self._closed[row] = closed_surface(self._triangles_of(row, complement(self._static.triangle, len(self.triangle_object))))
        return self._closed[row]

    def _triangles_of(self, row: int, among) -> np.ndarray:
        """``(t, 3)`` the buffer triangles of object ``row``, in buffer order, searched ``among`` the triangles a slice or
        (k,) sorted indices give (which must hold all of that row's)."""
        return self.buffers.triangles[among][self.triangle_object[among] == row]

    @cached_property
    def _kept_closed(self) -> dict | None:
        """The static part's :attr:`StaticPart.closed` when these buffers give its triangles the rows it keeps (a static
        row's triangles are then the same ones: the part's, compared or keyed by the cache), else ``None``."""
        static = self._static
        if static is None or static.rows is None or len(static.rows) != len(static.triangle):
            return None
        return static.closed if np.array_equal(self.triangle_object[as_block(static.triangle)], static.rows) else None

    def corner_scales(self, triangle: np.ndarray) -> np.ndarray:
        """``(k,)`` float64 largest local coordinate (in absolute value) of the corners of each of ``triangle`` (k,) buffer
        triangles: the mirror and glass triangles rays are re-launched from (their offsets), only those."""
        buffers = self.buffers
        corners = self.to_local(buffers.vertices[buffers.triangles[triangle].reshape(-1)]).reshape(-1, 9)
        return np.abs(corners).max(axis=1)

    def _embree(self, origins32: np.ndarray, directions32: np.ndarray, far: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Embree alone, chunked over the thread pool: ``(tfar, prim)`` per ray; ``far`` is left as it was.

        directions32 : (n, 3) float32, or float64 converted chunk by chunk on the worker threads
        prim : (n,) Embree primitive (map it with :meth:`_triangles`), -1 for a miss. embreex writes
        each hit's distance into the ``dists`` array it is given, so every call gets a copy.
        With two parts (static and moving), the moving one is traced up to the static hit and the
        nearer hit is kept, as a buffer triangle index. Only Embree (and that merge) runs in the
        worker threads: embreex takes the GIL back after every call, so numpy work on another
        thread would stall it. Where the compiled kernels call Embree themselves, they answer instead
        (:func:`.numba_kernels.trace_rays`: ``rtcIntersect8`` on packets of eight rays, the same answer).
        """

        n = len(directions32)
        tfar_out, prim_out = self.record_pool.take(n, np.float32), self.record_pool.take(n, np.int32)  # each thread fills its rows: no join
        traces = self.kernels is not None and self.kernels.traces and self.embree_handles is not None

        def run(start):
            s = slice(start, start + self.chunk)
            if traces:  # Embree called from the compiled pass: the same hits, without embreex's arrays per call (about half of a small call's time)
                self.kernels.trace_rays(self.embree_handles, self.part_triangle, self.part_shift, far[s],
                                        origins32[s], directions32[s], tfar_out[s], prim_out[s])
                return
            limit = np.array(far[s], np.float32)  # a copy: embreex writes the hits' distances into it
            d32 = directions32[s] if directions32.dtype == np.float32 else np.ascontiguousarray(directions32[s], np.float32)
            best = None
            for part, shift in zip(self.parts, self.part_shift):
                out = part.scene.run(shifted_origins(origins32[s], shift), d32, dists=limit if best is None else best[0].copy(), output=1)
                prim = out["primID"]
                if len(self.parts) == 1:
                    best = (out["tfar"], prim)
                    break
                hit = prim >= 0
                triangle = np.where(hit, part.triangle[np.where(hit, prim, 0)] if part.triangle is not None else prim, -1)
                if best is None:
                    best = (out["tfar"], triangle)
                else:
                    best = (np.where(hit, out["tfar"], best[0]), np.where(hit, triangle, best[1]))
            if best is None:
                best = (far[s], -1)
            tfar_out[s], prim_out[s] = best

        self.map(run, range(0, n, self.chunk))
        return tfar_out, prim_out

    def map(self, fn, items) -> list:
        """``[fn(item) for item in items]`` on the caster's threads, the calling one among them (:func:`.sharing.share`;
        Embree and the compiled kernels release the GIL)."""
        items = list(items)
        if self.threads > 1 and len(items) > 1 and self._pool is None:
            self._pool = ThreadPoolExecutor(self.threads - 1, "caster")
            weakref.finalize(self, self._pool.shutdown)
        return share(self._pool, fn, items, self.threads)

    def launch(self, origins, directions, max_distance=FAR, directions32=None, convert: bool = True):
        """The float32 query of :meth:`intersect`: ``(local (3,) or (n, 3) float64, origins32, directions32, far32)``.

        convert : False leaves float64 directions as they are (:meth:`_embree` converts them chunk by chunk)
        """
        n = len(directions)
        local = np.asarray(origins, np.float64)
        if local.ndim == 1 and not local.any():  # one zero origin, repeated by strides (embreex only reads it)
            origins32 = np.lib.stride_tricks.as_strided(np.zeros(3, np.float32), (n, 3), (0, 4), writeable=True)
        else:
            origins32 = np.ascontiguousarray(np.broadcast_to(local, (n, 3)), np.float32)
        far = np.empty(n, np.float32)
        far[:] = np.minimum(max_distance, FAR)
        if directions32 is None:
            directions32 = np.ascontiguousarray(directions, np.float32) if convert else directions
        return local, origins32, directions32, far

    def intersect(self, origins, directions, max_distance=FAR, directions32=None) -> Hits:
        """Nearest hit of each ray (Embree on every core, then float64 refinement), local frame; the numpy path.

        origins : (n, 3) or (3,) float64 local coordinates, metres ((3,): one shared origin)
        directions : (n, 3) float64 unit vectors, local frame
        max_distance : float or (n,) float64; hits beyond are misses
        directions32 : the same directions as float32, when the caller already has them
        """
        directions = np.asarray(directions, np.float64)
        local, origins32, directions32, far = self.launch(origins, directions, max_distance, directions32)
        shared = local.ndim == 1
        tfar, prim = self._embree(origins32, directions32, far)
        ray, triangle, normal, d, denom = self._gather(prim, directions)
        front, back = self._faces(triangle, denom)
        suspect = self.suspects(front, back, prim, lambda both: ray[(denom > 0) & both[self.triangle_object[triangle]]])
        moved = None
        if len(suspect):
            tfar, prim, moved = self.retrace(suspect, local, directions, far, tfar, prim)
            ray, triangle, normal, d, denom = self._gather(prim, directions)
        o_dot_n = dot3(local, normal) if shared else dot3(local[ray], normal)
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
            ray, distance, triangle, normal, d = ray[inside], distance[inside], triangle[inside], normal[inside], d[inside]
        return Hits(ray, distance, triangle, normal, d)

    def _gather(self, prim: np.ndarray, directions: np.ndarray):
        """``(ray, triangle, normal, direction, d.n)`` of the rays that hit, each gathered once."""
        ray = np.flatnonzero(prim >= 0)
        triangle = self._triangles(prim[ray])
        normal = self.plane_normal[triangle]
        d = directions[ray]
        return ray, triangle, normal, d, dot3(d, normal)

    def _faces(self, triangle: np.ndarray, denom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(front, back)`` (k,) bool: the objects some ray hit from the front (d.n < 0), and from behind (d.n > 0)."""
        obj = self.triangle_object[triangle]
        front = np.bincount(obj[denom < 0], minlength=self.objects)[: self.objects] > 0
        back = np.bincount(obj[denom > 0], minlength=self.objects)[: self.objects] > 0
        return front, back

    def _triangles(self, prim: np.ndarray) -> np.ndarray:
        """Buffer triangle indices (int64) of Embree primitive ids (of :meth:`_embree`)."""
        return prim.astype(np.int64) if self.embree_triangle is None else self.embree_triangle[prim]

    def suspects(self, front: np.ndarray, back: np.ndarray, prim: np.ndarray, back_hits) -> np.ndarray:
        """Rays that may have slipped through a vertex (see the module notes): indices among the n queried.

        front, back : (k,) bool objects hit from the front and from behind (:meth:`_faces`)
        prim : (n,) Embree's answer (-1: a miss); back_hits : a callable giving, for the objects
        flagged in its (k,) bool argument, the rays that hit their back faces; called only when
        some closed object (:meth:`closed`) was hit from both sides
        """
        both = front & back  # an open object (a pane, a leaf, a fence) is hit from behind by rays that slipped nowhere
        for row in np.flatnonzero(both):
            both[row] = self.closed(int(row))
        suspect = []
        if both.any():
            suspect.append(back_hits(both))
        if len(prim) and prim.min() < 0 and any(self.closed(int(row)) for row in np.flatnonzero(back & ~front)):  # the origin is enclosed: no ray can miss
            suspect.append(np.flatnonzero(prim < 0))
        return np.concatenate(suspect) if suspect else np.zeros(0, np.int64)

    def retrace(self, rays, local, directions, far, tfar, prim) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Trace ``rays`` again, moved by :data:`JITTER` four ways across; keep the nearest hit.

        far : (n,) float32 the query's own limits (never Embree's output). Returns new
        ``(tfar, prim, moved)``, moved (n,) bool: the rays whose hit now comes from a moved ray.
        Four ways (two crossed axes, both senses), since a ray that slipped in where it only just
        enters the mesh can be moved out of it by one of them.
        """
        d = directions[rays]
        o = np.broadcast_to(local, (len(directions), 3))[rays]
        # Two unit vectors across each ray: u = d x (the axis d is least aligned with), and d x u.
        axis = np.zeros_like(d)
        axis[np.arange(len(d)), np.argmin(np.abs(d), axis=1)] = 1.0
        u = np.cross(d, axis)
        u /= row_norms(u)[:, None]
        shift = JITTER * (1.0 + np.abs(o).max(axis=1))
        v = np.cross(d, u)
        ways = (u, -u, v, -v)
        # the four ways in one Embree query (each ray's answer is its own): origins and directions way after way
        turned = np.concatenate([d + JITTER * across for across in ways])
        turned /= row_norms(turned)[:, None]
        o32 = np.ascontiguousarray(np.concatenate([o + shift[:, None] * across for across in ways]), np.float32)
        best_t, best_p = tfar[rays].copy(), prim[rays].copy()
        # A way wins only when strictly nearer than the ray's own hit: Embree looks no farther (the nearest hit within
        # that bound is the one it finds unbounded, and a hit beyond never wins), and skips more of the scene.
        bound = np.where(best_p >= 0, best_t, far[rays])
        t4, p4 = self._embree(o32, np.ascontiguousarray(turned, np.float32), np.tile(bound, len(ways)))
        moved = np.zeros(len(rays), bool)
        for t2, p2 in zip(t4.reshape(len(ways), len(rays)), p4.reshape(len(ways), len(rays))):  # in order: a later way wins only when strictly nearer
            better = (p2 >= 0) & ((best_p < 0) | (t2 < best_t))
            best_t[better], best_p[better] = t2[better], p2[better]
            moved |= better
        take = rays[moved]
        tfar, prim = tfar.copy(), prim.copy()
        tfar[take], prim[take] = best_t[moved], best_p[moved]
        flags = np.zeros(len(directions), bool)
        flags[take] = True
        return tfar, prim, flags


def shifted_origins(origins32: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``(n, 3)`` float32 ray origins for an Embree part whose frame is this caster's moved by ``-shift`` (3,) float64: the
    float32 origins plus ``shift`` in float64, rounded again (the compiled trace's arithmetic); as given for no shift."""
    if not shift.any():
        return origins32
    return np.ascontiguousarray(origins32.astype(np.float64) + shift, np.float32)


def anchored(frame: np.ndarray) -> np.ndarray:
    """``frame`` (4, 4) with its origin moved to the nearest point of a grid of :data:`FOLLOW_GRID` metres: the frame a
    static part that follows a sensor is built in (:meth:`CasterCache.caster`); a street layout, about the world's
    origin, gets one frame for every pose of its ego car."""
    home = np.array(frame, np.float64)
    home[:3, 3] = np.round(home[:3, 3] / FOLLOW_GRID) * FOLLOW_GRID
    return home


def translated(kept: np.ndarray, frame: np.ndarray) -> bool:
    """Whether the (4, 4) frame ``frame`` is ``kept`` moved by a translation of at most :data:`MAX_SHIFT` metres (the same
    rotation, bit for bit), so a static part built in ``kept`` can serve it with its rays' origins shifted."""
    return (np.array_equal(kept[:3, :3], frame[:3, :3]) and np.array_equal(kept[3], frame[3])
            and float(np.abs(frame[:3, 3] - kept[:3, 3]).max()) <= MAX_SHIFT)  # fmt: skip


class RecordPool:
    """Memory for a caster's record arrays, used again once no array made from it is alive.

    A scan's records go into fresh memory otherwise, and the system maps and zeroes every page of it
    as the compiled pass first writes there (about 1 microsecond per 4 KiB page: 15 to 20 ns per hit,
    as much as the pass itself). Records taken from the pool are views of a kept byte buffer; while
    any such view (or a view of it) is alive the buffer is busy, so nothing a caller holds is ever
    written again. At most ``limit`` buffers are kept (the largest asked for); beyond that, fresh memory.
    """

    def __init__(self, limit: int = 8):
        self.limit = limit
        self.buffers: list[np.ndarray] = []
        self.lock = threading.Lock()

    def take(self, n: int, dtype) -> np.ndarray:
        """An uninitialised ``(n,)`` array of ``dtype``."""
        dtype = np.dtype(dtype)
        nbytes = n * dtype.itemsize
        if nbytes < 1 << 16:  # small: not worth keeping
            return np.empty(n, dtype)
        with self.lock:
            free = [k for k in range(len(self.buffers)) if sys.getrefcount(self.buffers[k]) == 2]  # the list's reference and the call's: no view alive
            fits = [k for k in free if len(self.buffers[k]) >= nbytes]
            if fits:
                buf = self.buffers[min(fits, key=lambda k: len(self.buffers[k]))]
            elif free or len(self.buffers) < self.limit:
                buf = np.empty(nbytes, np.uint8)
                if free:  # too small: replaced by a larger one
                    self.buffers[free[0]] = buf
                else:
                    self.buffers.append(buf)
            else:
                return np.empty(n, dtype)
            return buf[:nbytes].view(dtype)


def choose_kernels(kernel: str | None):
    """The compiled kernels (:func:`.kernels.compiled`) the choice asks for, or ``None`` for the numpy path."""
    kernel = kernel or os.environ.get(KERNEL_VARIABLE) or "auto"
    if kernel not in KERNELS:
        raise InputError(f"scan kernel {kernel!r} (argument or {KERNEL_VARIABLE}): use one of {', '.join(KERNELS)}")
    if kernel == "numpy":
        return None
    compiled = kernels.compiled()
    if compiled is None and kernel == "numba":
        raise InputError("scan kernel 'numba': numba is not installed; pip install 'bpy_pipeline[fast]' or use 'auto'")
    return compiled


class CasterCache:
    """A run's static objects' Embree scene and planes, kept from frame to frame by the run that owns it.

    ``cache.caster(buffers, frame, moving)`` returns a :class:`RayCaster` of all of ``buffers``.
    The triangles of the object rows not flagged in ``moving`` form the static part: when they
    (their buffer positions and their vertices, compared byte for byte with the copy kept of
    :func:`static_geometry`, or the caller's ``key``) and ``frame`` are exactly those of the previous
    call, its Embree scene and planes are reused; so are they when the same triangles, corner for corner, come at other
    buffer positions (:func:`moved_in_buffers`: moving objects exported among the static ones); otherwise they are
    built and kept. The moving rows get a small Embree scene of their own each call;
    the caster traces both and keeps the nearer hit (the same triangle, hence the same bytes,
    as one caster of all the buffers, but for exact ties).

    threads, kernel : as :class:`RayCaster`. ``builds`` and ``reuses`` count the static parts built and reused.
    """

    def __init__(self, threads: int | None = None, kernel: str | None = None):
        self.threads, self.kernel = threads, kernel
        self.kept: StaticPart | None = None
        self.builds = self.reuses = 0
        self.record_pool = RecordPool()  # the record memory of every frame's caster
        self._pool: ThreadPoolExecutor | None = None  # the threads of every frame's caster (started once)

    @property
    def pool(self) -> ThreadPoolExecutor | None:
        """The thread pool every caster of this cache runs on beside the calling thread (``threads - 1`` workers:
        :func:`.sharing.share`; ``None`` with one thread); made on first use."""
        threads = int(self.threads) if self.threads else default_threads()
        if threads > 1 and self._pool is None:
            self._pool = ThreadPoolExecutor(threads - 1, "caster")
            weakref.finalize(self, self._pool.shutdown)
        return self._pool

    def caster(self, buffers: SceneBuffers, frame, moving: np.ndarray | None = None, key=None, follow: bool = False) -> RayCaster:
        """A caster of ``buffers`` in ``frame`` ((4, 4) float64 local-to-world, e.g. a fixed pose for the run).

        moving : (k,) bool per row of ``buffers.objects``: the objects rebuilt every call (None: none)
        key : optional; when given, the caller's word that equal keys mean equal static geometry
            (e.g. the builder's parameters and seed): the static part's bytes are not compared
        follow : build the static part in :func:`anchored` ``frame`` (its rotation, its origin on a grid of
            :data:`FOLLOW_GRID` metres) instead of ``frame``, so every pose of a sensor driving through a static world
            without turning, within one grid cell, reuses it: its Embree scene and its triangles' planes stay in the
            anchored frame; the rays' origins are shifted into it for Embree (:attr:`RayCaster.part_shift`) and the
            planes' offsets moved into ``frame`` (``offset - n . shift``, one pass over the static triangles instead of
            their vertices moved and their planes solved again every frame). Embree then rounds the static triangles to
            float32 in the anchored frame instead of ``frame``: a ray passing within float32's rounding of an edge may
            meet the neighbouring triangle; every distance is still solved in float64 in ``frame``, against planes
            whose offsets differ from ones solved there by float64's rounding (about 1e-14 m in a street). The anchored
            frame depends on ``frame`` alone, so a frame gives the same bytes whichever frame built the part
        """
        frame = np.asarray(frame, np.float64)
        k = len(buffers.objects)
        moving = np.zeros(k, bool) if moving is None else np.asarray(moving, bool)
        if moving.shape != (k,):
            raise InputError(f"CasterCache.caster: moving must give each of the {k} object rows a flag, not shape {moving.shape}")
        static = np.flatnonzero(~moving[buffers.triangle_object]) if moving.any() else np.arange(len(buffers.triangles))
        geometry = ("key", key) if key is not None else static_geometry(buffers, static)
        home = anchored(frame) if follow else frame  # the frame the static part lies in
        kept = self.kept
        same_frame = kept is not None and np.array_equal(kept.frame, home)
        same_place = same_frame and np.array_equal(kept.triangle, static)
        if same_place and same_geometry(kept.geometry, geometry):
            self.reuses += 1
            part = kept
        elif same_frame and not same_place and key is None and moved_in_buffers(kept, buffers, static):
            self.reuses += 1  # the same static triangles at other buffer positions (the moving objects exported among them)
            part = kept.at(static)
        else:
            if key is None:  # a copy of its own: the caller's buffers may change in place later
                geometry = tuple(np.array(a) for a in geometry)
            if len(buffers.triangles):
                buffers.check()  # before any index is used to build (the reused path is checked by RayCaster)
            self.builds += 1
            if not moving.any() and not follow:  # nothing moves: the whole scene is the static part
                caster = RayCaster(buffers, frame, self.threads, kernel=self.kernel, record_pool=self.record_pool, pool=self.pool)
                self.kept = StaticPart(frame, static, geometry, caster.parts[0] if caster.parts else None, caster.plane_normal, caster.plane_offset,
                                       np.array(caster.triangle_object), caster._closed)  # fmt: skip
                return caster
            local = (np.asarray(buffers.vertices, np.float64) - home[:3, 3]) @ home[:3, :3]
            triangles = np.ascontiguousarray(buffers.triangles, np.int32)
            check_extent(local, triangles, buffers)
            normal, offset = triangle_planes(local, triangles[static], choose_kernels(self.kernel))
            part = self.kept = StaticPart(home, static, geometry, embree_part(local, triangles, static, normal), normal, offset,
                                          np.array(buffers.triangle_object[as_block(static)]))
        return RayCaster(buffers, frame, self.threads, kernel=self.kernel, static=part, record_pool=self.record_pool, pool=self.pool)


def moved_in_buffers(kept: StaticPart, buffers: SceneBuffers, static: np.ndarray) -> bool:
    """Whether the triangles ``static`` (s,) of ``buffers`` are the kept part's, corner for corner and in its order, at
    other buffer positions: a builder that exports its moving objects among the static ones (the street's road users)
    shifts the static triangles' indices every frame though none of them changed. Corners are compared as the bits of
    their float64 coordinates (:func:`same_geometry`'s rule)."""
    if len(static) != len(kept.triangle) or not len(static) or kept.corners is None:
        return False
    now = np.asarray(buffers.vertices, np.float64)[buffers.triangles[static]]  # a new (s, 3, 3) array
    return np.array_equal(kept.corners.view(np.int64), now.view(np.int64))


def static_geometry(buffers: SceneBuffers, static: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What a kept static part stands for: triangles ``static`` ((s, 3) int32 indices, contiguous) and the vertex
    rows they span ((hi - lo + 1, 3) float64, world, contiguous); views of ``buffers`` where they can be.

    The span also holds any moving object whose vertices lie between the static ones': it then changes
    with it, and the kept part is found again by its corners (:func:`moved_in_buffers`).
    """
    every = len(static) == len(buffers.triangles)  # static is then 0..m-1
    index = np.ascontiguousarray(buffers.triangles if every else buffers.triangles[static])
    if not len(index):
        return index, np.zeros((0, 3))
    return index, np.ascontiguousarray(buffers.vertices[index.min() : index.max() + 1], np.float64)


def same_geometry(kept, geometry) -> bool:
    """Whether two :func:`static_geometry` results (or two ``("key", key)`` pairs) are the same, byte for byte.

    Arrays are compared as integers of their item's size, so ``-0.0`` and ``0.0`` differ (as they would in
    a digest of the bytes); a comparison runs at memory speed (0.2 ms for a 235 k-triangle railway, where its
    sha256 took 2-8 ms a frame)."""
    keyed = [isinstance(g[0], str) for g in (kept, geometry)]
    if any(keyed):
        return all(keyed) and kept[1] == geometry[1]

    def raw(a):  # integers of the item's size (int32 indices, float64 vertices): whole items compared, bits not values
        return a.view(np.dtype(f"i{a.dtype.itemsize}"))

    return all(a.dtype == b.dtype and a.shape == b.shape and np.array_equal(raw(a), raw(b)) for a, b in zip(kept, geometry))


def as_block(index: np.ndarray) -> np.ndarray | slice:
    """``index`` (k,) sorted, distinct rows as ``slice(first, last + 1)`` when they are consecutive (a view, no gather), else as given."""
    if len(index) and int(index[-1]) - int(index[0]) + 1 == len(index):
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


def complement(index: np.ndarray, m: int) -> np.ndarray | slice:
    """The rows of ``0..m-1`` not in ``index`` (k,) sorted, distinct: a slice when they are consecutive (:func:`as_block`), else (m - k,) int64."""
    block = as_block(index)
    if isinstance(block, slice) and (block.start == 0 or block.stop == m):
        return slice(block.stop, m) if block.start == 0 else slice(0, block.start)
    if not len(index):
        return slice(0, m)
    rest = np.ones(m, bool)
    rest[index] = False
    return np.flatnonzero(rest)


def check_extent(local: np.ndarray, triangles: np.ndarray, buffers: SceneBuffers, among: slice | np.ndarray = slice(None)) -> None:
    """``InputError`` naming the first object with a vertex beyond :data:`MAX_COORDINATE` of the local origin.

    triangles : (m, 3) indices into ``local``, the buffer triangles ``among`` picks (a slice or (m,) indices: all by default)"""
    if not (local.max(initial=0.0) > MAX_COORDINATE or local.min(initial=0.0) < -MAX_COORDINATE):  # |local| without its copy
        return
    too_far = np.abs(local).max(axis=1, initial=0.0) > MAX_COORDINATE
    if too_far.any():
        bad = np.flatnonzero(too_far[triangles].any(axis=1))
        if len(bad):
            name = buffers.objects.names[buffers.triangle_object[among][bad[0]]]
            raise InputError(
                f"object {name!r}: has vertices more than {MAX_COORDINATE:.0e} m from the local origin (the sensor) "
                f"({np.abs(local[triangles[bad[0]]]).max():.3g} m); check its scale and location"
            )


def triangle_planes(vertices: np.ndarray, triangles: np.ndarray, compiled=None, out=None) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals ``(m, 3)`` float64 (winding order; zero for zero-area triangles) and offsets ``(m,)`` n . v0.

    vertices : (n, 3) float64; triangles : (m, 3) int indices. Computed in steps of
    :data:`PLANE_CHUNK` triangles so the temporaries stay small for 10-million-triangle scenes.
    compiled : :func:`.kernels.compiled`'s kernels: one pass, the same bits (``tests/test_scan_kernel.py``)
    out : ``(normal, offset)`` to write them into ((m, 3) and (m,) float64, C-contiguous, e.g. a block of a caster's rows)
    """
    m = len(triangles)
    normal, offset = (np.empty((m, 3)), np.empty(m)) if out is None else out
    if compiled is not None and m:
        compiled.triangle_planes(np.ascontiguousarray(vertices, np.float64), np.ascontiguousarray(triangles), normal, offset)
        return normal, offset
    for start in range(0, m, PLANE_CHUNK):
        s = slice(start, start + PLANE_CHUNK)
        v0, v1, v2 = (vertices[triangles[s, k]] for k in range(3))
        cross = np.cross(v1 - v0, v2 - v0)
        area2 = row_norms(cross)
        normal[s] = cross / np.where(area2 > 0, area2, 1.0)[:, None]
        offset[s] = np.einsum("ij,ij->i", normal[s], v0)
    return normal, offset
