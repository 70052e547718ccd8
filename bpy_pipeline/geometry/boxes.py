"""3D bounding boxes of labelled objects (cars, people, robot arms): fitting them to an instance's
triangles, moving them between frames, counting and keeping them. Pure numpy.

A box is fitted to the exported triangles of one instance (so it holds every point the scan puts
on that instance) around a heading the scene builder knows (a car's body, a person's facing, the
arm's vertical plane), or, without one, the heading of the smallest rectangle around its footprint.
What the sensor sees of each box (truncation, visible and unoccluded rays) is
:mod:`bpy_pipeline.lidar.cast.visibility`; the label files are written by the box writers of :mod:`bpy_pipeline.io`.
"""

from __future__ import annotations

import numpy as np

from ..buffers import SceneBuffers
from ..errors import InputError

BOX_DTYPE = np.dtype(
    [
        ("class_name", "U32"),  # class from assets_manifest/labels.yaml
        ("instance", "<u4"),
        ("centre", "<f8", (3,)),  # metres, the frame of the points
        ("size", "<f8", (3,)),  # length (along the heading), width, height, metres
        ("heading", "<f8"),  # radians about z, from the frame's x axis
        ("truncation", "<f4"),  # 0..1
        ("occlusion", "u1"),  # 0..3
        ("visible", "<u4"),  # rays whose first hit is this object
        ("unoccluded", "<u4"),  # rays that hit this object when it is alone
        ("points", "<u4"),  # labeled points of the instance in the final cloud
    ]
)


def wrap_angle(angle):
    """Angle(s) in radians wrapped to [-pi, pi)."""
    return (np.asarray(angle, float) + np.pi) % (2 * np.pi) - np.pi


def footprint_heading(xy: np.ndarray) -> float:
    """Yaw (radians) of the smallest-area rectangle around ``(n, 2)`` points (rotating calipers on the hull)."""
    points = np.unique(np.round(np.asarray(xy, float), 9), axis=0)
    if len(points) < 3:
        if len(points) == 2:
            d = points[1] - points[0]
            return float(np.arctan2(d[1], d[0]))
        return 0.0
    hull = _convex_hull(points)
    edges = np.diff(np.vstack([hull, hull[:1]]), axis=0)
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    best, best_area = 0.0, np.inf
    for angle in angles:
        c, s = np.cos(angle), np.sin(angle)
        local = hull @ np.array([[c, -s], [s, c]])
        area = np.prod(local.max(axis=0) - local.min(axis=0))
        if area < best_area - 1e-12:
            best, best_area = float(angle), area
    return float(wrap_angle(best))


def _cross2(u, v) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def _convex_hull(points: np.ndarray) -> np.ndarray:
    """Andrew's monotone chain; ``points`` unique, sorted by x then y."""
    order = np.lexsort((points[:, 1], points[:, 0]))
    pts = points[order]

    def half(seq):
        out = []
        for p in seq:
            while len(out) >= 2 and _cross2(out[-1] - out[-2], p - out[-2]) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def instance_triangles(buffers: SceneBuffers) -> np.ndarray:
    """``(m,)`` instance id of every triangle."""
    return buffers.objects.instance[buffers.triangle_object]


RIDER_CLASSES = ("rider", "motorcyclist")  # a two-wheeler's box takes its rider's class: KITTI's Cyclist is rider and bicycle in one box


def fit_boxes(buffers: SceneBuffers, classes, headings: dict | None = None) -> np.ndarray:
    """World-frame boxes (:data:`BOX_DTYPE`) of every instance whose class is in ``classes``, in increasing instance order.

    A box's class is its instance's rider class (:data:`RIDER_CLASSES`) when one of its objects has one, else
    its first object's.

    headings : ``{instance: yaw radians}`` from the scene builder; instances without one get the
        heading of their footprint's smallest rectangle
    The box is the tightest upright box around the instance's vertices in its heading's frame;
    it contains every triangle of the instance, hence every point a scan puts on it. All boxes at once
    (:func:`instance_vertices`), but for each one's rotation of its vertices and the footprints without a heading.
    """
    headings = headings or {}
    objects = buffers.objects
    names = np.asarray(objects.class_names, dtype=object)
    wanted = np.isin(names, [str(c) for c in classes]) if len(names) else np.zeros(0, bool)
    instances = np.unique(objects.instance[wanted])
    out = np.zeros(len(instances), BOX_DTYPE)
    if not len(instances):
        return out
    box_of_row = np.where(wanted, np.searchsorted(instances, objects.instance), -1)
    vertex_rows, bounds = instance_vertices(buffers, box_of_row, len(instances))
    if np.any(bounds[1:] == bounds[:-1]):
        raise ValueError("fit_boxes: an instance of a box class has no triangles")
    vertices = buffers.vertices[vertex_rows]
    yaw = np.array([headings.get(int(i), np.nan) for i in instances], float)
    for k in np.flatnonzero(np.isnan(yaw)):
        yaw[k] = footprint_heading(vertices[bounds[k] : bounds[k + 1], :2])
    c, s = np.cos(yaw), np.sin(yaw)
    rotation = np.zeros((len(instances), 3, 3))
    rotation[:, 0, 0], rotation[:, 0, 1], rotation[:, 1, 0], rotation[:, 1, 1], rotation[:, 2, 2] = c, -s, s, c, 1.0
    local = np.empty_like(vertices)
    for k in range(len(instances)):  # the matrix product box by box, as one box's vertices alone give it
        local[bounds[k] : bounds[k + 1]] = vertices[bounds[k] : bounds[k + 1]] @ rotation[k]
    low, high = np.minimum.reduceat(local, bounds[:-1], axis=0), np.maximum.reduceat(local, bounds[:-1], axis=0)
    rows = np.flatnonzero(wanted)
    first = np.full(len(instances), len(objects))
    np.minimum.at(first, box_of_row[rows], rows)  # each box's first object, and its first rider
    rider = rows[np.isin(names[rows], RIDER_CLASSES)]
    first_rider = np.full(len(instances), len(objects))
    np.minimum.at(first_rider, box_of_row[rider], rider)
    out["class_name"] = names[np.where(first_rider < len(objects), first_rider, first)].astype(str)
    out["instance"] = instances
    out["centre"] = np.matmul(rotation, ((low + high) / 2)[:, :, None])[:, :, 0]
    out["size"] = high - low
    out["heading"] = wrap_angle(yaw)
    return out


def object_triangles(buffers: SceneBuffers, box_of_row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(triangle, box)``: the ``(t,)`` increasing triangles of the objects that have a box and each one's box.

    box_of_row : ``(objects,)`` each object's box, -1 for none
    Exported buffers list each object's triangles together, objects in order (``triangle_object`` never decreases):
    each object's triangles are then a range found by a search, and the scene's other triangles are not gathered;
    other buffers take one pass over every triangle (the same answer)."""
    box_of_row = np.asarray(box_of_row, np.int64)
    owner = buffers.triangle_object
    if len(owner) > 1 and not (owner[1:] >= owner[:-1]).all():
        triangle = np.flatnonzero((box_of_row >= 0)[owner])
        return triangle, box_of_row[owner[triangle]]
    rows = np.flatnonzero(box_of_row >= 0)
    key = rows.astype(owner.dtype)  # the table's own type: no copy of it for the search
    start, end = np.searchsorted(owner, key, "left"), np.searchsorted(owner, key, "right")
    count = end - start
    triangle = np.arange(int(count.sum()), dtype=np.int64) + np.repeat(start - (np.cumsum(count) - count), count)
    return triangle, np.repeat(box_of_row[rows], count)


def instance_vertices(buffers: SceneBuffers, box_of_row: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, bounds)``: the vertex rows the triangles of each of ``count`` boxes use, box by box, increasing
    within each (``(v,)``), and the ``(count + 1,)`` bounds of each box's part: box k's are
    ``vertices[bounds[k]:bounds[k + 1]]``. ``box_of_row`` : ``(objects,)`` each object's box, -1 for none.

    A vertex used by one box (a box's objects have vertices of their own) is marked with its box once, in a table of
    the vertex rows from the lowest used to the highest; a vertex that two boxes share is found in both (a sort of the
    (box, vertex) pairs)."""
    triangle, box = object_triangles(buffers, box_of_row)
    corners = buffers.triangles[triangle].ravel()
    if not len(corners):
        return np.zeros(0, np.int64), np.zeros(count + 1, np.int64)
    owner = np.repeat(box, 3)
    low = int(corners.min())
    vertex_box = np.full(int(corners.max()) - low + 1, -1, np.int32)
    vertex_box[corners - low] = owner
    if np.array_equal(vertex_box[corners - low], owner):
        used = np.flatnonzero(vertex_box >= 0)
        box = vertex_box[used]
        order = np.argsort(box, kind="stable")
        vertices, box = used[order] + low, box[order]
    else:
        pairs = np.unique(owner * len(buffers.vertices) + corners)
        vertices, box = pairs % len(buffers.vertices), pairs // len(buffers.vertices)
    return vertices, np.searchsorted(box, np.arange(count + 1))


def box_corners(boxes: np.ndarray, grow=0.0) -> np.ndarray:
    """``(k, 8, 3)`` corners of ``(k,)`` BOX_DTYPE boxes, in their frame: bottom face 0-3, top face 4-7.

    grow : metres added to every half-size (one value or ``(k,)``): the corners of a box that far larger on every side
    """
    grow = np.broadcast_to(np.asarray(grow, float), (len(boxes),))
    signs = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], float)
    c, s = np.cos(boxes["heading"]), np.sin(boxes["heading"])
    turn = np.stack([np.stack([c, s], axis=-1), np.stack([-s, c], axis=-1)], axis=1)  # (k, 2, 2): box k's [[c, s], [-s, c]]
    local = signs * (np.asarray(boxes["size"][:, :2]) / 2 + grow[:, None])[:, None]  # (k, 4, 2)
    xy = np.matmul(local, turn) + np.asarray(boxes["centre"][:, :2])[:, None]  # box by box, as one box's product gives it
    out = np.zeros((len(boxes), 8, 3))
    out[:, :4, :2] = out[:, 4:, :2] = xy
    out[:, :4, 2] = (boxes["centre"][:, 2] - (boxes["size"][:, 2] / 2 + grow))[:, None]
    out[:, 4:, 2] = (boxes["centre"][:, 2] + (boxes["size"][:, 2] / 2 + grow))[:, None]
    return out


def boxes_in_frame(boxes: np.ndarray, frame: np.ndarray, where: str = "output.frame") -> np.ndarray:
    """Boxes moved from the world into the frame whose ``(4, 4)`` frame-to-world transform is ``frame``.

    Upright boxes stay upright only in a level frame: ``InputError`` (naming ``where``) when the
    frame's z axis is more than 0.5 degrees from vertical.
    """
    frame = np.asarray(frame, float)
    if frame[2, 2] < np.cos(np.radians(0.5)):
        tilt = np.degrees(np.arccos(np.clip(frame[2, 2], -1, 1)))
        raise InputError(
            f"{where}: 3D box labels need a level point frame, but the sensor is tilted {tilt:.1f} deg from vertical; write the points in a level frame "
            "(output.frame: world or kitti)"
        )
    out = boxes.copy()
    out["centre"] = (boxes["centre"] - frame[:3, 3]) @ frame[:3, :3]
    yaw = np.arctan2(frame[1, 0], frame[0, 0])
    out["heading"] = wrap_angle(boxes["heading"] - yaw)
    return out


def points_in_box(xyz: np.ndarray, box, margin: float = 0.0) -> np.ndarray:
    """``(n,)`` bool: which ``(n, 3)`` points lie inside ``box`` (one :data:`BOX_DTYPE` record) grown by ``margin``."""
    c, s = np.cos(box["heading"]), np.sin(box["heading"])
    local = np.asarray(xyz, float) - box["centre"]
    x = c * local[:, 0] + s * local[:, 1]
    y = -s * local[:, 0] + c * local[:, 1]
    half = np.asarray(box["size"]) / 2 + margin
    return (np.abs(x) <= half[0]) & (np.abs(y) <= half[1]) & (np.abs(local[:, 2]) <= half[2])


def count_points(boxes: np.ndarray, points: np.ndarray) -> None:
    """Fill ``points`` of ``boxes`` in place: how many records of ``points`` carry each box's instance."""
    counts = np.bincount(points["instance"].astype(np.int64), minlength=int(boxes["instance"].max(initial=0)) + 1)
    boxes["points"] = counts[boxes["instance"].astype(np.int64)]


def keep_boxes(boxes: np.ndarray, min_points: dict | None = None, default: int = 6) -> np.ndarray:
    """The boxes with at least their class's minimum number of points (``min_points[class]``, else ``default``)."""
    min_points = min_points or {}
    need = np.array([min_points.get(str(c), default) for c in boxes["class_name"]], np.int64)
    return boxes[boxes["points"].astype(np.int64) >= need]
