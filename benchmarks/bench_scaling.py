"""Rays per second against scene size and against rays per scan.

The scene is a rolling terrain (a height field over 400 m x 400 m, ``2 s^2`` triangles for a
grid of ``s`` x ``s`` cells) with the sensor 2 m above its centre, so the rays meet the same
surface whatever its triangle count. Three rates on the same rays, all cores:

- ``raw embreex``: ``EmbreeScene.run`` over a thread pool on float32 rays, nothing else
- ``RayCaster.intersect``: the pipeline's caster (float64 re-solve of every hit)
- ``scan``: the whole scan (chunks of rays, records and labels)

First the scene grows from 10 thousand to 10 million triangles under a fixed 64-channel
pattern; then, on a 1-million-triangle terrain, the rays per scan grow from a thousand to
4 million. ``build_s`` is the caster's set-up (planes and Embree's BVH) for that scene.
Run: python benchmarks/bench_scaling.py [--small]
"""

import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from common import arguments, best_of, report
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.scanner import scan
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern

SIDE = 400.0  # m, terrain edge


def terrain(triangles: int) -> SceneBuffers:
    """A rolling height field of about ``triangles`` triangles over :data:`SIDE` x :data:`SIDE` m, centred on the origin."""
    cells = max(1, int(round((triangles / 2) ** 0.5)))
    s = np.linspace(-SIDE / 2, SIDE / 2, cells + 1)
    x, y = np.meshgrid(s, s, indexing="ij")
    z = 0.8 * np.sin(x / 23.0) * np.cos(y / 17.0) + 0.3 * np.sin((x + 2 * y) / 7.0)
    vertices = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    index = np.arange(x.size, dtype=np.int32).reshape(cells + 1, cells + 1)
    p, q, r, w = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    tris = np.concatenate([np.stack([p, q, r], 1), np.stack([p, r, w], 1)])
    return SceneBuffers.from_meshes({"terrain": (vertices, tris)})


def pattern_of(rays: int):
    """A 64-channel spinning pattern (-25..+15 deg) of about ``rays`` rays."""
    columns = max(1, rays // 64)
    return sensor_pattern(resolve_sensor({"preset": "custom", "channels": 64, "vertical_fov_deg": [-25, 15], "columns": columns, "min_range": 0.0,
                                          "max_range": 150.0}))


class Traced:
    """One terrain with its caster and a bare embreex scene of the same float32 geometry, built once.

    build_s : seconds to set up the caster (planes and Embree's BVH)
    """

    def __init__(self, buffers: SceneBuffers, threads: int):
        self.buffers, self.threads = buffers, threads
        self.pose = pose_matrix((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))  # the terrain passes through the origin
        start = time.perf_counter()
        self.caster = RayCaster(buffers, frame=self.pose, threads=threads)
        self.build_s = time.perf_counter() - start
        self.raw = rtcore_scene.EmbreeScene()
        TriangleMesh(self.raw, np.ascontiguousarray(self.caster.to_local(buffers.vertices), np.float32), buffers.triangles)
        self.raw.run(np.zeros((1, 3), np.float32), np.array([[0, 0, -1]], np.float32), output=1)  # commit before going parallel
        self.pool = ThreadPoolExecutor(threads)

    def raw_embreex(self, directions32: np.ndarray, chunk: int = 32768):
        """embreex alone over the thread pool, sensor frame: ``(tfar, primID, geomID)``."""
        origins32 = np.zeros_like(directions32)
        spans = [slice(i, i + chunk) for i in range(0, len(directions32), chunk)]
        parts = list(self.pool.map(lambda s: self.raw.run(origins32[s], directions32[s], dists=150.0, output=1), spans))
        return tuple(np.concatenate([p[k] for p in parts]) for k in ("tfar", "primID", "geomID"))

    def rates(self, pattern, repeat: int = 3) -> dict:
        """Rays per second of the three ways with ``pattern`` from 2 m above the origin."""
        d, d32 = pattern.directions, pattern.directions.astype(np.float32)
        rays = len(d)
        t_raw = best_of(lambda: self.raw_embreex(d32), repeat)
        t_intersect = best_of(lambda: self.caster.intersect(np.zeros(3), d, 150.0, d32), repeat)
        t_scan = best_of(lambda: scan(self.caster, self.buffers, pattern, self.pose, 0.0, 150.0), repeat)
        return {
            "triangles": len(self.buffers.triangles), "rays": rays, "hits": int((self.raw_embreex(d32)[2] >= 0).sum()), "build_s": self.build_s,
            "raw_embreex_rays_per_s": rays / t_raw, "intersect_rays_per_s": rays / t_intersect, "scan_rays_per_s": rays / t_scan,
            "scan_vs_raw": t_raw / t_scan,
        }  # fmt: skip


def chart(size_rows: list[dict], ray_rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for key, label, style in (("raw_embreex_rays_per_s", "raw embreex", "o-"), ("intersect_rays_per_s", "RayCaster.intersect", "s-"),
                              ("scan_rays_per_s", "scan (records)", "^-")):
        left.loglog([r["triangles"] for r in size_rows], [r[key] for r in size_rows], style, label=label)
        right.loglog([r["rays"] for r in ray_rows], [r[key] for r in ray_rows], style, label=label)
    left.set(xlabel="triangles in the scene", ylabel="rays per second", title=f"Scene size ({size_rows[0]['rays']:,} rays a scan)")
    right.set(xlabel="rays per scan", title=f"Rays per scan ({ray_rows[0]['triangles']:,} triangles)")
    for ax in (left, right):
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    args = arguments(__doc__)
    threads = os.cpu_count() or 1
    sizes = [1e4, 3e4, 1e5] if args.small else [1e4, 3e4, 1e5, 3e5, 1e6, 3e6, 1e7]
    pattern = pattern_of(20_000 if args.small else 230_400)
    size_rows = [{"series": "scene size", **Traced(terrain(int(n)), threads).rates(pattern, 7)} for n in sizes]  # shared machines are noisy
    traced = Traced(terrain(int(1e5 if args.small else 1e6)), threads)
    counts = [1e3, 1e4, 1e5] if args.small else [1e3, 1e4, 1e5, 1e6, 4e6]
    ray_rows = [{"series": "rays per scan", **traced.rates(pattern_of(int(n)), 7 if n <= 1e5 else 3)} for n in counts]
    name = "scaling" + ("_small" if args.small else "")
    report(name, size_rows + ray_rows, args.out, {"threads": threads, "terrain_m": SIDE})
    chart(size_rows, ray_rows, args.out / f"{name}.png")


if __name__ == "__main__":
    main()
