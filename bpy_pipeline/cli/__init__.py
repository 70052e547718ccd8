"""The command line: ``run`` here (run.py and ``bpy-pipeline run``) with what every subcommand shares (one-line
errors, exit codes), and one module per other subcommand (:mod:`.presets`, :mod:`.fit`, :mod:`.show_config`,
:mod:`.evaluate`, :mod:`.convert`, :mod:`.match`; :mod:`.tiles` runs alone); :mod:`.commands` dispatches
``bpy-pipeline <subcommand>``.

``run``: ``[--config FILE] [--out DIR] [--seed N] [--frames N] [--set key.path=value ...]`` plus the dataset
options: ``--frames-range A:B``, ``--shard i/n``, ``--resume``, ``--overwrite``, ``--workers N``,
``--ray auto|ADDRESS``, ``--threads N``. Works the same under ``python run.py ...`` and
``blender --background --python-exit-code 1 --python run.py -- ...`` (Blender's own arguments
come before ``--`` and are ignored). Bad input prints one line and exits with code 2.
"""

from __future__ import annotations

import argparse
import atexit
import gc
import os
import re
import shutil
import signal
import socket
import sys
import tempfile
import threading
from contextlib import contextmanager
from typing import NoReturn

from ..errors import InputError
from .subcommand import Command


def script_arguments(argv: list[str]) -> list[str]:
    """The arguments meant for the script: after ``--`` when present (Blender's layout), else argv[1:]."""
    return argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]


def add_run_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    p.add_argument("--config", help="YAML config file (default: the embedded railway scene)")
    p.add_argument("--out", default="out", help="output folder (default: ./out)")
    p.add_argument("--seed", type=int, help="run seed (overrides the config)")
    p.add_argument("--frames", type=int, help="number of frames of the run (overrides the config)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override one config key (repeatable)")
    p.add_argument("--frames-range", metavar="A:B", help="make only frames A .. B-1 of the run (same bytes as in the full run)")
    p.add_argument("--shard", metavar="I/N", help="make only the I-th of N equal contiguous parts of the run's frames (0-based)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true", help="continue the run in --out (same config and seed): keep its verified frames, make the rest")
    mode.add_argument("--overwrite", action="store_true", help="remove the run in --out first")
    p.add_argument("--join", action="store_true", help=argparse.SUPPRESS)  # a worker: add frames to the run another process holds
    p.add_argument("--parent-pipe", action="store_true", help=argparse.SUPPRESS)  # a worker: stop when stdin, its parent's pipe, ends
    p.add_argument("--workers", type=int, default=1, help="local worker processes, each with its own Blender (default 1)")
    p.add_argument("--ray", metavar="ADDRESS", help="send frame ranges to a Ray cluster: auto, or HOST:PORT (pip install .[distributed])")
    p.add_argument("--threads", type=int, help="ray-casting threads per process (default: the cores available, split between workers)")
    return p


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (``error: PROG: what; --help lists the options``), exit code 2."""

    def error(self, message: str):
        print(f"error: {self.prog}: {message}; --help lists the options", file=sys.stderr)
        sys.exit(2)


def parser() -> argparse.ArgumentParser:
    return add_run_arguments(OneLineParser(prog="run.py", description="Generate labeled LiDAR frames from a procedural Blender scene."))


def frame_selection(args, frames: int) -> range:
    """The frame indices ``--frames-range`` and ``--shard`` select of a run of ``frames`` frames, as a range
    (never a list: a run may have up to 10**9 frames)."""
    selected = range(frames)
    if args.frames_range:
        parts = args.frames_range.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            a, b = (int(v) if v.strip() else d for v, d in zip(parts, (0, frames)))
        except ValueError:
            raise InputError(f"--frames-range: expected A:B (frame indices, B excluded; no step), got {args.frames_range!r}") from None
        if not 0 <= a < b <= frames:
            raise InputError(f"--frames-range: expected 0 <= A < B <= {frames} (the run's frames), got {args.frames_range}")
        selected = selected[a:b]
    if args.shard:
        try:
            i, n = (int(v) for v in args.shard.split("/"))
        except ValueError:
            raise InputError(f"--shard: expected I/N (the I-th of N parts, 0-based), got {args.shard!r}") from None
        if not 0 <= i < n:
            raise InputError(f"--shard: expected 0 <= I < N, got {args.shard}")
        selected = shard_of(selected, i, n)
    return selected


def shard_of(frames: range, i: int, parts: int) -> range:
    """Part ``i`` of :func:`split` ``(frames, parts)`` without making the other parts."""
    size, extra = divmod(len(frames), parts)
    start = i * size + min(i, extra)
    return frames[start : start + size + (i < extra)]


def load_run_config(args):
    """The run's config from ``--config`` and the overrides, or from ``--out``'s manifest for a worker (``--join``)."""
    from ..config import config_from_dict, load_config

    if args.join:  # the run's config, on this worker's share of the cores (--threads shapes no byte: run_key leaves it out)
        from dataclasses import replace

        from ..io import read_manifest

        config = config_from_dict(read_manifest(args.out)["config"])
        return config if args.threads is None else replace(config, threads=args.threads)
    overrides = list(args.set)
    if args.seed is not None:
        overrides.append(f"seed={args.seed}")
    if args.frames is not None:
        overrides.append(f"frames={args.frames}")
    if args.threads is not None:
        overrides.append(f"threads={args.threads}")
    return load_config(args.config, overrides)


def progress(total: int, estimate=None):
    """A per-frame log function: a tqdm bar on a terminal (frames done, rate, ETA), else one line per frame.

    estimate : the run's :class:`~.estimate.Estimate`; its seconds per frame give the ETA until frames are
        measured (tqdm's own rate takes over from the first frame on); a line with it is logged first
    """
    if estimate is not None:
        print(f"note: {estimate.line()}", flush=True)  # stdout: stderr holds only warnings and the one error line
    if sys.stderr.isatty():
        try:
            from tqdm import tqdm
        except ImportError:
            tqdm = None
        if tqdm is not None:
            bar = tqdm(total=total, unit="frame", file=sys.stderr)
            atexit.register(bar.close)  # the bar's last state and its newline, also when exit_process ends the process
            if estimate is not None:
                bar.set_postfix_str(f"estimated {estimate.seconds:.0f} s")

            def log(text: str) -> None:
                if text.startswith("frame "):
                    bar.update(1)
                    bar.set_postfix_str(text.split(": ", 1)[-1][:60])
                else:
                    bar.write(text)

            return log
    return lambda text: print(text, file=sys.stderr if text.startswith(("warning", "note")) else sys.stdout, flush=True)


def run_main(args) -> int:
    """``run``: make the selected frames of the run into ``--out``; returns the exit code."""
    if not args.out.strip():
        raise InputError("--out: empty; give a folder (default: ./out)")
    if args.parent_pipe:
        from ..parallel import stop_with_parent

        stop_with_parent(sys.stdin.fileno())
    if not 1 <= args.workers <= MAX_WORKERS:
        raise InputError(f"--workers: must be 1 .. {MAX_WORKERS}, got {args.workers}")
    if args.overwrite and args.config:  # before any work: --overwrite never removes an input
        from ..dataset import refuse_inputs_inside

        refuse_inputs_inside(args.out, [args.config])
    config = load_run_config(args)
    frames = frame_selection(args, config.frames)
    mode = "join" if args.join else "resume" if args.resume else "overwrite" if args.overwrite else "new"
    from ..estimate import check_limits, estimate_run

    estimate = None if args.join else check_limits(estimate_run(config, len(frames)), config)  # before any work
    if args.ray:
        check_ray_address(args.ray)
    if args.workers > 1 or args.ray:
        from ..parallel import run_parallel

        return run_parallel(config, args.out, frames, mode, workers=args.workers, ray_address=args.ray, log=progress(len(frames), estimate))
    started = "bpy" not in sys.modules  # Blender starts in this process now (python run.py), not already running (blender --python)
    with stops_held(), start_noise_dropped():
        try:
            import bpy
        except ImportError:
            raise InputError(
                "bpy: Blender's Python module is not installed; pip install 'bpy==4.5.*' (Python 3.11), or run blender --background --python-exit-code 1 "
                "--python run.py -- ..."
            ) from None
        empty_file(bpy, started)
    from ..plan import generate

    if started:  # this process is the run's: the start's objects (modules, Blender's types, the config) stay to its end,
        gc.freeze()  # and no collection of the garbage collector walks them again
    generate(config, args.out, log=progress(len(frames), estimate), frames=frames, mode=mode)  # the CLI reads nothing back
    return 0


KEPT_DATA = ("scenes", "screens", "window_managers", "workspaces")  # what an empty file keeps of the startup file


def empty_file(bpy, started: bool) -> None:
    """Blender's data as ``bpy.ops.wm.read_factory_settings(use_empty=True)`` leaves it: the factory startup file with
    every data block but its scenes, screens, window managers and workspaces removed.

    started : Blender was started by this process just now. Its file is then the factory startup, untouched
        (``bpy.app.factory_startup``, no file loaded), and removing the data blocks is all of what reading the factory
        settings again would change that a run sees (under 1 ms instead of some 75 ms). Otherwise (``blender --python run.py``: a
        startup file or a .blend of the user's, settings changed) the factory settings are read.
    """
    if started and bpy.app.factory_startup and not bpy.data.filepath:
        # every data block once, by its address: Blender 5.x also lists them all together (``bpy.data.all_ids``)
        kept = {block.as_pointer() for name in KEPT_DATA for block in getattr(bpy.data, name)}
        kinds = [getattr(bpy.data, name) for name in dir(bpy.data)]
        removed = {block.as_pointer(): block for kind in kinds if isinstance(kind, bpy.types.bpy_prop_collection) for block in kind
                   if isinstance(block, bpy.types.ID) and block.as_pointer() not in kept}
        bpy.data.batch_remove(list(removed.values()))
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)


COMMAND = Command("run", "generate labeled frames (as run.py)", "Generate labeled LiDAR frames from a config.",
                  lambda p: add_run_arguments(p).set_defaults(func=run_main))
MAX_WORKERS = 256
RAY_CONNECT_TIMEOUT_S = 10.0  # --ray HOST:PORT: the head must answer within this


def check_ray_address(address: str, timeout: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """Refuse, within ``timeout`` seconds, a ``--ray HOST:PORT`` nobody answers at (Ray itself retries for ever)."""
    if address == "auto":
        return
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"--ray: expected auto or HOST:PORT (the head's address, port 1..65535), got {address!r}")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except (OSError, UnicodeError) as err:
        why = "no answer" if isinstance(err, TimeoutError) else (getattr(err, "strerror", None) or str(err) or type(err).__name__)
        raise InputError(f"--ray: no Ray head answers at {address} within {timeout:g} s ({why}); start one with `ray start --head --port={port}`") from None


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that the run unwinds as on Ctrl-C (frames kept, lock released)."""


def _terminate(signum, frame) -> None:
    raise Terminated()


STOPPED = {KeyboardInterrupt: ("interrupted", 130), Terminated: ("terminated (SIGTERM)", 143)}  # what stopped a run: its words, its exit code


@contextmanager
def stops_held():
    """Ctrl-C and SIGTERM held while Blender starts in this process (or reads its factory settings), then raised.

    Raised inside Blender's start, they land in its own startup scripts, which print the traceback and go on: the run
    went on to its last frame and exited 0. Here they are noted, and the first is raised when the block ends (as
    :class:`Terminated` or ``KeyboardInterrupt``). Only in the main thread, where Python runs signal handlers, and only
    a signal whose handler Python set: one a program set in C (a Blender's own SIGINT) could not be put back.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    held = [signum for signum in (signal.SIGTERM, signal.SIGINT) if signal.getsignal(signum) is not None]
    previous = {signum: signal.signal(signum, lambda signum, frame: caught.append(signum)) for signum in held}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if caught:
        raise Terminated() if caught[0] == signal.SIGTERM else KeyboardInterrupt()


BLENDER_START_NOISE = frozenset({
    "could not get a list of mounted file-systems",  # its file browser's volumes, where /etc/mtab is missing (containerd's Debian images)
})  # lines Blender's start writes to stderr that are no concern of a run


@contextmanager
def start_noise_dropped():
    """What is written to stderr (file descriptor 2, C's writes with Python's) while Blender starts in this process, said
    again when the block ends, but the lines of :data:`BLENDER_START_NOISE`: a run's bad input stays one line. Held in
    memory on Linux (no temporary folder needed: a container's root may be read-only); with nowhere to hold them, the
    lines go straight through."""
    try:
        written = open(os.memfd_create("blender start"), "w+b") if hasattr(os, "memfd_create") else tempfile.TemporaryFile()
    except OSError:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    with written:
        os.dup2(written.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            written.seek(0)
            for line in written.read().decode(errors="replace").splitlines():
                if line not in BLENDER_START_NOISE:
                    print(line, file=sys.stderr, flush=True)


def stopped_by(err: BaseException) -> type | None:
    """The :data:`STOPPED` kind ``err`` is, or was raised from (its ``__cause__`` chain): a signal that lands while a C
    extension runs Python (numba loading a cached kernel) comes back wrapped, as a ``SystemError`` whose cause is the
    handler's exception. An error raised while handling one (its ``__context__`` only) is another failure: not followed."""
    seen = set()
    while err is not None and id(err) not in seen:
        seen.add(id(err))
        kind = next((k for k in STOPPED if isinstance(err, k)), None)
        if kind is not None:
            return kind
        err = err.__cause__
    return None


def guarded(func, args) -> int:
    """``func(args)`` with bad input, Ctrl-C and SIGTERM turned into one line and an exit code (2, 130, 143)."""
    try:
        previous = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:  # not the main thread
        previous = None
    try:
        return func(args)
    except InputError as err:
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code
    except BaseException as err:
        kind = stopped_by(err)
        if kind is None:
            raise
        words, code = STOPPED[kind]
        if not getattr(args, "parent_pipe", False):  # a worker's run says it (parallel.run_parallel), once
            print(f"{words}: every frame written so far is committed; --resume continues the run", file=sys.stderr)
        return code
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


STANDARD_STREAMS = ((0, "stdin", "r"), (1, "stdout", "w"), (2, "stderr", "w"))  # file descriptor, sys attribute, mode


def standard_streams_open() -> None:
    """A standard stream the process was started without (``2>&-``) opened on the null device, before any file is.

    Otherwise the first file the run opens (its lock, a frame's PLY) takes the closed stream's number, and what Blender
    or a library writes to stderr lands in the user's data. Python then has no ``sys.stderr`` (``None``): it gets one
    on the null device too, so the run's own lines go where the user sent them, nowhere.
    """
    for fd, name, mode in STANDARD_STREAMS:
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)  # the lowest free number: fd itself when the lower ones are open
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, mode, closefd=False))


def main(argv: list[str] | None = None) -> int:
    """Run the pipeline; returns the process exit code (2 on bad input, 130 on Ctrl-C, 143 on SIGTERM)."""
    standard_streams_open()
    args = parser().parse_args(script_arguments(sys.argv if argv is None else argv))
    return guarded(run_main, args)


SESSION_FOLDER = re.compile(r"blender_[A-Za-z0-9]{6}")  # the name mkdtemp gives Blender's session folder (blender_XXXXXX)


def remove_blender_session_folder(bpy) -> None:
    """Remove the folder the bpy module made for this process at its import (``bpy.app.tempdir``: ``blender_`` and six
    letters or digits, made by ``mkdtemp`` in ``$TMPDIR`` or ``/tmp``), as Blender's own teardown does; without it every
    run would leave one behind. Nothing for ``bpy`` ``None`` (not imported), a module without that folder, a folder of
    another name, or the temporary folder itself: where Blender cannot make its own, ``tempdir`` is the one it was given."""
    folder = os.path.normpath(getattr(getattr(bpy, "app", None), "tempdir", "") or ".")
    given = {os.path.normpath(base) for base in (os.environ.get("TMPDIR"), os.environ.get("TMP"), os.environ.get("TEMP"), "/tmp") if base}
    if SESSION_FOLDER.fullmatch(os.path.basename(folder)) and folder not in given:
        shutil.rmtree(folder, ignore_errors=True)


def exit_process(code: int) -> NoReturn:
    """End the process with exit ``code``, skipping the interpreter's and Blender's teardown.

    After a run, that teardown frees every object, module and Blender's data one by one: 0.3-0.5 s
    (docs/performance.md), and nothing of it reaches the disk. What a normal exit does
    that matters is done first: other threads are waited for, the ``atexit`` handlers run (a progress
    bar's last line, temporary folders), the bpy module's session folder is removed (:func:`remove_blender_session_folder`),
    and both output streams are flushed. Inside Blender's own executable (``blender --python run.py``) Blender ends itself:
    a plain ``sys.exit``.
    """
    bpy = sys.modules.get("bpy")
    if bpy is not None and bpy.app.binary_path:  # the bpy module has none
        sys.exit(code)
    # the first two steps of the interpreter's own exit (Py_FinalizeEx), in its order: thread pools told to
    # stop and every other thread waited for, then the atexit handlers
    threading._shutdown()
    atexit._run_exitfuncs()
    remove_blender_session_folder(bpy)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):  # no stream, a closed pipe or stream: what a normal exit would have lost too
            pass
    os._exit(code)
