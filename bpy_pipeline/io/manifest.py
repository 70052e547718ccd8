"""The run manifest, ``OUT/manifest.json`` (docs/datasets.md, "What is in the folder").

The manifest is a plain JSON object (indent 2, keys in insertion order, UTF-8, trailing
newline). numpy scalars and arrays become JSON numbers and lists, paths become strings.
NaN and infinity are refused (they are not JSON): a ``ValueError`` names the file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..errors import InputError, path_argument
from .atomic import atomic_write

MANIFEST_NAME = "manifest.json"
MAX_JSON_BYTES = 256 << 20  # a manifest or frame record larger than this is not one (nor is a device or a FIFO)


def to_json(value):
    """``json.dumps`` fallback: numpy scalars and arrays to Python numbers and lists, paths to strings."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable: {value!r}")


def write_manifest(out_dir: str | os.PathLike, manifest: dict) -> Path:
    """Write ``manifest`` (a JSON-able dict) to ``out_dir/manifest.json`` atomically; return its path."""
    path = Path(out_dir) / MANIFEST_NAME
    try:
        text = json.dumps(manifest, indent=2, sort_keys=False, ensure_ascii=False, allow_nan=False, default=to_json)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: cannot write the manifest as JSON ({err})") from None
    with atomic_write(path) as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    return path


def read_manifest(out_dir: str | os.PathLike) -> dict:
    """Read ``out_dir/manifest.json``; ``InputError`` naming the file when it is missing or not a JSON object."""
    path = Path(out_dir) / MANIFEST_NAME
    if path.exists() and not path.is_file():
        raise InputError(f"{path}: not a regular file, not a run manifest")
    if path.is_file() and path.stat().st_size > MAX_JSON_BYTES:
        raise InputError(f"{path}: larger than {MAX_JSON_BYTES >> 20} MB, not a run manifest")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise InputError(f"{path}: cannot read the run manifest ({err.strerror})") from None
    except (ValueError, RecursionError) as err:
        raise InputError(f"{path}: not valid JSON ({str(err) or type(err).__name__})") from None
    if not isinstance(manifest, dict):
        raise InputError(f"{path}: expected a JSON object at the top level, got {type(manifest).__name__}")
    return manifest


def read_frame_records(out_dir: str | os.PathLike) -> list[dict]:
    """The records of the committed frames of the dataset in ``out_dir`` (``records/NNNNNN.json``), by frame index."""
    records = []
    for path in sorted((Path(out_dir) / "records").glob("*.json")):
        if not path.is_file() or path.stat().st_size > MAX_JSON_BYTES:
            raise InputError(f"{path}: not a frame record (a regular file of at most {MAX_JSON_BYTES >> 20} MB)")
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except (ValueError, RecursionError) as err:
            raise InputError(f"{path}: not valid JSON ({str(err) or type(err).__name__})") from None
        if not isinstance(record, dict) or isinstance(record.get("index"), bool) or not isinstance(record.get("index"), int):
            raise InputError(f"{path}: not a frame record (a JSON object with an integer index)")
        records.append(record)
    return sorted(records, key=lambda r: r["index"])


def read_dataset(out_dir: str | os.PathLike) -> dict:
    """The run manifest with its committed frames' records under ``frames``."""
    return {**read_manifest(path_argument(out_dir, "out_dir")), "frames": read_frame_records(out_dir)}
