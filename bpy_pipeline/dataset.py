"""The output folder as a dataset: atomic frames, one record per frame, a lock, resume and overwrite.

Layout of ``OUT``::

    manifest.json          the run: config, seed, versions, sensor, class table; written once when
                           the run starts, and its ``summary`` once when it ends
    records/NNNNNN.json    one record per committed frame: its files with sha256, points, pose,
                           timings, objects, boxes. A frame is part of the dataset iff its record exists
    <format folders>       the frames' files (ply/, sequences/, kitti/, ...)
    .lock                  {"pid", "host", "started"} of the run writing the folder
    .staging/              frames being written (removed on the next start)
    .moving/NNNNNN.json    the files of a frame being moved into place (removed once its record exists)

Committing a frame: every file is written under ``.staging/NNNNNN/``; the list of its files goes
to ``.moving/NNNNNN.json``; the files are renamed into place; then ``records/NNNNNN.json`` is
created by an atomic rename (the commit mark) and the intent is removed. A kill at any point
leaves either a committed frame or files that the next start removes (those named by a leftover
intent whose frame has no record). Records are one file per frame, not lines of one log, because
worker processes and machines commit frames at once: a rename is atomic on every file system,
an append is not on network ones. Per-dataset indexes (ImageSets) are derived from the records
when a run ends. A run's cost per frame does not grow with the number of frames.

Per frame, nothing is read back and no folder is made or removed: files written through
:func:`~.io.atomic.hashed_open` get their sha256 as they are written (small text files are read
back), the preview is rendered and written on a thread of its own while the other files are
written (:func:`write_frame_files`, waited for before the intent), and a committed frame's emptied
staging folders are renamed to the next frame's. A committed frame's files start on their way to disk,
and leave the page cache at the next commit (:class:`~.io.page_cache.PageCacheRelease`).
"""

from __future__ import annotations

import contextvars
import datetime
import errno
import fcntl
import hashlib
import json
import os
import shutil
import socket
import time
from concurrent.futures import Executor, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .config import Config, config_to_dict
from .errors import InputError
from .io.atomic import atomic_write, digests_while_writing, temporary_files
from .io.confined import inside, readable_inside
from .io.manifest import MANIFEST_NAME, read_manifest, to_json, write_manifest
from .io.page_cache import PageCacheRelease
from .io.writers import WRITERS, frame_writers
from .lidar.cast.raycast import default_threads

DATASET_FORMAT = "bpy_pipeline dataset"
DATASET_VERSION = 2
RECORDS, STAGING, MOVING, LOCK = "records", ".staging", ".moving", ".lock"
MODES = ("new", "resume", "overwrite", "join")
MAX_RECORD_BYTES = 64 << 20  # an intent or a frame record larger than this is not one
MAX_FRAME_FILE_BYTES = 1 << 40  # a frame's file larger than this is not one (nor is a device or a FIFO)
BYTES_PER_POINT = 64  # on disk per point and format, a generous estimate (PLY: 35, LAS: 46, SemanticKITTI: 20)


def run_key(config: Config) -> str:
    """sha256 of everything that shapes a frame's bytes: the resolved config but its frame count."""
    data = config_to_dict(config)
    data.pop("frames", None)
    data.pop("threads", None)
    data.pop("limits", None)  # bounds on the work, never on a frame's bytes
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=to_json).encode()).hexdigest()


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


# Writers' ``beside`` parts go on threads only with a core to spare: one process on every core (config.threads 0 or
# above 1), where 80 parking frames ran at 0.97 of the inline wall time with the preview's thread (0.86-1.00, 5
# alternating pairs; docs/performance.md). A worker of --workers runs on its share of the cores, often
# one, where a thread only adds GIL hand-overs. The KITTI layout's labels and projections stay on the caller's
# thread: Python-heavy, they held the GIL against the other writes; its image goes beside.


def write_frame_files(frame, staging: Path, names: list[str], pool: Executor | None = None) -> list[Path]:
    """Every writer of ``names`` writes ``frame`` under ``staging``; their files in the order of ``names``, each
    writer's ``write`` files, then its ``beside`` files.

    With ``pool`` (:meth:`Dataset.commit` gives its own where the process has more than one thread) and more than
    one writer, each writer's ``beside`` part (the preview, the KITTI layout's image: numpy, compiled passes and zlib,
    which let go of the interpreter) runs on the pool while the ``write`` parts run here, in the caller's context (its
    :func:`~.io.atomic.digests_while_writing`, which the pool's tasks run in too); all are waited for before this
    returns or raises, so nothing writes under ``staging`` afterwards. Otherwise each runs here after its writer's
    ``write``. A failure of the ``write`` parts is raised first, then the ``beside`` parts' in the order of ``names``.
    """
    writers = {name: WRITERS.get(name) for name in names}
    beside = pool if len(names) > 1 else None
    results: dict[str, list[Path]] = {}
    besides: dict[str, list[Path]] = {}
    failed: dict[str, BaseException] = {}

    def background(name: str):
        try:
            besides[name] = writers[name].beside(frame, staging)
        except BaseException as err:  # re-raised by the caller's thread
            failed[name] = err

    later = [name for name in names if writers[name].beside is not None]
    running = [beside.submit(contextvars.copy_context().run, background, name) for name in later] if beside is not None else []
    try:
        for name in names:
            results[name] = writers[name].write(frame, staging)
            if beside is None and name in later:
                besides[name] = writers[name].beside(frame, staging)
    finally:
        wait(running)
        frame.shared.clear()  # what the writers shared (Frame.shared), no longer needed
    for name in later:
        if name in failed:
            raise failed[name]
    return [path for name in names for path in results[name] + besides.get(name, [])]


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _error(path: Path, doing: str, err: OSError) -> InputError:
    """The one line of a failed write: a full disk said as such (numpy's short writes carry no errno)."""
    try:
        full = err.errno == errno.ENOSPC or shutil.disk_usage(path if path.exists() else path.parent).free < (1 << 20)
    except OSError:
        full = False
    if full:
        return InputError(f"--out: no space left on the device holding {path} (trying to {doing} it); the frames committed so far are kept, --resume continues")
    return InputError(f"--out: cannot {doing} {path} ({err.strerror or err})")


# ---------------------------------------------------------------------------- the lock
LOCK_TRIES = 20  # attempts to take a lock that keeps changing under us before giving up
GARBAGE_LOCK_AGE_S = 60.0  # an unreadable lock file nobody holds is taken over once this old


def _holder(path: Path) -> dict | None:
    """The lock file's JSON (``None`` when empty, unreadable or not a mapping)."""
    try:
        holder = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError):
        return None
    return holder if isinstance(holder, dict) else None


def _same_file(fd: int, path: Path) -> bool:
    try:
        a, b = os.fstat(fd), os.stat(path)
    except FileNotFoundError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _flock(fd: int, path: Path) -> bool:
    """Try an exclusive ``flock`` without waiting: True when taken, False when another process holds it."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as err:
        raise InputError(f"--out: {path}: the file system does not support file locks ({err.strerror or err}); write to a local or NFSv4 folder") from None
    return True


def take_lock(path: Path, say: Callable[[str], None] = lambda text: None) -> int:
    """Take the run lock ``path``; returns the open file descriptor that holds it (keep it open for the run).

    The lock is the file's ``flock``, held for the whole run and dropped by the kernel when the process dies;
    the file's JSON (``pid``, ``host``, ``started``) only says who holds it. A new lock is written in full to a
    private file and flock-ed before :func:`os.link` makes it visible, so no reader sees it empty. A lock file
    whose flock is free is stale: it is replaced by an atomic rename of our own file over it *while we hold
    its flock*, and whoever takes a flock re-checks that the file is still the one at ``path``; so two
    processes taking over the same stale lock cannot both win. Refused (one line) when its flock is held,
    when it names a live pid on this host (a run that does not flock), when it names another host (whose
    flock this file system may not share), and when it is empty or unreadable but younger than
    :data:`GARBAGE_LOCK_AGE_S`.
    """
    me = {"pid": os.getpid(), "host": socket.gethostname(), "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
    mine = path.with_name(f"{path.name}.tmp-{os.getpid()}-{os.urandom(4).hex()}")
    try:
        fd = os.open(mine, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
    except OSError as err:
        raise _error(path, "create the lock file", err) from None
    try:
        os.write(fd, json.dumps(me).encode())
        os.fsync(fd)
        _flock(fd, path)  # ours alone: nobody else knows the file
        for _ in range(LOCK_TRIES):
            try:
                os.link(mine, path)  # atomic: fails when a lock exists
                return fd
            except FileExistsError:
                pass
            except OSError as err:
                raise _error(path, "create the lock file", err) from None
            try:
                old = os.open(path, os.O_RDONLY)
            except FileNotFoundError:
                continue  # released meanwhile: try again
            try:
                if not _flock(old, path):
                    holder = _holder(path) or {}
                    raise InputError(
                        f"--out: {path.parent} is being written by pid {holder.get('pid', '?')} on {holder.get('host', '?')} (since "
                        f"{holder.get('started', '?')}); wait for it, or stop that run"
                    )
                if not _same_file(old, path):
                    continue  # replaced or removed since we opened it: look again
                holder = _holder(path)
                if holder is None:
                    age = time.time() - os.fstat(old).st_mtime
                    if age < GARBAGE_LOCK_AGE_S:
                        raise InputError(
                            f"--out: {path} is empty or unreadable and nobody holds it ({age:.0f} s old; taken over from {GARBAGE_LOCK_AGE_S:.0f} s on); "
                            f"remove {path} if no run writes {path.parent}"
                        )
                    say(f"warning: {path.parent}: taking over an unreadable lock nobody holds ({age:.0f} s old)")
                elif holder.get("host") != me["host"]:
                    raise InputError(
                        f"--out: {path.parent} is locked by pid {holder.get('pid', '?')} on {holder.get('host', '?')} (since {holder.get('started', '?')}); "
                        f"this host cannot tell whether that run lives: remove {path} if it is dead"
                    )
                elif isinstance(holder.get("pid"), int) and holder["pid"] != me["pid"] and _pid_alive(holder["pid"]):
                    raise InputError(
                        f"--out: {path.parent} is locked by the live pid {holder['pid']} on this host (since {holder.get('started', '?')}), which holds no "
                        f"file lock; stop it, or remove {path} if it is not a bpy_pipeline run"
                    )
                else:
                    say(f"warning: {path.parent}: taking over the lock of a run that ended without releasing it (pid {holder.get('pid', '?')})")
                try:
                    os.rename(mine, path)  # atomic, under the old lock's flock: a late taker finds another file at path
                except OSError as err:
                    raise _error(path, "replace the stale lock file", err) from None
                return fd
            finally:
                os.close(old)
        raise InputError(f"--out: {path} kept changing while {LOCK_TRIES} attempts tried to take it; another process is starting on {path.parent}")
    except BaseException:
        os.close(fd)
        raise
    finally:
        mine.unlink(missing_ok=True)  # linked (or renamed) into place, or not needed


def release_lock(path: Path, fd: int) -> None:
    """Remove the lock file ``path`` if it is still the one ``fd`` holds, then drop the flock."""
    try:
        if fd >= 0 and _same_file(fd, path):
            path.unlink(missing_ok=True)
    finally:
        if fd >= 0:
            os.close(fd)


@dataclass
class Dataset:
    """An output folder opened for writing frames (see the module docstring); use :meth:`open` as a context manager.

    out : the folder; config : the run's config; mode : how it was opened (:data:`MODES`)
    committed : {frame index: record} of the frames in the dataset
    """

    out: Path
    config: Config
    mode: str = "new"
    log: Callable[[str], None] | None = None
    committed: dict[int, dict] = field(default_factory=dict)
    locked: bool = False
    lock_fd: int = -1  # the open, flock-ed lock file while locked
    created: bool = False  # the folder did not exist before this run
    _spare: Path | None = field(default=None, repr=False)  # the last committed frame's staging folders, emptied (reused by the next)
    _beside: ThreadPoolExecutor | None = field(default=None, repr=False)  # the writers' beside parts' threads (made by the first commit using them)
    _page_cache: PageCacheRelease = field(default_factory=PageCacheRelease, repr=False)  # the committed frames' pages, handed back a frame later

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, out: str | os.PathLike, config: Config, mode: str = "new", log: Callable[[str], None] | None = None, inputs=()) -> "Dataset":
        """Open ``out`` for ``config``.

        mode : ``new`` refuses a folder that holds a run; ``resume`` continues a run of the same config
            and seed (committed frames whose files still match their sha256 are kept, the rest redone);
            ``overwrite`` removes the old dataset first; ``join`` adds frames to a run another process
            holds the lock of (workers: same config and seed, no lock, no clean-up)
        inputs : paths the run reads beyond its config's (the config file, label files); ``overwrite`` refuses
            when one of them, or a file the config names, lies inside ``out``
        Raises :class:`InputError` (exit 2) for a folder it cannot or must not write.
        """
        if mode not in MODES:
            raise ValueError(f"Dataset.open: mode must be one of {MODES}, got {mode!r}")
        out = Path(out)
        if out.exists() and not out.is_dir():
            raise InputError(f"--out: {out} exists and is not a folder")
        if mode == "overwrite":
            refuse_inputs_inside(out, [*inputs, *input_paths(config)])
        dataset = cls(out, config, mode, log, created=not out.exists())
        if mode == "join":
            dataset._check_same_run(read_manifest(out))
            dataset.committed = dataset._read_records()
            return dataset
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise _error(out, "create the folder", err) from None
        check_writable(out, config)
        dataset._lock()
        try:
            dataset._prepare()
        except BaseException:
            dataset._unlock()
            raise
        return dataset

    def _lock(self) -> None:
        """Take ``OUT/.lock`` for this run, or refuse with one line (see :func:`take_lock`)."""
        self.lock_fd = take_lock(self.out / LOCK, self._say)
        self.locked = True

    def _unlock(self) -> None:
        if self.locked:
            release_lock(self.out / LOCK, self.lock_fd)
            self.lock_fd, self.locked = -1, False

    def _prepare(self) -> None:
        """Refuse, resume or overwrite an existing run; clean up what a killed run left; write the manifest."""
        for name in (RECORDS, MOVING, STAGING):  # the run's own folders: removed from and written into, never through a link
            if (self.out / name).is_symlink() or ((self.out / name).exists() and not (self.out / name).is_dir()):
                raise InputError(
                    f"--out: {self.out / name} is a link or a file, not the run's own folder; remove it or give another --out (nothing was removed)"
                )
        manifest_path = self.out / MANIFEST_NAME
        old = read_manifest(self.out) if manifest_path.exists() else None
        if old is not None and self.mode in ("new", "resume") and not is_our_manifest(old):
            raise InputError(f"--out: {manifest_path} is not a bpy_pipeline run's manifest; give another --out (nothing there is touched)")
        if old is not None and self.mode == "new":
            frames = len(list((self.out / RECORDS).glob("*.json")))
            if old.get("format") == DATASET_FORMAT and old.get("run_key") == run_key(self.config):  # another part of the same run (a --shard)
                raise InputError(f"--out: {self.out} holds {frames} frames of this run (same config and seed); give --resume to add the frames "
                                 "asked for to them or --overwrite to start it again")
            what = f"seed {old.get('seed')}, {frames} frames" if old.get("format") == DATASET_FORMAT else "an earlier version's output"
            raise InputError(f"--out: {self.out} holds another run ({what}); give --resume to continue it (same config and seed) or --overwrite to replace it")
        if old is not None and self.mode == "overwrite":
            self._remove_old(old)
            old = None
        self._clean_partial_frames()
        if old is not None:  # resume
            self._check_same_run(old)
            had = (old.get("config") or {}).get("frames")
            if isinstance(had, int) and self.config.frames < had:  # a resume may extend a run, never shrink it
                raise InputError(
                    f"--resume: {self.out} holds a run of {had} frames, this config has frames: {self.config.frames}; give --frames {had} or more (more "
                    "extends the run), or --overwrite"
                )
            self.committed = self._verified(self._read_records())
            manifest = {**old, "config": config_to_dict(self.config)}  # the frame count may have grown
        else:
            manifest = self._new_manifest()
        manifest.pop("summary", None)
        write_manifest(self.out, manifest)

    def _new_manifest(self) -> dict:
        from .lidar.sensor.sensors import spec_summary
        from .frame import versions

        # relative: inside Blender the package is bl_ext.<repo>.<id>.bpy_pipeline
        return {
            "format": DATASET_FORMAT,
            "version": DATASET_VERSION,
            "config": config_to_dict(self.config),
            "seed": self.config.seed,
            "run_key": run_key(self.config),
            "versions": versions(),
            "sensor": spec_summary(self.config.sensor.spec),
            "class_table": {int(k): v for k, v in __import__(f"{__package__}.labels", fromlist=["x"]).load_class_table().names.items()},
        }

    def _check_same_run(self, manifest: dict) -> None:
        if manifest.get("format") != DATASET_FORMAT:
            raise InputError(f"--resume: {self.out} holds an earlier version's output, which cannot be resumed; give --overwrite to replace it")
        if manifest.get("run_key") != run_key(self.config):
            old = manifest.get("config") or {}
            new = config_to_dict(self.config)
            keys = [k for k in sorted(set(old) | set(new)) if k not in ("frames", "threads", "limits") and old.get(k) != new.get(k)]
            raise InputError(
                f"--resume: {self.out} holds a run with another config or seed (differs in: {', '.join(keys) or 'versions'}); give --overwrite to replace it"
            )

    def _remove_old(self, manifest: dict) -> None:
        """Remove the old run: the files its records, intents and manifest name (confined to ``OUT``), its records,
        intents, staging folder and manifest, and the folders that leaves empty. Nothing else is touched: a file
        the run did not write stays. Every file is checked deletable first; one that is not refuses the overwrite
        with the old run whole."""
        if not is_our_manifest(manifest):
            raise InputError(
                f"--overwrite: {self.out / MANIFEST_NAME} is not a bpy_pipeline run's manifest; refusing to remove anything from {self.out}: give another --out"
            )
        files = self._files_of_run(manifest)
        for path in files:
            why = undeletable(path)
            if why:
                raise InputError(f"--overwrite: cannot remove {path} ({why}); nothing was removed, the old run in {self.out} is whole")
        folders = set()
        for path in files:
            try:
                path.unlink(missing_ok=True)
            except OSError as err:
                raise _error(path, "remove", err) from None
            folders.update(p for p in path.parents if self.out in p.parents)
        shutil.rmtree(self.out / STAGING, ignore_errors=True)
        for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):  # deepest first: the folders left empty go
            if folder.is_dir() and not folder.is_symlink():
                for below, _, _ in os.walk(folder, topdown=False):  # links are not followed
                    _rmdir_if_empty(Path(below))

    def _files_of_run(self, manifest: dict) -> list[Path]:
        """Every existing file the run in ``OUT`` wrote, by its manifest, records and intents (names confined to ``OUT``)."""
        own = [MANIFEST_NAME, *[f"{RECORDS}/{p.name}" for p in (self.out / RECORDS).glob("[0-9]*.json")],
               *[f"{MOVING}/{p.name}" for p in (self.out / MOVING).glob("[0-9]*.json")]]
        own += [str(p.relative_to(self.out)) for folder in (self.out / MOVING, self.out / RECORDS, self.out) for p in temporary_files(folder)]
        listed = [name for name in manifest.get("indexes") or [] if isinstance(name, str)]
        for frame in manifest.get("frames") or []:  # an earlier version's manifest listed its frames
            listed += [name for name in (frame.get("files") or []) if isinstance(name, str)] if isinstance(frame, dict) else []
        for name in own[1:]:
            listed += [rel for rel in _listed_files(self.out / name) if self._of_frame(self.out / name, rel)]
        files = []
        for name in own + listed:
            path = inside(self.out, name)
            if path is None:
                self._say(f"warning: {self.out}: the old run names {name!r}, which is not inside the folder; left alone")
            elif path.is_symlink() or path.is_file():
                files.append(path)
        return sorted(set(files))

    def _clean_partial_frames(self) -> None:
        """Remove staged frames, the moved files of frames that never got their record, and the temporary files of
        writes a kill cut short beside the intents, the records and the manifest (:func:`~.io.atomic.atomic_write`'s
        ``.<name>.<hex>.tmp``: only this run, holding the lock, writes there)."""
        shutil.rmtree(self.out / STAGING, ignore_errors=True)
        for folder in (self.out / MOVING, self.out / RECORDS, self.out):
            for leftover in temporary_files(folder):
                leftover.unlink(missing_ok=True)
        for intent in sorted((self.out / MOVING).glob("*.json")):
            if not (self.out / RECORDS / intent.name).exists():
                for rel in _listed_files(intent):
                    if not self._of_frame(intent, rel):
                        continue
                    path = inside(self.out, rel)
                    if path is None or (path.is_dir() and not path.is_symlink()):
                        self._say(f"warning: {intent}: {rel!r} is not a file inside {self.out}; left alone")
                        continue
                    path.unlink(missing_ok=True)
                self._say(f"warning: {self.out}: removed the files of frame {intent.stem}, which a killed run left without its record")
            intent.unlink()

    def _of_frame(self, listing: Path, name: str) -> bool:
        """True when ``name``, listed by the intent or record ``listing`` (``NNNNNN.json``), can be a file of that
        frame: every writer names a frame's files by its stem. Otherwise one warning, and the name is left alone."""
        if listing.stem in name:
            return True
        self._say(f"warning: {listing}: {name!r} is not a file of frame {listing.stem}; left alone")
        return False

    def _read_records(self) -> dict[int, dict]:
        records = {}
        for path in sorted((self.out / RECORDS).glob("*.json")):
            try:
                if readable_inside(path.parent, path.name, MAX_RECORD_BYTES)[0] is None:
                    raise ValueError("not a regular file of a record's size")
                record = json.loads(path.read_text())
                records[int(record["index"])] = record
            except (OSError, ValueError, KeyError, TypeError, RecursionError):
                self._say(f"warning: {path}: unreadable frame record, the frame is made again")
                if not path.is_dir():
                    path.unlink(missing_ok=True)
        return records

    def _verified(self, records: dict[int, dict]) -> dict[int, dict]:
        """The records whose files all exist inside ``OUT`` with their sha256; the others are removed (and redone)."""
        kept = {}
        for index, record in records.items():
            digests, files = record.get("sha256"), record.get("files")
            good = isinstance(digests, dict) and isinstance(files, list) and set(map(str, files)) <= set(digests)  # every file listed is checked
            good = good and all(_matches(self.out, rel, digest) for rel, digest in digests.items())
            if good:
                kept[index] = record
            else:
                self._say(f"warning: {self.out}: frame {index:06d} does not match its record; it is made again")
                (self.out / RECORDS / f"{index:06d}.json").unlink(missing_ok=True)
        return kept

    # ------------------------------------------------------------------ frames
    def has(self, index: int) -> bool:
        """True when frame ``index`` is committed (and, after a resume, verified)."""
        return index in self.committed

    def commit(self, frame, say: Callable[[str], None] | None = None) -> dict:
        """Write ``frame`` with every writer of the config and commit it (see the module docstring); returns its record.

        say : where its warning (an empty frame) goes (default: the dataset's log)"""
        import time

        start = time.perf_counter()
        staging = self.out / STAGING / frame.stem
        shutil.rmtree(staging, ignore_errors=True)
        spare, self._spare, committed = self._spare, None, False
        if spare is not None:  # the last frame's emptied folders, renamed: no folder made or removed per frame
            try:
                os.replace(spare, staging)
            except OSError:
                shutil.rmtree(spare, ignore_errors=True)
        try:
            with digests_while_writing() as hashed:  # sha256 of the files written through atomic.hashed_open, as they were written
                written = write_frame_files(frame, staging, frame_writers(self.config), self._beside_pool())
            relative = [str(Path(p).relative_to(staging)) for p in written]
            digests = {rel: hashed.get(os.path.abspath(staging / rel)) or sha256_file(staging / rel) for rel in relative}  # others read back
            intent = self.out / MOVING / f"{frame.stem}.json"
            with atomic_write(intent) as tmp:
                tmp.write_text(json.dumps(relative))
            for rel in relative:
                try:
                    (staging / rel).replace(self.out / rel)
                except FileNotFoundError:  # the final folder is not there yet (made once, on the first frame that writes into it)
                    (self.out / rel).parent.mkdir(parents=True, exist_ok=True)
                    (staging / rel).replace(self.out / rel)
            frame.files = relative
            self._page_cache.written_later([self.out / rel for rel in relative])
            frame.timings["write"] = frame.timings.get("write", 0.0) + time.perf_counter() - start
            record = frame_record(frame, digests)
            with atomic_write(self.out / RECORDS / f"{frame.stem}.json") as tmp:
                tmp.write_text(json.dumps(record, default=to_json, allow_nan=False) + "\n")
            intent.unlink()
            committed = True
        except OSError as err:
            raise _error(self.out, f"write frame {frame.index} into", err) from None
        finally:
            if committed:  # every file moved out: only folders are left, kept for the next frame
                self._spare = staging
            else:
                shutil.rmtree(staging, ignore_errors=True)
        frame.record = record
        self.committed[frame.index] = record
        if record["points"] == 0:
            (say or self._say)(f"warning: frame {frame.index}: 0 points. {empty_frame_cause(frame)}")
        return record

    def skip(self, frame, reason: str) -> dict:
        """Record ``frame`` as skipped (``output.skip_empty``): a record with ``"skipped": true``, the reason
        and its counts, and no files; the frame index stays taken, so a resume or another worker never makes it again."""
        record = {"index": frame.index, "skipped": True, "reason": reason, "files": [], "sha256": {},
                  "points": int(len(frame.points)) if frame.points is not None else 0,
                  "timings_s": {k: round(v, 4) for k, v in frame.timings.items()}}
        if frame.scene is not None and frame.scene.info is not None:
            record["scene"] = frame.scene.info
        try:
            with atomic_write(self.out / RECORDS / f"{frame.stem}.json") as tmp:
                tmp.write_text(json.dumps(record, default=to_json, allow_nan=False) + "\n")
        except OSError as err:
            raise _error(self.out, f"record skipped frame {frame.index} in", err) from None
        frame.record = record
        self.committed[frame.index] = record
        return record

    def _beside_pool(self) -> ThreadPoolExecutor | None:
        """The threads the writers' ``beside`` parts run on (:func:`write_frame_files`), one per such writer of the
        config, made once and kept for the run (no thread started per frame); ``None`` in a process of one thread
        (``config.threads`` 1, or 0 on one core) or with no such writer."""
        if self._beside is None and (self.config.threads or default_threads()) > 1:
            beside = sum(WRITERS.get(name).beside is not None for name in frame_writers(self.config))
            self._beside = ThreadPoolExecutor(beside, "beside writer") if beside else None
        return self._beside

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """Derive the per-dataset indexes and the summary from the records, and release the lock."""
        self._stop_threads()
        if self._spare is not None:
            shutil.rmtree(self._spare, ignore_errors=True)
            self._spare = None
        if self.mode == "join":
            return
        try:
            every = self._read_records()  # workers commit frames too
            records = [r for _, r in sorted(every.items()) if not r.get("skipped")]
            indexes = []
            for name in frame_writers(self.config):
                writer = WRITERS.get(name)
                if writer.index is not None:
                    indexes += [os.path.relpath(p, self.out) for p in writer.index(self.out, records, self.config) or ()]
            for name in (STAGING, MOVING):  # empty once every frame is committed
                if (self.out / name).is_dir() and not any((self.out / name).iterdir()):
                    (self.out / name).rmdir()
            manifest = read_manifest(self.out)
            manifest["indexes"] = sorted(set(manifest.get("indexes") or []) | set(indexes))  # what --overwrite removes beside the frames
            manifest["summary"] = {"frames": len(records), "points": int(sum(r["points"] for r in records)),
                                   "frame_indices": _ranges([r["index"] for r in records])}
            skipped = [i for i, r in every.items() if r.get("skipped")]
            if skipped:
                manifest["summary"]["skipped"] = {"frames": len(skipped), "frame_indices": _ranges(skipped)}
            write_manifest(self.out, manifest)
        finally:
            self._unlock()

    def __enter__(self) -> "Dataset":
        return self

    def __exit__(self, kind, error, trace) -> None:
        if kind is not None and self.mode in ("new", "overwrite") and not any((self.out / RECORDS).glob("*.json")):
            self._discard()  # a run that failed before its first frame leaves nothing behind
        else:
            self.close()

    def _stop_threads(self) -> None:
        if self._beside is not None:
            self._beside.shutdown()
            self._beside = None
        self._page_cache.close()

    def _discard(self) -> None:
        self._stop_threads()
        if self._spare is not None:
            shutil.rmtree(self._spare, ignore_errors=True)
            self._spare = None
        for name in (MANIFEST_NAME, RECORDS, STAGING, MOVING):
            path = self.out / name
            shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)
        self._unlock()
        if self.created and not any(self.out.iterdir()):
            self.out.rmdir()

    def _say(self, text: str) -> None:
        if self.log is not None:
            self.log(text)


def is_our_manifest(manifest: dict) -> bool:
    """True for the manifest of a bpy_pipeline run (this version's, or an earlier one's: a config and a seed)."""
    return manifest.get("format") == DATASET_FORMAT or ("format" not in manifest and isinstance(manifest.get("config"), dict) and "seed" in manifest)


def _listed_files(path: Path) -> list[str]:
    """The file names an intent (a JSON list) or a record (its ``files``) lists; ``[]`` when unreadable."""
    found, _ = readable_inside(path.parent, path.name, MAX_RECORD_BYTES)
    try:
        data = json.loads(found.read_text()) if found is not None else None
    except (OSError, ValueError, RecursionError):
        return []
    files = data.get("files") if isinstance(data, dict) else data
    return [name for name in files if isinstance(name, str)] if isinstance(files, list) else []


def _matches(out: Path, rel, digest) -> bool:
    """True when the record's file ``rel`` is a regular file inside ``out`` whose sha256 is ``digest``."""
    path, _ = readable_inside(out, rel, MAX_FRAME_FILE_BYTES)
    return path is not None and sha256_file(path) == digest


FS_IOC_GETFLAGS, FS_IMMUTABLE_FL, FS_APPEND_FL = 0x80086601, 0x10, 0x20  # linux/fs.h: the inode flags chattr sets


def _flags(path: Path) -> int:
    """The inode flags of ``path`` (``lsattr``), 0 where unknown."""
    import array

    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW)
    except OSError:
        return 0
    try:
        flags = array.array("l", [0])
        fcntl.ioctl(fd, FS_IOC_GETFLAGS, flags, True)
        return flags[0]
    except OSError:
        return 0
    finally:
        os.close(fd)


def undeletable(path: Path) -> str:
    """Why ``path`` cannot be removed (its folder not writable, it or its folder immutable or append-only), or ``""``."""
    folder = path.parent
    if not os.access(folder, os.W_OK | os.X_OK) or _flags(folder) & (FS_IMMUTABLE_FL | FS_APPEND_FL):
        return f"its folder {folder} is not writable"
    if not path.is_symlink() and _flags(path) & (FS_IMMUTABLE_FL | FS_APPEND_FL):
        return "it is immutable or append-only (chattr)"
    return ""


def _rmdir_if_empty(folder: Path) -> None:
    try:
        folder.rmdir()
    except OSError:
        pass


def input_paths(config: Config) -> list[str]:
    """What a run reads, as given in the config: every string naming an existing file, and every ``path`` (a file,
    a folder, or a glob pattern: its folder)."""
    found, stack = [], [("", config_to_dict(config))]
    while stack:
        key, node = stack.pop()
        if isinstance(node, dict):
            stack.extend(node.items())
        elif isinstance(node, (list, tuple)):
            stack.extend((key, value) for value in node)
        elif isinstance(node, str) and node and "\x00" not in node:
            node = os.path.expanduser(node)  # the blend builder's path may start with ~
            fixed = node[: min((node.find(c) for c in "*?[" if c in node), default=len(node))]
            if key == "path" and fixed != node:
                fixed = os.path.dirname(fixed) or "."
            if os.path.isfile(fixed) or (key == "path" and os.path.exists(fixed)):
                found.append(fixed)
    return found


def refuse_inputs_inside(out: str | os.PathLike, inputs, what: str = "--overwrite") -> None:
    """``InputError`` when an input path lies inside ``out`` (or is it), before anything is removed from ``out``."""
    root = os.path.realpath(out)
    for given in inputs:
        if given is None or not str(given):
            continue
        real = os.path.realpath(given)
        if real == root or real.startswith(root + os.sep):
            raise InputError(f"{what}: the input {given} lies inside {out}; nothing was removed: keep the inputs outside --out, or give another --out")


def _ranges(indices: list[int]) -> list[list[int]]:
    """``[[first, last], ...]`` runs of consecutive indices."""
    out = []
    for i in sorted(indices):
        if out and i == out[-1][1] + 1:
            out[-1][1] = i
        else:
            out.append([i, i])
    return out


def frame_record(frame, digests: dict[str, str]) -> dict:
    """The record of a written frame: its files and their sha256, points, pose, timings, objects, scene info, boxes."""
    from .builders import BUILDERS

    config = frame.config
    stations = 0 if config.sensor.trajectory is not None else BUILDERS.get(config.scene.builder).stations(config.scene.params)
    record = {
        "index": frame.index,
        "files": list(digests),
        "sha256": digests,
        "points": int(len(frame.points)),
        "triangles": int(len(frame.buffers.triangles)),
        "sensor_pose": frame.pose.tolist(),
    }
    if stations:
        record["station"] = frame.index % stations
    if frame.trajectory is not None:
        from .lidar.sensor.sensors import frame_time

        record["trajectory"] = frame.trajectory.frame_info(frame.index, frame_time(config.sensor.spec))
    record["timings_s"] = {k: round(v, 4) for k, v in frame.timings.items()}
    record["objects"] = frame.buffers.objects.rows()
    if frame.scene is not None and frame.scene.info is not None:
        record["scene"] = frame.scene.info
    if frame.rig is not None:
        record["rig"] = frame.rig.record()
    if frame.boxes is not None:
        record["boxes"] = [{"class": str(b["class_name"]), "instance": int(b["instance"]), "points": int(b["points"]), "visible": int(b["visible"]),
                            "unoccluded": int(b["unoccluded"]), "occlusion": int(b["occlusion"]),
                            "truncation": round(float(b["truncation"]), 4)} for b in frame.boxes]
    return record


def empty_frame_cause(frame) -> str:
    """The likely reason a frame has no points, for its warning."""
    spec = frame.config.sensor.spec
    if frame.buffers is None or not len(frame.buffers.triangles):
        return f"No object lies within the sensor's max_range ({spec.max_range} m) of its position {list(map(float, frame.pose[:3, 3].round(2)))}."
    return (
        f"The sensor ({spec.name}, {spec.vertical_fov_deg} deg vertical field, max_range {spec.max_range} m) at {list(map(float, frame.pose[:3, 3].round(2)))} "
        f"sees none of the scene's {len(frame.buffers.triangles)} triangles: check its position, rotation and field of view (a sensor on or under the ground "
        "sees nothing)."
    )


def available_memory() -> int:
    """Bytes of memory available to a new allocation (MemAvailable), or 0 when unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def check_writable(out: Path, config: Config) -> None:
    """Refuse, before any work, a folder that cannot take a frame: not writable, or too little free space
    for one frame's estimated size; and a sensor whose rays per frame cannot fit in memory."""
    from .lidar.points import POINT_DTYPE
    from .lidar.sensor.sensors import ray_count

    probe = out / f".write_test_{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as err:
        raise _error(out, "write into", err) from None
    rays = ray_count(config.sensor.spec)
    memory, frame_bytes = available_memory(), rays * POINT_DTYPE.itemsize * 2
    if memory and frame_bytes > memory:
        raise InputError(
            f"sensor: {rays:.3g} rays per frame need about {size(frame_bytes)} of memory for their points; {size(memory)} are available. Lower the resolution "
            "or the field of view"
        )
    need = rays * BYTES_PER_POINT * max(len(config.output.formats), 1)
    free = shutil.disk_usage(out).free
    if need > free:
        raise InputError(f"--out: {out} has {size(free)} free; one frame of {rays:.3g} rays may need {size(need)}")


def size(n: float) -> str:
    """A byte count for people: ``12.3 MB``."""
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1000
