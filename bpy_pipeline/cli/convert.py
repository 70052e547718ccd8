"""``bpy-pipeline convert SCAN [--labels FILE] --to PRESET --out DIR``: a dense real scan, labels carried, in a sparser sensor's pattern.

The scan is read as real-scan insertion reads it (:func:`~bpy_pipeline.io.real_scans.read_real_scan`, its
firings recovered by :func:`~bpy_pipeline.mixing.firings.recover_firings`), resampled into the target preset's
firings by one of :data:`~bpy_pipeline.mixing.convert.METHODS` (the parking paper's cone projection, the meshed ray
cast, or ``hybrid``: ours), and written as a one-frame dataset by the project's writers (SemanticKITTI layout by
default; ``--formats`` adds ply, npy, las, pcd, range_image), with its manifest and frame record.

Labels: each converted point takes the class, instance and intensity of the dense scan's return it came from
(:func:`~bpy_pipeline.mixing.convert.convert_firings` names it). They come from ``--labels`` (a SemanticKITTI
``.label``: uint32, semantic in the low 16 bits, instance in the high 16; or a ``.npy`` of one integer a point in
SemanticKITTI's 20 training ids, as the Open3D-ML samples are), else from the scan itself (``semantickitti``
format), else every point is ``unlabeled``. Classes go through the project's table (SemanticKITTI's names mapped
as real-scan insertion maps them) and are written back in SemanticKITTI's raw ids.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from .subcommand import Command

POINT_FORMATS = ("semantickitti", "ply", "npy", "las", "pcd", "range_image")
# SemanticKITTI training id -> raw id (semantic-kitti.yaml, learning_map_inv)
TRAINING_TO_RAW = np.array([0, 10, 11, 15, 18, 20, 30, 31, 32, 40, 44, 48, 49, 50, 51, 70, 71, 72, 80, 81], np.uint32)
LABEL_SPACES = ("auto", "raw", "train")


@dataclass
class Converted:
    """A converted scan.

    points : (k,) POINT_DTYPE in the target's frame (x forward, y left, z up, metres; ``ring``, ``range``,
        ``intensity``, ``semantic`` (the project's ids), ``instance`` and ``time`` filled)
    source : (k,) int64 the row of the dense scan's point each came from (-1: none)
    raw : (k,) uint32 that point's SemanticKITTI label as read (semantic | instance << 16), 0 without labels
    info : plain data for the frame record (method, counts, milliseconds)
    """

    points: np.ndarray
    source: np.ndarray
    raw: np.ndarray
    info: dict


def read_labels(path: str | Path, n: int, space: str = "auto") -> np.ndarray:
    """``(n,) uint32`` raw SemanticKITTI labels (semantic | instance << 16) of a ``.label`` or ``.npy`` file (module notes)."""
    path = Path(path)
    if space not in LABEL_SPACES:
        raise InputError(f"--label-space: {space!r} is not one of {', '.join(LABEL_SPACES)}")
    if not path.is_file():
        raise InputError(f"--labels: {path} is not a file")
    suffix = path.suffix.lower()
    if suffix not in (".label", ".npy"):
        raise InputError(f"--labels: {path} is not a SemanticKITTI .label or a .npy of one integer a point")
    if suffix == ".label":
        if path.stat().st_size % 4:
            raise InputError(f"--labels: {path}: {path.stat().st_size} bytes are not whole uint32 labels")
        labels = np.fromfile(path, "<u4").astype(np.uint32)
        space = "raw" if space == "auto" else space
    else:
        try:
            array = np.load(path)
        except (ValueError, OSError, EOFError) as err:
            raise InputError(f"--labels: {path}: not a numpy array file ({err})") from None
        if not isinstance(array, np.ndarray) or array.dtype.kind not in "iu" or array.ndim not in (1, 2) or (array.ndim == 2 and array.shape[1] != 1):
            raise InputError(
                f"--labels: {path}: expected one integer a point, (n,) or (n, 1), got {getattr(array, 'dtype', type(array))} {getattr(array, 'shape', '')}"
            )
        if array.size and array.min() < 0:
            raise InputError(f"--labels: {path}: negative labels (first at point {int(np.flatnonzero(array.reshape(-1) < 0)[0])})")
        if array.size and int(array.max()) > np.iinfo(np.uint32).max:
            raise InputError(
                f"--labels: {path}: labels up to {int(array.max())} do not fit SemanticKITTI's uint32 (semantic | instance << 16); first at point "
                f"{int(np.argmax(array.reshape(-1) > np.iinfo(np.uint32).max))}"
            )
        labels = array.reshape(-1).astype(np.uint32)
        space = "train" if space == "auto" else space
    if len(labels) != n:
        raise InputError(f"--labels: {path} holds {len(labels)} labels for the scan's {n} points")
    if space == "train":
        if len(labels) and labels.max() >= len(TRAINING_TO_RAW):
            raise InputError(
                f"--labels: {path}: training ids are 0..{len(TRAINING_TO_RAW) - 1}, got {int(labels.max())}; give --label-space raw for raw SemanticKITTI ids"
            )
        labels = TRAINING_TO_RAW[labels]
    return labels


def project_classes(raw: np.ndarray, table=None) -> tuple[np.ndarray, np.ndarray]:
    """``(semantic (n,) uint16 project ids, instance (n,) uint32)`` of raw SemanticKITTI labels (unknown ids: unlabeled)."""
    from ..labels import load_class_table
    from ..mixing.frame import SEMANTICKITTI_NAMES

    table = table or load_class_table()
    background = table.id_of("unlabeled")
    lut = np.full(1 << 16, background, np.uint16)
    for k, name in SEMANTICKITTI_NAMES.items():
        lut[k] = table.id_of(name)
    return lut[(raw & 0xFFFF).astype(np.int64)], (raw >> 16).astype(np.uint32)


def convert(scan_path, to: str, labels=None, method: str = "hybrid", lift: float = 0.0, source_preset: str | None = None, format: str | None = None,
            label_space: str = "auto", threads: int | None = None) -> Converted:
    """The scan at ``scan_path`` converted to preset ``to`` (module notes); ``lift`` metres: the target's centre above the source's."""
    from ..io.real_scans import read_real_scan
    from ..lidar.points import POINT_DTYPE
    from ..lidar.sensor.sensors import presets, resolve_sensor
    from ..mixing.convert import METHODS, convert_firings
    from ..mixing.firings import recover_firings

    names = list(presets())
    if to not in names:
        raise InputError(f"--to: unknown preset {to!r}; allowed: {', '.join(names)}")
    if source_preset is not None and source_preset not in names:
        raise InputError(f"--from: unknown preset {source_preset!r}; allowed: {', '.join(names)}")
    if method not in METHODS:
        raise InputError(f"--method: {method!r} is not one of {', '.join(METHODS)}")
    if not np.isfinite(lift):
        raise InputError(f"--lift: expected a finite number of metres, got {lift}")
    spec = resolve_sensor({"preset": to}, "--to")
    if spec.pattern != "spinning":
        raise InputError(f"--to: {to} is a {spec.pattern} sensor; conversion needs a spinning one (rings x columns), e.g. hdl32e, vlp16")
    path = Path(scan_path)
    if not path.is_file():
        raise InputError(f"SCAN: {path} is not a file")
    start = time.perf_counter()
    scan = read_real_scan(path, format)
    if labels is None:
        raw = scan.labels
    else:  # one label a row of the file, the rows left out (non-finite points) too
        raw = read_labels(labels, len(scan) if scan.kept is None else len(scan.kept), label_space)
        raw = raw if scan.kept is None else raw[scan.kept]
    try:
        firings = recover_firings(scan, source_preset)
    except InputError as err:
        raise InputError(str(err).replace("scene.preset", "--from")) from None
    read_ms = (time.perf_counter() - start) * 1e3
    start = time.perf_counter()
    xyz, ring, _, source_firing = convert_firings(firings, spec, (0.0, 0.0, lift), method, threads)
    convert_ms = (time.perf_counter() - start) * 1e3
    source = firings.point[source_firing]
    out = np.zeros(len(xyz), POINT_DTYPE)
    out["x"], out["y"], out["z"] = xyz.T
    out["ring"] = ring
    out["range"] = np.linalg.norm(xyz, axis=1)
    out["intensity"] = firings.intensity[source_firing]
    out["time"] = firings.time[source_firing]
    carried = np.zeros(len(out), np.uint32)
    if raw is not None:
        carried = np.asarray(raw, np.uint32)[source]
    out["semantic"], out["instance"] = project_classes(carried)
    info = {
        "conversion": {
            "scan": path.name, "to": to, "method": method, "lift_m": lift, "source_points": int(len(scan)), "source_returns": int(firings.valid.sum()),
            "source_rings": int(firings.shape[0]), "converted": int(len(out)), "labels": "none" if raw is None else ("file" if labels is not None else "scan"),
            "read_ms": round(read_ms, 2), "convert_ms": round(convert_ms, 2), "approximate": list(firings.approximate),
        }
    }
    return Converted(out, source, carried, info)


def write_converted(converted: Converted, out: str | Path, to: str, formats=("semantickitti",), overwrite: bool = False, scan_path: str = "",
                    inputs=()) -> dict:
    """Write a converted scan as a one-frame dataset under ``out`` (the run's manifest, record and writers); returns its record.

    inputs : other files the conversion read (its labels); ``overwrite`` refuses when one lies inside ``out``, as the scan"""
    from ..buffers import SceneBuffers
    from ..builders.base import BuildResult
    from ..config import load_config
    from ..dataset import Dataset
    from ..frame import Frame, frame_rng

    bad = [f for f in formats if f not in POINT_FORMATS]
    if bad or not formats:
        raise InputError(f"--formats: {bad[0] if bad else '(none)'!r} is not one of {', '.join(POINT_FORMATS)}")
    overrides = ["scene.builder=real_scan", f"scene.path={scan_path}", f"sensor.preset={to}", "sensor.position=[0, 0, 0]", "frames=1",
                 f"output.formats=[{', '.join(formats)}]", "output.boxes.formats=[]", "output.preview=false"]
    config = load_config(None, overrides)
    frame = Frame(index=0, config=config, rng=frame_rng(config.seed, 0), buffers=SceneBuffers.from_meshes({}), points=converted.points,
                  scene=BuildResult(info=converted.info))
    with Dataset.open(out, config, "overwrite" if overwrite else "new", inputs=[p for p in inputs if p]) as dataset:
        return dataset.commit(frame)


def add_convert_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    from ..mixing.convert import METHODS

    p.add_argument("scan", metavar="SCAN", help="the dense real scan (nuscenes, kitti, semantickitti .bin; npy, ply, las, pcd)")
    p.add_argument("--labels", metavar="FILE", help="its labels: a SemanticKITTI .label, or a .npy of SemanticKITTI training ids (one a point)")
    p.add_argument("--label-space", default="auto", choices=LABEL_SPACES,
                   help="ids in --labels: raw SemanticKITTI or training ids (auto: raw for .label, train for .npy)")
    p.add_argument("--to", required=True, metavar="PRESET", help="the sparser sensor's preset (spinning: hdl32e, vlp16, ...)")
    p.add_argument("--out", required=True, metavar="DIR", help="the dataset folder to write")
    p.add_argument("--method", default="hybrid", choices=METHODS,
                   help="cones (the parking paper's), mesh (ray cast at the meshed scan), hybrid (ours: mesh, cones where it misses)")
    p.add_argument("--from", dest="source", metavar="PRESET", help="the scan's own sensor, where the file lacks its rings (e.g. hdl64e)")
    p.add_argument("--format", choices=None, metavar="FORMAT", help="the scan's format when its name does not tell")
    p.add_argument("--lift", type=float, default=0.0, metavar="M", help="the target's centre this many metres above the scan's (default 0)")
    p.add_argument("--formats", default="semantickitti", metavar="A,B", help=f"output formats, of {', '.join(POINT_FORMATS)} (default semantickitti)")
    p.add_argument("--overwrite", action="store_true", help="replace a dataset already in --out")
    p.add_argument("--threads", type=int, help="ray-casting threads (default: the cores available)")
    return p


def convert_main(args) -> int:
    """``convert``: returns the exit code."""
    if not args.out.strip():
        raise InputError("--out: empty; give a folder")
    formats = tuple(f.strip() for f in args.formats.split(",") if f.strip())
    bad = [f for f in formats if f not in POINT_FORMATS]
    if bad or not formats:
        raise InputError(f"--formats: {bad[0] if bad else '(none)'!r} is not one of {', '.join(POINT_FORMATS)}")
    if args.overwrite:  # before any work: --overwrite never removes an input
        from ..dataset import refuse_inputs_inside

        refuse_inputs_inside(args.out, [args.scan, args.labels])
    converted = convert(args.scan, args.to, args.labels, args.method, args.lift, args.source, args.format, args.label_space, args.threads)
    record = write_converted(converted, args.out, args.to, formats, args.overwrite, str(Path(args.scan).resolve()), [args.labels])
    c = converted.info["conversion"]
    print(
        f"{c['source_returns']:,} returns of {c['scan']} -> {c['converted']:,} points of {args.to} ({args.method}, {c['convert_ms']:.0f} ms, labels: "
        f"{c['labels']}); {len(record['files'])} files in {args.out}"
    )
    return 0


def arguments(p) -> None:
    add_convert_arguments(p).set_defaults(func=convert_main)


COMMAND = Command("convert", "a dense real scan, labels carried, in a sparser sensor's pattern",
                  "Resample a dense real scan (and its labels) into a sparser sensor preset's firings and write it as a dataset (docs/mixing.md).", arguments)
