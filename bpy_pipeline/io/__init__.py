"""Writers and readers for point clouds and run outputs; pure numpy, never imports bpy.

Formats (docs/formats.md, docs/datasets.md): PLY (binary, all fields), SemanticKITTI (``.bin`` +
``.label``), LAS 1.4 (point format 6 + extra bytes), Pointcept NPY folders, a preview PNG and
the run manifest. Every writer takes an ``(n,)`` :data:`~bpy_pipeline.lidar.points.POINT_DTYPE`
array and writes under a temporary name, then renames (:mod:`.atomic`), so no half-written file
ever carries its final name. :data:`WRITERS` is the registry of per-frame writers (:mod:`.writers`).
"""

from .atomic import atomic_dir, atomic_write
from .las import read_las, write_las
from .layout import frame_stem, write_frame_preview
from .manifest import read_dataset, read_frame_records, read_manifest, write_manifest
from .npy import read_npy_folder, write_npy_folder
from .ply import read_ply, write_ply
from .preview import encode_png, render_preview, write_preview
from .semantickitti import read_bin, read_label, read_semantickitti, write_semantickitti
from .writers import WRITERS, Writer, register_writer
from . import formats  # noqa: F401  (registers the built-in writers)

__all__ = [
    "WRITERS",
    "Writer",
    "register_writer",
    "atomic_dir",
    "atomic_write",
    "encode_png",
    "frame_stem",
    "read_bin",
    "read_label",
    "read_las",
    "read_dataset",
    "read_frame_records",
    "read_manifest",
    "read_npy_folder",
    "read_ply",
    "read_semantickitti",
    "render_preview",
    "write_frame_preview",
    "write_las",
    "write_manifest",
    "write_npy_folder",
    "write_ply",
    "write_preview",
    "write_semantickitti",
]
