"""Run the upstream detectors' own dataset code on output folders, by hand: the check tests/test_loaders.py replays.

    python scripts/check_upstream_loaders.py --openpcdet /path/to/OpenPCDet [--mmdet3d /path/to/mmdetection3d] OUT [OUT ...]

Run it with a Python that has what the upstream dataset code imports (torch, numpy, easydict, pyyaml, scipy,
scikit-image, SharedArray, spconv; for mmdetection3d mmengine, mmcv and mmdet), never the project's own venv. The
checkouts stay untouched: each folder is checked in a work folder of its own (``--work``), with a copy of the
checkout's ``pcdet/`` and ``tools/`` and the folder's ``kitti``/``openpcdet`` copied in as ``data/kitti`` and
``data/custom``, as docs/formats.md's steps link them (``create_kitti_infos`` reads ``ROOT_DIR/data/kitti``).

What runs, unchanged (OpenPCDet 8caccce, mmdetection3d fe25f7a were the commits checked):
- OpenPCDet: ``python -m pcdet.datasets.kitti.kitti_dataset create_kitti_infos tools/cfgs/dataset_configs/kitti_dataset.yaml``
  and ``pcdet.datasets.custom.custom_dataset create_custom_infos`` (their ``__main__`` blocks: infos and the
  ground-truth databases), then ``KittiDataset`` / ``CustomDataset`` built from the written model yamls
  (``cfg_from_yaml_file`` from ``tools/``, as ``train.py``) and every train item (training) and val item through
  ``__getitem__``: the sampler, the road planes, the range masks, the voxels. The stock model yamls are tried too and
  their outcome reported (a run without pedestrians: ``KeyError: 'Pedestrian'``).
- mmdetection3d (with mmcv-lite: ``mmcv.ops`` and ``mmcv._ext``, compiled, are given as names that raise when
  called, and none is; ``np.long``, which ``dbsampler.py`` uses and numpy 1.24 removed, as ``np.int64``):
  ``tools/create_data.py kitti --with-plane``'s steps (``create_kitti_info_file``, ``update_pkl_infos``,
  ``create_groundtruth_database``), then the dataset of the written config (``Config.fromfile``, its ``_base_`` the
  checkout's pointpillars 3-class config) and every train and val item through its pipeline.

Only the compiled CUDA extensions are replaced, by numpy: ``roiaware_pool3d_cuda.points_in_boxes_cpu`` (a point
inside a box: |dz| <= h / 2, |local x, y| < half size + 1 cm, as roiaware_pool3d.cpp) and
``iou3d_nms_cuda.boxes_iou_bev_cpu`` (rotated bird's-eye IoU, as iou3d_cpu.cpp); ``pcdet/version.py``, which
OpenPCDet's setup.py writes, is given, and so is an empty ``torchvision`` where none loads (``data_processor.py``
imports it for its image steps only; PyPI's wheels hold ops built for a CUDA torch). Prints one line per check and
exits 1 when one fails.
"""

from __future__ import annotations

import argparse
import importlib.abc
import importlib.util
import pickle
import runpy
import shutil
import sys
import types
from pathlib import Path

import numpy as np

RESULTS: list[tuple[str, bool, str]] = []


def report(name: str, ok: bool, detail: str = "") -> None:
    RESULTS.append((name, ok, detail))
    print(f"{'ok  ' if ok else 'FAIL'} {name}{': ' + detail if detail else ''}", flush=True)


# ----------------------------------------------------------------------------- the CUDA extensions, in numpy
def points_in_boxes(boxes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(n_boxes, n_points)`` int: roiaware_pool3d.cpp's check_pt_in_box3d_cpu."""
    out = np.zeros((len(boxes), len(points)), np.int32)
    for i, (cx, cy, cz, dx, dy, dz, rz) in enumerate(np.asarray(boxes, np.float32)):
        sx, sy = points[:, 0] - cx, points[:, 1] - cy
        cosa, sina = np.cos(-rz), np.sin(-rz)
        local_x, local_y = sx * cosa - sy * sina, sx * sina + sy * cosa
        out[i] = (np.abs(points[:, 2] - cz) <= dz / 2) & (np.abs(local_x) < dx / 2 + 1e-2) & (np.abs(local_y) < dy / 2 + 1e-2)
    return out


def _corners(box) -> np.ndarray:
    x, y, _, dx, dy, _, r = box
    c, s = np.cos(r), np.sin(r)
    local = np.array([[dx, dy], [-dx, dy], [-dx, -dy], [dx, -dy]]) / 2
    return local @ np.array([[c, s], [-s, c]]) + [x, y]


def _clip(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the convex polygon ``subject`` cut by the convex counter-clockwise ``clip``."""
    out = subject
    for k in range(len(clip)):
        a, b = clip[k], clip[(k + 1) % len(clip)]
        side = lambda p: (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])  # noqa: E731
        polygon, out = out, []
        for j in range(len(polygon)):
            p, q = polygon[j], polygon[(j + 1) % len(polygon)]
            sp, sq = side(p), side(q)
            if sp >= 0:
                out.append(p)
            if sp * sq < 0:
                out.append(p + (q - p) * sp / (sp - sq))
        if not out:
            return np.zeros((0, 2))
        out = np.array(out)
    return out


def _area(polygon: np.ndarray) -> float:
    if len(polygon) < 3:
        return 0.0
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def bev_iou(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """``(n, m)`` rotated bird's-eye IoU: iou3d_cpu.cpp's iou_bev."""
    out = np.zeros((len(boxes_a), len(boxes_b)), np.float32)
    for i, a in enumerate(boxes_a):
        pa = _corners(a)
        for j, b in enumerate(boxes_b):
            overlap = _area(_clip(pa, _corners(b)))
            out[i, j] = overlap / max(a[3] * a[4] + b[3] * b[4] - overlap, 1e-8)
    return out


def install_stubs(version: str) -> None:
    """The two compiled extensions and the version file, as modules, before pcdet is imported."""
    import torch

    def roiaware_points_in_boxes_cpu(boxes, points, indices):
        indices.copy_(torch.from_numpy(points_in_boxes(boxes.numpy(), points.numpy())))
        return 1

    def iou_bev_cpu(boxes_a, boxes_b, ans):
        ans.copy_(torch.from_numpy(bev_iou(boxes_a.numpy(), boxes_b.numpy())))
        return 1

    modules = {
        "pcdet.version": {"__version__": version},
        "pcdet.ops.roiaware_pool3d.roiaware_pool3d_cuda": {"points_in_boxes_cpu": roiaware_points_in_boxes_cpu},
        "pcdet.ops.iou3d_nms.iou3d_nms_cuda": {"boxes_iou_bev_cpu": iou_bev_cpu},
    }
    try:
        import torchvision  # noqa: F401  (data_processor.py imports it for its image steps)
    except Exception:
        modules["torchvision"] = {}
    for name, attributes in modules.items():
        module = types.ModuleType(name)
        module.__dict__.update(attributes)
        sys.modules[name] = module


class CompiledOpsStub(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """``mmcv.ops``, its submodules and ``mmcv._ext`` (compiled CPU and CUDA ops; mmcv-lite has none): every name importable, each
    raising when called, so a dataset step that needed one would say so. The KITTI dataset steps call none (their
    boxes go through numpy)."""

    def find_spec(self, name, path=None, target=None):
        stubbed = name in ("mmcv.ops", "mmcv._ext") or name.startswith("mmcv.ops.")
        return importlib.util.spec_from_loader(name, self, is_package=True) if stubbed else None

    def create_module(self, spec):
        module = types.ModuleType(spec.name)
        module.__path__ = []

        def missing(attribute: str):
            if attribute.startswith("__"):
                raise AttributeError(attribute)

            def call(*args, **kwargs):
                raise NotImplementedError(f"{spec.name}.{attribute} is a compiled op, not in this check")

            return call

        module.__getattr__ = missing
        return module

    def exec_module(self, module) -> None:
        pass


def datasets_package(root: Path) -> None:
    """``pcdet.datasets`` without its ``__init__`` (which imports every dataset, nuScenes', Waymo's and Argoverse's
    dependencies included): the KITTI and custom modules import as they do there."""
    package = types.ModuleType("pcdet.datasets")
    package.__path__ = [str(root / "pcdet" / "datasets")]
    sys.modules["pcdet.datasets"] = package


# ----------------------------------------------------------------------------- OpenPCDet
def openpcdet_work(checkout: Path, out: Path, work: Path) -> Path:
    """A work copy of the checkout's ``pcdet`` and ``tools`` with the folder's layouts copied in under ``data``."""
    root = work / "OpenPCDet"
    if root.exists():
        shutil.rmtree(root)
    shutil.copytree(checkout / "pcdet", root / "pcdet", ignore=shutil.ignore_patterns("*.cu", "*.cpp", "*.h"))
    shutil.copytree(checkout / "tools", root / "tools")
    for layout, name in (("kitti", "kitti"), ("openpcdet", "custom")):
        if (out / layout).is_dir():
            shutil.copytree(out / layout, root / "data" / name)
    return root


def run_main(module: str, argv: list[str]) -> None:
    """``python -m module argv...`` in this process (the stubs in place)."""
    saved = sys.argv
    sys.argv = [module, *argv]
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=False)
    finally:
        sys.argv = saved


def run_main_file(path: Path, argv: list[str]) -> None:
    """``python path argv...`` in this process (the stubs in place)."""
    saved = sys.argv
    sys.argv = [str(path), *argv]
    try:
        runpy.run_path(str(path), run_name="__main__")
    finally:
        sys.argv = saved


def items_through_getitem(dataset_class, cfg_file: str, tools: Path, training: bool) -> str:
    """Every item of the dataset ``cfg_file`` (a model yaml, read from ``tools`` as train.py does) through __getitem__;
    raises when an item has no voxel, or a training item no box."""
    import os

    from easydict import EasyDict
    from pcdet.config import cfg_from_yaml_file
    from pcdet.utils import common_utils

    cwd = os.getcwd()
    os.chdir(tools)
    try:
        cfg = cfg_from_yaml_file(cfg_file, EasyDict())
        dataset = dataset_class(dataset_cfg=cfg.DATA_CONFIG, class_names=cfg.CLASS_NAMES, training=training, root_path=None,
                                logger=common_utils.create_logger())
        boxes, voxels = 0, 0
        for k in range(len(dataset)):
            item = dataset[k]
            if item["voxels"].shape[0] == 0 or (training and len(item["gt_boxes"]) == 0):
                raise AssertionError(f"item {k}: {item['voxels'].shape[0]} voxels, {len(item['gt_boxes'])} boxes")
            boxes += len(item.get("gt_boxes", []))
            voxels += item["voxels"].shape[0]
        return f"{len(dataset)} items, classes {list(cfg.CLASS_NAMES)}, {boxes} boxes, {voxels} voxels"
    finally:
        os.chdir(cwd)


def check_openpcdet(checkout: Path, out: Path, work: Path) -> None:
    root = openpcdet_work(checkout, out, work)
    sys.path.insert(0, str(root))
    for name in [m for m in sys.modules if m == "pcdet" or m.startswith("pcdet.")]:
        del sys.modules[name]
    install_stubs("0.6.0+8caccce")
    datasets_package(root)
    tag = out.name
    if (root / "data" / "kitti").is_dir():
        try:
            run_main("pcdet.datasets.kitti.kitti_dataset", ["create_kitti_infos", str(root / "tools/cfgs/dataset_configs/kitti_dataset.yaml")])
            db = pickle.loads((root / "data/kitti/kitti_dbinfos_train.pkl").read_bytes())
            report(f"{tag}: OpenPCDet create_kitti_infos (data/kitti)", True, "gt database " + ", ".join(f"{k} {len(v)}" for k, v in sorted(db.items())))
        except Exception as err:
            report(f"{tag}: OpenPCDet create_kitti_infos (data/kitti)", False, f"{type(err).__name__}: {err}")
        from pcdet.datasets.kitti.kitti_dataset import KittiDataset

        for cfg_file, training in (("../data/kitti/openpcdet_pv_rcnn.yaml", True), ("../data/kitti/openpcdet_pv_rcnn.yaml", False),
                                   ("../data/kitti/openpcdet_pointpillar.yaml", True), ("../data/kitti/openpcdet_pointpillar.yaml", False),
                                   ("cfgs/kitti_models/pv_rcnn.yaml", True), ("cfgs/kitti_models/pv_rcnn.yaml", False)):
            name = f"{tag}: OpenPCDet KittiDataset {cfg_file} {'train' if training else 'val'}"
            try:
                report(name, True, items_through_getitem(KittiDataset, cfg_file, root / "tools", training))
            except Exception as err:
                report(name, cfg_file.startswith("cfgs/"),
                       f"{type(err).__name__}: {err}" + (" (the stock config: reported, not a failure)" if cfg_file.startswith("cfgs/") else ""))
    if (root / "data" / "custom").is_dir():
        try:
            run_main("pcdet.datasets.custom.custom_dataset", ["create_custom_infos", str(root / "tools/cfgs/dataset_configs/custom_dataset.yaml")])
            db = pickle.loads((root / "data/custom/custom_dbinfos_train.pkl").read_bytes())
            report(f"{tag}: OpenPCDet create_custom_infos (data/custom)", True, "gt database " + ", ".join(f"{k} {len(v)}" for k, v in sorted(db.items())))
        except Exception as err:
            report(f"{tag}: OpenPCDet create_custom_infos (data/custom)", False, f"{type(err).__name__}: {err}")
        from pcdet.datasets.custom.custom_dataset import CustomDataset

        # cfgs/custom_models/pv_rcnn.yaml names its dataset yaml as ../dataset_configs/custom_dataset.yaml, a path no
        # working folder opens (train.py runs from tools/): the stock model with that one path as tools/ reaches it
        (root / "tools" / "stock_custom_pv_rcnn.yaml").write_text(
            "_BASE_CONFIG_: cfgs/custom_models/pv_rcnn.yaml\nDATA_CONFIG:\n    _BASE_CONFIG_: cfgs/dataset_configs/custom_dataset.yaml\n")
        for cfg_file, training in (("../data/custom/pv_rcnn.yaml", True), ("../data/custom/pv_rcnn.yaml", False), ("stock_custom_pv_rcnn.yaml", True)):
            name = f"{tag}: OpenPCDet CustomDataset {cfg_file} {'train' if training else 'val'}"
            try:
                report(name, True, items_through_getitem(CustomDataset, cfg_file, root / "tools", training))
            except Exception as err:
                report(name, cfg_file.startswith("stock"),
                       f"{type(err).__name__}: {err}" + (" (the stock config: reported, not a failure)" if cfg_file.startswith("stock") else ""))
    sys.path.remove(str(root))


# ----------------------------------------------------------------------------- mmdetection3d
def check_mmdet3d(checkout: Path, out: Path, work: Path) -> None:
    tag = out.name
    if not (out / "kitti").is_dir():
        return
    root = work / "mmdet3d"
    if root.exists():
        shutil.rmtree(root)
    shutil.copytree(out / "kitti", root / "data" / "kitti")
    sys.path.insert(0, str(checkout))
    sys.path.insert(0, str(checkout / "tools"))
    sys.meta_path.insert(0, CompiledOpsStub())
    if not hasattr(np, "long"):  # dbsampler.py's sample_all asks numpy for np.long, which numpy 1.24 removed
        np.long = np.int64
    import os

    cwd = os.getcwd()
    os.chdir(root)
    try:
        import mmdet3d.datasets  # noqa: F401  (registers the datasets and transforms, as register_all_modules does)

        run_main_file(checkout / "tools" / "create_data.py", ["kitti", "--root-path", "./data/kitti", "--out-dir", "./data/kitti", "--extra-tag", "kitti",
                                                              "--with-plane"])
        db = pickle.loads((root / "data/kitti/kitti_dbinfos_train.pkl").read_bytes())
        report(f"{tag}: mmdetection3d create_data.py kitti --with-plane", True, "gt database " + ", ".join(f"{k} {len(v)}" for k, v in sorted(db.items())))
    except Exception as err:
        report(f"{tag}: mmdetection3d create_data.py kitti --with-plane", False, f"{type(err).__name__}: {err}")
        os.chdir(cwd)
        return
    body = (root / "data/kitti/mmdet3d_pointpillars_kitti.py").read_text()
    stock = checkout / "configs/pointpillars/pointpillars_hv_secfpn_8xb6-160e_kitti-3d-3class.py"
    written = root / "mmdet3d_pointpillars_kitti.py"  # the written config with its _base_ where the checkout has it
    written.write_text(body.replace("['../pointpillars/pointpillars_hv_secfpn_8xb6-160e_kitti-3d-3class.py']", repr([str(stock)])))
    try:
        for config, label in ((written, "written config"), (stock, "stock pointpillars 3-class")):
            for split in ("train", "val"):
                name = f"{tag}: mmdetection3d {split} items ({label})"
                try:
                    report(name, True, mmdet3d_items(config, split))
                except Exception as err:
                    report(name, config == stock, f"{type(err).__name__}: {err}" + (" (the stock config: reported, not a failure)" if config == stock else ""))
    finally:
        os.chdir(cwd)
        sys.path.remove(str(checkout))
        sys.path.remove(str(checkout / "tools"))


def mmdet3d_items(config: Path, split: str) -> str:
    """Every item of the config's train (its RepeatDataset's dataset) or val dataset through its pipeline; raises when
    an item keeps no point inside point_cloud_range."""
    from mmdet3d.registry import DATASETS
    from mmengine.config import Config

    cfg = Config.fromfile(str(config))
    dataset = DATASETS.build(cfg.train_dataloader.dataset.dataset if split == "train" else cfg.val_dataloader.dataset)
    points, boxes = 0, 0
    for k in range(len(dataset)):
        item = dataset[k]
        count = int(item["inputs"]["points"].shape[0])
        if count == 0:
            raise AssertionError(f"item {k}: no point inside point_cloud_range")
        points += count
        boxes += len(item["data_samples"].gt_instances_3d.labels_3d) if split == "train" else 0
    return f"{len(dataset)} items, classes {list(cfg.class_names)}, {points} points" + (f", {boxes} boxes" if split == "train" else "")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, help="output folders (with kitti/ and openpcdet/)")
    parser.add_argument("--openpcdet", type=Path, help="an OpenPCDet checkout")
    parser.add_argument("--mmdet3d", type=Path, help="an mmdetection3d checkout")
    parser.add_argument("--work", type=Path, default=Path("upstream_check"), help="where the work copies go (replaced)")
    args = parser.parse_args(argv)
    for out in args.folders:
        work = args.work / out.name
        work.mkdir(parents=True, exist_ok=True)
        if args.openpcdet:
            check_openpcdet(args.openpcdet.resolve(), out.resolve(), work.resolve())
        if args.mmdet3d:
            check_mmdet3d(args.mmdet3d.resolve(), out.resolve(), work.resolve())
    failed = [r for r in RESULTS if not r[1]]
    print(f"{len(RESULTS) - len(failed)} passed, {len(failed)} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
