"""The built-in writers, registered by name (:mod:`.writers`): point formats, range image, preview, box labels."""

from __future__ import annotations

from pathlib import Path

from ..labels import load_class_table
from .boxes import write_frame_boxes, write_image_sets
from .layout import write_frame_las, write_frame_npy, write_frame_ply, write_frame_preview, write_frame_semantickitti
from .range_image import write_frame_range_image
from .writers import Writer, register_writer


def _points_writer(write_points):
    """A writer of the frame's points alone: ``write_points(out, index, points, sequence)``."""
    return Writer(lambda frame, out: write_points(out, frame.index, frame.points, frame.config.output.sequence))


def _write_range_image(frame, out: Path) -> list[Path]:
    return write_frame_range_image(out, frame.index, frame.points, frame.config.sensor.spec, load_class_table().color_lut())


def _check_range_image(config) -> None:
    from ..lidar.grid import check_grid

    check_grid(config.sensor.spec, "output.formats: range_image")


def _write_preview(frame, out: Path) -> list[Path]:
    return [write_frame_preview(out, frame.index, frame.points, load_class_table().color_lut())]


def _box_writer(name: str) -> Writer:
    """Box labels in layout ``name`` (kitti, openpcdet), with the frame's points and an ImageSets index."""

    def write(frame, out: Path) -> list[Path]:
        return write_frame_boxes(out, frame.index, frame.boxes, frame.points, [name], frame.config.output.boxes.names)

    def index(out: Path, records: list[dict], config) -> list[Path]:
        return write_image_sets(out, [r["index"] for r in records], [name])

    return Writer(write, index=index, boxes=True)


register_writer("ply", _points_writer(write_frame_ply))
register_writer("semantickitti", _points_writer(write_frame_semantickitti))
register_writer("las", _points_writer(write_frame_las))
register_writer("npy", _points_writer(write_frame_npy))
register_writer("range_image", Writer(_write_range_image, _check_range_image))
register_writer("preview", Writer(_write_preview))
register_writer("kitti", _box_writer("kitti"))
register_writer("openpcdet", _box_writer("openpcdet"))

from . import rig_outputs  # noqa: F401,E402  (registers rig and flash_image)
