"""Intensity of the street's HDL-64E against real SemanticKITTI and KITTI remission, per class.

Generates a few frames of examples/street/ego_hdl64e.yaml (3 layouts x 2 frames) with the code of this
checkout, and compares, per class (car, person, road, sidewalk, building, vegetation, terrain, pole, other),
their intensity with the real remission of ../shared/real_scans (or ``BPY_PIPELINE_REAL_SCANS``):

- the share of points at the maximum (KITTI's top step, 0.99, or above), the number of distinct values, the
  10/50/90 % quantiles, and the Wasserstein-1 distance between the two distributions (0..1 units);
- two real sets: the **fit** frames the hdl64e intensity law and the street's materials were fitted on
  (SemanticKITTI seq08 000720 and spvnas 000000, KITTI object 004747) and the **check** frames kept aside
  (KITTI object 000001, 000002, 000003, 000005; car, person and ``scene``, every other point in the front
  camera's view, compared with ours within +-40 deg of straight ahead);
- points per car and per person against range (median per range bin), ours against the real frames' labelled
  objects (SemanticKITTI instances, KITTI boxes): the drop that depends on reflectivity.

    python benchmarks/bench_intensity.py --before   # measure the checkout as "before": results/intensity_before.json
    python benchmarks/bench_intensity.py            # measure it as "after", beside the stored before: results/intensity_round21.json
    python benchmarks/bench_intensity.py --small    # 1 layout x 1 frame: that it runs
    python benchmarks/bench_intensity.py --fit      # refit the hdl64e reading on the fit frames: results/intensity_fit.json

The fit (``--fit``, :func:`fit_law`) simulates each real point of the fit frames' static classes from its range and
its class's reflectivity through the reading ``clip(s (a f(R))^gamma exp(sd z) - o, 0, 1)`` in 0.01 steps and matches
each class's 10/25/50/75/90 % quantiles in five range bins by Nelder-Mead; the classes' reflectivities are free about
the street's values before the fit (``PRIOR``) under a log-normal prior (sd 0.3).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bpy_pipeline.evaluate import labelled  # noqa: E402
from bpy_pipeline.io.ply import read_ply  # noqa: E402

REAL = Path(os.environ.get("BPY_PIPELINE_REAL_SCANS", ROOT.parent / "shared" / "real_scans"))
RESULTS = ROOT / "benchmarks" / "results"
CONFIG = ROOT / "examples" / "street" / "ego_hdl64e.yaml"
NAMED = ("car", "person", "road", "sidewalk", "building", "vegetation", "terrain", "pole")
CLASSES = (*NAMED, "other")
FIT_FRAMES = ("semantickitti_seq08_000720.bin", "semantickitti_spvnas_000000.bin", "kitti_hdl64e_004747.bin")
CHECK_FRAMES = ("kitti_hdl64e_000001.bin", "kitti_hdl64e_000002.bin", "kitti_hdl64e_000003.bin", "kitti_hdl64e_000005.bin")
AT_MAX = 0.99  # KITTI's remission tops out at 0.99 (steps of 0.01); ours at 1.0
FRONT_DEG = 40.0  # the KITTI camera's view, about +-40 deg of azimuth
RANGE_BINS = (0.0, 10.0, 20.0, 30.0, 50.0)


def remission(path: Path) -> np.ndarray:
    """(n,) float32 remission of a KITTI-layout .bin (x y z remission)."""
    return np.fromfile(path, np.float32).reshape(-1, 4)[:, 3]


def front(points: np.ndarray) -> np.ndarray:
    return np.abs(np.degrees(np.arctan2(points[:, 1], points[:, 0]))) <= FRONT_DEG


class Pool:
    """Intensities per class, and (points, range) per labelled car and person, gathered over frames."""

    def __init__(self):
        self.values: dict[str, list[np.ndarray]] = {}
        self.objects: dict[str, list[tuple[int, float]]] = {"car": [], "person": []}

    def add(self, name: str, values: np.ndarray) -> None:
        if len(values):
            self.values.setdefault(name, []).append(np.asarray(values, np.float64))

    def add_scan(self, scan: labelled.LabelledScan, intensity: np.ndarray, scene_view: np.ndarray | None, kitti_boxes: bool) -> None:
        """Per class of ``scan.classes`` (KITTI boxes: car and person only); ``scene``: the rest within ``scene_view``."""
        other = len(scan.classes)
        for k, name in enumerate(scan.classes):
            self.add(name, intensity[scan.labels == k])
        if not kitti_boxes:
            self.add("other", intensity[scan.labels == other])
        if scene_view is not None:
            car_person = np.isin(scan.labels, [scan.classes.index("car"), scan.classes.index("person")])
            self.add("scene", intensity[scene_view & (scan.labels >= 0) & ~car_person])
        for name in self.objects:
            k = scan.classes.index(name)
            for obj in np.unique(scan.instances[scan.labels == k]):
                if obj < 0:
                    continue
                mine = scan.instances == obj
                self.objects[name].append((int(mine.sum()), float(np.median(np.linalg.norm(scan.points[mine], axis=1)))))

    def get(self, name: str) -> np.ndarray:
        parts = self.values.get(name, [])
        return np.concatenate(parts) if parts else np.zeros(0)


def real_pool(frames) -> Pool:
    pool = Pool()
    for name in frames:
        path = REAL / name
        kitti = name.startswith("kitti_")
        scan = labelled.load_scans([path], ("car", "person") if kitti else NAMED)[0]
        pool.add_scan(scan, remission(path), scan.labels >= 0 if kitti else None, kitti)
    return pool


def generate(out: Path, layouts: int, frames: int) -> None:
    """``layouts`` street layouts x ``frames`` frames of the ego HDL-64E, written as PLY under ``out/layoutK``."""
    for k in range(layouts):
        subprocess.run([sys.executable, str(ROOT / "run.py"), "--config", str(CONFIG), "--out", str(out / f"layout{k}"), "--frames", str(frames),
                        "--seed", str(100 + k), "--overwrite", "--set", f"scene.layout_seed={100 + k}", "--set", "output.formats=[ply]",
                        "--set", "output.preview=false", "--set", "output.boxes.formats=[]"], check=True, stdout=subprocess.DEVNULL, cwd=ROOT)


def ours_pool(folder: Path) -> Pool:
    pool = Pool()
    for d in sorted(folder.glob("layout*")):
        for scan in labelled.load_scans([d], NAMED):
            intensity = read_ply(scan.source)["intensity"]
            pool.add_scan(scan, intensity, front(scan.points), False)
    return pool


def wasserstein(a: np.ndarray, b: np.ndarray) -> float:
    """Wasserstein-1 distance of two 1-D samples: the mean absolute gap of their quantile functions (1001 quantiles)."""
    q = np.linspace(0.0, 1.0, 1001)
    return float(np.mean(np.abs(np.quantile(a, q) - np.quantile(b, q))))


def describe(values: np.ndarray) -> dict:
    if len(values) == 0:
        return {"points": 0}
    q = np.quantile(values, [0.1, 0.5, 0.9])
    return {"points": int(len(values)), "at_max_pct": round(100 * float(np.mean(values >= AT_MAX - 1e-6)), 2), "distinct": int(len(np.unique(values))),
            "q10": round(float(q[0]), 3), "median": round(float(q[1]), 3), "q90": round(float(q[2]), 3)}


def compare(ours: Pool, real: Pool, names) -> list[dict]:
    rows = []
    for name in names:
        a, b = ours.get(name), real.get(name)
        row = {"class": name, **{f"ours_{k}": v for k, v in describe(a).items()}, **{f"real_{k}": v for k, v in describe(b).items()}}
        row["wasserstein"] = round(wasserstein(a, b), 4) if len(a) and len(b) else None
        rows.append(row)
    return rows


def per_object(pool: Pool) -> dict:
    """Median points per car and per person in each range bin: ``{class: [{range, objects, median_points}]}``."""
    out = {}
    for name, objects in pool.objects.items():
        counts, ranges = np.array([c for c, _ in objects] or [0]), np.array([r for _, r in objects] or [np.inf])
        rows = []
        for lo, hi in zip(RANGE_BINS[:-1], RANGE_BINS[1:]):
            mine = (ranges >= lo) & (ranges < hi)
            rows.append({"range_m": f"{lo:g}-{hi:g}", "objects": int(mine.sum()), "median_points": float(np.median(counts[mine])) if mine.any() else None})
        out[name] = rows
    return out


def measure(layouts: int, frames: int, keep: Path | None) -> dict:
    with tempfile.TemporaryDirectory(prefix="bench_intensity_") as tmp:
        out = keep or Path(tmp)
        generate(out, layouts, frames)
        ours = ours_pool(out)
    fit, check = real_pool(FIT_FRAMES), real_pool(CHECK_FRAMES)
    everything = real_pool(FIT_FRAMES + CHECK_FRAMES)
    return {"fit": compare(ours, fit, CLASSES), "check": compare(ours, check, ("car", "person", "scene")),
            "points_per_object": {"ours": per_object(ours), "real": per_object(everything)}}


def print_table(title: str, rows: list[dict]) -> None:
    print(f"\n{title}")
    print(f"{'class':11s} {'ours max%':>9s} {'real max%':>9s} {'ours dist':>9s} {'real dist':>9s} {'ours med':>8s} {'real med':>8s} {'W1':>7s}")
    for r in rows:
        print(
            f"{r['class']:11s} {r.get('ours_at_max_pct', ''):>9} {r.get('real_at_max_pct', ''):>9} {r.get('ours_distinct', ''):>9} "
            f"{r.get('real_distinct', ''):>9} "
            f"{r.get('ours_median', ''):>8} {r.get('real_median', ''):>8} {r['wasserstein'] if r['wasserstein'] is not None else '':>7}"
        )


PRIOR = {"road": 0.12, "sidewalk": 0.25, "building": 0.4, "vegetation": 0.5, "terrain": 0.4, "pole": 0.3}  # the street's values before the fit
FIT_BINS = (0.0, 10.0, 20.0, 30.0, 40.0, 60.0)
QUANTILES = np.array([0.1, 0.25, 0.5, 0.75, 0.9])


def fit_law(seed: int = 0) -> dict:
    """The hdl64e reading's ``scale, response, offset, compensated_range, exponent`` and total log sd, and the static
    classes' reflectivities, fitted on the SemanticKITTI fit frames (module notes)."""
    from scipy.optimize import minimize

    groups = []
    for name in FIT_FRAMES:
        if not name.startswith("semantickitti"):
            continue
        scan = labelled.load_scans([REAL / name], NAMED)[0]
        value, distance = remission(REAL / name), np.linalg.norm(scan.points, axis=1)
        for k, cls in enumerate(NAMED):
            if cls in PRIOR:
                groups.append((cls, value[scan.labels == k], distance[scan.labels == k]))
    binned, draw = [], np.random.default_rng(seed)
    for cls in PRIOR:
        value = np.concatenate([g[1] for g in groups if g[0] == cls])
        distance = np.concatenate([g[2] for g in groups if g[0] == cls])
        for lo, hi in zip(FIT_BINS[:-1], FIT_BINS[1:]):
            mine = np.flatnonzero((distance >= lo) & (distance < hi))
            if len(mine) >= 80:
                mine = draw.permutation(mine)[:4000]
                binned.append((cls, np.quantile(value[mine], QUANTILES), distance[mine], draw.standard_normal(len(mine))))
    names = list(PRIOR)

    def unpack(x):
        return x[:6], dict(zip(names, np.exp(x[6:])))

    def loss(x):
        (s, gamma, o, rc, e, sd), rho = unpack(x)
        if s <= 0 or not 0.02 < gamma <= 2 or not 5 <= rc <= 80 or not 0 <= e <= 20 or not 0 <= sd <= 1 or o < -0.5:
            return 1e3
        total = 0.0
        for cls, real, distance, z in binned:
            f = np.minimum(1.0, (rc / np.maximum(distance, 1e-3)) ** e)
            sim = np.clip(np.round(s * (rho[cls] * f) ** gamma * np.exp(sd * z) - o, 2), 0.0, 0.99)
            total += float(np.sum((np.quantile(sim, QUANTILES) - real) ** 2))
        return total + 0.01 * sum((math.log(rho[n] / PRIOR[n]) / 0.3) ** 2 for n in names)

    best = None
    for start in ([0.87, 0.23, 0.34, 21.5, 2.6, 0.16], [0.67, 0.3, 0.13, 25.0, 3.9, 0.25]):
        x0 = np.array(start + [math.log(PRIOR[n]) for n in names])
        res = minimize(loss, x0, method="Nelder-Mead", options={"maxiter": 6000, "maxfev": 6000, "xatol": 1e-4, "fatol": 1e-7, "adaptive": True})
        if best is None or res.fun < best.fun:
            best = res
    (s, gamma, o, rc, e, sd), rho = unpack(best.x)
    return {"frames": [f for f in FIT_FRAMES if f.startswith("semantickitti")], "loss": round(float(best.fun), 4),
            "law": {"scale": round(s, 3), "response": round(gamma, 3), "offset": round(o, 3), "compensated_range": round(rc, 1), "exponent": round(e, 2),
                    "log_sd": round(sd, 3)},
            "reflectivity": {n: round(v, 3) for n, v in rho.items()}, "prior": PRIOR}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", action="store_true", help="store this checkout's figures as the before (intensity_before.json)")
    p.add_argument("--small", action="store_true", help="1 layout x 1 frame: that it runs")
    p.add_argument("--keep", type=Path, help="write the generated frames here (kept) instead of a temporary folder")
    p.add_argument("--out", type=Path, default=RESULTS, help="folder for the JSON results")
    p.add_argument("--fit", action="store_true", help="refit the hdl64e reading and the static classes' reflectivities (intensity_fit.json)")
    args = p.parse_args()
    if not all((REAL / f).is_file() for f in FIT_FRAMES + CHECK_FRAMES):
        print(f"SKIP: the real scans are not at {REAL} (set BPY_PIPELINE_REAL_SCANS)")
        return
    if args.fit:
        fitted = fit_law()
        print(json.dumps(fitted, indent=2))
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "intensity_fit.json").write_text(json.dumps({"benchmark": "intensity_fit", **fitted}, indent=2) + "\n")
        return
    layouts, frames = (1, 1) if args.small else (3, 2)
    result = {"frames": {"ours": f"{layouts} layouts x {frames} frames of {CONFIG.relative_to(ROOT)} (scene.layout_seed 100..)", "fit": list(FIT_FRAMES),
                         "check": list(CHECK_FRAMES)},
              **measure(layouts, frames, args.keep)}
    print_table("fit frames", result["fit"])
    print_table("check frames", result["check"])
    for name, rows in result["points_per_object"]["ours"].items():
        real = result["points_per_object"]["real"][name]
        print(
            f"points per {name}: "
            + ", ".join(f"{o['range_m']} m ours {o['median_points']} ({o['objects']}) real {r['median_points']} ({r['objects']})" for o, r in zip(rows, real))
        )
    args.out.mkdir(parents=True, exist_ok=True)
    if args.before:
        (args.out / "intensity_before.json").write_text(json.dumps({"benchmark": "intensity_before", **result}, indent=2) + "\n")
        return
    before_file = args.out / "intensity_before.json"
    before = json.loads(before_file.read_text()) if before_file.is_file() else None
    summary = []
    for part in ("fit", "check"):
        old = {r["class"]: r for r in before[part]} if before else {}
        for r in result[part]:
            b = old.get(r["class"], {})
            summary.append({"frames": part, "class": r["class"], "at_max_pct_before": b.get("ours_at_max_pct"), "at_max_pct_after": r.get("ours_at_max_pct"),
                            "distinct_before": b.get("ours_distinct"), "distinct_after": r.get("ours_distinct"), "median_before": b.get("ours_median"),
                            "median_after": r.get("ours_median"), "median_real": r.get("real_median"), "w1_before": b.get("wasserstein"),
                            "w1_after": r["wasserstein"],
                            "w1_ratio": round(r["wasserstein"] / b["wasserstein"], 3) if b.get("wasserstein") and r["wasserstein"] is not None else None})
    name = "intensity_small" if args.small else "intensity_round21"
    (args.out / f"{name}.json").write_text(json.dumps({"benchmark": name, "summary": summary, "after": result, "before": before}, indent=2) + "\n")
    print(f"\nbefore -> after (W1 ratio under 0.5 and at max under 2 % is the target): {args.out / (name + '.json')}")
    for s in summary:
        print(
            f"  {s['frames']:5s} {s['class']:10s} max% {s['at_max_pct_before']} -> {s['at_max_pct_after']}  W1 {s['w1_before']} -> {s['w1_after']} "
            f"(x{s['w1_ratio']})"
        )


if __name__ == "__main__":
    main()
