"""Synthetic objects cast into real scans, exact per firing (bpy_pipeline.mixing): the nuScenes sweep and the KITTI scan."""

import math
from dataclasses import replace

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io.real_scans import RealScan, read_real_scan
from bpy_pipeline.mixing import KittiRule, NoiseInjections, ObjectBox, ParkingRule, RealScanScene, RemoveBox, mix_frame
from bpy_pipeline.mixing.convert import mesh_range_image
from bpy_pipeline.mixing.firings import angle_between, recover_firings
from bpy_pipeline.mixing.ground import PointIndex, in_box, ransac_ground

SWEEP = "nuscenes_hdl32e_sweep.bin"
KITTI = "kitti_hdl64e_000008_frontfov.bin"


@pytest.fixture
def sweep(real_scan):
    path = real_scan(SWEEP)
    scan = read_real_scan(path)
    return path, scan, recover_firings(scan)


def wall_section(path, x=15.0, **kw):
    """A flat wall whose front face is the plane x = ``x``, 20 m wide, 6 m high, centred on the sensor's height."""
    return RealScanScene(path=str(path), objects=[ObjectBox("box", (x + 0.05, 0.0, 0.0), (0.1, 20.0, 6.0), 0.0)], **kw)


def test_firings_of_the_nuscenes_sweep(sweep):
    path, scan, f = sweep
    raw = np.fromfile(path, np.float32).reshape(-1, 5)
    assert f.shape == (32, 1084) and len(f) == len(raw)
    # nuScenes LIDAR_TOP is x right, y forward: the sensor frame has x forward, y left
    np.testing.assert_allclose(scan.points[:, 0], raw[:, 1], atol=1e-6)
    np.testing.assert_allclose(scan.points[:, 1], -raw[:, 0], atol=1e-6)
    # empty firings sit on the ego-motion line, carry intensity, and get a modelled direction
    empty = ~f.valid
    assert 4000 < empty.sum() < 5300
    assert (f.intensity[empty] > 0).any()
    assert np.allclose(np.linalg.norm(f.direction, axis=1), 1.0)
    # returned firings point exactly at their return; the model reproduces them to ~0.03 deg
    back = f.origin[f.valid] + f.range[f.valid, None] * f.direction[f.valid]
    np.testing.assert_allclose(back, scan.points[f.point[f.valid]], atol=1e-9)
    assert f.residual_deg < 0.05
    # ring elevations within 0.1 deg of the README's medians (measured there without the ego-motion line)
    assert abs(f.elevation_deg[0] - -30.60) < 0.1 and abs(f.elevation_deg[-1] - 10.60) < 0.1
    assert f.approximate == []


def test_wall_points_lie_on_real_firings_and_follow_the_rings(sweep):
    path, scan, f = sweep
    m = mix_frame(wall_section(path), np.random.default_rng(0))
    new = m.inserted
    xyz = np.column_stack([m.points["x"], m.points["y"], m.points["z"]]).astype(np.float64)[new]
    k = m.firing[new]
    assert len(k) > 500
    # on a real firing's ray: the real return's direction where the firing returned, the modelled one where it was empty
    rel = xyz - f.origin[k]
    angle = angle_between(rel / np.linalg.norm(rel, axis=1, keepdims=True), f.direction[k])
    assert angle.max() < 1e-6
    real_dir = scan.points[f.point[k]] - f.origin[k]
    real_dir /= np.maximum(np.linalg.norm(real_dir, axis=1, keepdims=True), 1e-12)
    returned = f.valid[k]
    assert angle_between(rel[returned] / np.linalg.norm(rel[returned], axis=1, keepdims=True), real_dir[returned]).max() < 1e-6
    np.testing.assert_allclose(xyz[:, 0], 15.0, atol=2e-5)  # on the wall's face (float32 records)
    # exactly the firings whose ray meets the wall before any real return, ring by ring
    t = (15.0 - f.origin[:, 0]) / f.direction[:, 0]
    at = f.origin + t[:, None] * f.direction
    meets = (f.direction[:, 0] > 0) & (np.abs(at[:, 1]) < 10.0) & (np.abs(at[:, 2]) < 3.0) & (~f.valid | (f.range > t))
    edge = (np.abs(np.abs(at[:, 1]) - 10.0) < 1e-6) | (np.abs(np.abs(at[:, 2]) - 3.0) < 1e-6)
    expected = np.flatnonzero(meets & ~edge)
    assert set(expected) <= set(k) and len(set(k) - set(expected)) <= int(edge.sum())
    assert (m.points["ring"][new] == f.ring[k]).all()
    per_ring = np.bincount(f.ring[k], minlength=32)
    assert (per_ring == np.bincount(f.ring[expected], minlength=32)).all()
    # each ring's wall points run along consecutive columns (the real ring structure, no made-up rows)
    for r in np.flatnonzero(per_ring >= 5):
        cols = np.sort(f.column[k][f.ring[k] == r])
        assert (np.diff(cols) == 1).mean() > 0.9


def test_one_return_per_firing_and_nothing_behind_inserted_hits(sweep):
    path, scan, f = sweep
    section = RealScanScene(path=str(path), parking_rule=ParkingRule(enabled=True),
                            objects=[ObjectBox("car", (8.0, -3.0, -1.0), (4.5, 1.8, 1.6), 20.0), ObjectBox("person", (6.0, 2.0, -0.95))])
    m = mix_frame(section, np.random.default_rng(3))
    assert len(np.unique(m.firing)) == len(m.firing)
    assert m.inserted.sum() > 100 and len(m.placements) >= 2
    inserted_firings = m.firing[m.inserted]
    # every inserted hit on a firing that returned is nearer than that return, and that return is gone
    returned = f.valid[inserted_firings]
    assert (m.points["range"][m.inserted][returned] < f.range[inserted_firings[returned]]).all()
    real = m.firing[~m.inserted]
    assert not np.isin(real, inserted_firings).any()
    # no real return lies inside an inserted object's box (the cast replaces them, the rule refuses crowded boxes)
    xyz = np.column_stack([m.points["x"], m.points["y"], m.points["z"]]).astype(float)
    for p in m.placements:
        inside = in_box(xyz[~m.inserted], p.centre, p.size * 0.8, math.degrees(p.yaw))
        assert inside.sum() <= 5
    assert m.info["occluded_real"] > 0 and m.info["filled_empty"] >= 0


def test_remove_and_reinsert_gives_back_the_returns(sweep, tmp_path):
    plyfile = pytest.importorskip("plyfile")
    path, scan, f = sweep
    rings, columns = f.shape
    grid = f.returns.reshape(columns, rings, 3).transpose(1, 0, 2)
    valid = f.valid.reshape(columns, rings).T
    box = RemoveBox((-3.0, 6.0, -0.6), (4.0, 2.0, 2.2), 0.0)  # a real object (a parked car) left of the sensor
    inside = valid & in_box(grid.reshape(-1, 3), box.center, box.size, 0.0).reshape(rings, columns)
    assert inside.sum() > 300
    vertices, triangles = mesh_range_image(grid, inside)
    used = np.unique(triangles)
    remap = np.full(len(vertices), -1)
    remap[used] = np.arange(len(used))
    v, t = vertices[used], remap[triangles]
    mesh = tmp_path / "object.ply"
    vertex = np.array([tuple(p) for p in v], [("x", "f8"), ("y", "f8"), ("z", "f8")])
    face = np.array([(list(tt),) for tt in t], [("vertex_indices", "i4", (3,))])
    plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex"), plyfile.PlyElement.describe(face, "face")]).write(str(mesh))
    lo, hi = v.min(axis=0), v.max(axis=0)
    cut = mix_frame(RealScanScene(path=str(path), remove=[box]), np.random.default_rng(0))
    assert cut.info["removed"] == inside.sum()
    back = mix_frame(RealScanScene(path=str(path), remove=[box], objects=[ObjectBox(str(mesh), tuple((lo + hi) / 2), tuple(hi - lo), 0.0)]),
                     np.random.default_rng(0))
    original = f.returns
    new = back.inserted
    k = back.firing[new]
    xyz = np.column_stack([back.points["x"], back.points["y"], back.points["z"]]).astype(float)[new]
    r_idx, c_idx = np.divmod(used, columns)
    vertex_firing = r_idx + c_idx * rings  # grid vertex r * columns + c is firing c * rings + r
    # every re-inserted return is one of the removed object's, within 2 cm of where it was
    assert np.isin(k, vertex_firing).mean() > 0.95
    ours = np.isin(k, vertex_firing)
    assert np.linalg.norm(xyz[ours] - original[k[ours]], axis=1).max() < 0.02
    # firings through inner vertices of the mesh come back (a ray aimed exactly at a vertex of an open mesh
    # can slip between its triangles in float32: lidar/cast/raycast.py); one through its rim may pass the edge
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    rim = np.zeros(len(used), bool)
    rim[unique[count == 1].reshape(-1)] = True
    inner = vertex_firing[~rim]
    assert len(inner) > 100 and np.isin(inner, k).mean() > 0.97, np.isin(inner, k).mean()
    assert np.isin(vertex_firing, k).mean() > 0.8


def test_same_seed_same_bytes_with_rules_effects_and_injections(sweep):
    from bpy_pipeline.config import DropConfig, EffectsConfig, NoiseConfig

    path, scan, f = sweep
    noise = NoiseInjections(dropout_max=0.003, range_sigma=(0.001, 0.03), interior_points=15, cutoff_probability=0.6, class_flip=0.02)
    section = RealScanScene(path=str(path), parking_rule=ParkingRule(enabled=True), noise=noise)
    effects = EffectsConfig(noise=NoiseConfig(sigma=0.01), drop=DropConfig(model="uniform", probability=0.1))
    a = mix_frame(section, np.random.default_rng(11), effects, threads=1)
    b = mix_frame(section, np.random.default_rng(11), effects, threads=2)
    assert a.points.tobytes() == b.points.tobytes() and a.boxes.tobytes() == b.boxes.tobytes()
    assert len(np.unique(a.firing)) == len(a.firing)
    c = mix_frame(section, np.random.default_rng(12), effects)
    assert c.points.tobytes() != a.points.tobytes()


def test_drop_of_inserted_points_follows_the_fitted_model_on_held_out_columns(sweep, tmp_path):
    from bpy_pipeline.config import DropConfig, EffectsConfig
    from bpy_pipeline.lidar.effects.apply import FittedModels, write_model_file
    from bpy_pipeline.lidar.fit.fitting import FitOptions, OrganisedScan, fit_models, read_scan

    path, scan, f = sweep
    organised = read_scan(path, 32)
    train = np.arange(0, 800)  # fit on columns 0..799; the walls stand in the held-out columns 800..1083
    part = OrganisedScan(organised.xyz[:, :, train], organised.valid[:, :, train], organised.intensity[:, :, train], organised.source)
    models, _ = fit_models(part, FitOptions(folds=0))
    model_file = tmp_path / "hdl32e.yaml"
    write_model_file(model_file, FittedModels(drop_table=models.drop_table, source=models.source))
    effects = EffectsConfig(drop=DropConfig(model="table", model_file=str(model_file)))
    held = f.column >= 800
    az = np.degrees(np.arctan2(f.direction[held, 1], f.direction[held, 0]))
    centre = math.radians(float(np.degrees(np.angle(np.exp(1j * np.radians(az)).mean()))))
    for distance in (6.0, 12.0, 25.0):
        # a wall facing the sensor across the held-out sector, 2.5 m tall around the sensor's height
        c = (distance * math.cos(centre), distance * math.sin(centre), 0.0)
        section = RealScanScene(path=str(path), objects=[ObjectBox("box", c, (0.1, 2 * distance, 2.5), math.degrees(centre))])
        exact = mix_frame(section, np.random.default_rng(1))
        mixed = mix_frame(section, np.random.default_rng(1), effects)
        k = exact.firing[exact.inserted]
        k = k[f.column[k] >= 800]
        rng_ = exact.points["range"][exact.inserted][f.column[exact.firing[exact.inserted]] >= 800].astype(float)
        normal = np.array([math.cos(centre), math.sin(centre), 0.0])
        incidence = np.degrees(np.arccos(np.clip(np.abs(f.direction[k] @ normal), 0, 1)))
        expected = models.drop_table.bilinear(rng_, incidence).mean()
        kept = np.isin(k, mixed.firing[mixed.inserted]).sum()
        observed = 1.0 - kept / len(k)
        sigma = math.sqrt(max(expected * (1 - expected), 1e-4) / len(k))
        assert len(k) > 200
        assert abs(observed - expected) < 4 * sigma + 0.005, (distance, observed, expected, len(k))
        # a dropped firing stays empty: the real return behind the wall does not come back
        dropped = np.setdiff1d(k, mixed.firing)
        assert not np.isin(dropped, mixed.firing[~mixed.inserted]).any()


def test_kitti_scan_rings_from_scan_order_and_the_kitti_rule(real_scan):
    path = real_scan(KITTI)
    scan = read_real_scan(path)
    assert scan.format == "kitti" and scan.ring is None
    f = recover_firings(scan, "hdl64e")
    assert f.approximate and any("scan order" in a for a in f.approximate)
    assert (~f.valid).sum() > 0 and f.valid.sum() == len(scan)
    section = RealScanScene(path=str(path), preset="hdl64e", kitti_rule=KittiRule(enabled=True, count=3, collision_distance=5.0))
    m = mix_frame(section, np.random.default_rng(0))
    assert 1 <= len(m.placements) <= 3 and m.info["rules"]["kitti"]["placed"] == len(m.placements)
    assert len(np.unique(m.firing)) == len(m.firing)
    assert m.info["firings"]["approximate"]
    # inserted objects outside the front field of view are truncated; boxes carry it
    assert (m.boxes["truncation"] >= 0).all() and (m.boxes["truncation"] <= 1).all()
    for p, record in zip(m.placements, m.info["objects"]):  # equation (1): within 10 m of the sensor's line, along it or against it
        if abs(p.centre[1]) < 10:
            assert p.yaw in (0.0, math.pi)
        assert m.boxes[m.boxes["instance"] == record["instance"]]["class_name"] == "car"


def uneven_ring_scan(rng, rings=6, crop=None):
    """A scan of returns only, ring after ring in firing order (azimuth rising from 0), whose 2,156 firings a turn step
    0.18 deg six times and then 0.09 (as KITTI's HDL-64E scans do), with runs of 1-4 firings dropped, one run in each
    8 firings at most: ``(RealScan, dropped azimuths (k,) deg per ring)``. ``crop``: ring r keeps its firings within
    ``crop - 4 r`` deg of the x axis (a front camera's field of view, narrower for the lower rings at its corners)."""
    step = 360.0 / (6.5 * 308)  # 0.1798 deg: 308 blocks of six steps and a half-step close the turn
    azimuth = np.concatenate([[0.0], np.cumsum(np.tile([step] * 6 + [step / 2], 308))])[:-1]
    points, dropped = [], []
    for r in range(rings):
        keep = np.ones(len(azimuth), bool)
        for start in rng.choice(np.arange(2, len(azimuth) - 8, 8), 100, replace=False):
            keep[start : start + rng.integers(1, 5)] = False
        inside = np.ones(len(azimuth), bool) if crop is None else np.abs((azimuth + 180.0) % 360.0 - 180.0) < crop - 4.0 * r
        a, e = np.radians(azimuth[keep & inside]), np.radians(-10.0 + 2.0 * r)
        points.append(10.0 * np.column_stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.full(len(a), np.sin(e))]))
        w = azimuth if crop is None else (azimuth + 180.0) % 360.0 - 180.0  # the crop's part of the ring, in one piece
        dropped.append(azimuth[~keep & inside & (w > w[keep & inside].min()) & (w < w[keep & inside].max())])  # between its returns
    xyz = np.concatenate(points)
    return RealScan(xyz, np.full(len(xyz), 0.5)), dropped


@pytest.mark.parametrize("crop", [None, 40.0])
def test_empty_firings_of_a_scan_in_firing_order_are_the_dropped_ones(crop):
    """Counted between a ring's consecutive returns, the empty firings are the dropped firings, one for one and within
    half a step of them, though the 0.17 deg lattice of the preset does not follow the sensor's uneven steps (it made up
    empty cells beside the cells it put two returns in); cropped to a camera's view, none outside each ring's own part
    of it (the lattice's cells filled every ring to the widest ring's span)."""
    scan, dropped = uneven_ring_scan(np.random.default_rng(3), crop=crop)
    f = recover_firings(scan, "hdl64e")
    assert f.shape[0] == 6 and any("firing order" in note for note in f.approximate)
    for r, want in enumerate(dropped):
        empty = np.sort(np.degrees(np.arctan2(f.direction[~f.valid & (f.ring == r), 1], f.direction[~f.valid & (f.ring == r), 0])) % 360.0)
        assert len(empty) == len(want), (r, len(empty), len(want))
        assert np.abs(empty - np.sort(want)).max() < 0.09
    # the same returns with a ring field but in no firing order: the lattice's cells, as before
    order = np.random.default_rng(0).permutation(len(scan.points))
    shuffled = recover_firings(RealScan(scan.points[order], scan.intensity[order], ring=f.ring[f.valid][order]), "hdl64e")
    assert "empty firings from the lattice's gaps" in shuffled.approximate and not any("firing order" in n for n in shuffled.approximate)


def test_kitti_empty_firings_are_rarely_between_two_near_returns(real_scan):
    """On a full KITTI scan an empty firing is rarely flanked, in its ring, by returns under 20 m on both sides (a
    drop there is a dark or mirror-like spot): 3 % of the empty firings now, 24 % with the lattice's cells, most of
    them cells the lattice made up beside two returns it put in one cell."""
    f = recover_firings(read_real_scan(real_scan("kitti_hdl64e_004747.bin")), "hdl64e")
    rings, columns = f.shape
    near = np.zeros((rings, columns), bool)
    near[f.ring[f.valid], f.column[f.valid]] = f.range[f.valid] < 20.0
    flanked = near[f.ring, (f.column - 1) % columns] & near[f.ring, (f.column + 1) % columns]
    assert (flanked & ~f.valid).sum() / (~f.valid).sum() < 0.1


def test_real_boxes_hidden_by_an_inserted_object_get_their_occlusion_updated(sweep):
    path, scan, f = sweep
    real_car = ObjectBox("car", (-3.0, 6.0, -0.6), (4.0, 2.0, 2.2), 0.0)
    alone = mix_frame(RealScanScene(path=str(path), real_boxes=[real_car]), np.random.default_rng(0))
    assert alone.boxes[0]["occlusion"] == 0 and alone.boxes[0]["visible"] > 300
    blocker = ObjectBox("box", (-1.0, 2.5, -0.6), (3.0, 0.2, 2.2), 0.0)  # a wall between the sensor and the parked car
    hidden = mix_frame(RealScanScene(path=str(path), real_boxes=[real_car], objects=[blocker]), np.random.default_rng(0))
    real_box = hidden.boxes[hidden.boxes["instance"] == 0][0]
    assert real_box["visible"] < alone.boxes[0]["visible"] and real_box["occlusion"] > 0


def test_ground_ransac_and_point_index_agree_with_brute_force():
    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(-20, 20, 3000), rng.uniform(-20, 20, 3000), rng.normal(-1.8, 0.02, 3000)])
    clutter = np.column_stack([rng.uniform(-20, 20, 500), rng.uniform(-20, 20, 500), rng.uniform(-1.5, 2, 500)])
    points = np.concatenate([floor, clutter])
    g = ransac_ground(points)
    assert g.ground[:3000].mean() > 0.99 and g.ground[3000:].mean() < 0.15
    assert abs(g.height_at([[3.0, 4.0]])[0] + 1.8) < 0.02
    index = PointIndex(clutter, backend="voxel")
    for centre, size, yaw in (((1, 2, 0), (4, 2, 2), 30.0), ((-5, 5, 1), (3, 3, 1), -70.0)):
        assert (index.in_box(centre, size, yaw) == np.flatnonzero(in_box(clutter, centre, size, yaw))).all()
    q = np.array([[0.0, 0.0, 0.0], [50.0, 50.0, 0.0]])
    brute = np.linalg.norm(clutter[None] - q[:, None], axis=2).min(axis=1)
    got = index.nearest_distance(q, 2.0)
    assert (np.isinf(got) == (brute > 2.0)).all()
    assert np.allclose(got[np.isfinite(got)], brute[np.isfinite(got)])


def test_bad_input_names_the_key(tmp_path, real_scan):
    with pytest.raises(InputError, match="scene.path"):
        mix_frame(RealScanScene(path=""), np.random.default_rng(0))
    with pytest.raises(InputError, match="scene.path"):
        mix_frame(RealScanScene(path=str(tmp_path / "missing.bin")), np.random.default_rng(0))
    path = real_scan(SWEEP)
    with pytest.raises(InputError, match="scene.objects"):
        mix_frame(RealScanScene(path=str(path), objects=[ObjectBox("spaceship")]), np.random.default_rng(0))
    with pytest.raises(InputError, match="scene.objects.class"):
        mix_frame(RealScanScene(path=str(path), objects=[replace(ObjectBox("car"), class_name="dragon")]), np.random.default_rng(0))


def test_sensor_conversion_on_a_flat_ground_is_exact_for_the_meshed_cast():
    from bpy_pipeline.lidar.cast.raycast import RayCaster
    from bpy_pipeline.buffers import SceneBuffers
    from bpy_pipeline.geometry import primitives
    from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
    from bpy_pipeline.mixing.convert import project_to_cones, raycast_convert, target_rays

    ground = SceneBuffers.from_meshes({"ground": primitives.plane(400.0, 400.0)})
    source, target = resolve_sensor({"preset": "hdl64e"}, "s"), resolve_sensor({"preset": "vlp16"}, "t")
    directions, ring, column = target_rays(source)
    frame = np.eye(4)
    frame[2, 3] = 1.73
    hits = RayCaster(ground, frame=frame).intersect(np.zeros(3), directions, source.max_range)
    grid, valid = np.zeros((ring.max() + 1, column.max() + 1, 3)), np.zeros((ring.max() + 1, column.max() + 1), bool)
    grid[ring[hits.ray], column[hits.ray]] = directions[hits.ray] * hits.distance[:, None]
    valid[ring[hits.ray], column[hits.ray]] = True
    offset = (0.0, 0.0, 1.51 - 1.73)
    points, r, c = raycast_convert(grid, valid, target, offset)
    assert len(points) > 1000
    np.testing.assert_allclose(points[:, 2], -1.51, atol=1e-6)  # on the ground, seen from the target's height
    tdir, _, _ = target_rays(target)
    cols = len(np.unique(target_rays(target)[2]))
    assert angle_between(points / np.linalg.norm(points, axis=1, keepdims=True), tdir[r * cols + c]).max() < 1e-9
    cones, cr, cc = project_to_cones(grid[valid], target, offset)
    assert len(np.unique(cr * 10_000 + cc)) == len(cones)  # one point per target cell


def kitti_boxes(path):
    """The six labelled cars of KITTI frame 000008 as ObjectBoxes in the velodyne (sensor) frame."""
    import json

    data = json.loads(path.read_text())
    cam_to_velo = np.linalg.inv(np.array(data["R0_rect"]) @ np.array(data["Tr_velo_to_cam"]))
    out, counts = [], []
    for b in data["boxes"]:
        x, y, z, length, h, w, ry = b["box_cam_xyz_lhw_ry"]
        centre = (cam_to_velo @ [x, y - h / 2, z, 1.0])[:3]  # camera boxes stand on their bottom centre, y down
        out.append(ObjectBox("car", tuple(centre), (length, w, h), math.degrees(-ry - math.pi / 2)))
        counts.append(b["num_lidar_pts"])
    return out, np.array(counts)


def test_kitti_labelled_cars_hold_their_points_and_get_occluded(real_scan):
    path = real_scan(KITTI)
    boxes, counts = kitti_boxes(real_scan("kitti_000008_boxes.json"))
    scan = read_real_scan(path)
    inside = np.array([in_box(scan.points, b.center, b.size, b.yaw_deg).sum() for b in boxes])
    assert (np.abs(inside - counts) <= 0.1 * counts + 3).all(), (inside, counts)  # the reader's axes are KITTI's
    # a wall inserted between the sensor and the nearest car hides it; its box says so
    near = boxes[int(np.argmin([np.hypot(b.center[0], b.center[1]) for b in boxes]))]
    c = np.asarray(near.center)
    wall = ObjectBox("box", tuple(c * 0.6), (0.1, 3.0, 2.0), math.degrees(math.atan2(c[1], c[0])))
    before = mix_frame(RealScanScene(path=str(path), preset="hdl64e", real_boxes=boxes), np.random.default_rng(0))
    after = mix_frame(RealScanScene(path=str(path), preset="hdl64e", real_boxes=boxes, objects=[wall]), np.random.default_rng(0))
    k = [i for i, b in enumerate(boxes) if b is near][0]
    real_before, real_after = before.boxes[before.boxes["instance"] == 0], after.boxes[after.boxes["instance"] == 0]
    assert real_after[k]["visible"] < 0.5 * real_before[k]["visible"] and real_after[k]["occlusion"] > real_before[k]["occlusion"]
    # the KITTI rule snaps a new car's yaw to the nearest labelled car within snap_distance
    rule = KittiRule(enabled=True, count=2, snap_distance=100.0)
    m = mix_frame(RealScanScene(path=str(path), preset="hdl64e", real_boxes=boxes, kitti_rule=rule), np.random.default_rng(0))
    yaws = {round(math.radians(b.yaw_deg), 9) for b in boxes}
    assert m.placements and all(round(p.yaw, 9) in yaws for p in m.placements)


def test_semantickitti_labels_are_kept_and_labelled_vehicles_get_boxes(tmp_path):
    # a SemanticKITTI-style scan: a ground grid and one labelled car (raw id 10, instance 7) 10 m ahead
    xs, ys = np.meshgrid(np.arange(-30, 30, 0.5), np.arange(-30, 30, 0.5))
    ground = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, -1.7)])
    cx, cy, cz = np.meshgrid(np.linspace(8, 12, 20), np.linspace(-0.9, 0.9, 10), np.linspace(-1.5, -0.2, 6))
    car = np.column_stack([cx.ravel(), cy.ravel(), cz.ravel()])
    points = np.concatenate([ground, car])
    scan = np.column_stack([points, np.full(len(points), 0.3)]).astype(np.float32)
    (tmp_path / "velodyne").mkdir()
    (tmp_path / "labels").mkdir()
    scan.tofile(tmp_path / "velodyne" / "000000.bin")
    labels = np.concatenate([np.full(len(ground), 40, np.uint32), np.full(len(car), 10 | (7 << 16), np.uint32)])
    labels.tofile(tmp_path / "labels" / "000000.label")
    section = RealScanScene(path=str(tmp_path / "velodyne" / "000000.bin"), preset="hdl64e", objects=[ObjectBox("box", (5.0, 0.0, -1.0), (0.1, 3.0, 1.6), 0.0)])
    m = mix_frame(section, np.random.default_rng(0))
    real = ~m.inserted
    assert set(np.unique(m.points["semantic"][real])) == {20, 26}  # car, road in assets_manifest/labels.yaml
    assert set(np.unique(m.points["instance"][real & (m.points["semantic"] == 20)])) == {7}
    assert (m.points["instance"][m.inserted] == 8).all()  # above every real instance
    vehicle = m.boxes[(m.boxes["instance"] == 0) & (m.boxes["class_name"] == "car")]
    assert len(vehicle) == 1 and abs(vehicle[0]["centre"][0] - 10.0) < 0.1 and vehicle[0]["unoccluded"] == len(car)
    assert vehicle[0]["visible"] < vehicle[0]["unoccluded"]  # the inserted wall hides part of it


def test_convert_a_real_kitti_scan_to_a_vlp16(real_scan):
    from bpy_pipeline.lidar.sensor.sensors import resolve_sensor
    from bpy_pipeline.mixing.convert import convert_scan

    f = recover_firings(read_real_scan(real_scan(KITTI)), "hdl64e")
    target = resolve_sensor({"preset": "vlp16"}, "t")
    for method in ("cones", "raycast"):
        out = convert_scan(f, target, (0.0, 0.0, 1.51 - 1.73), method)
        assert 1000 < len(out) < f.valid.sum() / 4  # a 16-ring sensor keeps a fraction of the 64-ring scan
        assert out["ring"].max() < 16
        elevation = np.degrees(np.arcsin(out["z"] / out["range"]))
        table = np.array(target.elevations_deg) if target.elevations_deg else np.linspace(-15, 15, 16)
        assert np.abs(elevation - table[out["ring"]]).max() < 1e-3  # on the target's cones
    with pytest.raises(InputError, match="method"):
        convert_scan(f, target, method="nearest")


def test_a_folder_of_scans_gives_one_scan_per_frame(real_scan, tmp_path):
    import os

    for k, name in enumerate((SWEEP, SWEEP)):
        os.symlink(real_scan(name), tmp_path / f"{k:06d}.bin")
    (tmp_path / "notes.txt").write_text("not a scan")
    section = RealScanScene(path=str(tmp_path), format="nuscenes", parking_rule=ParkingRule(enabled=True))
    a = mix_frame(section, np.random.default_rng(0), frame=0)
    b = mix_frame(section, np.random.default_rng(0), frame=3)
    assert a.info["scan"]["path"].endswith("000000.bin") and b.info["scan"]["path"].endswith("000001.bin")
    assert a.points.tobytes() == b.points.tobytes()  # the same scan and generator: the same frame
    with pytest.raises(InputError, match="no scan files"):
        mix_frame(RealScanScene(path=str(tmp_path / "*.las")), np.random.default_rng(0))


def test_real_scan_section_round_trips_through_the_config(real_scan):
    from bpy_pipeline.config import config_from_dict, config_to_dict, load_config

    scene = {"builder": "real_scan", "path": str(real_scan(SWEEP)), "objects": [{"type": "car", "center": [8, 4, -0.9], "class": "van"}],
             "noise": {"range_sigma": [0.001, 0.03]}, "parking_rule": {"enabled": True, "count": {"kind": "normal", "mean": 3, "std": 1, "min": 0, "max": 10}}}
    config = load_config({"scene": scene})
    assert config.scene.params.objects[0].class_name == "van" and config.sensor.spec.name == "hdl32e"
    assert config_from_dict(config_to_dict(config)) == config
    with pytest.raises(InputError, match=r"scene.objects\[0\].type"):
        load_config({"scene": {**scene, "objects": [{"type": "spaceship"}]}})
    with pytest.raises(InputError, match="scene.format"):
        load_config({"scene": {**scene, "format": "xyz"}})


def test_ransac_ground_finds_a_cambered_highways_ground(real_scans_folder):
    """Without Patchwork++, the RANSAC method's grid still finds the ground one plane misses (SemanticKITTI
    sequence 01, a highway: one plane holds 30 % of its ground returns)."""
    source = real_scans_folder / "semantickitti_seq01_000000_points.npy"
    if not source.exists():
        pytest.skip(f"real scan {source} is absent (set BPY_PIPELINE_REAL_SCANS to its folder)")
    points = np.load(source)[:, :3].astype(float)
    labels = np.load(source.with_name(source.name.replace("_points", "_labels"))).reshape(-1)
    truth = np.isin(labels, [9, 10, 11, 12, 17])  # road, parking, sidewalk, other-ground, terrain (training ids)
    found = ransac_ground(points).ground
    assert truth[found].mean() > 0.9 and found[truth].mean() > 0.9
    assert found[labels == 1].mean() < 0.2  # car returns stay obstacles
