"""Splits that do not leak, and SemanticKITTI's own label space (io/splits.py, io/class_maps.py).

The pure checks run without Blender; the runs (a parking run in full, as a frame range and with two
workers) need bpy.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from bpy_pipeline.config import SplitConfig, load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.io import splits
from bpy_pipeline.io.class_maps import SEMANTIC_KITTI, semantic_kitti_lut, semantic_kitti_space_yaml, task_training
from bpy_pipeline.labels import load_class_table, semantickitti_ids

ROOT = Path(__file__).resolve().parents[1]


def resolved(frames=100, scene_frames=1, **keys):
    return splits.resolve(SplitConfig(**keys), frames, scene_frames)


# ----------------------------------------------------------------------------- the split
@pytest.mark.parametrize("keys, scene_frames", [({}, 1), ({}, 2**31 - 1), ({"by": "block", "block": 7}, 1), ({"by": "scene"}, 4), ({"seed": 3}, 1),
                                                ({"by": "fold", "folds": 5}, 1), ({"by": "fold", "folds": 4, "fold": 1}, 3)])
def test_no_scene_block_or_fold_is_in_two_splits(keys, scene_frames):
    split = resolved(200, scene_frames, **keys)
    names = [splits.split_of(i, split, 200) for i in range(200)]
    for start in range(0, 200, split.block):  # a unit: the builder's scene, a block, or the frames of a fold's unit
        assert len(set(names[start:start + split.block])) == 1
    if split.by == "fold":  # contiguous: val is one run of frames
        val = [i for i, n in enumerate(names) if n == "val"]
        assert val == list(range(val[0], val[-1] + 1)) and "test" not in names
        assert abs(len(val) - 200 / split.folds) <= split.block  # whole scenes


def test_default_is_by_scene_where_the_builder_makes_several_else_by_block():
    assert resolved(scene_frames=1).by == "scene" and resolved(scene_frames=1).block == 1  # parking, street, hall
    assert resolved(scene_frames=2**31 - 1).by == "block" and resolved(scene_frames=2**31 - 1).block == splits.DEFAULT_BLOCK  # the railway, one line
    assert resolved(scene_frames=12).by == "scene" and resolved(scene_frames=12).block == 12  # reroll_every: 12
    assert load_config(None, ["scene.builder=parking", "frames=4"]).output.split.by == "scene"
    assert load_config(None, []).output.split.by == "block"


def test_shares_hold_over_any_run_of_units():
    split = resolved(1000)
    names = [splits.split_of(i, split, 1000) for i in range(1000)]
    assert names[:5] == ["train", "train", "val", "train", "test"]
    for n in (3, 10, 20, 99):
        for start in range(0, 1000 - n, 37):
            window = names[start:start + n]
            for name, share in zip(splits.SPLITS, (0.7, 0.15, 0.15)):
                assert abs(window.count(name) - share * n) <= 2, (start, n, name)
    seeded = [splits.split_of(i, resolved(1000, seed=4), 1000) for i in range(1000)]
    assert seeded != names and abs(seeded.count("val") - 150) <= 2


def test_the_split_of_a_frame_does_not_depend_on_the_run_length_or_the_frames_around_it():
    for keys in ({}, {"by": "block", "block": 3}, {"seed": 9}):
        long = [splits.split_of(i, resolved(500, **keys), 500) for i in range(50)]
        assert long == [splits.split_of(i, resolved(50, **keys), 50) for i in range(50)]
        assert splits.split_indices(range(20, 40), resolved(**keys), 100) == {n: [i for i in range(20, 40) if long[i] == n] for n in splits.SPLITS}


def test_semantickitti_sequences_follow_the_split():
    split = resolved(100)
    for i in range(100):
        name, sequence = splits.split_of(i, split, 100), splits.sequence_of(i, split, 100)
        assert sequence in splits.SEQUENCES[name] and splits.split_of_sequence(sequence) == name
    train = [splits.sequence_of(i, split, 100) for i in range(100) if splits.split_of(i, split, 100) == "train"]
    assert train[:11] == [0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 0]  # round robin over the stock train sequences
    folds = resolved(10, by="fold", folds=5)
    assert [splits.sequence_of(i, folds, 10) for i in range(10)] == [0, 0, 1, 1, 2, 2, 3, 3, 8, 8]


@pytest.mark.parametrize("override, key", [
    ("output.split.by=random", "output.split.by"), ("output.split.train=1.2", "output.split.train"),
    ("output.split={train: 0.5, val: 0.1, test: 0.1}", "output.split"),
    ("output.split={by: block, block: -2}", "output.split.block"), ("output.split={by: fold, folds: 1}", "output.split.folds"),
    ("output.split={by: fold, folds: 3, fold: 3}", "output.split.fold"), ("output.split.seed=-1", "output.split.seed"),
    ("output.split={by: frame, block: 4}", "output.split.block"), ("output.sequence=3", "output.sequence"),
    ("output.semantickitti.labels=kitti", "output.semantickitti.labels"), ("output.class_map={car: [car, lorry]}", "output.class_map.car"),
    ("output.class_map={car: [car], auto: [car]}", "output.class_map.auto"), ("output.class_map={ignore: [reflection]}", "output.class_map"),
    ("output.class_map={car: van}", "output.class_map.car"), ("output.kitti.val_fraction=1.5", "output.kitti.val_fraction"),
])
def test_bad_split_and_label_keys_get_one_line_naming_the_key(override, key):
    frames = ["frames=20", "scene.builder=parking"]
    with pytest.raises(InputError) as err:
        load_config(None, [*frames, override])
    assert key in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(InputError, match="output.split.by: scene"):
        load_config(None, ["output.split.by=scene"])  # the railway builds one line for the run


def test_older_configs_keep_working():
    config = load_config(None, ["scene.builder=parking", "frames=8", "output.kitti.val_fraction=0.25", "output.sequence=0"])
    assert (config.output.split.train, config.output.split.val, config.output.split.test) == (0.75, 0.25, 0.0)
    from bpy_pipeline.config import config_from_dict, config_to_dict

    assert config_from_dict(config_to_dict(config)) == config  # the resolved split loads back as it is


# ----------------------------------------------------------------------------- the label space
def test_every_class_has_a_semantickitti_raw_id_of_its_learning_map():
    table = load_class_table()
    ids = semantickitti_ids()
    assert set(ids) == set(table.names.values())
    lut = semantic_kitti_lut()
    assert set(int(v) for v in lut[list(table.names)]) <= set(SEMANTIC_KITTI)
    for name, sk in {"car": 10, "person": 30, "road": 40, "sidewalk": 48, "building": 50, "vegetation": 70, "trunk": 71, "terrain": 72,
                     "pole": 80, "traffic sign": 81, "truck": 18, "bicycle": 11, "motorcycle": 15, "fence": 51, "unlabeled": 0}.items():  # fmt: skip
        assert lut[table.id_of(name)] == sk, name
    assert lut[60000] == 0  # ids outside the table: unlabeled


def test_the_class_table_file_is_parsed_once_whichever_way_its_path_is_given(monkeypatch):
    from bpy_pipeline import labels

    parsed = []
    monkeypatch.setattr(labels, "load_yaml", lambda text: parsed.append(text) or yaml.safe_load(text))
    caches = (labels._class_file, labels._class_table, labels._semantickitti_ids)
    for cached in caches:
        cached.cache_clear()
    try:
        table = labels.load_class_table()
        assert labels.load_class_table(labels.LABELS_PATH) is table and labels.load_class_table(str(labels.LABELS_PATH)) is table
        assert labels.semantickitti_ids() is labels.semantickitti_ids(labels.LABELS_PATH)
        assert len(parsed) == 1
    finally:  # the values parsed by the stand-in are not kept for later tests
        for cached in caches:
            cached.cache_clear()


def test_the_yaml_speaks_the_devkits_table_and_a_class_map_trains_a_task():
    stock = semantic_kitti_space_yaml()
    assert stock["learning_map"][10] == 1 and stock["learning_map"][52] == 0 and stock["learning_map_inv"][5] == 20
    assert set(stock["labels"]) == set(stock["learning_map"]) == set(SEMANTIC_KITTI)
    class_map = {"car": ["car", "van"], "pedestrian": ["person"], "background": "rest"}
    task = task_training(class_map)
    table = load_class_table()
    assert task.training[table.id_of("van")] == 1 and task.training[table.id_of("person")] == 2 and task.training[table.id_of("wall")] == 3
    assert task.training[table.id_of("unlabeled")] == 0 and task.training[table.id_of("reflection")] == 0  # rest: the classes the table trains
    sk = semantic_kitti_space_yaml(class_map=class_map)
    assert sk["learning_map"][10] == 1 and sk["learning_map"][30] == 2 and sk["learning_map"][50] == 3 and sk["learning_map"][0] == 0
    assert sk["learning_map_inv"] == {0: 0, 1: 10, 2: 30, 3: 11}


# ----------------------------------------------------------------------------- runs
PARKING = ["--set", "scene.builder=parking", "--set", "scene.cars={kind: normal, mean: 1, std: 1, min: 0, max: 2}", "--set", "sensor.columns=256",
           "--set", "output.formats=[semantickitti,npy]", "--set", "output.boxes.formats=[kitti,openpcdet]", "--set", "output.preview=false",
           "--seed", "4", "--frames", "7"]  # fmt: skip


def cli(*args):
    return subprocess.run([sys.executable, str(ROOT / "run.py"), *args], cwd=ROOT, capture_output=True, text=True, timeout=600)


def written_splits(out: Path) -> dict:
    """Every split the folder states: ImageSets, Pointcept lists, mmdetection3d infos and the frames of each sequence."""
    import pickle

    found = {}
    for path in sorted(out.rglob("*")):
        rel = str(path.relative_to(out))
        if path.is_file() and "ImageSets" in rel or path.name.startswith("npy_") and path.suffix == ".json":
            found[rel] = path.read_text()
        elif path.suffix == ".pkl":
            found[rel] = [i["lidar_points"]["lidar_path"] for i in pickle.loads(path.read_bytes())["data_list"]]
        elif path.suffix == ".bin" and "/velodyne/" in rel:
            found[rel] = "scan"
    found["yaml split"] = yaml.safe_load((out / "semantic-kitti.yaml").read_text())["split"]
    return found


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    pytest.importorskip("bpy", reason="the splits are checked on real runs")
    out = tmp_path_factory.mktemp("splits") / "full"
    done = cli("--out", str(out), *PARKING)
    assert done.returncode == 0, done.stderr[-2000:]
    return out


def test_written_splits_are_the_same_for_a_full_run_a_frame_range_and_two_workers(full_run, tmp_path):
    full = written_splits(full_run)
    assert any("ImageSets/test.txt" in k for k in full) and full["npy_val.json"]
    workers = tmp_path / "workers"
    assert cli("--out", str(workers), "--workers", "2", *PARKING).returncode == 0
    assert written_splits(workers) == full
    part = tmp_path / "part"  # frames 2..6 made alone, then 0..1 by a resume: the split of each frame never moves
    assert cli("--out", str(part), "--frames-range", "2:7", *PARKING).returncode == 0
    alone = written_splits(part)
    assert {k: v for k, v in alone.items() if k.endswith(".bin")} == {k: v for k, v in full.items() if k.endswith(".bin") and int(Path(k).stem) >= 2}
    assert cli("--out", str(part), "--resume", *PARKING).returncode == 0
    assert written_splits(part) == full


def test_a_run_writes_semantickitti_ids_the_stock_tables_know(full_run):
    config = yaml.safe_load((full_run / "semantic-kitti.yaml").read_text())
    valid = config["split"]["valid"]
    assert valid and all(any((full_run / "sequences" / f"{s:02d}" / "velodyne").glob("*.bin")) for s in valid)
    seen = set()
    for label in full_run.glob("sequences/*/labels/*.label"):
        ids = set(np.unique(np.fromfile(label, "<u4") & 0xFFFF).tolist())
        assert ids <= set(config["learning_map"]) and ids <= set(SEMANTIC_KITTI)
        seen |= ids
    assert {10, 49, 50} <= seen  # car, floor and ramp (other-ground), wall and pillar (building)
    for path in full_run.rglob("*"):  # never an empty index file
        if path.is_file() and ("ImageSets" in str(path) or path.name.startswith("npy_")):
            assert path.read_text().strip() not in ("", "[]"), path
    records = [json.loads(p.read_text()) for p in sorted((full_run / "records").glob("*.json"))]
    names = {name: {int(line) for line in (full_run / "kitti" / "ImageSets" / f"{name}.txt").read_text().split()} for name in ("train", "val", "test")}
    for record in records:  # the KITTI test frames are where the loaders read them
        folder = "testing" if record["index"] in names["test"] else "training"
        assert (full_run / "kitti" / folder / "velodyne" / f"{record['index']:06d}.bin").is_file()


def test_project_labels_keep_the_project_ids(full_run, tmp_path):
    out = tmp_path / "project"
    done = cli("--out", str(out), *PARKING[:-2], "--frames", "1", "--set", "output.semantickitti.labels=project")
    assert done.returncode == 0, done.stderr[-2000:]
    label = next(out.glob("sequences/*/labels/000000.label"))
    ids = set(np.unique(np.fromfile(label, "<u4") & 0xFFFF).tolist())
    table = load_class_table()
    assert table.id_of("wall") in ids and ids <= set(table.names)
    assert yaml.safe_load((out / "semantic-kitti.yaml").read_text())["labels"][table.id_of("wall")] == "wall"
    mine = np.fromfile(next(full_run.glob("sequences/*/labels/000000.label")), "<u4")  # the same frame in SemanticKITTI's ids
    np.testing.assert_array_equal(semantic_kitti_lut()[np.fromfile(label, "<u4") & 0xFFFF], mine & 0xFFFF)
