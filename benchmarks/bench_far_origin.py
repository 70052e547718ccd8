"""Position error against the distance from the world origin, with and without the local-frame shift.

One scene whose exact ray intersections are known (a 400 m ground plane, a wall 140 m out and a
car-sized box, all axis-aligned in the scene's own frame) is turned and placed 1 m to 100 km
from the world origin, and scanned by a 64-channel spinning sensor 1.8 m above its ground.
Four ways of tracing the same rays:

- ``shift + float64``: the pipeline (Embree in the sensor's frame, distance re-solved in float64
  against the hit triangle's plane: :class:`~bpy_pipeline.lidar.cast.raycast.RayCaster`)
- ``world + float64``: the same caster with Embree's scene in world coordinates (float32)
- ``shift, Embree t``: Embree in the sensor's frame, its own float32 distance
- ``world, Embree t``: Embree in world coordinates, its own distance: what a plain Embree,
  trimesh or Blender set-up gives (the hit point is the float32 origin plus t times the float32 direction)

Per distance and method: the largest position error (m) of a point against the exact
intersection, over the rays that hit the surface the exact answer hits, and the share of rays
that hit another surface or none (or one where there is none). A far-out float32 scene
misplaces its triangles' edges by up to half a float32 step (3.9 mm at 65-131 km), so rays
near an edge land on the wrong surface whatever is done with the distance afterwards.
Run: python benchmarks/bench_far_origin.py [--small]
"""

import numpy as np
from common import arguments, report

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.lidar.cast.raycast import FAR, RayCaster
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern

# The scene in its own frame: name -> (low corner, high corner), metres; a zero extent is a plane.
BOXES = {
    "ground": ((-200.0, -200.0, 0.0), (200.0, 200.0, 0.0)),
    "wall": ((140.0, -30.0, 0.0), (140.0, 30.0, 25.0)),
    "car": ((12.0, 4.0, 0.0), (16.5, 5.8, 1.5)),
    "pillar": ((-9.0, -7.0, 0.0), (-8.4, -6.4, 6.0)),
    "wire": ((6.0, -40.0, 3.0), (6.012, 40.0, 3.012)),  # 12 mm, a contact wire's size
}
SENSOR = (0.0, 0.0, 1.8)  # scene frame
TURN_DEG = (0.0, 0.0, 37.0)  # the scene's orientation in the world
METHODS = ("shift + float64", "world + float64", "shift, Embree t", "world, Embree t")


def flat_grid(low, high, cells: int):
    """An axis-aligned rectangle (one zero extent) as ``cells`` x ``cells`` quads, two triangles each."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    flat = int(np.flatnonzero(high == low)[0])
    u, v = [a for a in range(3) if a != flat]
    s = np.linspace(0.0, 1.0, cells + 1)
    a, b = np.meshgrid(s, s, indexing="ij")
    vertices = np.repeat(low[None], a.size, axis=0)
    vertices[:, u] += a.ravel() * (high[u] - low[u])
    vertices[:, v] += b.ravel() * (high[v] - low[v])
    index = np.arange(a.size).reshape(cells + 1, cells + 1)
    p, q, r, w = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    return vertices, np.concatenate([np.stack([p, q, r], 1), np.stack([p, r, w], 1)]).astype(np.int32)


def analytic_scene(cells: int = 1) -> dict:
    """The :data:`BOXES` as meshes in the scene frame; planes split into ``cells`` x ``cells`` quads."""
    meshes = {}
    for name, (low, high) in BOXES.items():
        low, high = np.asarray(low), np.asarray(high)
        if (high == low).any():
            meshes[name] = flat_grid(low, high, cells)
        else:
            meshes[name] = primitives.translated(primitives.box(*(high - low)), (low + high) / 2)
    return meshes


def placed(meshes: dict, pose: np.ndarray) -> SceneBuffers:
    """Scene buffers of ``meshes`` moved by the (4, 4) ``pose``."""
    return SceneBuffers.from_meshes({k: (v @ pose[:3, :3].T + pose[:3, 3], t) for k, (v, t) in meshes.items()})


def exact_hits(origin, directions, max_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact nearest hits of rays in the scene frame: ``(t (n,) float64, object row (n,), -1 for none)``.

    origin : (3,) float64, outside every box; directions : (n, 3) float64 unit vectors
    """
    best, row = np.full(len(directions), np.inf), np.full(len(directions), -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k, (low, high) in enumerate(BOXES.values()):
            t1, t2 = (np.asarray(low) - origin) / directions, (np.asarray(high) - origin) / directions
            t_in, t_out = np.fmin(t1, t2).max(axis=1), np.fmax(t1, t2).min(axis=1)
            hit = (t_in <= t_out) & (t_in > 0) & (t_in < best)
            best[hit], row[hit] = t_in[hit], k
    row[best > max_range] = -1
    return np.where(row >= 0, best, np.inf), row


def sensor_rays(small: bool):
    spec = resolve_sensor({"preset": "custom", "channels": 16 if small else 64, "vertical_fov_deg": [-25, 15],
                           "horizontal_resolution_deg": 1.0 if small else 0.2, "max_range": 150.0})
    return sensor_pattern(spec).directions, spec.max_range


def compare(point, row, exact_point, exact_row) -> tuple[float, int]:
    """``(largest position error over rays on the right surface, rays on another surface or none)``."""
    right = (row == exact_row) & (row >= 0)
    error = np.linalg.norm(point[right] - exact_point[right], axis=1).max() if right.any() else np.nan
    return float(error), int(np.count_nonzero(row != exact_row))


def measure(distance: float, directions, max_range: float, cells: int) -> list[dict]:
    """The four methods on the scene placed ``distance`` metres from the world origin."""
    heading = np.array([0.6, -0.8, 0.0])
    scene_pose = pose_matrix(heading * distance, TURN_DEG)
    buffers = placed(analytic_scene(cells), scene_pose)
    sensor_pose = pose_matrix(scene_pose[:3, :3] @ SENSOR + scene_pose[:3, 3], np.add(TURN_DEG, (0.0, 0.0, 5.0)))
    origin, world_d = sensor_pose[:3, 3], directions @ sensor_pose[:3, :3].T
    t_exact, exact_row = exact_hits(np.asarray(SENSOR), world_d @ scene_pose[:3, :3], max_range)
    exact_point = origin + world_d * np.where(exact_row >= 0, t_exact, 0.0)[:, None]
    n = len(directions)
    rows = []
    shifted, world = RayCaster(buffers, frame=sensor_pose), RayCaster(buffers, frame=np.eye(4))
    for method in METHODS:
        caster = shifted if method.startswith("shift") else world
        if method.endswith("float64"):
            if caster is shifted:
                hits = caster.intersect(np.zeros(3), directions, max_range)
                local = directions[hits.ray] * hits.distance[:, None]
                hit_point = local @ sensor_pose[:3, :3].T + origin
            else:
                hits = caster.intersect(origin, world_d, max_range)
                hit_point = origin + world_d[hits.ray] * hits.distance[:, None]
            ray, triangle = hits.ray, hits.triangle
        else:  # Embree's own distance, from the float32 ray it was given
            o32 = np.zeros((n, 3), np.float32) if caster is shifted else np.tile(origin.astype(np.float32), (n, 1))
            d32 = np.ascontiguousarray(directions if caster is shifted else world_d, np.float32)
            t, prim = caster._embree(o32, d32, np.full(n, min(max_range, FAR), np.float32))
            ray = np.flatnonzero(prim >= 0)
            triangle = caster._triangles(prim[ray])
            local = o32[ray].astype(np.float64) + d32[ray].astype(np.float64) * t[ray, None].astype(np.float64)
            hit_point = local @ sensor_pose[:3, :3].T + origin if caster is shifted else local
        row = np.full(n, -1)
        row[ray] = buffers.triangle_object[triangle]
        point = np.zeros((n, 3))
        point[ray] = hit_point
        error, wrong = compare(point, row, exact_point, exact_row)
        wire = list(BOXES).index("wire")
        rows.append({
            "distance_m": distance, "method": method, "max_error_m": error, "wrong_rays": wrong, "rays": n,
            "wire_hits": int((row == wire).sum()), "exact_wire_hits": int((exact_row == wire).sum()),
        })  # fmt: skip
    return rows


def chart(rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for method, style in zip(METHODS, ("o-", "s--", "^-", "v--")):
        sel = [r for r in rows if r["method"] == method]
        x = [r["distance_m"] for r in sel]
        left.loglog(x, [r["max_error_m"] for r in sel], style, label=method)
        right.semilogx(x, [r["wrong_rays"] for r in sel], style, label=method)
    left.axhline(1e-4, color="grey", lw=0.8, ls=":")
    left.text(1.2, 1.3e-4, "0.1 mm", color="grey")
    rays, wire = rows[0]["rays"], rows[0]["exact_wire_hits"]
    left.set(xlabel="distance of the scene from the world origin (m)", ylabel="largest position error (m)", title="Points on the right surface")
    right.set(xlabel="distance of the scene from the world origin (m)", ylabel=f"rays (of {rays:,}; {wire} hit the 12 mm wire)",
              title="Rays on another surface or none")
    left.legend(fontsize=8)
    for ax in (left, right):
        ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    args = arguments(__doc__)
    directions, max_range = sensor_rays(args.small)
    distances = [1.0, 1e3, 1e5] if args.small else [1.0, 10.0, 100.0, 1e3, 3e3, 1e4, 3e4, 1e5]
    rows = [row for d in distances for row in measure(d, directions, max_range, cells=20 if args.small else 100)]
    name = "far_origin" + ("_small" if args.small else "")
    report(name, rows, args.out, {"rays": len(directions), "max_range_m": max_range})
    chart(rows, args.out / f"{name}.png")


if __name__ == "__main__":
    main()
