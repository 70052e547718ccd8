"""A serial arm from a URDF file (as ROS-Industrial publishes robots): joints, limits and link meshes. Pure.

:func:`read_urdf` follows the chain of revolute (and continuous) joints from the root link: each
joint's ``origin`` (xyz, rpy) in its parent link's frame, its ``axis`` in its own frame and its
``limit`` (lower, upper, radians; a continuous joint: -pi..pi). Fixed joints before the first moving
one fold into the base, fixed joints after a moving one into that link. Each link's ``visual``
meshes (``package://`` and relative file names resolved against the URDF's folder) are listed with
their origin and scale; the Blender side imports them. :func:`arm_from_urdf` makes the
:class:`~.kinematics.ArmModel`: the joint frames (an rpy becomes ``ArmModel.fixed``) and one capsule
per link around its mesh (principal axis, radius to the farthest vertex) for the self-collision check.

Frames: metres, radians; the URDF's own frames (z up for ROS robots).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from .kinematics import ArmModel


@dataclass
class UrdfArm:
    """A URDF chain.

    name : the robot's name; links : link names, base first (j + 1)
    origins : (j, 3) joint positions in the parent link, m; turns : (j, 3, 3) their fixed rotations (rpy)
    axes : (j, 3) unit axes in the joint frame; lower, upper : (j,) rad
    visuals : per link, ``[(file Path, (4, 4) mesh -> link frame, scale (3,))]`` (fixed children folded in)
    """

    name: str
    links: list
    joint_names: list
    origins: np.ndarray
    turns: np.ndarray
    axes: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    visuals: list = field(default_factory=list)


def rpy_matrix(rpy) -> np.ndarray:
    """``(3, 3)`` URDF roll-pitch-yaw: Rz(yaw) @ Ry(pitch) @ Rx(roll)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def _numbers(text, where: str, count: int = 3, default=None) -> np.ndarray:
    if text is None:
        if default is None:
            raise InputError(f"{where}: missing")
        return np.asarray(default, float)
    try:
        values = np.array([float(v) for v in text.split()])
    except ValueError:
        values = np.zeros(0)
    if values.shape != (count,) or not np.isfinite(values).all():
        raise InputError(f"{where}: expected {count} numbers, got {text!r}")
    return values


def _origin(element, where: str) -> np.ndarray:
    """``(4, 4)`` of an ``<origin xyz rpy>`` child (identity when absent)."""
    m = np.eye(4)
    origin = element.find("origin") if element is not None else None
    if origin is not None:
        m[:3, :3] = rpy_matrix(_numbers(origin.get("rpy"), f"{where}.origin.rpy", default=(0, 0, 0)))
        m[:3, 3] = _numbers(origin.get("xyz"), f"{where}.origin.xyz", default=(0, 0, 0))
    return m


def _mesh_path(filename: str, folder: Path, where: str) -> Path:
    """A visual's file: ``package://pkg/rest`` looked up beside the URDF (its folder, its parents), else relative."""
    if filename.startswith("package://"):
        rest = Path(filename[len("package://"):])
        for base in (folder, *folder.parents):
            for candidate in (base / rest, base / Path(*rest.parts[1:])):
                if candidate.is_file():
                    return candidate
        raise InputError(f"{where}: mesh {filename!r} not found beside {folder}")
    path = Path(filename[len("file://"):] if filename.startswith("file://") else filename)
    path = path if path.is_absolute() else folder / path
    if not path.is_file():
        raise InputError(f"{where}: mesh {filename!r} not found ({path})")
    return path


def read_urdf(path: str | Path) -> UrdfArm:
    """The serial chain of a URDF file; ``InputError`` naming the file and element on what it cannot use."""
    path = Path(path)
    where = str(path)
    try:
        root = ET.parse(path).getroot()
    except OSError as err:
        raise InputError(f"{where}: cannot read the URDF ({err.strerror or err})") from None
    except ET.ParseError as err:
        raise InputError(f"{where}: not valid XML ({err})") from None
    if root.tag != "robot":
        raise InputError(f"{where}: expected a <robot> URDF, got <{root.tag}>")
    links = {link.get("name"): link for link in root.findall("link")}
    joints = root.findall("joint")
    children = {}
    for joint in joints:
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise InputError(f"{where}: joint {joint.get('name')!r}: needs <parent link> and <child link>")
        for end in (parent, child):
            if end.get("link") not in links:
                raise InputError(f"{where}: joint {joint.get('name')!r}: link {end.get('link')!r} is not a <link> of the file")
        children.setdefault(parent.get("link"), []).append(joint)
    child_links = {j.find("child").get("link") for j in joints}
    roots = [name for name in links if name not in child_links]
    if len(roots) != 1:
        raise InputError(f"{where}: expected one root link, found {roots}")
    chain_links, names, origins, rpys, axes, lower, upper = [roots[0]], [], [], [], [], [], []
    visuals = [[]]
    folder = path.parent

    def add_visuals(link_name: str, to_link: np.ndarray) -> None:
        for k, visual in enumerate(links[link_name].findall("visual")):
            here = f"{where}: link {link_name!r} visual[{k}]"
            mesh = visual.find("geometry/mesh")
            if mesh is None:
                continue  # primitives (box, cylinder) are left to the capsule chain
            scale = _numbers(mesh.get("scale"), f"{here}.scale", default=(1, 1, 1))
            visuals[-1].append((_mesh_path(mesh.get("filename", ""), folder, here), to_link @ _origin(visual, here), scale))

    add_visuals(roots[0], np.eye(4))
    pending = np.eye(4)  # fixed joints since the last moving one (their transform into the current link)
    current = roots[0]
    seen = {current}
    while True:
        following = children.get(current, [])
        if not following:
            break
        if len(following) > 1:
            raise InputError(f"{where}: link {current!r} has {len(following)} child joints; only a serial chain can be posed")
        joint = following[0]
        kind, name = joint.get("type"), joint.get("name")
        here = f"{where}: joint {name!r}"
        step = _origin(joint, here)
        child = joint.find("child").get("link")
        if kind == "fixed":
            pending = pending @ step
            add_visuals(child, pending)
        elif kind in ("revolute", "continuous"):
            full = pending @ step
            names.append(name)
            origins.append(full[:3, 3])
            rpys.append(full[:3, :3])
            axis = _numbers(joint.find("axis").get("xyz") if joint.find("axis") is not None else None, f"{here}.axis", default=(1, 0, 0))
            if np.linalg.norm(axis) == 0:
                raise InputError(f"{here}.axis: must not be zero")
            axes.append(axis / np.linalg.norm(axis))
            limit = joint.find("limit")
            if kind == "continuous":
                lo, hi = -np.pi, np.pi
            else:
                if limit is None or limit.get("lower") is None or limit.get("upper") is None:
                    raise InputError(f"{here}: a revolute joint needs <limit lower upper>")
                lo, hi = (_numbers(limit.get(k), f"{here}.limit.{k}", count=1)[0] for k in ("lower", "upper"))
                if not lo < hi:
                    raise InputError(f"{here}.limit: lower must be below upper, got {[lo, hi]}")
            lower.append(lo)
            upper.append(hi)
            chain_links.append(child)
            visuals.append([])
            pending = np.eye(4)
            add_visuals(child, pending)
        else:
            raise InputError(f"{here}: joint type {kind!r} cannot be posed (revolute, continuous or fixed)")
        if child in seen:
            raise InputError(f"{here}: link {child!r} comes twice along the chain (a loop); a serial chain visits each link once")
        seen.add(child)
        current = child
    if not names:
        raise InputError(f"{where}: no revolute joint: nothing to pose")
    return UrdfArm(root.get("name", path.stem), chain_links, names, np.array(origins), np.array(rpys), np.array(axes), np.array(lower), np.array(upper),
                   visuals)


def fit_capsule(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(a (3,), b (3,), radius)``: a capsule around ``vertices (n, 3)`` along their principal axis (it holds them all)."""
    v = np.asarray(vertices, float)
    centre = v.mean(axis=0)
    if len(v) < 2:
        return centre, centre, 1e-3
    _, _, vt = np.linalg.svd(v - centre, full_matrices=False)
    axis = vt[0]
    t = (v - centre) @ axis
    radial = np.linalg.norm((v - centre) - np.outer(t, axis), axis=1)
    radius = max(float(radial.max()), 1e-3)
    lo, hi = t.min() + radius, t.max() - radius
    if lo > hi:
        lo = hi = (t.min() + t.max()) / 2
    a, b = centre + lo * axis, centre + hi * axis
    # grow the radius until every vertex lies inside (the caps may miss corners)
    seg = b - a
    length2 = float(seg @ seg)
    s = np.clip(((v - a) @ seg) / length2, 0, 1) if length2 > 0 else np.zeros(len(v))
    radius = max(radius, float(np.linalg.norm(v - (a + s[:, None] * seg), axis=1).max()))
    return a, b, radius


def arm_from_urdf(urdf: UrdfArm, link_vertices: list, min_joint_gap: int = 2, clearance: float = 0.0) -> ArmModel:
    """The :class:`ArmModel` of a URDF chain; ``link_vertices``: per link ``(n, 3)`` its mesh in its own frame (may be empty)."""
    capsules = []
    for link, v in enumerate(link_vertices):
        if len(v):
            capsules.append((link, *fit_capsule(v)))
    if not capsules:
        raise InputError(f"URDF {urdf.name!r}: no link has a visual mesh")
    link = np.array([c[0] for c in capsules])
    i, j = np.triu_indices(len(capsules), 1)
    keep = np.abs(link[i] - link[j]) >= min_joint_gap
    return ArmModel(
        name=urdf.name,
        names=tuple(urdf.joint_names),
        origins=urdf.origins,
        axes=urdf.axes,
        lower=urdf.lower,
        upper=urdf.upper,
        capsule_link=link,
        capsule_a=np.array([c[1] for c in capsules]),
        capsule_b=np.array([c[2] for c in capsules]),
        capsule_radius=np.array([c[3] for c in capsules]),
        capsule_flat_start=np.zeros(len(capsules), bool),
        pairs=np.stack([i[keep], j[keep]], 1),
        clearance=clearance,
        fixed=urdf.turns,
    )


@dataclass
class MeshedArm:
    """An arm posed by :class:`ArmModel` and shown with its own link meshes: ``meshes`` per link ``(vertices, triangles)``."""

    model: ArmModel
    meshes: list

    def posed(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices, triangles)`` of the whole arm at joint angles ``q`` (rad), base frame."""
        from .kinematics import forward
        from .primitives import merge

        frames = forward(self.model, np.asarray(q, float))
        return merge([(v @ frames[k][:3, :3].T + frames[k][:3, 3], t) for k, (v, t) in enumerate(self.meshes) if len(t)])
