"""An articulated human: a skeleton of 14 segments, joints with anatomical limits, four pose families. Pure numpy.

The person's own frame: x forward, y left, z up, origin on the floor below the hip centre.
Segment lengths follow the height ``H`` (Drillis & Contini 1966, as tabulated in Winter,
*Biomechanics and Motor Control of Human Movement*, fig. 4.1: hip 0.530 H, knee 0.285 H, ankle
0.039 H, shoulder 0.818 H, upper arm 0.186 H, forearm 0.146 H, hand 0.108 H, biacromial breadth
0.259 H, foot 0.152 H). Joint ranges are the usual adult active ranges of motion (American Academy
of Orthopaedic Surgeons: hip flexion 120-125, extension 30, abduction 45; knee flexion 135-150;
ankle dorsiflexion 20, plantarflexion 45-50; shoulder flexion 180, extension 60, abduction 180;
elbow flexion 145-150; thoracolumbar flexion 80, extension 25, lateral bend 35, rotation 45;
neck flexion and extension 45, rotation 60 degrees).

Every segment's rest frame is parallel to the person's frame (the rest pose stands upright with
arms hanging); a segment's frame is its parent's, moved to the joint and turned by the joint's
rotations, in the order the degrees of freedom are listed:

    F[root] = placement @ T(joint_root) @ J_root(angles)
    F[s]    = F[parent] @ T(joint_s - joint_parent) @ J_s(angles)

The body is a union of capsules (segment, end points in the segment's frame, radius), each
scaled by ``H`` and a build factor on the radius. The mesh Blender shows is inscribed in the
same capsules (:func:`~.collision.capsule_mesh`), so capsule tests bound the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .collision import capsule_gaps, smallest_gap

# name, parent, joint position at rest (units of H, person frame)
SEGMENTS = (
    ("pelvis", None, (0.0, 0.0, 0.52)),
    ("spine", "pelvis", (0.0, 0.0, 0.60)),
    ("head", "spine", (0.0, 0.0, 0.83)),
    ("upper_arm_l", "spine", (0.0, 0.135, 0.80)),
    ("forearm_l", "upper_arm_l", (0.0, 0.135, 0.614)),
    ("upper_arm_r", "spine", (0.0, -0.135, 0.80)),
    ("forearm_r", "upper_arm_r", (0.0, -0.135, 0.614)),
    ("thigh_l", "pelvis", (0.0, 0.085, 0.52)),
    ("shank_l", "thigh_l", (0.0, 0.085, 0.285)),
    ("foot_l", "shank_l", (0.0, 0.085, 0.039)),
    ("thigh_r", "pelvis", (0.0, -0.085, 0.52)),
    ("shank_r", "thigh_r", (0.0, -0.085, 0.285)),
    ("foot_r", "shank_r", (0.0, -0.085, 0.039)),
)
SEGMENT_NAMES = tuple(s[0] for s in SEGMENTS)
SEGMENT_INDEX = {name: i for i, name in enumerate(SEGMENT_NAMES)}
PARENT = np.array([-1 if p is None else SEGMENT_INDEX[p] for _, p, _ in SEGMENTS])
JOINT = np.array([j for _, _, j in SEGMENTS], float)  # (s, 3), units of H

# segment, degree of freedom, axis (segment frame), limits in degrees. Positive angles:
# flexion swings the limb forward (hip, shoulder, elbow), the shank backward (knee), the toes
# down (ankle, plantarflexion), the trunk and head forward; abduction moves a limb outward.
DOFS = (
    ("pelvis", "pitch", (0, 1, 0), (-15.0, 30.0)),
    ("spine", "flexion", (0, 1, 0), (-25.0, 80.0)),
    ("spine", "lateral", (1, 0, 0), (-35.0, 35.0)),
    ("spine", "twist", (0, 0, 1), (-45.0, 45.0)),
    ("head", "flexion", (0, 1, 0), (-45.0, 45.0)),
    ("head", "twist", (0, 0, 1), (-60.0, 60.0)),
    ("upper_arm_l", "flexion", (0, -1, 0), (-60.0, 180.0)),
    ("upper_arm_l", "abduction", (1, 0, 0), (0.0, 180.0)),
    ("forearm_l", "flexion", (0, -1, 0), (0.0, 145.0)),
    ("upper_arm_r", "flexion", (0, -1, 0), (-60.0, 180.0)),
    ("upper_arm_r", "abduction", (-1, 0, 0), (0.0, 180.0)),
    ("forearm_r", "flexion", (0, -1, 0), (0.0, 145.0)),
    ("thigh_l", "flexion", (0, -1, 0), (-30.0, 125.0)),
    ("thigh_l", "abduction", (1, 0, 0), (-20.0, 45.0)),
    ("shank_l", "flexion", (0, 1, 0), (0.0, 145.0)),
    ("foot_l", "flexion", (0, 1, 0), (-20.0, 45.0)),
    ("thigh_r", "flexion", (0, -1, 0), (-30.0, 125.0)),
    ("thigh_r", "abduction", (-1, 0, 0), (-20.0, 45.0)),
    ("shank_r", "flexion", (0, 1, 0), (0.0, 145.0)),
    ("foot_r", "flexion", (0, 1, 0), (-20.0, 45.0)),
)
DOF_NAMES = tuple(f"{s}.{d}" for s, d, _, _ in DOFS)
DOF_INDEX = {name: i for i, name in enumerate(DOF_NAMES)}
DOF_SEGMENT = np.array([SEGMENT_INDEX[s] for s, _, _, _ in DOFS])
DOF_AXIS = np.array([a for _, _, a, _ in DOFS], float)
LOWER = np.array([lim[0] for _, _, _, lim in DOFS])
UPPER = np.array([lim[1] for _, _, _, lim in DOFS])

# segment, a, b (segment frame, units of H), radius (units of H)
CAPSULES = (
    ("pelvis", (0.0, -0.045, 0.03), (0.0, 0.045, 0.03), 0.058),
    ("spine", (0.0, -0.045, 0.04), (0.0, -0.045, 0.17), 0.055),
    ("spine", (0.0, 0.045, 0.04), (0.0, 0.045, 0.17), 0.055),
    ("head", (0.0, 0.0, 0.0), (0.0, 0.0, 0.05), 0.028),
    ("head", (0.012, 0.0, 0.092), (0.012, 0.0, 0.11), 0.063),
    ("upper_arm_l", (0.0, 0.0, -0.01), (0.0, 0.0, -0.186), 0.024),
    ("forearm_l", (0.0, 0.0, 0.0), (0.0, 0.0, -0.146), 0.02),
    ("forearm_l", (0.0, 0.0, -0.146), (0.0, 0.0, -0.23), 0.017),
    ("upper_arm_r", (0.0, 0.0, -0.01), (0.0, 0.0, -0.186), 0.024),
    ("forearm_r", (0.0, 0.0, 0.0), (0.0, 0.0, -0.146), 0.02),
    ("forearm_r", (0.0, 0.0, -0.146), (0.0, 0.0, -0.23), 0.017),
    ("thigh_l", (0.0, 0.0, 0.0), (0.0, 0.0, -0.235), 0.045),
    ("shank_l", (0.0, 0.0, 0.0), (0.0, 0.0, -0.236), 0.031),
    ("foot_l", (-0.025, 0.0, -0.017), (0.105, 0.0, -0.017), 0.022),
    ("thigh_r", (0.0, 0.0, 0.0), (0.0, 0.0, -0.235), 0.045),
    ("shank_r", (0.0, 0.0, 0.0), (0.0, 0.0, -0.236), 0.031),
    ("foot_r", (-0.025, 0.0, -0.017), (0.105, 0.0, -0.017), 0.022),
)
CAPSULE_SEGMENT = np.array([SEGMENT_INDEX[c[0]] for c in CAPSULES])
CAPSULE_A = np.array([c[1] for c in CAPSULES], float)
CAPSULE_B = np.array([c[2] for c in CAPSULES], float)
CAPSULE_RADIUS = np.array([c[3] for c in CAPSULES], float)
SEATED_SEGMENTS = ("pelvis", "thigh_l", "thigh_r")  # what rests on a desk top
SEATED_CAPSULES = np.isin(CAPSULE_SEGMENT, [SEGMENT_INDEX[s] for s in SEATED_SEGMENTS])  # (c,) their capsules
SEATED_CAPSULES.flags.writeable = False
BUILDS = {"slim": 0.88, "medium": 1.0, "broad": 1.13}  # capsule radius factors
POSES = ("standing", "walking", "sitting", "crouching")


def _self_pairs() -> np.ndarray:
    """Capsule pairs checked for self-intersection: not the same or adjacent segments, not arm-trunk at the shoulder."""
    skip = set()
    for s, parent in enumerate(PARENT):
        if parent >= 0:
            skip.add((min(s, parent), max(s, parent)))
    spine = SEGMENT_INDEX["spine"]
    pelvis = SEGMENT_INDEX["pelvis"]
    for side in "lr":
        upper = SEGMENT_INDEX[f"upper_arm_{side}"]
        skip.add((min(upper, spine), max(upper, spine)))
        thigh = SEGMENT_INDEX[f"thigh_{side}"]
        skip.add((min(thigh, spine), max(thigh, spine)))  # hip and lower trunk meet at the pelvis
        skip.add((min(thigh, pelvis), max(thigh, pelvis)))
    skip.add((SEGMENT_INDEX["head"], SEGMENT_INDEX["upper_arm_l"]))
    skip.add((SEGMENT_INDEX["head"], SEGMENT_INDEX["upper_arm_r"]))
    pairs = []
    for i in range(len(CAPSULES)):
        for j in range(i + 1, len(CAPSULES)):
            si, sj = CAPSULE_SEGMENT[i], CAPSULE_SEGMENT[j]
            if si != sj and (min(si, sj), max(si, sj)) not in skip:
                pairs.append((i, j))
    return np.array(pairs)


SELF_PAIRS = _self_pairs()


def neutral_angles() -> np.ndarray:
    """``(k,)`` degrees: the rest pose (upright, arms hanging slightly away from the body)."""
    angles = np.zeros(len(DOFS))
    angles[DOF_INDEX["upper_arm_l.abduction"]] = 8.0
    angles[DOF_INDEX["upper_arm_r.abduction"]] = 8.0
    return angles


def within_limits(angles: np.ndarray, tolerance: float = 1e-9) -> bool:
    """True when every angle (degrees) lies within its joint's limits."""
    angles = np.asarray(angles, float)
    return bool(((angles >= LOWER - tolerance) & (angles <= UPPER + tolerance)).all())


def _chain(s: int) -> list[int]:
    """The segments from the pelvis down to segment ``s``."""
    return ([] if PARENT[s] < 0 else _chain(PARENT[s])) + [s]


# the segments by their depth in the skeleton (the pelvis, its children, theirs, ...): a level's frames need only
# the level above's, so one stacked product places a level
DEPTH = np.array([len(_chain(s)) - 1 for s in range(len(SEGMENTS))])
LEVELS = tuple(np.flatnonzero(DEPTH == d) for d in range(DEPTH.max() + 1))
OFFSET = JOINT - np.where(PARENT[:, None] >= 0, JOINT[PARENT], 0.0)  # (s, 3) each joint from its parent's, units of H
FOOT_CHAINS = {side: _chain(SEGMENT_INDEX[f"foot_{side}"]) for side in "lr"}  # pelvis, thigh, shank, foot


def _dof_rounds() -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Round ``r`` of the joint rotations: ``(segments, dofs)``, the segments with more than ``r`` degrees of freedom
    and their ``r``-th one (from 0, in the order :data:`DOFS` lists them)."""
    per_segment = [np.flatnonzero(DOF_SEGMENT == s) for s in range(len(SEGMENTS))]
    rounds = []
    for r in range(max(map(len, per_segment))):
        segments = np.array([s for s, dofs in enumerate(per_segment) if len(dofs) > r])
        rounds.append((segments, np.array([per_segment[s][r] for s in segments])))
    return tuple(rounds)


DOF_ROUNDS = _dof_rounds()


def _rodrigues_terms() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per degree of freedom and entry of its rotation (row by row, (k, 9)) the terms of
    :func:`~.kinematics.axis_rotations`: ``axis_i axis_j`` (times ``1 - cos``), the signed axis component
    (times ``sin``, 0 on the diagonal) and whether ``cos`` is added (the diagonal)."""
    x, y, z = DOF_AXIS.T
    zero = np.zeros_like(x)
    pairs = np.stack([x * x, x * y, x * z, y * x, y * y, y * z, z * x, z * y, z * z], 1)
    signed = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], 1)  # a - b s is a + (-b) s, bit for bit
    return pairs, signed, np.tile(np.eye(3, dtype=bool).ravel(), (len(DOFS), 1))


DOF_PAIRS, DOF_SIGNED, DOF_DIAGONAL = _rodrigues_terms()


def dof_rotations(angles: np.ndarray) -> np.ndarray:
    """``(k, 3, 3)`` each degree of freedom's rotation about its axis by ``angles (k,)`` degrees: the numbers of
    :func:`~.kinematics.axis_rotations` (``c + a_i a_i t`` on the diagonal, ``a_i a_j t -+ a_k s`` off it, ``t = 1 - c``),
    every entry in one array expression."""
    radians = np.radians(np.asarray(angles, float))
    c, s = np.cos(radians)[:, None], np.sin(radians)[:, None]
    pairs = DOF_PAIRS * (1.0 - c)
    return (pairs + np.where(DOF_DIAGONAL, c, DOF_SIGNED * s)).reshape(-1, 3, 3)


def joint_rotations(angles: np.ndarray) -> np.ndarray:
    """``(s, 3, 3)`` joint rotation of each segment for ``angles (k,)`` in degrees.

    Each segment's is the identity times its degrees of freedom's rotations in their listed order; the products of
    one round (every segment's first, second, third degree of freedom) are one stacked ``matmul``, the same
    3 x 3 products as one at a time.
    """
    per_dof = dof_rotations(angles)  # (k, 3, 3)
    out = np.repeat(np.eye(3)[None], len(SEGMENTS), axis=0)
    for segments, dofs in DOF_ROUNDS:
        out[segments] = out[segments] @ per_dof[dofs]
    return out


def _locals(rotations: np.ndarray, height: float) -> np.ndarray:
    """``(s, 4, 4)`` each segment's frame in its parent's: turned by ``rotations (s, 3, 3)``, at its joint (``height`` m)."""
    local = np.zeros((len(SEGMENTS), 4, 4))
    local[:, :3, :3] = rotations
    local[:, :3, 3] = OFFSET * height
    local[:, 3, 3] = 1.0
    return local


def _frames(rotations: np.ndarray, height: float, placement: np.ndarray | None = None) -> np.ndarray:
    """:func:`segment_frames` from the segments' joint ``rotations (s, 3, 3)``: one stacked product per level of :data:`LEVELS`."""
    local = _locals(rotations, height)
    frames = np.empty((len(SEGMENTS), 4, 4))
    base = np.eye(4) if placement is None else np.asarray(placement, float)
    frames[LEVELS[0]] = base @ local[LEVELS[0]]
    for level in LEVELS[1:]:
        frames[level] = frames[PARENT[level]] @ local[level]
    return frames


def segment_frames(angles: np.ndarray, height: float, placement: np.ndarray | None = None) -> np.ndarray:
    """``(s, 4, 4)`` world frames of the segments for ``angles (k,)`` degrees and a person ``height`` (m).

    placement : (4, 4) the person's frame in the world (identity by default)
    """
    return _frames(joint_rotations(angles), height, placement)


def capsules(frames: np.ndarray, height: float, build: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The body's capsules placed by ``frames``: ``a (c, 3)``, ``b (c, 3)``, ``radius (c,)``, metres."""
    f = frames[CAPSULE_SEGMENT]
    a = np.einsum("cij,cj->ci", f[:, :3, :3], CAPSULE_A * height) + f[:, :3, 3]
    b = np.einsum("cij,cj->ci", f[:, :3, :3], CAPSULE_B * height) + f[:, :3, 3]
    return a, b, CAPSULE_RADIUS * height * build


def self_gap(angles: np.ndarray, height: float = 1.0, build: float = 1.0) -> float:
    """Smallest surface gap (metres) between the body's own non-adjacent capsules."""
    a, b, r = capsules(segment_frames(angles, height), height, build)
    return smallest_gap(a, b, r, SELF_PAIRS)


def _level_feet(angles: np.ndarray) -> np.ndarray:
    """Set the ankles so each foot's sole is level (within the ankle's limits); returns new angles.

    A foot's frame is placed with its ankle at 0 degrees through its chain only (pelvis, thigh, shank, foot:
    the products :func:`segment_frames` makes for them).
    """
    feet = [DOF_INDEX[f"foot_{side}.flexion"] for side in "lr"]
    flat = angles.copy()
    flat[feet] = 0.0
    local = _locals(joint_rotations(flat), 1.0)
    angles = angles.copy()
    for side, k in zip("lr", feet):
        frame = np.eye(4)
        for s in FOOT_CHAINS[side]:
            frame = frame @ local[s]
        forward = frame[:3, 0]
        pitch_down = np.degrees(np.arctan2(-forward[2], np.hypot(forward[0], forward[1])))  # toes below heel > 0
        angles[k] = min(max(-pitch_down, LOWER[k]), UPPER[k])  # np.clip's numbers, without its array set-up
    return angles


def _uniform(rng, ranges: dict) -> np.ndarray:
    angles = neutral_angles()
    for name, (lo, hi) in ranges.items():
        angles[DOF_INDEX[name]] = rng.uniform(lo, hi)
    return angles


def _both(name: str, lo: float, hi: float) -> dict:
    return {name.replace("*", "l"): (lo, hi), name.replace("*", "r"): (lo, hi)}


def sample_pose(kind: str, rng: np.random.Generator, build: float = max(BUILDS.values()), tries: int = 100) -> np.ndarray:
    """``(k,)`` joint angles in degrees for a pose family, drawn from ``rng``, within the limits and free of self-intersection.

    kind : ``standing``, ``walking`` (a random phase of the gait cycle), ``sitting`` (on a desk edge,
        thighs level, shanks hanging) or ``crouching``. Ankles are set so the soles are level
        where the ankle's range allows (a deep crouch lifts the heels).
    build : capsule radius factor the body must be free of self-intersection at (gaps scale with
        the height, so any height will do); draws are repeated up to ``tries`` times, then the
        neutral standing pose is returned.
    """
    if kind not in POSES:
        raise ValueError(f"unknown pose {kind!r}; allowed: {', '.join(POSES)}")
    for _ in range(tries):
        angles = _draw_pose(kind, rng)
        if self_gap(angles, 1.0, build) >= 0.0:
            return angles
    return _level_feet(neutral_angles())


def _draw_pose(kind: str, rng: np.random.Generator) -> np.ndarray:
    trunk = {"spine.lateral": (-6, 6), "spine.twist": (-12, 12), "head.twist": (-40, 40)}
    if kind == "standing":
        angles = _uniform(rng, trunk | {"pelvis.pitch": (-3, 5), "spine.flexion": (-5, 12), "head.flexion": (-15, 25)}
                          | _both("upper_arm_*.flexion", -15, 35) | _both("upper_arm_*.abduction", 6, 25)
                          | _both("forearm_*.flexion", 5, 70) | _both("thigh_*.flexion", -4, 8)
                          | _both("thigh_*.abduction", 0, 7) | _both("shank_*.flexion", 0, 8))
    elif kind == "walking":
        angles = _uniform(rng, trunk | {"pelvis.pitch": (0, 6), "spine.flexion": (0, 8), "head.flexion": (-10, 20)}
                          | _both("upper_arm_*.abduction", 6, 14) | _both("thigh_*.abduction", 0, 5))
        phase = rng.uniform(0.0, 2 * np.pi)
        for side, shift in (("l", 0.0), ("r", np.pi)):
            p = phase + shift
            angles[DOF_INDEX[f"thigh_{side}.flexion"]] = 8.0 + 20.0 * np.sin(p)  # -12 .. 28 degrees
            angles[DOF_INDEX[f"shank_{side}.flexion"]] = 8.0 + 26.0 * max(0.0, np.sin(p + 0.9 * np.pi))  # swing-phase knee bend
            angles[DOF_INDEX[f"upper_arm_{side}.flexion"]] = -18.0 * np.sin(p)  # arms swing against the legs
            angles[DOF_INDEX[f"forearm_{side}.flexion"]] = 15.0 + 15.0 * max(0.0, -np.sin(p))
    elif kind == "sitting":
        angles = _uniform(rng, trunk | {"pelvis.pitch": (-10, 0), "spine.flexion": (5, 20), "head.flexion": (0, 25)}
                          | _both("upper_arm_*.flexion", 0, 45) | _both("upper_arm_*.abduction", 8, 25)
                          | _both("forearm_*.flexion", 30, 100) | _both("thigh_*.abduction", 2, 12)
                          | _both("shank_*.flexion", 70, 100))
        for side in "lr":  # thighs level on the desk: hip flexion undoes the pelvis tilt
            angles[DOF_INDEX[f"thigh_{side}.flexion"]] = 90.0 + angles[DOF_INDEX["pelvis.pitch"]]
    elif kind == "crouching":
        angles = _uniform(rng, trunk | {"pelvis.pitch": (5, 20), "spine.flexion": (10, 35), "head.flexion": (-30, 0)}
                          | _both("upper_arm_*.flexion", 35, 80) | _both("upper_arm_*.abduction", 12, 35)
                          | _both("forearm_*.flexion", 20, 90) | _both("thigh_*.abduction", 15, 30))
        hip = rng.uniform(95, 115)
        knee = rng.uniform(115, 140)
        for side in "lr":
            angles[DOF_INDEX[f"thigh_{side}.flexion"]] = hip + rng.uniform(-4, 4)
            angles[DOF_INDEX[f"shank_{side}.flexion"]] = knee + rng.uniform(-4, 4)
    angles = np.clip(angles, LOWER, UPPER)
    if kind != "sitting":
        angles = _level_feet(angles)
    return angles


@dataclass
class Person:
    """One posed person in the world.

    angles : (k,) degrees; height : m; build : capsule radius factor; pose : the pose family
    placement : (4, 4) the person's frame (origin on the supporting surface below the hip
        centre, z up, yaw only) in the world
    frames : (s, 4, 4) segment frames, world
    a, b, radius : the body's capsules, world, metres
    support : (3,) the lowest point of the body (on the floor, or on the desk top when sitting)
    """

    angles: np.ndarray
    height: float
    build: float
    pose: str
    placement: np.ndarray
    frames: np.ndarray
    a: np.ndarray
    b: np.ndarray
    radius: np.ndarray
    support: np.ndarray

    @property
    def yaw(self) -> float:
        return float(np.arctan2(self.placement[1, 0], self.placement[0, 0]))


def pose_person(angles: np.ndarray, height: float, build: float, pose: str, position_xy, yaw: float, support_z: float = 0.0) -> Person:
    """Place a posed body: rotate by ``yaw`` about z at ``position_xy`` and lower it onto ``support_z``.

    The body comes to rest with its lowest capsule point on ``support_z`` (standing, walking,
    crouching: the floor), or with the lowest point of its pelvis and thighs on it (sitting).
    """
    rotations = joint_rotations(angles)
    a, b, r = capsules(_frames(rotations, height), height, build)
    rests = SEATED_CAPSULES if pose == "sitting" else np.ones(len(r), bool)
    bottoms = np.minimum(a[:, 2], b[:, 2]) - r
    lift = support_z - bottoms[rests].min()
    placement = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    placement[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    placement[:3, 3] = [position_xy[0], position_xy[1], lift]
    frames = _frames(rotations, height, placement)
    a, b, r = capsules(frames, height, build)
    low = np.argmin(np.where(rests, np.minimum(a[:, 2], b[:, 2]) - r, np.inf))
    end = a[low] if a[low, 2] <= b[low, 2] else b[low]
    support = np.array([end[0], end[1], end[2] - r[low]])
    return Person(np.asarray(angles, float), float(height), float(build), pose, placement, frames, a, b, r, support)


def pose_people(angles: np.ndarray, heights, builds, poses, positions_xy, yaws, supports_z) -> list[Person]:
    """:func:`pose_person` of ``n`` people at once, the same numbers: ``angles (n, k)`` degrees, ``heights (n,)`` m,
    ``builds (n,)``, ``poses`` (n pose families), ``positions_xy (n, 2)`` m, ``yaws (n,)`` radians, ``supports_z (n,)`` m.

    Each level's frames and each capsule's ends are one stacked product over every person (the same 4 x 4 and
    3 x 3 products as one person at a time): a street frame poses its pedestrians and riders together.
    """
    n = len(poses)
    if n == 0:
        return []
    angles = np.asarray(angles, float).reshape(n, -1)
    heights = np.asarray(heights, float).reshape(n)
    builds = np.asarray(builds, float).reshape(n)
    rotations = np.stack([joint_rotations(row) for row in angles])  # (n, s, 3, 3)
    local = np.zeros((n, len(SEGMENTS), 4, 4))
    local[:, :, :3, :3] = rotations
    local[:, :, :3, 3] = OFFSET[None] * heights[:, None, None]
    local[:, :, 3, 3] = 1.0
    ends_a = CAPSULE_A[None] * heights[:, None, None]  # (n, c, 3) in each capsule's segment frame, m
    ends_b = CAPSULE_B[None] * heights[:, None, None]
    radius = CAPSULE_RADIUS[None] * heights[:, None] * builds[:, None]  # (n, c)

    def place(base: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        frames = np.empty((n, len(SEGMENTS), 4, 4))
        frames[:, LEVELS[0]] = base[:, None] @ local[:, LEVELS[0]]
        for level in LEVELS[1:]:
            frames[:, level] = frames[:, PARENT[level]] @ local[:, level]
        f = frames[:, CAPSULE_SEGMENT].reshape(-1, 4, 4)
        a = np.einsum("cij,cj->ci", f[:, :3, :3], ends_a.reshape(-1, 3)) + f[:, :3, 3]
        b = np.einsum("cij,cj->ci", f[:, :3, :3], ends_b.reshape(-1, 3)) + f[:, :3, 3]
        return frames, a.reshape(n, -1, 3), b.reshape(n, -1, 3)

    _, a, b = place(np.broadcast_to(np.eye(4), (n, 4, 4)))
    rests = np.array([SEATED_CAPSULES if pose == "sitting" else np.ones(len(CAPSULES), bool) for pose in poses])  # (n, c)
    bottoms = np.minimum(a[..., 2], b[..., 2]) - radius
    placements = np.zeros((n, 4, 4))
    for i, (xy, yaw, support_z) in enumerate(zip(positions_xy, yaws, supports_z)):
        c, s = np.cos(yaw), np.sin(yaw)
        placements[i, :3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
        placements[i, :3, 3] = [xy[0], xy[1], support_z - bottoms[i][rests[i]].min()]
        placements[i, 3, 3] = 1.0
    frames, a, b = place(placements)
    out = []
    for i in range(n):
        low = np.argmin(np.where(rests[i], np.minimum(a[i, :, 2], b[i, :, 2]) - radius[i], np.inf))
        end = a[i, low] if a[i, low, 2] <= b[i, low, 2] else b[i, low]
        support = np.array([end[0], end[1], end[2] - radius[i, low]])
        out.append(Person(angles[i].copy(), float(heights[i]), float(builds[i]), poses[i], placements[i], frames[i], a[i], b[i], radius[i], support))
    return out


def seat_offset(angles: np.ndarray, height: float, build: float, margin: float = 0.02) -> float:
    """How far in front of the hip centre (metres, person frame) a desk edge must be for a seated pose.

    The shanks and feet hang ``margin`` metres in front of the edge; pelvis and thighs rest on the top.
    """
    frames = segment_frames(angles, height)
    a, b, r = capsules(frames, height, build)
    hanging = np.isin(CAPSULE_SEGMENT, [SEGMENT_INDEX[s] for s in ("shank_l", "shank_r", "foot_l", "foot_r")])
    return float((np.minimum(a[hanging, 0], b[hanging, 0]) - r[hanging]).min() - margin)


def people_overlap(p: Person, q: Person, clearance: float = 0.0) -> bool:
    """True when two people's bodies come closer than ``clearance`` (metres)."""
    reach = np.linalg.norm(p.placement[:2, 3] - q.placement[:2, 3])
    if reach > (p.height + q.height) * 0.7 + clearance:  # a body never reaches farther than 0.7 H from its origin
        return False
    return bool((capsule_gaps(p.a, p.b, p.radius, q.a, q.b, q.radius) < clearance).any())


def body_mesh(a: np.ndarray, b: np.ndarray, radius: np.ndarray, segments: int = 10, rings: int = 3):
    """The body's mesh from its capsules: ``(vertices (n, 3), triangles (m, 3), capsule (n,) int)``.

    One closed capsule mesh per capsule (:func:`~.collision.capsule_mesh`), inscribed in it;
    ``capsule`` gives each vertex's capsule (so :data:`CAPSULE_SEGMENT` gives its segment).
    """
    from .collision import capsule_meshes

    vertices, triangles = capsule_meshes(a, b, radius, segments, rings)  # (c, n, 3), (m, 3)
    count, per = vertices.shape[:2]
    shifted = triangles[None] + (np.arange(count) * per)[:, None, None]
    return vertices.reshape(-1, 3), shifted.reshape(-1, 3).astype(np.int32), np.repeat(np.arange(count), per)


def body_meshes(people: list[Person], segments: int = 10, rings: int = 3) -> list[tuple[np.ndarray, np.ndarray]]:
    """``[(vertices (n, 3), triangles (m, 3) int32)]``: each person's :func:`body_mesh`, the same numbers, every capsule
    of every person meshed in one :func:`~.collision.capsule_meshes` call."""
    if not people:
        return []
    from .collision import capsule_meshes

    a = np.concatenate([p.a for p in people])
    b = np.concatenate([p.b for p in people])
    vertices, triangles = capsule_meshes(a, b, np.concatenate([p.radius for p in people]), segments, rings)  # (P c, n, 3), (m, 3)
    count, per = len(people[0].a), vertices.shape[1]
    shifted = (triangles[None] + (np.arange(count) * per)[:, None, None]).reshape(-1, 3).astype(np.int32)
    flat = vertices.reshape(len(people), count * per, 3)
    return [(flat[i], shifted.copy()) for i in range(len(people))]
