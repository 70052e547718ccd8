"""What a sensor sees of each 3D box: truncation by its field of view and range, and the rays that reach
the object through the scene and when it is alone (occlusion). Pure numpy and embreex; the loops over (ray, box)
pairs and over cells are compiled where numba is (:mod:`.visibility_kernels`, the same bytes).

Per box and frame (world-frame :data:`~bpy_pipeline.geometry.boxes.BOX_DTYPE` records, filled in place):

- ``truncation`` (0..1): the share of the object's surface area outside the sensor's field of
  view (directions no ray of the pattern comes near, or beyond its range limits), the LiDAR
  analogue of KITTI's "leaving image boundaries".
- ``visible`` and ``unoccluded`` ray counts: the rays of the pattern that pass near an object are
  traced once through the whole scene (``visible``: the object is the first thing hit) and once
  against every object alone (``unoccluded``); :func:`occlusion_levels` turns ``visible /
  unoccluded`` into KITTI's levels 0..3.

All objects share the two casts of a frame: the rays passing near any box are traced through the
scene once, and the "alone" cast is one caster holding every box's triangles, each object moved to
its own cell of a grid far enough apart that a ray started at an object's bounding sphere can meet
no other object, so each (ray, object) pair is one ray of one cast.
"""

from __future__ import annotations

import numpy as np

from ...buffers import SceneBuffers
from ...geometry.boxes import box_corners, object_triangles
from .raycast import RayCaster, dot3, row_norms
from .scanner import scan_chunk, trace_beams
from ..sensor.rays import Pattern

# cosine: the cone prefilter lets through pairs this far outside an object's cone, so its dot products' rounding never drops a pair the exact test keeps
CONE_MARGIN = 1e-12
CONE_BLOCK = 16384  # rays per block of the numpy cone test: a (block, k) matrix, not (n, k)
SAMPLE_SPACING = 0.1  # m between surface samples for truncation (wider on objects that would need more than about:)
MAX_SAMPLES = 4000  # x 2 (surface_samples' area bound)
COUNTED_IDS = 1 << 22  # instance ids below this are counted through a table of every id (counts_per_instance)


class CellGrid:
    """Cells of ``cell_deg`` in azimuth (``columns``, wrapping) and elevation (``rows``, clamped at the poles)."""

    def __init__(self, cell_deg: float):
        self.cell = float(cell_deg)
        self.columns = int(np.ceil(360.0 / self.cell))
        self.rows = int(np.ceil(180.0 / self.cell)) + 1

    def cells(self, directions: np.ndarray, norm: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(n,)`` row and column of ``(n, 3)`` directions; ``norm``: their ``(n,)`` lengths if the caller has them."""
        d = np.asarray(directions, float)
        azimuth = np.degrees(np.arctan2(d[:, 1], d[:, 0])) + 180.0
        norm = row_norms(d) if norm is None else norm
        elevation = np.degrees(np.arcsin(np.clip(d[:, 2] / np.maximum(norm, 1e-12), -1, 1))) + 90.0
        col = np.floor(azimuth / self.cell).astype(int) % self.columns
        row = np.clip(np.floor(elevation / self.cell).astype(int), 0, self.rows - 1)
        return row, col


class Coverage(CellGrid):
    """The directions a sensor pattern covers: the cells (:class:`CellGrid`) that hold a ray.

    A direction is covered when its cell or a neighbouring one holds a ray, so the coverage is
    exact up to one cell; ``cell_deg`` should be at least the pattern's angular spacing.
    """

    def __init__(self, directions: np.ndarray, cell_deg: float):
        super().__init__(cell_deg)
        self.mask = np.zeros((self.rows, self.columns), bool)
        self.add(directions)

    def add(self, directions: np.ndarray) -> None:
        if len(directions):
            row, col = self.cells(directions)
            self.mask[row, col] = True
            self._grown = None

    def covers(self, directions: np.ndarray) -> np.ndarray:
        """``(n,)`` bool for ``(n, 3)`` directions (sensor frame)."""
        if getattr(self, "_grown", None) is None:  # the mask grown by one cell (azimuth wraps around)
            rows = self.mask | np.vstack([self.mask[1:], self.mask[-1:]]) | np.vstack([self.mask[:1], self.mask[:-1]])
            self._grown = rows | np.roll(rows, 1, axis=1) | np.roll(rows, -1, axis=1)
        row, col = self.cells(directions)
        return self._grown[row, col]


def subset_buffers(buffers: SceneBuffers, rows: list[int]) -> SceneBuffers:
    """The triangles of object ``rows`` alone, with only the vertices they use."""
    keep = np.isin(buffers.triangle_object, rows)
    used, triangles = np.unique(buffers.triangles[keep], return_inverse=True)
    return SceneBuffers(buffers.vertices[used], triangles.reshape(-1, 3).astype(np.int32), buffers.triangle_object[keep], buffers.objects)


def visibility(
    buffers: SceneBuffers,
    boxes: np.ndarray,
    patterns,
    pose: np.ndarray,
    min_range: float,
    max_range: float,
    cell_deg: float = 1.0,
    caster: RayCaster | None = None,
    surfaces=None,
    rng: np.random.Generator | None = None,
    direct_returns: np.ndarray | None = None,
) -> None:
    """Fill ``truncation``, ``visible`` and ``unoccluded`` of world-frame ``boxes`` in place.

    patterns : the sensor's rays (one :class:`Pattern` or an iterable of chunks), sensor frame
    pose : (4, 4) sensor-to-world transform at frame start
    cell_deg : coverage cell for truncation (about the pattern's coarsest angular spacing): the
        rays passing an object mark the directions they cover, taken from the sensor's centre
        to where they pass it (so rays leaving from the sensor's own mirrors count right)
    caster : a :class:`RayCaster` of ``buffers`` in the sensor's frame, if one exists already
    surfaces, rng : the scanner's rules for mirrors and glass and a generator for glass that
        reflects a fraction of beams (:func:`~bpy_pipeline.lidar.cast.scanner.trace_beams`)
    direct_returns : (n,) int64 per ray of the frame's scan of these rays from ``pose`` (all chunks', in order; rays
        beyond it have none), the instance of its return that met no mirror, -1 for none, when the scan drew nothing
        the trace would draw again (:func:`~bpy_pipeline.stages.scan.counts_direct_returns`): ``visible`` counts them
        and the rays passing the boxes are not traced through the scene again (the same counts); a (ray, object) pair
        whose ray's return is on the object's instance counts as ``unoccluded`` without its trace alone (the object is
        the first thing the ray meets in the whole scene, so alone too, up to the rounding of the two casts). Only for
        boxes that hold every object of their instance (:func:`~bpy_pipeline.stages.annotate.boxes_hold_their_instances`)
    The rays that pass within an object's bounding sphere are traced the scanner's way (glass
    passed through, no mirror bounces), per chunk once through the whole scene for all objects
    together (unless ``direct_returns`` has their answer) and once against all objects alone
    (:class:`AloneCaster`; with ``direct_returns``, after the last chunk, the pairs it does not answer, against the
    objects they pass), so a car's windows count the same in both.
    """
    if len(boxes) == 0:
        return
    caster = caster or RayCaster(buffers, frame=pose)
    kernels = getattr(caster, "kernels", None)
    passes = compiled_passes(kernels)
    objects = buffers.objects
    box_of_row = np.full(len(objects), -1, np.int64)  # each object's box: the one of its instance
    for k, instance in enumerate(boxes["instance"]):
        box_of_row[objects.instance == instance] = k
    boxed, owner = object_triangles(buffers, box_of_row)  # the objects' triangles, and their object
    centres = (boxes["centre"] - pose[:3, 3]) @ pose[:3, :3]  # bounding spheres in the sensor frame
    radii = np.linalg.norm(boxes["size"], axis=1) / 2 + 1e-3
    # the scan's answers leave some objects nothing to trace alone: their caster is built after the last chunk, for the others
    alone = AloneCaster(buffers, boxed, owner, centres, radii, pose) if direct_returns is None else None
    left = []  # with direct_returns: the (ray origin, direction, object, along) pairs still to trace alone
    visible = np.zeros(len(boxes), np.int64)
    unoccluded = np.zeros(len(boxes), np.int64)
    seen_points, seen_boxes = [], []  # where the rays passing each object are, seen from the sensor
    distance = np.linalg.norm(centres, axis=1)
    end = 0
    for chunk in [patterns] if isinstance(patterns, Pattern) else patterns:
        start, end = end, end + len(chunk)  # the chunk's rays among all the chunks'
        origins = chunk.origins  # None: every ray leaves the sensor's centre
        # a cone test from the sensor's centre first, widened by the farthest ray origin, then the
        # exact ray-sphere test on the (ray, object) pairs it lets through
        shift = 0.0 if origins is None else float(np.linalg.norm(origins, axis=1).max())
        reach = radii + shift
        cos_limit = np.where(distance > reach, np.sqrt(np.clip(1.0 - (reach / np.maximum(distance, 1e-12)) ** 2, 0.0, 1.0)), -2.0)
        ray, k = cone_pairs(chunk.directions, centres / np.maximum(distance, 1e-12)[:, None], cos_limit, kernels)
        ray, k, along = sphere_pairs(chunk.directions, origins, ray, k, centres, radii, max_range, passes)
        if len(ray) == 0:
            continue
        d = chunk.directions[ray]
        # the ray's point closest to the object's centre (+ 0.0 from the sensor's centre: a -0.0 made 0.0, as adding the origin does)
        seen_points.append(along[:, None] * d + (0.0 if origins is None else origins[ray]))
        seen_boxes.append(k)
        if direct_returns is None:  # the whole scene, each passing ray once: a ray whose first hit is object k passes k's sphere
            visible += _scene_returns(caster, buffers, chunk, np.unique(ray), boxes["instance"], box_of_row, min_range, max_range, surfaces, rng)
            # every object alone, each (ray, object) pair once
            unoccluded += alone.count(ray_origins(origins, ray), d, k, along, min_range, max_range, surfaces, rng)
        else:  # the pairs whose ray's first hit is their object count; of the others, those whose ray meets the object's
            # box are traced alone after the last chunk (a ray that misses the box misses the object)
            known = chunk_returns(direct_returns, start, len(chunk))[ray] == boxes["instance"][k]
            unoccluded += np.bincount(k[known], minlength=len(boxes))
            rest = np.flatnonzero(~known)
            o, d, k, along = ray_origins(origins, ray[rest]), d[rest], k[rest], along[rest]
            meets = meets_boxes(boxes, pose, o, d, k, passes)
            left.append((o[meets], d[meets], k[meets], along[meets]))
    if left:
        unoccluded += alone_counts(buffers, boxed, owner, centres, radii, pose, *(np.concatenate(a) for a in zip(*left)), min_range, max_range, surfaces, rng)
    boxes["visible"] = visible if direct_returns is None else counts_per_instance(boxes["instance"], direct_returns[direct_returns >= 0])
    boxes["unoccluded"] = unoccluded
    # truncation: every object's surface sampled in one call (each at its own spacing), then per object the
    # share of its area whose direction the passing rays cover, within the range limits; an object whose every
    # direction and distance is surely covered (:func:`wholly_covered`) is 0 without its samples: what they give it
    seen = np.concatenate(seen_points) if seen_points else np.zeros((0, 3))
    point_owner = np.concatenate(seen_boxes) if seen_boxes else np.zeros(0, np.int64)
    point_cells = CellGrid(cell_deg).cells(seen)  # each passing point's (row, col), once for both uses
    whole_view = wholly_covered(boxes, pose, point_cells, point_owner, min_range, max_range, cell_deg, passes)
    whole_view[whole_view] = have_area(buffers, boxed, owner, np.flatnonzero(whole_view))  # no area: 1, as sampled
    sampled = ~whole_view[owner]  # only these triangles' corners and areas are needed
    owner = owner[sampled]
    triangles = buffers.vertices[buffers.triangles[boxed[sampled]]]  # (m, 3, 3)
    tri_area = triangle_areas(triangles)
    total = np.bincount(owner, tri_area, minlength=len(boxes))  # each sampled box's sum: its triangles, in their order
    spacing = np.maximum(SAMPLE_SPACING, np.sqrt(total / MAX_SAMPLES))
    samples, area, triangle = surface_samples(triangles, spacing[owner], return_triangle=True, area_bound=True, area=tri_area)
    samples = (samples - pose[:3, 3]) @ pose[:3, :3]
    distance = row_norms(samples)
    inside = (distance >= min_range) & (distance <= max_range)
    sample_owner = owner[triangle]
    covered = np.zeros(len(samples), bool)
    if len(point_owner):  # every object's coverage at once (what :class:`Coverage` gives per object, cell for cell), for the
        # samples within the range limits of objects some ray passes (no other sample can count)
        passed = np.bincount(point_owner, minlength=len(boxes)) > 0
        partial = ~whole_view[point_owner]
        covered = covered_by_owner(seen[partial], point_owner[partial], samples, sample_owner, len(boxes), cell_deg, where=inside & passed[sample_owner],
                                   distance=distance, point_cells=(point_cells[0][partial], point_cells[1][partial]), passes=passes)  # fmt: skip
    order = np.argsort(sample_owner, kind="stable")  # the samples box by box, each box's in their order
    bounds = np.searchsorted(sample_owner[order], np.arange(len(boxes) + 1))
    area, covered = area[order], covered[order]
    truncation = np.where(whole_view, 0.0, 1.0)  # 1: no area
    for k in np.flatnonzero(~whole_view):
        mine = slice(bounds[k], bounds[k + 1])
        whole = area[mine].sum()
        if whole > 0:
            truncation[k] = 1.0 - area[mine][covered[mine]].sum() / whole
    boxes["truncation"] = truncation


def compiled_passes(kernels):
    """The compiled passes of this cast (:mod:`.visibility_kernels`) when the scan's ``kernels`` are the compiled ones
    (:func:`.raycast.choose_kernels`), else ``None`` (the numpy paths here: the same bytes)."""
    if kernels is None:
        return None
    from . import visibility_kernels

    return visibility_kernels


def sphere_pairs(directions: np.ndarray, origins: np.ndarray | None, ray: np.ndarray, box: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                 max_range: float, passes=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ray, box, along)``: the ``(p,)`` (ray, box) pairs (of :func:`cone_pairs`) whose ray passes the box's bounding sphere,
    in their order, and ``along`` (m) to each ray's point nearest the centre.

    directions, origins : the chunk's ``(n, 3)`` rays and origins (``None``: the sensor's centre); centres, radii :
    ``(k, 3)`` sensor-frame sphere centres and ``(k,)`` radii (m). A pair passes when its line comes within the radius
    of the centre, the centre is not more than a radius behind the origin and the sphere begins within ``max_range``.
    passes : :func:`compiled_passes` (one loop over the pairs) or ``None`` (numpy)."""
    if passes is not None:
        return passes.sphere_pairs(directions, np.zeros((0, 3)) if origins is None else origins, ray, box, centres, radii, float(max_range))
    d = directions[ray]
    offset = centres[box] if origins is None else centres[box] - origins[ray]
    along = dot3(offset, d)  # numpy 1.26's einsum's sums, on any numpy
    miss2 = dot3(offset, offset) - along**2
    radius = radii[box]
    passing = (miss2 <= radius**2) & (along >= -radius) & (along - radius <= max_range)
    return ray[passing], box[passing], along[passing]


def triangle_areas(triangles: np.ndarray) -> np.ndarray:
    """``(m,)`` areas (m^2) of ``(m, 3, 3)`` triangles, row by row (a triangle's area does not depend on the others)."""
    return row_norms(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])) / 2


def have_area(buffers: SceneBuffers, triangle: np.ndarray, owner: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """``(w,)`` bool: has box ``wanted[i]`` a triangle of non-zero area (:func:`triangle_areas`), i.e. a positive sum of them?

    triangle, owner : ``(t,)`` buffer triangles and each one's box (:func:`~bpy_pipeline.geometry.boxes.object_triangles`)
    Each box's first triangle answers when it has an area; only a box whose first has none is summed whole."""
    out = np.zeros(len(wanted), bool)
    if not len(wanted) or not len(owner):
        return out
    starts = np.flatnonzero(np.concatenate([[True], owner[1:] != owner[:-1]]))  # each run of one box's triangles
    first = np.full(int(max(owner.max(), wanted.max())) + 1, len(owner))
    np.minimum.at(first, owner[starts], starts)
    mine = first[wanted] < len(owner)  # the boxes with triangles
    out[mine] = triangle_areas(buffers.vertices[buffers.triangles[triangle[first[wanted[mine]]]]]) > 0
    again = mine & ~out
    if again.any():
        rows = np.isin(owner, wanted[again])
        total = np.bincount(owner[rows], triangle_areas(buffers.vertices[buffers.triangles[triangle[rows]]]), minlength=len(first))
        out[again] = total[wanted[again]] > 0
    return out


def ray_origins(origins: np.ndarray | None, ray: np.ndarray) -> np.ndarray:
    """``(p, 3)``: the origins of rays ``ray`` of a chunk whose ``origins`` are ``(n, 3)`` or ``None`` (the sensor's centre)."""
    return np.zeros((len(ray), 3)) if origins is None else origins[ray]


def chunk_returns(direct_returns: np.ndarray, first: int, count: int) -> np.ndarray:
    """``(count,)`` int64: ``direct_returns[first:first + count]`` (per ray, the instance of its return that met no
    mirror), -1 for the rays beyond its end."""
    part = direct_returns[first : first + count]
    if len(part) == count:
        return part
    out = np.full(count, -1, np.int64)
    out[: len(part)] = part
    return out


def meets_boxes(boxes: np.ndarray, pose: np.ndarray, origins: np.ndarray, directions: np.ndarray, box: np.ndarray, passes=None) -> np.ndarray:
    """``(p,)`` bool: does the line of each ray (``(p, 3)`` origins and directions, sensor frame) meet its box
    (``box`` (p,) into world-frame ``boxes``) grown by :data:`BOX_MARGIN`?

    A box holds its object's vertices (:func:`~bpy_pipeline.geometry.boxes.fit_boxes`), so a ray whose line misses it
    grown by far more than the rounding of the casts misses every triangle of the object. The slab test in each box's
    frame; a line along a face's plane (a 0/0 in it) counts as meeting it."""
    rotation = np.asarray(pose, float)[:3, :3]
    world_d = rotation @ np.ascontiguousarray(directions.T)  # (3, p): coordinate by coordinate (a product 5x faster on rows)
    turned_o = rotation @ np.ascontiguousarray(origins.T)
    shift = (pose[:3, 3] - boxes["centre"]).T  # (3, k) from each box's centre to the sensor
    half = (boxes["size"] / 2 + (BOX_MARGIN * (1.0 + np.abs(boxes["centre"]).max(axis=1) / 1e4))[:, None]).T
    if passes is not None:
        heading = boxes["heading"]
        return passes.meets_boxes(turned_o, world_d, np.ascontiguousarray(shift), np.cos(heading), np.sin(heading), np.ascontiguousarray(half),
                                  np.asarray(box, np.int64))
    world_o = turned_o + shift[:, box]  # from the box's centre
    c, s = np.cos(boxes["heading"])[box], np.sin(boxes["heading"])[box]
    half = half[:, box]
    # the box's frame: x along its heading, y across, z up
    local = ((c * world_o[0] + s * world_o[1], c * world_d[0] + s * world_d[1]), (c * world_o[1] - s * world_o[0], c * world_d[1] - s * world_d[0]),
             (world_o[2], world_d[2]))  # fmt: skip
    near, far = np.full(len(box), -np.inf), np.full(len(box), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for h, (o, d) in zip(half, local):  # a nan (0/0) makes near or far nan: the comparison below is False, the line kept
            low, high = (-h - o) / d, (h - o) / d
            near = np.maximum(near, np.minimum(low, high))
            far = np.minimum(far, np.maximum(low, high))
    return ~(near > far)


def alone_counts(buffers: SceneBuffers, triangle: np.ndarray, owner: np.ndarray, centres: np.ndarray, radii: np.ndarray, pose: np.ndarray,
                 origins: np.ndarray, directions: np.ndarray, box: np.ndarray, along: np.ndarray, min_range: float, max_range: float, surfaces,
                 rng) -> np.ndarray:  # fmt: skip
    """``(k,)`` returns per object of the ``(p,)`` pairs (:meth:`AloneCaster.count`' arguments) traced alone, in a
    caster of the objects some pair passes only (``triangle``, ``owner``, ``centres`` and ``radii``: :class:`AloneCaster`'s of all ``k`` objects)."""
    out = np.zeros(len(centres), np.int64)
    if len(box) == 0:
        return out
    traced, local = np.unique(box, return_inverse=True)
    renumber = np.full(len(centres), -1, np.int64)
    renumber[traced] = np.arange(len(traced))
    mine = renumber[owner] >= 0
    alone = AloneCaster(buffers, triangle[mine], renumber[owner[mine]], centres[traced], radii[traced], pose)
    out[traced] = alone.count(origins, directions, local, along, min_range, max_range, surfaces, rng)
    return out


def counts_per_instance(box_instance: np.ndarray, instance: np.ndarray) -> np.ndarray:
    """``(k,)`` int64: how many of the ``(d,)`` ``instance`` values are each of the ``(k,)`` distinct ``box_instance``.

    Instance ids up to :data:`COUNTED_IDS` are counted in one pass (a table of every id's count, read at the boxes'
    ids); larger ones by a search among the boxes' ids (the same counts)."""
    instance = np.asarray(instance, np.int64)
    box_instance = np.asarray(box_instance, np.int64)
    if not len(instance) or (instance.min() >= 0 and instance.max() < COUNTED_IDS):
        table = np.bincount(instance, minlength=1) if len(instance) else np.zeros(1, np.int64)
        inside = (box_instance >= 0) & (box_instance < len(table))
        return np.where(inside, table[np.where(inside, box_instance, 0)], 0).astype(np.int64)
    order = np.argsort(box_instance)
    known = np.asarray(box_instance, np.int64)[order]
    at = np.searchsorted(known, instance)
    mine = at < len(known)
    mine[mine] = known[at[mine]] == instance[mine]
    out = np.zeros(len(known), np.int64)
    out[order] = np.bincount(at[mine], minlength=len(known))
    return out


ANGLE_MARGIN = 1e-6  # degrees added to the directions a box spans: far beyond the rounding of a sample's cell (about 1e-12 degrees)
BOX_MARGIN = 0.01  # m (and as much again per 10 km of coordinates): a box grown by it holds every surface sample of its object
CORNER_PAIRS = np.array([(i, j) for i in range(8) for j in range(i + 1, 8)])  # (28, 2): every two corners, the footprint's edges among them


def wholly_covered(boxes: np.ndarray, pose: np.ndarray, point_cells: tuple[np.ndarray, np.ndarray], point_owner: np.ndarray, min_range: float, max_range: float,
                   cell_deg: float, passes=None) -> np.ndarray:
    """``(k,)`` bool: is every surface sample of box k's object surely within the range limits and covered (truncation 0)?

    boxes : (k,) world-frame BOX_DTYPE, each the tightest box around its object's vertices (so around every surface
        sample, up to rounding: grown by :data:`BOX_MARGIN`); point_cells, point_owner : the ``(p,)`` row and column
        (:class:`CellGrid`'s cells of ``cell_deg``) of the sensor-frame points where rays pass the objects, and their ``(p,)`` box
    A sample counts when its distance is within ``[min_range, max_range]`` and its direction's cell (:class:`CellGrid`'s
    cells) is within one cell of a passing point's. True only when the box's bounding box in the sensor frame is within
    the limits, and every cell of the directions the box spans (its elevations from its heights and its footprint's
    nearest and farthest horizontal distances, its azimuths from its footprint's corners, widened by :data:`ANGLE_MARGIN`)
    is so marked: then every sample counts, and the sampled share of covered area would be ``x / x``, 0 exactly. Boxes
    around the sensor's vertical axis, and those beyond these bounds, are left to the samples (False). All boxes at once,
    but for each one's few cells.
    """
    out = np.zeros(len(boxes), bool)
    if len(point_owner) == 0 or len(boxes) == 0:
        return out
    grid = CellGrid(cell_deg)
    margin = BOX_MARGIN * (1.0 + np.abs(boxes["centre"]).max(axis=1) / 1e4)
    corners = (box_corners(boxes, margin) - pose[:3, 3]) @ pose[:3, :3]  # (k, 8, 3) sensor frame
    low, high = corners.min(axis=1), corners.max(axis=1)
    near = np.maximum(np.maximum(low, -high), 0.0)  # per axis, the nearest the bounding box comes to the sensor
    far = np.maximum(np.abs(low), np.abs(high))
    xy = corners[..., :2]
    a, b = xy[:, CORNER_PAIRS[:, 0]], xy[:, CORNER_PAIRS[:, 1]]  # (k, 28, 2)
    ab = b - a
    length2 = (ab * ab).sum(axis=2)
    t = np.clip(-(a * ab).sum(axis=2) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    closest = a + t[..., None] * ab
    rho_near = np.sqrt((closest * closest).sum(axis=2).min(axis=1))  # the footprint's nearest horizontal distance
    rho_far = np.sqrt((xy * xy).sum(axis=2).max(axis=1))
    top = np.degrees(np.arctan2(high[:, 2], np.where(high[:, 2] >= 0, rho_near, rho_far)))
    bottom = np.degrees(np.arctan2(low[:, 2], np.where(low[:, 2] >= 0, rho_far, rho_near)))
    row0 = np.maximum(np.floor((bottom - ANGLE_MARGIN + 90.0) / grid.cell).astype(np.int64), 0)
    row1 = np.minimum(np.floor((top + ANGLE_MARGIN + 90.0) / grid.cell).astype(np.int64), grid.rows - 1)
    # the footprint's azimuths, from its centre's (less than half a turn either way: the sensor is outside it)
    mid = (low + high) / 2
    centre_azimuth = np.degrees(np.arctan2(mid[:, 1], mid[:, 0]))
    turn = (np.degrees(np.arctan2(xy[..., 1], xy[..., 0])) - centre_azimuth[:, None] + 180.0) % 360.0 - 180.0
    col0 = np.floor((centre_azimuth + turn.min(axis=1) - ANGLE_MARGIN + 180.0) / grid.cell).astype(np.int64)
    col1 = np.floor((centre_azimuth + turn.max(axis=1) + ANGLE_MARGIN + 180.0) / grid.cell).astype(np.int64)
    # each box's marks in a window of its cells and one more on every side (no column twice: narrower than a turn)
    height, width = row1 - row0 + 3, col1 - col0 + 3
    passed = np.bincount(point_owner, minlength=len(boxes))[: len(boxes)] > 0
    candidate = (passed & (np.sqrt((near * near).sum(axis=1)) >= min_range) & (np.sqrt((far * far).sum(axis=1)) <= max_range)
                 & (np.hypot(near[:, 0], near[:, 1]) > 0.0) & (width <= grid.columns))
    if not candidate.any():
        return out
    return (windows_covered if passes is None else passes.windows_covered)(point_owner, point_cells[0], point_cells[1], candidate, row0, col0, height, width,
                                                                           grid.columns)


def windows_covered(owner: np.ndarray, row: np.ndarray, col: np.ndarray, candidate: np.ndarray, row0: np.ndarray, col0: np.ndarray, height: np.ndarray,
                    width: np.ndarray, columns: int) -> np.ndarray:
    """``(k,)`` bool: is every cell of each candidate box's window within one cell of a point's? (:func:`wholly_covered`'s windows)

    owner, row, col : ``(p,)`` int64 each point's box and cell; candidate : ``(k,)`` bool the boxes to answer (others False);
    row0, col0 : ``(k,)`` the first row and column of each box's directions; height, width : ``(k,)`` its window, with one
    more cell on every side; columns : the cells in a turn (a window's columns wrap)."""
    out = np.zeros(len(candidate), bool)
    size = np.where(candidate, height * width, 0)
    offset = np.cumsum(size) - size
    mask = np.zeros(int(size.sum()), bool)
    mine = candidate[owner]
    owner, row, col = owner[mine], row[mine], col[mine]
    r, q = row - (row0[owner] - 1), (col - (col0[owner] - 1)) % columns
    inside = (r >= 0) & (r < height[owner]) & (q < width[owner])
    mask[(offset[owner] + r * width[owner] + q)[inside]] = True
    for k in np.flatnonzero(candidate):  # a cell is covered when it or one of its eight neighbours is marked
        marks = mask[offset[k] : offset[k] + size[k]].reshape(height[k], width[k])
        covered = np.zeros((height[k] - 2, width[k] - 2), bool)
        for dr in range(3):
            for dc in range(3):
                covered |= marks[dr : dr + height[k] - 2, dc : dc + width[k] - 2]
        out[k] = covered.all()
    return out


def cone_pairs(directions: np.ndarray, axes: np.ndarray, cos_limit: np.ndarray, kernels=None) -> tuple[np.ndarray, np.ndarray]:
    """``(ray, box)`` int64 pairs, ray-major: the rays of ``directions`` (n, 3) within box k's cone (unit ``axes``
    (k, 3), ``cos_limit`` (k,) the cosine of its half-angle), widened by :data:`CONE_MARGIN` so that the exact
    test after it alone decides. Compiled (``kernels.cone_pairs``, :mod:`.numba_kernels`) or numpy in blocks of
    :data:`CONE_BLOCK` rays; their dot products may round apart, never by the margin, so both give every pair
    the exact test keeps."""
    limit = np.asarray(cos_limit, np.float64) - CONE_MARGIN
    directions, axes = np.ascontiguousarray(directions, np.float64), np.ascontiguousarray(axes, np.float64)
    if kernels is not None:
        return kernels.cone_pairs(directions, axes, limit)
    rays, boxes = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for start in range(0, len(directions), CONE_BLOCK):
        ray, box = np.nonzero(directions[start : start + CONE_BLOCK] @ axes.T >= limit[None])
        rays.append(ray + start)
        boxes.append(box)
    return np.concatenate(rays).astype(np.int64), np.concatenate(boxes).astype(np.int64)


def covered_by_owner(points: np.ndarray, point_owner: np.ndarray, samples: np.ndarray, sample_owner: np.ndarray, count: int, cell_deg: float,
                     where: np.ndarray | None = None, distance: np.ndarray | None = None,
                     point_cells: tuple[np.ndarray, np.ndarray] | None = None, passes=None) -> np.ndarray:  # fmt: skip
    """``(s,)`` bool: is each sample's direction covered by the passing points of its own object?

    points, point_owner : ``(p, 3)`` sensor-frame points where rays pass the objects and ``(p,)`` their object (0..count-1)
    samples, sample_owner : ``(s, 3)`` sensor-frame surface samples and ``(s,)`` their object
    The same answer as ``Coverage(points of k, cell_deg).covers(samples of k)`` per object k (the same cells, the
    same one-cell growth: rows clamped at the poles, columns wrapping), with each direction's cell computed once.
    Each object gets a window of cells: the rows and columns its points and samples fall in, and one more on every
    side (every column, wrapping, when that would wrap), all windows in one mask. Each point marks its cell and the
    eight around it, and a sample is covered when its cell is marked. No sort: an object's window is the few cells
    its directions span (a whole row band only for an object around the sensor).
    where : ``(s,)`` bool, the samples to look at (the others come back False), or ``None`` for all
    distance : the ``(s,)`` samples' lengths (m, :func:`~.raycast.row_norms`) if the caller has it
    point_cells : the ``(p,)`` rows and columns of ``points`` (:meth:`CellGrid.cells`) if the caller has them
    passes : :func:`compiled_passes` (the windows, marks and look-ups in one compiled pass) or ``None`` (numpy)
    """
    if where is not None and where.all():  # every sample counts: no copies by a mask of all True (a quarter of a garage frame's call)
        where = None
    covered = np.zeros(len(samples), bool)
    if where is not None:  # only these samples can count: the others' cells are never looked up
        samples, sample_owner = samples[where], sample_owner[where]
        distance = None if distance is None else distance[where]
    grid = CellGrid(cell_deg)
    columns = grid.columns
    owned = (point_owner >= 0) & (point_owner < count)
    point_owner = point_owner[owned].astype(np.int64)
    found = np.zeros(len(samples), bool)
    if len(point_owner):
        point_row, point_col = grid.cells(points[owned]) if point_cells is None else (point_cells[0][owned], point_cells[1][owned])
        sample_owner = sample_owner.astype(np.int64)
        row, col = grid.cells(samples, distance)
        found = (owner_covered if passes is None else passes.owner_covered)(point_owner, point_row, point_col, sample_owner, row, col, count, grid.rows,
                                                                             columns)
    if where is None:
        return found
    covered[where] = found
    return covered


def owner_covered(point_owner: np.ndarray, point_row: np.ndarray, point_col: np.ndarray, sample_owner: np.ndarray, row: np.ndarray, col: np.ndarray,
                  count: int, rows: int, columns: int) -> np.ndarray:
    """``(s,)`` bool: is each sample's cell within one cell of a point of its own box? (:func:`covered_by_owner`'s windows)

    point_owner, point_row, point_col : ``(p,)`` int64 each point's box (0..count-1) and cell; sample_owner, row, col :
    ``(s,)`` the samples'; rows, columns : the grid's (:class:`CellGrid`)."""
    low_row, high_row = np.full(count, rows), np.zeros(count, np.int64)
    low_col, high_col = np.full(count, columns), np.zeros(count, np.int64)
    for owner, r, c in ((point_owner, point_row, point_col), (sample_owner, row, col)):
        np.minimum.at(low_row, owner, r)
        np.maximum.at(high_row, owner, r)
        np.minimum.at(low_col, owner, c)
        np.maximum.at(high_col, owner, c)
    low_row, low_col = np.minimum(low_row, high_row), np.minimum(low_col, high_col)  # an object with no cell: a window of one
    # a margin row or column is never a sample's, so a point's mark there (row -1 for row 0's neighbour) is
    # what clamping at a pole gives; a window that would wrap is every column, and its marks wrap
    whole = high_col - low_col + 3 > columns
    width = np.where(whole, columns, high_col - low_col + 3)
    size = (high_row - low_row + 3) * width
    offset = np.cumsum(size) - size - (low_row - 1) * width - np.where(whole, 0, low_col - 1)  # cell (k, r, c): offset[k] + r width[k] + c
    mask = np.zeros(int(size.sum()), bool)
    step, wraps = width[point_owner], whole[point_owner]
    base = offset[point_owner] + point_row * step
    for dc in (-1, 0, 1):
        c = point_col + dc
        if wraps.any():
            c = np.where(wraps, c % columns, c)
        mask[base + c - step] = True
        mask[base + c] = True
        mask[base + c + step] = True
    return mask[offset[sample_owner] + row * width[sample_owner] + col]


IDENTITY4 = np.eye(4)


def _scene_returns(caster, buffers: SceneBuffers, chunk: Pattern, traced: np.ndarray, box_instance: np.ndarray, box_of_row: np.ndarray, min_range: float,
                   max_range: float, surfaces, rng) -> np.ndarray:
    """``(k,)`` rays ``traced`` (indices into ``chunk``) whose return through the whole scene is from box k's objects
    (``box_instance`` (k,), ``box_of_row`` (objects,) each object's box, -1 for none), no mirror met."""
    if chunk.origins is None and getattr(caster, "kernels", None) is not None:
        # the compiled scan of those rays (Embree and the records in one pass; the same hits and draws as
        # trace_beams: tests/test_scan_kernel.py): with no mirror bounces a record's instance is that of its beam's last object
        points, _, _ = scan_chunk(caster, buffers, Pattern(chunk.directions[traced], chunk.ring[traced], chunk.time[traced]), IDENTITY4, min_range, max_range,
                                  max_bounces=0, surfaces=surfaces, rng=rng)
        return counts_per_instance(box_instance, points["instance"][points["bounces"] == 0].astype(np.int64))
    o = chunk.origins[traced] if chunk.origins is not None else np.zeros(3)
    beams = trace_beams(caster, buffers, o, chunk.directions[traced], min_range, max_range, max_bounces=0, surfaces=surfaces, rng=rng)
    hit = box_of_row[buffers.triangle_object[beams.triangle]]
    direct = (hit >= 0) & (beams.bounces == 0)
    return np.bincount(hit[direct], minlength=len(box_instance))


def _used_vertices(triangles: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(triangles, return_inverse=True)`` for ``triangles`` indexing ``count`` vertices, without the sort:
    the ``(u,)`` vertices used, increasing, and ``triangles`` renumbered into them (``(3 m,)``, flattened)."""
    flat = np.asarray(triangles).ravel()
    if not len(flat):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    low = int(flat.min())  # a table of the vertex rows from the lowest used to the highest
    mark = np.zeros(int(flat.max()) - low + 1, bool)
    mark[flat - low] = True
    renumber = np.cumsum(mark) - 1
    return np.flatnonzero(mark) + low, renumber[flat - low]


class AloneCaster:
    """Every box's object alone, in one caster: object k moved to cell k of a grid.

    Cells are ``4 r_max + 1`` m apart (r_max the largest bounding-sphere radius), so a ray started
    inside object k's sphere and traced ``2 r_max`` metres meets object k and nothing else: one
    cast answers "what would this ray hit if object k were alone?" for all pairs at once.
    """

    def __init__(self, buffers: SceneBuffers, triangle: np.ndarray, owner: np.ndarray, centres: np.ndarray, radii: np.ndarray, pose: np.ndarray):
        """triangle : ``(t,)`` increasing buffer triangles of the ``k`` objects; owner : ``(t,)`` the object (0..k-1) of each
        centres, radii : ``(k, 3)`` sensor-frame centres and ``(k,)`` radii (m) of their bounding spheres; pose : (4, 4) the sensor's"""
        self.radii = np.asarray(radii, float)
        self.reach = 2.0 * float(radii.max()) + 1e-3
        spacing = 4.0 * float(radii.max()) + 1.0
        side = int(np.ceil(len(centres) ** (1 / 3)))
        cells = np.stack(np.unravel_index(np.arange(len(centres)), (side, side, side)), axis=1) * spacing
        self.move = cells - centres  # (k, 3) sensor frame: object k's translation
        corners = buffers.triangles[triangle]
        used, triangles = _used_vertices(corners, len(buffers.vertices))
        vertex_owner = np.empty(len(used), np.int64)  # the object of each used vertex (one object's vertices are its own)
        vertex_owner[triangles] = np.repeat(owner, 3)
        vertices = buffers.vertices[used] + self.move[vertex_owner] @ np.asarray(pose, float)[:3, :3].T
        self.buffers = SceneBuffers(vertices, triangles.reshape(-1, 3).astype(np.int32), buffers.triangle_object[triangle], buffers.objects)
        self.caster = RayCaster(self.buffers, frame=pose, build="low")  # built every frame, traced by the few pairs left: Embree's fast build

    def count(self, origins, directions, box, along, min_range, max_range, surfaces, rng) -> np.ndarray:
        """``(k,)`` returns per box of the pairs (ray origin ``(p, 3)``, direction ``(p, 3)``, box ``(p,)``,
        ``along`` ``(p,)`` m to the point nearest the box's centre), each ray on its box alone,
        within ``[min_range, max_range]`` of its origin."""
        start = np.maximum(along - self.radii[box], min_range)  # where the pair's ray enters the sphere (not before min_range)
        shifted = origins + start[:, None] * directions + self.move[box]
        beams = trace_beams(self.caster, self.buffers, shifted, directions, 0.0, self.reach, max_bounces=0, surfaces=surfaces, rng=rng)
        within = start[beams.ray] + beams.path <= max_range
        return np.bincount(box[beams.ray[within]], minlength=len(self.move))


def surface_samples(triangles: np.ndarray, spacing, return_triangle: bool = False, area_bound: bool = False, area: np.ndarray | None = None):
    """Points spread over ``(m, 3, 3)`` triangles and the area each stands for: ``(p, 3)``, ``(p,)``.

    A triangle wider than ``spacing`` (metres; one value or ``(m,)``, one per triangle) is cut into
    n^2 equal triangles (n up to 24) and sampled at their centroids, so the areas add up exactly
    and large faces are not one point. ``return_triangle``: also the ``(p,)`` triangle of each sample.
    ``area_bound``: n is also at most ``ceil(sqrt(2 area) / spacing)`` (a right triangle's leg,
    so half a square is cut as before), which stops a long thin triangle (a car body's sliver)
    from being n^2 points along a line: about ``2 area / spacing^2`` samples in all.
    ``area``: the ``(m,)`` triangles' areas (m^2) if the caller has them already (the formula here, same values).
    """
    first = triangles[:, 0]
    edge1 = triangles[:, 1] - first
    edge2 = triangles[:, 2] - first
    edge = np.maximum(row_norms(edge1), row_norms(edge2))
    if area is None:
        area = row_norms(np.cross(edge1, edge2)) / 2
    if area_bound:
        edge = np.minimum(edge, np.sqrt(2.0 * area))
    level = np.clip(np.ceil(edge / spacing), 1, 24).astype(np.uint8)
    count = np.bincount(level, minlength=25)
    order = np.argsort(level, kind="stable")  # the triangles of each level, in increasing order (a radix sort)
    total = int((count * np.arange(25) ** 2).sum())
    points, weights, owners = np.empty((total, 3)), np.empty(total), np.empty(total, np.int64)
    start = at = 0
    for n in np.flatnonzero(count):  # each level's n^2 centroids of every triangle, written in place
        rows = order[start : start + count[n]]
        start += count[n]
        u, v = _centroids(int(n))
        size = len(rows) * len(u)
        # first + u edge1 + v edge2, added in that order
        block = points[at : at + size].reshape(len(rows), len(u), 3)
        np.multiply(u[None, :, None], edge1[rows][:, None], out=block)
        block += first[rows][:, None]
        block += np.multiply(v[None, :, None], edge2[rows][:, None])
        weights[at : at + size] = np.repeat(area[rows] / n**2, len(u))
        owners[at : at + size] = np.repeat(rows, len(u))
        at += size
    if return_triangle:
        return points, weights, owners
    return points, weights


_CENTROIDS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _centroids(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``(n^2,)`` barycentric ``u``, ``v`` of the centroids of a triangle cut into n^2 equal ones (kept per n)."""
    if n not in _CENTROIDS:
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        up = i + j <= n - 1
        down = i + j <= n - 2
        u = np.concatenate([(i[up] + 1 / 3) / n, (i[down] + 2 / 3) / n])
        v = np.concatenate([(j[up] + 1 / 3) / n, (j[down] + 2 / 3) / n])
        u.flags.writeable = v.flags.writeable = False
        _CENTROIDS[n] = (u, v)
    return _CENTROIDS[n]


def occlusion_levels(visible: np.ndarray, unoccluded: np.ndarray, levels=(0.8, 0.4, 0.1)) -> np.ndarray:
    """``(n,)`` uint8 occlusion level 0..3 from visible and unoccluded counts (an object no ray reaches is 3)."""
    visible = np.asarray(visible, float)
    unoccluded = np.asarray(unoccluded, float)
    fraction = np.where(unoccluded > 0, visible / np.maximum(unoccluded, 1), 0.0)
    t0, t1, t2 = levels
    return np.select([fraction >= t0, fraction >= t1, fraction >= t2], [0, 1, 2], 3).astype(np.uint8)
