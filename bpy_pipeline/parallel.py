"""Frames in several processes: local workers (``--workers N``) and a Ray cluster (``--ray ADDRESS``).

The parent opens the dataset (lock, clean-up, manifest) and closes it (indexes, summary); workers
join it and commit frames with the same atomic protocol (:mod:`.dataset`), each from its own
Blender. Frames are handed out in contiguous ranges aligned to the scenes they share (a railway's
stations), and every frame is a pure function of (config, seed, index), so the bytes do not depend
on the worker count. Each worker runs one BLAS thread and its share of the ray-casting threads, so
the machine is not oversubscribed.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
from dataclasses import replace
from pathlib import Path
from typing import Callable

from .config import Config
from .dataset import Dataset
from .errors import InputError
from .lidar.cast.raycast import default_threads

SINGLE_THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
ROOT = Path(__file__).resolve().parents[1]


def split(frames: list, parts: int) -> list[list]:
    """``frames`` in ``parts`` contiguous runs of nearly equal length (the first ones one longer)."""
    size, extra = divmod(len(frames), parts)
    out, start = [], 0
    for k in range(parts):
        end = start + size + (k < extra)
        out.append(frames[start:end])
        start = end
    return out


def aligned_ranges(frames: list[int], parts: int, per_scene: int) -> list[list[int]]:
    """``frames`` in at most ``parts`` contiguous runs that do not cut a scene's frames apart."""
    groups: list[list[int]] = []
    for f in frames:
        if groups and f // per_scene == groups[-1][-1] // per_scene and f == groups[-1][-1] + 1:
            groups[-1].append(f)
        else:
            groups.append([f])
    return [sum(chunk, []) for chunk in split(groups, min(parts, len(groups))) if chunk]


def worker_command(out: str, frames: list[int], threads: int) -> list[str]:
    """The command of a worker making ``frames`` (a contiguous run) into ``out``: Blender's own binary when
    this process is a Blender, else this Python with the bpy module.

    A Blender has loaded bpy before any script runs, so bpy is only looked up: importing it here would start a
    Blender in this process (0.3-0.5 s of a core) only to learn it is not one, before the first worker starts.
    """
    args = ["--out", str(out), "--join", "--frames-range", f"{frames[0]}:{frames[-1] + 1}", "--threads", str(threads), "--parent-pipe"]
    bpy = sys.modules.get("bpy")
    binary = bpy.app.binary_path if bpy is not None else ""
    if binary and Path(binary).name.startswith("blender"):
        return [binary, "--background", "--factory-startup", "--python-exit-code", "1", "--python", str(ROOT / "run.py"), "--", *args]
    return [sys.executable, "-m", "bpy_pipeline", "run", *args]


def run_parallel(config: Config, out: str, frames: list[int], mode: str, workers: int = 1, ray_address: str | None = None,
                 log: Callable[[str], None] = print) -> int:
    """Make ``frames`` of ``config`` into ``out`` with ``workers`` local processes or on the Ray cluster at
    ``ray_address``; returns the exit code (0 when every frame is committed)."""
    from .stages.view import frames_per_scene

    with Dataset.open(out, config, mode, log=log) as dataset:
        todo = [f for f in frames if not dataset.has(f)]
        if not todo:
            return 0
        if ray_address:
            return _run_on_ray(out, todo, ray_address, frames_per_scene(config), log)
        ranges = aligned_ranges(todo, workers, frames_per_scene(config))
        threads = max(1, (config.threads or default_threads()) // len(ranges))
        env = {**os.environ, **SINGLE_THREAD_ENV}
        # each worker's stdin: a pipe this process holds open until it ends, however it ends (stop_with_parent);
        # its stdout and stderr: pipes whose lines this process says in its own log (forward_lines)
        procs = [subprocess.Popen(worker_command(out, r, threads), env=env, cwd=os.getcwd(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True, errors="replace") for r in ranges]
        errors: list[str] = []
        readers = forward_lines(procs, log, errors)
        try:
            codes = [p.wait() for p in procs]
        except BaseException:  # Ctrl-C or SIGTERM: the workers stop too (each keeps its committed frames)
            for p in procs:
                p.terminate()
            for p in procs:
                p.wait()
            raise
        finally:
            for p in procs:
                p.stdin.close()
            for reader in readers:
                reader.join()
        if errors and all(c == 2 for c in codes if c):  # bad input a worker found: said once, exit 2; with no frame made, nothing left
            raise InputError(errors[0].removeprefix("error: "))
    failed = [f"{r[0]}:{r[-1] + 1} (exit {c})" for r, c in zip(ranges, codes) if c != 0]
    for line in dict.fromkeys(errors):
        print(line, file=sys.stderr, flush=True)
    if failed:
        log(f"warning: workers failed for frames {', '.join(failed)}; their committed frames are kept, --resume makes the rest")
        return 2 if all(c == 2 for c in codes if c) else 1
    return 0


def forward_lines(procs: list[subprocess.Popen], log: Callable[[str], None], errors: list[str]) -> list[threading.Thread]:
    """Say every line the workers ``procs`` print in this process's ``log``, one line at a time, as they come.

    A worker's frame lines (its stdout) drive the run's one progress bar, or its one line a frame, instead of a bar
    per worker on one terminal line; its warnings and notes go where this process's go; its error lines
    (``error: ...``) are appended to ``errors``, for the caller to say once; anything else it prints to stderr (a
    traceback) goes to this process's stderr. (A worker says no stop line on Ctrl-C or SIGTERM: this process says its
    own, or a warning naming the worker's exit code.) One thread a stream: a worker whose pipe were not read would
    stop at a full pipe.
    """
    lock = threading.Lock()

    def say_err(text: str) -> None:
        if text.startswith(("warning", "note")):
            log(text)
        elif text.startswith("error: "):
            errors.append(text)
        else:
            print(text, file=sys.stderr, flush=True)

    def forward(stream, say: Callable[[str], None]) -> None:
        for line in stream:
            with lock:
                say(line.rstrip("\n"))
        stream.close()

    readers = [threading.Thread(target=forward, args=(stream, say), name="worker lines", daemon=True)
               for p in procs for stream, say in ((p.stdout, log), (p.stderr, say_err))]
    for reader in readers:
        reader.start()
    return readers


def stop_with_parent(pipe: int) -> threading.Thread:
    """Stop this worker as SIGTERM stops a run (its committed frames kept, one line, exit 143) once ``pipe`` ends.

    ``pipe`` is the file descriptor of the worker's stdin, which its parent (:func:`run_parallel`) holds open while the
    run goes: it ends when the parent ends, however (Ctrl-C, a crash, kill -9, the out-of-memory killer). Without this,
    a worker whose parent was killed goes on committing frames, with no lock held, into a folder that the next run may
    resume or overwrite with another config. Read with ``os.read``, not through ``sys.stdin``, whose lock this
    thread would hold at the interpreter's shutdown (a fatal error inside Blender, which shuts the interpreter down).
    """

    def watch() -> None:
        while os.read(pipe, 4096):  # b"" at the pipe's end only: the parent never writes to it
            pass
        os.kill(os.getpid(), signal.SIGTERM)

    thread = threading.Thread(target=watch, name="parent pipe", daemon=True)
    thread.start()
    return thread


def _frames_task(out: str, frames: list[int], threads: int) -> str | None:
    """A Ray task: make ``frames`` into ``out`` (joining the run) in this worker's own Blender.

    Returns None, or the one line of the bad input that stopped it: returned, not raised, so that Ray does not run
    the task again for an input that stays bad, and the run says it once."""
    os.environ.update(SINGLE_THREAD_ENV)
    import bpy

    from .config import config_from_dict
    from .io import read_manifest
    from .plan import run_frames

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = replace(config_from_dict(read_manifest(out)["config"]), threads=threads)
    try:
        for _ in run_frames(config, out, frames=frames, mode="join"):
            pass
    except InputError as err:
        return str(err)
    return None


def _run_on_ray(out: str, frames: list[int], address: str, per_scene: int, log: Callable[[str], None]) -> int:
    """Frame ranges as Ray tasks (retried on failure); every task commits its frames itself. Bad input a task met is
    raised once, as :class:`InputError`, after every task has ended."""
    try:
        import ray
    except ImportError:
        raise InputError("--ray: Ray is not installed; pip install '.[distributed]'") from None
    try:
        ray.init(address=address, log_to_driver=False, include_dashboard=False, runtime_env={"env_vars": SINGLE_THREAD_ENV},
                 logging_level=logging.WARNING)  # not Ray's INFO lines about connecting: the run's own say what happens
    except (ConnectionError, RuntimeError, ValueError) as err:
        raise InputError(f"--ray: cannot connect to a Ray cluster at {address} ({str(err).splitlines()[0]}); start one with `ray start --head`") from None
    try:
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        task = ray.remote(num_cpus=1, max_retries=3, retry_exceptions=True)(_frames_task)
        ranges = aligned_ranges(frames, 4 * cpus, per_scene)
        pending = {task.remote(str(Path(out).resolve()), r, 1): r for r in ranges}
        failed, bad_input = [], []
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            r = pending.pop(done[0])
            try:
                error = ray.get(done[0])
            except Exception as err:  # a task that failed after its retries
                failed.append(f"{r[0]}:{r[-1] + 1} ({type(err).__name__})")
                continue
            if error is None:
                log(f"frames {r[0]}..{r[-1]} done on the cluster")
            else:
                bad_input.append(error)
    finally:
        ray.shutdown()
    if bad_input:
        raise InputError(bad_input[0])
    if failed:
        log(f"warning: Ray tasks failed for frames {', '.join(failed)}; --resume makes the rest")
        return 1
    return 0
