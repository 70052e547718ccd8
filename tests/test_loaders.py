"""The datasets as the loaders users train with read them, step by step from their source.

Followed (the search tool's snapshots):
- OpenPCDet 8cacccec11db6f59bf6934600c9a175dae254806: ``pcdet/datasets/kitti/kitti_dataset.py``
  (``set_split``, ``get_infos`` with ``count_inside_pts``, ``get_fov_flag``), ``pcdet/utils/calibration_kitti.py``,
  ``pcdet/utils/object3d_kitti.py``; ``pcdet/datasets/custom/custom_dataset.py`` (``get_label``, ``get_infos``,
  ``create_custom_infos``).
- mmdetection3d fe25f7a51d36e3702f961e198894580d83c4387b: ``tools/dataset_converters/kitti_converter.py``
  (``create_kitti_info_file``, ``_calculate_num_points_in_gt``), ``kitti_data_utils.py`` (``_read_imageset_file``,
  ``get_kitti_image_info``, ``get_label_anno``).
- Pointcept d74c646db6abec569d0f23e0c34e7ddfce142789: ``pointcept/datasets/defaults.py`` (``DefaultDataset.get_data_list``,
  ``get_data``).
- The SemanticKITTI devkit's label remapping (``remap_lut[label & 0xFFFF]`` from ``learning_map``) and its
  ``inv(Tr) @ pose @ Tr`` reading of poses.txt.
Torch, scikit-image and scipy are not needed: ``in_hull`` (a Delaunay test on a box's corners) and
``points_in_rbbox`` are replaced by the equivalent point-in-oriented-box test; images are read with Pillow.

The dataset: 6 parking frames (seed 1, few cars) where frame 2 has no car, split by scene with the split's
seed 5: val frame 0, test frame 3, train the rest (the empty frame in train).

SemanticKITTI's stock loaders, followed at the same commits: Pointcept's ``pointcept/datasets/semantic_kitti.py``
(``SemanticKITTIDataset.get_data_list``, ``get_data``, ``get_learning_map``), mmdetection3d's
``configs/_base_/datasets/semantickitti.py`` (``labels_map``, ``max_label``, ann files), ``mmdet3d/datasets/
seg3d_dataset.py`` (``get_seg_label_mapping``: ids missing from the map become 0), ``transforms/loading.py``
(``LoadAnnotations3D``: ``mask % seg_offset``), ``tools/dataset_converters/update_infos_to_v2.py``
(``update_kitti_infos``) and ``tools/create_data.py``; the devkit (semantic-kitti-api a9c749e,
``config/semantic-kitti.yaml``, ``evaluate_semantics.py``: the sequences of ``split[valid]``).
SUSTechPOINTS 566f81d: ``public/js/obj_cfg.js`` (its class list), ``public/js/lidar.js`` (intensity / 255).
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
EMPTY = 2  # the frame without a box
FRAMES = 6
SPLIT = {"train": [1, 2, 4, 5], "val": [0], "test": [3]}  # output.split.seed 5 over six scenes (io/splits.py)
# SemanticKITTI's learning map as the stock loaders hard-code it (devkit ids; Pointcept: the devkit's training
# id - 1 with ignore_index -1; mmdetection3d's labels_map: the same with 19 for ignored)
DEVKIT_LEARNING_MAP = {0: 0, 1: 0, 10: 1, 11: 2, 13: 5, 15: 3, 16: 5, 18: 4, 20: 5, 30: 6, 31: 7, 32: 8, 40: 9, 44: 10, 48: 11, 49: 12, 50: 13,
                       51: 14, 52: 0, 60: 9, 70: 15, 71: 16, 72: 17, 80: 18, 81: 19, 99: 0, 252: 1, 253: 7, 254: 6, 255: 8, 256: 5, 257: 5, 258: 4, 259: 5}
POINTCEPT_LEARNING_MAP = {raw: train - 1 for raw, train in DEVKIT_LEARNING_MAP.items()}
MMDET3D_LABELS_MAP = {raw: train - 1 if train else 19 for raw, train in DEVKIT_LEARNING_MAP.items()}
SK_CLASSES = ["car", "bicycle", "motorcycle", "truck", "other-vehicle", "person", "bicyclist", "motorcyclist", "road", "parking", "sidewalk",
              "other-ground", "building", "fence", "vegetation", "trunk", "terrain", "pole", "traffic-sign"]  # Pointcept's training ids 0..18
SUSTECH_CLASS_LIST = {"Car", "Pedestrian", "Van", "Bus", "Truck", "ScooterRider", "Scooter", "BicycleRider", "Bicycle", "Motorcycle", "MotorcyleRider",
                      "PoliceCar", "TourCar", "RoadWorker", "Child", "BabyCart", "Cart", "Cone", "FireHydrant", "SaftyTriangle", "PlatformCart",
                      "ConstructionCart", "RoadBarrel", "TrafficBarrier", "LongVehicle", "BicycleGroup", "ConcreteTruck", "Tram", "Excavator",
                      "Animal", "TrashCan", "ForkLift", "Trimotorcycle", "FreightTricycle", "Crane", "RoadRoller", "Bulldozer", "DontCare",
                      "Misc", "Unknown", "Unknown1", "Unknown2", "Unknown3", "Unknown4", "Unknown5"}  # obj_cfg.js obj_type_map


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    pytest.importorskip("bpy", reason="the dataset is made by a real parking run")
    out = tmp_path_factory.mktemp("loaders") / "out"
    command = [sys.executable, str(ROOT / "run.py"), "--out", str(out), "--frames", str(FRAMES), "--seed", "1", "--set", "scene.builder=parking",
               "--set", "scene.cars={kind: normal, mean: 1, std: 2, min: 0, max: 6}", "--set", "output.formats=[ply,semantickitti,npy,pcd]",
               "--set", "output.boxes.formats=[kitti,openpcdet,sustech]", "--set", "output.split.seed=5"]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    records = [json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))]
    assert [len(r["boxes"]) == 0 for r in records] == [i == EMPTY for i in range(FRAMES)], "the run no longer has exactly frame 2 empty"
    return out


def image_shape(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as image:
        return np.array(np.asarray(image).shape[:2], dtype=np.int32)


def in_box(points: np.ndarray, box: np.ndarray) -> np.ndarray:
    """OpenPCDet's ``in_hull(points, boxes_to_corners_3d(box))`` for a box ``[x, y, z, dx, dy, dz, heading]`` (centre)."""
    c, s = np.cos(box[6]), np.sin(box[6])
    local = points[:, :3] - box[:3]
    x, y = c * local[:, 0] + s * local[:, 1], -s * local[:, 0] + c * local[:, 1]
    return (np.abs(x) <= box[3] / 2) & (np.abs(y) <= box[4] / 2) & (np.abs(local[:, 2]) <= box[5] / 2)


# ----------------------------------------------------------------------------- OpenPCDet, KITTI
class Calibration:
    """pcdet/utils/calibration_kitti.py: get_calib_from_file and the transforms get_infos uses."""

    def __init__(self, calib_file):
        lines = open(calib_file).readlines()
        self.P2 = np.array(lines[2].strip().split(" ")[1:], dtype=np.float32).reshape(3, 4)
        self.R0 = np.array(lines[4].strip().split(" ")[1:], dtype=np.float32).reshape(3, 3)
        self.V2C = np.array(lines[5].strip().split(" ")[1:], dtype=np.float32).reshape(3, 4)

    @staticmethod
    def cart_to_hom(pts):
        return np.hstack((pts, np.ones((pts.shape[0], 1), dtype=np.float32)))

    def rect_to_lidar(self, pts_rect):
        R0_ext = np.vstack((np.hstack((self.R0, np.zeros((3, 1), dtype=np.float32))), np.zeros((1, 4), dtype=np.float32)))
        R0_ext[3, 3] = 1
        V2C_ext = np.vstack((self.V2C, np.zeros((1, 4), dtype=np.float32)))
        V2C_ext[3, 3] = 1
        return np.dot(self.cart_to_hom(pts_rect), np.linalg.inv(np.dot(R0_ext, V2C_ext).T))[:, 0:3]

    def lidar_to_rect(self, pts_lidar):
        return np.dot(self.cart_to_hom(pts_lidar), np.dot(self.V2C.T, self.R0.T))

    def rect_to_img(self, pts_rect):
        pts_2d_hom = np.dot(self.cart_to_hom(pts_rect), self.P2.T)
        pts_img = (pts_2d_hom[:, 0:2].T / self.cart_to_hom(pts_rect)[:, 2]).T
        return pts_img, pts_2d_hom[:, 3 - 1] - self.P2.T[3, 2]


class Object3d:
    """pcdet/utils/object3d_kitti.py."""

    def __init__(self, line):
        label = line.strip().split(" ")
        self.cls_type = label[0]
        self.truncation, self.occlusion, self.alpha = float(label[1]), float(label[2]), float(label[3])
        self.box2d = np.array([float(v) for v in label[4:8]], dtype=np.float32)
        self.h, self.w, self.l = (float(v) for v in label[8:11])
        self.loc = np.array([float(v) for v in label[11:14]], dtype=np.float32)
        self.ry = float(label[14])
        self.score = float(label[15]) if len(label) == 16 else -1.0
        height = float(self.box2d[3]) - float(self.box2d[1]) + 1
        self.level = (
            0
            if height >= 40 and self.truncation <= 0.15 and self.occlusion <= 0
            else 1
            if height >= 25 and self.truncation <= 0.3 and self.occlusion <= 1
            else 2
            if height >= 25 and self.truncation <= 0.5 and self.occlusion <= 2
            else -1
        )


def openpcdet_kitti_infos(root: Path, split: str, has_label: bool = True) -> list[dict]:
    """KittiDataset.set_split + get_infos(has_label, count_inside_pts=has_label), as create_kitti_infos calls it
    (``has_label=False`` for test). A missing ImageSets file leaves ``sample_id_list`` None, and
    ``executor.map(process_single_scene, None)`` raises TypeError."""
    root_split_path = root / ("training" if split != "test" else "testing")
    split_dir = root / "ImageSets" / (split + ".txt")
    sample_id_list = [x.strip() for x in open(split_dir).readlines()] if split_dir.exists() else None
    infos = []
    for sample_idx in iter(sample_id_list):
        info = {"point_cloud": {"num_features": 4, "lidar_idx": sample_idx}}
        img_file = root_split_path / "image_2" / ("%s.png" % sample_idx)
        assert img_file.exists()
        info["image"] = {"image_idx": sample_idx, "image_shape": image_shape(img_file)}
        calib = Calibration(root_split_path / "calib" / ("%s.txt" % sample_idx))
        assert (root_split_path / "velodyne" / ("%s.bin" % sample_idx)).exists()
        if not has_label:
            infos.append(info)
            continue
        label_file = root_split_path / "label_2" / ("%s.txt" % sample_idx)
        assert label_file.exists()
        obj_list = [Object3d(line) for line in open(label_file).readlines()]
        annotations = {
            "name": np.array([obj.cls_type for obj in obj_list]),
            "truncated": np.array([obj.truncation for obj in obj_list]),
            "occluded": np.array([obj.occlusion for obj in obj_list]),
            "bbox": np.concatenate([obj.box2d.reshape(1, 4) for obj in obj_list], axis=0),
            "dimensions": np.array([[obj.l, obj.h, obj.w] for obj in obj_list]),
            "location": np.concatenate([obj.loc.reshape(1, 3) for obj in obj_list], axis=0),
            "rotation_y": np.array([obj.ry for obj in obj_list]),
            "difficulty": np.array([obj.level for obj in obj_list], np.int32),
        }
        num_objects = len([obj.cls_type for obj in obj_list if obj.cls_type != "DontCare"])
        num_gt = len(annotations["name"])
        loc, dims, rots = annotations["location"][:num_objects], annotations["dimensions"][:num_objects], annotations["rotation_y"][:num_objects]
        loc_lidar = calib.rect_to_lidar(loc)
        l, h, w = dims[:, 0:1], dims[:, 1:2], dims[:, 2:3]
        loc_lidar[:, 2] += h[:, 0] / 2
        gt_boxes_lidar = np.concatenate([loc_lidar, l, w, h, -(np.pi / 2 + rots[..., np.newaxis])], axis=1)
        annotations["gt_boxes_lidar"] = gt_boxes_lidar
        points = np.fromfile(str(root_split_path / "velodyne" / ("%s.bin" % sample_idx)), dtype=np.float32).reshape(-1, 4)
        pts_rect = calib.lidar_to_rect(points[:, 0:3])
        pts_img, pts_rect_depth = calib.rect_to_img(pts_rect)
        shape = info["image"]["image_shape"]
        fov_flag = (pts_img[:, 0] >= 0) & (pts_img[:, 0] < shape[1]) & (pts_img[:, 1] >= 0) & (pts_img[:, 1] < shape[0]) & (pts_rect_depth >= 0)
        pts_fov = points[fov_flag]
        num_points_in_gt = -np.ones(num_gt, dtype=np.int32)
        for k in range(num_objects):
            num_points_in_gt[k] = in_box(pts_fov[:, :3], gt_boxes_lidar[k]).sum()
        annotations["num_points_in_gt"] = num_points_in_gt
        info["annos"] = annotations
        infos.append(info)
    return infos


def sustech_boxes(out: Path, index: int) -> dict[str, np.ndarray]:
    objects = json.loads((out / "sustech" / "label" / f"{index:06d}.json").read_text())
    return {o["obj_id"]: np.array([*(o["psr"]["position"][a] for a in "xyz"), *(o["psr"]["scale"][a] for a in "xyz"),
                                   o["psr"]["rotation"]["z"]]) for o in objects}


def test_openpcdet_kitti_get_infos(dataset):
    root = dataset / "kitti"
    train, val = openpcdet_kitti_infos(root, "train"), openpcdet_kitti_infos(root, "val")
    test = openpcdet_kitti_infos(root, "test", has_label=False)  # from kitti/testing
    assert {name: sorted(int(i["point_cloud"]["lidar_idx"]) for i in infos) for name, infos in (("train", train), ("val", val), ("test", test))} == SPLIT
    seen = 0
    for info in train + val:
        annos, index = info["annos"], int(info["point_cloud"]["lidar_idx"])
        assert tuple(info["image"]["image_shape"]) == (375, 1242)
        if index == EMPTY:
            assert annos["name"].tolist() == ["DontCare"] and annos["gt_boxes_lidar"].shape == (0, 7)
            continue
        truth = np.array(list(sustech_boxes(dataset, index).values()))
        for box, count in zip(annos["gt_boxes_lidar"], annos["num_points_in_gt"]):
            assert count > 0, "a labelled object holds no point of the camera's field of view"
            match = np.abs(truth[:, :3] - box[:3]).sum(axis=1).argmin()  # the same box as the SUSTechPOINTS label
            np.testing.assert_allclose(box[:6], truth[match, :6], atol=2e-3)
            assert abs((box[6] - truth[match, 6] + np.pi) % (2 * np.pi) - np.pi) < 1e-3
            seen += 1
        # DontCare: no box in the image
        assert set(annos["name"]) <= {"Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc", "DontCare"}
        assert (annos["bbox"][:, 2] > annos["bbox"][:, 0]).all() and (annos["bbox"][:, 3] - annos["bbox"][:, 1] > 0).all()
    assert seen >= 2


# ----------------------------------------------------------------------------- mmdetection3d, KITTI
def _extend_matrix(mat):
    return np.concatenate([mat, np.array([[0.0, 0.0, 0.0, 1.0]])], axis=0)


def mmdet3d_kitti_infos(data_path: Path, image_ids: list[int], training: bool = True) -> list[dict]:
    """get_kitti_image_info(training, label_info=training, velodyne=True, calib=True) + _calculate_num_points_in_gt (remove_outside)."""
    infos = []
    folder = "training" if training else "testing"
    for idx in image_ids:
        velodyne_path = data_path / folder / "velodyne" / f"{idx:06d}.bin"
        image_path = data_path / folder / "image_2" / f"{idx:06d}.png"
        assert velodyne_path.exists() and image_path.exists()  # exist_check=True raises ValueError otherwise
        lines = open(data_path / folder / "calib" / f"{idx:06d}.txt").readlines()
        P2 = _extend_matrix(np.array([float(v) for v in lines[2].split(" ")[1:13]]).reshape([3, 4]))
        rect = np.zeros([4, 4])
        rect[3, 3] = 1.0
        rect[:3, :3] = np.array([float(v) for v in lines[4].split(" ")[1:10]]).reshape([3, 3])
        Trv2c = _extend_matrix(np.array([float(v) for v in lines[5].split(" ")[1:13]]).reshape([3, 4]))
        _extend_matrix(np.array([float(v) for v in lines[6].split(" ")[1:13]]).reshape([3, 4]))  # Tr_imu_to_velo must parse
        if not training:
            infos.append({"image": {"image_idx": idx, "image_shape": image_shape(image_path)}})
            continue
        content = [line.strip().split(" ") for line in open(data_path / "training" / "label_2" / f"{idx:06d}.txt").readlines()]
        num_objects = len([x[0] for x in content if x[0] != "DontCare"])
        annos = {
            "name": np.array([x[0] for x in content]),
            "occluded": np.array([int(x[2]) for x in content]),
            "bbox": np.array([[float(v) for v in x[4:8]] for x in content]).reshape(-1, 4),
            "dimensions": np.array([[float(v) for v in x[8:11]] for x in content]).reshape(-1, 3)[:, [2, 0, 1]],
            "location": np.array([[float(v) for v in x[11:14]] for x in content]).reshape(-1, 3),
            "rotation_y": np.array([float(x[14]) for x in content]).reshape(-1),
        }
        shape = image_shape(image_path)
        points_v = np.fromfile(velodyne_path, dtype=np.float32, count=-1).reshape([-1, 4])
        # box_np_ops.remove_outside_points: keep the points whose projection lies in the image, in front
        cam = np.c_[points_v[:, :3], np.ones(len(points_v))] @ (rect @ Trv2c).T
        img = cam @ P2.T
        uv = img[:, :2] / img[:, 2:3]
        points_v = points_v[(img[:, 2] > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < shape[1]) & (uv[:, 1] >= 0) & (uv[:, 1] < shape[0])]
        dims, loc, rots = annos["dimensions"][:num_objects], annos["location"][:num_objects], annos["rotation_y"][:num_objects]
        gt_boxes_camera = np.concatenate([loc, dims, rots[..., np.newaxis]], axis=1)
        # box_np_ops.box_camera_to_lidar: xyz to lidar, (l, h, w) -> (l, w, h), r -> -r - pi/2; origin (0.5, 0.5, 0)
        xyz_lidar = (np.c_[gt_boxes_camera[:, :3], np.ones(len(gt_boxes_camera))] @ np.linalg.inv((rect @ Trv2c).T))[:, :3]
        lidar = np.concatenate([xyz_lidar, gt_boxes_camera[:, 3:4], gt_boxes_camera[:, 5:6], gt_boxes_camera[:, 4:5], -gt_boxes_camera[:, 6:7] - np.pi / 2],
                               axis=1)
        centred = lidar.copy()
        centred[:, 2] += lidar[:, 5] / 2
        num_points_in_gt = np.array([in_box(points_v[:, :3], box).sum() for box in centred], dtype=np.int64)
        annos["num_points_in_gt"] = np.concatenate([num_points_in_gt, -np.ones([len(annos["dimensions"]) - num_objects])]).astype(np.int32)
        infos.append({"image": {"image_idx": idx, "image_shape": shape}, "annos": annos, "gt_boxes_lidar": centred})
    return infos


def mmdet3d_update_kitti_infos(data_list: list[dict]) -> list[dict]:
    """update_infos_to_v2.update_kitti_infos's control flow: ``ignore_class_name`` is bound inside the loop and
    printed after it, so an empty info list (an empty ImageSets file) raises UnboundLocalError."""
    converted_list = []
    for ori_info_dict in data_list:
        ignore_class_name = set()
        for name in ori_info_dict.get("annos", {}).get("name", []):
            if name not in ("Pedestrian", "Cyclist", "Car", "Van", "Truck", "Person_sitting", "Tram", "Misc"):
                ignore_class_name.add(name)
        converted_list.append(ori_info_dict)
    print(f"ignore classes: {ignore_class_name}")
    return converted_list


def test_mmdet3d_kitti_converter(dataset):
    folder = dataset / "kitti" / "ImageSets"
    ids = {name: [int(line) for line in open(folder / f"{name}.txt").readlines()] for name in ("train", "val", "test")}  # _read_imageset_file: all three
    assert ids == SPLIT
    for name in ("train", "val", "test"):  # create_data.py kitti: update_pkl_infos on each info file
        mmdet3d_update_kitti_infos(mmdet3d_kitti_infos(dataset / "kitti", ids[name], training=name != "test"))
    with pytest.raises(UnboundLocalError):  # why an empty split gets no ImageSets file
        mmdet3d_update_kitti_infos([])
    infos = mmdet3d_kitti_infos(dataset / "kitti", ids["train"] + ids["val"])
    for info in infos:
        annos = info["annos"]
        if annos["name"].tolist() == ["DontCare"]:  # frame 2, or a frame whose boxes are all outside the image
            assert annos["num_points_in_gt"].tolist() == [-1]
            continue
        assert (annos["num_points_in_gt"] > 0).all()
        assert (annos["bbox"][:, 3] - annos["bbox"][:, 1] >= 1).all()  # real 2D boxes, not zeros


# ----------------------------------------------------------------------------- OpenPCDet, custom
def openpcdet_custom_infos(root: Path, split: str) -> list[dict]:
    """CustomDataset.set_split + get_infos(has_label=True) as create_custom_infos calls it."""
    split_dir = root / "ImageSets" / (split + ".txt")
    sample_id_list = [x.strip() for x in open(split_dir).readlines()] if split_dir.exists() else None
    infos = []
    for sample_idx in sample_id_list:
        lines = open(root / "labels" / ("%s.txt" % sample_idx)).readlines()
        gt_boxes, gt_names = [], []
        for line in lines:
            line_list = line.strip().split(" ")
            gt_boxes.append(line_list[:-1])
            gt_names.append(line_list[-1])
        gt_boxes_lidar = np.array(gt_boxes, dtype=np.float32)
        points = np.load(root / "points" / ("%s.npy" % sample_idx))
        infos.append({"point_cloud": {"num_features": 4, "lidar_idx": sample_idx},
                      "annos": {"name": np.array(gt_names), "gt_boxes_lidar": gt_boxes_lidar[:, :7]}, "points": points})
    return infos


def test_openpcdet_custom_create_infos(dataset):
    root = dataset / "openpcdet"
    train, val = openpcdet_custom_infos(root, "train"), openpcdet_custom_infos(root, "val")
    # the empty frame is written but not listed
    assert [int(i["point_cloud"]["lidar_idx"]) for i in train] == [1, 4, 5] and [int(i["point_cloud"]["lidar_idx"]) for i in val] == [0]
    assert (root / "ImageSets" / "test.txt").read_text() == "000003\n"
    assert (root / "labels" / f"{EMPTY:06d}.txt").read_text() == ""
    with pytest.raises(IndexError):  # why: get_infos slices [:, :7], which an empty label file cannot give
        np.array([], dtype=np.float32)[:, :7]
    for info in train + val:
        boxes, points = info["annos"]["gt_boxes_lidar"], info["points"]
        assert points.dtype == np.float32 and points.shape[1] == 4
        assert set(info["annos"]["name"]) == {"Car"}
        for box in boxes:  # create_groundtruth_database's points_in_boxes
            assert in_box(points, box).sum() >= 12


# ----------------------------------------------------------------------------- Pointcept
def test_pointcept_default_dataset_get_data(dataset):
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.io.class_maps import load_class_maps
    from bpy_pipeline.labels import load_class_table

    valid_assets = ["coord", "color", "normal", "strength", "segment", "instance", "pose"]
    data_root = str(dataset)
    data_list = []
    for split in ["npy_train.json", "npy_val.json", "npy_test.json"]:  # DefaultDataset.get_data_list with split files
        assert os.path.isfile(os.path.join(data_root, split))
        with open(os.path.join(data_root, split)) as f:
            names = [os.path.join(data_root, data) for data in json.load(f)]
        assert [int(os.path.basename(p)) for p in names] == SPLIT[split[4:-5]]
        data_list += names
    table = load_class_table()
    classes = max(table.learning_map.values())
    for data_path in data_list:
        data_dict = {}
        for asset in os.listdir(data_path):
            if asset.endswith(".npy") and asset[:-4] in valid_assets:
                data_dict[asset[:-4]] = np.load(os.path.join(data_path, asset))
        data_dict["coord"] = data_dict["coord"].astype(np.float32)
        data_dict["segment"] = data_dict["segment"].reshape([-1]).astype(np.int32)
        data_dict["instance"] = data_dict["instance"].reshape([-1]).astype(np.int32)
        index = int(os.path.basename(data_path))
        raw = read_ply(dataset / "ply" / f"{index:06d}.ply")  # the project's raw ids
        np.testing.assert_array_equal(data_dict["coord"], np.stack([raw["x"], raw["y"], raw["z"]], axis=1))
        expected = np.array([table.learning_map[int(s)] for s in raw["semantic"]]) - 1
        np.testing.assert_array_equal(data_dict["segment"], expected)
        assert data_dict["segment"].min() >= -1 and data_dict["segment"].max() < classes
        car = table.id_of("car")
        cars = raw["semantic"] == car
        np.testing.assert_array_equal(data_dict["instance"][cars], raw["instance"][cars])
        stuff = ~load_class_maps().things[raw["semantic"]]
        assert stuff.any() and (data_dict["instance"][stuff] == -1).all()  # floor, walls, ceiling: no instances
        if index == EMPTY:
            assert not cars.any()


def test_openpcdet_create_kitti_infos_needs_every_imageset(dataset, tmp_path):
    """A split without frames gets no ImageSets file; OpenPCDet's create_kitti_infos then stops at that split (set_split
    leaves None), as mmdetection3d's converter does at an empty one: both need frames in train, val and test."""
    import shutil

    root = tmp_path / "kitti"
    shutil.copytree(dataset / "kitti", root)
    (root / "ImageSets" / "test.txt").unlink()
    with pytest.raises(TypeError):
        openpcdet_kitti_infos(root, "test", has_label=False)


# ----------------------------------------------------------------------------- SemanticKITTI
def pointcept_semantic_kitti(data_root: Path, split: str) -> list[tuple[str, np.ndarray]]:
    """Pointcept's SemanticKITTIDataset(split).get_data_list + get_data: ``[(name, segment)]``."""
    split2seq = dict(train=[0, 1, 2, 3, 4, 5, 6, 7, 9, 10], val=[8], test=[11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21])
    data_list = []
    for seq in split2seq[split]:
        seq = str(seq).zfill(2)
        seq_folder = os.path.join(data_root, "dataset", "sequences", seq)
        seq_files = sorted(os.listdir(os.path.join(seq_folder, "velodyne")))
        data_list += [os.path.join(seq_folder, "velodyne", file) for file in seq_files]
    out = []
    for data_path in data_list:
        scan = np.fromfile(data_path, dtype=np.float32).reshape(-1, 4)
        label_file = data_path.replace("velodyne", "labels").replace(".bin", ".label")
        segment = np.fromfile(label_file, dtype=np.int32).reshape(-1)
        segment = np.vectorize(POINTCEPT_LEARNING_MAP.__getitem__)(segment & 0xFFFF).astype(np.int32)  # KeyError on an unknown id
        assert len(segment) == len(scan)
        out.append((f"{os.path.basename(os.path.dirname(os.path.dirname(data_path)))}_{os.path.splitext(os.path.basename(data_path))[0]}", segment))
    return out


def test_pointcept_semantic_kitti_dataset(dataset, tmp_path):
    from bpy_pipeline.io import read_ply

    data_root = tmp_path / "semantic_kitti"
    data_root.mkdir()
    (data_root / "dataset").symlink_to(dataset)  # the stock config's data_root holds dataset/sequences
    table = yaml.safe_load((dataset / "semantic-kitti.yaml").read_text())["project_classes"]
    expected = {"car": "car", "person": "person", "wall": "building", "pillar": "building", "floor": "other-ground", "ramp": "other-ground"}
    for split, frames in SPLIT.items():
        loaded = pointcept_semantic_kitti(data_root, split)
        assert sorted(int(name.split("_")[1]) for name, _ in loaded) == frames
        for name, segment in loaded:
            points = read_ply(dataset / "ply" / f"{name.split('_')[1]}.ply")
            from bpy_pipeline.labels import load_class_table

            names = load_class_table().names
            for project, stock in expected.items():
                mine = np.array([names[int(s)] == project for s in points["semantic"]])
                if mine.any():
                    assert (segment[mine] == SK_CLASSES.index(stock)).all(), (project, table[project])
            assert set(np.unique(segment)) <= set(range(-1, 19))


def test_mmdet3d_semantic_kitti_dataset(dataset):
    import pickle

    seg_label_mapping = np.zeros(259 + 1, dtype=np.int64)  # SemanticKittiDataset.get_seg_label_mapping
    for idx in MMDET3D_LABELS_MAP:
        seg_label_mapping[idx] = MMDET3D_LABELS_MAP[idx]
    for split, frames in SPLIT.items():
        infos = pickle.loads((dataset / f"semantickitti_infos_{split}.pkl").read_bytes())  # mmengine.load
        assert infos["metainfo"] == {"DATASET": "SemanticKITTI"}
        assert sorted(int(Path(i["lidar_points"]["lidar_path"]).stem) for i in infos["data_list"]) == frames
        for info in infos["data_list"]:
            points = np.fromfile(dataset / info["lidar_points"]["lidar_path"], dtype=np.float32).reshape(-1, info["lidar_points"]["num_pts_feats"])
            mask = np.fromfile(dataset / info["pts_semantic_mask_path"], dtype=np.int32).astype(np.int64) % 2**16  # LoadAnnotations3D
            assert len(mask) == len(points)
            assert set(np.unique(mask)) <= set(MMDET3D_LABELS_MAP), "an id mmdetection3d would silently read as car"
            mapped = seg_label_mapping[mask]  # PointSegClassMapping
            assert mapped.min() >= 0 and mapped.max() <= 19


def test_semantickitti_devkit_files(dataset):
    config = yaml.safe_load((dataset / "semantic-kitti.yaml").read_text())

    assert set(config) >= {"labels", "color_map", "content", "learning_map", "learning_map_inv", "learning_ignore", "split"}
    assert config["learning_map"] == DEVKIT_LEARNING_MAP and config["color_map"][10] == [245, 150, 100]  # the devkit's own (BGR)
    assert config["split"] == {"train": [0, 1, 2, 3], "valid": [8], "test": [11]}  # train frames 1, 2, 4, 5 round robin over 00-07, 09, 10
    for split, numbers in config["split"].items():  # evaluate_semantics.py reads the labels of split[valid] (and the others)
        for number in numbers:
            assert any((dataset / "sequences" / f"{number:02d}" / "labels").glob("*.label")), (split, number)
    assert abs(sum(config["content"].values()) - 1.0) < 1e-9
    maxkey = max(config["learning_map"])
    remap_lut = np.zeros(maxkey + 100, dtype=np.int32)  # the devkit's remapping
    remap_lut[list(config["learning_map"])] = list(config["learning_map"].values())
    records = {json.loads(p.read_text())["index"]: json.loads(p.read_text()) for p in sorted((dataset / "records").glob("*.json"))}
    for number in sum(config["split"].values(), []):
        folder = dataset / "sequences" / f"{number:02d}"
        scans = sorted((folder / "velodyne").glob("*.bin"))
        for scan in scans:
            label = np.fromfile(folder / "labels" / (scan.stem + ".label"), dtype=np.uint32)
            assert set(np.unique(label & 0xFFFF)) <= set(config["learning_map"])
            sem = remap_lut[label & 0xFFFF]
            assert sem.max() <= max(config["learning_map_inv"]) and config["learning_ignore"][0] is True
        poses = np.loadtxt(folder / "poses.txt").reshape(-1, 3, 4)
        times = np.atleast_1d(np.loadtxt(folder / "times.txt"))
        assert len(poses) == len(times) == len(scans)
        calib = {line.split(":")[0]: np.array(line.split(":")[1].split(), float) for line in (folder / "calib.txt").read_text().splitlines()}
        tr = np.vstack([calib["Tr"].reshape(3, 4), [0, 0, 0, 1]])
        first = np.linalg.inv(np.array(records[int(scans[0].stem)]["sensor_pose"]))
        for pose, scan in zip(poses, scans):
            velo = np.linalg.inv(tr) @ np.vstack([pose, [0, 0, 0, 1]]) @ tr  # the devkit's reading
            np.testing.assert_allclose(velo, first @ np.array(records[int(scan.stem)]["sensor_pose"]), atol=1e-9)


# ----------------------------------------------------------------------------- SUSTechPOINTS and PCD
def test_sustech_labels_and_pcd_clouds(dataset):
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.io.pcd import read_pcd

    types = set()
    for index in range(FRAMES):
        objects = json.loads((dataset / "sustech" / "label" / f"{index:06d}.json").read_text())
        assert (objects == []) == (index == EMPTY)
        for o in objects:
            assert set(o) == {"obj_id", "obj_type", "psr"} and set(o["psr"]) == {"position", "rotation", "scale"}
            types.add(o["obj_type"])
        points = read_ply(dataset / "ply" / f"{index:06d}.ply")
        sustech = read_pcd(dataset / "sustech" / "lidar" / f"{index:06d}.pcd")
        np.testing.assert_array_equal(sustech["intensity"], points["intensity"] * np.float32(255))  # lidar.js: intensity / 255
        assert sustech["intensity"].max() > 1.0
        for name in ("x", "y", "z", "semantic", "instance"):
            np.testing.assert_array_equal(sustech[name], points[name])
        assert read_pcd(dataset / "pcd" / f"{index:06d}.pcd").tobytes() == points.tobytes()
    assert types and types <= SUSTECH_CLASS_LIST, types - SUSTECH_CLASS_LIST
    o3d = pytest.importorskip("open3d", exc_type=ImportError, reason="Open3D reads the PCD as a viewer would (pip install open3d; Debian needs libusb-1.0-0)")
    cloud = o3d.t.io.read_point_cloud(str(dataset / "pcd" / "000000.pcd"))
    points = read_ply(dataset / "ply" / "000000.ply")
    for name in ("intensity", "semantic", "instance", "ring", "time", "range", "bounces"):
        np.testing.assert_array_equal(cloud.point[name].numpy().ravel(), points[name], err_msg=name)


# ----------------------------------------------------------------------------- training: the samplers, the ranges, __getitem__
# Followed (OpenPCDet 8caccce): kitti_dataset.py (get_road_plane, __getitem__, create_groundtruth_database), dataset.py
# (prepare_data: the sampler, keep_arrays_by_name, the data processor, the retry on a training item without a box),
# augmentor/database_sampler.py (__init__, filter_by_difficulty, filter_by_min_points, __call__: np.stack of the sampled,
# put_boxes_on_road_planes), processor/data_processor.py (mask_points_and_boxes_outside_range, transform_points_to_voxels),
# utils/common_utils.py (mask_points_by_range: x and y only), utils/box_utils.py (mask_boxes_outside_range_numpy: box
# centres, USE_CENTER_TO_FILTER); custom/custom_dataset.py (__getitem__, create_groundtruth_database).
# mmdetection3d (fe25f7a): datasets/transforms/dbsampler.py (filter_by_min_points indexes db_infos[name]),
# transforms_3d.py (PointsRangeFilter: x, y and z; ObjectRangeFilter: bird's eye view), datasets/kitti_dataset.py (plane).
# Left out: the samplers' collision test between sampled boxes (boxes_bev_iou_cpu) and the flips, rotations and scalings,
# which move no item's boxes out of a range they fitted before. The stock values below are the configs' own.
# tools/cfgs/dataset_configs/kitti_dataset.yaml
STOCK_KITTI = {"classes": ["Car", "Pedestrian", "Cyclist"], "range": [0, -40, -3, 70.4, 40, 1], "voxel": [0.05, 0.05, 0.1], "fov": True,
               "sampler": {"USE_ROAD_PLANE": True, "PREPARE": {"filter_by_min_points": ["Car:5", "Pedestrian:5", "Cyclist:5"], "filter_by_difficulty": [-1]},
                           "SAMPLE_GROUPS": ["Car:20", "Pedestrian:15", "Cyclist:15"], "LIMIT_WHOLE_SCENE": True}}
STOCK_CUSTOM = {"classes": ["Vehicle", "Pedestrian", "Cyclist"], "range": [-75.2, -75.2, -2, 75.2, 75.2, 4], "voxel": [0.1, 0.1, 0.15], "fov": False,
                "sampler": {"USE_ROAD_PLANE": False, "PREPARE": {"filter_by_min_points": ["Vehicle:5", "Pedestrian:5", "Cyclist:5"]},
                            "SAMPLE_GROUPS": ["Vehicle:20", "Pedestrian:15", "Cyclist:15"], "LIMIT_WHOLE_SCENE": True}}  # custom_dataset.yaml
MAX_RETRIES = 200  # __getitem__ calls itself for another random item: a dataset of empty items ends in RecursionError


def written_openpcdet(dataset_yaml: Path, model_yaml: Path) -> dict:
    """The dataset and model yamls the run wrote, as the replica's config (CLASS_NAMES from the model yaml; its
    DATA_CONFIG keys over the dataset yaml's, as pcdet/config.py's merge_new_config puts them)."""
    data, model = yaml.safe_load(dataset_yaml.read_text()), yaml.safe_load(model_yaml.read_text())
    data = {**data, **{k: v for k, v in model["DATA_CONFIG"].items() if k != "_BASE_CONFIG_"}}
    sampler = data["DATA_AUGMENTOR"]["AUG_CONFIG_LIST"][0]
    assert sampler["NAME"] == "gt_sampling" and model["DATA_CONFIG"]["_BASE_CONFIG_"].endswith(dataset_yaml.name)
    voxel = [p for p in data["DATA_PROCESSOR"] if p["NAME"] == "transform_points_to_voxels"][0]["VOXEL_SIZE"]
    anchors = model["MODEL"]["DENSE_HEAD"]["ANCHOR_GENERATOR_CONFIG"]
    assert [a["class_name"] for a in anchors] == model["CLASS_NAMES"]  # AxisAlignedTargetAssigner: one anchor set per class
    return {"classes": model["CLASS_NAMES"], "range": data["POINT_CLOUD_RANGE"], "voxel": voxel, "fov": data.get("FOV_POINTS_ONLY", False), "sampler": sampler,
            "anchors": {a["class_name"]: a["anchor_bottom_heights"][0] for a in anchors}}


def road_plane(root_split: Path, sample_idx: str):
    """KittiDataset.get_road_plane: the fourth line, normal turned up (b < 0 in the camera frame), unit length; None without a file."""
    plane_file = root_split / "planes" / ("%s.txt" % sample_idx)
    if not plane_file.exists():
        return None
    lines = [float(i) for i in open(plane_file).readlines()[3].split()]
    plane = np.asarray(lines)
    if plane[1] > 0:
        plane = -plane
    return plane / np.linalg.norm(plane[0:3])


def put_boxes_on_road_planes(gt_boxes: np.ndarray, road_planes: np.ndarray, calib: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """DataBaseSampler.put_boxes_on_road_planes: each box's bottom moved onto the plane below its centre."""
    a, b, c, d = road_planes
    center_cam = calib.lidar_to_rect(gt_boxes[:, 0:3])
    center_cam[:, 1] = (-d - a * center_cam[:, 0] - c * center_cam[:, 2]) / b
    cur_lidar_height = calib.rect_to_lidar(center_cam)[:, 2]
    mv_height = gt_boxes[:, 2] - gt_boxes[:, 5] / 2 - cur_lidar_height
    gt_boxes = gt_boxes.copy()
    gt_boxes[:, 2] -= mv_height
    return gt_boxes, mv_height


def gt_database(items: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]) -> dict[str, list[dict]]:
    """create_groundtruth_database (used_classes None): ``items`` of (points, names, boxes, difficulty); every box's
    points among all of the frame's points (not the camera's view only)."""
    db: dict[str, list[dict]] = {}
    for points, names, boxes, difficulty in items:
        for i in range(boxes.shape[0]):
            db.setdefault(str(names[i]), []).append({"name": str(names[i]), "box3d_lidar": boxes[i], "num_points_in_gt": int(in_box(points, boxes[i]).sum()),
                                                     "difficulty": int(difficulty[i])})
    return db


class DataBaseSampler:
    """OpenPCDet's DataBaseSampler: ``__init__`` (KeyError for a class the database lacks), its filters and sample groups,
    and ``__call__`` (np.stack of each group's sampled boxes: ValueError for a group left empty by the filters)."""

    def __init__(self, db: dict, sampler_cfg: dict, class_names: list[str]):
        self.cfg = sampler_cfg
        self.db_infos = {name: [] for name in class_names}
        [self.db_infos[cur_class].extend(db[cur_class]) for cur_class in class_names]
        for func_name, val in sampler_cfg["PREPARE"].items():
            if func_name == "filter_by_difficulty":
                self.db_infos = {k: [i for i in v if i["difficulty"] not in val] for k, v in self.db_infos.items()}
            elif func_name == "filter_by_min_points":
                for name_num in val:
                    name, min_num = name_num.split(":")
                    if int(min_num) > 0 and name in self.db_infos:
                        self.db_infos[name] = [i for i in self.db_infos[name] if i["num_points_in_gt"] >= int(min_num)]
        self.sample_groups = {}
        for x in sampler_cfg["SAMPLE_GROUPS"]:
            class_name, sample_num = x.split(":")
            if class_name in class_names:
                self.sample_groups[class_name] = int(sample_num)

    def __call__(self, data: dict, calib: Calibration | None) -> dict:
        boxes, names = data["gt_boxes"], data["gt_names"]
        for class_name, sample_num in self.sample_groups.items():
            if self.cfg.get("LIMIT_WHOLE_SCENE", False):
                sample_num -= int(np.sum(class_name == names))
            if sample_num > 0:
                pool = self.db_infos[class_name]
                sampled = [pool[k % len(pool)] for k in range(sample_num)] if pool else []
                sampled_boxes = np.stack([x["box3d_lidar"] for x in sampled], axis=0).astype(np.float32)
                if self.cfg["USE_ROAD_PLANE"]:
                    sampled_boxes, _ = put_boxes_on_road_planes(sampled_boxes, data["road_plane"], calib)
                boxes = np.concatenate([boxes, sampled_boxes], axis=0)
                names = np.concatenate([names, [class_name] * len(sampled_boxes)])
        return {**data, "gt_boxes": boxes, "gt_names": names}


def voxel_count(points: np.ndarray, point_range, voxel_size) -> int:
    """transform_points_to_voxels: the voxels the points inside the range fill (points outside any axis are dropped)."""
    low, high = np.asarray(point_range[:3], float), np.asarray(point_range[3:], float)
    inside = ((points[:, :3] >= low) & (points[:, :3] < high)).all(axis=1)
    return len(np.unique(np.floor((points[inside, :3] - low) / np.asarray(voxel_size, float)).astype(np.int64), axis=0))


def prepare_data(data: dict, cfg: dict, training: bool, sampler: DataBaseSampler | None, calib=None) -> dict:
    """DatasetTemplate.prepare_data up to the retry: the sampler (training), the classes kept, the range masks, the voxels."""
    if training:
        data = sampler(data, calib)
    keep = np.array([n in cfg["classes"] for n in data["gt_names"]], bool)
    boxes = data["gt_boxes"][keep]
    points = data["points"]
    point_range = np.asarray(cfg["range"], float)
    points = points[(points[:, 0] >= point_range[0]) & (points[:, 0] <= point_range[3]) & (points[:, 1] >= point_range[1]) & (points[:, 1] <= point_range[4])]
    if training:  # REMOVE_OUTSIDE_BOXES with USE_CENTER_TO_FILTER
        boxes = boxes[((boxes[:, :3] >= point_range[:3]) & (boxes[:, :3] <= point_range[3:])).all(axis=-1)]
    return {**data, "gt_boxes": boxes, "points": points, "voxels": voxel_count(points, point_range, cfg["voxel"])}


def openpcdet_kitti_dataset(root: Path, cfg: dict, training: bool):
    """KittiDataset(training).__getitem__ over the train (training) or val infos, with the sampler made from the train
    split's ground-truth database; returns ``getitem(index, depth)``."""
    infos = openpcdet_kitti_infos(root, "train" if training else "val")
    train_infos = infos if training else openpcdet_kitti_infos(root, "train")
    split_root = root / "training"

    def items():
        for info in train_infos:
            annos = info["annos"]
            n = annos["gt_boxes_lidar"].shape[0]
            points = np.fromfile(split_root / "velodyne" / f"{info['point_cloud']['lidar_idx']}.bin", np.float32).reshape(-1, 4)
            yield points, annos["name"][:n], annos["gt_boxes_lidar"], annos["difficulty"][:n]

    sampler = DataBaseSampler(gt_database(items()), cfg["sampler"], cfg["classes"]) if training else None
    rng = np.random.default_rng(0)

    def getitem(index: int, depth: int = 0) -> dict:
        info = infos[index]
        sample_idx = info["point_cloud"]["lidar_idx"]
        calib = Calibration(split_root / "calib" / f"{sample_idx}.txt")
        annos = info["annos"]
        real = annos["name"] != "DontCare"  # common_utils.drop_info_with_name
        data = {"gt_names": annos["name"][real], "gt_boxes": annos["gt_boxes_lidar"]}
        plane = road_plane(split_root, sample_idx)
        if plane is not None:
            data["road_plane"] = plane
        points = np.fromfile(split_root / "velodyne" / f"{sample_idx}.bin", np.float32).reshape(-1, 4)
        if cfg["fov"]:
            pts_img, depth_rect = calib.rect_to_img(calib.lidar_to_rect(points[:, :3]))
            shape = info["image"]["image_shape"]
            points = points[(pts_img[:, 0] >= 0) & (pts_img[:, 0] < shape[1]) & (pts_img[:, 1] >= 0) & (pts_img[:, 1] < shape[0]) & (depth_rect >= 0)]
        data = prepare_data({**data, "points": points}, cfg, training, sampler, calib)
        if training and len(data["gt_boxes"]) == 0:
            if depth >= MAX_RETRIES:
                raise RecursionError("maximum recursion depth exceeded: no training item holds a box")
            return getitem(int(rng.integers(len(infos))), depth + 1)
        return data

    return infos, getitem


def openpcdet_custom_dataset(root: Path, cfg: dict, training: bool):
    """CustomDataset(training).__getitem__ (no road plane, every point), as :func:`openpcdet_kitti_dataset`."""
    infos = openpcdet_custom_infos(root, "train" if training else "val")
    train_infos = infos if training else openpcdet_custom_infos(root, "train")
    db = gt_database((i["points"], i["annos"]["name"], i["annos"]["gt_boxes_lidar"], np.zeros(len(i["annos"]["name"]), int)) for i in train_infos)
    sampler = DataBaseSampler(db, cfg["sampler"], cfg["classes"]) if training else None
    rng = np.random.default_rng(0)

    def getitem(index: int, depth: int = 0) -> dict:
        info = infos[index]
        data = prepare_data({"gt_names": info["annos"]["name"], "gt_boxes": info["annos"]["gt_boxes_lidar"], "points": info["points"]}, cfg, training, sampler)
        if training and len(data["gt_boxes"]) == 0:
            if depth >= MAX_RETRIES:
                raise RecursionError("maximum recursion depth exceeded: no training item holds a box")
            return getitem(int(rng.integers(len(infos))), depth + 1)
        return data

    return infos, getitem


def every_item(infos, getitem) -> list[dict]:
    return [getitem(k) for k in range(len(infos))]


def test_openpcdet_kitti_road_planes_put_boxes_on_the_ground(dataset):
    """Each frame's planes file (KITTI's layout) is what get_road_plane reads, and puts every labelled car back where
    it stands: the sampler moves a sampled box onto it by that much (put_boxes_on_road_planes)."""
    root = dataset / "kitti"
    moved = []
    for split in ("train", "val"):
        for info in openpcdet_kitti_infos(root, split):
            sample_idx = info["point_cloud"]["lidar_idx"]
            lines = (root / "training" / "planes" / f"{sample_idx}.txt").read_text().splitlines()
            assert lines[:3] == ["# Matrix", "WIDTH 4", "HEIGHT 1"] and len(lines[3].split()) == 4
            plane = road_plane(root / "training", sample_idx)
            assert plane[1] < -0.99 and plane[3] == pytest.approx(1.51, abs=0.01)  # level, the parking robot's sensor height
            boxes = info["annos"]["gt_boxes_lidar"]
            if len(boxes):
                moved.append(put_boxes_on_road_planes(boxes, plane, Calibration(root / "training" / "calib" / f"{sample_idx}.txt"))[1])
    moved = np.concatenate(moved)
    assert len(moved) >= 2 and np.abs(moved).max() < 0.02, moved  # the cars stand on the floor the plane says


def test_openpcdet_stock_3class_sampler_needs_every_class_the_written_config_names_those_present(dataset):
    """A parking run holds only cars: the stock kitti_dataset.yaml's sampler stops at Pedestrian, as OpenPCDet did
    (``database_sampler.py: KeyError: 'Pedestrian'``); the written config names Car alone, with its range and anchors,
    and every train item comes out with boxes and voxels, every val item with voxels."""
    root = dataset / "kitti"
    with pytest.raises(KeyError, match="Pedestrian"):
        openpcdet_kitti_dataset(root, STOCK_KITTI, training=True)
    cfg = written_openpcdet(root / "openpcdet_kitti_dataset.yaml", root / "openpcdet_pv_rcnn.yaml")
    assert cfg["classes"] == ["Car"] and cfg["sampler"]["SAMPLE_GROUPS"] == ["Car:20"] and cfg["sampler"]["PREPARE"]["filter_by_min_points"] == ["Car:5"]
    assert cfg["range"] == [0.0, -40.0, -2.78, 70.4, 40.0, 1.22] and cfg["anchors"] == {"Car": pytest.approx(-1.56)}  # the ground at -1.51 m, not -1.73
    infos, getitem = openpcdet_kitti_dataset(root, cfg, training=True)
    for item in every_item(infos, getitem):
        assert len(item["gt_boxes"]) > 0 and item["voxels"] > 0
    infos, getitem = openpcdet_kitti_dataset(root, cfg, training=False)
    assert all(item["voxels"] > 0 for item in every_item(infos, getitem))
    pillars = written_openpcdet(root / "openpcdet_kitti_dataset.yaml", root / "openpcdet_pointpillar.yaml")  # pointpillar.yaml's range and pillars
    assert pillars["range"] == [0.0, -39.68, -2.78, 69.12, 39.68, 1.22] and pillars["voxel"] == [0.16, 0.16, 4] and pillars["anchors"] == cfg["anchors"]
    for training in (True, False):
        infos, getitem = openpcdet_kitti_dataset(root, pillars, training)
        assert all(item["voxels"] > 0 and (len(item["gt_boxes"]) > 0 or not training) for item in every_item(infos, getitem))


def test_openpcdet_custom_written_config_fits_the_parking_run(dataset):
    """The custom layout: the stock custom_dataset.yaml's classes (Vehicle, Pedestrian, Cyclist) are none of the
    written categories (KeyError at Vehicle); the written one names Car and moves the range onto the data."""
    root = dataset / "openpcdet"
    with pytest.raises(KeyError, match="Vehicle"):
        openpcdet_custom_dataset(root, STOCK_CUSTOM, training=True)
    cfg = written_openpcdet(root / "custom_dataset.yaml", root / "pv_rcnn.yaml")
    assert cfg["classes"] == ["Car"] and cfg["range"][2] == pytest.approx(-1.51 - 2)
    for training in (True, False):
        infos, getitem = openpcdet_custom_dataset(root, cfg, training)
        for item in every_item(infos, getitem):
            assert item["voxels"] > 0 and (len(item["gt_boxes"]) > 0 or not training)


def _run(out: Path, *settings: str) -> Path:
    command = [sys.executable, str(ROOT / "run.py"), "--out", str(out), "--frames", "8", "--seed", "0", "--set", "output.formats=[ply]",
               "--set", "output.boxes.formats=[kitti,openpcdet]", "--set", "output.preview=false", *(a for s in settings for a in ("--set", s))]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def hall(tmp_path_factory) -> dict[str, Path]:
    """The industrial hall (sensor 4.5 m up, the KITTI camera 1 m from the -x wall at 1.73 m) in the sensor frame and in
    ``output.frame: kitti``, eight frames each."""
    pytest.importorskip("bpy", reason="the hall is a real run")
    base = tmp_path_factory.mktemp("hall")
    return {frame: _run(base / frame, "scene.builder=industrial_hall", f"output.frame={frame}") for frame in ("sensor", "kitti")}


def test_hall_in_the_sensor_frame_is_outside_every_stock_range_the_written_configs_fit(hall):
    """4.5 m up, the hall's points and boxes lie below the stock ranges' z: KITTI's training items lose every box
    (mask_boxes_outside_range) and __getitem__ retries until RecursionError; the custom layout's points fill no voxel.
    The written configs move the ranges (and anchors) onto the floor and every item comes out."""
    root = hall["sensor"] / "kitti"
    cfg = written_openpcdet(root / "openpcdet_kitti_dataset.yaml", root / "openpcdet_pv_rcnn.yaml")
    assert cfg["classes"] == ["Pedestrian"]  # the hall holds people and robot arms (KITTI's Misc)
    assert cfg["range"] == [-7.0, -40.0, -5.77, 63.4, 40.0, -1.77]  # floor at -4.5 m, the camera at x = -7 m
    with pytest.raises(RecursionError):
        infos, getitem = openpcdet_kitti_dataset(root, {**cfg, "range": STOCK_KITTI["range"]}, training=True)
        getitem(0)
    for training in (True, False):
        infos, getitem = openpcdet_kitti_dataset(root, cfg, training)
        for item in every_item(infos, getitem):
            assert item["voxels"] > 0 and (len(item["gt_boxes"]) > 0 or not training)
    custom = hall["sensor"] / "openpcdet"
    infos, getitem = openpcdet_custom_dataset(custom, {**STOCK_CUSTOM, "classes": ["Person"],
                                                       "sampler": {**STOCK_CUSTOM["sampler"], "SAMPLE_GROUPS": ["Person:15"]}}, False)
    assert all(item["voxels"] == 0 for item in every_item(infos, getitem))  # 0.0 % of the points inside z [-2, 4]
    cfg = written_openpcdet(custom / "custom_dataset.yaml", custom / "pv_rcnn.yaml")
    assert cfg["classes"] == ["Person"] and cfg["anchors"] == {"Person": -4.5}
    for training in (True, False):
        infos, getitem = openpcdet_custom_dataset(custom, cfg, training)
        assert all(item["voxels"] > 0 and (len(item["gt_boxes"]) > 0 or not training) for item in every_item(infos, getitem))


def test_hall_in_the_kitti_frame_fits_the_stock_ranges(hall):
    """``output.frame: kitti`` puts the ground at -1.73 m under an origin above the KITTI camera: the stock ranges hold
    every item (the classes still those present), the road planes say 1.73 m, and the written configs move nothing."""
    root = hall["kitti"] / "kitti"
    cfg = written_openpcdet(root / "openpcdet_kitti_dataset.yaml", root / "openpcdet_pv_rcnn.yaml")
    assert cfg["range"] == STOCK_KITTI["range"] and cfg["anchors"] == {"Pedestrian": -0.6}
    stock = {**STOCK_KITTI, "classes": cfg["classes"], "sampler": cfg["sampler"]}
    for training in (True, False):
        infos, getitem = openpcdet_kitti_dataset(root, stock, training)
        for item in every_item(infos, getitem):
            assert item["voxels"] > 0 and (len(item["gt_boxes"]) > 0 or not training)
            np.testing.assert_allclose(item["road_plane"], [0, -1, 0, 1.73], atol=1e-6)
    custom = hall["kitti"] / "openpcdet"
    points = np.concatenate([np.load(p) for p in sorted((custom / "points").glob("*.npy"))])
    floor = np.percentile(points[:, 2], 1)
    assert -1.8 < floor < -1.6 and ((points[:, 2] >= -2) & (points[:, 2] <= 4)).mean() > 0.99  # custom_dataset.yaml's z [-2, 4]


def mmdet3d_written(path: Path) -> dict:
    """The written mmdetection3d config, executed as mmengine does for its own variables (``_base_`` merged elsewhere)."""
    names: dict = {}
    exec(compile(path.read_text(), str(path), "exec"), {}, names)
    return names


def test_mmdet3d_written_config_samples_only_classes_present_and_keeps_the_points(dataset, hall):
    """mmdetection3d's DataBaseSampler indexes ``db_infos[name]`` for every filter_by_min_points key (KeyError:
    'Pedestrian' with the stock 3-class config on the parking run); PointsRangeFilter keeps x, y and z: the hall's points
    in the sensor frame all fall below the stock z and none is left. The written configs name the classes present, move
    the range, and give the model as many classes and anchor sets."""
    for root, classes, point_range in ((dataset / "kitti", ["Car"], [0.0, -39.68, -2.78, 69.12, 39.68, 1.22]),
                                       (hall["sensor"] / "kitti", ["Pedestrian"], [-7.0, -39.68, -5.77, 62.12, 39.68, -1.77])):
        infos = openpcdet_kitti_infos(root, "train")
        db = gt_database((np.fromfile(root / "training" / "velodyne" / f"{i['point_cloud']['lidar_idx']}.bin", np.float32).reshape(-1, 4), i["annos"]["name"],
                          i["annos"]["gt_boxes_lidar"], i["annos"]["difficulty"]) for i in infos)
        with pytest.raises(KeyError):
            [db[name] for name in ("Car", "Pedestrian", "Cyclist")]  # the stock filter_by_min_points=dict(Car=5, Pedestrian=5, Cyclist=5)
        config = mmdet3d_written(root / "mmdet3d_pointpillars_kitti.py")
        assert config["class_names"] == classes and config["point_cloud_range"] == point_range
        sampler = config["db_sampler"]
        assert list(sampler["prepare"]["filter_by_min_points"]) == classes == list(sampler["sample_groups"])
        for name, minimum in sampler["prepare"]["filter_by_min_points"].items():
            assert [i for i in db[name] if i["num_points_in_gt"] >= minimum and i["difficulty"] != -1]  # a group the sampler can draw from
        head = config["model"]["bbox_head"]
        assert head["num_classes"] == len(classes) == len(head["anchor_generator"]["ranges"]) == len(config["model"]["train_cfg"]["assigner"])
        low, high = np.array(point_range[:3]), np.array(point_range[3:])
        for info in infos:
            points = np.fromfile(root / "training" / "velodyne" / f"{info['point_cloud']['lidar_idx']}.bin", np.float32).reshape(-1, 4)
            assert ((points[:, :3] > low) & (points[:, :3] < high)).all(axis=1).any()  # PointsRangeFilter leaves points
    stock = np.array([0, -39.68, -3, 69.12, 39.68, 1])
    for path in sorted((hall["sensor"] / "kitti" / "training" / "velodyne").glob("*.bin")):
        points = np.fromfile(path, np.float32).reshape(-1, 4)
        inside = ((points[:, :3] > stock[:3]) & (points[:, :3] < stock[3:])).all(axis=1)
        assert inside.mean() < 0.05  # the stock range keeps a few wall and shelf points at most, no floor


@pytest.fixture(scope="module")
def street(tmp_path_factory) -> Path:
    """examples/street/config.yaml (the HDL-64E 1.73 m up at the intersection), eight frames, every box layout."""
    pytest.importorskip("bpy", reason="the street is a real run")
    out = tmp_path_factory.mktemp("street") / "out"
    command = [sys.executable, str(ROOT / "run.py"), "--config", str(ROOT / "examples" / "street" / "config.yaml"), "--out", str(out), "--frames", "8",
               "--set", "output.boxes.formats=[kitti,openpcdet,sustech]", "--set", "output.preview=false"]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return out


def test_street_every_vehicle_in_view_is_boxed_the_same_way_in_every_layout(street):
    """Vans, trucks and buses are boxed as KITTI does (Van, Truck, Misc), cars, people and riders as before, in
    label_2 wherever the camera sees their points and in the custom and SUSTechPOINTS layouts around the sensor; a van's
    points are SemanticKITTI's car (10), as KITTI's vans are in SemanticKITTI; a rider on a motorcycle is a motorcyclist
    (32) in a box of its own class, a rider on a bicycle a bicyclist (31) in KITTI's Cyclist box."""
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.io.class_maps import load_class_maps
    from bpy_pipeline.io.sustech import label_type, sustech_type
    from bpy_pipeline.labels import load_class_table

    from bpy_pipeline.config import BOX_CLASSES

    maps, table = load_class_maps(), load_class_table()
    kinds: dict[str, int] = {}
    for path in sorted((street / "records").glob("*.json")):
        record = json.loads(path.read_text())
        stem = path.stem
        folder = "testing" if f"kitti/testing/label_2/{stem}.txt" in record["files"] else "training"
        root = street / "kitti" / folder
        boxes = {b["instance"]: b["class"] for b in record["boxes"]}
        sustech = {int(o["obj_id"]): o["obj_type"] for o in json.loads((street / "sustech" / "label" / f"{stem}.json").read_text())}
        assert set(sustech) == set(boxes) and all(sustech[i] == sustech_type(c) for i, c in boxes.items())
        custom = sorted(line.split()[7] for line in (street / "openpcdet" / "labels" / f"{stem}.txt").read_text().splitlines())
        assert custom == sorted(label_type(c) for c in boxes.values())
        points = read_ply(street / "ply" / f"{stem}.ply")
        calib = Calibration(root / "calib" / f"{stem}.txt")
        shape = image_shape(root / "image_2" / f"{stem}.png")
        pts_img, depth = calib.rect_to_img(calib.lidar_to_rect(np.stack([points["x"], points["y"], points["z"]], axis=1)))
        seen = (pts_img[:, 0] >= 0) & (pts_img[:, 0] < shape[1]) & (pts_img[:, 1] >= 0) & (pts_img[:, 1] < shape[0]) & (depth > 0.1)
        expected = sorted(maps.kitti_name(c) for i, c in boxes.items() if seen[points["instance"] == i].any())
        lines = [line.split()[0] for line in (root / "label_2" / f"{stem}.txt").read_text().splitlines()]
        assert sorted(t for t in lines if t != "DontCare") == expected
        assert lines[: len(expected)] == [t for t in lines if t != "DontCare"]  # DontCare lines last: the loaders take the boxes before them
        users = {o["instance"] for o in record["objects"] if o["class"] in BOX_CLASSES}
        thin = {i for i in users - set(boxes) if seen[points["instance"] == i].any()}  # seen, fewer points than their class's minimum
        assert lines.count("DontCare") == (len(thin) if expected or thin else 1)  # KITTI's regions of objects too far to label
        for c in boxes.values():
            kinds[c] = kinds.get(c, 0) + 1
        semantic = np.fromfile(street / [f for f in record["files"] if f.endswith(".label")][0], np.uint32) & 0xFFFF
        project = points["semantic"]
        for name, sk in (("van", 10), ("motorcyclist", 32), ("rider", 31), ("truck", 18), ("bus", 13)):
            assert (semantic[project == table.id_of(name)] == sk).all(), name
        for instance, c in boxes.items():  # a two-wheeler's box is its rider's: the motorcycle and its rider share the instance
            classes = {o["class"] for o in record["objects"] if o["instance"] == instance}
            if classes & {"bicycle", "motorcycle"}:
                assert c == ({"bicycle": "rider", "motorcycle": "motorcyclist"}[next(iter(classes & {"bicycle", "motorcycle"}))])
    assert all(kinds.get(c) for c in ("car", "van", "truck", "bus", "person", "rider", "motorcyclist")), kinds

