"""SUSTechPOINTS annotations: the layout of one SUSTechPOINTS scene, as its tool loads it.

Files (frame ``NNNNNN``)::

    sustech/lidar/NNNNNN.pcd    binary PCD with the label fields (:mod:`.pcd`)
    sustech/label/NNNNNN.json   [{"obj_id": "7", "obj_type": "Car",
                                  "psr": {"position": {"x", "y", "z"}, "rotation": {"x": 0, "y": 0, "z": yaw},
                                          "scale": {"x": length, "y": width, "z": height}}}, ...]

Boxes are in the frame of the points (metres; yaw in radians about z from the x axis), centred;
``obj_id`` is the instance id and ``obj_type`` a type of SUSTechPOINTS' class list (``output.boxes.names``,
else labels.yaml ``sustech_names``: car Car, person Pedestrian, rider BicycleRider, ...; Misc for the rest).
A frame without boxes has an empty list. The PCD's ``intensity`` is 0..255 (the point record's 0..1 times
255): the tool's colour-by-intensity view divides it by 255 (public/js/lidar.js ``map_intesity_to_color``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .atomic import atomic_write
from .pcd import write_pcd


def label_type(class_name: str, names: dict | None = None) -> str:
    """``names[class]`` if given, else the class's words capitalised and joined (``robot arm`` -> ``RobotArm``)."""
    if names and class_name in names:
        return str(names[class_name])
    return "".join(word.capitalize() for word in class_name.replace("_", " ").split())


INTENSITY_SCALE = 255.0  # SUSTechPOINTS reads intensity as 0..255


def sustech_type(class_name: str, names: dict | None = None) -> str:
    """``names[class]`` (output.boxes.names) if given, else labels.yaml ``sustech_names``, else ``Misc``."""
    from .class_maps import load_sustech_names

    if names and class_name in names:
        return str(names[class_name])
    return load_sustech_names().get(" ".join(class_name.replace("_", " ").lower().split()), "Misc")


def sustech_objects(boxes: np.ndarray, names: dict | None = None) -> list[dict]:
    """The SUSTechPOINTS objects of ``boxes`` (BOX_DTYPE)."""
    out = []
    for box in boxes:
        (x, y, z), (length, width, height) = (float(v) for v in box["centre"]), (float(v) for v in box["size"])
        out.append({
            "obj_id": str(int(box["instance"])),
            "obj_type": sustech_type(str(box["class_name"]), names),
            "psr": {"position": {"x": x, "y": y, "z": z}, "rotation": {"x": 0.0, "y": 0.0, "z": float(box["heading"])},
                    "scale": {"x": length, "y": width, "z": height}},
        })  # fmt: skip
    return out


def write_frame(out_dir: str | os.PathLike, stem: str, points: np.ndarray, boxes, names: dict | None = None) -> list[Path]:
    """``sustech/lidar/NNNNNN.pcd`` and ``sustech/label/NNNNNN.json`` of one frame."""
    root = Path(out_dir) / "sustech"
    label = root / "label" / f"{stem}.json"
    objects = sustech_objects(boxes if boxes is not None else [], names)
    with atomic_write(label) as tmp:
        tmp.write_text(json.dumps(objects, indent=1) + "\n")
    scaled = np.array(points, copy=True)
    scaled["intensity"] = scaled["intensity"] * np.float32(INTENSITY_SCALE)
    return [write_pcd(root / "lidar" / f"{stem}.pcd", scaled), label]
