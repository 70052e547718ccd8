"""The frames and classes each stock loader reads from a dataset folder (docs/formats.md, "What the stock loaders read").

    python scripts/loader_figures.py OUT [OUT ...]

Replays, per split, the loaders replicated step by step in tests/test_loaders.py from their upstream code
(the commits are named there): Pointcept's SemanticKITTIDataset and DefaultDataset (npy lists), mmdetection3d's
SemanticKittiDataset (its info files and labels_map), the SemanticKITTI devkit (the yaml's split and
learning_map), OpenPCDet's KittiDataset and CustomDataset (ImageSets), mmdetection3d's KITTI converter. Prints
one markdown table row per loader and split: the frames it reads and the training classes with points (or the
box types).
"""

from __future__ import annotations

import json
import pickle
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import test_loaders as loaders  # noqa: E402  (the replicated upstream code)


def names_of(counts: dict, table: list[str]) -> str:
    return ", ".join(f"{table[k]} {v:,}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1]) if k >= 0) or "none"


def rows(out: Path) -> list[tuple[str, str, int, str]]:
    found = []
    with tempfile.TemporaryDirectory() as tmp:
        data_root = Path(tmp) / "semantic_kitti"
        data_root.mkdir()
        (data_root / "dataset").symlink_to(out.resolve())
        for split in ("train", "val", "test"):
            try:
                loaded = loaders.pointcept_semantic_kitti(data_root, split)
            except FileNotFoundError as err:
                found.append(("Pointcept SemanticKITTIDataset", split, 0, f"fails: {type(err).__name__}"))
                continue
            counts: dict[int, int] = {}
            for _, segment in loaded:
                for k, v in zip(*np.unique(segment, return_counts=True)):
                    counts[int(k)] = counts.get(int(k), 0) + int(v)
            found.append(("Pointcept SemanticKITTIDataset", split, len(loaded), names_of(counts, loaders.SK_CLASSES)))
    mapping = np.zeros(260, np.int64)
    for k, v in loaders.MMDET3D_LABELS_MAP.items():
        mapping[k] = v
    for split in ("train", "val", "test"):
        path = out / f"semantickitti_infos_{split}.pkl"
        if not path.exists():
            found.append(("mmdetection3d SemanticKittiDataset", split, 0, "no info file (empty split)"))
            continue
        infos = pickle.loads(path.read_bytes())["data_list"]
        counts = {}
        for info in infos:
            mask = mapping[np.fromfile(out / info["pts_semantic_mask_path"], np.int32).astype(np.int64) % 2**16]
            for k, v in zip(*np.unique(mask, return_counts=True)):
                if k != 19:
                    counts[int(k)] = counts.get(int(k), 0) + int(v)
        found.append(("mmdetection3d SemanticKittiDataset", split, len(infos), names_of(counts, loaders.SK_CLASSES)))
    config = yaml.safe_load((out / "semantic-kitti.yaml").read_text())
    inverse = {t: config["labels"][raw] for t, raw in config["learning_map_inv"].items()}
    lut = np.zeros(max(config["learning_map"]) + 100, np.int32)
    lut[list(config["learning_map"])] = list(config["learning_map"].values())
    for split, numbers in config["split"].items():
        counts, scans = {}, 0
        for number in numbers:
            for label in sorted((out / "sequences" / f"{number:02d}" / "labels").glob("*.label")):
                scans += 1
                for k, v in zip(*np.unique(lut[np.fromfile(label, np.uint32) & 0xFFFF], return_counts=True)):
                    if k:
                        counts[int(k) - 1] = counts.get(int(k) - 1, 0) + int(v)
        found.append(("SemanticKITTI devkit", split, scans, names_of(counts, [inverse[t + 1] for t in range(len(inverse) - 1)])))
    for split in ("train", "val", "test"):
        path = out / f"npy_{split}.json"
        frames = json.loads(path.read_text()) if path.exists() else []
        counts = {}
        for folder in frames:
            segment = np.load(out / folder / "segment.npy")
            for k, v in zip(*np.unique(segment, return_counts=True)):
                counts[int(k)] = counts.get(int(k), 0) + int(v)
        table = yaml.safe_load((ROOT / "assets_manifest" / "labels.yaml").read_text())
        train_names = {}
        for raw, train in table["learning_map"].items():
            train_names.setdefault(train - 1, table["labels"][raw])
        found.append(("Pointcept DefaultDataset (npy lists)", split, len(frames), names_of(counts, train_names)))
    for split in ("train", "val", "test"):
        if not (out / "kitti" / "ImageSets" / f"{split}.txt").exists():
            found.append(("OpenPCDet KittiDataset", split, 0, "no ImageSets file: create_kitti_infos stops (TypeError)"))
            continue
        infos = loaders.openpcdet_kitti_infos(out / "kitti", split, has_label=split != "test")
        types: dict[str, int] = {}
        for info in infos:
            for name in info.get("annos", {}).get("name", []):
                types[str(name)] = types.get(str(name), 0) + 1
        found.append(("OpenPCDet KittiDataset", split, len(infos), ", ".join(f"{k} {v}" for k, v in sorted(types.items())) or "(test: no labels read)"))
        if split != "test":
            custom = loaders.openpcdet_custom_infos(out / "openpcdet", split) if (out / "openpcdet" / "ImageSets" / f"{split}.txt").exists() else []
            types = {}
            for info in custom:
                for name in info["annos"]["name"]:
                    types[str(name)] = types.get(str(name), 0) + 1
            found.append(("OpenPCDet CustomDataset", split, len(custom), ", ".join(f"{k} {v}" for k, v in sorted(types.items())) or "none"))
    return found


if __name__ == "__main__":
    for folder in sys.argv[1:]:
        out = Path(folder)
        manifest = json.loads((out / "manifest.json").read_text())
        print(
            f"\n{out}: builder {manifest['config']['scene']['builder']}, {manifest['summary']['frames']} frames, split "
            f"{manifest['config']['output']['split']}\n"
        )
        print("| loader | split | frames | classes read (points) / box types (boxes) |\n|---|---|---|---|")
        for loader, split, frames, what in rows(out):
            print(f"| {loader} | {split} | {frames} | {what} |")
