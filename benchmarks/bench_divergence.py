"""Beam divergence: how often a 12 mm catenary wire is returned, against the sub-ray count, and what it costs.

Two sensors, each with the wire across its scan line, at several distances R:

* the railway thesis's terrestrial scanner (``railway_tls``, 0.05 x 0.05 deg) restricted to a
  16 x 1.6 deg window: its vertical profiles cross a horizontal wire, slightly sloped so that
  the wire meets each profile at a different phase of the 0.05 deg row spacing; divergence
  0.3 mrad (a typical phase-based or pulsed TLS);
* a VLP-16 (``vlp16``, 0.2 deg azimuth step at 10 Hz): its rings cross 40 vertical wires
  around it (as the overhead contact wire's image crosses them ahead of a vehicle), slightly
  tilted so that each ring meets them at its own phase; divergence 3 mrad (Velodyne's manuals
  give 3.0 mrad across the scan, 1.5 along it).

The wires are cylinders of the ``primitives`` builder, built in Blender and exported through the
depsgraph, 5 m in front of a wall (so that every beam returns and the time is that of a scene
that is hit everywhere). The hit rate is the share of crossings (a profile or a ring meeting a
wire) that return at least one wire point, with ``return: first``.
References: a zero-width ray hits with probability ``min(1, w / delta)`` (``w = D / R`` the
wire's angular width, ``delta`` the beam spacing along the scan line), a footprint of full angle
``gamma`` with ``min(1, (w + gamma') / delta)`` (``gamma'`` the footprint's width along the
scan line: ``gamma`` for a profile, ``gamma / cos(elevation)`` in azimuth for a ring). The time is
the scan alone (trace, records, reduction), best of several tries, against the plain scan
(one ray a beam) of the same beams, and against a plain scan of as many rays as there are
sub-rays (the same beams repeated): the second ratio is the footprint model's own overhead
and, both runs lasting as long, it is not skewed by other jobs on the machine, which favour
short runs in a best-of timing. A second table compares the first, strongest and last returns.
Writes ``divergence.json`` and ``divergence.png``.

Run: python benchmarks/bench_divergence.py [--small]
"""

import math
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from common import arguments, best_of, report

import bpy

from bpy_pipeline.builders.primitives.params import PrimitivesScene, Shape
from bpy_pipeline.config import SceneConfig
from bpy_pipeline.blender.export import export_scene
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.effects.divergence import Divergence, scan_footprint
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.scanner import scan
from bpy_pipeline.lidar.sensor.sensors import azimuth_step, azimuths, elevation_step, elevations, resolve_sensor, sensor_pattern
from bpy_pipeline.lidar.sensor.rays import Pattern
from bpy_pipeline.frame import frame_rng
from bpy_pipeline.blender import build_scene

DIAMETER = 0.012  # m, a contact wire
SLOPE = 0.05  # the TLS wire's slope, and the VLP-16 wires' tilt: phases vary from crossing to crossing
PHI = (math.sqrt(5.0) - 1.0) / 2.0
WALL_GAP = 5.0  # m from the wire to the wall behind it


def wire(name, length, position, rotation_deg) -> Shape:
    return Shape("cylinder", [DIAMETER / 2, length], tuple(position), tuple(rotation_deg), class_name="contact wire", reflectivity=0.7, segments=24, name=name)


def tls_case(distance: float, window: float):
    """Scene and sensor: a horizontal wire along y at x = distance, sloped, for the TLS's vertical profiles; a wall behind."""
    spec = resolve_sensor({"preset": "railway_tls", "horizontal_fov_deg": [-window, window], "vertical_fov_deg": [-0.8, 0.8]})
    length = 2.0 * distance * math.tan(math.radians(window)) + 2.0
    shapes = [
        wire("wire_0", length, (distance, 0.0, 0.0), (90.0 + math.degrees(math.atan(SLOPE)), 0.0, 0.0)),
        Shape("plane", [4 * length, 4 * length], (distance + WALL_GAP, 0.0, 0.0), (0.0, -90.0, 0.0), class_name="wall", name="wall"),
    ]
    column = np.arange(len(azimuths(spec)))
    y = distance * np.tan(np.radians(azimuths(spec)))
    slant = np.sqrt(distance**2 + y**2 + (SLOPE * y) ** 2)  # to the wire in each profile
    delta = math.radians(elevation_step(spec))

    def reference(gamma):  # mean over profiles of the crossing probability
        return float(np.mean(np.minimum(1.0, (DIAMETER / slant + gamma) / delta)))

    def crossings(points, wire_instances):  # one crossing per profile; a hit when any of its points is on the wire
        columns = np.floor(points["time"] / (azimuth_step(spec) / (360.0 * spec.rotation_hz)) + 1e-9).astype(int)  # rows fire within their column's period
        on = np.isin(points["instance"], wire_instances)
        return np.isin(column, columns[on]).sum(), len(column)

    return spec, shapes, reference, crossings


def vlp16_case(distance: float, wires: int):
    """Scene and sensor: ``wires`` vertical wires around the VLP-16 at a horizontal distance, tilted; a box room behind."""
    spec = resolve_sensor({"preset": "vlp16"})
    step = azimuth_step(spec)
    tilt = math.degrees(math.atan(SLOPE))
    height = 2.0 * distance * math.tan(math.radians(16.0)) + 1.0
    shapes = []
    for k in range(wires):
        azimuth = 360.0 * k / wires + step * ((k * PHI) % 1.0)  # spread over the phases of the column grid
        a = math.radians(azimuth)
        shapes.append(wire(f"wire_{k:03d}", height, (distance * math.cos(a), distance * math.sin(a), 0.0), (tilt, 0.0, azimuth)))
    side = 2.0 * (distance + WALL_GAP)
    shapes.append(Shape("box", [side, side, 2.0 * height], (0.0, 0.0, 0.0), class_name="wall", name="wall"))
    delta = math.radians(step)
    cos_el = np.cos(np.radians(elevations(spec)))

    def reference(gamma):  # mean over rings: a vertical wire is D / R wide in azimuth, the footprint gamma / cos(el)
        return float(np.mean(np.minimum(1.0, (DIAMETER / distance + gamma / cos_el) / delta)))

    def crossings(points, wire_instances):  # one crossing per (wire, ring)
        on = np.isin(points["instance"], wire_instances)
        pairs = np.unique(points["instance"][on].astype(np.int64) * 65536 + points["ring"][on])
        return len(pairs), len(wire_instances) * spec.channels

    return spec, shapes, reference, crossings


def build(shapes):
    build_scene(SceneConfig("primitives", PrimitivesScene(shapes)), frame_rng(0, 0))
    buffers = export_scene(load_class_table())
    wires = buffers.objects.instance[[i for i, name in enumerate(buffers.objects.names) if name.startswith("wire_")]]
    return buffers, wires


def timed(run) -> float:
    """Best wall time of ``run()``: more tries for short scans (at least two, about 0.3 s in all)."""
    start = time.perf_counter()
    run()
    once = time.perf_counter() - start
    return min(once, best_of(run, repeat=min(20, max(2, math.ceil(0.3 / once)))))


def tiled(pattern: Pattern, times: int) -> Pattern:
    """The beams of ``pattern`` ``times`` over: plain rays as many as a footprint's sub-rays."""
    return Pattern(np.tile(pattern.directions, (times, 1)), np.tile(pattern.ring, times), np.tile(pattern.time, times))


def scan_with(caster, buffers, pattern, spec, rays, mrad, pick="first"):
    if rays == 1:
        return lambda: scan(caster, buffers, pattern, np.eye(4), spec.min_range, spec.max_range)[0]
    divergence = Divergence(mrad=mrad, rays=rays, pick=pick)
    return lambda: scan_footprint(caster, buffers, pattern, np.eye(4), divergence, spec.min_range, spec.max_range)[0]


def measure(sensor, case, distance, mrad, counts):
    """Hit rate and time per sub-ray count; the wire stands 5 m in front of a wall, so every beam returns
    (timing a scan of the sky would time misses only) while the first return is the wire's whenever a sub-ray meets it."""
    spec, shapes, reference, crossings = case(distance)
    buffers, wires = build(shapes)
    pattern = sensor_pattern(spec)
    caster = RayCaster(buffers, frame=np.eye(4))
    rows, bare = [], None
    for rays in counts:
        run = scan_with(caster, buffers, pattern, spec, rays, mrad)
        points = run()
        seconds = timed(run)
        bare = bare or seconds
        plain = seconds if rays == 1 else timed(scan_with(caster, buffers, tiled(pattern, rays), spec, 1, mrad))
        hit, total = crossings(points, wires)
        on = np.isin(points["instance"], wires)
        rows.append({
            "sensor": sensor, "distance_m": distance, "mrad": mrad, "rays": rays, "beams": len(pattern), "crossings": total,
            "hit_rate": hit / total, "zero_width_reference": reference(0.0), "footprint_reference": reference(mrad * 1e-3),
            "wire_points": int(on.sum()), "scan_s": seconds, "cost_vs_one_ray": seconds / bare,
            "cost_vs_as_many_plain_rays": seconds / plain, "sub_rays_per_s": len(pattern) * rays / seconds,
        })
    return rows


def return_modes(sensor, case, distance, mrad, rays):
    """The wire in front of a wall: which return modes keep it."""
    spec, shapes, reference, crossings = case(distance)
    buffers, wires = build(shapes)
    pattern = sensor_pattern(spec)
    caster = RayCaster(buffers, frame=np.eye(4))
    row = {"sensor": sensor, "distance_m": distance, "wall_behind_m": WALL_GAP, "mrad": mrad, "rays": rays}
    for pick in ("first", "strongest", "last"):
        hit, total = crossings(scan_with(caster, buffers, pattern, spec, rays, mrad, pick)(), wires)
        row[f"hit_rate_{pick}"] = hit / total
    row["hit_rate_one_ray"] = crossings(scan_with(caster, buffers, pattern, spec, 1, mrad)(), wires)[0] / total
    return row


def chart(rows, path):
    sensors = list(dict.fromkeys(r["sensor"] for r in rows))
    fig, axes = plt.subplots(1, len(sensors) + 1, figsize=(5.2 * (len(sensors) + 1), 4.2))
    for ax, sensor in zip(axes, sensors):
        mine = [r for r in rows if r["sensor"] == sensor]
        for i, distance in enumerate(dict.fromkeys(r["distance_m"] for r in mine)):
            at = [r for r in mine if r["distance_m"] == distance]
            colour = f"C{i}"
            ax.plot([r["rays"] for r in at], [r["hit_rate"] for r in at], "o-", color=colour, label=f"{distance:g} m")
            ax.axhline(at[0]["zero_width_reference"], color=colour, ls=":", lw=1)
            ax.axhline(at[0]["footprint_reference"], color=colour, ls="--", lw=1)
        ax.set_xscale("log")
        ax.set_xlabel("sub-rays per beam")
        ax.set_ylabel("wire hit rate (12 mm)")
        ax.set_ylim(0, 1.05)
        ax.set_title(f"{sensor}, {mine[0]['mrad']:g} mrad\n(dotted: zero-width ray, dashed: footprint)", fontsize=10)
        ax.legend(fontsize=8, loc="lower right")
    ax = axes[-1]
    for i, sensor in enumerate(sensors):
        mine = [r for r in rows if r["sensor"] == sensor]
        counts = list(dict.fromkeys(r["rays"] for r in mine))
        cost = [np.median([r["cost_vs_one_ray"] for r in mine if r["rays"] == n]) for n in counts]
        overhead = [n * np.median([r["cost_vs_as_many_plain_rays"] for r in mine if r["rays"] == n]) for n in counts]
        ax.plot(counts, cost, "s-", color=f"C{i}", label=f"{sensor}: / one ray a beam")
        ax.plot(counts, overhead, "^--", color=f"C{i}", label=f"{sensor}: n x / as many plain rays")
    ax.plot(counts, counts, "k:", lw=1, label="sub-rays")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("sub-rays per beam")
    ax.set_ylabel("scan time / one ray a beam")
    ax.set_title("cost (median over distances)", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    args = arguments(__doc__)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    counts = (1, 7, 19) if args.small else (1, 3, 7, 19, 37, 61)
    window, wires = (5.0, 12) if args.small else (8.0, 40)
    tls = lambda distance: tls_case(distance, window)  # noqa: E731
    vlp = lambda distance: vlp16_case(distance, wires)  # noqa: E731
    rows = []
    for distance in (25.0, 100.0) if args.small else (10.0, 25.0, 50.0, 100.0, 140.0):  # range 150 m (and the wall behind)
        rows += measure("railway_tls", tls, distance, 0.3, counts)
    for distance in (10.0, 50.0) if args.small else (5.0, 10.0, 25.0, 50.0, 90.0):  # range 100 m
        rows += measure("vlp16", vlp, distance, 3.0, counts)
    modes = [return_modes("railway_tls", tls, 50.0, 0.3, 7), return_modes("vlp16", vlp, 25.0, 3.0, 19)]
    name = "divergence" + ("_small" if args.small else "")
    args.out.mkdir(parents=True, exist_ok=True)
    chart(rows, args.out / f"{name}.png")
    report(name, rows, args.out, {"return_modes": modes, "wire_diameter_m": DIAMETER, "chart": f"{name}.png"})
    print("\nthe wire 5 m in front of a wall: hit rate by return mode")
    for row in modes:
        print("  " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()))


if __name__ == "__main__":
    main()
