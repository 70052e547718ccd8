"""Railway data for training: a 1 km two-track mobile sequence, and thin parts' hit rates against distance and beam model.

``mobile``: two tracks, 1 km, masts on both sides (48 +- 2 m spans), the ``railway_profiler``
preset (200 profiles/s, 5,080 points a profile) on a train roof 4.2 m above the track centreline,
yawed 30 deg, at 25 m/s; one frame = 200 profiles (1 s), 40 frames cover the line (``--small``:
200 m, 4 frames of 40 profiles). The whole line is built once for the run (one railway per run)
and each frame exports what its stretch of path can reach. The reference is the sequence's own
sensor time: ``realtime_factor`` = wall time of the frames / seconds of scanning they stand for.
The sequence runs twice in the same process: ``path`` (the default: wires, trims and stones graded
by the distance to the run's whole path) and ``fixed`` (``scene.detail.mode: fixed``, the whole line
with wires at ``catenary.points_per_10m``); the notes give path / fixed ratios of triangles and time.
``BENCH_RAILWAY_PARTS=mobile`` (or ``hits``) runs one part alone.

``hits``: three stations (100 m apart) of the thesis's terrestrial scanner (``railway_tls``, 0.05 deg;
``--small``: 0.2 deg) 4 m beside a straight single track, each looking along it over a 90 x 58 deg window (2 to 60 deg
up: the catenary). For every dropper, registration arm and cantilever insulator set of the line
in the window (their positions from the ``railway_layout`` ground truth) the share that returns at
least one point, in distance bins, for three beam models measured in the same run:
``ideal`` (zero-width rays, no noise), ``divergence`` (0.3 mrad footprint, 7 sub-rays, first return)
and ``realistic`` (the divergence plus the preset's 2 mm noise and range-dependent drop).
Writes ``railway_mobile.json``, ``railway_hits.json`` and ``railway_hits.png``.

Run: python benchmarks/bench_railway_mobile.py [--small]
"""

import json
import os
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from common import arguments, report

BINS = [(0, 15), (15, 30), (30, 60), (60, 120)]
MODELS = {
    "ideal": ["effects.ideal=true"],
    "divergence": ["effects.ideal=true", "sensor.divergence={mrad: 0.3, rays: 7, return: first}"],
    "realistic": ["sensor.divergence={mrad: 0.3, rays: 7, return: first}"],
}


def run(overrides: list[str], out: Path) -> tuple[dict, float]:
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import run as run_pipeline

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["output.preview=false", "output.frame=world", *overrides])
    start = time.perf_counter()
    manifest = run_pipeline(config, out, log=lambda *_: None)
    return manifest, time.perf_counter() - start


DETAIL = {"path": [], "fixed": ["scene.detail.mode=fixed"]}  # detail graded along the run's path / the whole line at points_per_10m


def mobile(small: bool, tmp: Path, detail: str = "path") -> dict:
    length, frames, profiles = (200.0, 4, 40) if small else (1000.0, 40, 200)
    speed = 25.0
    manifest, wall = run([
        "scene.builder=railway", f"scene.track.end=[{length}, 0, 0]", f"scene.track.mid=[{length / 2}, 0, 0]", "scene.track.start=[0, 0, 0]",
        "scene.track.tracks=2", "scene.supports.layout=both_sides", "scene.supports.span=48", "scene.supports.span_jitter=2",
        "sensor.preset=railway_profiler", f"sensor.columns={profiles}", "sensor.rotation_deg=[0, 0, 30]",
        f"sensor.trajectory={{curve: track_centreline, speed: {speed}, height: 4.2}}", f"frames={frames}", "output.formats=[ply]",
        *DETAIL[detail],
    ], tmp / f"mobile_{detail}")
    per = manifest["frames"]
    totals = {k: sum(f["timings_s"].get(k, 0.0) for f in per) for k in ("build", "export", "scan", "effects", "write")}
    sensor_time = frames * profiles / 200.0
    triangles = [f["triangles"] for f in per]
    return {"scenario": "mobile", "detail": detail, "length_m": length, "frames": frames, "rays_per_frame": profiles * 5080,
            "points": sum(f["points"] for f in per), "triangles_per_frame_mean": float(np.mean(triangles)), "triangles_per_frame_max": int(max(triangles)),
            "wall_s": wall, **{f"{k}_s": v for k, v in totals.items()}, "sensor_time_s": sensor_time, "realtime_factor": wall / sensor_time,
            "distance_m": speed * sensor_time}


def compare(rows: list[dict]) -> dict:
    """Path-following against fixed detail, measured in the same run: ratios (path / fixed)."""
    path, fixed = (next(r for r in rows if r["detail"] == d) for d in ("path", "fixed"))
    return {f"{k}_ratio_path_over_fixed": path[k] / fixed[k] for k in ("triangles_per_frame_mean", "wall_s", "export_s", "scan_s", "points") if fixed[k]}


def segment_distance(points, a, b):
    """``(n, k)`` distances (m) from points (n, 3) to segments a[k]-b[k]."""
    ab = b - a
    t = np.clip(((points[:, None] - a[None]) * ab[None]).sum(-1) / np.maximum((ab**2).sum(-1), 1e-12)[None], 0, 1)
    return np.linalg.norm(points[:, None] - (a[None] + t[..., None] * ab[None]), axis=-1)


def hit_rates(truth: dict, cloud, objects: dict, pose: np.ndarray, fov: tuple) -> dict:
    """{class: [(hit, total) per distance bin]} for droppers, registration arms and insulators whose
    centre lies in the scanner's window ``fov`` ((azimuth lo, hi), (elevation lo, hi)) degrees."""
    xyz = np.column_stack([cloud["x"], cloud["y"], cloud["z"]]).astype(float)
    out = {k: [[0, 0] for _ in BINS] for k in ("dropper", "registration arm", "insulator")}
    station = pose[:3, 3]

    def add(kind, centre, hit):
        local = pose[:3, :3].T @ (np.asarray(centre) - station)
        azimuth, elevation = np.degrees(np.arctan2(local[1], local[0])), np.degrees(np.arctan2(local[2], np.hypot(local[0], local[1])))
        if not (fov[0][0] <= azimuth <= fov[0][1] and fov[1][0] <= elevation <= fov[1][1]):
            return
        distance = float(np.linalg.norm(local))
        for i, (lo, hi) in enumerate(BINS):
            if lo <= distance < hi:
                out[kind][i][0] += int(hit)
                out[kind][i][1] += 1

    dropper_points = xyz[np.isin(cloud["instance"], [v for k, v in objects.items() if k.endswith(".droppers")])]
    for d in truth["droppers"]:
        lower, upper = np.array(d["lower"]), np.array(d["upper"])
        near = segment_distance(dropper_points, lower, upper).min(0) < 0.05 if len(dropper_points) else np.zeros(len(lower), bool)
        for k in range(len(lower)):
            add("dropper", (lower[k] + upper[k]) / 2, near[k])
    for support in truth["supports"]:
        for arm in support["cantilevers"]:
            attach = np.array(arm["attach"])
            for kind, name in (("registration arm", f"support.{support['index']:02d}.registration_arm.t{arm['track']}"),
                               ("insulator", f"support.{support['index']:02d}.insulators.t{arm['track']}")):
                if name in objects:
                    add(kind, attach, (cloud["instance"] == objects[name]).any())
    return out


def hits(small: bool, tmp: Path) -> tuple[list[dict], dict]:
    from bpy_pipeline.io import read_ply

    base = ["scene.builder=railway", "scene.track.start=[-10, 0, 0]", "scene.track.mid=[160, 0, 0]", "scene.track.end=[330, 0, 0]",
            "scene.supports.layout=single", "scene.stations.chainages=[10, 110, 210]", "frames=3", "sensor.preset=railway_tls",
            "sensor.vertical_fov_deg=[2, 60]",
            "sensor.horizontal_fov_deg=[-45, 45]", f"sensor.sampling_factor={0.25 if small else 1.0}", "output.formats=[ply,railway_layout]"]
    rows, curves = [], {}
    for model, extra in MODELS.items():
        manifest, wall = run(base + extra, tmp / model)
        rates = {k: [[0, 0] for _ in BINS] for k in ("dropper", "registration arm", "insulator")}
        for frame in manifest["frames"]:  # three stations of one line: their counts add up
            truth = json.loads((tmp / model / "railway_layout" / f"{frame['index']:06d}.json").read_text())
            cloud = read_ply(tmp / model / "ply" / f"{frame['index']:06d}.ply")
            objects = {o["name"]: o["instance"] for o in frame["objects"]}
            for kind, bins in hit_rates(truth, cloud, objects, np.array(frame["sensor_pose"]), ((-45, 45), (2, 60))).items():
                for b, (hit, total) in enumerate(bins):
                    rates[kind][b][0] += hit
                    rates[kind][b][1] += total
        curves[model] = rates
        scan_s = sum(f["timings_s"]["scan"] + f["timings_s"].get("effects", 0.0) for f in manifest["frames"])  # the trace and the drop models
        for kind, bins in rates.items():
            for (lo, hi), (hit, total) in zip(BINS, bins):
                rows.append({"model": model, "class": kind, "distance_m": f"{lo}-{hi}", "hit": hit, "total": total, "rate": hit / total if total else None,
                             "scan_s": scan_s})
    return rows, curves


def chart(curves: dict, path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(13, 4), sharey=True)
    centres = [(lo + hi) / 2 for lo, hi in BINS]
    for ax, kind in zip(axes, ("dropper", "registration arm", "insulator")):
        for model, style in zip(MODELS, ("o-", "s--", "^:")):
            rates = [h / t if t else np.nan for h, t in curves[model][kind]]
            ax.plot(centres, rates, style, label=model)
        ax.set_title(kind)
        ax.set_xlabel("distance from the scanner (m)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("share of elements with >= 1 point")
    axes[0].legend()
    fig.suptitle("railway_tls, three stations: thin parts returned, by beam model")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    args = arguments(__doc__)
    suffix = "_small" if args.small else ""
    parts = os.environ.get("BENCH_RAILWAY_PARTS", "mobile,hits").split(",")  # e.g. mobile: rerun the sequence alone
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if "mobile" in parts:
            mobile(True, tmp / "warm_up")  # the first run pays for loading the scanner: not in either row
            rows = [mobile(args.small, tmp, detail) for detail in DETAIL]
            report("railway_mobile" + suffix, rows, args.out, compare(rows))
        if "hits" in parts:
            rows, curves = hits(args.small, tmp)
            report("railway_hits" + suffix, rows, args.out, {"bins_m": BINS, "models": MODELS})
            chart(curves, args.out / f"railway_hits{suffix}.png")


if __name__ == "__main__":
    main()
