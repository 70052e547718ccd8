"""Ray casters side by side: speed against accuracy, on the same scene and rays, in one run.

The scene is :mod:`bench_far_origin`'s (ground, wall, a car-sized box, a pillar and a 12 mm
wire, axis-aligned in their own frame and turned 37 degrees in the world, planes split into
a grid of triangles), near the world origin; the rays are a 64-channel spinning sensor's
(0.1 deg steps, 150 m) 1.8 m above the ground. Every method's hit points are compared with
the exact intersections: the largest position error over the rays that hit the surface the
exact answer hits, and the rays that hit another surface or none.

- ``embreex raw``: ``EmbreeScene.run`` on float32 rays over a thread pool, Embree's float32 distance
- ``RayCaster.intersect``: the pipeline's caster (sensor frame, float64 re-solve, vertex re-traces)
- ``Open3D RaycastingScene``: ``open3d.t.geometry.RaycastingScene.cast_rays`` (Embree inside), float32
  distances and no labels; skipped with a note where open3d is not importable
- ``scan (records)``: the whole scan, point records and labels included (float32 x y z), with the
  compiled kernel when numba is installed; ``scan (records, numpy path)``: the same with ``kernel="numpy"``
- ``trimesh + embreex``: ``trimesh.ray.ray_pyembree.RayMeshIntersector.intersects_location``
- ``Blender BVHTree``: ``mathutils.bvhtree.BVHTree.FromPolygons`` and ``ray_cast`` in a Python
  loop, world coordinates, as BlAInder does; timed on a subset of the rays and extrapolated
- ``Blender scene.ray_cast``: ``bpy.types.Scene.ray_cast`` over the evaluated depsgraph, subset
- ``trimesh ray_triangle`` (pure numpy) needs the ``rtree`` package for its broad phase; it is
  not a dependency of this project and is reported as not run when it is not installed.

Rays per second use every core for Embree-based methods (embreex releases the GIL while
tracing); trimesh's wrapper and Blender's ray casts run on one thread. The Embree-based methods
are timed in interleaved rounds (best of 5 each), so a busy moment of a shared machine hits all
of them alike; ``vs_embreex_raw`` is each one's speed over raw embreex's in the same run.

Watertightness, separately: rays from 200 places around a closed UV sphere (24 segments),
each aimed exactly at a vertex where it enters the sphere; ``slipped_vertex_rays`` counts
those that pass into it without a hit there (a hit more than 1 cm beyond the vertex, or none).
``embreex (robust off)`` is the same raw query on a scene built without Embree's robust flag.
Run: python benchmarks/bench_raycasters.py [--small]
"""

import importlib.util
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from common import arguments, report

import bpy
from bench_far_origin import BOXES, SENSOR, TURN_DEG, analytic_scene, exact_hits, placed
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.compiled import numba_available
from bpy_pipeline.lidar.cast.raycast import RayCaster, default_threads
from bpy_pipeline.lidar.cast.scanner import scan, scan_chunk
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern


REPEAT = 5  # interleaved timing rounds; the best of each method counts


class Setup:
    """The scene, the rays and the exact answer."""

    def __init__(self, small: bool):
        self.scene_pose = pose_matrix((0.0, 0.0, 0.0), TURN_DEG)
        self.buffers = placed(analytic_scene(cells=30 if small else 220), self.scene_pose)
        spec = resolve_sensor({"preset": "custom", "channels": 16 if small else 64, "vertical_fov_deg": [-25, 15],
                               "horizontal_resolution_deg": 1.0 if small else 0.1, "min_range": 0.0, "max_range": 150.0})
        self.pattern = sensor_pattern(spec)
        self.max_range = spec.max_range
        self.pose = pose_matrix(self.scene_pose[:3, :3] @ SENSOR, np.add(TURN_DEG, (0.0, 0.0, 5.0)))
        self.origin = self.pose[:3, 3]
        self.directions = self.pattern.directions @ self.pose[:3, :3].T  # world
        t, self.exact_row = exact_hits(np.asarray(SENSOR), self.directions @ self.scene_pose[:3, :3], self.max_range)
        self.exact_point = self.origin + self.directions * np.where(self.exact_row >= 0, t, 0.0)[:, None]

    def score(self, ray: np.ndarray, point: np.ndarray, row: np.ndarray, subset: np.ndarray | None = None) -> dict:
        """Accuracy of hits ``ray`` (indices), world ``point`` (h, 3), object ``row`` (h,), over ``subset`` of the rays."""
        rows = np.full(len(self.directions), -1)
        rows[ray] = row
        points = np.zeros((len(self.directions), 3))
        points[ray] = point
        sel = np.arange(len(self.directions)) if subset is None else subset
        right = (rows[sel] == self.exact_row[sel]) & (rows[sel] >= 0)
        error = np.linalg.norm(points[sel][right] - self.exact_point[sel][right], axis=1)
        return {"max_error_m": float(error.max()), "wrong_rays": int(np.count_nonzero(rows[sel] != self.exact_row[sel])), "compared_rays": len(sel)}


def embreex_raw(setup: Setup, threads: int):
    vertices32 = np.ascontiguousarray(setup.buffers.vertices, np.float32)
    start = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, vertices32, setup.buffers.triangles)
    o32 = np.tile(setup.origin.astype(np.float32), (len(setup.directions), 1))
    d32 = np.ascontiguousarray(setup.directions, np.float32)
    scene.run(o32[:1], d32[:1], output=1)  # commit
    build = time.perf_counter() - start
    spans = [slice(i, i + 32768) for i in range(0, len(d32), 32768)]
    pool = ThreadPoolExecutor(threads)

    def run():
        return list(pool.map(lambda s: scene.run(o32[s], d32[s], dists=setup.max_range, output=1), spans))

    out = {k: np.concatenate([p[k] for p in run()]) for k in ("tfar", "primID", "geomID")}
    ray = np.flatnonzero(out["geomID"] >= 0)
    point = o32[ray].astype(np.float64) + d32[ray].astype(np.float64) * out["tfar"][ray, None].astype(np.float64)
    return run, build, setup.score(ray, point, setup.buffers.triangle_object[out["primID"][ray]])


def raycaster(setup: Setup, threads: int):
    start = time.perf_counter()
    caster = RayCaster(setup.buffers, frame=setup.pose, threads=threads)
    build = time.perf_counter() - start
    d = setup.pattern.directions
    d32 = d.astype(np.float32)
    hits = caster.intersect(np.zeros(3), d, setup.max_range, d32)
    point = (d[hits.ray] * hits.distance[:, None]) @ setup.pose[:3, :3].T + setup.origin
    return (lambda: caster.intersect(np.zeros(3), d, setup.max_range, d32)), build, setup.score(hits.ray, point, setup.buffers.triangle_object[hits.triangle])


def open3d_raycast(setup: Setup, threads: int):
    """Open3D's ``RaycastingScene.cast_rays`` (Embree inside), world float32, no maximum distance: hits beyond are dropped."""
    import open3d as o3d

    vertices32 = np.ascontiguousarray(setup.buffers.vertices, np.float32)
    start = time.perf_counter()
    scene = o3d.t.geometry.RaycastingScene(nthreads=threads)
    scene.add_triangles(o3d.core.Tensor(vertices32), o3d.core.Tensor(np.ascontiguousarray(setup.buffers.triangles, np.uint32)))
    o32 = np.tile(setup.origin.astype(np.float32), (len(setup.directions), 1))
    d32 = np.ascontiguousarray(setup.directions, np.float32)
    rays = o3d.core.Tensor(np.ascontiguousarray(np.hstack([o32, d32])))
    scene.cast_rays(rays[:1], nthreads=threads)  # builds its scene
    build = time.perf_counter() - start
    out = scene.cast_rays(rays, nthreads=threads)
    t, triangle = out["t_hit"].numpy(), out["primitive_ids"].numpy()
    ray = np.flatnonzero(t <= setup.max_range)
    point = o32[ray].astype(np.float64) + d32[ray].astype(np.float64) * t[ray, None].astype(np.float64)
    return (lambda: scene.cast_rays(rays, nthreads=threads)), build, setup.score(ray, point, setup.buffers.triangle_object[triangle[ray]])


def full_scan(setup: Setup, threads: int, kernel: str = "auto"):
    caster = RayCaster(setup.buffers, frame=setup.pose, threads=threads, kernel=kernel)
    scan(caster, setup.buffers, setup.pattern, setup.pose, 0.0, setup.max_range)
    points, _, ray = scan_chunk(caster, setup.buffers, setup.pattern, np.eye(4), 0.0, setup.max_range)
    xyz = np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64) @ setup.pose[:3, :3].T + setup.origin
    row = np.searchsorted(setup.buffers.objects.instance, points["instance"])  # instance ids are 1..k in row order
    return (lambda: scan(caster, setup.buffers, setup.pattern, setup.pose, 0.0, setup.max_range)), None, setup.score(ray, xyz, row)


def trimesh_embree(setup: Setup, threads: int):
    import trimesh
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    mesh = trimesh.Trimesh(setup.buffers.vertices, setup.buffers.triangles, process=False)
    origins = np.tile(setup.origin, (len(setup.directions), 1))
    start = time.perf_counter()
    intersector = RayMeshIntersector(mesh)
    intersector.intersects_first(origins[:1], setup.directions[:1])  # builds its scene
    build = time.perf_counter() - start
    location, ray, triangle = intersector.intersects_location(origins, setup.directions, multiple_hits=False)
    far = np.linalg.norm(location - setup.origin, axis=1) > setup.max_range  # trimesh has no maximum distance
    ray, location, triangle = ray[~far], location[~far], triangle[~far]
    return (
        (lambda: intersector.intersects_location(origins, setup.directions, multiple_hits=False)),
        build,
        setup.score(ray, location, setup.buffers.triangle_object[triangle]),
    )


def subset_of(setup: Setup, count: int) -> np.ndarray:
    """``count`` rays spread over the whole pattern (every k-th)."""
    return np.arange(0, len(setup.directions), max(1, len(setup.directions) // count))


def blender_bvhtree(setup: Setup, threads: int, count: int):
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    start = time.perf_counter()
    tree = BVHTree.FromPolygons(setup.buffers.vertices.tolist(), setup.buffers.triangles.tolist(), all_triangles=True)
    build = time.perf_counter() - start
    subset = subset_of(setup, count)
    origin = Vector(setup.origin)
    directions = setup.directions[subset].tolist()
    start = time.perf_counter()
    results = [tree.ray_cast(origin, Vector(d), setup.max_range) for d in directions]
    seconds = (time.perf_counter() - start) * len(setup.directions) / len(subset)
    hit = np.array([r[0] is not None for r in results])
    point = np.array([tuple(r[0]) for r in results if r[0] is not None]).reshape(-1, 3)
    index = np.array([r[2] for r in results if r[0] is not None], np.int64)
    return seconds, build, setup.score(subset[hit], point, setup.buffers.triangle_object[index], subset)


def blender_scene_ray_cast(setup: Setup, threads: int, count: int):
    from bpy_pipeline.blender.mesh_objects import mesh_object, scene_collection

    bpy.ops.wm.read_factory_settings(use_empty=True)
    start = time.perf_counter()
    objects = {}
    collection = scene_collection()
    for row, name in enumerate(setup.buffers.objects.names):
        mask = setup.buffers.triangle_object == row
        triangles = setup.buffers.triangles[mask]
        used = np.unique(triangles)
        remap = np.searchsorted(used, triangles)
        objects[mesh_object(name, (setup.buffers.vertices[used], remap), collection).name] = row
    depsgraph = bpy.context.evaluated_depsgraph_get()
    scene = bpy.context.scene
    scene.ray_cast(depsgraph, tuple(setup.origin), (0.0, 0.0, -1.0))  # builds Blender's scene BVH
    build = time.perf_counter() - start
    subset = subset_of(setup, count)
    origin = tuple(setup.origin)
    directions = [tuple(d) for d in setup.directions[subset].tolist()]
    start = time.perf_counter()
    results = [scene.ray_cast(depsgraph, origin, d, distance=setup.max_range) for d in directions]
    seconds = (time.perf_counter() - start) * len(setup.directions) / len(subset)
    hit = np.array([r[0] for r in results])
    point = np.array([tuple(r[1]) for r in results if r[0]]).reshape(-1, 3)
    row = np.array([objects[r[4].original.name] for r in results if r[0]], np.int64)
    return seconds, build, setup.score(subset[hit], point, row, subset)


def vertex_rays(seed: int = 0, places: int = 200):
    """A closed UV sphere (turned) and rays aimed exactly at its vertices, entering it there.

    Returns ``(vertices, triangles, origins (n, 3), directions (n, 3), distances (n,))``, world frame.
    """
    vertices, triangles = primitives.uv_sphere(1.5, 24)
    vertices = vertices @ pose_matrix((0, 0, 0), (17, -33, 61))[:3, :3].T
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    depth = lambda p: -(p @ normal.T - np.einsum("ij,ij->i", normal, a)).max(axis=1)  # noqa: E731  > 0 inside
    rng = np.random.default_rng(seed)
    origins, directions, distances = [], [], []
    for _ in range(places):
        sensor = rng.normal(size=3)
        sensor *= rng.uniform(3.0, 40.0) / np.linalg.norm(sensor)
        d = vertices - sensor
        distance = np.linalg.norm(d, axis=1)
        d /= distance[:, None]
        enters = (depth(vertices + 0.01 * d) > 1e-5) & (depth(vertices - 0.01 * d) < -1e-5)
        origins.append(np.repeat(sensor[None], enters.sum(), axis=0))
        directions.append(d[enters])
        distances.append(distance[enters])
    return vertices, triangles, np.concatenate(origins), np.concatenate(directions), np.concatenate(distances)


def slipped_vertex_rays() -> tuple[dict, int]:
    """Per method, how many vertex-aimed rays slip into the sphere (:func:`vertex_rays`); and how many rays."""
    import trimesh
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    vertices, triangles, origins, directions, distance = vertex_rays()
    far = np.full(len(distance), np.inf)
    slipped = lambda got: int(np.count_nonzero(~(got <= distance + 0.01)))  # noqa: E731
    out = {}
    for name, robust in (("embreex raw", True), ("embreex (robust off)", False)):
        scene = rtcore_scene.EmbreeScene(robust=robust)
        TriangleMesh(scene, vertices.astype(np.float32), triangles)
        hit = scene.run(origins.astype(np.float32), directions.astype(np.float32), output=1)
        out[name] = slipped(np.where(hit["geomID"] >= 0, hit["tfar"], np.inf))
    buffers = SceneBuffers.from_meshes({"sphere": (vertices, triangles)})
    hits = RayCaster(buffers, frame=np.eye(4)).intersect(origins, directions)
    got = far.copy()
    got[hits.ray] = hits.distance
    out["RayCaster.intersect"] = out["scan (records)"] = out["scan (records, numpy path)"] = slipped(got)
    if importlib.util.find_spec("open3d") is not None:
        import open3d as o3d

        o3d_scene = o3d.t.geometry.RaycastingScene()
        o3d_scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32)))
        t_hit = o3d_scene.cast_rays(o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32)))["t_hit"].numpy()
        out["Open3D RaycastingScene"] = slipped(np.where(np.isfinite(t_hit), t_hit, np.inf))
    location, ray, _ = RayMeshIntersector(trimesh.Trimesh(vertices, triangles, process=False)).intersects_location(origins, directions, multiple_hits=False)
    got = far.copy()
    got[ray] = np.linalg.norm(location - origins[ray], axis=1)
    out["trimesh + embreex"] = slipped(got)
    tree = BVHTree.FromPolygons(vertices.tolist(), triangles.tolist(), all_triangles=True)
    got = np.array([r[3] if r[0] is not None else np.inf for r in (tree.ray_cast(Vector(o), Vector(d)) for o, d in zip(origins.tolist(), directions.tolist()))])
    out["Blender BVHTree"] = slipped(got)
    return out, len(distance)


def chart(rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for i, r in enumerate(r for r in rows if r.get("rays_per_s")):
        ax.loglog(r["rays_per_s"], max(r["max_error_m"], 1e-15), "o")
        ax.annotate(r["method"], (r["rays_per_s"], max(r["max_error_m"], 1e-15)), textcoords="offset points", xytext=(6, 5 if i % 2 else -12), fontsize=8)
    ax.set(xlabel="rays per second", ylabel="largest position error (m)",
           title=f"Speed against accuracy ({rows[0]['rays']:,} rays, {rows[0]['triangles']:,} triangles)")
    ax.axhline(1e-4, color="grey", lw=0.8, ls=":")
    ax.grid(True, which="major", alpha=0.3)
    lo, hi = ax.get_xlim()
    ax.set_xlim(lo, hi * 8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    args = arguments(__doc__)
    threads = default_threads()
    # numba's import and kernel load (~0.6 s, once a process) out of the timings
    RayCaster(SceneBuffers.from_meshes({"warm-up": primitives.box(1, 1, 1)}), frame=np.eye(4))
    setup = Setup(args.small)
    count = 5000 if args.small else 50000  # rays timed for Blender's ray casts (a Python loop)
    methods = [
        ("embreex raw", embreex_raw, threads, "float32 distance"),
        ("RayCaster.intersect", raycaster, threads, "sensor frame, float64 re-solve"),
        ("scan (records)", full_scan, threads,
         "point records: float32 x y z" + ("; compiled kernel" if numba_available() else "; numba absent: numpy path")),
        ("scan (records, numpy path)", lambda s, t: full_scan(s, t, "numpy"), threads, "point records, kernel='numpy'"),
        ("trimesh + embreex", trimesh_embree, 1, "trimesh.ray.ray_pyembree"),
        ("Blender BVHTree", lambda s, t: blender_bvhtree(s, t, count), 1, f"Python loop; {count:,} rays timed, extrapolated"),
        ("Blender scene.ray_cast", lambda s, t: blender_scene_ray_cast(s, t, count), 1, f"Python loop; {count:,} rays timed, extrapolated"),
    ]
    if importlib.util.find_spec("open3d") is not None:
        methods.insert(1, ("Open3D RaycastingScene", open3d_raycast, threads, "open3d.t.geometry.RaycastingScene.cast_rays, float32 distance, no labels"))
    rows = []
    common = {"rays": len(setup.directions), "triangles": len(setup.buffers.triangles), "hits": int((setup.exact_row >= 0).sum())}
    timed = {}
    for name, fn, used_threads, note in methods:
        seconds, build, accuracy = fn(setup, used_threads)
        if callable(seconds):  # timed below, interleaved with the other callables
            timed[name], seconds = seconds, None
        rows.append({"method": name, **common, "threads": used_threads, "rays_per_s": seconds, "build_s": build, **accuracy, "note": note})
    best = {name: np.inf for name in timed}
    for _ in range(REPEAT):  # interleaved rounds: a busy moment of the shared machine hits every method alike
        for name, fn in timed.items():
            start = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - start)
    for r in rows:
        if r["method"] in best:
            r["rays_per_s"] = len(setup.directions) / best[r["method"]]
        elif r["rays_per_s"] is not None:
            r["rays_per_s"] = len(setup.directions) / r["rays_per_s"]
    slips, vertex_ray_count = slipped_vertex_rays()
    for r in rows:
        r["slipped_vertex_rays"] = slips.get(r["method"])
    rows.append({"method": "embreex (robust off)", **common, "slipped_vertex_rays": slips["embreex (robust off)"], "note": "watertightness only"})
    if importlib.util.find_spec("open3d") is None:
        rows.append({"method": "Open3D RaycastingScene", **common, "note": "not run: open3d is not installed (pip install open3d; Debian needs libusb-1.0-0)"})
    if importlib.util.find_spec("rtree") is None:
        rows.append({"method": "trimesh ray_triangle", **common, "note": "not run: needs the rtree package (not a dependency)"})
    reference = rows[0]["rays_per_s"]
    for r in rows:
        if r.get("rays_per_s"):
            r["vs_embreex_raw"] = r["rays_per_s"] / reference
    name = "raycasters" + ("_small" if args.small else "")
    report(name, rows, args.out, {"threads": threads, "wire_hits_exact": int((setup.exact_row == list(BOXES).index("wire")).sum()),
                                  "vertex_rays": vertex_ray_count})
    chart(rows, args.out / f"{name}.png")


if __name__ == "__main__":
    main()
