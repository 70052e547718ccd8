"""A flash camera's own image outputs: depth and intensity per pixel, with several returns where a pixel sees two surfaces.

A flash (direct time-of-flight) camera lights its whole field at once; each pixel of its receiver
integrates the light coming back from its own solid angle (about 0.83 x 0.83 deg for the sparse
3D camera) and its histogram can hold one peak per surface at a distinct range. The sparse-camera
thesis names these multiple returns per pixel as the camera's advantage over CARLA's model, which
casts one ray per pixel. Here each pixel's footprint is sampled by ``sub x sub`` rays spread
evenly over the pixel's cell (image-plane cell of a ``pinhole`` camera, angular cell of a
``grid`` one); their hits, sorted by range, split into returns where consecutive ranges differ by
more than ``separation`` metres (the pulse's range resolution) and the farther hit lies more than
``separation`` off the nearer one's surface plane (so a slanted road, whose sub-rays spread over
metres of range, stays one broadened return, as its echo does). A return's range is the mean of
its sub-rays' ranges weighted by their received power (reflectivity x cos incidence), its
intensity that power summed over the pixel's sub-rays (the share of the pixel it fills x its
reflectance), its labels those of its strongest sub-ray. The nearest ``max_returns`` returns are
kept, nearest first.

Images (``R = max_returns``): ``depth`` (R, rows, columns) float32 metres along the pixel's ray
(0 = no return), ``intensity`` (R, rows, columns) float32 0..1, ``semantic`` (R, rows, columns)
uint16, ``instance`` (R, rows, columns) uint32. Row 0 is the top row, column 0 the left column
(the pattern's image order).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .raycast import RayCaster
from .scanner import trace_beams
from ..sensor.sensors import SensorSpec, azimuths, check_flash, elevations


@dataclass(frozen=True)
class FlashImages:
    """A flash camera's frame as images (see the module docstring)."""

    depth: np.ndarray
    intensity: np.ndarray
    semantic: np.ndarray
    instance: np.ndarray

    @property
    def returns_per_pixel(self) -> np.ndarray:
        """``(rows, columns)`` int: how many returns each pixel holds."""
        return (self.depth > 0).sum(axis=0)


def footprint_directions(spec: SensorSpec, sub: int) -> np.ndarray:
    """``(rows, columns, sub * sub, 3)`` unit directions (sensor frame) spread evenly over each pixel's cell."""
    check_flash(spec, "flash image")
    rows, columns = int(spec.channels), int(spec.columns)
    offsets = (np.arange(sub) + 0.5) / sub - 0.5  # within the cell, in cell units
    du, dv = np.meshgrid(offsets, offsets, indexing="ij")
    du, dv = du.ravel(), dv.ravel()
    out = np.empty((rows, columns, sub * sub, 3))
    if spec.pattern == "pinhole":
        half = math.radians((spec.horizontal_fov_deg[1] - spec.horizontal_fov_deg[0]) / 2)
        focal = columns / (2.0 * math.tan(half))
        col = np.arange(columns)[None, :, None] + 0.5 + du[None, None, :]
        row = np.arange(rows)[:, None, None] + 0.5 + dv[None, None, :]
        y = -(col - columns / 2) / focal
        z = (rows / 2 - row) / focal
        out[..., 0] = 1.0
        out[..., 1] = np.broadcast_to(y, out.shape[:3])
        out[..., 2] = np.broadcast_to(z, out.shape[:3])
        return out / np.linalg.norm(out, axis=-1, keepdims=True)
    az, el = azimuths(spec), elevations(spec)
    step_az = abs(az[1] - az[0]) if len(az) > 1 else 1.0
    step_el = abs(el[0] - el[1]) if len(el) > 1 else 1.0
    a = np.radians(az[None, :, None] - du[None, None, :] * step_az)  # columns go from the left (high azimuth)
    e = np.radians(el[:, None, None] - dv[None, None, :] * step_el)  # rows go down
    out[..., 0] = np.cos(e) * np.cos(a)
    out[..., 1] = np.cos(e) * np.sin(a)
    out[..., 2] = np.broadcast_to(np.sin(e), out.shape[:3])
    return out


def flash_images(buffers, spec: SensorSpec, pose: np.ndarray, sub: int = 3, separation: float = 0.3, max_returns: int = 2, surfaces=None,
                 threads: int | None = None) -> FlashImages:
    """The :class:`FlashImages` of a flash camera of ``spec`` at ``pose`` (4, 4) in ``buffers`` (see the module docstring)."""
    rows, columns = int(spec.channels), int(spec.columns)
    directions = footprint_directions(spec, sub).reshape(-1, 3)
    n_sub = sub * sub
    shape = (max_returns, rows, columns)
    images = FlashImages(np.zeros(shape, np.float32), np.zeros(shape, np.float32), np.zeros(shape, np.uint16), np.zeros(shape, np.uint32))
    if not len(buffers.triangles):
        return images
    caster = RayCaster(buffers, frame=pose, threads=threads)
    beams = trace_beams(caster, buffers, np.zeros(3), directions, spec.min_range, spec.max_range, max_bounces=0, surfaces=surfaces)
    distance = np.full(len(directions), np.inf)
    power = np.zeros(len(directions))
    row_of = np.full(len(directions), -1, np.int64)
    point = np.zeros((len(directions), 3))
    normal = np.zeros((len(directions), 3))
    objects = buffers.objects
    distance[beams.ray] = beams.path
    point[beams.ray] = beams.point
    corners = buffers.vertices[buffers.triangles[beams.triangle]].astype(np.float64)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal[beams.ray] = (cross / np.maximum(np.linalg.norm(cross, axis=1, keepdims=True), 1e-300)) @ pose[:3, :3]  # world -> local
    owner = buffers.triangle_object[beams.triangle]
    power[beams.ray] = objects.reflectivity[owner] * beams.cos_incidence * beams.gain
    row_of[beams.ray] = owner
    distance, power, row_of = (a.reshape(rows * columns, n_sub) for a in (distance, power, row_of))
    point, normal = point.reshape(rows * columns, n_sub, 3), normal.reshape(rows * columns, n_sub, 3)
    order = np.argsort(distance, axis=1, kind="stable")
    d = np.take_along_axis(distance, order, 1)
    w = np.take_along_axis(power, order, 1)
    r = np.take_along_axis(row_of, order, 1)
    point = np.take_along_axis(point, order[..., None], 1)
    normal = np.take_along_axis(normal, order[..., None], 1)
    hit = np.isfinite(d)
    off_plane = np.abs(np.einsum("pij,pij->pi", normal[:, :-1], point[:, 1:] - point[:, :-1]))
    gap = (np.diff(np.where(hit, d, np.nan), axis=1) > separation) & (off_plane > separation)
    group = np.concatenate([np.zeros((len(d), 1), np.int64), np.cumsum(gap, axis=1)], axis=1)
    for j in range(max_returns):
        member = hit & (group == j)
        any_hit = member.any(axis=1)
        weight = np.where(member, np.maximum(w, 1e-9), 0.0)
        total = weight.sum(axis=1)
        depth = np.where(any_hit, (np.where(member, d, 0.0) * weight).sum(axis=1) / np.maximum(total, 1e-300), 0.0)
        strongest = np.argmax(np.where(member, w, -1.0), axis=1)
        obj = r[np.arange(len(r)), strongest]
        images.depth[j] = depth.reshape(rows, columns)
        images.intensity[j] = np.where(any_hit, np.where(member, w, 0.0).sum(axis=1) / n_sub, 0.0).reshape(rows, columns)
        images.semantic[j] = np.where(any_hit & (obj >= 0), objects.semantic[np.maximum(obj, 0)], 0).reshape(rows, columns)
        images.instance[j] = np.where(any_hit & (obj >= 0), objects.instance[np.maximum(obj, 0)], 0).reshape(rows, columns)
    return images
