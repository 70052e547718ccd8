"""Twins from real scans: the support surfaces found in a scan's points against the truth, and a populated frame.

1. A synthetic indoor scan: the industrial_hall builder's layout (``geometry/indoor.hall_layout`` at the builder's
   defaults: floor, walls, six desks 0.72 m high, three shelf racks) with two standing people and three stacks of pallets (1.4 m),
   meshed in numpy and scanned by the HDL-64E preset's rays from a tripod 1.8 m up at (-1, -3); written as an
   organised ``.npy`` (x y z intensity, zeros where empty) and read back as a real scan, so the finder sees
   points only. Truth per return: floor, desk top (the upward face of a desk's top), other.
2. Real outdoor frames (no indoor real scan is available): SemanticKITTI sequence 01 frame 0 and frame 000700,
   whose per-point labels give the floor: walkable ground (road, parking, sidewalk, other-ground, terrain) and
   paved ground (without terrain); RANSAC threshold 0.1 m (roads are cambered).

Per surface kind: precision (returns of found surfaces of that kind that are the truth's) and recall (truth
returns on a found surface of that kind). Then the hall populated (4 people on the floor, 2 arms on desks)
and KITTI 004747 (4 people on the road and pavement), cast by their firings. Results:
``benchmarks/results/real_twins.json`` and ``real_twins.png``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from common import ROOT, arguments, report

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.indoor import boxes_mesh, hall_layout
from bpy_pipeline.geometry.objects import person_mesh
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
from bpy_pipeline.mixing.convert import target_rays
from bpy_pipeline.mixing.section import SupportParams
from bpy_pipeline.mixing.supports import find_supports

REAL = ROOT.parent / "shared" / "real_scans"
TRUTH = {0: "empty", 1: "floor", 2: "desk", 3: "other"}
SENSOR_AT = np.array([-1.0, -3.0, 1.8])  # hall frame: a tripod in the aisle south of the desks


def hall_meshes(seed: int = 3) -> tuple[dict, dict]:
    """``(meshes {name: (v, t)}, truth class per mesh name prefix)`` of the hall in the sensor frame (sensor at the origin)."""
    from bpy_pipeline.builders.industrial_hall.params import IndustrialHallScene

    params = IndustrialHallScene()
    layout = hall_layout(params)
    rng = np.random.default_rng(seed)
    meshes = {"floor": boxes_mesh(layout.floor), "walls": boxes_mesh(layout.walls)}
    for f in layout.furniture:
        if f.class_name == "desk":
            meshes[f"desktop {f.name}"] = boxes_mesh(f.parts[:1])
            meshes[f"desklegs {f.name}"] = boxes_mesh(f.parts[1:])
        else:
            meshes[f"shelf {f.name}"] = f.mesh()
    from bpy_pipeline.geometry.human import BUILDS, sample_pose

    for k, xy in enumerate(((2.0, -2.0), (-3.5, 3.2))):
        v, t = person_mesh(sample_pose("standing", rng, BUILDS["medium"]), 1.75, BUILDS["medium"], "standing")
        meshes[f"person {k}"] = (v + [xy[0], xy[1], 0.0], t)
    for k, (x, y) in enumerate(((1.0, 1.0), (-6.5, -3.5), (3.5, -4.5))):
        meshes[f"crate {k}"] = primitives.translated(primitives.box(1.2, 1.0, 1.4), (x, y, 0.7))
    return {name: (np.asarray(v, float) - SENSOR_AT, t) for name, (v, t) in meshes.items()}


def hall_scan(folder: Path, preset: str = "hdl64e", seed: int = 3) -> tuple[Path, np.ndarray, dict]:
    """The hall scanned by ``preset``: ``(scan.npy path, truth (rings, columns) uint8 of TRUTH, desk tops {name: (centre xy, half xy, z)})``."""
    meshes = hall_meshes(seed)
    buffers = SceneBuffers.from_meshes(meshes)
    spec = resolve_sensor({"preset": preset}, "sensor")
    directions, ring, column = target_rays(spec)
    hits = RayCaster(buffers, frame=np.eye(4)).intersect(np.zeros(3), directions, min(spec.max_range, 60.0))
    keep = hits.distance >= spec.min_range
    shape = (int(ring.max()) + 1, int(column.max()) + 1)
    grid, truth = np.zeros((*shape, 4), np.float32), np.zeros(shape, np.uint8)
    r, c = ring[hits.ray[keep]], column[hits.ray[keep]]
    xyz = directions[hits.ray[keep]] * hits.distance[keep, None]
    grid[r, c, :3] = xyz
    grid[r, c, 3] = 0.5
    names = np.array(list(meshes))[buffers.triangle_object[hits.triangle[keep]]]
    up = hits.normal[keep, 2] > 0.9
    truth[r, c] = np.where(names == "floor", 1, np.where(np.char.startswith(names.astype(str), "desktop") & up, 2, 3))
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "hall_scan.npy"
    np.save(path, grid)
    tops = {}
    from bpy_pipeline.builders.industrial_hall.params import IndustrialHallScene

    for f in hall_layout(IndustrialHallScene()).furniture:
        if f.class_name == "desk":
            centre, half = f.parts[0]
            tops[f.name] = (centre[:2] - SENSOR_AT[:2], half[:2], float(centre[2] + half[2] - SENSOR_AT[2]))
    return path, truth, tops


def scores(found: list, truth_mask: dict, n: int) -> dict:
    """Per kind of ``truth_mask`` ({kind: (n,) bool}): precision and recall of the returns on the found surfaces of that kind."""
    out = {}
    for kind, truth in truth_mask.items():
        got = np.zeros(n, bool)
        for s in found:
            if s.kind == kind:
                got[s.index] = True
        tp = int((got & truth).sum())
        out[kind] = {"precision": round(tp / max(int(got.sum()), 1), 4), "recall": round(tp / max(int(truth.sum()), 1), 4),
                     "found": int(sum(s.kind == kind for s in found))}
    return out


GROUND = {"walkable": [9, 10, 11, 12, 17], "paved": [9, 10, 11, 12]}  # SemanticKITTI training ids: road, parking, sidewalk, other-ground (, terrain)


def semantickitti_floor(name: str) -> tuple[np.ndarray, dict] | None:
    """``(xyz (n, 3), {truth name: (n,) bool})`` of a SemanticKITTI frame: walkable ground (terrain too) and paved ground."""
    points, labels = REAL / f"{name}_points.npy", REAL / f"{name}_labels.npy"
    if not points.exists():
        return None
    xyz = np.load(points)[:, :3].astype(np.float64)
    label = np.load(labels).reshape(-1)
    return xyz, {key: np.isin(label, ids) for key, ids in GROUND.items()}


def populated_frame(path: Path, fmt: str, preset: str, people: int, arms: int, seed: int = 1):
    """A real-scan frame of ``path`` with ``people`` and ``arms`` placed on the surfaces found (no effects)."""
    from bpy_pipeline.config import load_config
    from bpy_pipeline.mixing.frame import mix_frame

    config = load_config(None, ["scene.builder=real_scan", f"scene.path={path}", f"scene.format={fmt}", f"scene.preset={preset}",
                                f"scene.population.people={people}", f"scene.population.arms={arms}"])
    return mix_frame(config.scene.params, np.random.default_rng(seed))


def chart(rows: list[dict], hall: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(14, 5.5))
    labels = [
        f"{r['scan'].replace('SemanticKITTI seq01_000000', 'SemKITTI 01/0').replace('SemanticKITTI ', 'SemKITTI ').replace('synthetic ', '')}\n"
        f"{r['kind'].replace('floor vs ', 'floor: ')}"
        for r in rows
    ]
    x = np.arange(len(rows))
    a.tick_params(axis="x", labelrotation=0)
    a.bar(x - 0.2, [r["precision"] for r in rows], 0.4, label="precision")
    a.bar(x + 0.2, [r["recall"] for r in rows], 0.4, label="recall")
    a.set_xticks(x, labels, fontsize=8)
    a.set_ylim(0, 1.05)
    a.set_title("support surfaces found in the points vs truth")
    a.legend(loc="lower right")
    xyz, truth, found, placed = hall["xyz"], hall["truth"], hall["found"], hall["placed"]
    b.scatter(xyz[:, 0], xyz[:, 1], s=0.2, c="0.8")
    b.scatter(xyz[truth == 2, 0], xyz[truth == 2, 1], s=10, c="tab:orange", label="truth: desk tops", zorder=3)
    for s in found:
        colour = {"floor": "tab:blue", "desk": "tab:red", "other": "tab:gray"}[s.kind]
        if s.kind == "desk":
            b.scatter(s.cells[:, 0], s.cells[:, 1], s=3, c=colour, marker="s", zorder=4)
        else:
            b.scatter(s.cells[:, 0], s.cells[:, 1], s=1, c=colour, alpha=0.25, zorder=2)
    b.scatter([], [], s=12, c="tab:blue", label="found: floor (cells)")
    b.scatter([], [], s=12, c="tab:red", label="found: desk (cells)")
    for p in placed:
        b.plot(p.centre[0], p.centre[1], "k^" if p.type == "person" else "ms", ms=6, zorder=5)
    b.plot([], [], "k^", label="person placed")
    b.plot([], [], "ms", label="arm placed")
    b.plot(0, 0, "g*", ms=9, label="sensor")
    b.set_aspect("equal")
    b.set_xlim(-8, 10)
    b.set_ylim(-4, 10)
    b.set_title("synthetic hall (HDL-64E, read back as a point file), top view")
    b.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    import tempfile

    args = arguments(__doc__.splitlines()[0])
    rows, notes = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        path, truth_grid, _ = hall_scan(Path(tmp))
        grid = np.load(path)
        have = np.linalg.norm(grid[..., :3], axis=2) > 0
        xyz = grid[have][:, :3].astype(np.float64)
        truth = truth_grid[have]
        start = time.perf_counter()
        found = find_supports(xyz, SupportParams())
        ms = (time.perf_counter() - start) * 1e3
        for kind, s in scores(found, {"floor": truth == 1, "desk": truth == 2}, len(xyz)).items():
            rows.append({"scan": "synthetic hall", "kind": kind, **s, "points": len(xyz), "ms": round(ms, 1)})
        frame = populated_frame(path, "npy", "hdl64e", 4, 2)
        placed = [p for p in frame.placements if p.rule == "population"]
        log = frame.info["rules"]["population"]
        notes["hall_population"] = {k: log[k] for k in ("person", "robot_arm", "rejections")}
        notes["hall_inserted_points"] = int(frame.inserted.sum())
        notes["hall_placed"] = [p.info() for p in placed]
        hall = {"xyz": xyz, "truth": truth, "found": found, "placed": placed}
    for name in (["semantickitti_seq01_000000"] if args.small else ["semantickitti_seq01_000000", "semantickitti_000700"]):
        got = semantickitti_floor(name)
        if got is None:
            notes[name] = "absent"
            continue
        xyz, truths = got
        start = time.perf_counter()
        found = find_supports(xyz, SupportParams(threshold=0.1))
        ms = (time.perf_counter() - start) * 1e3
        for key, truth in truths.items():
            s = scores(found, {"floor": truth}, len(xyz))["floor"]
            rows.append({"scan": name.replace("semantickitti_", "SemanticKITTI "), "kind": f"floor vs {key}", **s, "points": len(xyz), "ms": round(ms, 1)})
    kitti = REAL / "kitti_hdl64e_004747.bin"
    if kitti.exists():
        frame = populated_frame(kitti, "kitti", "hdl64e", 4, 0)
        notes["kitti_004747_placed"] = [p.info() for p in frame.placements if p.rule == "population"]
        log = frame.info["rules"]["population"]
        notes["kitti_004747_population"] = {k: log[k] for k in ("person", "rejections")}
        notes["kitti_004747_surfaces"] = {kind: sum(s["kind"] == kind for s in log["supports"]) for kind in ("floor", "desk", "other")}
        notes["kitti_004747_inserted_points"] = int(frame.inserted.sum())
    report("real_twins", rows, args.out, notes)
    chart(rows, hall, args.out / "real_twins.png")


if __name__ == "__main__":
    main()
