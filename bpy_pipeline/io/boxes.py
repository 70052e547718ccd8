"""3D bounding boxes of objects (cars, people, robot arms): fitting, truncation, occlusion, and the KITTI
and OpenPCDet label files. Pure numpy and embreex; never imports bpy.

A box is fitted to the exported triangles of one instance (so it holds every point the scan puts
on that instance) around a heading the scene builder knows (a car's body, a person's facing, the
arm's vertical plane), or, without one, the heading of the smallest rectangle around its footprint.

Per box and frame:

- ``truncation`` (0..1): the share of the object's surface area outside the sensor's field of
  view (directions no ray of the pattern comes near, or beyond its range limits), the LiDAR
  analogue of KITTI's "leaving image boundaries".
- ``visible`` and ``unoccluded`` point counts: the rays of the pattern that can reach the object
  are traced twice, through the whole scene (the object is the first thing hit) and against the
  object alone; ``occlusion`` is a level 0..3 from ``visible / unoccluded`` and the thresholds
  ``levels = (t0, t1, t2)``: 0 (fully visible) from t0 up, 1 (partly occluded) from t1, 2 (largely
  occluded) from t2, 3 (mostly hidden) below.
- ``points``: the labeled points of the instance in the final cloud (after effects); boxes with
  fewer than their class's minimum are dropped (the sparse-camera thesis kept 12 for cars, 6 for
  other classes).

Files (frame ``NNNNNN``):

- KITTI object layout: ``kitti/label_2/NNNNNN.txt`` (``type truncated occluded alpha bbox(4)
  h w l x y z rotation_y``, camera coordinates), ``kitti/calib/NNNNNN.txt`` (``Tr_velo_to_cam``
  is KITTI's axis change x_cam = -y, y_cam = -z, z_cam = x; no image is rendered, so P0-P3 are a
  nominal 1242 x 375 pinhole and every 2D bbox is 0) and ``kitti/velodyne/NNNNNN.bin``.
- OpenPCDet custom layout: ``openpcdet/labels/NNNNNN.txt`` (``x y z dx dy dz heading_angle
  category_name``, the box centre, its length, width, height and yaw in the point frame),
  ``openpcdet/points/NNNNNN.npy`` ((n, 4) float32 x y z intensity) and ``openpcdet/ImageSets/train.txt``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..buffers import SceneBuffers
from ..errors import InputError
from ..lidar.raycast import RayCaster
from ..lidar.scanner import trace_beams
from ..lidar.sensors import Pattern
from .atomic import atomic_write

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
SAMPLE_SPACING = 0.1  # m between surface samples for truncation (wider on objects that would need more than:)
MAX_SAMPLES = 4000
KITTI_AXES = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # velodyne -> camera rotation


def label_name(class_name: str, names: dict | None = None) -> str:
    """The label-file type of a class: ``names[class]`` if given, else its words capitalised and joined (``robot arm`` -> ``RobotArm``)."""
    if names and class_name in names:
        return str(names[class_name])
    return "".join(word.capitalize() for word in class_name.replace("_", " ").split())


def wrap_angle(angle):
    """Angle(s) in radians wrapped to [-pi, pi)."""
    return (np.asarray(angle, float) + np.pi) % (2 * np.pi) - np.pi


# ----------------------------------------------------------------------------- fitting
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


def fit_boxes(buffers: SceneBuffers, classes, headings: dict | None = None) -> np.ndarray:
    """World-frame boxes (:data:`BOX_DTYPE`) of every instance whose class is in ``classes``.

    headings : ``{instance: yaw radians}`` from the scene builder; instances without one get the
        heading of their footprint's smallest rectangle
    The box is the tightest upright box around the instance's vertices in its heading's frame;
    it contains every triangle of the instance, hence every point a scan puts on it.
    """
    headings = headings or {}
    objects = buffers.objects
    wanted = {str(c) for c in classes}
    rows = [r for r in range(len(objects)) if objects.class_names[r] in wanted]
    by_instance: dict[int, list[int]] = {}
    for r in rows:
        by_instance.setdefault(int(objects.instance[r]), []).append(r)
    tri_rows = buffers.triangle_object
    out = np.zeros(len(by_instance), BOX_DTYPE)
    for k, (instance, members) in enumerate(sorted(by_instance.items())):
        triangles = buffers.triangles[np.isin(tri_rows, members)]
        vertices = buffers.vertices[np.unique(triangles)]
        yaw = headings.get(instance)
        if yaw is None:
            yaw = footprint_heading(vertices[:, :2])
        c, s = np.cos(yaw), np.sin(yaw)
        rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        local = vertices @ rotation
        low, high = local.min(axis=0), local.max(axis=0)
        out[k]["class_name"] = objects.class_names[members[0]]
        out[k]["instance"] = instance
        out[k]["centre"] = rotation @ ((low + high) / 2)
        out[k]["size"] = high - low
        out[k]["heading"] = wrap_angle(yaw)
    return out


def boxes_in_frame(boxes: np.ndarray, frame: np.ndarray, where: str = "output.frame") -> np.ndarray:
    """Boxes moved from the world into the frame whose ``(4, 4)`` frame-to-world transform is ``frame``.

    Upright boxes stay upright only in a level frame: ``InputError`` (naming ``where``) when the
    frame's z axis is more than 0.5 degrees from vertical.
    """
    frame = np.asarray(frame, float)
    if frame[2, 2] < np.cos(np.radians(0.5)):
        tilt = np.degrees(np.arccos(np.clip(frame[2, 2], -1, 1)))
        raise InputError(f"{where}: 3D box labels need a level point frame, but the sensor is tilted {tilt:.1f} deg from vertical; write the points in the world frame (output.frame: world)")
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


# ----------------------------------------------------------------------------- field of view, visibility
class Coverage:
    """The directions a sensor pattern covers: cells of ``cell_deg`` in azimuth and elevation that hold a ray.

    A direction is covered when its cell or a neighbouring one holds a ray, so the coverage is
    exact up to one cell; ``cell_deg`` should be at least the pattern's angular spacing.
    """

    def __init__(self, directions: np.ndarray, cell_deg: float):
        self.cell = float(cell_deg)
        self.columns = int(np.ceil(360.0 / self.cell))
        self.rows = int(np.ceil(180.0 / self.cell)) + 1
        self.mask = np.zeros((self.rows, self.columns), bool)
        self.add(directions)

    def _cells(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = np.asarray(directions, float)
        azimuth = np.degrees(np.arctan2(d[:, 1], d[:, 0])) + 180.0
        elevation = np.degrees(np.arcsin(np.clip(d[:, 2] / np.maximum(np.linalg.norm(d, axis=1), 1e-12), -1, 1))) + 90.0
        col = np.floor(azimuth / self.cell).astype(int) % self.columns
        row = np.clip(np.floor(elevation / self.cell).astype(int), 0, self.rows - 1)
        return row, col

    def add(self, directions: np.ndarray) -> None:
        if len(directions):
            row, col = self._cells(directions)
            self.mask[row, col] = True
            self._grown = None

    def covers(self, directions: np.ndarray) -> np.ndarray:
        """``(n,)`` bool for ``(n, 3)`` directions (sensor frame)."""
        if getattr(self, "_grown", None) is None:  # the mask grown by one cell (azimuth wraps around)
            rows = self.mask | np.vstack([self.mask[1:], self.mask[-1:]]) | np.vstack([self.mask[:1], self.mask[:-1]])
            self._grown = rows | np.roll(rows, 1, axis=1) | np.roll(rows, -1, axis=1)
        row, col = self._cells(directions)
        return self._grown[row, col]


def _subset(buffers: SceneBuffers, rows: list[int]) -> SceneBuffers:
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
) -> None:
    """Fill ``truncation``, ``visible`` and ``unoccluded`` of world-frame ``boxes`` in place.

    patterns : the sensor's rays (one :class:`Pattern` or an iterable of chunks), sensor frame
    pose : (4, 4) sensor-to-world transform at frame start
    cell_deg : coverage cell for truncation (about the pattern's coarsest angular spacing): the
        rays passing an object mark the directions they cover, taken from the sensor's centre
        to where they pass it (so rays leaving from the sensor's own mirrors count right)
    caster : a :class:`RayCaster` of ``buffers`` in the sensor's frame, if one exists already
    surfaces, rng : the scanner's rules for mirrors and glass and a generator for glass that
        reflects a fraction of beams (:func:`~bpy_pipeline.lidar.scanner.trace_beams`)
    Only the rays that pass within an object's bounding sphere are traced, once through the
    whole scene and once against the object alone, both the scanner's way (glass passed
    through, no mirror bounces), so a car's windows count the same in both.
    """
    if len(boxes) == 0:
        return
    caster = caster or RayCaster(buffers, frame=pose)
    instance_of_triangle = instance_triangles(buffers)
    objects = buffers.objects
    members = [[r for r in range(len(objects)) if objects.instance[r] == box["instance"]] for box in boxes]
    # bounding spheres in the sensor frame
    centres = (boxes["centre"] - pose[:3, 3]) @ pose[:3, :3]
    radii = np.linalg.norm(boxes["size"], axis=1) / 2 + 1e-3
    alone = [(RayCaster(sub, frame=pose), sub) for sub in (_subset(buffers, rows) for rows in members)]
    visible = np.zeros(len(boxes), np.int64)
    unoccluded = np.zeros(len(boxes), np.int64)
    seen = [[] for _ in range(len(boxes))]  # per object: where the rays passing it are, seen from the sensor
    for chunk in [patterns] if isinstance(patterns, Pattern) else patterns:
        origins = np.zeros((len(chunk), 3)) if chunk.origins is None else chunk.origins
        # a cone test from the sensor's centre first (all objects at once), widened by the farthest
        # ray origin, then the exact ray-sphere test on the rays it lets through
        shift = 0.0 if chunk.origins is None else float(np.linalg.norm(origins, axis=1).max())
        reach = radii + shift
        distance = np.linalg.norm(centres, axis=1)
        cos_limit = np.where(distance > reach, np.sqrt(np.clip(1.0 - (reach / np.maximum(distance, 1e-12)) ** 2, 0.0, 1.0)), -2.0)
        towards = chunk.directions @ (centres / np.maximum(distance, 1e-12)[:, None]).T  # (n, k)
        cone = towards >= cos_limit[None]
        for k in range(len(boxes)):
            candidates = np.flatnonzero(cone[:, k])
            if len(candidates) == 0:
                continue
            offset = centres[k] - origins[candidates]
            along = np.einsum("ij,ij->i", offset, chunk.directions[candidates])
            miss2 = np.einsum("ij,ij->i", offset, offset) - along**2
            passing = (miss2 <= radii[k] ** 2) & (along >= -radii[k]) & (along - radii[k] <= max_range)
            near = candidates[passing]
            if len(near) == 0:
                continue
            o = origins[near] if chunk.origins is not None else np.zeros(3)
            d = chunk.directions[near]
            seen[k].append(o + along[passing, None] * d)  # the ray's point closest to the object's centre
            beams = trace_beams(caster, buffers, o, d, min_range, max_range, max_bounces=0, surfaces=surfaces, rng=rng)
            hit_instance = instance_of_triangle[beams.triangle]
            visible[k] += int(np.count_nonzero((hit_instance == boxes["instance"][k]) & (beams.bounces == 0)))
            lone = trace_beams(*alone[k], o, d, min_range, max_range, max_bounces=0, surfaces=surfaces, rng=rng)
            unoccluded[k] += len(lone.ray)  # the object alone: every return is on it
    boxes["visible"] = visible
    boxes["unoccluded"] = unoccluded
    for k, rows in enumerate(members):
        triangles = buffers.vertices[buffers.triangles[np.isin(buffers.triangle_object, rows)]]  # (m, 3, 3)
        total = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1).sum() / 2
        samples, area = surface_samples(triangles, max(SAMPLE_SPACING, float(np.sqrt(total / MAX_SAMPLES))))
        samples = (samples - pose[:3, 3]) @ pose[:3, :3]
        distance = np.linalg.norm(samples, axis=1)
        inside = (distance >= min_range) & (distance <= max_range)
        if seen[k]:  # the directions the rays passing the object cover, from the sensor's centre
            inside &= Coverage(np.concatenate(seen[k]), cell_deg).covers(samples)
        else:
            inside[:] = False
        total = area.sum()
        boxes["truncation"][k] = float(1.0 - area[inside].sum() / total) if total > 0 else 1.0


def surface_samples(triangles: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points spread over ``(m, 3, 3)`` triangles and the area each stands for: ``(p, 3)``, ``(p,)``.

    A triangle wider than ``spacing`` (metres) is cut into n^2 equal triangles (n up to 24) and
    sampled at their centroids, so the areas add up exactly and large faces are not one point.
    """
    edge = np.maximum(np.linalg.norm(triangles[:, 1] - triangles[:, 0], axis=1), np.linalg.norm(triangles[:, 2] - triangles[:, 0], axis=1))
    level = np.clip(np.ceil(edge / spacing), 1, 24).astype(int)
    area = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1) / 2
    points, weights = [], []
    for n in np.unique(level):
        rows = np.flatnonzero(level == n)
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        up = i + j <= n - 1
        down = i + j <= n - 2
        u = np.concatenate([(i[up] + 1 / 3) / n, (i[down] + 2 / 3) / n])
        v = np.concatenate([(j[up] + 1 / 3) / n, (j[down] + 2 / 3) / n])  # n^2 barycentric points
        t = triangles[rows]
        points.append((t[:, None, 0] + u[None, :, None] * (t[:, None, 1] - t[:, None, 0]) + v[None, :, None] * (t[:, None, 2] - t[:, None, 0])).reshape(-1, 3))
        weights.append(np.repeat(area[rows] / n**2, len(u)))
    if not points:
        return np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(points), np.concatenate(weights)


def occlusion_levels(visible: np.ndarray, unoccluded: np.ndarray, levels=(0.8, 0.4, 0.1)) -> np.ndarray:
    """``(n,)`` uint8 occlusion level 0..3 from visible and unoccluded counts (an object no ray reaches is 3)."""
    visible = np.asarray(visible, float)
    unoccluded = np.asarray(unoccluded, float)
    fraction = np.where(unoccluded > 0, visible / np.maximum(unoccluded, 1), 0.0)
    t0, t1, t2 = levels
    return np.select([fraction >= t0, fraction >= t1, fraction >= t2], [0, 1, 2], 3).astype(np.uint8)


def count_points(boxes: np.ndarray, points: np.ndarray) -> None:
    """Fill ``points`` of ``boxes`` in place: how many records of ``points`` carry each box's instance."""
    counts = np.bincount(points["instance"].astype(np.int64), minlength=int(boxes["instance"].max(initial=0)) + 1)
    boxes["points"] = counts[boxes["instance"].astype(np.int64)]


def keep_boxes(boxes: np.ndarray, min_points: dict | None = None, default: int = 6) -> np.ndarray:
    """The boxes with at least their class's minimum number of points (``min_points[class]``, else ``default``)."""
    min_points = min_points or {}
    need = np.array([min_points.get(str(c), default) for c in boxes["class_name"]], np.int64)
    return boxes[boxes["points"].astype(np.int64) >= need]


# ----------------------------------------------------------------------------- files
def kitti_lines(boxes: np.ndarray, names: dict | None = None) -> list[str]:
    """KITTI label lines of boxes given in a level LiDAR frame (x forward, y left, z up)."""
    lines = []
    for box in boxes:
        length, width, height = box["size"]
        bottom = box["centre"] - [0.0, 0.0, height / 2]
        x, y, z = KITTI_AXES @ bottom
        rotation_y = float(wrap_angle(-box["heading"] - np.pi / 2))
        alpha = float(wrap_angle(rotation_y - np.arctan2(x, z)))
        lines.append(
            f"{label_name(str(box['class_name']), names)} {float(box['truncation']):.4f} {int(box['occlusion'])} {alpha:.4f} "
            f"0.00 0.00 0.00 0.00 {height:.4f} {width:.4f} {length:.4f} {x:.4f} {y:.4f} {z:.4f} {rotation_y:.4f}"
        )
    return lines


def kitti_calib_text() -> str:
    """A KITTI object calib file: nominal pinhole projections, identity rectification, KITTI's LiDAR-to-camera axis change."""
    p = np.array([[700.0, 0.0, 621.0, 0.0], [0.0, 700.0, 187.5, 0.0], [0.0, 0.0, 1.0, 0.0]])
    tr = np.hstack([KITTI_AXES, np.zeros((3, 1))])

    def row(name, m):
        return name + ": " + " ".join(f"{v:.12e}" for v in np.asarray(m, float).ravel())

    return "\n".join([row("P0", p), row("P1", p), row("P2", p), row("P3", p), row("R0_rect", np.eye(3)), row("Tr_velo_to_cam", tr), row("Tr_imu_to_velo", np.hstack([np.eye(3), np.zeros((3, 1))]))]) + "\n"


def read_kitti_labels(path: str | os.PathLike) -> np.ndarray:
    """Boxes (:data:`BOX_DTYPE`, LiDAR frame; ``class_name`` holds the label type) from a KITTI label file written by :func:`write_frame_boxes`."""
    rows = [line.split() for line in Path(path).read_text().splitlines() if line.strip()]
    out = np.zeros(len(rows), BOX_DTYPE)
    for k, r in enumerate(rows):
        h, w, length = map(float, r[8:11])
        cam = np.array(list(map(float, r[11:14])))
        bottom = KITTI_AXES.T @ cam
        out[k]["class_name"] = r[0]
        out[k]["truncation"] = float(r[1])
        out[k]["occlusion"] = int(r[2])
        out[k]["size"] = (length, w, h)
        out[k]["centre"] = bottom + [0.0, 0.0, h / 2]
        out[k]["heading"] = wrap_angle(-float(r[14]) - np.pi / 2)
    return out


def openpcdet_lines(boxes: np.ndarray, names: dict | None = None) -> list[str]:
    """OpenPCDet custom-dataset lines ``x y z dx dy dz heading_angle category_name``."""
    return [
        " ".join(f"{v:.4f}" for v in (*box["centre"], *box["size"], float(box["heading"]))) + f" {label_name(str(box['class_name']), names)}"
        for box in boxes
    ]


def read_openpcdet_labels(path: str | os.PathLike) -> np.ndarray:
    """Boxes (:data:`BOX_DTYPE`; ``class_name`` holds the category name) from an OpenPCDet custom label file."""
    rows = [line.split() for line in Path(path).read_text().splitlines() if line.strip()]
    out = np.zeros(len(rows), BOX_DTYPE)
    for k, r in enumerate(rows):
        values = list(map(float, r[:7]))
        out[k]["centre"], out[k]["size"], out[k]["heading"] = values[:3], values[3:6], values[6]
        out[k]["class_name"] = r[7]
    return out


def _write_text(path: Path, text: str) -> Path:
    with atomic_write(path) as tmp:
        tmp.write_text(text)
    return path


def _xyzi(points: np.ndarray) -> np.ndarray:
    return np.column_stack([points["x"], points["y"], points["z"], points["intensity"]]).astype(np.float32)


def write_frame_boxes(out_dir: str | os.PathLike, frame_index: int, boxes: np.ndarray, points: np.ndarray, formats, names: dict | None = None) -> list[Path]:
    """Write one frame's boxes (in the frame of ``points``) and points in each of ``formats`` (``kitti``, ``openpcdet``)."""
    from .layout import frame_stem

    out_dir = Path(out_dir)
    stem = frame_stem(frame_index)
    written = []
    if "kitti" in formats:
        written.append(_write_text(out_dir / "kitti" / "label_2" / f"{stem}.txt", "".join(line + "\n" for line in kitti_lines(boxes, names))))
        written.append(_write_text(out_dir / "kitti" / "calib" / f"{stem}.txt", kitti_calib_text()))
        with atomic_write(out_dir / "kitti" / "velodyne" / f"{stem}.bin") as tmp:
            _xyzi(points).tofile(tmp)
        written.append(out_dir / "kitti" / "velodyne" / f"{stem}.bin")
    if "openpcdet" in formats:
        written.append(_write_text(out_dir / "openpcdet" / "labels" / f"{stem}.txt", "".join(line + "\n" for line in openpcdet_lines(boxes, names))))
        path = out_dir / "openpcdet" / "points" / f"{stem}.npy"
        with atomic_write(path) as tmp:
            with open(tmp, "wb") as handle:
                np.save(handle, _xyzi(points))
        written.append(path)
    return written


def write_image_sets(out_dir: str | os.PathLike, frame_indices, formats) -> list[Path]:
    """``kitti/ImageSets/train.txt`` and ``openpcdet/ImageSets/train.txt``: the frames written so far, one stem per line."""
    from .layout import frame_stem

    text = "".join(frame_stem(i) + "\n" for i in frame_indices)
    return [_write_text(Path(out_dir) / name / "ImageSets" / "train.txt", text) for name in ("kitti", "openpcdet") if name in formats]
