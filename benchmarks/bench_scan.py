"""Scan speed: the full scan (records and labels) beside raw embreex on the same scene and rays.

Scenes: an Ouster OS1-128 (131 k rays) near the middle of a closed 40 m box (numpy buffers), and
the default railway job's scene and sensor (railway_tls, 1.44 M rays; with ``--small`` sampled
at 0.1), and the parking builder's first frame with its sensor (cars with glass windows: the
rays meeting glass go on in the numpy path). Outside ``--small`` a third scene adds a 1-million-triangle
Geometry Nodes terrain under the railway, for the caster's set-up cost.

All in one process and one run, every core for Embree:
- ``raw embreex``: embreex's own ``EmbreeScene.run(..., output=1)`` on the caster's float32 rays
  (the same zero origin repeated by strides) in the same chunks over a thread pool of the same
  size, nothing else done (the reference);
- ``scan``: :func:`bpy_pipeline.lidar.cast.scanner.scan` with the compiled kernel (numba, when
  installed: Embree called from inside the pass) and with ``kernel="numpy"``; ``ratio`` = raw
  time / scan time (target >= 0.8), best of interleaved rounds (about a second of raw tracing, at least 7);
- ``post_ns_per_hit``: (scan time - raw time) / hits, wall time of the work after Embree (one core);
  ``kernel_pass_ns_per_hit``: the kernel's pass alone over an answer embreex gave (one core);
- set-up per triangle: ``RayCaster(...)`` (target <= 150 ns); Embree's own build of the same
  buffers read in place (the floor: the caster's set-up less its checks, planes and float32 copy);
  embreex's ``TriangleMesh`` plus commit (the copy it makes); and a
  :class:`~bpy_pipeline.lidar.cast.raycast.CasterCache` handing back the kept caster for the next frame.
Run: python benchmarks/bench_scan.py [--small]
"""

import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from common import arguments, best_of, report

import bpy
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.compiled import numba_available
from bpy_pipeline.config import load_config
from bpy_pipeline.blender.export import export_scene
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.cast import kernels
from bpy_pipeline.lidar.cast.embree import attach_triangles
from bpy_pipeline.lidar.points import BEAM_DTYPE, POINT_DTYPE
from bpy_pipeline.lidar.cast.raycast import CasterCache, RayCaster, default_threads
from bpy_pipeline.lidar.cast.scanner import scan
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern
from bpy_pipeline.frame import frame_rng
from bpy_pipeline.stages.view import sensor_pose
from bpy_pipeline.blender import build_scene

REPEAT = 7


def raw_embreex(caster: RayCaster, directions32: np.ndarray, max_range: float):
    """Reference: embreex alone on the caster's local float32 vertices, same chunks and threads; returns (run, hits)."""
    buffers = caster.buffers
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(caster.to_local(buffers.vertices), np.float32), buffers.triangles)
    origins32 = np.lib.stride_tricks.as_strided(np.zeros(3, np.float32), directions32.shape, (0, 4), writeable=True)  # the caster's own zero origin
    scene.run(origins32[:1], directions32[:1], output=1)  # commit before going parallel
    spans = [slice(i, i + caster.chunk) for i in range(0, len(directions32), caster.chunk)]
    pool = ThreadPoolExecutor(caster.threads)

    def run():
        return sum(int((out["geomID"] >= 0).sum()) for out in pool.map(lambda s: scene.run(origins32[s], directions32[s], dists=max_range, output=1), spans))

    return run


def set_up(buffers: SceneBuffers, pose: np.ndarray, threads: int) -> dict:
    """Seconds per triangle to build a caster, embreex's copy-and-commit alone, and a cached caster's hand-back."""
    m = len(buffers.triangles)
    caster_s = best_of(lambda: RayCaster(buffers, frame=pose, threads=threads), REPEAT)
    local32 = np.ascontiguousarray((buffers.vertices - pose[:3, 3]) @ pose[:3, :3], np.float32)

    def triangle_mesh():
        scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene, local32, buffers.triangles)
        scene.run(np.zeros((1, 3), np.float32), np.float32([[0, 0, 1]]), output=1)

    copy_s = best_of(triangle_mesh, REPEAT)

    def embree_build():
        scene = rtcore_scene.EmbreeScene()
        keep = attach_triangles(scene, local32, buffers.triangles)  # noqa: F841 (Embree reads it until the scene goes)
        scene.run(np.zeros((1, 3), np.float32), np.float32([[0, 0, 1]]), output=1)

    build_s = best_of(embree_build, REPEAT)
    cache = CasterCache(threads)
    cache.caster(buffers, pose)
    kept_s = best_of(lambda: cache.caster(buffers, pose), REPEAT)
    return {"caster_ns_per_triangle": caster_s / m * 1e9, "embree_build_ns_per_triangle": build_s / m * 1e9, "triangle_mesh_ns_per_triangle": copy_s / m * 1e9,
            "cached_ns_per_triangle": kept_s / m * 1e9}


def measure(label: str, buffers: SceneBuffers, pattern, pose: np.ndarray, min_range: float, max_range: float, threads: int, small: bool = False) -> dict:
    rays = len(pattern)
    fused = RayCaster(buffers, frame=pose, threads=threads, kernel="auto")
    plain = RayCaster(buffers, frame=pose, threads=threads, kernel="numpy")
    points, _ = scan(fused, buffers, pattern, pose, min_range, max_range)  # compiles (or loads) the kernel
    reference, _ = scan(plain, buffers, pattern, pose, min_range, max_range)
    assert points.tobytes() == reference.tobytes(), "the kernel and numpy paths disagree"
    raw = raw_embreex(fused, pattern.directions.astype(np.float32), max_range)
    raw_hits = raw()
    timed = {"raw": raw, "numpy": lambda: scan(plain, buffers, pattern, pose, min_range, max_range)}
    if fused.kernels is not None:
        timed["kernel"] = lambda: scan(fused, buffers, pattern, pose, min_range, max_range)
    best = {name: np.inf for name in timed}
    start = time.perf_counter()
    raw()
    rounds = 3 if small else int(np.clip(1.0 / (time.perf_counter() - start), REPEAT, 200))  # about a second of raw tracing: small scenes get many rounds
    for _ in range(rounds):  # interleaved, so a busy moment of the shared machine hits every method alike
        for name, fn in timed.items():
            start = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - start)
    hits = len(points)
    row = {"scene": label, "triangles": len(buffers.triangles), "rays": rays, "hits": hits, "raw_hits": raw_hits, "threads": threads,
           "raw_embreex_rays_per_s": rays / best["raw"], "numpy_ratio": best["raw"] / best["numpy"],
           "numpy_post_ns_per_hit": (best["numpy"] - best["raw"]) / hits * 1e9}  # fmt: skip
    if "kernel" in best:
        row.update({"kernel_ratio": best["raw"] / best["kernel"], "kernel_post_ns_per_hit": (best["kernel"] - best["raw"]) / hits * 1e9,
                    "kernel_pass_ns_per_hit": kernel_pass(fused, buffers, pattern, min_range, max_range) / hits * 1e9})  # fmt: skip
    if len(buffers.triangles) >= 10000:  # per triangle, only where triangles dominate the fixed costs
        row.update(set_up(buffers, pose, threads))
    return row


def kernel_pass(caster: RayCaster, buffers: SceneBuffers, pattern, min_range: float, max_range: float) -> float:
    """Seconds of the kernel's pass alone over Embree's answer (one core)."""
    d = np.ascontiguousarray(pattern.directions)
    local, o32, d32, far = caster.launch(np.zeros(3), d, max_range)
    tfar, prim = caster._embree(o32, d32, far)
    n = len(d)
    points, beam, ray = np.empty(n, POINT_DTYPE), np.empty(n, BEAM_DTYPE), np.empty(n, np.int64)
    origins = np.zeros((1, 3))
    identity = np.zeros(0, np.int64) if caster.embree_triangle is None else caster.embree_triangle
    none = np.zeros(0, np.bool_)
    return best_of(lambda: kernels.fill_diffuse(caster.kernels, tfar, prim, identity, none, origins, d, caster, buffers.objects, pattern.ring, pattern.time,
                                                min_range, max_range, points, beam, ray), REPEAT)


def box_scene(small: bool):
    """An OS1-128 near the middle of a closed 40 m box (walls 10 m high, normals outward: seen from inside), its pose and pattern."""
    buffers = SceneBuffers.from_meshes({"box": primitives.box(40.0, 40.0, 10.0)})
    spec = resolve_sensor({"preset": "os1_128"})
    return buffers, sensor_pattern(spec), pose_matrix([0.2, -0.3, 0.1], [0, 0, 0]), spec


def parking_scene():
    """The parking builder's first frame (cars with glass windows) and its sensor."""
    config = load_config(None, ["scene.builder=parking"])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    build_scene(config.scene, frame_rng(0, 0))
    return export_scene(load_class_table()), sensor_pattern(config.sensor.spec), sensor_pose(config), config.sensor.spec


def railway_scene(small: bool, terrain_side: int = 0):
    overrides = ["sensor.sampling_factor=0.1"] if small else []
    config = load_config(None, overrides)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    build_scene(config.scene, frame_rng(0, 0))
    if terrain_side:
        from bench_export import gn_object, grid

        terrain = gn_object("terrain", grid(terrain_side))
        terrain.scale = (200.0, 200.0, 1.0)
        terrain.location = (0.0, 0.0, -0.01)
    buffers = export_scene(load_class_table())
    spec = config.sensor.spec
    return buffers, sensor_pattern(spec), sensor_pose(config), spec


def main():
    args = arguments(__doc__)
    threads = default_threads()
    # numba's import and kernel load (~0.6 s, once a process) out of the timings
    RayCaster(SceneBuffers.from_meshes({"warm-up": primitives.box(1, 1, 1)}), frame=np.eye(4))
    rows = []
    buffers, pattern, pose, spec = box_scene(args.small)
    rows.append(measure("os1_128 in a 40 m box", buffers, pattern, pose, spec.min_range, spec.max_range, threads, args.small))
    buffers, pattern, pose, spec = railway_scene(args.small)
    rows.append(measure("default railway (railway_tls)", buffers, pattern, pose, spec.min_range, spec.max_range, threads, args.small))
    buffers, pattern, pose, spec = parking_scene()
    rows.append(measure("parking, first frame (glass windows)", buffers, pattern, pose, spec.min_range, spec.max_range, threads, args.small))
    if not args.small:
        buffers, pattern, pose, spec = railway_scene(False, 708)
        rows.append(measure("railway on a 1 M-triangle GN terrain", buffers, pattern, pose, spec.min_range, spec.max_range, threads, args.small))
    print(f"ratio = raw embreex time / scan time (target >= 0.8); {threads} threads; numba {'installed' if numba_available() else 'not installed'}")
    report("scan" + ("_small" if args.small else ""), rows, args.out, {"threads": threads, "numba": numba_available(), "repeat": REPEAT})


if __name__ == "__main__":
    main()
