"""``bpy-pipeline COMMAND ...`` (or ``python -m bpy_pipeline COMMAND ...``): the pipeline and its tools.

Commands:

``run [--config FILE] [--out DIR] ...``
    Generate frames, as ``run.py`` does (:mod:`.cli` lists the options).

``sensors [list]``
    The sensor presets, one line each: pattern, channels, elevation range, columns, rays a
    frame, rate and range.
``sensors show NAME [--rays FILE.npy]``
    One preset's resolved fields and summary; ``--rays`` saves the ray directions of a full
    frame as ``(n, 3)`` float32 in the sensor frame (x forward, y left, z up).
``fit SCAN [SCAN ...] --out MODEL.yaml [--rings 32 ...]``
    Ray drop and range noise models fitted to real organised scans (``lidar/fit/fitting.py``),
    written for ``effects.drop.model_file`` / ``effects.noise.model_file``; prints each drop
    model's held-out error.
``evaluate --train DATASET --test REAL [--reference REAL ...] --classes car,person --out report.json``
    Train the reference segmentation model on generated datasets, test it on real labelled scans
    and print per-class IoU with 95 % intervals, beside the same model trained on real frames
    (leave one group out); docs/evaluate.md.

``convert SCAN [--labels FILE] --to PRESET --out DIR [--method cones|mesh|hybrid]``
    A dense real scan resampled into a sparser sensor's firings, each point keeping the class,
    instance and intensity of the return it came from, written as a dataset (:mod:`.conversion`).

``match REAL [REAL ...] --config BASE.yaml --out MATCHED.yaml``
    Per-class object counts, distance and heading histograms fitted to labelled real frames, written
    as the real_scan (or parking) builder's placement distributions (:mod:`.match`, docs/match.md).

Each command is a ``_add_<name>(subparsers)`` function that registers its parser and sets
``func`` (``args -> exit code``); add new commands the same way. Bad input (``InputError``)
prints one line and exits with code 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import yaml

from .errors import InputError
from .lidar.sensor import sensors


_LINE = "{:<16} {:<11} {:>8}  {:>17}  {:>7}  {:>11}  {:>8}  {:>9}"


def preset_line(name: str) -> str:
    """One listing line of a preset's key figures."""
    s = sensors.spec_summary(sensors.resolve_sensor({"preset": name}))
    el_lo, el_hi = s["elevation_deg"]
    lo, hi = s["range_m"]
    return _LINE.format(
        name, s["pattern"], s["channels"], f"{el_lo:+.2f}..{el_hi:+.2f}", s["columns"], f"{s['rays_per_frame']:,}",
        f"{1.0 / s['frame_time_s']:g}", f"{lo:g}-{hi:g}",
    )


def list_sensors(args) -> int:
    print(_LINE.format("preset", "pattern", "channels", "elevation deg", "columns", "rays/frame", "rate Hz", "range m"))
    for name in sensors.presets():
        print(preset_line(name))
    return 0


def show_sensor(args) -> int:
    names = list(sensors.presets())
    if args.name not in names:
        raise InputError(f"sensors show: unknown preset {args.name!r}; allowed: {', '.join(names)}")
    spec = sensors.resolve_sensor({"preset": args.name}, where=args.name)
    shown = {"fields": sensors.spec_fields(spec), "summary": sensors.spec_summary(spec), "effects": sensors.preset_effects(args.name), "sources": sensors.preset_sources(args.name)}
    print(yaml.safe_dump(shown, sort_keys=False, width=100, default_flow_style=None), end="")
    if args.rays:
        if Path(args.rays).is_dir() or not Path(args.rays).parent.is_dir():
            raise InputError(f"--rays: {args.rays} must be a file path in an existing folder (FILE.npy)")
        n = save_rays(spec, args.rays)
        print(f"rays: {n:,} directions (float32, sensor frame) written to {args.rays}")
    return 0


def save_rays(spec: sensors.SensorSpec, path: str | Path, chunk_rays: int = 1 << 20) -> int:
    """Write a full frame's ray directions as an ``(n, 3)`` float32 ``.npy``, chunk by chunk, atomically."""
    path = Path(path)
    total = sensors.ray_count(spec)
    tmp = path.with_name(path.name + ".tmp")
    try:
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float32, shape=(total, 3))
    except OSError as err:
        raise InputError(f"--rays: cannot write {path} ({err.strerror or err})") from None
    try:
        start = 0
        for part in sensors.iter_pattern(spec, chunk_rays):
            out[start : start + len(part)] = part.directions
            start += len(part)
        out.flush()
        del out
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise InputError(f"--rays: cannot write {path} ({err.strerror or err})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return total


def _add_run(sub) -> None:
    from .cli import add_run_arguments, run_main

    p = sub.add_parser("run", help="generate labeled frames (as run.py)", description="Generate labeled LiDAR frames from a config.")
    add_run_arguments(p).set_defaults(func=run_main)


def _add_sensors(sub) -> None:
    p = sub.add_parser("sensors", help="list the sensor presets or show one", description="List the sensor presets or show one.")
    p.set_defaults(func=list_sensors)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.add_parser("list", help="one line per preset (the default)").set_defaults(func=list_sensors)
    show = actions.add_parser("show", help="one preset's resolved fields and summary")
    show.add_argument("name", metavar="NAME", help="preset name")
    show.add_argument("--rays", metavar="FILE.npy", help="save its ray directions for a full frame, (n, 3) float32, sensor frame")
    show.set_defaults(func=show_sensor)


def fit_effects(args) -> int:
    """Fit drop and noise models to real organised scans and write a model file for the effects."""
    from dataclasses import replace

    from .lidar.fit import fitting
    from .lidar.effects.apply import write_model_file

    options = fitting.FitOptions()
    changes = {k: getattr(args, k) for k in fitting.FitOptions.__dataclass_fields__ if getattr(args, k, None) is not None}
    options = replace(options, **changes)
    if not (np.isfinite(options.min_range) and np.isfinite(options.max_range) and 0 < options.min_range < options.max_range):
        raise InputError(f"fit: need 0 < --min-range < --max-range, finite metres, got {options.min_range} and {options.max_range}")
    if not (np.isfinite(args.empty_radius) and args.empty_radius >= 0):
        raise InputError(f"--empty-radius: must be a finite number of metres >= 0, got {args.empty_radius}")
    if not (np.isfinite(options.intensity_scale) and options.intensity_scale > 0):
        raise InputError(f"--intensity-scale: must be a finite number > 0 (the intensity of an apparent reflectance of 1), got {options.intensity_scale}")
    for key, least, most in (("folds", 0, fitting.MAX_FOLDS), ("mlp_steps", 1, fitting.MAX_MLP_STEPS), ("max_gap", 0, fitting.MAX_GAP)):  # they multiply the work
        if not least <= getattr(options, key) <= most:
            raise InputError(f"--{key.replace('_', '-')}: must lie in {least}..{most:,}, got {getattr(options, key):,}")
    if min(options.range_bins, options.incidence_bins, options.noise_range_bins, options.noise_incidence_bins, options.min_samples,
           options.mlp_range_bins, options.mlp_incidence_bins, options.mlp_steps) < 1 or options.seed < 0:
        raise InputError("fit: bin counts, --min-samples and --mlp-steps must be >= 1, --seed >= 0")
    from .io.confined import refuse_output_over_input

    out = Path(args.out)
    refuse_output_over_input(out, args.scans)
    if not out.parent.is_dir() and (out.parent.exists() or any(p.exists() and not p.is_dir() for p in out.parents)):
        raise InputError(f"--out: {out.parent} is not a folder (a file stands in the path); give a path in a folder")
    if args.fields < 4 or not 0 <= args.intensity_field < args.fields or args.ring_field >= args.fields or args.rings < 1:
        raise InputError(f"fit: need --fields >= 4 (x y z intensity), 0 <= --intensity-field < --fields, --ring-field < --fields and --rings >= 1; got --fields {args.fields}, --intensity-field {args.intensity_field}, --ring-field {args.ring_field}, --rings {args.rings}")
    ring_field = None if args.ring_field < 0 else args.ring_field
    scans = [fitting.read_scan(path, args.rings, args.fields, args.intensity_field, ring_field, args.empty_radius) for path in args.scans]
    scan = scans[0] if len(scans) == 1 else fitting.stack_scans(scans)
    models, report = fitting.fit_models(scan, options)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_model_file(out, models)
    except OSError as err:
        raise InputError(f"--out: cannot write {out} ({err.strerror or err})") from None
    src = models.source
    print(f"{src['sweeps']} sweep(s) of {src['rings']} x {src['columns']}: {src['empty']} empty firings; "
          f"{src['samples']} with a known target ({src['filled_from_neighbours']} filled from ring neighbours), {src['dropped']} of them dropped")
    t = models.threshold
    print(f"uniform: drop {models.uniform:.4f}")
    print(f"threshold: exponent {t.exponent:g}, softness {t.softness:.3g}, 50 % range at 10 % / 80 %: {t.range_at(0.1):.1f} m / {t.range_at(0.8):.1f} m")
    kept = int((~np.isnan(models.drop_table.values)).sum())
    print(f"table: {options.range_bins} x {options.incidence_bins} bins, {kept} with >= {options.min_samples} samples")
    print(f"mlp: {models.drop_mlp.parameters} weights over {options.mlp_range_bins} x {options.mlp_incidence_bins} bins with >= {options.min_samples} samples (drop; noise likewise), seed {options.seed}")
    print(f"noise: sigma {models.noise_range[0] * 1000:.1f} mm + {models.noise_range[1] * 1000:.2f} mm per m (from {src['noise_samples']} samples)")
    if "cross_validation" in report:
        cv = report["cross_validation"]
        names = list(cv)
        best, pick = fitting.simplest_within_noise(cv, names)
        print(f"held-out log-loss over {options.folds} column blocks (nats per firing; lower is better):")
        for name in names:
            diff = cv[name]["loss"] - cv[best]["loss"]
            se = diff.std(ddof=1) / np.sqrt(len(diff))
            print(f"  {name:<12} {cv[name]['parameters']:>3} parameters  {cv[name]['loss'].mean():.4f}  ({diff.mean():+.4f} +- {se:.4f} to the best)")
        print(f"simplest within noise of the best: {pick}")
    print(f"written: {args.out} (effects.drop.model_file and effects.noise.model_file read it)")
    return 0


def _add_fit(sub) -> None:
    p = sub.add_parser(
        "fit", help="fit ray drop and range noise to real organised scans",
        description="Fit the uniform, threshold, table and mlp drop models and the range, table and mlp noise models to real "
        "organised scans (one sweep: gaps filled from ring neighbours; several sweeps of a static scene: per-pixel "
        "medians) and write a model file for effects.drop.model_file and effects.noise.model_file.",
    )
    p.add_argument("scans", nargs="+", metavar="SCAN", help="organised sweep(s): float32 .bin (x y z intensity ring per firing, column after column) or .npy (rings, columns, >= 4)")
    p.add_argument("--out", required=True, metavar="FILE.yaml", help="model file to write")
    p.add_argument("--rings", type=int, default=32, help="rings (channels) per column (default 32, an HDL-32E)")
    p.add_argument("--fields", type=int, default=5, help=".bin: float32 fields per firing (default 5)")
    p.add_argument("--intensity-field", type=int, default=3, help=".bin: field of the intensity (default 3)")
    p.add_argument("--ring-field", type=int, default=4, help=".bin: field of the ring id, checked (default 4; -1: none)")
    p.add_argument("--empty-radius", type=float, default=0.5, help="m: returns nearer the origin are empty-firing candidates (default 0.5)")
    for name, kind, what in (
        ("max_gap", int, "columns: longest run of empty firings filled from its ring neighbours"),
        ("intensity_scale", float, "intensity of an apparent reflectance of 1"),
        ("min_range", float, "m: nearer targets are left out (the vehicle itself)"),
        ("max_range", float, "m: farther targets are left out"),
        ("range_bins", int, "drop table: log-spaced range bins"),
        ("incidence_bins", int, "drop table: incidence bins over 0..90 deg"),
        ("noise_range_bins", int, "noise table: range bins"),
        ("noise_incidence_bins", int, "noise table: incidence bins"),
        ("min_samples", int, "bins with fewer samples are discarded"),
        ("folds", int, "column blocks for the held-out comparison (0: skip)"),
        ("mlp_range_bins", int, "mlp drop and noise models: log-spaced range bins they learn from"),
        ("mlp_incidence_bins", int, "mlp models: incidence bins over 0..90 deg"),
        ("mlp_steps", int, "mlp models: Adam steps"),
        ("seed", int, "mlp models: seed of the weights' start (same seed, same file)"),
    ):
        default = getattr(__import__("bpy_pipeline.lidar.fit.fitting", fromlist=["FitOptions"]).FitOptions, name)
        p.add_argument("--" + name.replace("_", "-"), dest=name, type=kind, default=None, help=f"{what} (default {default})")
    p.set_defaults(func=fit_effects)


def _add_config(sub) -> None:
    p = sub.add_parser("config", help="print the resolved config with the source of each value",
                       description="Print the resolved config: each value with where it comes from (default < preset < builder < profile < config < --set; bpy_pipeline/resolved.py).")
    view = p.add_mutually_exclusive_group(required=True)
    view.add_argument("--resolved", action="store_true", help="the resolved tree")
    view.add_argument("--reference", action="store_true", help="every config key with its type, default, unit, range and meaning (docs/config.md)")
    p.add_argument("--config", help="YAML config file (default: the embedded railway scene)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override one config key (repeatable)")
    p.set_defaults(func=print_resolved)


def print_resolved(args) -> int:
    from .resolved import render, resolved

    if args.reference:
        from .config import config_reference

        print(config_reference())
        return 0

    print(render(*resolved(args.config, args.set)), end="")
    return 0


def run_evaluate(args) -> int:
    """Train on ``--train``, test on ``--test`` (and the real reference), print the table, write the JSON report."""
    from .evaluate import evaluate, table
    from .evaluate.run import write_report

    out = Path(args.out)
    if out.is_dir() or (out.parent.exists() and not out.parent.is_dir()):
        raise InputError(f"--out: {out} must be a file path in a folder")
    from .io.confined import refuse_output_over_input

    refuse_output_over_input(out, [*args.train, *args.test, *(args.reference or [])])
    if args.every < 1 or (args.max_frames is not None and args.max_frames < 1) or args.jobs < 1:
        raise InputError("evaluate: --every, --max-frames and --jobs must be >= 1")
    report = evaluate(args.train, args.test, args.classes, args.reference, args.model, args.seed, args.every, args.max_frames,
                      args.max_points_per_scan, args.jobs, log=lambda m: print(m, file=sys.stderr), steps=args.steps)
    write_report(out, report)
    print(table(report))
    print(f"written: {out}")
    return 0


def _add_evaluate(sub) -> None:
    from .evaluate.models import MAX_POINTS_PER_SCAN, MODELS

    p = sub.add_parser("evaluate", help="train a reference model on generated data, report IoU on real labelled scans",
                       description="Train the reference per-point segmentation model on generated datasets, test it on real labelled scans "
                       "and report per-class IoU with 95 %% intervals (bootstrap over objects); with --reference, the same model trained "
                       "on real frames, leave one group out, on the same test scans (docs/evaluate.md).")
    p.add_argument("--train", action="append", required=True, metavar="DATASET", help="generated dataset folder (ply/) or labelled scans (repeatable)")
    p.add_argument("--test", action="append", required=True, metavar="REAL", help="real labelled scan: SemanticKITTI .bin (+ .label), X_points.npy (+ X_labels.npy), "
                   "KITTI object .bin (+ label_2, calib), or a folder of them (repeatable)")
    p.add_argument("--reference", action="append", metavar="REAL", help="real labelled scans to train the reference on, leave one group out (repeatable)")
    p.add_argument("--classes", default="car,person", help="evaluation classes, SemanticKITTI training names, comma separated (default car,person)")
    p.add_argument("--out", required=True, metavar="REPORT.json", help="JSON report to write")
    p.add_argument("--model", default="lgbm", choices=list(MODELS), help="reference model (default lgbm)")
    p.add_argument("--seed", type=int, default=0, help="model, sampling and bootstrap seed (default 0)")
    p.add_argument("--every", type=int, default=1, help="use every N-th frame of the generated datasets (default 1)")
    p.add_argument("--max-frames", type=int, default=None, help="at most this many frames of each generated dataset")
    p.add_argument("--max-points-per-scan", type=int, default=MAX_POINTS_PER_SCAN, help=f"background points sampled from each training scan (default {MAX_POINTS_PER_SCAN})")
    p.add_argument("--jobs", type=int, default=1, help="model threads (default 1)")
    p.add_argument("--steps", type=int, default=None, help="the networks' training steps, for --train's model and every --reference fold alike "
                   "(default: 12 passes over the --train frames in batches of 4, at least 120)")
    p.set_defaults(func=run_evaluate)


def _add_convert(sub) -> None:
    from .cli.convert import add_convert_arguments, convert_main

    p = sub.add_parser("convert", help="a dense real scan, labels carried, in a sparser sensor's pattern",
                       description="Resample a dense real scan (and its labels) into a sparser sensor preset's firings and write it as a dataset (docs/mixing.md).")
    add_convert_arguments(p).set_defaults(func=convert_main)


def _add_match(sub) -> None:
    from .cli.match import add_match_arguments, match_main

    p = sub.add_parser("match", help="fit object counts, distances and headings to labelled real scans; write them into a config",
                       description="Fit per-class object counts, distance and heading histograms (and the points-per-object curve) to "
                       "labelled real frames and write them as the builder's placement distributions (docs/match.md).")
    add_match_arguments(p).set_defaults(func=match_main)


def _add_realism(sub) -> None:
    from .evaluate.realism import add_realism_arguments, realism_main

    p = sub.add_parser("realism", help="compare a generated dataset with real labelled scans of the same sensor, per class",
                       description="Per class: intensity (Wasserstein distance, share saturated), points per object against range, returns per "
                       "row, range distribution; BEV occupancy JSD and MMD as the generative-LiDAR papers compute them. Prints what differs "
                       "most and writes a JSON report and a PNG (docs/evaluate.md).")
    add_realism_arguments(p).set_defaults(func=realism_main)


COMMANDS = [_add_run, _add_sensors, _add_fit, _add_config, _add_evaluate, _add_realism, _add_convert, _add_match]


def parser() -> argparse.ArgumentParser:
    from .cli import OneLineParser  # errors in one line, exit code 2

    p = OneLineParser(prog="bpy-pipeline", description="Synthetic labeled LiDAR point clouds: generate frames and the tools around them.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in COMMANDS:
        add(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code (2 on bad input)."""
    from .cli import guarded  # InputError, Ctrl-C and SIGTERM: one line, exit 2, 130, 143

    args = parser().parse_args(sys.argv[1:] if argv is None else argv)
    return guarded(args.func, args)


def console() -> None:
    """The ``bpy-pipeline`` script: :func:`main`, then :func:`~.cli.exit_process` (no teardown)."""
    from .cli import exit_process

    exit_process(main())


if __name__ == "__main__":
    console()
