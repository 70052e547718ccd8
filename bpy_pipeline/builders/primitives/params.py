"""``scene.builder: primitives``: planes, boxes, spheres and cylinders at poses, for tests and calibration."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from ...schema import meta
from ...buffers import MATERIALS
from ...errors import InputError
from ..base import Builder, BuildContext, BuildResult, register_builder

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Shape:
    """One shape of the ``primitives`` builder.

    ``size``: plane and box, edge length (a number, or [x, y] / [x, y, z]); sphere, radius;
    cylinder, [radius, height]. A plane's normal is +Z before rotation; rotations are
    Blender's XYZ Euler angles in degrees. ``segments`` tessellates spheres and cylinders.
    """

    type: Literal["plane", "box", "sphere", "cylinder"]
    size: float | list[float] = field(
        default=1.0, metadata=meta("m", help="plane, box: edge length (a number or [x, y] / [x, y, z]); sphere: radius; cylinder: [radius, height]")
    )
    position: Vec3 = field(default=(0.0, 0.0, 0.0), metadata=meta("m"))
    rotation_deg: Vec3 = field(default=(0.0, 0.0, 0.0), metadata=meta("deg"))
    class_name: str = field(default="unlabeled", metadata={"key": "class"})
    material: str = "diffuse"  # one of buffers.MATERIALS
    reflectivity: float = field(default=0.5, metadata=meta("", 0, 1))
    segments: int = field(default=64, metadata=meta("", low=3, help="spheres and cylinders: segments around"))
    name: str = ""


@dataclass(frozen=True)
class PrimitivesScene:
    """``scene.builder: primitives``: a ground plane, a box and a sphere unless shapes are given."""

    shapes: list[Shape] = field(
        default_factory=lambda: [
            Shape("plane", [40.0, 40.0], class_name="ground", name="ground"),
            Shape("box", [2.0, 2.0, 2.0], (8.0, 0.0, 1.0), class_name="wall", name="box"),
            Shape("sphere", 1.0, (0.0, 8.0, 1.0), class_name="person", reflectivity=0.8, name="sphere"),
        ]
    )



SIZES = {"plane": (1, 2), "box": (1, 3), "sphere": (1,), "cylinder": (2,)}  # how many numbers a size may have


def check(params: PrimitivesScene, where: str) -> None:
    """``InputError`` naming the key of a shape's size of the wrong count or sign, or an unknown material (the fields' ranges: the schema's)."""
    for i, shape in enumerate(params.shapes):
        at = f"{where}.shapes[{i}]"
        sizes = [shape.size] if isinstance(shape.size, float) else shape.size
        want = SIZES[shape.type]
        if len(sizes) not in want or any(s <= 0 for s in sizes):
            raise InputError(f"{at}.size: a {shape.type} takes {' or '.join(map(str, want))} positive number(s), got {shape.size}")
        if shape.material not in MATERIALS:
            raise InputError(f"{at}.material: expected one of {', '.join(MATERIALS)}, got {shape.material!r}")


def build(params: PrimitivesScene, context: BuildContext) -> BuildResult:
    from . import scene as primitives

    primitives.build(params)
    return BuildResult()


register_builder("primitives", Builder(PrimitivesScene, build, check))
