"""Twins from real scans (mixing/supports.py): floors and desks found in a scan's points, people and arms placed on them.

The indoor scan is synthetic (no real indoor scan is available): the industrial_hall builder's layout scanned by the
HDL-64E preset's rays and written as an organised .npy, read back as a real scan (benchmarks/bench_real_twins.py), so
the finder sees points only while the truth of each return is known. The outdoor floor is KITTI frame 004747.
"""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_real_twins import hall_scan, scores  # noqa: E402

from bpy_pipeline.config import load_config  # noqa: E402
from bpy_pipeline.mixing.frame import mix_frame  # noqa: E402
from bpy_pipeline.mixing.section import SupportParams  # noqa: E402
from bpy_pipeline.mixing.supports import dbscan, find_supports  # noqa: E402


@pytest.fixture(scope="module")
def hall(tmp_path_factory):
    """``(scan path, xyz (n, 3) of the returns, truth (n,) 1 floor 2 desk top 3 other, desk tops)``."""
    path, truth_grid, tops = hall_scan(tmp_path_factory.mktemp("hall"))
    grid = np.load(path)
    have = np.linalg.norm(grid[..., :3], axis=2) > 0
    return path, grid[have][:, :3].astype(np.float64), truth_grid[have], tops


def section(path, fmt, people, arms, *extra):
    config = load_config(None, ["scene.builder=real_scan", f"scene.path={path}", f"scene.format={fmt}", "scene.preset=hdl64e",
                                f"scene.population.people={people}", f"scene.population.arms={arms}", *extra])
    return config.scene.params


def brute_dbscan(xy, eps, min_samples):
    d = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    near = d <= eps
    core = near.sum(axis=1) >= min_samples
    label = np.full(len(xy), -1)
    k = 0
    for start in np.flatnonzero(core):
        if label[start] >= 0:
            continue
        stack = [start]
        label[start] = k
        while stack:
            i = stack.pop()
            for j in np.flatnonzero(near[i] & core & (label < 0)):
                label[j] = k
                stack.append(j)
        k += 1
    return label, core, near


def test_dbscan_matches_a_brute_force_dbscan():
    rng = np.random.default_rng(4)
    xy = np.concatenate([rng.normal((0, 0), 0.3, (60, 2)), rng.normal((3, 1), 0.2, (40, 2)), rng.uniform(-2, 5, (30, 2))])
    got = dbscan(xy, 0.35, 5)
    want, core, near = brute_dbscan(xy, 0.35, 5)
    # the same partition of the core points (numbering may differ), border points in a cluster of a core neighbour
    pairs = {(int(a), int(b)) for a, b in zip(got[core], want[core])}
    assert len(pairs) == len({a for a, _ in pairs}) == len({b for _, b in pairs}) == want.max() + 1
    border = ~core & near[:, core].any(axis=1)
    for i in np.flatnonzero(border):
        assert got[i] in set(got[np.flatnonzero(near[i] & core)])
    assert (got[~core & ~border] == -1).all()


def test_floor_and_desks_found_in_the_hall_points_against_the_truth(hall):
    _, xyz, truth, tops = hall
    found = find_supports(xyz, SupportParams())
    s = scores(found, {"floor": truth == 1, "desk": truth == 2}, len(xyz))
    assert s["floor"]["precision"] > 0.9 and s["floor"]["recall"] > 0.95, s
    assert s["desk"]["precision"] > 0.75 and s["desk"]["recall"] > 0.85, s
    floor = [f for f in found if f.kind == "floor"]
    desks = [f for f in found if f.kind == "desk"]
    assert abs(floor[0].height - (-1.8)) < 0.01  # the tripod is 1.8 m up
    assert all(abs(d.above_floor - 0.72) < 0.03 for d in desks)
    # every desk top the scan sees well (a patch at least 0.5 m across both ways) is found: a found desk covers most of its returns
    seen = 0
    for name, (centre, half, z) in tops.items():
        on_top = (truth == 2) & (np.abs(xyz[:, :2] - centre) <= half).all(axis=1)
        if on_top.sum() < 3 or (np.ptp(xyz[on_top, :2], axis=0) < 0.5).any():
            continue
        seen += 1
        hit = np.zeros(len(xyz), bool)
        for d in desks:
            hit[d.index] = True
        assert (hit & on_top).sum() > 0.8 * on_top.sum(), name
    assert seen >= 4


def mesh_of(frame, instance):
    rows = np.flatnonzero(frame.buffers.objects.instance == instance)
    tri = frame.buffers.triangles[np.isin(frame.buffers.triangle_object, rows)]
    return frame.buffers.vertices[np.unique(tri)]


def local_median(xyz, xy, reach=0.2):
    near = np.linalg.norm(xyz[:, :2] - xy, axis=1) <= reach
    return np.median(xyz[near, 2]) if near.any() else np.nan


def in_yawed_box(points, vertices, yaw, bottom):
    """Points inside the box around ``vertices`` turned by ``yaw``, above ``bottom`` m."""
    c, s = math.cos(yaw), math.sin(yaw)
    turn = np.array([[c, -s], [s, c]])
    local, lv = points[:, :2] @ turn, vertices[:, :2] @ turn
    inside = ((local >= lv.min(axis=0)) & (local <= lv.max(axis=0))).all(axis=1)
    return inside & (points[:, 2] > bottom) & (points[:, 2] <= vertices[:, 2].max())


def test_people_stand_on_the_hall_floor_and_arms_on_its_desks(hall):
    path, xyz, truth, tops = hall
    frame = mix_frame(section(path, "npy", 4, 2), np.random.default_rng(3))
    first = int(frame.points["instance"][~frame.inserted].max(initial=0)) + 1
    placed = [(p, first + k) for k, p in enumerate(frame.placements)]
    people = [(p, i) for p, i in placed if p.type == "person"]
    arms = [(p, i) for p, i in placed if p.type == "robot_arm"]
    assert len(people) == 4 and len(arms) == 2
    floor, desk, other = xyz[truth == 1], xyz[truth == 2], xyz[truth == 3]
    for p, inst in people:
        v = mesh_of(frame, inst)
        feet = v[v[:, 2] < v[:, 2].min() + 0.03]
        for foot in feet[:: max(len(feet) // 8, 1)]:
            assert abs(foot[2] - local_median(floor, foot[:2], 0.3)) < 0.05  # on the real floor's points
        # no real return other than the floor's inside the person's box (5 cm above its feet)
        assert not in_yawed_box(xyz[truth != 1], v, p.yaw, v[:, 2].min() + 0.05).any()
        got = frame.points[frame.points["instance"] == inst]
        assert len(got) > 20 and (got["semantic"] == got["semantic"][0]).all()
    for p, inst in arms:
        v = mesh_of(frame, inst)
        base = v[v[:, 2] < v[:, 2].min() + 0.01]
        for point in base[:: max(len(base) // 6, 1)]:
            assert abs(point[2] - local_median(desk, point[:2], 0.15)) < 0.05  # on a desk top the finder found
        assert any(((np.abs(base[:, :2] - c) <= h + 0.05).all(axis=1)).all() for c, h, _ in tops.values())
        # no wall, shelf, pallet or person return within the arm's capsules (its mesh vertices stand in: 3 cm)
        from scipy.spatial import cKDTree

        above = other[other[:, 2] > v[:, 2].min() + 0.1]  # real returns 10 cm above the desk top (the placer's clearance)
        d, _ = cKDTree(above).query(v, distance_upper_bound=0.5)
        assert d.min() > 0.02, d.min()
    # the real firings cast them: one return per firing, each inserted point on its firing's ray
    assert len(np.unique(frame.firing)) == len(frame.firing)
    ins = frame.points[frame.inserted]
    f = frame.firing[frame.inserted]
    xyz_ins = np.column_stack([ins["x"], ins["y"], ins["z"]]).astype(np.float64)
    along = frame.firings.origin[f] + ins["range"][:, None] * frame.firings.direction[f]
    assert np.abs(xyz_ins - along).max() < 1e-3
    names = {int(frame.points["semantic"][frame.points["instance"] == i][0]) for _, i in people}
    assert len(names) == 1 and names != {int(frame.points["semantic"][frame.points["instance"] == arms[0][1]][0])}


def test_people_stand_on_a_real_kitti_road(real_scan):
    path = real_scan("kitti_hdl64e_004747.bin")
    frame = mix_frame(section(path, "kitti", 4, 0), np.random.default_rng(5))
    real = frame.points[~frame.inserted]
    xyz = np.column_stack([real["x"], real["y"], real["z"]]).astype(np.float64)
    first = int(real["instance"].max(initial=0)) + 1
    people = [(p, first + k) for k, p in enumerate(frame.placements)]
    assert len(people) == 4 and all(p.type == "person" for p, _ in people)
    for p, inst in people:
        v = mesh_of(frame, inst)
        low = v[:, 2].min()
        feet = v[v[:, 2] < low + 0.03]
        for foot in feet[:: max(len(feet) // 8, 1)]:
            near = xyz[np.linalg.norm(xyz[:, :2] - foot[:2], axis=1) <= 0.3]
            ground = near[near[:, 2] < near[:, 2].min() + 0.15]  # the local ground: the lowest returns beneath
            assert len(ground) >= 3 and abs(foot[2] - np.median(ground[:, 2])) < 0.05
        # no real non-ground return (more than 10 cm above the feet) in the person's box
        assert not in_yawed_box(xyz, v, p.yaw, low + 0.1).any()
        assert (frame.points["instance"] == inst).sum() > 10


def test_same_seed_same_bytes(hall):
    path = hall[0]
    a = mix_frame(section(path, "npy", 3, 1), np.random.default_rng(11))
    b = mix_frame(section(path, "npy", 3, 1), np.random.default_rng(11))
    c = mix_frame(section(path, "npy", 3, 1), np.random.default_rng(12))
    assert a.points.tobytes() == b.points.tobytes() and a.boxes.tobytes() == b.boxes.tobytes()
    assert a.points.tobytes() != c.points.tobytes()


@pytest.mark.parametrize("setting, key", [
    ("scene.population.people_on=[roof]", "scene.population.people_on"),
    ("scene.population.person={count: 2}", "scene.population.person"),
    ("scene.population.supports.eps=-1", "scene.population.supports.eps"),
])
def test_bad_population_is_one_line_exit_2(tmp_path, setting, key):
    done = subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(tmp_path / "out"), "--set", "scene.builder=real_scan",
                           "--set", "scene.path=scan.bin", "--set", setting], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2 and key in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "out" / "sequences").exists()
