"""Realism: simulated scans against real labelled scans of the same sensors.

Two real scans (../shared/real_scans, read only):

* **HDL-32E, nuScenes sweep**, replayed: the sweep's own returns (ego motion undone, gaps of up to
  4 columns filled from ring neighbours; lidar/fit/fitting.py) are meshed as a range image (two
  triangles per 2 x 2 cell of firings whose ranges agree within 10 %), each triangle carrying the
  reflectivity its real returns imply (apparent reflectance intensity / 100 over cos incidence,
  in steps of 0.01; firings no cell covers become small squares facing the sensor; returns nearer
  than 2 m, the ego vehicle's body, are left out on both sides). The ``hdl32e`` preset scans that mesh from the sensor's origin, ideal and with
  its default (realistic) effects. Per ring: return fraction and range histogram (histogram
  intersection with the real ring: 1 = identical distributions); intensity histograms per range
  band (the sensor's 0..255 integers); and the drop fraction against range and incidence: the
  real sweep's firings with a known target against the same firings through the preset's drop
  model (``fitting.simulate_drops``: range, incidence and apparent reflectance of each firing).
* **HDL-64E, KITTI frame 000008** (front field of view) and its six labelled cars: a car of each
  label's size (the sedan mesh of geometry/objects.py: body, glass windows, interior, tyres),
  at the label's pose, on a ground plane at the labels' mean bottom height, in front of the
  ``hdl64e`` preset at the lidar's origin. Per car: points in the box, simulated over real
  (the label's count), the share of points on the half facing the sensor, rings that see it and
  points per ring (real rings: the nearest preset elevation), for the default effects, ideal,
  and with one driver changed at a time (white or black paint, opaque windows). The real scan
  holds only the points inside the front camera's image; the simulated scans are cropped to the
  same frustum (its bounds read from the real points' image slopes). Intensity of
  the points on cars and on the road, per range band, against KITTI's reflectance; range noise per
  band by one estimator (ring-wise second differences) on the real and the simulated scan.
* **Points per object against distance**: a car (4.2 x 1.8 x 1.5 m, yaw 30 deg) and a person
  (1.75 m) from 5 to 60 m in front of the HDL-64E, default effects and ideal, with the six real
  cars (no pedestrian is labelled in the frame).

Cost: the realistic replay scan's time over the ideal one's (same mesh, best of 3).
Writes benchmarks/results/realism.json and realism.png. Run: python benchmarks/bench_realism.py [--small]
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
from common import ROOT, arguments, best_of, report

import bpy_pipeline
from bpy_pipeline.config import effects_from_dict
from bpy_pipeline.geometry.objects import (STYLES, car_parts, fit_to_box, person_object, ObjectPart, PARTS, GLASS_REFLECTIVITY, INTERIOR_REFLECTIVITY,
                                           TYRE_REFLECTIVITY)
from bpy_pipeline.lidar.fit import fitting
from bpy_pipeline.lidar.sensor.sensors import elevations, preset_effects, resolve_sensor

REAL = Path(os.environ.get("BPY_PIPELINE_REAL_SCANS", ROOT.parent / "shared" / "real_scans"))
NUSCENES, KITTI, BOXES = REAL / "nuscenes_hdl32e_sweep.bin", REAL / "kitti_hdl64e_000008_frontfov.bin", REAL / "kitti_000008_boxes.json"
RANGE_BANDS = [(0.0, 10.0), (10.0, 20.0), (20.0, 40.0), (40.0, 100.0)]
RANGE_BINS = np.geomspace(1.0, 100.0, 25)
DROP_RANGES = np.geomspace(2.0, 100.0, 7)
DROP_INCIDENCE = np.array([0.0, 30.0, 60.0, 90.0])
MIN_RANGE = 2.0  # m: nearer returns of the nuScenes sweep are the ego vehicle's own body (the fit leaves them out too)
ROAD = 0.10  # asphalt at 905 nm, as the nuScenes sweep's calibrated intensity reads its road (median 9-11 of 100)
SILVER, WHITE, BLACK = 0.50, 0.70, 0.05  # paint reflectivities of geometry/objects.py COLOURS


def intersection(a: np.ndarray, b: np.ndarray, bins) -> float:
    """Histogram intersection of two samples over ``bins``: 1 = the same distribution, 0 = disjoint."""
    if len(a) == 0 or len(b) == 0:
        return float("nan")
    ha, _ = np.histogram(a, bins)
    hb, _ = np.histogram(b, bins)
    return float(np.minimum(ha / max(ha.sum(), 1), hb / max(hb.sum(), 1)).sum())


# ----------------------------------------------------------------------------- HDL-32E: the nuScenes sweep replayed
def range_image_mesh(points: np.ndarray, apparent: np.ndarray, cos: np.ndarray, agree: float = 0.3, exponent: float = 1.0) -> dict:
    """Meshes of an organised scan, grouped by reflectivity in steps of 0.01 (``api.scan`` mesh entries).

    points : (rings, columns, 3) returns, NaN where unknown; apparent : (rings, columns) apparent
    reflectance; cos : (rings, columns) cosine of incidence. Two triangles per 2 x 2 cell of firings
    whose ranges agree within ``agree`` (relative), with reflectivity ``apparent / cos^exponent`` (the
    intensity model's incidence exponent, so the model gives the real intensity back); rows half a
    ring spacing beyond the first and last rings (the beams at the edges would graze the mesh's
    border); every known firing that no cell covers (a pole, a branch) becomes a splat: a square facing
    the sensor, one firing's angular cell wide, with reflectivity ``apparent``.
    """
    rings, columns = points.shape[:2]
    r = np.linalg.norm(points, axis=2)
    direction = points / np.where(r > 0, r, 1.0)[..., None]
    el = np.arcsin(np.clip(direction[..., 2], -1, 1))
    step = float(np.nanmedian(np.diff(np.nanmedian(el, axis=1))))
    def shifted(row: int, by: float) -> np.ndarray:
        d = direction[row]
        horiz = d[:, :2] / np.maximum(np.linalg.norm(d[:, :2], axis=1, keepdims=True), 1e-9)
        e = el[row] + by
        return np.column_stack([horiz * np.cos(e)[:, None], np.sin(e)]) * r[row][:, None]
    grid = np.concatenate([shifted(0, -0.5 * step)[None], points, shifted(rings - 1, 0.5 * step)[None]])
    rho = np.clip(np.nan_to_num(apparent / cos**exponent, nan=0.1), 0.0, 1.0)
    rho = np.concatenate([rho[:1], rho, rho[-1:]])
    rows = rings + 2
    rg = np.linalg.norm(grid, axis=2)
    index = np.arange(rows * columns).reshape(rows, columns)
    quads = np.stack([index[:-1].ravel(), np.roll(index, -1, axis=1)[:-1].ravel(), index[1:].ravel(), np.roll(index, -1, axis=1)[1:].ravel()], axis=1)
    rq = rg.ravel()[quads]
    ok = np.isfinite(rq).all(axis=1)
    ok[ok] &= (rq[ok].max(axis=1) - rq[ok].min(axis=1)) <= agree * rq[ok].min(axis=1)
    covered = np.zeros(rows * columns, bool)
    covered[quads[ok].ravel()] = True
    quads = quads[ok]
    triangles = np.concatenate([quads[:, [0, 2, 1]], quads[:, [1, 2, 3]]])
    vertices = np.nan_to_num(grid.reshape(-1, 3))
    reflect = rho.ravel()[triangles].mean(axis=1)
    # splats for the known firings no cell covers
    lone = np.isfinite(rg.ravel()) & ~covered
    lone[:columns] = lone[-columns:] = False  # the padding rows
    centre = vertices[lone]
    dist = np.linalg.norm(centre, axis=1, keepdims=True)
    toward = centre / dist
    side = np.cross(toward, [0.0, 0.0, 1.0])
    side /= np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-9)
    up = np.cross(side, toward)
    half_w, half_h = dist * math.radians(360.0 / columns) * 0.55, dist * abs(step) * 0.55
    corners = [centre + sx * half_w * side + sy * half_h * up for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    base = len(vertices)
    n = len(centre)
    vertices = np.concatenate([vertices, np.stack(corners, axis=1).reshape(-1, 3)])
    k = base + 4 * np.arange(n)
    splats = np.concatenate([np.stack([k, k + 1, k + 2], axis=1), np.stack([k, k + 2, k + 3], axis=1)])
    triangles = np.concatenate([triangles, splats])
    splat_rho = np.clip(np.nan_to_num(np.concatenate([apparent[:1], apparent, apparent[-1:]]).ravel()[lone], nan=0.1), 0.0, 1.0)
    reflect = np.concatenate([reflect, splat_rho, splat_rho])
    bins = np.rint(np.clip(reflect, 0.0, 1.0) * 100).astype(int)
    meshes = {}
    for b in np.unique(bins):
        tri = triangles[bins == b]
        used, inverse = np.unique(tri, return_inverse=True)
        meshes[f"surface {b}"] = (vertices[used], inverse.reshape(-1, 3), "building", "diffuse", float(0.01 * b))
    return meshes


def hdl32e_replay(small: bool) -> tuple[list[dict], dict, dict]:
    scan = fitting.read_scan(NUSCENES, 32)
    geometry = fitting.scan_geometry(scan)
    rings, columns = geometry.range.shape
    points = geometry.range[..., None] * geometry.direction
    cos = np.clip(np.nan_to_num(geometry.cos_incidence, nan=0.5), 0.1, 1.0)
    exponent = preset_effects("hdl32e")["intensity"].get("incidence_exponent", 1.0)
    meshes = range_image_mesh(points, geometry.reflectance, cos, exponent=exponent)
    ideal = bpy_pipeline.scan(meshes, "hdl32e", effects={"ideal": True}, seed=0)
    sim = bpy_pipeline.scan(meshes, "hdl32e", seed=0)
    ideal, sim = ideal[ideal["range"] >= MIN_RANGE], sim[sim["range"] >= MIN_RANGE]
    real_xyz = scan.xyz[0]
    real_range = np.linalg.norm(real_xyz, axis=2)
    real_valid = scan.valid[0] & (real_range >= MIN_RANGE)
    real_intensity = scan.intensity[0]
    rows = []
    per_ring = []
    for ring in range(rings):
        rr = real_range[ring][real_valid[ring]]
        sr = sim["range"][sim["ring"] == ring]
        ir = ideal["range"][ideal["ring"] == ring]
        per_ring.append({
            "ring": ring, "real_returns": int(len(rr)), "sim_returns": int(len(sr)), "ideal_returns": int(len(ir)),
            "range_intersection_sim": round(intersection(rr, sr, RANGE_BINS), 3), "range_intersection_ideal": round(intersection(rr, ir, RANGE_BINS), 3),
        })
    totals = {k: sum(p[k] for p in per_ring) for k in ("real_returns", "sim_returns", "ideal_returns")}
    rows.append({"case": "hdl32e replay", "quantity": "returns (all rings)", "real": totals["real_returns"], "sim": totals["sim_returns"],
                 "ideal": totals["ideal_returns"], "sim/real": round(totals["sim_returns"] / totals["real_returns"], 3)})
    rows.append({"case": "hdl32e replay", "quantity": "range hist. intersection (median ring)",
                 "sim": float(np.nanmedian([p["range_intersection_sim"] for p in per_ring])),
                 "ideal": float(np.nanmedian([p["range_intersection_ideal"] for p in per_ring]))})
    # intensity per range band, in the sensor's 0..255
    real_i, real_r = real_intensity[real_valid], real_range[real_valid]
    sim_i = np.rint(sim["intensity"].astype(np.float64) * 255)
    bands = []
    for lo, hi in RANGE_BANDS:
        a = real_i[(real_r >= lo) & (real_r < hi)]
        b = sim_i[(sim["range"] >= lo) & (sim["range"] < hi)]
        bands.append({"band_m": [lo, hi], "real_median": float(np.median(a)) if len(a) else None, "sim_median": float(np.median(b)) if len(b) else None,
                      "real_p90": float(np.percentile(a, 90)) if len(a) else None, "sim_p90": float(np.percentile(b, 90)) if len(b) else None,
                      "intersection": round(intersection(a, b, np.arange(0, 257) - 0.5), 3)})
        rows.append({"case": "hdl32e replay", "quantity": f"intensity {lo:g}-{hi:g} m (median real / sim)", "real": bands[-1]["real_median"],
                     "sim": bands[-1]["sim_median"], "intersection": bands[-1]["intersection"]})
    # drop fraction against range and incidence: the real firings, and the same firings through the preset's drop model
    samples = fitting.drop_samples(scan, geometry)
    effects = effects_from_dict(preset_effects("hdl32e"))
    # simulate_drops gives each firing reflectivity a / cos (a Lambertian target's); under the profile's
    # incidence exponent k the model reads rho cos^k, so a cos^(1 - k) in makes it read the firing's real a
    k = effects.intensity.incidence_exponent
    as_read = replace(samples, reflectance=samples.reflectance * np.clip(samples.cos_incidence, 1e-6, 1.0) ** (1.0 - k))
    simulated = fitting.simulate_drops(as_read, effects, np.random.default_rng(0))
    incidence = np.degrees(np.arccos(np.clip(samples.cos_incidence, 0, 1)))
    drop = []
    for i in range(len(DROP_RANGES) - 1):
        for j in range(len(DROP_INCIDENCE) - 1):
            m = (
                (samples.range >= DROP_RANGES[i])
                & (samples.range < DROP_RANGES[i + 1])
                & (incidence >= DROP_INCIDENCE[j])
                & (incidence < DROP_INCIDENCE[j + 1])
            )
            if m.sum() >= 50:
                drop.append({"range_m": [round(DROP_RANGES[i], 2), round(DROP_RANGES[i + 1], 2)], "incidence_deg": [DROP_INCIDENCE[j], DROP_INCIDENCE[j + 1]],
                             "firings": int(m.sum()), "real": round(float(samples.dropped[m].mean()), 4), "sim": round(float(simulated[m].mean()), 4)})
    rows.append({"case": "hdl32e sweep", "quantity": "drop fraction (all firings with a target)", "real": round(float(samples.dropped.mean()), 4),
                 "sim": round(float(simulated.mean()), 4)})
    by_range = []
    for i in range(len(DROP_RANGES) - 1):
        m = (samples.range >= DROP_RANGES[i]) & (samples.range < DROP_RANGES[i + 1])
        by_range.append({"range_m": [round(DROP_RANGES[i], 2), round(DROP_RANGES[i + 1], 2)], "real": round(float(samples.dropped[m].mean()), 4),
                         "sim": round(float(simulated[m].mean()), 4), "firings": int(m.sum())})
        rows.append({"case": "hdl32e sweep", "quantity": f"drop {DROP_RANGES[i]:.1f}-{DROP_RANGES[i + 1]:.1f} m", "real": by_range[-1]["real"],
                     "sim": by_range[-1]["sim"]})
    repeat = 1 if small else 3
    t_ideal = best_of(lambda: bpy_pipeline.scan(meshes, "hdl32e", effects={"ideal": True}, seed=0), repeat)
    t_real = best_of(lambda: bpy_pipeline.scan(meshes, "hdl32e", seed=0), repeat)
    rows.append({"case": "hdl32e replay", "quantity": "scan time, realistic / ideal", "sim": round(t_real / t_ideal, 3)})
    detail = {"per_ring": per_ring, "intensity_bands": bands, "drop_range_incidence": drop, "drop_by_range": by_range,
              "mesh_triangles": int(sum(len(m[1]) for m in meshes.values()))}
    charts = {"real_range": real_range, "real_valid": real_valid, "sim": sim, "ideal": ideal, "real_i": real_i, "sim_i": sim_i, "drop_by_range": by_range}
    return rows, detail, charts


# ----------------------------------------------------------------------------- HDL-64E: KITTI's labelled cars
def lidar_to_camera() -> np.ndarray:
    """(4, 4) KITTI lidar frame -> rectified camera frame (``R0_rect @ Tr_velo_to_cam``)."""
    data = json.loads(BOXES.read_text())
    r0 = np.eye(4)
    r0[:3, :3] = np.asarray(data["R0_rect"], float)[:3, :3]
    return r0 @ np.asarray(data["Tr_velo_to_cam"], float)


def image_slopes(xyz: np.ndarray) -> np.ndarray:
    """(n, 2) ``x / z`` and ``y / z`` of lidar points in the rectified camera frame (inf behind the camera)."""
    cam = xyz @ lidar_to_camera()[:3, :3].T + lidar_to_camera()[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(cam[:, 2:3] > 0.1, cam[:, :2] / cam[:, 2:3], np.inf)


def kitti_boxes() -> list[dict]:
    """The labelled cars in the lidar frame: centre (3,), size (length, width, height), yaw (rad), real count."""
    data = json.loads(BOXES.read_text())
    to_lidar = np.linalg.inv(lidar_to_camera())
    out = []
    for box in data["boxes"]:
        x, y, z, l, h, w, ry = box["box_cam_xyz_lhw_ry"]
        centre = to_lidar @ np.array([x, y - h / 2, z, 1.0])
        bottom = to_lidar @ np.array([x, y, z, 1.0])
        heading = to_lidar[:3, :3] @ np.array([math.cos(ry), 0.0, -math.sin(ry)])
        out.append({"centre": centre[:3], "bottom_z": float(bottom[2]), "size": np.array([l, w, h]), "yaw": math.atan2(heading[1], heading[0]),
                    "real_points": int(box["num_lidar_pts"]), "occluded": int(box["occluded"]), "truncated": float(box["truncated"])})
    return out


def in_box(xyz: np.ndarray, box: dict, margin: float = 0.0) -> np.ndarray:
    c, s = math.cos(-box["yaw"]), math.sin(-box["yaw"])
    d = xyz - box["centre"]
    local = np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]])
    return (np.abs(local) <= box["size"] / 2 + margin).all(axis=1)


def placed(parts: list[ObjectPart], centre, yaw: float) -> list[ObjectPart]:
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return [ObjectPart(p.vertices @ rot.T + np.asarray(centre), p.triangles, p.material, p.reflectivity) for p in parts]


def car(size, paint: float = SILVER, glass: bool = True) -> list[ObjectPart]:
    mesh = car_parts(STYLES[0])
    reflect = {"body": ("diffuse", paint), "windows": ("glass" if glass else "diffuse", GLASS_REFLECTIVITY if glass else paint),
               "interior": ("diffuse", INTERIOR_REFLECTIVITY), "tyres": ("diffuse", TYRE_REFLECTIVITY)}
    return fit_to_box([ObjectPart(*mesh[name], *reflect[name]) for name in PARTS], size)


def ground(z: float, half: float = 120.0) -> tuple:
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], float)
    return (v, np.array([[0, 1, 2], [0, 2, 3]]), "road", "diffuse", ROAD)


def scene_of(objects: dict[str, list[ObjectPart]], ground_z: float) -> dict:
    meshes = {"ground": ground(ground_z)}
    for name, parts in objects.items():
        for k, p in enumerate(parts):
            meshes[f"{name} part {k}"] = (p.vertices, p.triangles, "car" if "car" in name else "person", p.material, p.reflectivity)
    return meshes


def ring_of(xyz: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Nearest elevation of ``table`` (degrees) for each point: the ring of an unorganised scan."""
    el = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
    return np.abs(el[:, None] - table[None]).argmin(axis=1)


def pattern(xyz: np.ndarray, rings: np.ndarray, box: dict) -> dict:
    """Share of points on the half of the box facing the sensor, rings that see it, points per ring (median)."""
    if len(xyz) == 0:
        return {"facing_share": None, "rings": 0, "points_per_ring": 0.0}
    toward = -box["centre"][:2] / np.linalg.norm(box["centre"][:2])
    facing = ((xyz[:, :2] - box["centre"][:2]) @ toward) > 0
    _, counts = np.unique(rings, return_counts=True)
    return {"facing_share": round(float(facing.mean()), 3), "rings": int(len(counts)), "points_per_ring": float(np.median(counts))}


NOISE_BANDS = [(2.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 40.0)]


def ring_noise(xyz: np.ndarray, rings: np.ndarray) -> dict:
    """Range noise per range band from ring-wise second differences: along each ring (points in azimuth
    order), three neighbours within 0.3 deg whose ranges agree within 1 % give ``(r_c - (r_l + r_r) / 2) / sqrt(1.5)``;
    the robust sigma (1.4826 MAD, m) per band, and the count. Surface roughness counts as noise: an upper bound."""
    r = np.linalg.norm(xyz, axis=1)
    az = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    residual, at = [], []
    for q in np.unique(rings):
        o = np.flatnonzero(rings == q)
        o = o[np.argsort(az[o])]
        if len(o) < 3:
            continue
        a, rr = az[o], r[o]
        gap = np.diff(a)
        mid, left, right = rr[1:-1], rr[:-2], rr[2:]
        ok = (gap[:-1] > 0.05) & (gap[:-1] < 0.3) & (gap[1:] > 0.05) & (gap[1:] < 0.3) & (np.abs(left - mid) < 0.01 * mid) & (np.abs(right - mid) < 0.01 * mid)
        residual.append((mid - 0.5 * (left + right))[ok] / math.sqrt(1.5))
        at.append(mid[ok])
    residual, at = np.concatenate(residual), np.concatenate(at)
    out = {}
    for lo, hi in NOISE_BANDS:
        x = residual[(at >= lo) & (at < hi)]
        out[f"{lo:g}-{hi:g}"] = {"sigma_mm": round(float(1.4826 * np.median(np.abs(x - np.median(x)))) * 1000, 2) if len(x) >= 50 else None,
                                 "triples": int(len(x))}
    return out


def kitti_cars(small: bool) -> tuple[list[dict], dict, dict]:
    boxes = kitti_boxes()
    real = np.fromfile(KITTI, np.float32).reshape(-1, 4)
    real_xyz = real[:, :3].astype(np.float64)
    # the scan is cropped to the camera image (about 81 x 29 deg, so near low beams are cut): the same
    # frustum, read from the real points' image slopes, crops the simulated scans
    slopes = image_slopes(real_xyz)
    window = np.percentile(slopes, [0.02, 99.98], axis=0)
    ground_z = float(np.mean([b["bottom_z"] for b in boxes]))
    table = elevations(resolve_sensor({"preset": "hdl64e"}))
    real_rings = ring_of(real_xyz, table)
    variants = {"default": {}, "ideal": {"effects": {"ideal": True}}, "white paint": {"paint": WHITE}, "black paint": {"paint": BLACK},
                "opaque windows": {"glass": False}}
    if small:
        variants = {k: variants[k] for k in ("default", "ideal")}
    rows, per_car = [], []
    clouds = {}
    for name, variant in variants.items():
        objects = {f"car {k}": placed(car(b["size"], variant.get("paint", SILVER), variant.get("glass", True)), b["centre"], b["yaw"]) for k,
                   b in enumerate(boxes)}
        cloud = bpy_pipeline.scan(scene_of(objects, ground_z), "hdl64e", effects=variant.get("effects"), seed=8)
        xyz = np.column_stack([cloud["x"], cloud["y"], cloud["z"]]).astype(np.float64)
        sim_slopes = image_slopes(xyz)
        keep = ((sim_slopes >= window[0]) & (sim_slopes <= window[1])).all(axis=1)
        clouds[name] = (cloud[keep], xyz[keep])
    for k, box in enumerate(boxes):
        real_in = in_box(real_xyz, box)
        entry = {"car": k, "distance_m": round(float(np.linalg.norm(box["centre"][:2])), 2), "size_lwh_m": [round(float(x), 2) for x in box["size"]],
                 "occluded": box["occluded"], "truncated": box["truncated"], "real_label": box["real_points"], "real_in_box": int(real_in.sum()),
                 "real_pattern": pattern(real_xyz[real_in], real_rings[real_in], box)}
        for name, (cloud, xyz) in clouds.items():
            mine = in_box(xyz, box)
            entry[name] = {"points": int(mine.sum()), "ratio": round(mine.sum() / box["real_points"], 3), **pattern(xyz[mine], cloud["ring"][mine], box)}
        per_car.append(entry)
        rows.append({"case": f"kitti car {k}", "quantity": f"points at {entry['distance_m']} m (occl. {box['occluded']}, trunc. {box['truncated']})",
                     "real": box["real_points"], "sim": entry["default"]["points"], "ideal": entry["ideal"]["points"], "sim/real": entry["default"]["ratio"],
                     **({"black/real": entry["black paint"]["ratio"], "opaque/real": entry["opaque windows"]["ratio"]} if "black paint" in entry else {})})
    # intensity on cars and road, per range band, against KITTI's reflectance
    sim_cloud, sim_xyz = clouds["default"]
    on_car_real = np.zeros(len(real_xyz), bool)
    on_car_sim = np.zeros(len(sim_xyz), bool)
    for box in boxes:
        on_car_real |= in_box(real_xyz, box, 0.1)
        on_car_sim |= in_box(sim_xyz, box, 0.1)
    real_road = (np.abs(real_xyz[:, 2] - ground_z) < 0.15) & ~on_car_real
    sim_road = (np.abs(sim_xyz[:, 2] - ground_z) < 0.15) & ~on_car_sim
    real_r, sim_r = np.linalg.norm(real_xyz, axis=1), np.linalg.norm(sim_xyz, axis=1)
    intensity = []
    for what, real_mask, sim_mask in (("car", on_car_real, on_car_sim), ("road", real_road, sim_road)):
        for lo, hi in RANGE_BANDS[:3]:
            a = real[:, 3][real_mask & (real_r >= lo) & (real_r < hi)]
            b = sim_cloud["intensity"][sim_mask & (sim_r >= lo) & (sim_r < hi)]
            if len(a) < 20 or len(b) < 20:
                continue
            intensity.append({"surface": what, "band_m": [lo, hi], "real_median": round(float(np.median(a)), 3), "sim_median": round(float(np.median(b)), 3),
                              "intersection": round(intersection(a, b, np.arange(0, 1.02, 0.02) - 0.01), 3), "real_n": int(len(a)), "sim_n": int(len(b))})
            rows.append({"case": "kitti intensity", "quantity": f"{what} {lo:g}-{hi:g} m (median real / sim)", "real": intensity[-1]["real_median"],
                         "sim": intensity[-1]["sim_median"], "intersection": intensity[-1]["intersection"]})
    # range noise: the same estimator on the real scan and on the simulated one (road and cars)
    noise_real = ring_noise(real_xyz, real_rings)
    noise_sim = ring_noise(sim_xyz, sim_cloud["ring"])
    for band in noise_real:
        rows.append({"case": "kitti noise", "quantity": f"range sigma {band} m (mm, ring-wise)", "real": noise_real[band]["sigma_mm"],
                     "sim": noise_sim[band]["sigma_mm"]})
    charts = {"real": real, "real_car": on_car_real, "sim": sim_cloud, "sim_car": on_car_sim, "per_car": per_car}
    return rows, {"ground_z_m": ground_z, "image_slopes_x_y": window.round(4).tolist(), "cars": per_car, "intensity": intensity,
                  "noise": {"real": noise_real, "sim": noise_sim}}, charts


def points_against_distance(small: bool, ground_z: float) -> tuple[list[dict], dict]:
    distances = [5.0, 15.0, 30.0, 60.0] if small else [5.0, 7.5, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0, 50.0, 60.0]
    size_car = np.array([4.2, 1.8, 1.5])
    rng = np.random.default_rng(3)
    person = person_object(rng)
    person_size = person[0].vertices.max(axis=0) - person[0].vertices.min(axis=0)
    rows, curve = [], []
    for d in distances:
        entry = {"distance_m": d}
        for what, parts, size in (("car", car(size_car), size_car), ("person", person, person_size)):
            centre = np.array([d, 0.0, ground_z + size[2] / 2])
            box = {"centre": centre, "size": size, "yaw": math.radians(30.0) if what == "car" else 0.0}
            meshes = scene_of({what: placed(parts, centre, box["yaw"])}, ground_z)
            for name, effects in (("default", None), ("ideal", {"ideal": True})):
                cloud = bpy_pipeline.scan(meshes, "hdl64e", effects=effects, seed=11)
                xyz = np.column_stack([cloud["x"], cloud["y"], cloud["z"]]).astype(np.float64)
                entry[f"{what}_{name}"] = int(in_box(xyz, box, 0.02).sum())
        curve.append(entry)
        rows.append({"case": "points vs distance", "quantity": f"{d:g} m: car / person", "sim": f"{entry['car_default']} / {entry['person_default']}",
                     "ideal": f"{entry['car_ideal']} / {entry['person_ideal']}"})
    return rows, {"curve": curve, "car_size_m": size_car.tolist(), "person_size_m": [round(float(x), 3) for x in person_size]}


# ----------------------------------------------------------------------------- charts
def chart(path: Path, hdl32e: dict, kitti: dict, curve: dict, cars: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(16, 9))
    ax = axes[0, 0]
    for ring, colour in ((4, "C0"), (12, "C1"), (20, "C2"), (28, "C3")):
        real = hdl32e["real_range"][ring][hdl32e["real_valid"][ring]]
        sim = hdl32e["sim"]["range"][hdl32e["sim"]["ring"] == ring]
        ax.hist(real, RANGE_BINS, histtype="step", color=colour, label=f"ring {ring} real")
        ax.hist(sim, RANGE_BINS, histtype="step", color=colour, linestyle="--", label=f"ring {ring} sim")
    ax.set_xscale("log"), ax.set_xlabel("range (m)"), ax.set_ylabel("returns"), ax.set_title("HDL-32E replay: range per ring (solid real, dashed sim)")
    ax.legend(fontsize=7, ncol=2)
    ax = axes[0, 1]
    bins = np.arange(0, 101, 2)
    ax.hist(hdl32e["real_i"], bins, histtype="step", density=True, label="nuScenes (0..255)")
    ax.hist(hdl32e["sim_i"], bins, histtype="step", density=True, label="hdl32e default")
    ax.set_xlabel("intensity (0..255, clipped at 100)"), ax.set_title("HDL-32E intensity"), ax.legend()
    ax = axes[0, 2]
    centres = [math.sqrt(r["range_m"][0] * r["range_m"][1]) for r in hdl32e["drop_by_range"]]
    ax.plot(centres, [r["real"] for r in hdl32e["drop_by_range"]], "o-", label="nuScenes sweep")
    ax.plot(centres, [r["sim"] for r in hdl32e["drop_by_range"]], "s--", label="hdl32e drop model")
    ax.set_xscale("log"), ax.set_xlabel("range (m)"), ax.set_ylabel("drop fraction"), ax.set_title("HDL-32E ray drop against range"), ax.legend()
    ax = axes[1, 0]
    real, sim = kitti["real"], kitti["sim"]
    ax.hist(real[kitti["real_car"], 3], np.arange(0, 1.02, 0.02), histtype="step", density=True, label="KITTI cars")
    ax.hist(sim["intensity"][kitti["sim_car"]], np.arange(0, 1.02, 0.02), histtype="step", density=True, label="sim cars (silver)")
    ax.hist(real[~kitti["real_car"], 3], np.arange(0, 1.02, 0.02), histtype="step", density=True, label="KITTI rest")
    ax.set_xlabel("reflectance 0..1"), ax.set_title("HDL-64E intensity"), ax.legend()
    ax = axes[1, 1]
    x = np.arange(len(cars))
    ax.bar(x - 0.3, [c["real_label"] for c in cars], 0.2, label="real (label)")
    ax.bar(x - 0.1, [c["default"]["points"] for c in cars], 0.2, label="sim default")
    ax.bar(x + 0.1, [c["ideal"]["points"] for c in cars], 0.2, label="sim ideal")
    if "black paint" in cars[0]:
        ax.bar(x + 0.3, [c["black paint"]["points"] for c in cars], 0.2, label="sim black paint")
    ax.set_xticks(x, [f"car {c['car']}\n{c['distance_m']} m" for c in cars], fontsize=8)
    ax.set_ylabel("points in box"), ax.set_title("KITTI 000008: the six labelled cars"), ax.legend(fontsize=8)
    ax = axes[1, 2]
    d = [c["distance_m"] for c in curve["curve"]]
    ax.plot(d, [c["car_default"] for c in curve["curve"]], "o-", label="car, default")
    ax.plot(d, [c["car_ideal"] for c in curve["curve"]], "o:", label="car, ideal")
    ax.plot(d, [c["person_default"] for c in curve["curve"]], "s-", label="person, default")
    ax.plot(d, [c["person_ideal"] for c in curve["curve"]], "s:", label="person, ideal")
    ax.plot([c["distance_m"] for c in cars], [c["real_label"] for c in cars], "k*", markersize=10, label="KITTI cars (real)")
    (
        ax.set_xscale("log"),
        ax.set_yscale("log"),
        ax.set_xlabel("distance (m)"),
        ax.set_ylabel("points on object"),
        ax.set_title("HDL-64E: points per object"),
        ax.legend(fontsize=8),
    )
    from matplotlib.ticker import ScalarFormatter

    for ax in (axes[0, 0], axes[0, 2], axes[1, 2]):
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(ScalarFormatter() if ax is axes[1, 2] else plt.NullFormatter())
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    args = arguments(__doc__.splitlines()[0])
    missing = [p.name for p in (NUSCENES, KITTI, BOXES) if not p.exists()]
    if missing:
        print(f"bench_realism: skipped, real scans absent: {', '.join(missing)} (set BPY_PIPELINE_REAL_SCANS)")
        return
    rows32, detail32, charts32 = hdl32e_replay(args.small)
    rows64, detail64, charts64 = kitti_cars(args.small)
    rows_curve, detail_curve = points_against_distance(args.small, detail64["ground_z_m"])
    name = "realism_small" if args.small else "realism"
    notes = {"hdl32e": detail32, "kitti": detail64, "points_against_distance": detail_curve,
             "profiles": {"hdl32e": preset_effects("hdl32e"), "hdl64e": preset_effects("hdl64e")}}
    report(name, rows32 + rows64 + rows_curve, args.out, json.loads(json.dumps(notes, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))))
    chart(args.out / f"{name}.png", charts32, charts64, detail_curve, detail64["cars"])


if __name__ == "__main__":
    main()
