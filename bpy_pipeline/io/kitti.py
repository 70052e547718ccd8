"""The KITTI object layout, as OpenPCDet's and mmdetection3d's KITTI loaders read it.

Files (frame ``NNNNNN``)::

    kitti/training/velodyne/NNNNNN.bin   float32 (n, 4): x y z (m, sensor frame), intensity (0..1)
    kitti/training/label_2/NNNNNN.txt    type truncated occluded alpha bbox(4) h w l x y z rotation_y
    kitti/training/calib/NNNNNN.txt      P0..P3 (the camera's 3 x 4 projection), R0_rect, Tr_velo_to_cam, Tr_imu_to_velo
    kitti/training/planes/NNNNNN.txt     the road plane a b c d in the rectified camera frame, as KITTI's (OpenPCDet's
                                         USE_ROAD_PLANE, mmdetection3d's --with-plane): the builders' ground, world z = 0
    kitti/training/image_2/NNNNNN.png    the camera's view: Blender's rendering where the pipeline gives one
                                         (:mod:`bpy_pipeline.blender.camera_render`), else the labelled points it sees
    kitti/testing/...                    the same files for the frames of the test split (``output.split``)
    kitti/ImageSets/{train,val,test}.txt frame stems of each split that holds a frame (none for an empty split)

The camera (``output.kitti.camera``) is a pinhole fixed to the LiDAR; ``Tr_velo_to_cam`` is its
pose composed with KITTI's axis change (x_cam = -y, y_cam = -z, z_cam = x), from the points' frame
(``output.frame``). Types come from ``kitti_names`` in ``assets_manifest/labels.yaml`` (Car, Van, Truck,
Pedestrian, Person_sitting, Cyclist, Tram, Misc), overridden by ``output.boxes.names`` (``DontCare``: a region). As in KITTI, ``label_2`` lists the
objects seen in the image: a box whose points all fall outside it is left out (the OpenPCDet
custom layout keeps every box around the sensor); its 2D box is the extent of its points in the
image, and its truncation is the larger of the LiDAR truncation and the share of its points
outside the image. A frame without such an object gets one ``DontCare`` line (KITTI's own
placeholder), because OpenPCDet's ``get_infos`` and mmdetection3d's converter concatenate the
objects of a label file and fail on an empty one; the frame stays in the ImageSets. Objects seen with
fewer points than their class's minimum are DontCare regions, after the boxed objects, as in KITTI's files.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..geometry.transforms import KITTI_SENSOR_HEIGHT, euler_xyz_matrix, sensor_to_output
from ..compiled import compiled_wanted
from .atomic import atomic_write, hashed_open, write_text_hashed
from .class_maps import ClassMaps, load_class_maps
from ._records import XYZI, XyziBlock, packed_columns
from .preview import encode_png, splat
from .splits import SPLITS, split_indices

KITTI_AXES = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # sensor (x fwd, y left, z up) -> camera (x right, y down, z fwd)
IMAGE_BACKGROUND = (40, 40, 46)
DONT_CARE = "DontCare -1 -1 -10 0.00 0.00 1.00 1.00 -1 -1 -1 -1000 -1000 -1000 -10"
MIN_DEPTH = 0.1  # m in front of the camera for a point to project
MAX_INSTANCE_TABLE = 1 << 22  # instance ids up to this are looked up in a table (4 MB of bools at most); larger ones searched


def wrap_angle(angle):
    """Angle(s) in radians wrapped to [-pi, pi)."""
    return (np.asarray(angle, float) + np.pi) % (2 * np.pi) - np.pi


def camera_matrices(camera, to_points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(K (3, 3), Tr_velo_to_cam (3, 4))`` of an ``output.kitti.camera`` section (pixels; metres).

    to_points : ``(4, 4)`` sensor frame -> the points' frame (``output.frame``; :func:`~bpy_pipeline.geometry.transforms.sensor_to_output`),
        ``None`` when the points are in the sensor frame: ``Tr_velo_to_cam`` takes points of the points' frame
    """
    width, height = (int(v) for v in camera.resolution)
    focal = (width / 2) / np.tan(np.radians(float(camera.fov_deg)) / 2)
    k = np.array([[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]])
    rotation = euler_xyz_matrix(camera.rotation_deg)  # camera body (x forward) -> sensor
    to_cam = KITTI_AXES @ rotation.T
    tr = np.hstack([to_cam, -(to_cam @ np.asarray(camera.position, float))[:, None]])
    if to_points is not None:  # the points' frame -> the sensor's -> the camera's
        tr = tr @ np.linalg.inv(np.asarray(to_points, float))
    return k, tr


def ground_plane(sensor_pose: np.ndarray) -> np.ndarray:
    """``(4,)`` the builders' ground (world z = 0) as ``n . p + d = 0`` (unit normal ``n`` up) in the sensor frame of a
    sensor at ``sensor_pose`` (4, 4): ``n`` is the world's up in that frame, ``d`` the sensor's height above the ground."""
    sensor_pose = np.asarray(sensor_pose, float)
    return np.append(sensor_pose[2, :3], sensor_pose[2, 3])


def points_ground(sensor_pose: np.ndarray, output_frame: str, found: dict | None = None, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """``(4,)`` the ground under a sensor at ``sensor_pose`` (4, 4) as ``n . p + d = 0`` in the points' frame
    (``output.frame``, ``origin`` as :func:`~bpy_pipeline.geometry.transforms.output_pose`): a real scan's ground where the
    mixing found it (``found``: ``{normal, offset}``, ``n . p = offset`` in the sensor frame, its record's
    ``rules.ground``), else the builders' ground (:func:`ground_plane`)."""
    sensor = np.append(found["normal"], -float(found["offset"])) if found else ground_plane(sensor_pose)
    return plane_in_frame(sensor, sensor_to_output(output_frame, np.asarray(sensor_pose, float), origin))


def plane_in_frame(plane: np.ndarray, transform: np.ndarray | None) -> np.ndarray:
    """``(4,)`` plane ``n . p + d = 0`` moved through the ``(4, 4)`` rigid ``transform`` (``None``: unchanged)."""
    if transform is None:
        return np.asarray(plane, float)
    normal = np.asarray(transform, float)[:3, :3] @ np.asarray(plane[:3], float)
    return np.append(normal, float(plane[3]) - normal @ np.asarray(transform, float)[:3, 3])


def road_plane(tr: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """``(4,)`` KITTI's road plane ``a b c d`` of the ground plane ``ground`` (:func:`ground_plane`, the points' frame):
    ``a x + b y + c z + d = 0`` in the rectified camera frame (R0_rect is the identity here) seen through
    ``Tr_velo_to_cam`` ``tr`` (3, 4), unit normal up (``b < 0``, y points down), so ``d`` is the camera's height above the road."""
    normal_cam = tr[:, :3] @ np.asarray(ground[:3], float)
    return np.append(normal_cam, float(ground[3]) - normal_cam @ tr[:, 3])


def plane_text(plane: np.ndarray) -> str:
    """A KITTI ``planes/NNNNNN.txt`` file: its three header lines, then ``a b c d`` (OpenPCDet reads the fourth line)."""
    return "# Matrix\nWIDTH 4\nHEIGHT 1\n" + " ".join(f"{v:.6e}" for v in plane) + "\n"


def project(xyz: np.ndarray, k: np.ndarray, tr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates ``(n, 2)`` (u right, v down) and depths ``(n,)`` (m along the optical axis) of ``(n, 3)`` sensor-frame points."""
    cam = np.asarray(xyz, np.float64) @ tr[:, :3].T + tr[:, 3]
    depth = cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (cam @ k.T)[:, :2] / depth[:, None]
    return uv, depth


def in_image(uv: np.ndarray, depth: np.ndarray, resolution) -> np.ndarray:
    """``(n,)`` bool: in front of the camera and inside the image."""
    width, height = resolution
    return (depth > MIN_DEPTH) & (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)


def calib_text(k: np.ndarray, tr: np.ndarray) -> str:
    """A KITTI object calib file: the camera as P0..P3, identity rectification, ``Tr_velo_to_cam``."""
    p = np.hstack([k, np.zeros((3, 1))])

    def row(name, m):
        return name + ": " + " ".join(f"{v:.12e}" for v in np.asarray(m, float).ravel())

    rows = [row(f"P{i}", p) for i in range(4)] + [row("R0_rect", np.eye(3)), row("Tr_velo_to_cam", tr),
                                                  row("Tr_imu_to_velo", np.hstack([np.eye(3), np.zeros((3, 1))]))]
    return "\n".join(rows) + "\n"


def points_of_instances(instance: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """``(m,)`` int64 indices of the points whose ``instance`` ((n,) ids) is one of ``wanted`` ((w,) ids), grouped by
    instance in ascending order, each group in point order (a stable sort of only those points by instance)."""
    wanted = np.asarray(wanted, np.int64)
    if len(wanted) == 0 or len(instance) == 0:
        return np.zeros(0, np.int64)
    top = int(wanted.max())
    if 0 <= int(wanted.min()) and top < MAX_INSTANCE_TABLE:  # a table of the ids up to the largest wanted one, then one look-up a point
        table = np.zeros(top + 2, bool)
        table[wanted] = True
        picked = np.flatnonzero(table[np.minimum(instance, top + 1)])
    else:
        picked = np.flatnonzero(np.isin(instance, wanted))
    return picked[np.argsort(instance[picked], kind="stable")]


def label_lines(boxes: np.ndarray, points: np.ndarray, camera, maps: ClassMaps | None = None, names: dict | None = None, to_points: np.ndarray | None = None,
                regions: np.ndarray | None = None) -> list[str]:
    """KITTI label lines of ``boxes`` (BOX_DTYPE, the level points' frame) seen by ``camera`` in ``points`` (POINT_DTYPE).

    A box whose type is ``DontCare``, and each of ``regions`` (BOX_DTYPE: objects seen but too thin to label), becomes a
    DontCare region (its 2D box, no 3D box) after every boxed object, as in KITTI's files ("regions in which objects have
    not been labeled, for example because they have been too far away from the laser scanner"): the loaders take the
    objects before the DontCare lines as the 3D boxes. A frame without a seen object gives ``[DONT_CARE]``.
    to_points : as :func:`camera_matrices`
    """
    maps = load_class_maps() if maps is None else maps
    k, tr = camera_matrices(camera, to_points)
    resolution = tuple(int(v) for v in camera.resolution)
    regions = boxes[:0] if regions is None else regions
    wanted = np.concatenate([boxes["instance"], regions["instance"]])  # the boxes', then the regions' instances
    order = points_of_instances(points["instance"], wanted)
    owners = points["instance"][order]
    xyz = np.stack([points[name][order] for name in ("x", "y", "z")], axis=1)  # (m, 3) float32: the boxed instances' points, grouped by instance
    uv, depth = project(xyz, k, tr)  # each point's numbers as projected box by box (row by row the same arithmetic)
    seen = in_image(uv, depth, resolution)
    every = [(b, False) for b in boxes] + [(b, True) for b in regions]
    first, end = np.searchsorted(owners, wanted, "left"), np.searchsorted(owners, wanted, "right")  # each box's points: rows first..end
    running = np.concatenate([[0], np.cumsum(seen)])
    lines, dont_care = [], []
    for j in np.flatnonzero(running[end] > running[first]).tolist():  # the boxes the camera sees a point of, in order
        (box, region), rows = every[j], slice(first[j], end[j])
        mine = uv[rows][seen[rows]]
        left, top = mine.min(axis=0)
        right, bottom_px = mine.max(axis=0)
        truncation = max(float(box["truncation"]), 1.0 - len(mine) / (end[j] - first[j]))
        length, width, height = box["size"]
        bottom = np.asarray(box["centre"], float) - [0.0, 0.0, height / 2]
        x, y, z = tr[:, :3] @ bottom + tr[:, 3]
        heading = tr[:, :3] @ [np.cos(box["heading"]), np.sin(box["heading"]), 0.0]  # the box's length axis in the camera frame
        rotation_y = float(wrap_angle(np.arctan2(-heading[2], heading[0])))
        alpha = float(wrap_angle(rotation_y - np.arctan2(x, z)))
        kind = "DontCare" if region else maps.kitti_name(str(box["class_name"]), names)
        if kind == "DontCare":
            dont_care.append(f"DontCare -1 -1 -10 {left:.2f} {top:.2f} {right:.2f} {bottom_px:.2f} -1 -1 -1 -1000 -1000 -1000 -10")
            continue
        lines.append(
            f"{kind} {truncation:.4f} {int(box['occlusion'])} {alpha:.4f} "
            f"{left:.2f} {top:.2f} {right:.2f} {bottom_px:.2f} {height:.4f} {width:.4f} {length:.4f} {x:.4f} {y:.4f} {z:.4f} {rotation_y:.4f}"
        )
    return lines + dont_care or [DONT_CARE]


@cache
def _square_kernels():
    """The compiled passes of :func:`render_image` (numba, cached on disk), or ``None`` without them
    (:func:`~bpy_pipeline.compiled.compiled_wanted`: no numba, or ``BPY_PIPELINE_SCAN_KERNEL=numpy``; both paths paint the same pixels).

    ``shift_rows(cam (n, 3), t (3,))``: ``cam += t`` in place. ``paint_squares``: with ``pix = cam @ k.T``, each point's
    :func:`project` values (``u = pix[:, 0] / cam[:, 2]``, ``v = pix[:, 1] / cam[:, 2]``, depth ``cam[:, 2]``: the same
    IEEE operations, no fused multiply-add), then numpy's path: the points :func:`in_image` keeps, in order, each painting
    its dot x dot square (rows of the square outer, columns inner, as np.meshgrid ravels them; clipped to the image) at
    -depth with :func:`~.preview.splat`'s rule (at least as deep as the pixel's best wins).
    """
    if not compiled_wanted():
        return None
    import numba

    @numba.njit(cache=True, nogil=True)
    def shift_rows(cam, t):  # pragma: no cover (compiled)
        for i in range(cam.shape[0]):
            for j in range(3):
                cam[i, j] += t[j]

    @numba.njit(cache=True, nogil=True)
    def paint_squares(flat, pix, cam, semantic, lut, dot, width, height, min_depth, best):  # pragma: no cover (compiled)
        first = -((dot - 1) // 2)
        for i in range(len(cam)):
            d = cam[i, 2]
            if not d > min_depth:  # behind the camera, or NaN (before dividing: no division by zero)
                continue
            u, v = pix[i, 0] / d, pix[i, 1] / d
            if not (u >= 0 and u < width and v >= 0 and v < height):
                continue
            col, row = np.int64(np.floor(u)), np.int64(np.floor(v))
            colour = lut[min(np.int64(semantic[i]), len(lut) - 1)]
            for dv in range(first, first + dot):
                r = min(max(row + dv, 0), height - 1)
                for du in range(first, first + dot):
                    p = r * width + min(max(col + du, 0), width - 1)
                    if -d >= best[p]:
                        best[p] = -d
                        flat[p, 0], flat[p, 1], flat[p, 2] = colour[0], colour[1], colour[2]

    return SimpleNamespace(shift_rows=shift_rows, paint_squares=paint_squares)


def render_image(points: np.ndarray, camera, color_lut: np.ndarray, dot: int = 3, to_points: np.ndarray | None = None) -> np.ndarray:
    """``(height, width, 3) uint8``: the LiDAR points seen by the camera, coloured by class, nearer over farther.

    A projection of the labelled cloud (not a rendering of the scene's surfaces): it gives the
    loaders the image and its size, and shows what the 2D boxes enclose. to_points : as :func:`camera_matrices`
    """
    k, tr = camera_matrices(camera, to_points)
    width, height = (int(v) for v in camera.resolution)
    image = np.empty((height, width, 3), np.uint8)
    image.reshape(height, width * 3)[:] = np.tile(np.asarray(IMAGE_BACKGROUND, np.uint8), width)  # row by row: 30x faster than a 3-byte broadcast
    xyz = packed_columns(points, ("x", "y", "z"), np.float64)  # the float32 values, as project takes them
    lut = np.asarray(color_lut, np.uint8)
    kernels = _square_kernels()
    if kernels is not None:  # project's products (the same matrix products), its sum and quotients in the compiled passes
        cam = xyz @ tr[:, :3].T
        kernels.shift_rows(cam, np.ascontiguousarray(tr[:, 3]))
        pix = np.matmul(cam, k.T, out=xyz)  # into xyz's memory, no longer needed
        kernels.paint_squares(image.reshape(-1, 3), pix, cam, points["semantic"], lut, dot, width, height, MIN_DEPTH, np.full(width * height, -np.inf))
        return image
    uv, depth = project(xyz, k, tr)
    seen = in_image(uv, depth, (width, height))
    if not seen.any():
        return image
    semantic = np.minimum(points["semantic"][seen], len(lut) - 1)
    col, row = np.floor(uv[seen]).astype(np.int64).T
    offsets = np.arange(dot) - (dot - 1) // 2
    du, dv = (a.ravel() for a in np.meshgrid(offsets, offsets))
    col = np.clip(col[:, None] + du, 0, width - 1).ravel()
    row = np.clip(row[:, None] + dv, 0, height - 1).ravel()
    splat(image, col, row, np.repeat(-depth[seen], len(du)), np.repeat(np.take(lut, semantic, axis=0), len(du), axis=0))
    return image


def _text(path: Path, text: str) -> Path:
    with atomic_write(path) as tmp:
        write_text_hashed(tmp, text)  # the bytes of tmp.write_text(text), hashed as written
    return path


def write_frame(out_dir: str | os.PathLike, stem: str, points: np.ndarray, boxes: np.ndarray, camera, color_lut: np.ndarray, names: dict | None = None,
                image: np.ndarray | None = None, folder: str = "training", to_points: np.ndarray | None = None, ground: np.ndarray | None = None) -> list[Path]:
    """One frame of the KITTI layout under ``out_dir/kitti/<folder>`` (see the module docstring); returns the paths:
    :func:`write_frame_text`'s, then :func:`write_image`'s."""
    return (write_frame_text(out_dir, stem, points, boxes, camera, names, folder, to_points, ground)
            + [write_image(out_dir, stem, points, camera, color_lut, image, folder, to_points)])


def write_frame_text(out_dir: str | os.PathLike, stem: str, points: np.ndarray, boxes: np.ndarray, camera, names: dict | None = None, folder: str = "training",
                     to_points: np.ndarray | None = None, ground: np.ndarray | None = None, regions: np.ndarray | None = None,
                     xyzi: XyziBlock | None = None) -> list[Path]:
    """A frame's ``velodyne``, ``label_2``, ``calib`` and ``planes`` files under ``out_dir/kitti/<folder>``; returns their paths.

    folder : ``training``, or ``testing`` for a frame of the test split (where the loaders read test frames)
    to_points : ``(4, 4)`` sensor frame -> the points' frame (:func:`camera_matrices`); ``None``: the sensor frame
    ground : ``(4,)`` the ground plane ``n . p + d = 0`` in the points' frame (:func:`ground_plane`, :func:`plane_in_frame`);
        ``None``: level, KITTI's 1.73 m below the origin
    regions : BOX_DTYPE boxes too thin to label, written as DontCare regions where the camera sees them (:func:`label_lines`)
    xyzi : :class:`~._records.XyziBlock` of ``points``, made once for the files that hold these bytes (``velodyne``'s)
    """
    root = Path(out_dir) / "kitti" / folder
    k, tr = camera_matrices(camera, to_points)
    velodyne = root / "velodyne" / f"{stem}.bin"
    with atomic_write(velodyne) as tmp, hashed_open(tmp) as f:  # hashed as written: the commit reads it back no more
        if xyzi is not None:
            f.write(xyzi.array, xyzi.sha256)
        else:
            f.write(packed_columns(points, XYZI))
    lines = label_lines(boxes if boxes is not None else np.zeros(0, _box_dtype()), points, camera, names=names, to_points=to_points, regions=regions)
    plane = road_plane(tr, np.array([0.0, 0.0, 1.0, KITTI_SENSOR_HEIGHT]) if ground is None else ground)
    return [velodyne, _text(root / "label_2" / f"{stem}.txt", "".join(line + "\n" for line in lines)), _text(root / "calib" / f"{stem}.txt", calib_text(k, tr)),
            _text(root / "planes" / f"{stem}.txt", plane_text(plane))]


def write_image(out_dir: str | os.PathLike, stem: str, points: np.ndarray, camera, color_lut: np.ndarray, image: np.ndarray | None = None,
                folder: str = "training", to_points: np.ndarray | None = None) -> Path:
    """A frame's ``image_2`` PNG under ``out_dir/kitti/<folder>``; returns its path.

    image : ``(height, width, 3) uint8`` the camera's rendering of the scene (:func:`bpy_pipeline.blender.camera_render.render_camera`);
        without one, the projection of the labelled points (:func:`render_image`)
    """
    image_path = Path(out_dir) / "kitti" / folder / "image_2" / f"{stem}.png"
    if image is not None and np.shape(image) != (int(camera.resolution[1]), int(camera.resolution[0]), 3):
        raise ValueError(f"image_2: expected a {camera.resolution[1]} x {camera.resolution[0]} RGB image, got shape {np.shape(image)}")
    data = encode_png(render_image(points, camera, color_lut, to_points=to_points) if image is None else image, level=1)
    with atomic_write(image_path) as tmp, hashed_open(tmp) as f:
        f.write(data)
    return image_path


def _box_dtype():
    from ..geometry.boxes import BOX_DTYPE

    return BOX_DTYPE


def write_image_sets(out_dir: str | os.PathLike, folder: str, sets: dict[str, list[int]]) -> list[Path]:
    """``out_dir/folder/ImageSets/{train,val,test}.txt``: one frame stem a line, for each split of ``sets`` that holds a frame.

    An empty split gets no file (and loses one a previous index wrote): mmdetection3d's converter fails on an empty list.
    """
    written = []
    for name in SPLITS:
        path = Path(out_dir) / folder / "ImageSets" / f"{name}.txt"
        if sets.get(name):
            written.append(_text(path, "".join(f"{i:06d}\n" for i in sets[name])))
        else:
            path.unlink(missing_ok=True)
    return written


def write_index(out_dir: str | os.PathLike, records: list[dict], config) -> list[Path]:
    """``kitti/ImageSets/{train,val,test}.txt`` of the committed frames, by ``output.split`` (:mod:`.splits`); no file for an empty split."""
    return write_image_sets(out_dir, "kitti", split_indices([r["index"] for r in records], config.output.split, config.frames))
