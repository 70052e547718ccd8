"""The frame plan: the stages every frame of a run goes through, chosen once per run (:func:`plan`).

Three plans, each a tuple of small stages over the same :class:`~bpy_pipeline.frame.Frame`:

- **single sensor**: build -> pose -> export -> scan -> effects [-> camera] [-> annotate] [-> flash];
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

A plan's last stages that call no Blender (:attr:`Stage.finishing`: the boxes, flash images) and the frame's
commit may run on a thread beside the next frame's first stages (:func:`run_frames`, :func:`overlaps`).
"""

from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import nullcontext
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
from .lidar.cast.raycast import default_threads
from .lidar.sensor.sensors import ray_count
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
OVERLAP_MIN_RAYS = 1 << 16  # rays a frame (a rig's: all its sensors') from which a frame finishes beside the next one. Smaller frames
# spend their time in the interpreter, which two threads take turns at: 80 parking frames (the vlp16, 14,480 rays) ran at 1.02-1.06
# of the wall time with the thread; the ego street, the default railway and the os1_128 box at 0.88-0.95 (docs/performance.md)


@dataclass(frozen=True)
class Stage:
    """A stage of a frame plan: ``function(frame, run)`` fills in its part of the frame.

    name : what the stage is (for logs and the plan's listing)
    timing : the frame timing its seconds add to (several stages may share one); ``None`` for a stage
        that times its own parts (a rig's members; the effects stage, which traces the lazy scan's chunks
        as it goes: their tracing is the ``scan`` timing, the rest ``effects``)
    finishing : it calls no Blender and changes nothing the run keeps across frames (it reads the frame, the
        run's config and class table, and uses the run's rays and casters, which two threads may share), so
        a frame's last stages, when all are finishing, may run beside the next frame's first (:func:`run_frames`)
    reads_blender : it reads the frame's objects from Blender itself (a render, a rig's members' exports), not the
        builder's arrays: a run with no such stage leaves Blender's copy of each frame's road users to its end
    """

    name: str
    function: StageFunction
    timing: str | None
    finishing: bool = False
    reads_blender: bool = False

    def __call__(self, frame: Frame, run: Run) -> None:
        self.function(frame, run)


def _single(config: Config) -> tuple[Stage, ...]:
    stages = [Stage("build", build_stage, "build"), Stage("pose", pose_stage, "build"), Stage("export", export_stage, "export"),
              Stage("scan", scan_stage, "scan"), Stage("effects", effects_stage, None)]
    if config.output.kitti.camera.render and "kitti" in config.output.boxes.formats:  # Blender renders it: before the finishing stages
        stages.append(Stage("camera", camera_stage, "camera", reads_blender=True))
    if config.output.boxes.formats:
        stages.append(Stage("annotate", annotate_stage, "boxes", finishing=True))
    return tuple(stages)


def _rig(config: Config) -> tuple[Stage, ...]:
    boxes = bool(config.output.boxes.formats or config.output.skip_empty)
    stages = [Stage("build", build_stage, "build"), Stage("pose", pose_stage, "build"),
              Stage("members", members_stage_of(config, boxes), None, reads_blender=True),
              Stage("merge", merge_stage, "scan")]
    if boxes:
        stages.append(Stage("merged boxes", merged_boxes_stage, "boxes", finishing=True))
    return tuple(stages)


def _real_scan(config: Config) -> tuple[Stage, ...]:
    timings = {"annotate_stage": "boxes", "effects_stage": "effects"}
    return tuple(Stage(f.__name__.removesuffix("_stage"), f, timings.get(f.__name__, "scan"), finishing=f is MIXING_STAGES[-1]) for f in MIXING_STAGES)


def _scene(config: Config) -> tuple[Stage, ...]:
    return _rig(config) if config.sensor.rig else _single(config)


# how a builder's frames are made (Builder.plan): from a Blender scene (one sensor or a rig), or from a real scan
PLANS: Registry[Callable[[Config], tuple[Stage, ...]]] = Registry("frame plan", "scene.builder")
PLANS.register("scene", _scene)
PLANS.register("real_scan", _real_scan)

# what a writer may need besides points and boxes (Writer.needs) -> the stage that makes it (one sensor, a rig)
PRODUCTS: Registry[tuple[Stage, Stage]] = Registry("frame product", "output.formats")
PRODUCTS.register("flash", (Stage("flash", flash_stage, "flash", finishing=True), Stage("flash", rig_flash_stage, "flash", finishing=True)))


def plan(config: Config) -> tuple[Stage, ...]:
    """The stages every frame of a run of ``config`` goes through, in order (see the module docstring)."""
    builder = BUILDERS.get(config.scene.builder)
    stages = PLANS.get(builder.plan)(config)
    products = []
    for name in frame_writers(config):
        for need in WRITERS.get(name).needs:
            if need not in products:
                products.append(need)
    return stages + tuple(PRODUCTS.get(need)[1 if config.sensor.rig else 0] for need in products)


def run_stages(frame: Frame, run: Run, stages: tuple[Stage, ...], said: list[str]) -> None:
    """``stages`` on ``frame`` in turn, timed; the line of each long stage appended to ``said``."""
    for stage in stages:
        start = time.perf_counter()
        stage(frame, run)
        took = time.perf_counter() - start
        if stage.timing is not None:
            frame.timings[stage.timing] = frame.timings.get(stage.timing, 0.0) + took
        if took > LONG_STAGE_S:
            said.append(f"note: frame {frame.index}: {stage.name} took {took:.1f} s")


def builder_warnings(frame: Frame) -> list[str]:
    """The builder's warnings, as lines, when this frame built its scene."""
    return [f"warning: frame {frame.index}: {line}" for line in frame.scene.warnings] if frame.built else []


def make_frame(run: Run, index: int, stages: tuple[Stage, ...] | None = None) -> Frame:
    """Frame ``index`` through the run's plan (``stages``; :func:`plan` of its config when ``None``), timed;
    the builder's warnings (when this frame built its scene) and long stages are logged."""
    frame = Frame(index, run.config, frame_rng(run.config.seed, index))
    said: list[str] = []
    run_stages(frame, run, plan(run.config) if stages is None else stages, said)
    if run.log is not None:
        for line in said + builder_warnings(frame):
            run.log(line)
    return frame


def finishing_start(stages: tuple[Stage, ...]) -> int:
    """Where the plan's finishing stages begin: the index of the first of its last stages that are all
    :attr:`Stage.finishing` (``len(stages)`` when the last one is not)."""
    start = len(stages)
    while start > 0 and stages[start - 1].finishing:
        start -= 1
    return start


def overlaps(config: Config, until_kept: bool) -> bool:
    """Whether a run of ``config`` gives each frame's finishing stages and commit a thread of their own,
    beside the next frame's first stages: with a core to spare (``config.threads`` 0 or above 1; a worker
    of ``--workers`` runs on its share of the cores, often one) and frames of at least :data:`OVERLAP_MIN_RAYS`
    rays, never while ``output.frames_kept`` counts the frames kept so far (the next frame depends on it)."""
    rays = sum(ray_count(member.spec) for member in config.sensor.rig) if config.sensor.rig else ray_count(config.sensor.spec)
    return not until_kept and rays >= OVERLAP_MIN_RAYS and (config.threads or default_threads()) > 1


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


def run_frames(config: Config, out_dir: str | Path, build: bool = True, frames: Iterable[int] | None = None, mode: str = "new",
               log: Callable[[str], None] | None = None, overlap: bool = True) -> Iterator[Frame]:
    """The frames of a run, one at a time: each is committed to the dataset in ``out_dir`` when it is yielded.

    frames : the frame indices to make (default: all of ``config.frames``); any subset gives the same
        bytes per frame as the full run
    mode : ``new`` (refuse a folder holding another run), ``resume`` (same config and seed: skip
        committed frames) or ``overwrite`` (remove the old dataset first); see :mod:`.dataset`
    Stopping early (``close()``, or dropping the iterator) keeps every frame already yielded, and commits no other.
    ``build=False`` scans the current scene as it is instead of building ``config.scene`` (the Blender
    panel's "my scene", or a built scene the user has edited since).

    With ``overlap`` and a core to spare (:func:`overlaps`), frame k's finishing stages (its boxes; :func:`finishing_start`)
    and its commit run on a thread while frame k + 1's first stages (Blender's build and export, the scan)
    run here; frame k is yielded once both are done, before frame k + 1's finishing stages start. Each frame
    is a function of its own generator and the run's config, so the bytes are the same either way. A
    frame's log lines (long stages, the builder's warnings, a skip, an empty frame) are said, in order,
    when it is done. An error in frame k + 1's first stages comes after frame k is committed and yielded.
    A stage's timing is its wall time, so beside another frame it holds the turns it waited for the
    interpreter; ``overlap=False`` runs every stage alone (the stage costs of ``benchmarks/bench_speed.py``).
    When no stage reads the frame's objects from Blender (:attr:`Stage.reads_blender`), a builder that gives its road
    users as arrays leaves them out of Blender until the run ends (``BuildContext.in_blender``): the same bytes.
    """
    output = config.output
    until_kept = output.skip_empty and output.frames_kept and (frames is None or list(frames) == list(range(config.frames)))  # a full run
    frames = range(config.frames) if frames is None else frames
    if until_kept:  # frame indices go on until `frames` frames are kept (at most MAX_INDICES_PER_KEPT per kept frame)
        frames = range(MAX_INDICES_PER_KEPT * config.frames)
    stages = plan(config)
    run = Run(config, build, log=log, in_blender=any(stage.reads_blender for stage in stages))
    cut = finishing_start(stages)
    first, finishing = stages[:cut], stages[cut:]

    def say(lines: list[str]) -> None:
        for line in lines if log is not None else ():
            log(line)

    def finish(frame: Frame, said: list[str]) -> bool:  # the finishing stages and the commit; False for a skipped frame
        run_stages(frame, run, finishing, said)
        said.extend(builder_warnings(frame))
        reason = empty_reason(frame, run) if output.skip_empty else None
        if reason is not None:
            dataset.skip(frame, reason)
            said.append(f"frame {frame.index}: skipped ({reason})")
            return False
        dataset.commit(frame, say=said.append)
        return True

    def done(pending: tuple[Frame, list[str], Future]) -> Iterator[Frame]:  # a frame's lines, then the frame unless skipped
        frame, said, future = pending
        try:
            kept = future.result()
        finally:
            say(said)
        if kept:
            yield frame

    try:
        beside_frames = ThreadPoolExecutor(1, "finishing") if overlap and overlaps(config, until_kept) else nullcontext()
        with Dataset.open(out_dir, config, mode, log=log) as dataset, beside_frames as beside:
            pending = None  # the frame whose finishing stages run beside this one's first
            for index in frames:
                if until_kept and sum(1 for r in dataset.committed.values() if not r.get("skipped")) >= config.frames:
                    break
                if dataset.has(index):
                    continue
                frame, said = Frame(index, config, frame_rng(config.seed, index)), []
                try:
                    run_stages(frame, run, first, said)
                except BaseException:
                    if pending is not None:  # the frame before is committed and yielded first, as without the thread
                        yield from done(pending)
                    say(said)
                    raise
                if pending is not None:
                    yield from done(pending)
                pending = (frame, said, beside.submit(finish, frame, said) if beside is not None else finished_now(finish, frame, said))
                if beside is None:
                    yield from done(pending)
                    pending = None
            else:
                if until_kept and log is not None:
                    log(
                        f"warning: output.frames_kept: {MAX_INDICES_PER_KEPT * config.frames} frame indices gave fewer than {config.frames} kept frames; "
                        f"the scene rarely holds {output.min_objects} labelled objects"
                    )
            if pending is not None:
                yield from done(pending)
    finally:  # Blender then holds the last frame's road users, as when each frame put them there
        if run.result.show is not None:
            run.result.show()


def finished_now(function: Callable, *args) -> Future:
    """``function(*args)`` called here and now, as a done :class:`~concurrent.futures.Future` (its result or its error)."""
    future: Future = Future()
    try:
        future.set_result(function(*args))
    except BaseException as err:  # re-raised by future.result()
        future.set_exception(err)
    return future


def generate(config: Config, out_dir: str | Path, log=print, build: bool = True, frames: Iterable[int] | None = None, mode: str = "new") -> None:
    """Generate the frames ``frames`` (default: all) of ``config`` into ``out_dir``, a line of ``log`` each."""
    for frame in run_frames(config, out_dir, build, frames, mode, log):  # None: all (output.frames_kept: until enough are kept)
        log(f"frame {frame.index + 1}/{config.frames}: {len(frame.points)} points, " + ", ".join(f"{k} {v:.2f} s" for k, v in frame.timings.items()))


def run(config: Config, out_dir: str | Path, log=print, build: bool = True, frames: Iterable[int] | None = None, mode: str = "new") -> dict:
    """:func:`generate`, then the manifest with its frames' records (read back from ``out_dir``)."""
    generate(config, out_dir, log, build, frames, mode)
    return read_dataset(out_dir)
