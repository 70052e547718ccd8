"""Wire sampling density against what it costs and what the scan can tell: triangles, build and scan time, wire error.

The railway of the default job (one track, 150 m, three spans, contact, messenger, feeder and
earth wires, droppers) is built with the thesis's fixed sampling at several points_per_10m and
with the sensor-driven default (chords within half the beam spacing at each wire's distance),
then scanned from the default station by the thesis's scanner at 0.1 deg. The wire position error
of a point is its distance from the exact wire (the analytic parabola of its span, the reference)
less the wire's radius, over every point labeled contact, messenger, feeder or earth wire; it is
reported in mm and in beam spacings at the point's range (range x angular step): the scan cannot
show an error under half a spacing (dotted line in the chart), which the sensor-driven sampling keeps.
Ballast stones are off so the wires make the difference. Times are best of two.
Run: python benchmarks/bench_railway_lod.py [--small]
"""

import time

import numpy as np
from common import arguments, report

import bpy

from bpy_pipeline.config import load_config
from bpy_pipeline.blender.export import export_scene
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.frame import frame_rng
from bpy_pipeline.stages.scan import scan_buffers
from bpy_pipeline.stages.view import scene_view, sensor_pose
from bpy_pipeline.blender import build_scene

WIRES = ("contact_wire", "messenger_wire", "feeder", "earth_wire")


def wire_errors(points, buffers, layout) -> tuple[np.ndarray, np.ndarray]:
    """``(k,)`` distance (m) of every wire point from its span's exact wire axis, less the wire radius,
    and ``(k,)`` each point's range (m)."""
    instance = {name: int(i) for name, i in zip(buffers.objects.names, buffers.objects.instance)}
    errors, ranges = [], []
    for wire in layout.wires:
        key = f"span.{wire.run}.{wire.span:02d}.{wire.kind}"
        if key not in instance:
            continue
        mine = points[points["instance"] == instance[key]]
        if not len(mine):
            continue
        xyz = np.column_stack([mine["x"], mine["y"], mine["z"]]).astype(float)
        chord = (wire.end - wire.start)[:2]
        t = (xyz[:, :2] - wire.start[:2]) @ chord / (chord @ chord)
        axis_xy = wire.start[:2] + t[:, None] * chord
        lateral = np.linalg.norm(xyz[:, :2] - axis_xy, axis=1)
        errors.append(np.abs(np.hypot(lateral, xyz[:, 2] - wire.z_at(t)) - wire.diameter / 2))
        ranges.append(mine["range"].astype(float))
    return (np.concatenate(errors), np.concatenate(ranges)) if errors else (np.zeros(0), np.zeros(0))


def measure(label: str, overrides: list[str], repeat: int) -> dict:
    config = load_config(None, overrides)
    view = scene_view(config, 0, 1)
    table = load_class_table()
    builds, scans = [], []
    for _ in range(repeat):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        start = time.perf_counter()
        layout = build_scene(config.scene, frame_rng(0, 0), view).scene
        builds.append(time.perf_counter() - start)
        buffers = export_scene(table, keep_within=(sensor_pose(config)[:3, 3], config.sensor.spec.max_range))
        start = time.perf_counter()
        points, _ = scan_buffers(buffers, config, frame_rng(0, 0))
        scans.append(time.perf_counter() - start)
    wire_rows = [i for i, n in enumerate(buffers.objects.names) if n.endswith(WIRES)]
    wire_triangles = int(np.isin(buffers.triangle_object, wire_rows).sum())
    errors, ranges = wire_errors(points, buffers, layout)
    relative = errors / (ranges * view.step)  # in beam spacings at the point's range
    return {
        "sampling": label, "wire_triangles": wire_triangles, "triangles": len(buffers.triangles),
        "build_s": min(builds), "scan_s": min(scans), "wire_points": len(errors),
        "wire_error_p95_mm": float(np.percentile(errors, 95) * 1000), "wire_error_max_mm": float(errors.max() * 1000),
        "error_p95_spacings": float(np.percentile(relative, 95)), "error_max_spacings": float(relative.max()),
    }


def main():
    args = arguments(__doc__)
    sampling = 0.25 if args.small else 0.5
    base = ["sensor.preset=railway_tls", f"sensor.sampling_factor={sampling}", "output.frame=world", "scene.detail.stones=false"]
    densities = [1, 5, 20] if args.small else [1, 2, 5, 10, 20, 50, 100]
    repeat = 1 if args.small else 2
    rows = [measure(f"fixed {n}/10 m", base + ["scene.detail.mode=fixed", f"scene.catenary.points_per_10m={n}"], repeat) for n in densities]
    rows.append(measure("sensor-driven", base, repeat))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    x = [r["error_max_spacings"] for r in rows]
    for ax, key, title in zip(axes, ("wire_triangles", "build_s", "scan_s"), ("wire triangles", "build time (s)", "scan time (s)")):
        y = [r[key] for r in rows]
        ax.plot(x[:-1], y[:-1], "o-", label="fixed points per 10 m (thesis)")
        ax.plot(x[-1:], y[-1:], "r*", ms=14, label="sensor-driven (default)")
        for r, xi, yi in zip(rows, x, y):
            ax.annotate(r["sampling"].replace("fixed ", ""), (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.set_xscale("log")
        ax.axvline(0.5, color="grey", ls=":", lw=1)
        ax.set_xlabel("largest wire error, in beam spacings at its range")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_yscale("log")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Wire sampling: cost against the error the scan shows (railway_tls at {0.05 / sampling:g} deg)")
    fig.tight_layout()
    name = "railway_lod" + ("_small" if args.small else "")
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / f"{name}.png", dpi=110)
    report(name, rows, args.out, {"sensor": f"railway_tls, sampling_factor {sampling} ({0.05 / sampling:g} deg)", "chart": f"{name}.png",
                                  "reference": "exact parabola of each span (analytic)", "repeat": repeat})


if __name__ == "__main__":
    main()
