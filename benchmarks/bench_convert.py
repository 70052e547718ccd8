"""Sensor conversion with labels (bpy-pipeline convert): the parking paper's cone projection, the meshed ray cast and ours (hybrid).

1. Accuracy against a truth: a procedural street (bench_mixing's: ground, walls, boxes, eight cars) scanned by
   an HDL-64E at 1.73 m (the dense source, written as an organised scan with one instance id per object) and by
   the HDL-32E at 1.84 m (the truth). The source converted to the HDL-32E by each method through the command's
   own path (bpy_pipeline.cli.convert.convert, lift 0.11 m). Per method: milliseconds (best of N: reading the scan,
   recovering its firings and converting; the real scans' rows likewise), the share of
   the truth's returns reproduced (same ring and column), returns where the truth has none, the position error
   in the cells both have, and the share of those cells whose carried label (the object) is the truth's.
2. Per-ring statistics against a real sparser scan: the KITTI HDL-64E frame 004747 (and, without --small, the
   three SemanticKITTI sequence 01 frames) converted to the HDL-32E (lift 0.11 m: nuScenes' LIDAR_TOP sits about
   1.84 m up, KITTI's 1.73 m) beside the real nuScenes HDL-32E sweep: returns per ring (share of the ring's 1084
   columns), the median elevation of each ring's returns, and each ring's median range; summarised over the rings
   both sensors cover (the HDL-64E sees -24.9 .. +2 deg only, so HDL-32E rings 0-4 and 25-31 stay empty).
   The scenes differ (a German street or highway against a Boston or Singapore one), so ranges compare the
   sensors and the places together; elevations and ring coverage compare the sensors alone.
Run: python benchmarks/bench_convert.py [--small]
"""

import numpy as np
from bench_mixing import street_scene
from common import ROOT, arguments, best_of, report

from bpy_pipeline.cli.convert import convert
from bpy_pipeline.io.real_scans import read_real_scan
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
from bpy_pipeline.mixing.convert import METHODS
from bpy_pipeline.mixing.firings import recover_firings

REAL = ROOT.parent / "shared" / "real_scans"
NUSCENES = REAL / "nuscenes_hdl32e_sweep.bin"
KITTI = REAL / "kitti_hdl64e_004747.bin"
SEQ01 = [REAL / f"semantickitti_seq01_00000{k}_points.npy" for k in range(3)]
H_SOURCE, H_TARGET = 1.73, 1.84
NAMES = {"cones": "parking paper: cones", "mesh": "meshed ray cast", "hybrid": "ours: hybrid"}


def street_truth(tmp, seed: int = 7):
    """The street scanned by both sensors: ``(scan.npy, labels.npy, truth xyz (32, columns, 3), truth valid, truth object)``."""
    from bpy_pipeline.lidar.cast.raycast import RayCaster
    from bpy_pipeline.mixing.convert import target_rays

    buffers = street_scene(np.random.default_rng(seed))
    source, target = resolve_sensor({"preset": "hdl64e"}, "source"), resolve_sensor({"preset": "hdl32e"}, "target")
    grids = {}
    for name, spec, height in (("source", source, H_SOURCE), ("truth", target, H_TARGET)):
        directions, ring, column = target_rays(spec)
        frame = np.eye(4)
        frame[2, 3] = height
        hits = RayCaster(buffers, frame=frame).intersect(np.zeros(3), directions, spec.max_range)
        keep = hits.distance >= spec.min_range
        shape = (ring.max() + 1, column.max() + 1)
        xyz, valid, obj = np.zeros((*shape, 3)), np.zeros(shape, bool), np.zeros(shape, np.int64)
        r, c = ring[hits.ray[keep]], column[hits.ray[keep]]
        xyz[r, c] = directions[hits.ray[keep]] * hits.distance[keep, None]
        valid[r, c] = True
        obj[r, c] = buffers.triangle_object[hits.triangle[keep]] + 1
        grids[name] = (xyz, valid, obj)
    xyz, valid, obj = grids["source"]
    organised = np.concatenate([xyz, valid[..., None] * 0.5], axis=2).astype(np.float32)
    scan, labels = tmp / "street.npy", tmp / "street_labels.npy"
    np.save(scan, organised)
    np.save(labels, (np.where(valid, 10, 0) | (obj << 16)).T.reshape(-1).astype(np.int64))  # column after column, as the reader lists it
    return scan, labels, grids["truth"]


def accuracy(repeat: int, tmp) -> list[dict]:
    scan, labels, (truth, truth_valid, truth_obj) = street_truth(tmp)
    rows = []
    for method in METHODS:
        run = lambda: convert(scan, "hdl32e", labels, method, H_TARGET - H_SOURCE, label_space="raw")  # noqa: E731
        ms = best_of(run, repeat) * 1e3
        out = run()
        pts = out.points
        ring, column = pts["ring"].astype(np.int64), np.zeros(len(pts), np.int64)
        spec = resolve_sensor({"preset": "hdl32e"}, "t")
        from bpy_pipeline.lidar.sensor.sensors import azimuths

        az = np.degrees(np.arctan2(pts["y"], pts["x"]))
        line = np.asarray(azimuths(spec), float)
        column = np.round((az - line[0]) / (line[1] - line[0])).astype(np.int64) % len(line)
        have = np.zeros_like(truth_valid)
        have[ring, column] = True
        both = have & truth_valid
        got = np.zeros_like(truth)
        got[ring, column] = np.column_stack([pts["x"], pts["y"], pts["z"]])
        label = np.zeros_like(truth_obj)
        label[ring, column] = pts["instance"]
        error = np.linalg.norm(got[both] - truth[both], axis=1)
        rows.append({
            "method": NAMES[method], "ms": round(ms, 1), "source_returns": out.info["conversion"]["source_returns"], "truth_returns": int(truth_valid.sum()),
            "converted": int(len(pts)), "reproduced": round(float(both.sum() / truth_valid.sum()), 4), "spurious": int((have & ~truth_valid).sum()),
            "error_median_m": round(float(np.median(error)), 4), "error_mean_m": round(float(error.mean()), 4),
            "error_p90_m": round(float(np.percentile(error, 90)), 4),
            "error_p99_m": round(float(np.percentile(error, 99)), 3), "label_agreement": round(float((label[both] == truth_obj[both]).mean()), 4),
        })
    return rows


def ring_stats(xyz: np.ndarray, ring: np.ndarray, rings: int, columns: int) -> dict:
    """Per ring: returns / columns, median elevation (deg) and median range (m) of ``xyz`` (k, 3) with ``ring`` (k,)."""
    r = np.linalg.norm(xyz, axis=1)
    el = np.degrees(np.arcsin(np.clip(xyz[:, 2] / np.maximum(r, 1e-9), -1, 1)))
    count = np.bincount(ring, minlength=rings)[:rings]
    med = lambda v: [round(float(np.median(v[ring == k])), 3) if count[k] else None for k in range(rings)]  # noqa: E731
    return {"returns_share": [round(float(c / columns), 4) for c in count], "elevation_deg": med(el), "range_m": med(r), "ranges": r, "ring": ring}


def real_rings(repeat: int, small: bool) -> tuple[list[dict], dict]:
    scan = read_real_scan(NUSCENES)
    f = recover_firings(scan, "hdl32e")
    ok = f.valid
    real = ring_stats(f.returns[ok] - f.origin[ok], f.ring[ok], 32, f.shape[1])
    sources = [KITTI] + ([] if small else [p for p in SEQ01 if p.exists()])
    rows, curves = [], {"nuScenes HDL-32E (real)": real}
    covered = None
    for method in METHODS:
        shares, elev, rng_, times, ks = [], [], [], [], []
        for path in sources:
            run = lambda: convert(path, "hdl32e", None, method, H_TARGET - H_SOURCE, source_preset="hdl64e")  # noqa: E731
            times.append(best_of(run, repeat) * 1e3)
            out = run().points
            xyz = np.column_stack([out["x"], out["y"], out["z"]]).astype(float)
            stats = ring_stats(xyz, out["ring"].astype(np.int64), 32, 1084)
            if path == KITTI:
                curves[f"KITTI 004747 -> HDL-32E, {NAMES[method]}"] = stats
            have = np.array([s > 0.05 for s in stats["returns_share"]])
            covered = have if covered is None else covered | have
            k = np.flatnonzero(have & (np.array(real["returns_share"]) > 0))
            shares.append(np.mean([abs(stats["returns_share"][i] - real["returns_share"][i]) for i in k]))
            elev.append(np.max([abs(stats["elevation_deg"][i] - real["elevation_deg"][i]) for i in k]))
            rng_.append(np.median([abs(stats["range_m"][i] - real["range_m"][i]) for i in k]))
            a, b = np.sort(stats["ranges"][np.isin(stats["ring"], k)]), np.sort(real["ranges"][np.isin(real["ring"], k)])
            grid = np.linspace(0, 80, 801)
            ks.append(float(np.max(np.abs(np.searchsorted(a, grid) / len(a) - np.searchsorted(b, grid) / len(b)))))
        rows.append({
            "method": NAMES[method], "scans": len(sources), "ms_mean": round(float(np.mean(times)), 1),
            "rings_covered": int(covered.sum()), "returns_share_mean_abs_diff": round(float(np.mean(shares)), 4),
            "elevation_max_abs_diff_deg": round(float(np.mean(elev)), 3), "median_range_abs_diff_m": round(float(np.mean(rng_)), 2),
            "range_ks_distance": round(float(np.mean(ks)), 3),
        })
    return rows, curves


def chart(acc, curves, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(19, 4.5))
    colours = {"cones": "tab:orange", "mesh": "tab:blue", "hybrid": "tab:green"}
    ax = axes[0]
    for row, method in zip(acc, METHODS):
        ax.scatter(row["ms"], row["error_mean_m"], s=60, color=colours[method],
                   label=f"{row['method']}: {row['reproduced']:.0%} reproduced, labels {row['label_agreement']:.1%} right")
        ax.errorbar(row["ms"], row["error_mean_m"], yerr=[[0], [max(row["error_p99_m"] - row["error_mean_m"], 0)]], color=colours[method], capsize=4)
    ax.set_xlabel("ms per conversion (street, HDL-64E -> HDL-32E)")
    ax.set_ylabel("position error vs the HDL-32E's own scan, m (mean, bar to p99)")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    rings = np.arange(32)
    for ax, key, label in zip(axes[1:], ("returns_share", "elevation_deg", "range_m"),
                              ("returns per ring / 1084 columns", "median elevation of the ring's returns, deg", "median range of the ring's returns, m")):
        for name, stats in curves.items():
            values = np.array([np.nan if v is None else v for v in stats[key]], float)
            method = next((m for m in METHODS if NAMES[m] in name), None)
            ax.plot(rings, values, marker="o" if method is None else None, color="k" if method is None else colours[method], ms=3, label=name)
        ax.set_xlabel("HDL-32E ring")
        ax.set_ylabel(label)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    import tempfile
    from pathlib import Path

    args = arguments(__doc__.splitlines()[0])
    repeat = 1 if args.small else 3
    if not (NUSCENES.exists() and KITTI.exists()):
        print(f"skipped: {NUSCENES} or {KITTI} is absent")
        return
    with tempfile.TemporaryDirectory() as tmp:
        acc = accuracy(repeat, Path(tmp))
    rings, curves = real_rings(repeat, args.small)
    notes = {"per_ring": {name: {k: v for k, v in s.items() if k not in ("ranges", "ring")} for name, s in curves.items()}, "lift_m": H_TARGET - H_SOURCE}
    report("convert", acc + rings, args.out, notes)
    chart(acc, curves, args.out / "convert.png")


if __name__ == "__main__":
    main()
