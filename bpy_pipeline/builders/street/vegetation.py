"""Trees, bushes and hedges as a LiDAR sees them: trunks and porous foliage. Pure numpy.

Real foliage is not a surface. A beam meets leaves and twigs anywhere inside a crown, passes
through gaps, and returns from the crown's outside and inside alike: a real tree gives a
scattered, volumetric cloud, where a solid ball would give a clean shell that no real scan has.
So a crown here is a cloud of small *leaf cards* (quads ``card`` metres across, turned at
random) filling its volume, denser towards its outside, with ``density`` cards per cubic
metre: a beam crossing a crown of diameter ``d`` meets on average about
``density * card**2 / 2 * d`` cards, so crowns are porous at their edges and mostly opaque
through their middle, as leafy crowns are.

Meshes are ``(vertices (n, 3) float64, triangles (m, 3) int32)`` in metres, world frame, z up.
Every function draws only from the ``rng`` it is given.
"""

from __future__ import annotations

import math

import numpy as np

from ...geometry import primitives

Mesh = tuple[np.ndarray, np.ndarray]

CROWN_SHAPES = ("round", "oval", "cone", "column")


def leaf_cards(centres: np.ndarray, card: float, rng: np.random.Generator) -> Mesh:
    """Square cards of edge ``card`` (m) centred on ``centres`` (n, 3), each turned at random.

    Returns a mesh of ``4 n`` vertices and ``2 n`` triangles.
    """
    centres = np.asarray(centres, float).reshape(-1, 3)
    n = len(centres)
    normal = rng.normal(size=(n, 3))
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    helper = np.where(np.abs(normal[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(normal, u)
    h = card / 2.0
    corners = np.stack([centres - h * u - h * v, centres + h * u - h * v, centres + h * u + h * v, centres - h * u + h * v], axis=1)
    base = 4 * np.arange(n, dtype=np.int32)[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    return corners.reshape(-1, 3), triangles.astype(np.int32)


def crown_points(shape: str, centre, radius: float, height: float, count: int, rng: np.random.Generator) -> np.ndarray:
    """``(count, 3)`` points filling a crown of ``shape`` around ``centre`` (3,), denser towards its outside.

    round / oval: an ellipsoid of horizontal ``radius`` and vertical semi-axis ``height / 2``;
    cone: a cone of base ``radius`` at the bottom of ``height``; column: a narrow ellipsoid.
    """
    direction = rng.normal(size=(count, 3))
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    depth = rng.random(count) ** 0.35  # mostly near the outside: leaves grow towards the light
    centre = np.asarray(centre, float)
    if shape == "cone":
        z = rng.random(count) ** 1.5  # 0 at the base, 1 at the tip; more cards low in the crown
        reach = radius * (1.0 - z) * depth
        angle = rng.uniform(0.0, 2 * math.pi, count)
        return centre + np.column_stack([reach * np.cos(angle), reach * np.sin(angle), (z - 0.5) * height])
    return centre + direction * depth[:, None] * np.array([radius, radius, height / 2.0])


def crown_volume(shape: str, radius: float, height: float) -> float:
    """The crown's volume (m^3)."""
    if shape == "cone":
        return math.pi * radius**2 * height / 3.0
    return 4.0 / 3.0 * math.pi * radius**2 * height / 2.0


def crown_size(shape: str, height: float, crown_radius: float, clear_below: float = 1.5) -> tuple[float, float]:
    """``(radius, crown_height)`` (m) of the crown of a tree ``height`` tall with ``crown_radius``: the crown
    takes the upper part of the height (a cone or column more of it) and hangs no lower than ``clear_below``."""
    if shape not in CROWN_SHAPES:
        raise ValueError(f"crown shape {shape!r}; allowed: {', '.join(CROWN_SHAPES)}")
    crown_height = {"round": 1.1 * 2 * crown_radius, "oval": 1.5 * 2 * crown_radius, "cone": 0.75 * height, "column": 0.7 * height}[shape]
    crown_height = min(crown_height, 0.8 * height, height - clear_below)
    radius = crown_radius if shape != "column" else min(crown_radius, 0.2 * crown_height)
    return radius, crown_height


def crown(shape: str, radius: float, crown_height: float, rng: np.random.Generator, density: float = 6.0, card: float = 0.4) -> Mesh:
    """Foliage of a crown of ``shape``, ``radius`` and ``crown_height`` (m) centred on the origin, at ``density``
    cards of edge ``card`` (m) per m^3."""
    count = max(8, int(density * crown_volume(shape, radius, crown_height)))
    return leaf_cards(crown_points(shape, np.zeros(3), radius, crown_height, count, rng), card, rng)


def default_trunk_radius(height: float) -> float:
    """The default trunk radius (m) of a tree ``height`` tall: 4 % of it, at least 0.08 m."""
    return max(0.08, 0.04 * height)


def tree(base, height: float, crown_radius: float, shape: str, rng: np.random.Generator,
         density: float = 6.0, card: float = 0.4, trunk_radius: float | None = None, clear_below: float = 1.5) -> tuple[Mesh, Mesh]:
    """``(trunk, crown)`` of a tree standing at ``base`` (3,), ``height`` (m) tall to the crown's top.

    The crown (:func:`crown_size`) has its foliage at ``density`` cards per m^3; the trunk (8-sided,
    ``trunk_radius`` default :func:`default_trunk_radius`) reaches from 0.2 m under the ground into the
    crown's middle, so it is seen between the leaves as real trunks are. No foliage hangs lower
    than ``clear_below`` (m) above ``base`` (a street tree's crown clears the traffic under it).
    """
    base = np.asarray(base, float)
    radius, crown_height = crown_size(shape, height, crown_radius, clear_below)
    top = height - crown_height / 2.0
    leaves = primitives.translated(crown(shape, radius, crown_height, rng, density, card), base + [0.0, 0.0, top])
    r = default_trunk_radius(height) if trunk_radius is None else trunk_radius
    trunk = primitives.translated(primitives.cylinder(r, top + 0.2, 8), base + [0.0, 0.0, (top - 0.2) / 2.0])
    return trunk, leaves


def bush(base, radius: float, height: float, rng: np.random.Generator, density: float = 14.0, card: float = 0.3) -> Mesh:
    """Foliage of a bush: an ellipsoid of ``radius`` and ``height`` (m) resting on ``base`` (3,)."""
    centre = np.asarray(base, float) + [0.0, 0.0, height / 2.0]
    count = max(8, int(density * crown_volume("round", radius, height)))
    return leaf_cards(crown_points("round", centre, radius, height, count, rng), card, rng)


def hedge(start, end, width: float, height: float, rng: np.random.Generator, density: float = 30.0, card: float = 0.25) -> Mesh:
    """Foliage of a hedge from ``start`` to ``end`` ((3,) on the ground), ``width`` x ``height`` (m).

    Cards fill the hedge's box, most of them in its outer 30 cm (a clipped hedge is dense at its faces).
    """
    start, end = np.asarray(start, float), np.asarray(end, float)
    axis = end - start
    length = float(np.linalg.norm(axis[:2]))
    if length < 1e-6:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int32)
    along = axis / max(float(np.linalg.norm(axis)), 1e-12)
    across = np.array([-along[1], along[0], 0.0]) / max(math.hypot(along[0], along[1]), 1e-12)
    count = max(8, int(density * length * width * height))
    s = rng.random(count) * length
    # lateral and vertical offsets pushed towards the faces: |x|^0.4 keeps most cards near the outside
    lateral = np.sign(rng.random(count) - 0.5) * rng.random(count) ** 0.4 * (width / 2.0)
    z = height * (1.0 - rng.random(count) ** 2.5)
    centres = start + s[:, None] * along + lateral[:, None] * across + z[:, None] * [0.0, 0.0, 1.0]
    return leaf_cards(centres, card, rng)
