"""The training configs written beside the data: what OpenPCDet and mmdetection3d need for the frames this run holds.

The stock 3-class configs name Car, Pedestrian and Cyclist in their database samplers and anchors; a run without one
of them stops at the sampler (``KeyError: 'Pedestrian'``, OpenPCDet ``database_sampler.py`` and mmdetection3d
``dbsampler.py``). Their point-cloud ranges and anchors expect the ground where KITTI has it, 1.73 m below the
LiDAR; a sensor 4.5 m up puts every point below the range. So the index of the box layouts writes, from the committed
frames (OpenPCDet 8caccce, mmdetection3d fe25f7a)::

    kitti/openpcdet_kitti_dataset.yaml    OpenPCDet's kitti_dataset.yaml for this run (DATA_PATH ../data/kitti)
    kitti/openpcdet_pv_rcnn.yaml          tools/cfgs/kitti_models/pv_rcnn.yaml with this run's classes, range and anchors
    kitti/openpcdet_pointpillar.yaml      tools/cfgs/kitti_models/pointpillar.yaml likewise (its pillars and range restated)
    kitti/mmdet3d_pointpillars_kitti.py   configs/pointpillars/pointpillars_hv_secfpn_8xb6-160e_kitti-3d-3class.py likewise
    openpcdet/custom_dataset.yaml         OpenPCDet's custom_dataset.yaml for this run (DATA_PATH ../data/custom)
    openpcdet/pv_rcnn.yaml                tools/cfgs/custom_models/pv_rcnn.yaml likewise

Classes: those of the train frames that the samplers keep (KITTI: a ``label_2`` object of difficulty easy, moderate
or hard, as ``filter_by_difficulty: [-1]`` keeps; custom: any box), of the stock three for the KITTI layout, each with
its minimum points (5 as stock, lower where ``output.boxes.min_points`` keeps thinner boxes). Range: the stock range's
x and y, its z window moved by the ground's height in the points' frame (the median over the frames) relative to the
stock ground (KITTI's -1.73 m; the custom models' anchors stand at 0), so the voxel grids keep their sizes; the anchors'
bottom heights move with it. With ``output.frame: kitti`` the move is zero and the stock KITTI configs fit as they are.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .atomic import atomic_write, write_text_hashed
from .class_maps import load_class_maps
from ..geometry.transforms import sensor_to_output
from .kitti import points_ground
from .splits import split_indices
from .sustech import label_type

STOCK_KITTI_GROUND = -1.73  # m: the ground under KITTI's LiDAR, where the stock KITTI configs' ranges and anchors stand
STOCK_CUSTOM_GROUND = 0.0  # m: where OpenPCDet's custom models put their anchors' bottoms (tools/cfgs/custom_models)
KITTI_CLASSES = ("Pedestrian", "Cyclist", "Car")  # the stock 3-class configs' classes, in mmdetection3d's order
ANCHORS = {  # KITTI type: ((l, w, h) m, bottom height m in KITTI's frame, matched, unmatched IoU): the stock models' anchors
    "Car": ((3.9, 1.6, 1.56), -1.78, 0.6, 0.45),
    "Pedestrian": ((0.8, 0.6, 1.73), -0.6, 0.5, 0.35),
    "Cyclist": ((1.76, 0.6, 1.73), -0.6, 0.5, 0.35),
}
KITTI_RANGE = (0.0, -40.0, -3.0, 70.4, 40.0, 1.0)  # OpenPCDet kitti_dataset.yaml
PILLAR_RANGE = (0.0, -39.68, -3.0, 69.12, 39.68, 1.0)  # mmdetection3d pointpillars (a multiple of its 0.16 m pillars)
CUSTOM_RANGE = (-75.2, -75.2, -2.0, 75.2, 75.2, 4.0)  # OpenPCDet custom_dataset.yaml
MIN_POINTS = 5  # the stock samplers' filter_by_min_points
KITTI_EVALUATED = ("Car", "Pedestrian", "Cyclist", "Van", "Person_sitting", "Truck")  # the KITTI evaluation's classes
HEADER = "# Written by bpy_pipeline for the frames of this output folder ({frames} frames, train {train}); see docs/formats.md.\n"


def kitti_difficulty(fields: list[str]) -> int:
    """KITTI's difficulty of a ``label_2`` line's fields: 0 easy, 1 moderate, 2 hard, -1 none of them (the samplers drop
    those). The 2D box height is taken as bottom - top, as mmdetection3d does (OpenPCDet adds one pixel), and must be
    over 25 px (mmdetection3d), so an object kept here is kept by both."""
    truncation, occlusion = float(fields[1]), int(float(fields[2]))
    height = float(fields[7]) - float(fields[5])
    for level, (min_height, max_occlusion, max_truncation) in enumerate(((40, 0, 0.15), (25, 1, 0.3), (25, 2, 0.5))):
        if height > min_height and occlusion <= max_occlusion and truncation <= max_truncation:
            return level
    return -1


def sampled_kitti_types(root: Path, stems: list[int]) -> dict[str, int]:
    """``{KITTI type: objects}`` of the ``label_2`` files of frames ``stems`` under ``root`` (``kitti/training``) that a
    sampler with ``filter_by_difficulty: [-1]`` keeps."""
    counts: dict[str, int] = {}
    for stem in stems:
        path = root / "label_2" / f"{stem:06d}.txt"
        for line in path.read_text().splitlines() if path.is_file() else []:
            fields = line.split()
            if len(fields) >= 15 and fields[0] != "DontCare" and kitti_difficulty(fields) >= 0:
                counts[fields[0]] = counts.get(fields[0], 0) + 1
    return counts


def ground_height(records: list[dict], config) -> float:
    """m, the median over ``records`` of the ground's height at the points' origin (about -1.73 for a KITTI-like
    sensor; the builders' ground, or a real scan's found ground), rounded to 1 cm."""
    heights = []
    for record in records:
        if "sensor_pose" not in record:
            continue
        found = ((record.get("scene") or {}).get("rules") or {}).get("ground")
        normal_d = points_ground(np.asarray(record["sensor_pose"], float), config.output.frame, found, config.output.kitti.camera.position)
        heights.append(-normal_d[3] / normal_d[2] if abs(normal_d[2]) > 1e-6 else 0.0)
    return round(float(np.median(heights)), 2) if heights else STOCK_KITTI_GROUND


def camera_xy(records: list[dict], config) -> tuple[float, float]:
    """m, the KITTI camera's x and y in the points' frame (the median over ``records``): where the forward-only KITTI
    range starts. ``(0, 0)`` in the sensor frame with the camera at the sensor and in ``output.frame: kitti``."""
    camera = np.append(np.asarray(config.output.kitti.camera.position, float), 1.0)
    spots = []
    for record in records:
        if "sensor_pose" in record:
            to_points = sensor_to_output(config.output.frame, np.asarray(record["sensor_pose"], float), config.output.kitti.camera.position)
            spots.append(camera[:3] if to_points is None else (to_points @ camera)[:3])
    x, y = np.median(spots, axis=0)[:2] if spots else (0.0, 0.0)
    return round(float(x), 2), round(float(y), 2)


def moved_range(stock: tuple, shift: float, xy=(0.0, 0.0)) -> list[float]:
    """``stock`` point-cloud range with its z window moved by ``shift`` m and its x, y windows by ``xy`` m (the
    windows' sizes kept, so the voxel grids keep theirs)."""
    (x, y), r = xy, stock
    return [round(r[0] + x, 2), round(r[1] + y, 2), round(r[2] + shift, 2), round(r[3] + x, 2), round(r[4] + y, 2), round(r[5] + shift, 2)]


def min_points_of(config, kind_of_class) -> dict[str, int]:
    """``{type: minimum points}`` for the samplers: :data:`MIN_POINTS`, lower where ``output.boxes.min_points`` keeps
    thinner boxes of a class of that type. ``kind_of_class(class) -> type``."""
    boxes = config.output.boxes
    out: dict[str, int] = {}
    for name in boxes.classes:
        kind = kind_of_class(name)
        out[kind] = min(out.get(kind, MIN_POINTS), int(boxes.min_points.get(name, boxes.min_points_default)))
    return out


def _yaml_list(values) -> str:
    return "[" + ", ".join(json.dumps(v) if isinstance(v, str) else repr(v) for v in values) + "]"


def _write(path: Path, text: str) -> Path:
    with atomic_write(path) as tmp:
        write_text_hashed(tmp, text)
    return path


def _anchor_yaml(kind: str, size, bottom: float, matched: float, unmatched: float, stride: int = 8) -> str:
    return (f"      - {{class_name: {kind}, anchor_sizes: [{_yaml_list([round(float(v), 3) for v in size])}], anchor_rotations: [0, 1.57],\n"
            f"         anchor_bottom_heights: [{bottom:.2f}], align_center: false, feature_map_stride: {stride},\n"
            f"         matched_threshold: {matched}, unmatched_threshold: {unmatched}}}\n")


def openpcdet_dataset_yaml(dataset: str, data_path: str, info_prefix: str, classes: list[str], min_points: dict, sample_groups: dict,
                           point_range: list[float], road_plane: bool, extra: str, header: str) -> str:
    """An OpenPCDet dataset yaml (``kitti_dataset.yaml`` or ``custom_dataset.yaml`` of 8caccce with this run's classes and range)."""
    kitti = dataset == "KittiDataset"
    voxel = "[0.05, 0.05, 0.1]" if kitti else "[0.1, 0.1, 0.15]"
    voxels = "{'train': 16000, 'test': 40000}" if kitti else "{'train': 150000, 'test': 150000}"
    flip = "['x']" if kitti else "['x', 'y']"
    return (
        header
        + f"DATASET: '{dataset}'\nDATA_PATH: '{data_path}'\n\nPOINT_CLOUD_RANGE: {_yaml_list(point_range)}\n{extra}\n"
        + "DATA_SPLIT: {'train': train, 'test': val}\n\n"
        + f"INFO_PATH: {{'train': [{info_prefix}_infos_train.pkl], 'test': [{info_prefix}_infos_val.pkl]}}\n\n"
        + ("GET_ITEM_LIST: ['points']\nFOV_POINTS_ONLY: True\n\n" if kitti else "")
        + "POINT_FEATURE_ENCODING: {\n    encoding_type: absolute_coordinates_encoding,\n"
        + "    used_feature_list: ['x', 'y', 'z', 'intensity'],\n    src_feature_list: ['x', 'y', 'z', 'intensity'],\n}\n\n"
        + "DATA_AUGMENTOR:\n    DISABLE_AUG_LIST: ['placeholder']\n    AUG_CONFIG_LIST:\n"
        + f"        - NAME: gt_sampling\n          USE_ROAD_PLANE: {road_plane}\n          DB_INFO_PATH: [{info_prefix}_dbinfos_train.pkl]\n"
        + "          PREPARE: {\n"
        + f"             filter_by_min_points: {_yaml_list([f'{c}:{min_points.get(c, MIN_POINTS)}' for c in classes])},\n"
        + ("             filter_by_difficulty: [-1],\n" if kitti else "")
        + "          }\n"
        + f"          SAMPLE_GROUPS: {_yaml_list([f'{c}:{sample_groups.get(c, 15)}' for c in classes])}\n"
        + "          NUM_POINT_FEATURES: 4\n          DATABASE_WITH_FAKELIDAR: False\n          REMOVE_EXTRA_WIDTH: [0.0, 0.0, 0.0]\n"
          "          LIMIT_WHOLE_SCENE: True\n\n"
        + f"        - NAME: random_world_flip\n          ALONG_AXIS_LIST: {flip}\n\n"
        + "        - NAME: random_world_rotation\n          WORLD_ROT_ANGLE: [-0.78539816, 0.78539816]\n\n"
        + "        - NAME: random_world_scaling\n          WORLD_SCALE_RANGE: [0.95, 1.05]\n\n"
        + "DATA_PROCESSOR:\n    - NAME: mask_points_and_boxes_outside_range\n      REMOVE_OUTSIDE_BOXES: True\n\n"
        + "    - NAME: shuffle_points\n      SHUFFLE_ENABLED: {'train': True, 'test': False}\n\n"
        + f"    - NAME: transform_points_to_voxels\n      VOXEL_SIZE: {voxel}\n      MAX_POINTS_PER_VOXEL: 5\n      MAX_NUMBER_OF_VOXELS: {voxels}\n"
    )


def openpcdet_model_yaml(stock: str, dataset_yaml: str, model_yaml: str, classes: list[str], anchors: dict, header: str, stride: int = 8,
                         data: str = "") -> str:
    """An OpenPCDet model yaml (at ``model_yaml``, its path from ``tools/``): the stock model ``stock`` with this run's
    classes, dataset yaml and anchors (``{type: (size, bottom, matched, unmatched)}``, in ``classes`` order, on a feature
    map of ``stride``); ``data``: the lines of DATA_CONFIG the stock model sets itself (after the dataset yaml's)."""
    return (
        header
        + f"# Train from OpenPCDet/tools with the output linked in under OpenPCDet/data (docs/formats.md): python train.py --cfg_file {model_yaml}\n"
        + f"_BASE_CONFIG_: {stock}\n\nCLASS_NAMES: {_yaml_list(classes)}\n\nDATA_CONFIG:\n    _BASE_CONFIG_: {dataset_yaml}\n{data}\n"
        + "MODEL:\n  DENSE_HEAD:\n    ANCHOR_GENERATOR_CONFIG:\n"
        + "".join(_anchor_yaml(c, *anchors[c], stride) for c in classes)
    )


def pillar_data_config(point_range: list[float]) -> str:
    """The DATA_CONFIG lines tools/cfgs/kitti_models/pointpillar.yaml sets over kitti_dataset.yaml: its range (a multiple
    of its 0.16 m pillars, here moved as the dataset's) and its pillars."""
    return (f"    POINT_CLOUD_RANGE: {_yaml_list(point_range)}\n    DATA_PROCESSOR:\n"
            "        - NAME: mask_points_and_boxes_outside_range\n          REMOVE_OUTSIDE_BOXES: True\n"
            "        - NAME: shuffle_points\n          SHUFFLE_ENABLED: {'train': True, 'test': False}\n"
            "        - NAME: transform_points_to_voxels\n          VOXEL_SIZE: [0.16, 0.16, 4]\n          MAX_POINTS_PER_VOXEL: 32\n"
            "          MAX_NUMBER_OF_VOXELS: {'train': 16000, 'test': 40000}\n")


def mmdet3d_config(classes: list[str], min_points: dict, point_range: list[float], shift: float, header: str) -> str:
    """mmdetection3d's (fe25f7a) pointpillars 3-class KITTI config with this run's classes, sampler, range and anchors."""
    stock = [c for c in KITTI_CLASSES if c in classes]
    ranges = [[point_range[0], point_range[1], round(ANCHORS[c][1] + shift, 2), point_range[3], point_range[4], round(ANCHORS[c][1] + shift, 2)] for c in stock]
    assigners = "".join(
        f"        dict(type='Max3DIoUAssigner', iou_calculator=dict(type='mmdet3d.BboxOverlapsNearest3D'), pos_iou_thr={ANCHORS[c][2]},\n"
        f"             neg_iou_thr={ANCHORS[c][3]}, min_pos_iou={ANCHORS[c][3]}, ignore_iof_thr=-1),  # {c}\n"
        for c in stock
    )
    points = "dict(type='LoadPointsFromFile', coord_type='LIDAR', load_dim=4, use_dim=4, backend_args=backend_args)"
    return (
        header
        + "# Copy into mmdetection3d/configs/bpy_pipeline/ and train with OUT/kitti linked in as mmdetection3d/data/kitti, after\n"
        + "# python tools/create_data.py kitti --root-path data/kitti --out-dir data/kitti --extra-tag kitti --with-plane\n"
        + "_base_ = ['../pointpillars/pointpillars_hv_secfpn_8xb6-160e_kitti-3d-3class.py']\n\n"
        + f"point_cloud_range = {point_range}\ndata_root = 'data/kitti/'\nclass_names = {stock}\nmetainfo = dict(classes=class_names)\nbackend_args = None\n\n"
        + "db_sampler = dict(\n    data_root=data_root,\n    info_path=data_root + 'kitti_dbinfos_train.pkl',\n    rate=1.0,\n"
        + f"    prepare=dict(filter_by_difficulty=[-1], filter_by_min_points=dict({', '.join(f'{c}={min_points.get(c, MIN_POINTS)}' for c in stock)})),\n"
        + f"    classes=class_names,\n    sample_groups=dict({', '.join(f'{c}=15' for c in stock)}),\n    points_loader={points},\n"
          "    backend_args=backend_args)\n\n"
        + f"train_pipeline = [\n    {points},\n    dict(type='LoadAnnotations3D', with_bbox_3d=True, with_label_3d=True),\n"
        + "    dict(type='ObjectSample', db_sampler=db_sampler, use_ground_plane=True),\n    dict(type='RandomFlip3D', flip_ratio_bev_horizontal=0.5),\n"
        + "    dict(type='GlobalRotScaleTrans', rot_range=[-0.78539816, 0.78539816], scale_ratio_range=[0.95, 1.05]),\n"
        + "    dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range),\n    dict(type='ObjectRangeFilter', point_cloud_range=point_cloud_range),\n"
        + "    dict(type='PointShuffle'),\n    dict(type='Pack3DDetInputs', keys=['points', 'gt_labels_3d', 'gt_bboxes_3d'])]\n"
        + f"test_pipeline = [\n    {points},\n"
        + "    dict(type='MultiScaleFlipAug3D', img_scale=(1333, 800), pts_scale_ratio=1, flip=False, transforms=[\n"
        + "        dict(type='GlobalRotScaleTrans', rot_range=[0, 0], scale_ratio_range=[1., 1.], translation_std=[0, 0, 0]),\n"
        + "        dict(type='RandomFlip3D'), dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range)]),\n"
        + "    dict(type='Pack3DDetInputs', keys=['points'])]\n\n"
        + "train_dataloader = dict(dataset=dict(dataset=dict(pipeline=train_pipeline, metainfo=metainfo)))\n"
        + "val_dataloader = dict(dataset=dict(pipeline=test_pipeline, metainfo=metainfo))\n"
        + "test_dataloader = dict(dataset=dict(pipeline=test_pipeline, metainfo=metainfo))\n\n"
        + "model = dict(\n    data_preprocessor=dict(voxel_layer=dict(point_cloud_range=point_cloud_range)),\n"
        + "    voxel_encoder=dict(point_cloud_range=point_cloud_range),\n"
        + f"    bbox_head=dict(num_classes={len(stock)}, anchor_generator=dict(ranges={ranges},\n"
        + f"                   sizes={[list(ANCHORS[c][0]) for c in stock]})),\n"
        + f"    train_cfg=dict(assigner=[\n{assigners}    ]))\n"
    )


def _remove(paths: list[Path]) -> None:
    for path in paths:
        path.unlink(missing_ok=True)


def write_kitti_configs(out_dir: str | os.PathLike, records: list[dict], config) -> list[Path]:
    """The KITTI layout's OpenPCDet dataset and model yamls and mmdetection3d config (module docstring); none (and none
    left from before) when the train frames hold no sampled object of the stock three classes."""
    root = Path(out_dir) / "kitti"
    files = [root / "openpcdet_kitti_dataset.yaml", root / "openpcdet_pv_rcnn.yaml", root / "openpcdet_pointpillar.yaml",
             root / "mmdet3d_pointpillars_kitti.py"]
    sets = split_indices([r["index"] for r in records], config.output.split, config.frames)
    present = sampled_kitti_types(root / "training", sets.get("train", []))
    classes = [c for c in ("Car", "Pedestrian", "Cyclist") if present.get(c)]
    if not classes:
        _remove(files)
        return []
    maps, names = load_class_maps(), config.output.boxes.names
    min_points = min_points_of(config, lambda name: maps.kitti_name(name, names))
    ground = ground_height(records, config)
    shift, xy = ground - STOCK_KITTI_GROUND, camera_xy(records, config)
    point_range = moved_range(KITTI_RANGE, shift, xy)
    header = HEADER.format(frames=len(records), train=len(sets.get("train", [])))
    comment = (f"# Classes of the train frames' sampled objects: {', '.join(f'{c} {present[c]}' for c in sorted(present))}.\n"
               f"# The ground lies at z = {ground:.2f} m in the points' frame (KITTI: -1.73): z range and anchors moved by {shift:+.2f} m; "
               f"the camera stands at x, y = {xy[0]:.2f}, {xy[1]:.2f} m, where the forward range starts.\n")
    dataset = openpcdet_dataset_yaml("KittiDataset", "../data/kitti", "kitti", classes, min_points, {"Car": 20, "Pedestrian": 15, "Cyclist": 15},
                                     point_range, True, "",
                                     header + comment + "# Pair: openpcdet_pv_rcnn.yaml or openpcdet_pointpillar.yaml beside it "
                                                        "(tools/cfgs/kitti_models/pv_rcnn.yaml, pointpillar.yaml).\n")
    anchors = {c: (ANCHORS[c][0], round(ANCHORS[c][1] + shift, 2), ANCHORS[c][2], ANCHORS[c][3]) for c in classes}
    dataset_yaml = "../data/kitti/openpcdet_kitti_dataset.yaml"
    model = openpcdet_model_yaml("cfgs/kitti_models/pv_rcnn.yaml", dataset_yaml, "../data/kitti/openpcdet_pv_rcnn.yaml", classes, anchors, header + comment)
    pillar_range = moved_range(PILLAR_RANGE, shift, xy)
    pillars = openpcdet_model_yaml("cfgs/kitti_models/pointpillar.yaml", dataset_yaml, "../data/kitti/openpcdet_pointpillar.yaml", classes, anchors,
                                   header + comment, stride=2, data=pillar_data_config(pillar_range))
    mmdet3d = mmdet3d_config(classes, min_points, pillar_range, shift, header + comment)
    return [_write(path, text) for path, text in zip(files, (dataset, model, pillars, mmdet3d))]


def write_custom_configs(out_dir: str | os.PathLike, records: list[dict], config, with_boxes: list[int]) -> list[Path]:
    """The OpenPCDet custom layout's dataset and model yamls (module docstring) for the frames ``with_boxes``."""
    root = Path(out_dir) / "openpcdet"
    files = [root / "custom_dataset.yaml", root / "pv_rcnn.yaml"]
    sets = split_indices(with_boxes, config.output.split, config.frames)
    names = config.output.boxes.names
    maps = load_class_maps()
    sizes: dict[str, list] = {}
    kitti_of: dict[str, str] = {}
    train = set(sets.get("train", []))
    for record in records:
        for box in record.get("boxes") or []:
            kitti_of[label_type(box["class"], names)] = maps.kitti_name(box["class"], names)
    for index in sorted(train):
        path = root / "labels" / f"{index:06d}.txt"
        for line in path.read_text().splitlines() if path.is_file() else []:
            fields = line.split()
            sizes.setdefault(fields[7], []).append([float(v) for v in fields[3:6]])
    classes = [c for c in sorted(sizes) if sizes[c] and kitti_of.get(c, "Misc") in KITTI_EVALUATED]
    if not classes:
        _remove(files)
        return []
    min_points = min_points_of(config, lambda name: label_type(name, names))
    ground = ground_height(records, config)
    shift = ground - STOCK_CUSTOM_GROUND
    header = HEADER.format(frames=len(records), train=len(train))
    comment = (f"# Classes with boxes in the train frames (and a KITTI type the evaluation knows): {', '.join(f'{c} {len(sizes[c])}' for c in classes)}.\n"
               f"# The ground lies at z = {ground:.2f} m in the points' frame (custom models: 0): z range and anchors moved by {shift:+.2f} m.\n")
    mapping = "MAP_CLASS_TO_KITTI: {\n" + "".join(f"    '{c}': '{kitti_of.get(c, 'Misc')}',\n" for c in sorted(kitti_of)) + "}\n"
    dataset = openpcdet_dataset_yaml("CustomDataset", "../data/custom", "custom", classes, min_points, {}, moved_range(CUSTOM_RANGE, shift), False, mapping,
                                     header + comment + "# Pair: pv_rcnn.yaml beside it (tools/cfgs/custom_models/pv_rcnn.yaml).\n")
    anchors = {}
    for c in classes:
        large = kitti_of.get(c) in ("Car", "Van", "Truck")
        anchors[c] = (np.mean(sizes[c], axis=0).round(2).tolist(), round(ground, 2), 0.55 if large else 0.5, 0.4 if large else 0.35)
    model = openpcdet_model_yaml("cfgs/custom_models/pv_rcnn.yaml", "../data/custom/custom_dataset.yaml", "../data/custom/pv_rcnn.yaml", classes, anchors,
                                 header + comment + "# Anchors: the mean size of each class's train boxes, standing on the ground.\n")
    return [_write(path, text) for path, text in zip(files, (dataset, model))]
