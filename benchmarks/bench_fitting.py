"""Ray-drop models fitted to a real HDL-32E sweep: held-out error against parameters and cost.

The nuScenes sweep (../shared/real_scans/nuscenes_hdl32e_sweep.bin, 32 x 1084 firings) is read
as an organised scan (ego motion undone, gaps of up to 4 columns filled from ring neighbours,
incidence from local normals; lidar/fit/fitting.py). Each model is fitted on 7 of 8 blocks of 135
columns (45 degrees of azimuth) and scored on the eighth: mean negative log-likelihood per
firing (nats), paired fold by fold against the best model. "Within noise" = the mean paired
difference is at most one standard error. Cost: the model's drop decision (probability and
draw, effects.drop_mask) on a million points, best of five.
A scan simulated with each held-out fit (apply_effects on the real firings' geometry) gives
per-ring drop fractions and the drop fraction against range, beside the real ones.
Second result, fitting_mlp.json / .png: the ``mlp`` model (the Raphael paper's perceptron over
(range, incidence) bins with >= 100 firings) against the tables on the same held-out column
blocks: log-loss, Brier score and calibration (held-out predictions in 10 quantile bins,
predicted against observed drop; ECE = the firing-weighted mean gap).
Run: python benchmarks/bench_fitting.py [--small]
"""

import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np
from common import ROOT, arguments, best_of, report

from bpy_pipeline.config import effects_from_dict
from bpy_pipeline.lidar.fit import fitting
from bpy_pipeline.lidar.effects.apply import FittedModels, drop_mask, fitted_models, write_model_file

SCAN = ROOT.parent / "shared" / "real_scans" / "nuscenes_hdl32e_sweep.bin"
FOLDS = 8
RANGE = (2.0, 100.0)
TABLES = [(2, 1), (4, 1), (8, 1), (4, 2), (8, 2), (8, 4), (16, 4), (16, 8), (32, 8), (56, 16)]
NAMES = ["carla", "uniform", "threshold_n2", "threshold"] + [f"table {r}x{i}" for r, i in TABLES]
SIMPLEST_FIRST = ["carla", "uniform", "threshold_n2", "table 2x1", "threshold", "table 4x1", "table 4x2", "table 8x1", "table 8x2",
                  "table 8x4", "table 16x4", "table 16x8", "table 32x8", "table 56x16"]


def fitted_file(name: str, train: fitting.Samples, folder: Path) -> tuple[dict, str]:
    """The effects section and model file that reproduce ``name`` fitted on ``train``."""
    path = folder / "model.yaml"
    if name == "carla":
        return {"drop": {"model": "carla"}}, ""
    if name == "uniform":
        models, model = FittedModels(uniform=fitting.fit_uniform(train)), "uniform"
    elif name.startswith("threshold"):
        models, model = FittedModels(threshold=fitting.fit_threshold(train, 2.0 if name == "threshold_n2" else None)), "threshold"
    else:
        nr, ni = (int(v) for v in name.split()[1].split("x"))
        table = fitting.fit_drop_table(train, np.geomspace(*RANGE, nr + 1), fitting.incidence_edges(ni))
        models, model = FittedModels(drop_table=table), "table"
    write_model_file(path, models)
    return {"drop": {"model": model, "model_file": str(path)}}, str(path)


def simulate(samples, fold, name, folder, seed=0):
    """Held-out simulated drops: each fold's firings through apply_effects with the model fitted on the others."""
    dropped = np.zeros(len(samples), bool)
    for k in range(FOLDS):
        test = fold == k
        section, _ = fitted_file(name, samples.subset(~test), folder)
        dropped[test] = fitting.simulate_drops(samples.subset(test), effects_from_dict(section), np.random.default_rng([seed, k]))
    return dropped


def cost_per_million(name, samples, folder, n=1_000_000):
    """ms to decide the drops of a million points with ``name`` fitted on all samples."""
    rng = np.random.default_rng(0)
    pick = rng.integers(0, len(samples), n)
    points, beam = fitting.samples_as_points(samples.subset(pick))
    section, _ = fitted_file(name, samples, folder)
    effects = effects_from_dict(section)
    models = fitted_models(effects.drop)
    drop_mask(points, beam, effects, rng, models)  # warm: the table's raster is built once
    return 1000 * best_of(lambda: drop_mask(points, beam, effects, rng, models), 5) * 1e6 / n


def main():
    args = arguments(__doc__)
    if not SCAN.exists():
        print(f"skipped: {SCAN} is absent")
        return
    start = time.perf_counter()
    scan = fitting.read_scan(SCAN, 32)
    geometry = fitting.scan_geometry(scan)
    samples = fitting.drop_samples(scan, geometry, *RANGE)
    noise = fitting.noise_samples(scan, geometry, *RANGE)
    prepare_s = time.perf_counter() - start
    names = NAMES if not args.small else ["carla", "uniform", "threshold", "table 4x2", "table 8x4"]
    scores = fitting.cross_validate(samples, names, FOLDS, scan.shape[1], {"range": RANGE, "min_samples": 100})
    best, pick = fitting.simplest_within_noise(scores, [n for n in SIMPLEST_FIRST if n in scores])
    fold = fitting.column_folds(samples, FOLDS, scan.shape[1])
    rows, simulated = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name in names:
            diff = scores[name]["loss"] - scores[best]["loss"]
            se = float(diff.std(ddof=1) / math.sqrt(FOLDS))
            rows.append({
                "model": name, "parameters": scores[name]["parameters"],
                "held_out_nats_per_firing": float(scores[name]["loss"].mean()), "minus_best": float(diff.mean()), "se": se,
                "within_noise": bool(diff.mean() <= se),
                "cost_ms_per_Mpts": cost_per_million(name, samples, folder, 200_000 if args.small else 1_000_000),
            })
        for name in {"uniform", "threshold", pick} & set(names):
            simulated[name] = simulate(samples, fold, name, folder)

    rings = np.arange(scan.shape[0])
    real_ring = np.array([samples.dropped[samples.ring == k].mean() if (samples.ring == k).any() else np.nan for k in rings])
    sim_ring = {k: np.array([v[samples.ring == r].mean() if (samples.ring == r).any() else np.nan for r in rings]) for k, v in simulated.items()}
    edges = np.geomspace(*RANGE, 13)
    centre = np.sqrt(edges[:-1] * edges[1:])
    in_bin = [(samples.range >= lo) & (samples.range < hi) for lo, hi in zip(edges[:-1], edges[1:])]
    real_range = np.array([samples.dropped[m].mean() if m.any() else np.nan for m in in_bin])
    count_range = np.array([m.sum() for m in in_bin])
    sim_range = {k: np.array([v[m].mean() if m.any() else np.nan for m in in_bin]) for k, v in simulated.items()}
    raw_ring = (~scan.valid[0]).mean(axis=1)
    ring_rms = {k: float(np.sqrt(np.nanmean((v - real_ring) ** 2))) for k, v in sim_ring.items()}
    range_rms = {k: float(np.sqrt(np.nansum(count_range * (v - real_range) ** 2) / count_range.sum())) for k, v in sim_range.items()}
    noise_table = fitting.fit_noise_table(noise, np.geomspace(*RANGE, 9), fitting.incidence_edges(1), 100)

    notes = {
        "command": "python benchmarks/bench_fitting.py" + (" --small" if args.small else ""),
        "scan": str(SCAN.name), "firings": int(scan.valid.size), "empty": int((~scan.valid).sum()),
        "samples_with_known_target": len(samples), "dropped_among_them": int(samples.dropped.sum()),
        "filled_from_ring_neighbours": int(geometry.filled.sum()), "prepare_s": prepare_s,
        "folds": f"{FOLDS} blocks of {scan.shape[1] // FOLDS} columns", "best": best, "recommended": pick,
        "per_ring_drop_real_all_firings": [round(float(x), 4) for x in raw_ring],
        "per_ring_drop_real_known_target": [round(float(x), 4) for x in real_ring],
        "per_ring_drop_simulated": {k: [round(float(x), 4) for x in v] for k, v in sim_ring.items()},
        "per_ring_rms": ring_rms,
        "range_bin_centres_m": [round(float(x), 2) for x in centre], "drop_vs_range_real": [round(float(x), 4) for x in real_range],
        "drop_vs_range_simulated": {k: [round(float(x), 4) for x in v] for k, v in sim_range.items()},
        "drop_vs_range_rms_weighted": range_rms,
        "noise_sigma_mm_by_range": {f"{lo:.1f}-{hi:.1f}": (None if np.isnan(s) else round(1000 * float(s), 2))
                                    for lo, hi, s in zip(noise_table.range_edges[:-1], noise_table.range_edges[1:], noise_table.values[:, 0])},
    }
    name = "fitting" + ("_small" if args.small else "")
    report(name, rows, args.out, notes)
    print(f"best: {best}; simplest within noise of the best: {pick}")
    chart(rows, pick, real_ring, raw_ring, sim_ring, centre, real_range, sim_range, count_range, noise_table, args.out / f"{name}.png")
    mlp_comparison(samples, scan.shape[1], args)


MLP_NAMES = ["uniform", "table 4x2", "table 8x4", "mlp 8x4", "mlp 16x8"]


def calibration(p, dropped, bins=10):
    """Held-out predictions in ``bins`` quantile bins: (mean predicted, observed, firings) each, and the ECE."""
    order = np.argsort(p, kind="stable")
    groups = np.array_split(order, bins)
    pred = np.array([p[g].mean() for g in groups])
    obs = np.array([dropped[g].mean() for g in groups])
    n = np.array([len(g) for g in groups])
    return pred, obs, n, float(np.sum(n * np.abs(pred - obs)) / n.sum())


def mlp_comparison(samples, columns, args):
    """The mlp against the tables on held-out column blocks: log-loss, Brier, calibration; fitting_mlp.json and .png."""
    names = MLP_NAMES if not args.small else ["table 4x2", "mlp 8x4"]
    start = time.perf_counter()
    scores = fitting.cross_validate(samples, names, FOLDS, columns, {"range": RANGE, "min_samples": 100})
    cv_s = time.perf_counter() - start
    fold = fitting.column_folds(samples, FOLDS, columns)
    y = samples.dropped.astype(float)
    ref = "table 4x2"
    rows, curves = [], {}
    for name in names:
        p = scores[name]["p_drop"]
        brier = np.array([np.mean((p[fold == k] - y[fold == k]) ** 2) for k in range(FOLDS)])
        brier_ref = np.array([np.mean((scores[ref]["p_drop"][fold == k] - y[fold == k]) ** 2) for k in range(FOLDS)])
        diff = scores[name]["loss"] - scores[ref]["loss"]
        pred, obs, n, ece = calibration(p, samples.dropped)
        curves[name] = (pred, obs)
        rows.append({
            "model": name, "parameters": scores[name]["parameters"],
            "held_out_nats_per_firing": float(scores[name]["loss"].mean()), "minus_table_4x2": float(diff.mean()),
            "se": float(diff.std(ddof=1) / math.sqrt(FOLDS)), "brier": float(brier.mean()),
            "brier_minus_table_4x2": float((brier - brier_ref).mean()), "brier_se": float((brier - brier_ref).std(ddof=1) / math.sqrt(FOLDS)),
            "ece": ece, "calibration_predicted": [round(float(v), 4) for v in pred], "calibration_observed": [round(float(v), 4) for v in obs],
        })
    # the fitted surfaces on all firings, drop against range at three incidences
    r = np.geomspace(*RANGE, 60)
    surfaces = {}
    table = fitting.fit_drop_table(samples, np.geomspace(*RANGE, 5), fitting.incidence_edges(2))
    mlp = fitting.fit_drop_mlp(samples, np.geomspace(*RANGE, 9))
    for angle in (15.0, 45.0, 75.0):
        cos = np.full(len(r), math.cos(math.radians(angle)))
        surfaces[angle] = (table.lookup(r, cos), mlp.lookup(r, cos))
    edges = np.geomspace(*RANGE, 13)
    centre = np.sqrt(edges[:-1] * edges[1:])
    real = np.array([samples.dropped[(samples.range >= lo) & (samples.range < hi)].mean() for lo, hi in zip(edges[:-1], edges[1:])])
    name = "fitting_mlp" + ("_small" if args.small else "")
    notes = {
        "command": "python benchmarks/bench_fitting.py" + (" --small" if args.small else ""),
        "scan": SCAN.name, "samples_with_known_target": len(samples), "folds": f"{FOLDS} blocks of {columns // FOLDS} columns",
        "mlp": "the Raphael paper's method: (range, incidence) bins with >= 100 firings, each bin's (mean range, mean incidence, drop ratio), "
               "a perceptron with one tanh layer of 8 fitted to them by full-batch Adam (3000 steps, seed 0), bins weighted by firings",
        "reference": "table 4x2 (the fit default); minus_* are paired fold-by-fold differences, se one standard error",
        "cross_validation_s": cv_s,
    }
    report(name, [{k: v for k, v in row.items() if not k.startswith("calibration")} for row in rows], args.out, notes)
    payload = json.loads((args.out / f"{name}.json").read_text())
    payload["rows"] = rows  # with the calibration curves
    (args.out / f"{name}.json").write_text(json.dumps(payload, indent=2) + "\n")
    chart_mlp(rows, curves, r, surfaces, centre, real, args.out / f"{name}.png")


def chart_mlp(rows, curves, r, surfaces, centre, real, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(16, 4.8))
    for i, row in enumerate(rows):
        ax[0].errorbar(i, row["minus_table_4x2"], yerr=row["se"], fmt="o", capsize=3, color="tab:green" if row["model"].startswith("mlp") else "tab:blue")
    ax[0].set_xticks(range(len(rows)), [f"{row['model']}\n({row['parameters']} par.)" for row in rows], fontsize=7)
    ax[0].axhline(0, color="k", lw=0.5)
    ax[0].set_yscale("symlog", linthresh=0.002)
    ax[0].set_ylabel("held-out log-loss minus table 4x2 (nats / firing)")
    ax[0].set_title("held-out column blocks (8 x 45 deg), paired +- 1 SE")
    for name, (pred, obs) in curves.items():
        ax[1].plot(pred, obs, "o-", ms=3, label=f"{name} (ECE {next(x['ece'] for x in rows if x['model'] == name):.4f})")
    top = max(max(p.max(), o.max()) for p, o in curves.values())
    ax[1].plot([0, top], [0, top], "k:", lw=0.8)
    ax[1].set_xlabel("predicted drop probability (held out, decile means)")
    ax[1].set_ylabel("observed drop fraction")
    ax[1].set_title("calibration")
    ax[1].legend(fontsize=7)
    ax[2].plot(centre, real, "ko", label="real, all incidences")
    for (angle, (table, mlp)), colour in zip(surfaces.items(), ("tab:blue", "tab:orange", "tab:red")):
        ax[2].plot(r, table, "--", color=colour, lw=1, label=f"table 4x2, {angle:g} deg")
        ax[2].plot(r, mlp, "-", color=colour, label=f"mlp 8x4, {angle:g} deg")
    ax[2].set_xscale("log")
    ax[2].set_xlabel("range, m")
    ax[2].set_ylabel("drop probability")
    ax[2].set_title("fitted surfaces (all columns)")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"chart: {path}")


def chart(rows, pick, real_ring, raw_ring, sim_ring, centre, real_range, sim_range, count_range, noise_table, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(13, 9))
    shown = [r for r in rows if r["model"] != "carla"]
    for panel, key, label in ((ax[0, 0], "parameters", "parameters (measured bins for tables)"),
                              (ax[0, 1], "cost_ms_per_Mpts", "drop decision, ms per million points")):
        for r in shown:
            colour = "tab:green" if r["model"] == pick else ("tab:blue" if r["within_noise"] else "tab:grey")
            panel.errorbar(max(r[key], 0.5 if key == "parameters" else 0.1), r["minus_best"], yerr=r["se"], fmt="o", color=colour, capsize=3)
            panel.annotate(r["model"], (max(r[key], 0.5 if key == "parameters" else 0.1), r["minus_best"]), fontsize=7, xytext=(4, 3),
                           textcoords="offset points")
        panel.set_xscale("log")
        panel.set_yscale("symlog", linthresh=0.002)
        panel.axhline(0, color="k", lw=0.5)
        panel.set_xlabel(label)
        panel.set_ylabel("held-out loss minus the best (nats / firing)")
    carla = next((r for r in rows if r["model"] == "carla"), None)
    ax[0, 0].set_title("fit error on held-out columns" + (f" (CARLA defaults: +{carla['minus_best']:.2f}, off the chart)" if carla else ""))
    ax[0, 1].set_title(f"cost; green: recommended ({pick}), blue: within one SE of the best")
    rings = np.arange(len(real_ring))
    ax[1, 0].plot(rings, raw_ring, "k:", label="real, all firings (sky, own vehicle included)")
    ax[1, 0].plot(rings, real_ring, "ko-", label="real, firings with a known target")
    for k, v in sim_ring.items():
        ax[1, 0].plot(rings, v, ".-", label=f"simulated, {k} (held out)")
    ax[1, 0].set_xlabel("ring (0: lowest beam)")
    ax[1, 0].set_ylabel("drop fraction")
    ax[1, 0].legend(fontsize=7)
    ax[1, 0].set_title("per-ring drop: real HDL-32E sweep vs simulated")
    se = np.sqrt(np.maximum(real_range * (1 - real_range), 1e-4) / np.maximum(count_range, 1))
    ax[1, 1].errorbar(centre, real_range, yerr=2 * se, fmt="ko-", capsize=2, label="real (2 binomial SE)")
    for k, v in sim_range.items():
        ax[1, 1].plot(centre, v, ".-", label=f"simulated, {k}")
    twin = ax[1, 1].twinx()
    sig = noise_table.values[:, 0] * 1000
    rc = np.sqrt(noise_table.range_edges[:-1] * noise_table.range_edges[1:])
    twin.plot(rc, sig, "s--", color="tab:purple", alpha=0.6, label="range noise sigma, mm (one-sweep upper bound)")
    twin.set_yscale("log")
    twin.set_ylabel("noise sigma, mm", color="tab:purple")
    twin.legend(fontsize=7, loc="lower right")
    ax[1, 1].set_xscale("log")
    ax[1, 1].set_xlabel("range, m")
    ax[1, 1].set_ylabel("drop fraction")
    ax[1, 1].legend(fontsize=7, loc="upper left")
    ax[1, 1].set_title("drop fraction against range")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"chart: {path}")


if __name__ == "__main__":
    main()
