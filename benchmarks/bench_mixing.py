"""Synthetic cars in a real scan: the exact per-firing cast against the parking and KITTI papers' methods; sensor conversion.

1. Mixing: the nuScenes sweep (../shared/real_scans/nuscenes_hdl32e_sweep.bin, 32 x 1084 firings), five
   cars at fixed boxes. Milliseconds per mixed frame (best of N, Embree warmed up), ours split by stage
   (read, firings, placement, meshes, cast, effects, records, boxes), beside the two papers' methods on
   the same frame and the same car meshes (benchmarks/mixing_references.py): the parking paper's
   (each car scanned alone by the hdl32e preset's nominal pattern, its points copied in, the
   background it occludes removed by the cone test) and the KITTI paper's (spherical point tracing of
   a dense point model, with the point wall). For all three: the angle from each inserted point to
   the nearest real firing's ray (from that firing's origin on the ego-motion line), how many inserted
   points share a firing with another inserted point, and the range difference to the exact cast on
   the firings both hit.
2. Sensor conversion (the parking paper, section 4.2): a procedural street (ground, walls, boxes,
   cars) scanned by an HDL-64E at 1.73 m (the dense source) and by a VLP-16 at 1.51 m (the truth);
   the source converted to the VLP-16 by the paper's projection onto the target's cones and by the
   meshed ray cast (bpy_pipeline/mixing/convert.py). Per method: time, the share of the truth's
   returns reproduced (same ring and column), returns where the truth has none, and the position error
   in the cells both have. Then both methods on the real KITTI scan (HDL-64E, front view) to a VLP-16:
   time and points (no truth there).
Run: python benchmarks/bench_mixing.py [--small]
"""

import math
import time

import numpy as np
from common import ROOT, arguments, best_of, report

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.objects import car_object
from bpy_pipeline.io.real_scans import read_real_scan
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
from bpy_pipeline.mixing import ObjectBox, RealScanScene, mix_frame
from bpy_pipeline.mixing.convert import convert_scan, project_to_cones, raycast_convert, target_rays
from bpy_pipeline.mixing.firings import recover_firings
from mixing_references import angular_error, kitti_paper_insert, parking_paper_insert

SCAN = ROOT.parent / "shared" / "real_scans" / "nuscenes_hdl32e_sweep.bin"
KITTI = ROOT.parent / "shared" / "real_scans" / "kitti_hdl64e_000008_frontfov.bin"
CARS = ((8, 4, 0), (-10, 5, 90), (12, -6, 30), (20, 2, 0), (-6, -8, 180))  # as bench_reference_jobs' mixed frame


def error_row(name, ms, firings, points, inserted, exact_firing, exact_range, extra=None):
    angle, firing = angular_error(firings, points[inserted])
    shared = len(firing) - len(np.unique(firing))
    both = np.isin(firing, exact_firing)
    lookup = dict(zip(exact_firing.tolist(), exact_range.tolist()))
    r = np.linalg.norm(points[inserted][both] - firings.origin[firing[both]], axis=1)
    dr = np.abs(r - np.array([lookup[k] for k in firing[both].tolist()])) if both.any() else np.zeros(1)
    row = {
        "method": name, "ms_per_frame": round(ms, 2), "inserted_points": int(inserted.sum()),
        "angle_median_deg": float(np.degrees(np.median(angle))), "angle_p95_deg": float(np.degrees(np.percentile(angle, 95))),
        "angle_max_deg": float(np.degrees(angle.max())),
        "points_sharing_a_firing": int(shared), "range_diff_median_m": float(np.median(dr)), "range_diff_p95_m": float(np.percentile(dr, 95)),
    }
    row.update(extra or {})
    return row


def mixing(repeat: int) -> tuple[list[dict], dict]:
    cars = [ObjectBox("car", (x, y, -0.9), (4.5, 1.9, 1.6), a) for x, y, a in CARS]
    section = RealScanScene(path=str(SCAN), objects=cars)
    mix_frame(section, np.random.default_rng(0))  # warm up Embree
    best, frame = math.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        m = mix_frame(section, np.random.default_rng(0))
        took = time.perf_counter() - start
        if took < best:
            best, frame = took, m
    stages = frame.info["timings_ms"]
    f = frame.firings
    xyz = np.column_stack([frame.points[k] for k in "xyz"]).astype(np.float64)
    exact_firing = frame.firing[frame.inserted]
    exact_range = frame.points["range"][frame.inserted].astype(np.float64)
    insertion_ms = stages["cast"] + stages["effects"] + stages["records"]  # the references' share of the work (meshes given, no boxes)
    rows = [error_row("exact per-firing cast (ours)", best * 1e3, f, xyz, frame.inserted, exact_firing, exact_range, {"insertion_ms": round(insertion_ms, 2)})]
    scan = read_real_scan(SCAN)
    firings = recover_firings(scan)
    t_park = best_of(lambda: parking_paper_insert(firings, firings.valid, frame.buffers, frame.placements), repeat) * 1e3
    pts, ins = parking_paper_insert(firings, firings.valid, frame.buffers, frame.placements)
    rows.append(error_row("parking paper: scan alone + cone test", t_park, f, pts, ins, exact_firing, exact_range, {"insertion_ms": round(t_park, 2)}))
    t_kitti = best_of(lambda: kitti_paper_insert(firings, firings.valid, frame.buffers), repeat) * 1e3
    pts, ins = kitti_paper_insert(firings, firings.valid, frame.buffers)
    rows.append(error_row("KITTI paper: spherical tracing + point wall", t_kitti, f, pts, ins, exact_firing, exact_range, {"insertion_ms": round(t_kitti, 2)}))
    for row in rows:
        row["insertion_ratio_to_ours"] = round(row["insertion_ms"] / rows[0]["insertion_ms"], 2)
    return rows, stages


def street_scene(rng) -> SceneBuffers:
    """A procedural street: ground, two building walls, boxes, eight cars (pure meshes, sensor at the origin)."""
    meshes = {"ground": primitives.translated(primitives.plane(240.0, 240.0), (0.0, 0.0, 0.0))}
    for k, (y, length) in enumerate(((12.0, 120.0), (-14.0, 120.0))):
        meshes[f"wall {k}"] = primitives.translated(primitives.box(length, 0.4, 8.0), (0.0, y, 4.0))
    for k in range(10):
        x, y = rng.uniform(-40, 40), rng.choice([-1, 1]) * rng.uniform(5, 10)
        meshes[f"box {k}"] = primitives.translated(primitives.box(*rng.uniform(0.5, 2.0, 3)), (x, y, 0.6))
    for k in range(8):
        parts = car_object(rng)
        v = np.concatenate([p.vertices for p in parts])
        offset = 0
        tris = []
        for p in parts:
            tris.append(p.triangles + offset)
            offset += len(p.vertices)
        yaw = rng.uniform(0, 2 * np.pi)
        c, s = np.cos(yaw), np.sin(yaw)
        pos = (rng.uniform(-30, 30), rng.choice([-1, 1]) * rng.uniform(3, 9), -v[:, 2].min())
        meshes[f"car {k}"] = (v @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + pos, np.concatenate(tris))
    return SceneBuffers.from_meshes(meshes)


def scan_grid(buffers, spec, height):
    """``(points (rings, columns, 3) in the sensor frame, valid (rings, columns))`` of ``spec`` at ``height`` m."""
    directions, ring, column = target_rays(spec)
    frame = np.eye(4)
    frame[2, 3] = height
    hits = RayCaster(buffers, frame=frame).intersect(np.zeros(3), directions, spec.max_range)
    rings, columns = ring.max() + 1, column.max() + 1
    points, valid = np.zeros((rings, columns, 3)), np.zeros((rings, columns), bool)
    keep = hits.distance >= spec.min_range
    r, c = ring[hits.ray[keep]], column[hits.ray[keep]]
    points[r, c] = directions[hits.ray[keep]] * hits.distance[keep, None]
    valid[r, c] = True
    return points, valid


def conversion(repeat: int) -> list[dict]:
    buffers = street_scene(np.random.default_rng(7))
    source, target = resolve_sensor({"preset": "hdl64e"}, "source"), resolve_sensor({"preset": "vlp16"}, "target")
    h_source, h_target = 1.73, 1.51
    grid, valid = scan_grid(buffers, source, h_source)
    truth, truth_valid = scan_grid(buffers, target, h_target)
    offset = (0.0, 0.0, h_target - h_source)
    rows = []
    for name, fn in (
        ("paper: projection onto the target's cones", lambda: project_to_cones(grid[valid], target, offset)),
        ("meshed ray cast, joins within 10 % + 0.3 m", lambda: raycast_convert(grid, valid, target, offset, max_jump=0.1)),
        ("meshed ray cast, joins within 30 % + 0.3 m", lambda: raycast_convert(grid, valid, target, offset, max_jump=0.3)),
    ):
        ms = best_of(fn, repeat) * 1e3
        points, ring, column = fn()
        have = np.zeros_like(truth_valid)
        have[ring, column] = True
        both = have & truth_valid
        got = np.zeros_like(truth)
        got[ring, column] = points
        error = np.linalg.norm(got[both] - truth[both], axis=1)
        directions, _, _ = target_rays(target)
        d = directions.reshape(truth.shape)
        off = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", got[both] / np.linalg.norm(got[both], axis=1, keepdims=True), d[both]), -1, 1)))
        rows.append({
            "method": name, "ms": round(ms, 2), "source_returns": int(valid.sum()), "truth_returns": int(truth_valid.sum()),
            "reproduced": round(float(both.sum() / truth_valid.sum()), 4), "spurious": int((have & ~truth_valid).sum()),
            "error_median_m": float(np.median(error)), "error_p90_m": float(np.percentile(error, 90)), "error_p99_m": float(np.percentile(error, 99)),
            "error_mean_m": float(error.mean()), "off_firing_median_deg": float(np.median(off)),
        })
    if KITTI.exists():  # the real KITTI scan (no truth): cost and points of each method
        firings = recover_firings(read_real_scan(KITTI), "hdl64e")
        for method in ("cones", "raycast"):
            ms = best_of(lambda: convert_scan(firings, target, offset, method), repeat) * 1e3
            rows.append({"method": f"KITTI 000008 (front view) -> VLP-16, {method}", "ms": round(ms, 2), "source_returns": int(firings.valid.sum()),
                         "converted": int(len(convert_scan(firings, target, offset, method)))})
    return rows


def chart(mix_rows, stages, conv_rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    ax = axes[0]
    left = 0.0
    for k, (name, ms) in enumerate(stages.items()):
        ax.barh(0, ms, left=left, label=name, color=plt.cm.tab10(k))
        left += ms
    for i, row in enumerate(mix_rows[1:], start=1):
        ax.barh(i, row["insertion_ms"], color="black")
    ax.set_yticks(range(len(mix_rows)), ["ours (all stages)", "parking paper", "KITTI paper"])
    ax.set_xlabel("ms per frame (nuScenes sweep, 5 cars)")
    ax.legend(fontsize=7, loc="lower right")
    ax = axes[1]
    for i, row in enumerate(mix_rows):
        ax.bar(i, max(row["angle_median_deg"], 1e-9), color=("tab:green", "tab:orange", "tab:red")[i])
        ax.errorbar(i, max(row["angle_median_deg"], 1e-9), yerr=[[0], [row["angle_p95_deg"] - row["angle_median_deg"]]], color="k", capsize=4)
    ax.set_yscale("log")
    ax.set_xticks(range(len(mix_rows)), ["ours", "parking", "KITTI"])
    ax.set_ylabel("angle to the nearest real firing, deg (median, bar to p95)")
    ax = axes[2]
    for row, colour in zip([r for r in conv_rows if "reproduced" in r], ("tab:orange", "tab:blue", "tab:cyan")):
        ax.scatter(row["ms"], row["error_mean_m"], s=60, color=colour, label=f"{row['method']} ({row['reproduced']:.0%} reproduced)")
        ax.errorbar(row["ms"], row["error_mean_m"], yerr=[[0], [max(row["error_p99_m"] - row["error_mean_m"], 0)]], color=colour, capsize=4)
    ax.set_xlabel("ms per conversion (HDL-64E -> VLP-16)")
    ax.set_ylabel("position error vs direct VLP-16 scan, m (mean, bar to p99)")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    repeat = 2 if args.small else 7
    if not SCAN.exists():
        print(f"skipped: {SCAN} is absent")
        return
    mix_rows, stages = mixing(repeat)
    conv_rows = conversion(repeat)
    notes = {"stages_ms_of_best_ours": stages, "scan": SCAN.name, "cars": [list(c) for c in CARS]}
    report("mixing", mix_rows, args.out, notes)
    report("mixing_conversion", conv_rows, args.out)
    chart(mix_rows, stages, conv_rows, args.out / "mixing.png")


if __name__ == "__main__":
    main()
