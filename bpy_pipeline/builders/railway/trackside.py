"""Trackside objects of a railway: fences, signals and platforms, as triangle meshes in world metres. Pure numpy.

Placed along the alignment of a :class:`~.railway_layout.RailwayLayout` from the ``scene.trackside``
config (``bpy_pipeline.builders.railway.RailwayTrackside``), drawing only from the run's generator:

- **fences** on both sides, ``fence_offset`` m beyond the outermost track centres: posts every
  ``fence_post_spacing`` m and three horizontal rails, ``fence_height`` m over the ground there;
- **signals** every ``signal_spacing`` m (+- a quarter of it) on ``signal_side``, 3.2 m from their
  track's centre: a mast of 0.14 m, ``signal_height`` m, with a 0.35 x 0.25 x 1.0 m head facing
  oncoming trains (a mast support is moved out of the way: the signal yields 3 m when closer);
- a **platform** of ``platform_length`` m at ``platform_chainage`` (its middle; < 0: the line's middle)
  on ``platform_side``: its edge ``platform_edge`` m from its track's centre (1.65-1.70 m on European
  lines), ``platform_width`` m wide, its top ``platform_height`` m above the rails (0.55 or 0.76 m).
Meshes follow the curve: long parts are swept through the alignment's frames every <= 2 m.
"""

from __future__ import annotations

import numpy as np

from ...geometry import primitives
from .parts import bar, tube


def _sweep(alignment, s0: float, s1: float, profile_yz: np.ndarray):
    """A closed prism whose (k, 2) (lateral, height) ``profile_yz`` (counter-clockwise) runs from chainage s0 to s1."""
    s = np.linspace(s0, s1, max(2, int(np.ceil((s1 - s0) / 2.0)) + 1))
    frames = alignment.frames(s)
    k = len(profile_yz)
    rings = np.einsum("nij,kj->nki", frames[:, :3, 1:3], profile_yz) + frames[:, None, :3, 3]  # (n, k, 3)
    vertices = rings.reshape(-1, 3)
    faces = []
    for i in range(len(s) - 1):
        for j in range(k):
            a, b = i * k + j, i * k + (j + 1) % k
            c, d = a + k, b + k
            faces += [(a, b, d), (a, d, c)]
    cap = [(0, j, j + 1) for j in range(1, k - 1)]
    last = (len(s) - 1) * k
    faces += [(c, b, a) for a, b, c in cap] + [(last + a, last + b, last + c) for a, b, c in cap]
    return vertices, np.asarray(faces, np.int32)


def platform(alignment, surface_at, params, rail_top: float, track_offset: float):
    """The platform mesh, or ``None`` (``platform_length`` 0)."""
    p = params
    if p.platform_length <= 0:
        return None
    middle = alignment.length / 2 if p.platform_chainage < 0 else p.platform_chainage
    s0, s1 = max(0.0, middle - p.platform_length / 2), min(alignment.length, middle + p.platform_length / 2)
    sign = 1.0 if p.platform_side == "left" else -1.0
    edge = track_offset + sign * p.platform_edge
    far = edge + sign * p.platform_width
    bottom = float(min(surface_at(edge), surface_at(far))) - 0.2
    top = rail_top + p.platform_height
    y0, y1 = sorted((edge, far))
    profile = np.array([[y0, bottom], [y1, bottom], [y1, top], [y0, top]])
    return _sweep(alignment, s0, s1, profile)


def fence(alignment, surface_at, params, lateral: float):
    """A fence ``lateral`` m beside the alignment over its whole length: posts and three rails."""
    p = params
    s = np.arange(0.0, alignment.length + 1e-9, p.fence_post_spacing)
    base = float(surface_at(lateral))
    frames = alignment.frames(s, lateral, base)
    parts = [primitives.translated(primitives.box(0.06, 0.06, p.fence_height), f[:3, 3] + np.array([0, 0, p.fence_height / 2])) for f in frames]
    for h in (0.25, 0.55, 0.9):
        z = h * p.fence_height
        ends = frames[:, :3, 3] + np.array([0.0, 0.0, z])
        parts += [bar(a, b, 0.03) for a, b in zip(ends[:-1], ends[1:])]
    return primitives.merge(parts)


def signal_chainages(length: float, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """``(k,)`` chainages (m) of signals every ``spacing`` +- spacing / 4 along ``length`` (none for spacing 0)."""
    if spacing <= 0:
        return np.zeros(0)
    out, s = [], spacing / 2
    while s < length:
        out.append(s + rng.uniform(-spacing / 4, spacing / 4))
        s += spacing
    return np.clip(np.asarray(out), 0.0, length)


def signal_frames(layout, params, rng: np.random.Generator) -> np.ndarray:
    """``(k, 4, 4)`` level frames of the signals (see the module docstring), kept 3 m clear of every support."""
    p = params
    chainages = signal_chainages(layout.alignment.length, p.signal_spacing, rng)
    supports = np.array([s.chainage for s in layout.supports])
    for i, s in enumerate(chainages):
        if len(supports) and np.abs(supports - s).min() < 3.0:
            near = supports[np.argmin(np.abs(supports - s))]
            chainages[i] = near + 3.0 if near + 3.0 <= layout.alignment.length else near - 3.0
    offsets = layout.section.offsets
    lateral = offsets[0] - 3.2 if p.signal_side == "right" else offsets[-1] + 3.2
    base = float(layout.section.surface(lateral))
    return layout.alignment.frames(chainages, lateral, base)


def signal(frame: np.ndarray, height: float, facing: float):
    """A signal in the level ``frame`` (4, 4): mast up to ``height``, head at its top facing ``facing`` (+1 ahead, -1 back)."""
    mast = tube((0.0, 0.0, 0.0), (0.0, 0.0, height), 0.07, 8)
    head = primitives.translated(primitives.box(0.25, 0.35, 1.0), (facing * 0.2, 0.0, height - 0.5))
    v, t = primitives.merge([mast, head])
    return v @ frame[:3, :3].T + frame[:3, 3], t


def vegetation(alignment, surface_at, params, inner: float, outer: float, rng: np.random.Generator):
    """Trees and bushes on both sides between ``inner`` and ``outer`` m from the alignment, ``vegetation_per_100m``
    plants per side and 100 m: a third trees (a trunk of 0.15-0.3 m and a crown of 1.5-3 m radius, 5-12 m tall),
    the rest bushes (a 0.5-1.5 m ball on the ground); ``None`` when there are none."""
    p = params
    count = int(round(p.vegetation_per_100m * alignment.length / 100.0))
    if count <= 0 or outer <= inner:
        return None
    parts = []
    for sign in (-1.0, 1.0):
        s = rng.uniform(0.0, alignment.length, count)
        lateral = sign * rng.uniform(inner, outer, count)
        tree = rng.random(count) < 1 / 3
        size = rng.uniform(0.0, 1.0, count)
        base = alignment.offset(s, lateral, 0.0)
        for k in range(count):
            ground = base[k] + np.array([0.0, 0.0, float(surface_at(lateral[k]))])
            if tree[k]:
                height = 5.0 + 7.0 * size[k]
                crown = 1.5 + 1.5 * size[k]
                parts.append(tube(ground, ground + np.array([0.0, 0.0, height - crown]), 0.15 + 0.15 * size[k], 8))
                parts.append(primitives.translated(primitives.uv_sphere(crown, 12), ground + np.array([0.0, 0.0, height - crown])))
            else:
                radius = 0.5 + 1.0 * size[k]
                parts.append(primitives.translated(primitives.uv_sphere(radius, 10), ground + np.array([0.0, 0.0, 0.6 * radius])))
    return primitives.merge(parts)
