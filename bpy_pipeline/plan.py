"""The frame plan: the stages every frame of a run goes through, chosen once per run (:func:`plan`).

Three plans, each a tuple of small stages over the same :class:`~bpy_pipeline.frame.Frame`:

- **single sensor**: build -> pose -> export -> scan -> effects [-> annotate] [-> flash] [-> camera];
- **rig** (``sensor.rig``): build -> pose -> members (export, scan, effects [, boxes] for each sensor, then the
  platform's buffers) -> merge [-> merged boxes] [-> flash];
- **real-scan background** (a builder whose ``plan`` is ``real_scan``): background -> place -> cast ->
  effects -> annotate (:mod:`bpy_pipeline.stages.mixing`).

``build`` comes before ``pose`` because a moving sensor may follow a curve of the built scene. A stage
is in the plan only when the run asks for what it makes (boxes when a box format or ``skip_empty``
asks, the camera when KITTI renders, the products a writer ``needs``: :data:`PRODUCTS`), so no stage
asks whether it should run. A run can start at any frame: a scene that serves several frames
(railway stations) is built from the generator of the first frame it serves, so any frame alone
gives the same bytes as in the full run. What a run keeps across frames is its
:class:`~bpy_pipeline.frame.Run`, never the module.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from .builders.base import BUILDERS
from .config import Config
from .dataset import Dataset
from .frame import Frame, Run, StageFunction, frame_rng
from .io import read_dataset
from .io.writers import WRITERS, frame_writers
from .registry import Registry
from .stages.annotate import annotate_stage
from .stages.camera import camera_stage
from .stages.flash import flash_stage, rig_flash_stage
from .stages.mixing import MIXING_STAGES
from .stages.rig import members_stage_of, merge_stage, merged_boxes_stage
from .stages.scan import effects_stage, scan_stage
from .stages.scene import build_stage, export_stage, pose_stage

LONG_STAGE_S = 3.0  # a stage that takes longer gets a line of its own
MAX_INDICES_PER_KEPT = 20  # output.frames_kept: frame indices tried per kept frame before giving up


@dataclass(frozen=True)
class Stage:
    """A stage of a frame plan: ``function(frame, run)`` fills in its part of the frame.

    name : what the stage is (for logs and the plan's listing)
    timing : the frame timing its seconds add to (several stages may share one); ``None`` for a stage
        that times its own parts (a rig's members; the effects stage, which traces the lazy scan's chunks
        as it goes: their tracing is the ``scan`` timing, the rest ``effects``)
    """

    name: str
    function: StageFunction
    timing: str | None

    def __call__(self, frame: Frame, run: Run) -> None:
        self.function(frame, run)


def _single(config: Config) -> tuple[Stage, ...]:
    stages = [Stage("build", build_stage, "build"), Stage("pose", pose_stage, "build"), Stage("export", export_stage, "export"),
              Stage("scan", scan_stage, "scan"), Stage("effects", effects_stage, None)]
    if config.output.boxes.formats:
        stages.append(Stage("annotate", annotate_stage, "boxes"))
    if config.output.kitti.camera.render and "kitti" in config.output.boxes.formats:
        stages.append(Stage("camera", camera_stage, "camera"))
    return tuple(stages)


def _rig(config: Config) -> tuple[Stage, ...]:
    boxes = bool(config.output.boxes.formats or config.output.skip_empty)
    stages = [Stage("build", build_stage, "build"), Stage("pose", pose_stage, "build"), Stage("members", members_stage_of(config, boxes), None),
              Stage("merge", merge_stage, "scan")]
    if boxes:
        stages.append(Stage("merged boxes", merged_boxes_stage, "boxes"))
    return tuple(stages)


def _real_scan(config: Config) -> tuple[Stage, ...]:
    timings = {"annotate_stage": "boxes", "effects_stage": "effects"}
    return tuple(Stage(f.__name__.removesuffix("_stage"), f, timings.get(f.__name__, "scan")) for f in MIXING_STAGES)


def _scene(config: Config) -> tuple[Stage, ...]:
    return _rig(config) if config.sensor.rig else _single(config)


# how a builder's frames are made (Builder.plan): from a Blender scene (one sensor or a rig), or from a real scan
PLANS: Registry[Callable[[Config], tuple[Stage, ...]]] = Registry("frame plan", "scene.builder")
PLANS.register("scene", _scene)
PLANS.register("real_scan", _real_scan)

# what a writer may need besides points and boxes (Writer.needs) -> the stage that makes it (one sensor, a rig)
PRODUCTS: Registry[tuple[Stage, Stage]] = Registry("frame product", "output.formats")
PRODUCTS.register("flash", (Stage("flash", flash_stage, "flash"), Stage("flash", rig_flash_stage, "flash")))


def plan(config: Config) -> tuple[Stage, ...]:
    """The stages every frame of a run of ``config`` goes through, in order (see the module docstring)."""
    builder = BUILDERS.get(config.scene.builder)
    if builder.stages:  # a builder that still gives its own stages: ((stage(frame, run), timing), ...)
        stages = tuple(Stage(getattr(f, "__name__", "stage").removesuffix("_stage"), f, timing) for f, timing in builder.stages)
    else:
        stages = PLANS.get(builder.plan)(config)
    products = []
    for name in frame_writers(config):
        for need in WRITERS.get(name).needs:
            if need not in products:
                products.append(need)
    return stages + tuple(PRODUCTS.get(need)[1 if config.sensor.rig else 0] for need in products)


def make_frame(run: Run, index: int, stages: tuple[Stage, ...] | None = None) -> Frame:
    """Frame ``index`` through the run's plan (``stages``; :func:`plan` of its config when ``None``), timed;
    the builder's warnings (when this frame built its scene) and long stages are logged."""
    frame = Frame(index, run.config, frame_rng(run.config.seed, index))
    for stage in plan(run.config) if stages is None else stages:
        start = time.perf_counter()
        stage(frame, run)
        took = time.perf_counter() - start
        if stage.timing is not None:
            frame.timings[stage.timing] = frame.timings.get(stage.timing, 0.0) + took
        if run.log is not None and took > LONG_STAGE_S:
            run.log(f"note: frame {index}: {stage.name} took {took:.1f} s")
    if run.log is not None and frame.built:
        for line in frame.scene.warnings:
            run.log(f"warning: frame {index}: {line}")
    return frame


def labelled_objects(frame: Frame, run: Run) -> int:
    """How many objects of ``output.boxes.classes`` the frame's cloud holds with their minimum points
    (its boxes when it has any, else counted from the points' instances)."""
    if frame.boxes is not None:
        return int(len(frame.boxes))
    section = run.config.output.boxes
    wanted = {run.table.id_of(c): section.min_points.get(c, section.min_points_default) for c in section.classes}
    points = frame.points
    keep = np.isin(points["semantic"], list(wanted)) & (points["instance"] > 0)
    instances, first, counts = np.unique(points["instance"][keep], return_index=True, return_counts=True)
    classes = points["semantic"][keep][first]
    return int(sum(1 for c, n in zip(classes, counts) if n >= wanted[int(c)]))


def empty_reason(frame: Frame, run: Run) -> str | None:
    """Why ``output.skip_empty`` skips the frame, ``None`` to keep it."""
    objects = labelled_objects(frame, run)
    need = run.config.output.min_objects
    return None if objects >= need else f"{objects} labelled object{'s' if objects != 1 else ''}, fewer than output.min_objects ({need})"


def run_frames(config: Config, out_dir: str | Path, build: bool = True, frames: Iterable[int] | None = None, mode: str = "new", log: Callable[[str], None] | None = None) -> Iterator[Frame]:
    """The frames of a run, one at a time: each is committed to the dataset in ``out_dir`` when it is yielded.

    frames : the frame indices to make (default: all of ``config.frames``); any subset gives the same
        bytes per frame as the full run
    mode : ``new`` (refuse a folder holding another run), ``resume`` (same config and seed: skip
        committed frames) or ``overwrite`` (remove the old dataset first); see :mod:`.dataset`
    Stopping early (``close()``, or dropping the iterator) keeps every frame already yielded.
    ``build=False`` scans the current scene as it is instead of building ``config.scene`` (the Blender
    panel's "my scene", or a built scene the user has edited since).
    """
    output = config.output
    until_kept = output.skip_empty and output.frames_kept and (frames is None or list(frames) == list(range(config.frames)))  # a full run
    frames = range(config.frames) if frames is None else frames
    if until_kept:  # frame indices go on until `frames` frames are kept (at most MAX_INDICES_PER_KEPT per kept frame)
        frames = range(MAX_INDICES_PER_KEPT * config.frames)
    run = Run(config, build, log=log)
    stages = plan(config)
    with Dataset.open(out_dir, config, mode, log=log) as dataset:
        for index in frames:
            if until_kept and sum(1 for r in dataset.committed.values() if not r.get("skipped")) >= config.frames:
                break
            if dataset.has(index):
                continue
            frame = make_frame(run, index, stages)
            reason = empty_reason(frame, run) if output.skip_empty else None
            if reason is not None:
                dataset.skip(frame, reason)
                if log is not None:
                    log(f"frame {index}: skipped ({reason})")
                continue
            dataset.commit(frame)
            yield frame
        else:
            if until_kept and log is not None:
                log(f"warning: output.frames_kept: {MAX_INDICES_PER_KEPT * config.frames} frame indices gave fewer than {config.frames} kept frames; the scene rarely holds {output.min_objects} labelled objects")


def run(config: Config, out_dir: str | Path, log=print, build: bool = True, frames: Iterable[int] | None = None, mode: str = "new") -> dict:
    """Generate the frames ``frames`` (default: all) of ``config`` into ``out_dir``; returns the manifest (with its frames)."""
    for frame in run_frames(config, out_dir, build, frames, mode, log):  # None: all (output.frames_kept: until enough are kept)
        log(f"frame {frame.index + 1}/{config.frames}: {len(frame.points)} points, " + ", ".join(f"{k} {v:.2f} s" for k, v in frame.timings.items()))
    return read_dataset(out_dir)
