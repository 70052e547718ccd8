"""Scan speed: the full scan (records and labels) beside raw embreex on the same scene and rays.

Both use every core: the reference is embreex's own ``EmbreeScene.run(..., output=1)`` on the
same float32 rays, chunked over a thread pool, with nothing else done. The ratio of the two
rates is the figure that matters (target: at least 0.8).
Run: python benchmarks/bench_scan.py [--small]
"""

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from common import arguments, best_of, report

import bpy  # noqa: E402
from embreex import rtcore_scene  # noqa: E402
from embreex.mesh_construction import TriangleMesh  # noqa: E402

from bpy_pipeline.config import load_config  # noqa: E402
from bpy_pipeline.export import export_scene  # noqa: E402
from bpy_pipeline.geometry.transforms import pose_matrix  # noqa: E402
from bpy_pipeline.labels import load_class_table  # noqa: E402
from bpy_pipeline.lidar.raycast import RayCaster  # noqa: E402
from bpy_pipeline.lidar.scanner import scan  # noqa: E402
from bpy_pipeline.lidar.sensors import sensor_pattern  # noqa: E402
from bpy_pipeline.pipeline import frame_rng  # noqa: E402
from bpy_pipeline.scenes import build_scene  # noqa: E402
from bench_export import gn_object, grid  # noqa: E402


def raw_embreex(vertices32, triangles, origins32, directions32, threads, chunk=16384):
    """Reference: embreex alone, every core, same chunking; returns hit count."""
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, vertices32, triangles)
    scene.run(origins32[:1], directions32[:1], output=1)  # commit before going parallel
    spans = [slice(i, i + chunk) for i in range(0, len(origins32), chunk)]

    def run():
        with ThreadPoolExecutor(threads) as pool:
            return sum(int((out["geomID"] >= 0).sum()) for out in pool.map(lambda s: scene.run(origins32[s], directions32[s], output=1), spans))

    return run


def measure(config, terrain_side: int) -> dict:
    """Scan the default railway (plus a GN terrain grid of ~2 side^2 triangles when side > 0)."""
    build_scene(config.scene, frame_rng(0, 0))
    if terrain_side:
        terrain = gn_object("terrain", grid(terrain_side))
        terrain.scale = (200.0, 200.0, 1.0)
        terrain.location = (0.0, 0.0, -0.01)
    buffers = export_scene(load_class_table())
    pattern = sensor_pattern(config.sensor.spec)
    pose = pose_matrix(config.sensor.position, config.sensor.rotation_deg)
    threads = os.cpu_count()

    caster = RayCaster(buffers, frame=pose, threads=threads)
    full = lambda: scan(caster, buffers, pattern, pose, 0.2, 150.0)  # noqa: E731
    points, _ = full()
    t_full = best_of(full)

    vertices32 = np.ascontiguousarray(buffers.vertices - pose[:3, 3], np.float32)
    directions32 = np.ascontiguousarray(pattern.directions @ pose[:3, :3].T, np.float32)
    origins32 = np.zeros_like(directions32)
    raw = raw_embreex(vertices32, buffers.triangles, origins32, directions32, threads)
    raw_hits = raw()
    t_raw = best_of(raw)

    rays = len(pattern)
    return {
        "triangles": len(buffers.triangles), "rays": rays, "hits": len(points), "raw_hits": raw_hits,
        "raw_embreex_rays_per_s": rays / t_raw, "scan_rays_per_s": rays / t_full, "ratio": t_raw / t_full,
    }


def main():
    args = arguments(__doc__)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    resolution = 0.4 if args.small else 0.1
    config = load_config(None, ["sensor.preset=custom", "sensor.channels=320", "sensor.vertical_fov_deg=[-70, 90]",
                                f"sensor.horizontal_resolution_deg={resolution}", "sensor.min_range=0.2", "sensor.max_range=150", "sensor.position=[0, -4, 2]"])
    rows = []
    for label, side in (("default railway", 0), ("railway on a GN terrain grid", 200 if args.small else 708)):
        rows.append({"scene": label, **measure(config, side)})
    print(f"ratio = scan / raw embreex throughput, target >= 0.8; {os.cpu_count()} threads")
    report("scan" + ("_small" if args.small else ""), rows, args.out, {"threads": os.cpu_count()})


if __name__ == "__main__":
    main()
