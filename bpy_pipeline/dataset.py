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
"""

from __future__ import annotations

import datetime
import errno
import hashlib
import json
import os
import shutil
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .config import Config, config_to_dict
from .errors import InputError
from .io.atomic import atomic_write
from .io.manifest import MANIFEST_NAME, read_manifest, to_json, write_manifest
from .io.writers import WRITERS, frame_writers

DATASET_FORMAT = "bpy_pipeline dataset"
DATASET_VERSION = 2
RECORDS, STAGING, MOVING, LOCK = "records", ".staging", ".moving", ".lock"
MODES = ("new", "resume", "overwrite", "join")
BYTES_PER_POINT = 64  # on disk per point and format, a generous estimate (PLY: 35, LAS: 46, SemanticKITTI: 20)


def run_key(config: Config) -> str:
    """sha256 of everything that shapes a frame's bytes: the resolved config but its frame count."""
    data = config_to_dict(config)
    data.pop("frames", None)
    data.pop("threads", None)
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=to_json).encode()).hexdigest()


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


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
    created: bool = False  # the folder did not exist before this run

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, out: str | os.PathLike, config: Config, mode: str = "new", log: Callable[[str], None] | None = None) -> "Dataset":
        """Open ``out`` for ``config``.

        mode : ``new`` refuses a folder that holds a run; ``resume`` continues a run of the same config
            and seed (committed frames whose files still match their sha256 are kept, the rest redone);
            ``overwrite`` removes the old dataset first; ``join`` adds frames to a run another process
            holds the lock of (workers: same config and seed, no lock, no clean-up)
        Raises :class:`InputError` (exit 2) for a folder it cannot or must not write.
        """
        if mode not in MODES:
            raise ValueError(f"Dataset.open: mode must be one of {MODES}, got {mode!r}")
        out = Path(out)
        if out.exists() and not out.is_dir():
            raise InputError(f"--out: {out} exists and is not a folder")
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
        path = self.out / LOCK
        me = {"pid": os.getpid(), "host": socket.gethostname(), "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
        for _ in range(2):
            try:
                fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                try:
                    holder = json.loads(path.read_text())
                except (OSError, ValueError):
                    holder = {}
                if holder.get("host") == me["host"] and isinstance(holder.get("pid"), int) and not _pid_alive(holder["pid"]):
                    self._say(f"warning: {self.out}: taking over the lock of a run that ended without releasing it (pid {holder['pid']})")
                    path.unlink(missing_ok=True)
                    continue
                raise InputError(f"--out: {self.out} is being written by pid {holder.get('pid', '?')} on {holder.get('host', '?')} (since {holder.get('started', '?')}); wait for it, or remove {path} if that run is dead") from None
            except OSError as err:
                raise _error(path, "create the lock file", err) from None
            with os.fdopen(fd, "w") as handle:
                json.dump(me, handle)
            self.locked = True
            return

    def _unlock(self) -> None:
        if self.locked:
            (self.out / LOCK).unlink(missing_ok=True)
            self.locked = False

    def _prepare(self) -> None:
        """Refuse, resume or overwrite an existing run; clean up what a killed run left; write the manifest."""
        manifest_path = self.out / MANIFEST_NAME
        old = read_manifest(self.out) if manifest_path.exists() else None
        if old is not None and self.mode == "new":
            what = f"seed {old.get('seed')}, {len(list((self.out / RECORDS).glob('*.json')))} frames" if old.get("format") == DATASET_FORMAT else "an earlier version's output"
            raise InputError(f"--out: {self.out} holds another run ({what}); give --resume to continue it (same config and seed) or --overwrite to replace it")
        if old is not None and self.mode == "overwrite":
            self._remove_old(old)
            old = None
        self._clean_partial_frames()
        if old is not None:  # resume
            self._check_same_run(old)
            self.committed = self._verified(self._read_records())
            manifest = {**old, "config": config_to_dict(self.config)}  # the frame count may have grown
        else:
            manifest = self._new_manifest()
        manifest.pop("summary", None)
        write_manifest(self.out, manifest)

    def _new_manifest(self) -> dict:
        from .lidar.sensors import spec_summary
        from .frame import versions

        return {
            "format": DATASET_FORMAT,
            "version": DATASET_VERSION,
            "config": config_to_dict(self.config),
            "seed": self.config.seed,
            "run_key": run_key(self.config),
            "versions": versions(),
            "sensor": spec_summary(self.config.sensor.spec),
            "class_table": {int(k): v for k, v in __import__(f"{__package__}.labels", fromlist=["x"]).load_class_table().names.items()},  # relative: inside Blender the package is bl_ext.<repo>.<id>.bpy_pipeline
        }

    def _check_same_run(self, manifest: dict) -> None:
        if manifest.get("format") != DATASET_FORMAT:
            raise InputError(f"--resume: {self.out} holds an earlier version's output, which cannot be resumed; give --overwrite to replace it")
        if manifest.get("run_key") != run_key(self.config):
            old = manifest.get("config") or {}
            new = config_to_dict(self.config)
            keys = [k for k in sorted(set(old) | set(new)) if k not in ("frames", "threads") and old.get(k) != new.get(k)]
            raise InputError(f"--resume: {self.out} holds a run with another config or seed (differs in: {', '.join(keys) or 'versions'}); give --overwrite to replace it")

    def _remove_old(self, manifest: dict) -> None:
        """Remove the old dataset: its frames' files, records, manifest and indexes (the whole folder's content)."""
        if manifest.get("format") not in (DATASET_FORMAT, None) and "config" not in manifest:
            raise InputError(f"--overwrite: {self.out}/manifest.json is not a bpy_pipeline manifest; refusing to remove the folder's content")
        for entry in self.out.iterdir():
            if entry.name == LOCK:
                continue
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()

    def _clean_partial_frames(self) -> None:
        """Remove staged frames and the moved files of frames that never got their record."""
        shutil.rmtree(self.out / STAGING, ignore_errors=True)
        for intent in sorted((self.out / MOVING).glob("*.json")):
            if not (self.out / RECORDS / intent.name).exists():
                try:
                    files = json.loads(intent.read_text())
                except (OSError, ValueError):
                    files = []
                for rel in files:
                    (self.out / rel).unlink(missing_ok=True)
                self._say(f"warning: {self.out}: removed the files of frame {intent.stem}, which a killed run left without its record")
            intent.unlink()

    def _read_records(self) -> dict[int, dict]:
        records = {}
        for path in sorted((self.out / RECORDS).glob("*.json")):
            try:
                record = json.loads(path.read_text())
                records[int(record["index"])] = record
            except (OSError, ValueError, KeyError, TypeError):
                self._say(f"warning: {path}: unreadable frame record, the frame is made again")
                path.unlink(missing_ok=True)
        return records

    def _verified(self, records: dict[int, dict]) -> dict[int, dict]:
        """The records whose files all exist with their sha256; the others are removed (and redone)."""
        kept = {}
        for index, record in records.items():
            good = all((self.out / rel).is_file() and sha256_file(self.out / rel) == digest for rel, digest in record.get("sha256", {}).items())
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

    def commit(self, frame) -> dict:
        """Write ``frame`` with every writer of the config and commit it (see the module docstring); returns its record."""
        import time

        start = time.perf_counter()
        staging = self.out / STAGING / frame.stem
        shutil.rmtree(staging, ignore_errors=True)
        try:
            written = []
            for name in frame_writers(self.config):
                written += WRITERS.get(name).write(frame, staging)
            relative = [str(Path(p).relative_to(staging)) for p in written]
            digests = {rel: sha256_file(staging / rel) for rel in relative}
            intent = self.out / MOVING / f"{frame.stem}.json"
            with atomic_write(intent) as tmp:
                tmp.write_text(json.dumps(relative))
            for rel in relative:
                (self.out / rel).parent.mkdir(parents=True, exist_ok=True)
                (staging / rel).replace(self.out / rel)
            frame.files = relative
            frame.timings["write"] = frame.timings.get("write", 0.0) + time.perf_counter() - start
            record = frame_record(frame, digests)
            with atomic_write(self.out / RECORDS / f"{frame.stem}.json") as tmp:
                tmp.write_text(json.dumps(record, default=to_json, allow_nan=False) + "\n")
            intent.unlink()
        except OSError as err:
            raise _error(self.out, f"write frame {frame.index} into", err) from None
        finally:
            shutil.rmtree(staging, ignore_errors=True)
        frame.record = record
        self.committed[frame.index] = record
        if record["points"] == 0:
            self._say(f"warning: frame {frame.index}: 0 points. {empty_frame_cause(frame)}")
        return record

    def skip(self, frame, reason: str) -> dict:
        """Record ``frame`` as skipped (``output.skip_empty``): a record with ``"skipped": true``, the reason
        and its counts, and no files; the frame index stays taken, so a resume or another worker never makes it again."""
        record = {"index": frame.index, "skipped": True, "reason": reason, "files": [], "sha256": {}, "points": int(len(frame.points)) if frame.points is not None else 0,
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

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """Derive the per-dataset indexes and the summary from the records, and release the lock."""
        if self.mode == "join":
            return
        try:
            records = [r for _, r in sorted(self._read_records().items()) if not r.get("skipped")]  # workers commit frames too
            for name in frame_writers(self.config):
                writer = WRITERS.get(name)
                if writer.index is not None:
                    writer.index(self.out, records, self.config)
            for name in (STAGING, MOVING):  # empty once every frame is committed
                if (self.out / name).is_dir() and not any((self.out / name).iterdir()):
                    (self.out / name).rmdir()
            manifest = read_manifest(self.out)
            manifest["summary"] = {"frames": len(records), "points": int(sum(r["points"] for r in records)), "frame_indices": _ranges([r["index"] for r in records])}
            skipped = [i for i, r in self._read_records().items() if r.get("skipped")]
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

    def _discard(self) -> None:
        for name in (MANIFEST_NAME, RECORDS, STAGING, MOVING):
            path = self.out / name
            shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)
        self._unlock()
        if self.created and not any(self.out.iterdir()):
            self.out.rmdir()

    def _say(self, text: str) -> None:
        if self.log is not None:
            self.log(text)


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
        from .lidar.sensors import frame_time

        record["trajectory"] = frame.trajectory.frame_info(frame.index, frame_time(config.sensor.spec))
    record["timings_s"] = {k: round(v, 4) for k, v in frame.timings.items()}
    record["objects"] = frame.buffers.objects.rows()
    if frame.scene is not None and frame.scene.info is not None:
        record["scene"] = frame.scene.info
    if frame.rig is not None:
        record["rig"] = frame.rig.record()
    if frame.boxes is not None:
        record["boxes"] = [{"class": str(b["class_name"]), "instance": int(b["instance"]), "points": int(b["points"]), "visible": int(b["visible"]), "unoccluded": int(b["unoccluded"]), "occlusion": int(b["occlusion"]), "truncation": round(float(b["truncation"]), 4)} for b in frame.boxes]
    return record


def empty_frame_cause(frame) -> str:
    """The likely reason a frame has no points, for its warning."""
    spec = frame.config.sensor.spec
    if frame.buffers is None or not len(frame.buffers.triangles):
        return f"No object lies within the sensor's max_range ({spec.max_range} m) of its position {list(map(float, frame.pose[:3, 3].round(2)))}."
    return (f"The sensor ({spec.name}, {spec.vertical_fov_deg} deg vertical field, max_range {spec.max_range} m) at {list(map(float, frame.pose[:3, 3].round(2)))} "
            f"sees none of the scene's {len(frame.buffers.triangles)} triangles: check its position, rotation and field of view (a sensor on or under the ground sees nothing).")


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
    from .lidar.sensors import ray_count

    probe = out / f".write_test_{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as err:
        raise _error(out, "write into", err) from None
    rays = ray_count(config.sensor.spec)
    memory, frame_bytes = available_memory(), rays * POINT_DTYPE.itemsize * 2
    if memory and frame_bytes > memory:
        raise InputError(f"sensor: {rays:.3g} rays per frame need about {size(frame_bytes)} of memory for their points; {size(memory)} are available. Lower the resolution or the field of view")
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
