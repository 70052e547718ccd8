"""``bpy-pipeline realism``: a generated dataset beside real labelled scans of the same sensor, per class.

What it measures (every figure: generated against real; a class only on the real scans that label it):

- **intensity** per class, over the real scans that carry remission: the 1-Wasserstein distance between the two
  distributions (0..1 units of remission), the share of points saturated (remission >= :data:`SATURATED`),
  the number of distinct values and the median;
- **points per object against range** per object class: each object's point count and median range; per range
  band (:data:`RANGE_BANDS`) the median and the 90th percentile count of either side; the ratio is that of the
  90th percentiles (the best-seen objects of the band, so that how many objects stand half hidden weighs less),
  over all bands the geometric mean of the bands' ratios, weighted by the real objects in each. Objects of fewer
  than :data:`MIN_OBJECT_POINTS` points are left out on both sides (real sources without instance ids are split
  into objects by linking points within 0.5 m, which leaves far objects in one-point pieces), and a band
  needs :data:`MIN_OBJECTS` real objects for a ratio;
- **returns per row** (the drop pattern): the share of each row's pixels of the 64-row range image
  (:mod:`.projection`) that hold a return, within +-45 degrees of straight ahead (the field every real scan
  covers), averaged over the scans;
- **range distribution** per class: the 1-Wasserstein distance between the ranges of the class's points, metres;
- **bird's-eye-view occupancy**, as the generative-LiDAR papers compute it (LiDARGen, "Learning to Generate
  Realistic LiDAR Point Clouds", and "LiDAR Diffusion Models" after it): each scan's x, y histogram over a
  160 m x 160 m field centred on the sensor in 100 x 100 cells; **JSD**: the Jensen-Shannon divergence
  (base 2, 0..1) of the two sets' summed, normalised histograms; **MMD**: squared maximum mean discrepancy of
  the per-scan normalised histograms under a Gaussian kernel on their Euclidean distance (sigma 0.5), as
  GraphRNN's ``compute_mmd`` that those papers use. Real scans cropped to the camera's view (SqueezeSeg's
  front 90 degrees) are left out of it.

Every per-class figure (intensity, points per object, ranges) reads the points within +-:data:`LABELLED_DEG` of straight
ahead on both sides: KITTI's object frames label only what their camera sees (+-40.7 degrees) and SqueezeSeg's frames
hold only the front 90 degrees, so a class's real points lie there, and a generated frame's cars beside the sensor
(which no real box-labelled frame labels) would otherwise read as a range gap that is none.

:func:`findings` turns the figures into sentences ranked by how far apart the two sides are; :func:`plot`
draws one PNG of them. Pure numpy, scipy and matplotlib (the plot); never imports bpy.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..errors import InputError
from .label_maps import parse_classes
from .labelled import LabelledScan, load_scans
from .projection import ROWS, pixels

SATURATED = 0.99  # remission at or above this is saturated (1.0 is the top of both scales)
RANGE_BANDS = (0.0, 10.0, 20.0, 30.0, 50.0, 80.0)  # metres
OBJECT_CLASSES = ("car", "truck", "other-vehicle", "person", "bicyclist")
MIN_OBJECT_POINTS = 5
MIN_OBJECTS = 3  # real objects in a range band for its ratio
FRONT_DEG = 45.0  # returns per row: azimuths within this of straight ahead
LABELLED_DEG = 40.0  # per-class figures: azimuths within this of straight ahead, the field every real source labels (KITTI's camera: +-40.7)
BEV_FIELD_M = 160.0
BEV_BINS = 100
MMD_SIGMA = 0.5
FRONT_ONLY_SPAN_DEG = 120.0  # a scan whose azimuths span less is cropped to the camera's view: left out of the BEV figures
DEFAULT_CLASSES = ("car", "truck", "other-vehicle", "person", "bicyclist", "road", "sidewalk", "parking", "building", "fence",
                   "vegetation", "trunk", "terrain", "pole", "traffic-sign")  # fmt: skip


# ----------------------------------------------------------------------------- the measures
def intensity_figures(generated: np.ndarray, real: np.ndarray) -> dict:
    """Wasserstein distance, saturated share, distinct values and median of two remission samples (NaN when one is empty)."""
    from scipy.stats import wasserstein_distance

    def side(v):
        if not len(v):
            return {"points": 0, "saturated": math.nan, "distinct": 0, "median": math.nan}
        return {"points": int(len(v)), "saturated": float(np.mean(v >= SATURATED)), "distinct": int(len(np.unique(v))), "median": float(np.median(v))}

    both = len(generated) and len(real)
    return {"wasserstein": float(wasserstein_distance(generated, real)) if both else math.nan, "generated": side(generated), "real": side(real)}


def in_labelled_field(points: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: ``(n, 3)`` sensor-frame points within +-:data:`LABELLED_DEG` of straight ahead (x forward)."""
    return np.abs(np.degrees(np.arctan2(points[:, 1], points[:, 0]))) <= LABELLED_DEG


def class_points(scan: LabelledScan, c: int) -> np.ndarray:
    """``(n,)`` bool: the scan's points of class index ``c`` in the labelled field (:func:`in_labelled_field`)."""
    return (scan.labels == c) & in_labelled_field(scan.points)


def object_sizes(scans: Sequence[LabelledScan], c: int) -> np.ndarray:
    """``(k, 2)`` float64 rows of (points, median range m) of every object of class index ``c`` with at least
    :data:`MIN_OBJECT_POINTS` points in the labelled field (:func:`class_points`)."""
    rows = []
    for scan in scans:
        mask = class_points(scan, c)
        if not mask.any():
            continue
        ids, inverse = np.unique(scan.instances[mask], return_inverse=True)
        ranges = np.linalg.norm(scan.points[mask], axis=1)
        for k in range(len(ids)):
            rows.append((float(np.sum(inverse == k)), float(np.median(ranges[inverse == k]))))
    out = np.array(rows, np.float64).reshape(-1, 2)
    return out[out[:, 0] >= MIN_OBJECT_POINTS]


def points_per_object(generated: np.ndarray, real: np.ndarray) -> dict:
    """Per range band the objects, median and 90th-percentile points of either side and their ratio; ``ratio``: over all bands."""
    bands = []
    logs, weights = [], []
    for lo, hi in zip(RANGE_BANDS[:-1], RANGE_BANDS[1:]):
        g = generated[(generated[:, 1] >= lo) & (generated[:, 1] < hi), 0]
        r = real[(real[:, 1] >= lo) & (real[:, 1] < hi), 0]
        row = {"band_m": [lo, hi], "generated_objects": int(len(g)), "real_objects": int(len(r)),
               "generated_median": float(np.median(g)) if len(g) else math.nan, "real_median": float(np.median(r)) if len(r) else math.nan,
               "generated_p90": float(np.percentile(g, 90)) if len(g) else math.nan, "real_p90": float(np.percentile(r, 90)) if len(r) else math.nan}
        row["ratio"] = row["generated_p90"] / row["real_p90"] if len(g) and len(r) >= MIN_OBJECTS else math.nan
        if math.isfinite(row["ratio"]) and row["ratio"] > 0:
            logs.append(math.log(row["ratio"]))
            weights.append(len(r))
        bands.append(row)
    ratio = math.exp(float(np.average(logs, weights=weights))) if logs else math.nan
    return {"bands": bands, "ratio": ratio, "generated_objects": int(len(generated)), "real_objects": int(len(real))}


def returns_per_row(scans: Sequence[LabelledScan]) -> np.ndarray:
    """``(ROWS,)`` mean share of each row's pixels holding a return, within +-:data:`FRONT_DEG` of straight ahead."""
    width = 512
    lo, hi = int(width * (0.5 - FRONT_DEG / 360)), int(width * (0.5 + FRONT_DEG / 360))
    shares = []
    for scan in scans:
        row, column = pixels(scan.points, ROWS, width)
        hit = np.zeros((ROWS, width), bool)
        hit[row, column] = True
        shares.append(hit[:, lo:hi].mean(axis=1))
    return np.mean(shares, axis=0) if shares else np.full(ROWS, np.nan)


def bev_histogram(points: np.ndarray) -> np.ndarray:
    """``(BEV_BINS, BEV_BINS)`` float64 x, y histogram over the :data:`BEV_FIELD_M` square centred on the sensor."""
    half = BEV_FIELD_M / 2
    return np.histogram2d(points[:, 0], points[:, 1], bins=BEV_BINS, range=[[-half, half], [-half, half]])[0]


def jsd(p: np.ndarray, q: np.ndarray) -> float:
    """Jensen-Shannon divergence, base 2 (0..1), of two histograms (normalised here)."""
    p = p.ravel() / max(p.sum(), 1e-12)
    q = q.ravel() / max(q.sum(), 1e-12)
    m = 0.5 * (p + q)

    def kl(a, b):
        keep = a > 0
        return float(np.sum(a[keep] * np.log2(a[keep] / b[keep])))

    return 0.5 * kl(p, m) + 0.5 * kl(q, m)


def mmd(x: np.ndarray, y: np.ndarray, sigma: float = MMD_SIGMA) -> float:
    """Squared MMD of two sets of histograms ``(a, d)``, ``(b, d)`` (each normalised to sum 1) under
    ``exp(-|u - v|^2 / (2 sigma^2))``."""
    x = x / np.maximum(x.sum(axis=1, keepdims=True), 1e-12)
    y = y / np.maximum(y.sum(axis=1, keepdims=True), 1e-12)

    def k(a, b):
        d2 = np.maximum((a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2 * a @ b.T, 0.0)
        return np.exp(-d2 / (2 * sigma * sigma)).mean()

    return float(k(x, x) + k(y, y) - 2 * k(x, y))


def azimuth_span_deg(points: np.ndarray) -> float:
    """The azimuth span of a scan's points (degrees; 360 for a full turn), from a 1-degree histogram."""
    if not len(points):
        return 0.0
    occupied = np.histogram(np.degrees(np.arctan2(points[:, 1], points[:, 0])), bins=360, range=(-180, 180))[0] > 0
    return float(occupied.sum())


# ----------------------------------------------------------------------------- the report
def realism_report(generated: Iterable[str | Path], real: Iterable[str | Path], classes: str | Sequence[str] = DEFAULT_CLASSES,
                   plot: str | Path | None = None) -> dict:
    """Compare the generated datasets with the real labelled scans (module notes); write the PNG to ``plot`` if given."""
    classes = parse_classes(classes)
    gen = load_scans(list(generated), classes)
    rea = load_scans(list(real), classes)
    if not gen:
        raise InputError("--generated: no generated frame")
    if not rea:
        raise InputError("--real: no real labelled scan")
    report: dict = {"classes": list(classes), "generated": [s.name for s in gen], "real": [s.name for s in rea], "labelled_field_deg": LABELLED_DEG,
                    "saturated_at": SATURATED, "intensity": {}, "points_per_object": {}, "range_wasserstein_m": {}}
    from scipy.stats import wasserstein_distance

    gen_i = [s for s in gen if s.remission is not None]
    real_i = [s for s in rea if s.remission is not None]
    report["real_without_remission"] = [s.name for s in rea if s.remission is None]
    for c, name in enumerate(classes):
        g = np.concatenate([s.remission[class_points(s, c)] for s in gen_i] or [np.zeros(0)])
        r = np.concatenate([s.remission[class_points(s, c)] for s in real_i if s.knows(name)] or [np.zeros(0)])
        report["intensity"][name] = intensity_figures(g, r)
        gr = np.concatenate([np.linalg.norm(s.points[class_points(s, c)], axis=1) for s in gen] or [np.zeros(0)])
        rr = np.concatenate([np.linalg.norm(s.points[class_points(s, c)], axis=1) for s in rea if s.knows(name)] or [np.zeros(0)])
        report["range_wasserstein_m"][name] = float(wasserstein_distance(gr, rr)) if len(gr) and len(rr) else math.nan
        if name in OBJECT_CLASSES:
            report["points_per_object"][name] = points_per_object(object_sizes(gen, c), object_sizes([s for s in rea if s.knows(name)], c))
    all_g = np.concatenate([s.remission for s in gen_i] or [np.zeros(0)])
    all_r = np.concatenate([s.remission for s in real_i] or [np.zeros(0)])
    report["intensity_all_points"] = intensity_figures(all_g, all_r)
    report["returns_per_row"] = {"generated": returns_per_row(gen).tolist(), "real": returns_per_row(rea).tolist(), "front_deg": FRONT_DEG}
    full = [s for s in rea if azimuth_span_deg(s.points) >= FRONT_ONLY_SPAN_DEG]
    hg = np.stack([bev_histogram(s.points).ravel() for s in gen])
    hr = np.stack([bev_histogram(s.points).ravel() for s in full]) if full else np.zeros((0, BEV_BINS * BEV_BINS))
    report["bev"] = {"field_m": BEV_FIELD_M, "bins": BEV_BINS, "real_scans": [s.name for s in full],
                     "jsd": jsd(hg.sum(0), hr.sum(0)) if len(hr) else math.nan, "mmd": mmd(hg, hr) if len(hr) else math.nan}
    report["findings"] = findings(report)
    if plot is not None:
        draw(report, Path(plot), hg.sum(0).reshape(BEV_BINS, BEV_BINS), hr.sum(0).reshape(BEV_BINS, BEV_BINS) if len(hr) else None)
        report["plot"] = str(plot)
    return report


def findings(report: dict) -> list[dict]:
    """Sentences on what differs, most first: ``{score, what, text}``. Scores are on comparable 0..1-ish scales:
    intensity Wasserstein and saturated-share gap (remission units), |log2| of the points-per-object ratio,
    mean gap of returns per row, range Wasserstein / 20 m, BEV JSD."""
    out = []
    for name, f in report["intensity"].items():
        g, r = f["generated"], f["real"]
        if not (g["points"] and r["points"]):
            continue
        gap = abs(g["saturated"] - r["saturated"])
        out.append({"score": max(f["wasserstein"], gap), "what": f"intensity {name}",
                    "text": f"{name} intensity: {100 * g['saturated']:.1f} % of generated points saturated (real {100 * r['saturated']:.1f} %), "
                            f"median {g['median']:.2f} vs {r['median']:.2f}, {g['distinct']} distinct values vs {r['distinct']}; "
                            f"Wasserstein {f['wasserstein']:.3f}"})
    for name, f in report["points_per_object"].items():
        if math.isfinite(f["ratio"]):
            word = "more" if f["ratio"] > 1 else "fewer"
            out.append({"score": abs(math.log2(f["ratio"])), "what": f"points per object {name}",
                        "text": f"{name}: generated objects return {f['ratio']:.2f}x the points of real ones at the same range (90th percentiles) "
                                f"({word}; {f['generated_objects']} generated, {f['real_objects']} real objects)"})
    rows = report["returns_per_row"]
    g, r = np.array(rows["generated"]), np.array(rows["real"])
    if np.isfinite(g).all() and np.isfinite(r).all():
        worst = int(np.argmax(np.abs(g - r)))
        out.append({"score": float(np.mean(np.abs(g - r))), "what": "returns per row",
                    "text": f"returns per row (drop pattern): {100 * g.mean():.1f} % of pixels return in the generated scans, {100 * r.mean():.1f} % in the "
                            f"real ones; the widest gap at row {worst} (0 = highest): {100 * g[worst]:.0f} % vs {100 * r[worst]:.0f} %"})
    for name, w in report["range_wasserstein_m"].items():
        if math.isfinite(w):
            out.append({"score": w / 20.0, "what": f"range {name}", "text": f"{name} ranges: Wasserstein {w:.1f} m between generated and real"})
    bev = report["bev"]
    if math.isfinite(bev["jsd"]):
        out.append(
            {
                "score": bev["jsd"],
                "what": "BEV occupancy",
                "text": f"bird's-eye-view occupancy: JSD {bev['jsd']:.3f}, MMD {bev['mmd']:.2e} (LiDAR Diffusion Models on KITTI-360: JSD 0.211, MMD 3.84e-4)",
            }
        )
    return sorted(out, key=lambda f: -f["score"])


def summary_lines(report: dict, top: int = 8) -> list[str]:
    """The ``top`` findings as lines, most different first."""
    return [f"{i + 1}. {f['text']}" for i, f in enumerate(report["findings"][:top])]


def draw(report: dict, path: Path, bev_generated: np.ndarray, bev_real: np.ndarray | None) -> None:
    """One PNG: intensity per class, points per object against range, returns per row, BEV occupancy of both sides."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(17, 9))
    names = [n for n, f in report["intensity"].items() if f["generated"]["points"] and f["real"]["points"]]
    x = np.arange(len(names))
    ax = axes[0, 0]
    ax.bar(x - 0.2, [100 * report["intensity"][n]["generated"]["saturated"] for n in names], 0.4, label="generated")
    ax.bar(x + 0.2, [100 * report["intensity"][n]["real"]["saturated"] for n in names], 0.4, label="real")
    ax.set_xticks(x, names, rotation=60, fontsize=7)
    ax.set_ylabel(f"% of points saturated (remission >= {SATURATED})")
    ax.set_title("Saturated intensity per class")
    ax.legend(fontsize=7)
    ax = axes[0, 1]
    ax.bar(x - 0.2, [report["intensity"][n]["generated"]["median"] for n in names], 0.4, label="generated median")
    ax.bar(x + 0.2, [report["intensity"][n]["real"]["median"] for n in names], 0.4, label="real median")
    ax.plot(x, [report["intensity"][n]["wasserstein"] for n in names], "k.-", label="Wasserstein distance")
    ax.set_xticks(x, names, rotation=60, fontsize=7)
    ax.set_ylabel("remission (0..1)")
    ax.set_title("Intensity per class")
    ax.legend(fontsize=7)
    ax = axes[0, 2]
    for name, colour in (("car", "C0"), ("person", "C3"), ("bicyclist", "C2")):
        f = report["points_per_object"].get(name)
        if not f:
            continue
        mid = [0.5 * (b["band_m"][0] + b["band_m"][1]) for b in f["bands"]]
        ax.plot(mid, [b["generated_p90"] for b in f["bands"]], "o-", color=colour, label=f"{name} generated ({f['ratio']:.2f}x real)")
        ax.plot(mid, [b["real_p90"] for b in f["bands"]], "s--", color=colour, label=f"{name} real")
    ax.set_yscale("log")
    ax.set_xlabel("median range of the object (m)")
    ax.set_ylabel("points per object (90th percentile of the band)")
    ax.set_title("Points per object against range")
    ax.legend(fontsize=7)
    ax = axes[1, 0]
    rows = report["returns_per_row"]
    ax.plot(rows["generated"], label="generated")
    ax.plot(rows["real"], label="real")
    ax.set_xlabel("row of the range image (0 = highest)")
    ax.set_ylabel(f"share of pixels with a return (+-{FRONT_DEG:.0f} deg ahead)")
    ax.set_title("Returns per row (drop pattern)")
    ax.legend(fontsize=7)
    half = BEV_FIELD_M / 2
    for ax, hist, title in ((axes[1, 1], bev_generated, "generated"), (axes[1, 2], bev_real, "real")):
        if hist is None:
            ax.set_axis_off()
            continue
        ax.imshow(np.log1p(hist / max(hist.sum(), 1) * 1e4).T, origin="lower", extent=[-half, half, -half, half], cmap="magma")
        ax.set_title(f"BEV occupancy, {title} (log)" + (f": JSD {report['bev']['jsd']:.3f}, MMD {report['bev']['mmd']:.1e}" if title == "real" else ""))
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    fig.suptitle("Realism: generated against real scans of the same sensor. Most different: " + (report["findings"][0]["what"] if report["findings"] else "-"))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


# ----------------------------------------------------------------------------- the command
def add_realism_arguments(p):
    """The ``realism`` command's options."""
    p.add_argument("--generated", action="append", required=True, metavar="DATASET", help="a generated dataset folder (ply/), repeatable")
    p.add_argument("--real", action="append", required=True, metavar="REAL", help="real labelled scans of the same sensor, or a folder of them (repeatable)")
    p.add_argument("--classes", default=",".join(DEFAULT_CLASSES), help="classes, SemanticKITTI training names (default: the 15 the street holds)")
    p.add_argument("--out", required=True, metavar="REPORT.json", help="the JSON report to write")
    p.add_argument("--plot", metavar="PLOT.png", default=None, help="the PNG to write (default: beside --out)")
    return p


def realism_main(args) -> int:
    """Run the comparison, print the findings, write the report and the plot."""
    from ..io.confined import refuse_output_over_input
    from .run import write_report

    out = Path(args.out)
    if out.is_dir():
        raise InputError(f"--out: {out} is a folder; give a file path")
    plot = Path(args.plot) if args.plot else out.with_suffix(".png")
    inputs = [*args.generated, *args.real]
    refuse_output_over_input(out, inputs)
    refuse_output_over_input(plot, [*inputs, out], "--plot")
    report = realism_report(args.generated, args.real, args.classes, plot)
    write_report(out, report)
    print("What differs most, generated against real:")
    for line in summary_lines(report):
        print(line)
    print(f"written: {out}, {plot}")
    return 0
