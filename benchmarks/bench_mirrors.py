"""Mirror cost: one frame of the super-resolution mirror LiDAR, and what scene mirrors add.

The sensor of the human-robot paper (seed 002): an Ouster OS1-128 at 2048 columns (262,144
rays) looking through its eight mirror segments, 6 m above the floor of a factory hall built
from primitives (desks as boxes, people as cylinders with a sphere for the head, a robot arm
as a few boxes). The scan step of the pipeline (``pipeline.scan_buffers``: the rays through the
sensor's mirrors, the Embree trace, the mirror-edge drop and the effects) is timed, best of
five, in wall and in CPU time, on the same Blender-exported buffers in these variants (a run traces the sensor's own
mirrors and builds its edge-drop mask once, on its first frame; that one-off cost is reported
apart, as ``first_frame_extra_s``):

- the bare OS1-128 at the same pose (no sensor mirrors: its rays go sideways into the hall)
  and the mirror sensor, for the cost of the sensor's own mirrors;
- the mirror sensor in the hall with a mirror wall (a few per cent of the rays bounce), a
  polished floor under the sensor (a mirror patch: a third of them bounce up to the ceiling),
  and a glass partition, for the cost of scene bounces against the same hall without them.

The paper reports 27.6 s a frame in Blender Geometry Nodes; the aim here is under 0.5 s of
scan time on two cores. Writes benchmarks/results/mirrors.json and mirrors.png (scan times,
and the frame seen from above: the star pattern).
Run: python benchmarks/bench_mirrors.py [--small]
"""

import os
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from common import arguments, best_of, report

import bpy

from bpy_pipeline.config import load_config
from bpy_pipeline.blender.export import export_scene
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.sensor.mirror_sensor import MirrorFrame
from bpy_pipeline.frame import frame_rng
from bpy_pipeline.stages.scan import scan_buffers
from bpy_pipeline.blender import build_scene

HEIGHT = 6.0  # m, sensor above the floor


def hall_shapes(rng: np.random.Generator) -> list[dict]:
    """Floor, four walls, a ceiling, 8 desks, 6 people and a robot arm, as primitives shapes."""
    shapes = [
        {"type": "plane", "size": [24, 24], "class": "floor", "name": "floor"},
        {"type": "plane", "size": [24, 24], "position": [0, 0, 7.5], "rotation_deg": [180, 0, 0], "class": "ceiling", "name": "ceiling"},
    ]
    for i, (x, y, yaw) in enumerate([(12, 0, 90), (-12, 0, -90), (0, 12, 180), (0, -12, 0)]):
        shapes.append({"type": "plane", "size": [24, 7.5], "position": [x, y, 3.75], "rotation_deg": [90, 0, yaw], "class": "wall", "name": f"wall_{i}"})
    for i in range(8):
        x, y = rng.uniform(-6, 6, 2)
        shapes.append({"type": "box", "size": [1.6, 0.8, 0.72], "position": [x, y, 0.36], "rotation_deg": [0, 0, float(rng.uniform(0, 180))], "class": "desk",
                       "name": f"desk_{i}"})
    for i in range(6):
        x, y = rng.uniform(-5, 5, 2)
        height = float(rng.uniform(1.6, 1.9))
        shapes.append({"type": "cylinder", "size": [0.22, height - 0.25], "position": [x, y, (height - 0.25) / 2], "class": "person", "name": f"person_{i}",
                       "segments": 24})
        shapes.append({"type": "sphere", "size": 0.12, "position": [x, y, height - 0.12], "class": "person", "name": f"head_{i}", "segments": 16})
    arm = [([0.6, 0.6, 0.5], [2.5, -2.0, 0.25]), ([0.25, 0.25, 1.1], [2.5, -2.0, 1.05]), ([0.9, 0.2, 0.2], [2.9, -2.0, 1.6]),
           ([0.15, 0.15, 0.5], [3.3, -2.0, 1.35])]
    shapes += [{"type": "box", "size": size, "position": pos, "class": "robot arm", "name": f"arm_{i}"} for i, (size, pos) in enumerate(arm)]
    return shapes


VARIANTS = {
    "hall": [],
    "hall + mirror wall": [{"type": "plane", "size": [10, 4], "position": [4.5, 0, 2], "rotation_deg": [90, 0, -90], "class": "wall", "material": "mirror",
                            "reflectivity": 0.9, "name": "mirror_wall"}],
    "hall + mirror floor": [{"type": "plane", "size": [8, 8], "position": [0, 0, 0.01], "class": "floor", "material": "mirror", "reflectivity": 0.8,
                             "name": "polished_floor"}],
    "hall + glass partition": [{"type": "plane", "size": [10, 3], "position": [-4.0, 0, 1.5], "rotation_deg": [90, 0, -90], "class": "wall",
                                "material": "glass", "reflectivity": 0.1, "name": "glass"}],
}


def config_for(shapes, columns: int, reflector: bool):
    return load_config(None, [
        "scene.builder=primitives", f"scene.shapes={shapes}",
        "sensor.preset=os1_128", f"sensor.columns={columns}", f"sensor.position=[0, 0, {HEIGHT}]",
        f"sensor.reflector={{enabled: {str(reflector).lower()}}}", "output.preview=false",
    ])


def cpu_time(fn) -> float:
    """CPU seconds of ``fn()`` over every thread of the process (steadier than wall time on a shared machine)."""
    start = time.process_time()
    fn()
    return time.process_time() - start


def measure(shapes, columns: int, reflector: bool, repeat: int) -> tuple[dict, np.ndarray]:
    config = config_for(shapes, columns, reflector)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    build_scene(config.scene, frame_rng(0, 0))
    buffers = export_scene(load_class_table())
    points, _ = scan_buffers(buffers, config, frame_rng(0, 0))
    seconds = best_of(lambda: scan_buffers(buffers, config, frame_rng(0, 0)), repeat)
    cpu = min(cpu_time(lambda: scan_buffers(buffers, config, frame_rng(0, 0))) for _ in range(repeat))
    rays = 128 * columns
    row = {
        "rays": rays, "triangles": len(buffers.triangles), "points": len(points),
        "ghost_points": int((points["bounces"] > 0).sum()), "scan_s": seconds, "scan_cpu_s": cpu, "rays_per_s": rays / seconds,
    }
    return row, points


def main():
    args = arguments(__doc__)
    columns, repeat = (512, 1) if args.small else (2048, 5)
    rng = np.random.default_rng(2)
    base = hall_shapes(rng)
    rows, clouds = [], {}
    bare, _ = measure(base, columns, reflector=False, repeat=repeat)
    rows.append({"variant": "bare OS1-128, hall", **bare})
    for name, extra in VARIANTS.items():
        row, points = measure(base + extra, columns, reflector=True, repeat=repeat)
        rows.append({"variant": f"mirror sensor, {name}", **row})
        clouds[name] = points
    reference = rows[1]["scan_s"]
    for row in rows:
        row["vs_mirror_sensor_hall"] = row["scan_s"] / reference
        row["cpu_vs_mirror_sensor_hall"] = row["scan_cpu_s"] / rows[1]["scan_cpu_s"]
        row["bounced_share"] = row["ghost_points"] / row["points"]
    # The one-off work of a run's first frame: the sensor's rays through its own mirrors, and the edge-drop mask.
    config = config_for(base, columns, True)
    spec, reflector = config.sensor.spec, config.sensor.reflector
    edge = reflector.edge_drop

    def first_frame():
        traced = MirrorFrame.of(reflector, spec)
        return traced.reflected(reflector), traced.edge_drop_mask(spec, edge.probability, edge.beam_diameter)

    t_first = best_of(first_frame, repeat)
    _, mask = first_frame()
    for row in rows[1:]:
        row["first_frame_extra_s"] = t_first
    notes = {
        "threads": os.cpu_count(),
        "sensor_height_m": HEIGHT,
        "paper_s_per_frame": 27.6,
        "target_scan_s": 0.5,
        "edge_mask_dropped_pixel_fraction": float((mask > 0).mean()),
        "load_average_1min": os.getloadavg()[0],
        "scan_s": "per frame, wall: Embree trace through the reflected rays (with scene mirrors and glass), edge drop, effects (pipeline.scan_buffers)",
        "scan_cpu_s": "per frame, CPU seconds of both threads together (less sensitive than wall time to other load on the machine)",
        "first_frame_extra_s": "once a run: tracing the sensor's own mirrors and building the edge-drop mask (kept for the next frames)",
    }
    print(f"paper: 27.6 s a frame; mirror sensor here: {reference:.3f} s a frame (+{t_first:.3f} s once a run); target 0.5 s; {os.cpu_count()} threads")
    name = "mirrors" + ("_small" if args.small else "")
    report(name, rows, args.out, notes)
    chart(rows, clouds["hall"], args.out / f"{name}.png")


def chart(rows, points, path):
    fig, (bars, top) = plt.subplots(1, 2, figsize=(14, 6), gridspec_kw={"width_ratios": [1, 1.2]})
    labels = [r["variant"].replace(", ", "\n") for r in rows]
    y = np.arange(len(rows))
    for offset, key, colour, name in ((-0.2, "scan_s", "#3070b0", "wall time"), (0.2, "scan_cpu_s", "#c08030", "CPU time, both threads")):
        values = [r[key] for r in rows]
        bars.barh(y + offset, values, height=0.4, color=colour, label=name)
        for i, v in enumerate(values):
            bars.text(v, i + offset, f" {v:.3f} s", va="center", fontsize=8)
    bars.set_yticks(y, labels)
    bars.axvline(0.5, color="red", linestyle="--", label="target 0.5 s")
    bars.set_xlabel(f"scan time per frame, s (2 cores; load average {os.getloadavg()[0]:.1f} while measured)")
    bars.invert_yaxis()
    bars.legend(loc="lower right")
    bars.set_title(f"{rows[1]['rays']:,} rays; Blender GN in the paper: 27.6 s")
    lut = load_class_table().color_lut() / 255.0
    order = np.argsort(points["z"])
    top.scatter(points["x"][order], points["y"][order], s=0.05, c=lut[points["semantic"][order]])
    top.set_aspect("equal")
    top.set_facecolor("#18181c")
    top.set_title("the frame from above (sensor frame, 6 m up): the star pattern")
    top.set_xlabel("x, m")
    top.set_ylabel("y, m")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    start = time.perf_counter()
    main()
    print(f"total {time.perf_counter() - start:.1f} s")
