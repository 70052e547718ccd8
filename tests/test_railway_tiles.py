"""The training export: tiles cover every point once, sampling keeps N points (rare classes too), Pointcept folders."""

import json

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.tiles import class_quotas, farthest_point, sample, tiles
from bpy_pipeline.cli.tiles import main
from bpy_pipeline.io.tiles import TileSettings, export_tiles
from samples import random_points


@pytest.mark.parametrize("size,overlap", [(10.0, 0.0), (10.0, 2.0), (7.5, 5.0), (200.0, 0.0)])
def test_tile_cores_cover_every_point_once_and_windows_hold_the_overlap(size, overlap):
    rng = np.random.default_rng(1)
    xy = rng.uniform([-40, -12], [60, 12], (20000, 2))
    xy[:50] = np.round(xy[:50] / (size - overlap)) * (size - overlap)  # points on cell borders
    found = tiles(xy, size, overlap)
    cores = np.concatenate([t.window[t.core] for t in found])
    assert np.array_equal(np.sort(cores), np.arange(len(xy)))  # each point in exactly one core
    for t in found:
        x0, y0, x1, y1 = t.bounds
        assert x1 - x0 == pytest.approx(size) and y1 - y0 == pytest.approx(size)
        inside = np.flatnonzero(((xy >= [x0, y0]) & (xy < [x1, y1])).all(1))
        assert np.array_equal(t.window, inside)  # the window is exactly the points in its square


def test_class_histograms_of_the_cores_sum_to_the_whole(tmp_path):
    rng = np.random.default_rng(2)
    points = random_points(30000, rng, extent=30.0, instances=1000)
    points["semantic"] = rng.choice([1, 2, 3, 14], len(points), p=[0.8, 0.15, 0.0499, 0.0001])
    points["range"] = np.hypot(points["x"], points["y"])
    index = export_tiles(points, tmp_path, "scan", TileSettings(size=10.0, overlap=2.0, points=512, method="random", class_aware=True), rng)
    total = {}
    for entry in index:
        for c, k in entry["core_histogram"].items():
            total[int(c)] = total.get(int(c), 0) + k
    classes, counts = np.unique(points["semantic"], return_counts=True)
    assert total == {int(c): int(k) for c, k in zip(classes, counts)}
    folder = tmp_path / "scan" / index[0]["tile"]
    coord, core = np.load(folder / "coord.npy"), np.load(folder / "core.npy")
    assert coord.shape == (min(512, index[0]["window_points"]), 3) and core.shape == (len(coord),) and core.any()
    assert len(np.load(folder / "segment.npy")) == len(coord)
    assert json.loads((tmp_path / "scan" / "tiles.json").read_text())["tiles"] == index


def test_range_crop_drops_far_points(tmp_path):
    rng = np.random.default_rng(3)
    points = random_points(5000, rng, extent=50.0, instances=1000)
    points["range"] = np.hypot(points["x"], points["y"])
    index = export_tiles(points, tmp_path, "near", TileSettings(size=20.0, points=0, max_range=25.0), rng)
    assert sum(e["core_points"] for e in index) == int((points["range"] <= 25.0).sum())


def test_class_aware_sampling_keeps_rare_classes():
    rng = np.random.default_rng(4)
    labels = np.concatenate([np.full(100000, 1), np.full(40, 14), np.full(3000, 9)])
    xyz = rng.uniform(0, 10, (len(labels), 3))
    plain = sample(xyz, 4096, "random", rng)
    aware = sample(xyz, 4096, "random", rng, labels)
    assert len(aware) == 4096 and len(np.unique(aware)) == 4096
    assert (labels[aware] == 14).sum() == 40 > (labels[plain] == 14).sum()  # every dropper point kept
    quotas = class_quotas(labels, 4096)
    assert sum(quotas.values()) == 4096 and quotas[14] == 40


def test_farthest_point_sampling_spreads_out():
    rng = np.random.default_rng(5)
    xyz = np.concatenate([rng.normal(0, 0.01, (5000, 3)), [[10, 0, 0], [0, 10, 0], [0, 0, 10]]])
    picked = farthest_point(xyz, 4, rng)
    assert {5000, 5001, 5002} <= set(picked.tolist())  # the outliers come first after the start
    assert len(sample(xyz, 100, "fps", rng)) == 100


def test_bad_settings_name_the_key(tmp_path):
    points = random_points(10, np.random.default_rng(0))
    for settings, key in ((TileSettings(size=0), "tiles.size"), (TileSettings(overlap=10.0), "tiles.overlap"), (TileSettings(method="grid"), "tiles.method")):
        with pytest.raises(InputError, match=key):
            export_tiles(points, tmp_path, "x", settings, np.random.default_rng(0))
    assert not (tmp_path / "x").exists()


def test_the_command_tiles_a_dataset_folder(tmp_path):
    from bpy_pipeline.io.ply import write_ply

    points = random_points(2000, np.random.default_rng(6), extent=20.0, instances=1000)
    write_ply(tmp_path / "run" / "ply" / "000000.ply", points)
    assert main([str(tmp_path / "run"), str(tmp_path / "tiles"), "--size", "10", "--points", "100", "--method", "fps", "--class-aware"]) == 0
    index = json.loads((tmp_path / "tiles" / "000000" / "tiles.json").read_text())["tiles"]
    assert sum(e["core_points"] for e in index) == 2000 and all(e["written_points"] <= 100 for e in index)


def test_coarse_classes_group_the_railway_classes(tmp_path):
    from bpy_pipeline.io.tiles import coarse_classes
    from bpy_pipeline.labels import load_class_table

    names, lookup = coarse_classes()
    table = load_class_table()
    raw = {n: i for i, n in table.names.items()}
    assert names[lookup[raw["dropper"]]] == names[lookup[raw["contact wire"]]] == "wire"
    assert names[lookup[raw["steady arm"]]] == names[lookup[raw["mast"]]] == "support"
    assert names[lookup[raw["car"]]] == "car" and lookup[raw["unlabeled"]] == -1
    points = random_points(3000, np.random.default_rng(7), extent=10.0, instances=1000)
    points["semantic"] = raw["dropper"]
    index = export_tiles(points, tmp_path, "c", TileSettings(size=10.0, points=0, coarse=True), np.random.default_rng(0))
    segment = np.load(tmp_path / "c" / index[0]["tile"] / "segment.npy")
    assert (segment == names.index("wire")).all()
    assert json.loads((tmp_path / "c" / "coarse.json").read_text())["names"] == names
