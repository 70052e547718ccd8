"""Writers: the registry of everything a frame can be written as (``output.formats``, preview, boxes).

A writer is ``write(frame, out) -> list[Path]``: it writes one :class:`~bpy_pipeline.frame.Frame`
(its points, boxes and config) under the folder ``out`` and returns the paths it wrote; an optional
``beside(frame, out)`` writes the rest, on a thread of its own where a core is spare (the images). ``check``
validates the config for it (``InputError`` naming the key); ``needs`` names what else the frame must
carry, which the frame plan (:mod:`bpy_pipeline.plan`) makes in a stage: a writer only writes. ``index`` rewrites a per-dataset index
(ImageSets, a class table file) from the committed frames' records, after a run or a resume.
Adding a format is one module that defines its writer and calls :func:`register_writer`, plus its
name in the import line of :mod:`bpy_pipeline.io.formats`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from ..registry import Registry


def no_check(config) -> None:
    """A writer that works with any config."""


def no_files(frame, out: Path) -> list[Path]:
    """The ``write`` of a writer whose work is all in its ``beside`` part."""
    return []


@dataclass(frozen=True)
class Writer:
    """A writer's registry entry (see the module docstring)."""

    write: Callable[[Any, Path], list[Path]]
    check: Callable[[Any], None] = no_check
    index: Callable[[Path, list[dict], Any], list[Path]] | None = None
    boxes: bool = False  # writes box labels: named in output.boxes.formats, not output.formats
    needs: tuple[str, ...] = ()  # what the frame must carry besides points and boxes (``flash``: flash images), made by the stage the frame plan adds for it
    # a part of the work that may run on a thread of its own while the writers' ``write`` parts run (an image: numpy, compiled passes
    # and zlib, which mostly let go of the interpreter); its paths follow ``write``'s (``dataset.write_frame_files``)
    beside: Callable[[Any, Path], list[Path]] | None = None


WRITERS: Registry[Writer] = Registry("output format", "output.formats")


def register_writer(name: str, writer: Writer) -> Writer:
    """Make ``name`` usable in ``output.formats`` (or as the preview and box writers)."""
    return WRITERS.register(name, writer)


def frame_writers(config) -> list[str]:
    """Names of the writers a frame of ``config`` goes through: its formats, the preview, its box formats."""
    return [*config.output.formats, *(["preview"] if config.output.preview else []), *config.output.boxes.formats]
