"""Six-axis arm kinematics: forward kinematics, joint limits, link self-collision, random valid poses. Pure numpy.

The arm is a serial chain read from ``assets_manifest/robot_arm.yaml`` (a Staubli TX90L-class
robot by default), written the URDF way: joint ``i`` sits at ``origin`` in link ``i - 1``'s frame
and turns link ``i`` about ``axis``:

    frame[0] = base                                  (the base link, on the floor)
    frame[i] = frame[i - 1] @ T(origin_i) @ R(axis_i, q_i)      i = 1..6
                (@ F_i before R for a URDF joint turned by its rpy: ``ArmModel.fixed``)

Link shapes are capsules in their link's frame; the same capsules are the self-collision model
and (inscribed meshes) the links Blender shows, so a configuration the check accepts has links
whose meshes do not intersect. Angles are radians in code, degrees in the YAML file.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..yaml_text import read_yaml_file

ARM_PATH = Path(__file__).resolve().parents[2] / "assets_manifest" / "robot_arm.yaml"


@dataclass(frozen=True)
class ArmModel:
    """A serial arm.

    names : joint names, length j
    origins : (j, 3) float64 joint positions in the parent link's frame, metres
    axes : (j, 3) float64 unit rotation axes in the parent link's frame
    lower, upper : (j,) float64 joint limits, radians
    capsule_link : (c,) int link index of each capsule (0 = base, i = after joint i)
    capsule_a, capsule_b : (c, 3) float64 capsule end points in their link's frame, metres
    capsule_radius : (c,) float64 metres
    capsule_flat_start : (c,) bool, the capsule ends in a flat disc at ``a`` (the base on the floor)
    pairs : (p, 2) int capsule index pairs checked for self-collision
    clearance : metres two checked capsules must keep between them
    fixed : (j, 3, 3) float64 fixed rotation of each joint's frame before it turns (a URDF joint's rpy), or None
    """

    name: str
    names: tuple[str, ...]
    origins: np.ndarray
    axes: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    capsule_link: np.ndarray
    capsule_a: np.ndarray
    capsule_b: np.ndarray
    capsule_radius: np.ndarray
    capsule_flat_start: np.ndarray
    pairs: np.ndarray
    clearance: float
    fixed: np.ndarray | None = None

    @property
    def joints(self) -> int:
        return len(self.names)


def _vector(value, where: str, length: int = 3) -> np.ndarray:
    try:
        out = np.asarray(value, float)
    except (TypeError, ValueError):
        out = None
    if out is None or out.shape != (length,) or not np.isfinite(out).all():
        raise InputError(f"{where}: expected a list of {length} numbers, got {value!r}")
    return out


def _capsules(items, where: str):
    if not isinstance(items, list) or not items:
        raise InputError(f"{where}: expected a list of capsules {{a, b, radius}}")
    out = []
    for k, item in enumerate(items):
        here = f"{where}[{k}]"
        if not isinstance(item, dict):
            raise InputError(f"{here}: expected a mapping {{a, b, radius}}")
        radius = item.get("radius")
        if not isinstance(radius, (int, float)) or radius <= 0:
            raise InputError(f"{here}.radius: expected a number > 0, got {radius!r}")
        out.append((_vector(item.get("a"), f"{here}.a"), _vector(item.get("b"), f"{here}.b"), float(radius), bool(item.get("flat_start", False))))
    return out


def parse_arm(data: dict, where: str) -> ArmModel:
    """Validate the mapping of a robot_arm.yaml file; ``InputError`` naming ``where`` and the key."""
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a mapping with name, base, joints, self_collision")
    joints = data.get("joints")
    if not isinstance(joints, list) or not joints:
        raise InputError(f"{where}: joints: expected a list of joints")
    names, origins, axes, lower, upper = [], [], [], [], []
    capsules = [(0, c) for c in _capsules((data.get("base") or {}).get("capsules"), f"{where}: base.capsules")]
    for i, joint in enumerate(joints):
        here = f"{where}: joints[{i}]"
        if not isinstance(joint, dict):
            raise InputError(f"{here}: expected a mapping")
        names.append(str(joint.get("name", f"joint_{i + 1}")))
        origins.append(_vector(joint.get("origin"), f"{here}.origin"))
        axis = _vector(joint.get("axis"), f"{here}.axis")
        if np.linalg.norm(axis) == 0:
            raise InputError(f"{here}.axis: must not be zero")
        axes.append(axis / np.linalg.norm(axis))
        lo, hi = _vector(joint.get("limits_deg"), f"{here}.limits_deg", 2)
        if not lo < hi:
            raise InputError(f"{here}.limits_deg: lower must be below upper, got {[lo, hi]}")
        lower.append(np.radians(lo))
        upper.append(np.radians(hi))
        capsules += [(i + 1, c) for c in _capsules(joint.get("capsules"), f"{here}.capsules")]
    check = data.get("self_collision") or {}
    gap = check.get("min_joint_gap", 2)
    clearance = check.get("clearance", 0.0)
    if not isinstance(gap, int) or gap < 1:
        raise InputError(f"{where}: self_collision.min_joint_gap: expected an integer >= 1, got {gap!r}")
    if not isinstance(clearance, (int, float)) or clearance < 0:
        raise InputError(f"{where}: self_collision.clearance: expected a number >= 0, got {clearance!r}")
    link = np.array([c[0] for c in capsules])
    i, j = np.triu_indices(len(capsules), 1)
    keep = np.abs(link[i] - link[j]) >= gap
    return ArmModel(
        name=str(data.get("name", "arm")),
        names=tuple(names),
        origins=np.array(origins),
        axes=np.array(axes),
        lower=np.array(lower),
        upper=np.array(upper),
        capsule_link=link,
        capsule_a=np.array([c[1][0] for c in capsules]),
        capsule_b=np.array([c[1][1] for c in capsules]),
        capsule_radius=np.array([c[1][2] for c in capsules]),
        capsule_flat_start=np.array([c[1][3] for c in capsules]),
        pairs=np.stack([i[keep], j[keep]], 1),
        clearance=float(clearance),
    )


@lru_cache(maxsize=8)
def load_arm(path: str | Path = ARM_PATH) -> ArmModel:
    """The arm model of a robot_arm.yaml file (default: the TX90L in assets_manifest)."""
    path = Path(path)
    data = read_yaml_file(path, "arm model")
    return parse_arm(data, str(path))


def axis_rotations(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotations by ``angles (...)`` radians about unit ``axes (..., 3)`` (Rodrigues)."""
    axes = np.broadcast_to(np.asarray(axes, float), np.shape(angles) + (3,))
    x, y, z = axes[..., 0], axes[..., 1], axes[..., 2]
    c, s = np.cos(angles), np.sin(angles)
    t = 1.0 - c
    return np.stack(
        [
            np.stack([c + x * x * t, x * y * t - z * s, x * z * t + y * s], -1),
            np.stack([y * x * t + z * s, c + y * y * t, y * z * t - x * s], -1),
            np.stack([z * x * t - y * s, z * y * t + x * s, c + z * z * t], -1),
        ],
        -2,
    )


def forward(model: ArmModel, q: np.ndarray, base: np.ndarray | None = None) -> np.ndarray:
    """Link frames for joint angles ``q``: ``(..., j + 1, 4, 4)`` float64 (frame 0 the base).

    q : (..., j) radians; base : (4, 4) world pose of the base link (identity by default)
    """
    q = np.asarray(q, float)
    batch = q.shape[:-1]
    frames = np.empty(batch + (model.joints + 1, 4, 4))
    frames[..., 0, :, :] = np.eye(4) if base is None else base
    rotations = axis_rotations(model.axes, q)  # (..., j, 3, 3)
    for i in range(model.joints):
        local = np.zeros(batch + (4, 4))
        local[..., :3, :3] = rotations[..., i, :, :] if model.fixed is None else model.fixed[i] @ rotations[..., i, :, :]
        local[..., :3, 3] = model.origins[i]
        local[..., 3, 3] = 1.0
        frames[..., i + 1, :, :] = frames[..., i, :, :] @ local
    return frames


def within_limits(model: ArmModel, q: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
    """``(...)`` bool: every joint of ``q (..., j)`` lies within its limits."""
    q = np.asarray(q, float)
    return ((q >= model.lower - tolerance) & (q <= model.upper + tolerance)).all(axis=-1)


def capsules_world(model: ArmModel, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The link capsules placed by ``frames (..., j + 1, 4, 4)``: ``a (..., c, 3)``, ``b (..., c, 3)``, ``radius (c,)``."""
    f = frames[..., model.capsule_link, :, :]  # (..., c, 4, 4)
    a = np.einsum("...ij,...j->...i", f[..., :3, :3], model.capsule_a) + f[..., :3, 3]
    b = np.einsum("...ij,...j->...i", f[..., :3, :3], model.capsule_b) + f[..., :3, 3]
    return a, b, model.capsule_radius


def self_collision_gaps(model: ArmModel, frames: np.ndarray) -> np.ndarray:
    """``(..., p)`` surface gaps (metres) of the checked capsule pairs; below ``model.clearance`` is a collision."""
    from .collision import segment_distance

    a, b, r = capsules_world(model, frames)
    i, j = model.pairs[:, 0], model.pairs[:, 1]
    return segment_distance(a[..., i, :], b[..., i, :], a[..., j, :], b[..., j, :]) - r[i] - r[j]


def floor_gap(model: ArmModel, frames: np.ndarray, floor_z: float = 0.0) -> np.ndarray:
    """``(...)`` lowest height (metres) of the moving links' capsules above ``floor_z``.

    Links 2 onwards count (the base and the turret stand on the floor and never move down).
    """
    a, b, r = capsules_world(model, frames)
    moving = model.capsule_link >= 2
    low = np.minimum(a[..., moving, 2], b[..., moving, 2]) - r[moving]
    return low.min(axis=-1) - floor_z


def is_valid(model: ArmModel, q: np.ndarray, base: np.ndarray | None = None, floor_z: float | None = None) -> np.ndarray:
    """``(...)`` bool: within limits, no self-collision, and (given ``floor_z``) clear of the floor."""
    frames = forward(model, q, base)
    ok = within_limits(model, q) & (self_collision_gaps(model, frames) >= model.clearance).all(axis=-1)
    if floor_z is not None:
        ok &= floor_gap(model, frames, floor_z) >= model.clearance
    return ok


def random_configuration(model: ArmModel, rng: np.random.Generator, base: np.ndarray | None = None, floor_z: float | None = None, batch: int = 64,
                         max_batches: int = 50) -> np.ndarray:
    """``(j,)`` joint angles drawn uniformly within the limits, rejected until :func:`is_valid`.

    Draws ``batch`` candidates at a time and returns the first valid one, so the result depends
    only on ``rng``. Raises ``InputError`` when ``max_batches`` batches hold no valid pose (a
    model whose capsules always collide).
    """
    for _ in range(max_batches):
        q = rng.uniform(model.lower, model.upper, size=(batch, model.joints))
        ok = np.flatnonzero(is_valid(model, q, base, floor_z))
        if len(ok):
            return q[ok[0]]
    raise InputError(f"arm {model.name!r}: no collision-free joint configuration in {batch * max_batches} draws; check its capsules and limits")


def arm_heading(model: ArmModel, frames: np.ndarray) -> float:
    """Yaw (radians) of the arm's vertical plane: the x axis of link 1 projected on the floor."""
    x = frames[1, :3, 0]
    return float(np.arctan2(x[1], x[0]))
