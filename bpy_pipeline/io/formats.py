"""The built-in writers, registered by name (:mod:`.writers`): point formats, range image, preview, box labels.

Point formats (``output.formats``): ply, semantickitti (+ its yaml, calib, poses and times), las, npy
(+ Pointcept split lists), pcd, range_image. Box label layouts (``output.boxes.formats``): kitti
(KITTI object layout with camera images and ImageSets), openpcdet (custom layout), sustech
(SUSTechPOINTS JSON + PCD).
"""

from __future__ import annotations

from pathlib import Path

from ..geometry.transforms import sensor_to_output
from ..labels import load_class_table
from . import kitti, npy, openpcdet, semantickitti, sustech, train_configs
from ._records import WRITE_CHUNK, XyziBlock, xyzi_block
from .class_maps import maps_for, semantic_kitti_lut
from .layout import frame_stem, write_frame_las, write_frame_ply, write_frame_preview
from .pcd import write_pcd
from .range_image import write_frame_range_image
from .splits import sequence_of, split_of
from .writers import Writer, no_files, register_writer


def _points_writer(write_points):
    """A writer of the frame's points alone: ``write_points(out, index, points, sequence)``."""
    return Writer(lambda frame, out: write_points(out, frame.index, frame.points, frame.config.output.sequence))


def _write_range_image(frame, out: Path) -> list[Path]:
    return write_frame_range_image(out, frame.index, frame.points, frame.config.sensor.spec, load_class_table().color_lut())


def _check_range_image(config) -> None:
    from ..lidar.sensor.grid import check_grid

    check_grid(config.sensor.spec, "output.formats: range_image")


def _write_preview(frame, out: Path) -> list[Path]:
    table = load_class_table()
    return [write_frame_preview(out, frame.index, frame.points, table.color_lut(), frame.boxes, table.names)]


def _write_npy(frame, out: Path) -> list[Path]:
    """``npy/NNNNNN/*.npy``: ``segment`` in the training ids of ``output.class_map`` (the table's without one)."""
    return npy.write_npy_folder(Path(out) / "npy" / frame_stem(frame.index), frame.points, maps_for(frame.config.output.class_map))


def _xyzi(frame) -> XyziBlock | None:
    """The frame's x y z intensity block and its sha256 (:func:`._records.xyzi_block`), made once a frame for the files
    that hold these bytes (SemanticKITTI's and the KITTI layout's ``velodyne`` files, OpenPCDet's points after their
    header); ``None`` for a cloud of more than :data:`._records.WRITE_CHUNK` points (written a chunk at a time)."""
    if len(frame.points) > WRITE_CHUNK:
        return None
    if "xyzi" not in frame.shared:
        frame.shared["xyzi"] = xyzi_block(frame.points)
    return frame.shared["xyzi"]


def _write_semantickitti(frame, out: Path) -> list[Path]:
    """``sequences/SS/{velodyne,labels}/NNNNNN.*``: the sequence of the frame's split, SemanticKITTI's raw ids
    unless ``output.semantickitti.labels: project``."""
    config = frame.config
    lut = None if config.output.semantickitti.labels == "project" else semantic_kitti_lut()
    frame_stem(frame.index)
    sequence = sequence_of(frame.index, config.output.split, config.frames)
    return list(semantickitti.write_semantickitti(out, sequence, frame.index, frame.points, lut, _xyzi(frame)))


def _kitti_folder(frame) -> str:
    return "testing" if split_of(frame.index, frame.config.output.split, frame.config.frames) == "test" else "training"


def _write_kitti(frame, out: Path) -> list[Path]:
    """The KITTI layout's point file, labels, calibration and road plane (its image is :func:`_write_kitti_image`)."""
    output = frame.config.output
    to_points = sensor_to_output(output.frame, frame.pose, output.kitti.camera.position)
    found = (getattr(getattr(frame, "mixed", None), "rule_log", None) or {}).get("ground")  # a real scan's, where the mixing looked
    ground = kitti.points_ground(frame.pose, output.frame, found, output.kitti.camera.position)
    return kitti.write_frame_text(out, frame_stem(frame.index), frame.points, frame.boxes, output.kitti.camera, output.boxes.names, _kitti_folder(frame),
                                  to_points, ground, frame.thin_boxes, _xyzi(frame))


def _write_kitti_image(frame, out: Path) -> list[Path]:
    """``image_2``: the camera stage's rendering (output.kitti.camera.render), else the points' projection."""
    return [kitti.write_image(out, frame_stem(frame.index), frame.points, frame.config.output.kitti.camera, load_class_table().color_lut(),
                              frame.images.get("image_2"), _kitti_folder(frame),
                              sensor_to_output(frame.config.output.frame, frame.pose, frame.config.output.kitti.camera.position))]


def _write_openpcdet(frame, out: Path) -> list[Path]:
    return openpcdet.write_frame(out, frame_stem(frame.index), frame.points, frame.boxes, frame.config.output.boxes.names, _xyzi(frame))


def _write_sustech(frame, out: Path) -> list[Path]:
    return sustech.write_frame(out, frame_stem(frame.index), frame.points, frame.boxes, frame.config.output.boxes.names)


def _write_pcd(frame, out: Path) -> list[Path]:
    return [write_pcd(Path(out) / "pcd" / f"{frame_stem(frame.index)}.pcd", frame.points)]


register_writer("ply", _points_writer(write_frame_ply))
register_writer("semantickitti", Writer(_write_semantickitti, index=semantickitti.write_index))
register_writer("las", _points_writer(write_frame_las))
register_writer("npy", Writer(_write_npy, index=npy.write_index))
register_writer("pcd", Writer(_write_pcd))
register_writer("range_image", Writer(_write_range_image, _check_range_image))
register_writer("preview", Writer(no_files, beside=_write_preview))
def _index_kitti(out: Path, records: list[dict], config) -> list[Path]:
    """The KITTI layout's ImageSets, then the training configs of this run (:mod:`.train_configs`)."""
    return kitti.write_index(out, records, config) + train_configs.write_kitti_configs(out, records, config)


def _index_openpcdet(out: Path, records: list[dict], config) -> list[Path]:
    """The custom layout's ImageSets (frames with a box), then the training configs of this run (:mod:`.train_configs`)."""
    with_boxes = [r["index"] for r in records if r.get("boxes")]
    return openpcdet.write_index(out, records, config) + train_configs.write_custom_configs(out, records, config, with_boxes)


register_writer("kitti", Writer(_write_kitti, index=_index_kitti, boxes=True, beside=_write_kitti_image))  # its camera's ranges: the fields' metadata
register_writer("openpcdet", Writer(_write_openpcdet, index=_index_openpcdet, boxes=True))
register_writer("sustech", Writer(_write_sustech, boxes=True))

from . import rig_outputs  # noqa: F401,E402  (registers rig and flash_image)
from . import railway_layout  # noqa: F401,E402  (registers railway_layout)
