"""Sensor rigs: several sensors on one platform (a static post, a vehicle, a robot), scanned in one frame. Pure.

``sensor.rig`` lists the sensors, each a preset (refined field by field, as ``sensor`` is) at a
``position`` (m) and ``rotation_deg`` (roll, pitch, yaw) relative to the platform; the platform
stands where ``sensor.position`` / ``rotation_deg`` (or the scene, or a trajectory) puts a single
sensor. A name instead of a list takes one of :data:`RIG_PRESETS`.

Each frame scans every sensor with its own rays, timing and range, through the same stages a
single-sensor run uses, each from its own generator (:func:`member_rng`), so sensor k of a rig
gives the bytes a single-sensor run of that sensor at that pose and generator gives. The frame's
merged cloud lies in the platform frame (``output.frame: sensor``; the world frame on request) and
carries the index of the sensor that saw each point: :data:`RIG_POINT_DTYPE` (the point record
plus ``sensor``, uint8), used only for rigs, so single-sensor outputs keep their bytes.

Boxes: per sensor, a box is kept where that sensor puts its minimum points on it (the sparse-
camera thesis split its boxes between its three cameras the same way, keeping a box cut by a
field-of-view boundary in every camera that holds enough points); merged, where the merged cloud
does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .geometry.boxes import BOX_DTYPE, keep_boxes
from .geometry.lod import SensorView
from .geometry.field_of_view import FieldOfView
from .geometry.transforms import pose_matrix, transform_points
from .lidar.points import POINT_DTYPE
from .lidar.sensor.sensors import SensorSpec, angular_resolution, elevations, mount_offset, resolve_sensor

RIG_POINT_DTYPE = np.dtype(POINT_DTYPE.descr + [("sensor", "u1")])
MAX_SENSORS = 255

# Rigs by name: members as a config would list them.
RIG_PRESETS: dict[str, list[dict]] = {
    # The sparse-camera thesis: three 80-degree flash cameras on a 2 m post, 240 degrees together
    # (CARLA's 80 x 13.3 deg geometry and 35 m, its table 2.3), looking level.
    "flash_post_240": [
        {"preset": "flash96x16_carla", "position": [0.0, 0.0, 2.0], "rotation_deg": [0.0, 0.0, 80.0]},
        {"preset": "flash96x16_carla", "position": [0.0, 0.0, 2.0], "rotation_deg": [0.0, 0.0, 0.0]},
        {"preset": "flash96x16_carla", "position": [0.0, 0.0, 2.0], "rotation_deg": [0.0, 0.0, -80.0]},
    ],
    # A car's roof LiDAR (360 deg) and four flash cameras at the body's corners for the near field
    # (platform: the car's centre on the ground, x forward).
    "car_roof": [
        {"preset": "hdl32e", "position": [0.0, 0.0, 1.9], "rotation_deg": [0.0, 0.0, 0.0]},
        {"preset": "flash96x16_grid", "position": [2.3, 0.9, 0.6], "rotation_deg": [0.0, 0.0, 45.0]},
        {"preset": "flash96x16_grid", "position": [2.3, -0.9, 0.6], "rotation_deg": [0.0, 0.0, -45.0]},
        {"preset": "flash96x16_grid", "position": [-2.3, 0.9, 0.6], "rotation_deg": [0.0, 0.0, 135.0]},
        {"preset": "flash96x16_grid", "position": [-2.3, -0.9, 0.6], "rotation_deg": [0.0, 0.0, -135.0]},
    ],
}


@dataclass(frozen=True)
class RigSensor:
    """One sensor of a rig: its spec and its pose on the platform (m, degrees)."""

    spec: SensorSpec = field(metadata={"inline": True})  # its keys are the rig entry's (sensor.rig[k].max_range)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """``(4, 4)`` sensor-to-platform transform, the preset's mount height included."""
        out = pose_matrix(self.position, self.rotation_deg)
        out[:3, 3] += mount_offset(self.spec)
        return out


def _vector(value, where: str) -> tuple[float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise InputError(f"{where}: expected three numbers [x, y, z], got {value!r}")
    return tuple(float(v) for v in value)


def rig_from_data(data, where: str = "sensor.rig") -> tuple[RigSensor, ...]:
    """The rig of a config's ``sensor.rig``: a name from :data:`RIG_PRESETS` or a list of ``{preset, position, rotation_deg, ...}``."""
    if isinstance(data, str):
        if data not in RIG_PRESETS:
            raise InputError(f"{where}: unknown rig {data!r}; allowed: {', '.join(RIG_PRESETS)}, or a list of {{preset, position, rotation_deg}}")
        data = RIG_PRESETS[data]
    if not isinstance(data, list) or not data:
        raise InputError(f"{where}: expected a rig name ({', '.join(RIG_PRESETS)}) or a non-empty list of {{preset, position, rotation_deg}}, got {data!r}")
    if len(data) > MAX_SENSORS:
        raise InputError(f"{where}: at most {MAX_SENSORS} sensors (the point's sensor index is uint8), got {len(data)}")
    out = []
    for k, item in enumerate(data):
        here = f"{where}[{k}]"
        if not isinstance(item, dict) or "preset" not in item:
            raise InputError(f"{here}: expected a mapping with a preset, position and rotation_deg, got {item!r}")
        item = dict(item)
        position = _vector(item.pop("position", [0.0, 0.0, 0.0]), f"{here}.position")
        rotation = _vector(item.pop("rotation_deg", [0.0, 0.0, 0.0]), f"{here}.rotation_deg")
        out.append(RigSensor(resolve_sensor(item, here), position, rotation))
    return tuple(out)


def member_rng(seed: int, frame: int, sensor: int) -> np.random.Generator:
    """The generator of sensor ``sensor`` of a rig in frame ``frame`` of a run seeded with ``seed``."""
    return np.random.default_rng(np.random.SeedSequence([seed, frame, 1 + sensor]))


def merge_clouds(clouds: list[np.ndarray], matrices: list[np.ndarray] | None = None) -> np.ndarray:
    """``(p,)`` :data:`RIG_POINT_DTYPE`: the clouds (each ``(p_k,)`` POINT_DTYPE) one after the other, with their index.

    matrices : per cloud, the ``(4, 4)`` transform into the merged frame (sensor -> platform), or
        ``None`` when the clouds share a frame already (the world)
    """
    n = sum(len(c) for c in clouds)
    out = np.empty(n, RIG_POINT_DTYPE)
    start = 0
    for k, cloud in enumerate(clouds):
        part = out[start : start + len(cloud)]
        for name in POINT_DTYPE.names:
            part[name] = cloud[name]
        if matrices is not None and len(cloud):
            xyz = transform_points(np.column_stack([cloud["x"], cloud["y"], cloud["z"]]).astype(np.float64), matrices[k])
            part["x"], part["y"], part["z"] = xyz.T
        part["sensor"] = k
        start += len(cloud)
    return out


def split_cloud(merged: np.ndarray) -> list[np.ndarray]:
    """The merged cloud's points per sensor (POINT_DTYPE, merged frame), by sensor index."""
    count = int(merged["sensor"].max()) + 1 if len(merged) else 0
    plain = merged[list(POINT_DTYPE.names)]
    return [np.ascontiguousarray(plain[merged["sensor"] == k]).astype(POINT_DTYPE) for k in range(count)]


def field_of_view(spec: SensorSpec, pose: np.ndarray) -> FieldOfView:
    """The :class:`~.geometry.field_of_view.FieldOfView` of a sensor of ``spec`` at ``pose`` (4, 4), for placement."""
    table = elevations(spec)
    step = angular_resolution(spec)[1] or 0.0
    if len(table) == 0:  # a pattern without rows (rosette, profile, rays from a file): every direction
        azimuth, elevation = (-180.0, 180.0), (-90.0, 90.0)
    else:
        lo, hi = spec.horizontal_fov_deg
        azimuth = (float(lo), float(hi))
        elevation = (float(table.min()) - step / 2, float(table.max()) + step / 2)
    return FieldOfView(np.asarray(pose, float), azimuth, elevation, float(spec.min_range), float(spec.max_range))


def out_of_reach(spec: SensorSpec, pose: np.ndarray, centres: np.ndarray, radii: np.ndarray, margin_deg: float = 1.0) -> np.ndarray:
    """``(n,)`` bool: spheres (world ``centres`` (n, 3), ``radii`` (n,) m) that no ray of a sensor of ``spec`` at
    ``pose`` can pass within: wholly outside its azimuth or elevation span (the rays' own, widened by
    ``margin_deg``), or farther than its range. Conservative: ``False`` whenever in doubt (a pattern without rows, a
    rosette, a profile or rays from a file, spans every direction: :func:`field_of_view`)."""
    local = (np.asarray(centres, float) - pose[:3, 3]) @ pose[:3, :3]
    d = np.linalg.norm(local, axis=1)
    radii = np.asarray(radii, float)
    inside = d <= radii
    spread = np.degrees(np.arcsin(np.clip(radii / np.maximum(d, 1e-12), 0.0, 1.0))) + margin_deg
    far = np.sqrt(np.maximum(d**2 - radii**2, 0.0)) - radii > spec.max_range
    out = far & ~inside
    fov = field_of_view(spec, np.eye(4))
    el = np.degrees(np.arcsin(np.clip(local[:, 2] / np.maximum(d, 1e-12), -1.0, 1.0)))
    out |= ~inside & ((el + spread < fov.elevation[0]) | (el - spread > fov.elevation[1]))
    if fov.azimuth[1] - fov.azimuth[0] < 360.0:
        az = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
        middle = (fov.azimuth[0] + fov.azimuth[1]) / 2
        off = np.abs((az - middle + 180.0) % 360.0 - 180.0)  # angle from the span's middle
        half = (fov.azimuth[1] - fov.azimuth[0]) / 2
        out |= ~inside & (off - spread > half) & (spread < 90.0)
    return out


@dataclass(frozen=True)
class RigView(SensorView):
    """A :class:`~.geometry.lod.SensorView` that also knows each sensor's field of view (``fields``)."""

    fields: tuple = field(default=())


# ----------------------------------------------------------------------------- boxes
def merged_boxes(member_boxes: list[np.ndarray], min_points: dict, default: int) -> np.ndarray:
    """World-frame boxes of the merged cloud from each sensor's unfiltered world boxes (BOX_DTYPE).

    Per instance: the geometry of its first sensor's box (every sensor fits the same triangles),
    points, visible and unoccluded summed over the sensors, truncation the smallest; kept where the
    summed points reach the class's minimum.
    """
    by_instance: dict[int, np.ndarray] = {}
    for boxes in member_boxes:
        for box in boxes:
            key = int(box["instance"])
            if key not in by_instance:
                by_instance[key] = box.copy()
            else:
                held = by_instance[key]
                for name in ("points", "visible", "unoccluded"):
                    held[name] += box[name]
                held["truncation"] = min(held["truncation"], box["truncation"])
    out = np.array([by_instance[k] for k in sorted(by_instance)], dtype=BOX_DTYPE) if by_instance else np.zeros(0, BOX_DTYPE)
    return keep_boxes(out, min_points, default)


@dataclass
class RigFrame:
    """A rig's frame beside the merged one: the sensors, each sensor's :class:`~.frame.Frame`, and their transforms.

    sensors : the rig's :class:`RigSensor` s; frames : per sensor, its frame (points in its own
    frame, or the world; boxes kept where it holds their minimum points); to_merged : per sensor,
    its ``(4, 4)`` transform into the merged cloud's frame (``None``: the world, shared)
    """

    sensors: tuple
    frames: list = field(default_factory=list)
    to_merged: list | None = None

    def record(self) -> dict:
        """Plain data for the frame's record: per sensor, its preset, pose (world), points and boxes."""
        out = []
        for k, (sensor, frame) in enumerate(zip(self.sensors, self.frames)):
            entry = {"index": k, "preset": sensor.spec.name, "pose": frame.pose.tolist(), "points": int(len(frame.points)),
                     "timings_s": {n: round(v, 4) for n, v in frame.timings.items()}}
            if frame.boxes is not None:
                entry["boxes"] = [{"class": str(b["class_name"]), "instance": int(b["instance"]), "points": int(b["points"])} for b in frame.boxes]
            out.append(entry)
        return {"sensors": out}
