"""``bpy-pipeline fit SCAN [SCAN ...] --out MODEL.yaml [--rings 32 ...]``: effect models fitted to real scans.

Ray drop and range noise models fitted to real organised scans (:mod:`bpy_pipeline.lidar.fit.fitting`), written
for ``effects.drop.model_file`` / ``effects.noise.model_file``; prints each drop model's held-out error.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .subcommand import Command


def fit_effects(args) -> int:
    """Fit drop and noise models to real organised scans and write a model file for the effects."""
    from dataclasses import replace

    from ..lidar.fit import fitting
    from ..lidar.effects.apply import write_model_file

    options = fitting.FitOptions()
    changes = {k: getattr(args, k) for k in fitting.FitOptions.__dataclass_fields__ if getattr(args, k, None) is not None}
    options = replace(options, **changes)
    if not (np.isfinite(options.min_range) and np.isfinite(options.max_range) and 0 < options.min_range < options.max_range):
        raise InputError(f"fit: need 0 < --min-range < --max-range, finite metres, got {options.min_range} and {options.max_range}")
    if not (np.isfinite(args.empty_radius) and args.empty_radius >= 0):
        raise InputError(f"--empty-radius: must be a finite number of metres >= 0, got {args.empty_radius}")
    if not (np.isfinite(options.intensity_scale) and options.intensity_scale > 0):
        raise InputError(f"--intensity-scale: must be a finite number > 0 (the intensity of an apparent reflectance of 1), got {options.intensity_scale}")
    # they multiply the work
    for key, least, most in (("folds", 0, fitting.MAX_FOLDS), ("mlp_steps", 1, fitting.MAX_MLP_STEPS), ("max_gap", 0, fitting.MAX_GAP)):
        if not least <= getattr(options, key) <= most:
            raise InputError(f"--{key.replace('_', '-')}: must lie in {least}..{most:,}, got {getattr(options, key):,}")
    if min(options.range_bins, options.incidence_bins, options.noise_range_bins, options.noise_incidence_bins, options.min_samples,
           options.mlp_range_bins, options.mlp_incidence_bins, options.mlp_steps) < 1 or options.seed < 0:
        raise InputError("fit: bin counts, --min-samples and --mlp-steps must be >= 1, --seed >= 0")
    from ..io.confined import refuse_output_over_input

    out = Path(args.out)
    refuse_output_over_input(out, args.scans)
    if not out.parent.is_dir() and (out.parent.exists() or any(p.exists() and not p.is_dir() for p in out.parents)):
        raise InputError(f"--out: {out.parent} is not a folder (a file stands in the path); give a path in a folder")
    if args.fields < 4 or not 0 <= args.intensity_field < args.fields or args.ring_field >= args.fields or args.rings < 1:
        raise InputError(
            "fit: need --fields >= 4 (x y z intensity), 0 <= --intensity-field < --fields, --ring-field < --fields and --rings >= 1; got --fields "
            f"{args.fields}, --intensity-field {args.intensity_field}, --ring-field {args.ring_field}, --rings {args.rings}"
        )
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
    print(
        f"mlp: {models.drop_mlp.parameters} weights over {options.mlp_range_bins} x {options.mlp_incidence_bins} bins with >= {options.min_samples} samples "
        f"(drop; noise likewise), seed {options.seed}"
    )
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


def arguments(p) -> None:
    from ..lidar.fit.fitting import FitOptions

    p.add_argument("scans", nargs="+", metavar="SCAN",
                   help="organised sweep(s): float32 .bin (x y z intensity ring per firing, column after column) or .npy (rings, columns, >= 4)")
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
        default = getattr(FitOptions, name)
        p.add_argument("--" + name.replace("_", "-"), dest=name, type=kind, default=None, help=f"{what} (default {default})")
    p.set_defaults(func=fit_effects)


COMMAND = Command(
    "fit", "fit ray drop and range noise to real organised scans",
    "Fit the uniform, threshold, table and mlp drop models and the range, table and mlp noise models to real "
    "organised scans (one sweep: gaps filled from ring neighbours; several sweeps of a static scene: per-pixel "
    "medians) and write a model file for effects.drop.model_file and effects.noise.model_file.",
    arguments,
)
