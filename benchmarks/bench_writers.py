"""Writers and box labels: before and after, in one run (ratios, not absolute times).

- LAS: the records alone (the loop before: per-chunk ``np.stack`` to float64, a transposed int32
  cast, one field at a time, copied below from ``io/las.py`` at commit bde0316; against the one
  structured array of ``io/las.las_records``), and whole files (the writer at bde0316, read from
  git, against today's), as nanoseconds a point and as time per byte relative to PLY's.
- Preview: render + PNG encode at the old settings (1600 x 800 px, zlib level 6) against the new
  (1280 x 560 px, level 1), on the same cloud; PNG sizes beside.
- Boxes: :func:`visibility_reference.visibility_per_object` (a caster per object and a
  Python loop over the objects, the way before) against :func:`~bpy_pipeline.lidar.cast.visibility.visibility`
  (one cast through the scene, one against all objects alone) on a parking-like scene: sedans and
  people around a VLP-16 at 10 Hz (0.2 deg columns), the scene's caster given to both (as the scan
  has one), so the ratio is that of the per-object work.
Run: python benchmarks/bench_writers.py [--small]; results in benchmarks/results/writers.json.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from common import ROOT, arguments, best_of, report

from bpy_pipeline.buffers import ObjectTable, SceneBuffers
from bpy_pipeline.geometry import human, objects, primitives
from bpy_pipeline.geometry.boxes import fit_boxes
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.io import las as las_module
from bpy_pipeline.io.las import RECORD_DTYPE, write_las
from bpy_pipeline.io.ply import PLY_DTYPE, ply_records, write_ply
from bpy_pipeline.io.preview import encode_png, encode_png_indexed, render_indexed, render_preview
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.points import empty_points
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.sensor.sensors import iter_pattern, resolve_sensor
from bpy_pipeline.lidar.cast.visibility import visibility
from visibility_reference import visibility_per_object


LAS_BEFORE = "bde0316"  # the last commit with the LAS writer before this change


def cloud(n: int, rng: np.random.Generator) -> np.ndarray:
    pts = empty_points(n)
    for name in "xyz":
        pts[name] = rng.uniform(-40, 40, n)
    pts["z"] *= 0.1
    pts["intensity"] = rng.uniform(0, 1, n)
    pts["semantic"] = rng.integers(0, 30, n)
    pts["instance"] = rng.integers(0, 50, n)
    pts["ring"] = rng.integers(0, 64, n)
    pts["time"] = rng.uniform(0, 0.1, n)
    pts["range"] = rng.uniform(1, 60, n)
    pts["bounces"] = rng.integers(0, 2, n)
    return pts


def las_records_before(pts, classification, offset, scale):
    """The record loop of io/las.py before (commit bde0316), for one chunk."""
    xyz = np.stack([pts["x"], pts["y"], pts["z"]], axis=1).astype(np.float64)
    records = np.zeros(len(pts), RECORD_DTYPE)
    records["X"], records["Y"], records["Z"] = np.rint((xyz - offset) / scale).astype(np.int32).T
    records["intensity"] = np.rint(np.clip(pts["intensity"].astype(np.float64), 0.0, 1.0) * 65535.0).astype(np.uint16)
    records["returns"] = 1 | (1 << 4)
    records["classification"] = classification
    records["gps_time"] = pts["time"]
    for name, _, _, _ in las_module.EXTRA_DIMENSIONS:
        records[name] = pts[name]
    return records


def writer_before():
    """``write_las`` as it was at commit bde0316 (two passes, a record loop per chunk), from git; ``None`` outside a checkout."""
    import subprocess
    import types

    done = subprocess.run(["git", "show", f"{LAS_BEFORE}:bpy_pipeline/io/las.py"], cwd=ROOT, capture_output=True, text=True)
    if done.returncode:
        return None
    module = types.ModuleType("bpy_pipeline.io._las_before")
    module.__package__ = "bpy_pipeline.io"
    exec(compile(done.stdout, "las.py@" + LAS_BEFORE, "exec"), module.__dict__)
    return module.write_las


def bench_las(n: int, folder: Path) -> list[dict]:
    pts = cloud(n, np.random.default_rng(0))
    classification = np.ones(n, np.uint8)
    offset, scale = np.floor([pts[c].min() for c in "xyz"]), np.full(3, 0.001)
    rows = []
    # the records alone (no disk): the loop before, the structured array now, and PLY's records
    build = {name: best_of(fn, 5) for name, fn in (("before", lambda: las_records_before(pts, classification, offset, scale)),
                                                   ("after", lambda: las_module.las_records(pts, classification, offset, scale)),
                                                   ("ply", lambda: ply_records(pts)))}
    for name in ("before", "after"):
        row = {"case": f"LAS records {n} points", "variant": name, "ns_per_point": build[name] / n * 1e9,
               "per_byte_vs_ply": (build[name] / RECORD_DTYPE.itemsize) / (build["ply"] / PLY_DTYPE.itemsize)}
        if name == "after":
            row["speedup"] = build["before"] / build["after"]
        rows.append(row)
    # whole files, on a RAM disk where there is one: the writer before (git), now, and PLY
    ply_s = best_of(lambda: write_ply(folder / "a.ply", pts), 5)
    ply_bytes = (folder / "a.ply").stat().st_size
    after_s = best_of(lambda: write_las(folder / "a.las", pts), 5)
    after_bytes = (folder / "a.las").stat().st_size
    before = writer_before()
    if before is not None:
        pts_before = pts.copy()
        pts_before["semantic"] = np.minimum(pts_before["semantic"], 255)
        before_s = best_of(lambda: before(folder / "b.las", pts_before), 5)
        before_bytes = (folder / "b.las").stat().st_size
        rows.append({"case": f"LAS file {n} points", "variant": f"before ({LAS_BEFORE})", "ns_per_point": before_s / n * 1e9,
                     "per_byte_vs_ply": (before_s / before_bytes) / (ply_s / ply_bytes)})
    rows.append({"case": f"LAS file {n} points", "variant": "after", "ns_per_point": after_s / n * 1e9,
                 "per_byte_vs_ply": (after_s / after_bytes) / (ply_s / ply_bytes), **({"speedup": before_s / after_s} if before is not None else {})})
    rows.append({"case": f"PLY file {n} points", "variant": "reference", "ns_per_point": ply_s / n * 1e9, "per_byte_vs_ply": 1.0})
    return rows


def bench_preview(n: int) -> list[dict]:
    table = load_class_table()
    pts = cloud(n, np.random.default_rng(1))
    pts["semantic"] = np.minimum(pts["semantic"], max(table.names))
    lut = table.color_lut()
    rows = []
    timings = {}
    def rgb(size, level):
        return encode_png(render_preview(pts, lut, size, names=table.names), level)

    def indexed(size, level):  # what write_preview writes: palette indices, an indexed PNG
        index, palette = render_indexed(pts, lut, size, names=table.names)
        return encode_png_indexed(index[..., 0], palette, level)

    for variant, encode, size, level in (("before: 1600x800, zlib 6", rgb, (1600, 800), 6), ("after: 1280x560, zlib 1", rgb, (1280, 560), 1),
                                         ("now: 1280x560, indexed, zlib 1", indexed, (1280, 560), 1)):  # fmt: skip
        seconds = best_of(lambda: encode(size, level), 5)
        timings[variant] = seconds
        rows.append({"case": f"preview {n} points", "variant": variant, "ms": seconds * 1e3, "png_kib": len(encode(size, level)) / 1024})
    for row in rows[1:]:
        row["speedup"] = timings[rows[0]["variant"]] / timings[row["variant"]]
    return rows


def parking_like(cars: int, people: int, rng: np.random.Generator):
    """Buffers of a floor, a back wall, ``cars`` cars and ``people`` people around the origin; and their headings."""
    parts = [("floor", "floor", 1, primitives.translated(primitives.box(80, 80, 0.2), (0, 0, -0.1))),
             ("wall", "wall", 2, primitives.translated(primitives.box(0.3, 60, 3), (25, 0, 1.5)))]  # fmt: skip
    headings = {}
    style = objects.STYLES[0]  # a sedan: the car mesh the parking builder uses
    for k in range(cars):
        angle, distance, yaw = rng.uniform(-np.pi, np.pi), rng.uniform(5, 20), rng.uniform(-np.pi, np.pi)
        if style is not None:
            mesh = [p for p in objects.car_parts(style, 1.5).values()]
            v = np.concatenate([m[0] for m in mesh])
            t = np.concatenate([m[1] + sum(len(x[0]) for x in mesh[:i]) for i, m in enumerate(mesh)])
        else:
            v, t = primitives.translated(primitives.box(4.4, 1.8, 1.5), (0, 0, 0.75))
        c, s = np.cos(yaw), np.sin(yaw)
        v = v @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [distance * np.cos(angle), distance * np.sin(angle), 0]
        parts.append((f"car{k}", "car", 100 + k, (v, t)))
        headings[100 + k] = yaw
    for k in range(people):
        angle, distance = rng.uniform(-np.pi, np.pi), rng.uniform(3, 15)
        person = human.pose_person(human.neutral_angles(), 1.75, 1.0, "standing", (distance * np.cos(angle), distance * np.sin(angle)),
                                   rng.uniform(-np.pi, np.pi))
        parts.append((f"person{k}", "person", 200 + k, human.body_mesh(person.a, person.b, person.radius)[:2]))
        headings[200 + k] = person.yaw
    vertices, triangles, owner, offset = [], [], [], 0
    for row, (_, _, _, (v, t)) in enumerate(parts):
        vertices.append(v)
        triangles.append(np.asarray(t) + offset)
        owner.append(np.full(len(t), row, np.int32))
        offset += len(v)
    k = len(parts)
    table = ObjectTable([p[0] for p in parts], [""] * k, [p[1] for p in parts], np.zeros(k, np.uint16), np.array([p[2] for p in parts], np.uint32),
                        np.zeros(k, np.uint8), np.full(k, 0.5, np.float32))
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(owner), table), headings


def bench_boxes(cars: int, people: int) -> list[dict]:
    buffers, headings = parking_like(cars, people, np.random.default_rng(2))
    sensor = resolve_sensor({"preset": "vlp16", "rotation_hz": 10.0}, "sensor")
    pose = pose_matrix([0.0, 0.0, 1.5], [0.0, 0.0, 0.0])
    boxes = fit_boxes(buffers, ["car", "person"], headings)
    scene_caster = RayCaster(buffers, frame=pose)
    results = {}
    visibility(buffers, boxes.copy(), iter_pattern(sensor, 1 << 16), pose, sensor.min_range, sensor.max_range, cell_deg=1.0)  # warm-up (imports, Embree)
    for variant, fn in (("before: a caster per object", visibility_per_object), ("after: one cast for all", visibility)):
        filled = boxes.copy()

        def once():  # the scene's caster is given, as the scan has one: what differs is the per-object work
            fn(buffers, filled, iter_pattern(sensor, 1 << 16), pose, sensor.min_range, sensor.max_range, cell_deg=1.0, caster=scene_caster)

        results[variant] = (best_of(once, 5), filled)
    (before_s, before), (after_s, after) = results.values()
    same = bool((before["visible"] == after["visible"]).all() and (before["unoccluded"] == after["unoccluded"]).all())
    return [
        {"case": f"boxes: {cars} cars, {people} people", "variant": "before: a caster per object", "ms": before_s * 1e3},
        {"case": f"boxes: {cars} cars, {people} people", "variant": "after: one cast for all", "ms": after_s * 1e3, "speedup": before_s / after_s,
         "same_counts": same},
    ]


if __name__ == "__main__":
    args = arguments(__doc__.splitlines()[0])
    points = 100_000 if args.small else 1_000_000
    ram = Path("/dev/shm") if Path("/dev/shm").is_dir() else None  # file speed without the disk's noise
    with tempfile.TemporaryDirectory(dir=ram) as tmp:
        rows = bench_las(points, Path(tmp))
    rows += bench_preview(14_000)  # a parking frame
    if not args.small:
        rows += bench_preview(1_000_000)
    rows += bench_boxes(*((4, 3) if args.small else (12, 8)))
    report("writers", rows, args.out, {"small": args.small, "las_reference": "io/las.py record loop at commit bde0316"})
