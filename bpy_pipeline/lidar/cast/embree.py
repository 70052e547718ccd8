"""Embree scenes whose triangles Embree reads in place from numpy buffers (no per-element copies).

embreex's ``TriangleMesh`` copies every vertex and index into Embree's own buffers through
untyped numpy indexing, about 0.4 us per triangle: more than the trace of a frame for large
scenes. Embree itself can read an application's buffers where they are
(``rtcSetSharedGeometryBuffer``); embreex does not expose it, so :func:`attach_triangles` calls
the Embree library embreex ships with (``ctypes``) on the scene embreex made: embreex still
traces the rays. The vertex buffer is the same float32 ``(x, y, z, pad)`` layout embreex fills,
so Embree builds the same hierarchy and every hit is the same.

The handle of embreex's scene is read from the ``EmbreeScene`` object, whose memory layout is
checked first (:func:`shared_buffers_supported`: object sizes, and the device pointer of a scene
made on a known device). Where the check fails (another embreex build), or the library is not
found, :func:`attach_triangles` falls back to ``TriangleMesh``: slower, same hits.
"""

from __future__ import annotations

import ctypes
import glob
import os
from functools import cache

import numpy as np
from embreex import rtcore, rtcore_scene
from embreex.mesh_construction import TriangleMesh

RTC_GEOMETRY_TYPE_TRIANGLE = 0
RTC_BUFFER_TYPE_INDEX, RTC_BUFFER_TYPE_VERTEX = 0, 1
RTC_FORMAT_UINT3, RTC_FORMAT_FLOAT3 = 0x5003, 0x9003
# Embree's build qualities (RTC_BUILD_QUALITY_*), set on the scene and on its geometry (both are needed for the fast build)
BUILD_QUALITY = {
    "medium": 1,  # Embree's default: a binned SAH hierarchy, for scenes many rays meet
    "low": 0,  # a Morton-code build, about a third of the build's CPU, its traces slower: for scenes few rays meet
}
POINTER = ctypes.sizeof(ctypes.c_void_p)
HEAD = 2 * POINTER  # PyObject_HEAD: reference count and type


@cache
def _library():
    """The Embree library embreex is linked to, with the few functions used here; ``None`` when not found."""
    import embreex

    here = os.path.dirname(embreex.__file__)
    patterns = ("embreex.libs/libembree4*", "embreex/.dylibs/libembree4*", "embreex/libembree4*", "embreex.libs/embree4*.dll", "embreex/embree4*.dll")
    found = [p for pattern in patterns for p in sorted(glob.glob(os.path.join(os.path.dirname(here), pattern)))]
    # An Embree the process already exports (a distribution Blender links the system libembree4 for
    # Cycles) is the one embreex's own calls bound to: its device must not meet the bundled copy's code.
    for path in ([None] if os.name == "posix" else []) + found:
        try:
            lib = ctypes.CDLL(path)
            lib.rtcNewGeometry, lib.rtcIntersect8  # the latter for the compiled pass (lidar/cast/numba_kernels.py)
        except (OSError, AttributeError):
            continue
        v, u, z = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
        lib.rtcNewGeometry.restype, lib.rtcNewGeometry.argtypes = v, [v, ctypes.c_int]
        lib.rtcSetSharedGeometryBuffer.restype = None
        lib.rtcSetSharedGeometryBuffer.argtypes = [v, ctypes.c_int, u, ctypes.c_int, v, z, z, z]
        lib.rtcCommitGeometry.restype, lib.rtcCommitGeometry.argtypes = None, [v]
        lib.rtcAttachGeometry.restype, lib.rtcAttachGeometry.argtypes = u, [v, v]
        lib.rtcReleaseGeometry.restype, lib.rtcReleaseGeometry.argtypes = None, [v]
        lib.rtcGetSceneDevice.restype, lib.rtcGetSceneDevice.argtypes = v, [v]
        lib.rtcReleaseDevice.restype, lib.rtcReleaseDevice.argtypes = None, [v]
        lib.rtcCommitScene.restype, lib.rtcCommitScene.argtypes = None, [v]
        lib.rtcSetSceneBuildQuality.restype, lib.rtcSetSceneBuildQuality.argtypes = None, [v, ctypes.c_int]
        lib.rtcSetGeometryBuildQuality.restype, lib.rtcSetGeometryBuildQuality.argtypes = None, [v, ctypes.c_int]
        return lib
    return None


def _word(address: int) -> int:
    return ctypes.c_void_p.from_address(address).value or 0


def _handles(scene: rtcore_scene.EmbreeScene) -> tuple[int, int]:
    """``(RTCScene, RTCDevice)`` of an embreex scene (layout checked by :func:`shared_buffers_supported`)."""
    scene_handle = _word(id(scene) + HEAD)  # EmbreeScene: PyObject_HEAD, RTCScene scene_i, int is_committed, EmbreeDevice device
    device_object = _word(id(scene) + HEAD + 2 * POINTER)
    return scene_handle, _word(device_object + HEAD)  # EmbreeDevice: PyObject_HEAD, RTCDevice device


@cache
def shared_buffers_supported() -> bool:
    """Whether this embreex's objects have the layout :func:`_handles` reads and its Embree library is found."""
    lib = _library()
    if lib is None:
        return False
    if rtcore_scene.EmbreeScene.__basicsize__ != HEAD + 3 * POINTER or rtcore.EmbreeDevice.__basicsize__ != HEAD + POINTER:
        return False
    device = rtcore.EmbreeDevice()
    scene = rtcore_scene.EmbreeScene(device)
    if _word(id(scene) + HEAD + 2 * POINTER) != id(device):
        return False
    scene_handle, device_handle = _handles(scene)
    if not scene_handle or not device_handle:
        return False
    asked = lib.rtcGetSceneDevice(scene_handle)  # Embree's own answer must name the same device
    lib.rtcReleaseDevice(asked)
    return asked == device_handle


def commit_scene(scene: rtcore_scene.EmbreeScene) -> None:
    """Build ``scene``'s hierarchy now, once, before threads share it.

    Through the library (``ctypes`` lets go of the interpreter lock while Embree builds, so the run's other
    thread goes on meanwhile) where this embreex's layout is the one checked; then embreex's own first
    query, which commits a scene Embree holds unchanged in a few microseconds (and the whole scene
    where the library was not used).
    """
    handle = scene_handle(scene)
    if handle:
        _library().rtcCommitScene(handle)
    scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32), output=1)


def scene_handle(scene: rtcore_scene.EmbreeScene) -> int:
    """The ``RTCScene`` of an embreex scene, or 0 where this embreex's layout is not the one checked."""
    return _handles(scene)[0] if shared_buffers_supported() else 0


def attach_triangles(scene: rtcore_scene.EmbreeScene, vertices: np.ndarray, triangles: np.ndarray, build: str = "medium") -> tuple:
    """Add one triangle geometry to an uncommitted embreex ``scene``; returns the buffers Embree reads.

    vertices : (n, 3) float local coordinates (cast to float32 once, into Embree's layout)
    triangles : (m, 3) int indices into ``vertices``
    build : a :data:`BUILD_QUALITY` of the scene's hierarchy, set on the scene and the geometry (where the library is
        called directly; embreex's own ``TriangleMesh`` builds at its default)
    Keep the returned arrays alive as long as the scene: Embree reads them in place.
    """
    quality = BUILD_QUALITY[build]
    padded = np.zeros((len(vertices) + 1, 4), np.float32)  # x y z pad, and one spare row: Embree loads 16 bytes per vertex
    padded[:-1, :3] = vertices
    triangles = np.ascontiguousarray(triangles)
    # Embree's own copy (the caller may reuse its array); from int32 a plain copy of the same bits (indices >= 0)
    index = triangles.view(np.uint32).copy() if triangles.dtype == np.int32 else triangles.astype(np.uint32)
    if not shared_buffers_supported():
        TriangleMesh(scene, padded[:-1, :3], index.astype(np.int32))
        return ()
    lib = _library()
    scene_handle, device_handle = _handles(scene)
    geometry = lib.rtcNewGeometry(device_handle, RTC_GEOMETRY_TYPE_TRIANGLE)
    if quality != BUILD_QUALITY["medium"]:
        lib.rtcSetSceneBuildQuality(scene_handle, quality)
        lib.rtcSetGeometryBuildQuality(geometry, quality)
    lib.rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, padded.ctypes.data, 0, 16, len(vertices))
    lib.rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, index.ctypes.data, 0, 12, len(index))
    lib.rtcCommitGeometry(geometry)
    lib.rtcAttachGeometry(scene_handle, geometry)
    lib.rtcReleaseGeometry(geometry)
    return padded, index
