"""The parking paper's noise injections (its section 3.3), seeded and off by default, for ablation.

They act on the inserted objects' returns (class flips on every point). What the exact
per-firing cast already gives, and so what these only add on top:

- *dropout* and *range noise per object*: the sensor's own drop and noise models fitted with
  ``python -m bpy_pipeline fit`` (``effects.drop`` / ``effects.noise`` with ``model_file``) apply to
  inserted points per firing; the paper's per-object draws are a coarser stand-in;
- *vertical cut-off* (simulated occlusion): the cast occludes objects by the real returns in
  front of them, firing by firing, so real occlusion needs no simulation;
- *random interior points*: the project's cars have interiors (seats, dashboard) seen through
  glass windows, which the paper's CAD models lacked. Injected points are still put on real
  firings (the nearest firing's direction) and kept only where nearer than its return, so no
  firing gets a second return;
- *class flips*: annotation noise, not a sensor effect; nothing replaces it.
"""

from __future__ import annotations

import numpy as np

from .firings import Firings
from .section import NoiseInjections


def object_dropout(instance: np.ndarray, objects: np.ndarray, section: NoiseInjections, rng: np.random.Generator) -> np.ndarray:
    """``(p,)`` bool, True for inserted returns kept: per object a probability from U(0, dropout_max)."""
    if section.dropout_max <= 0:
        return np.ones(len(instance), bool)
    p = dict(zip(objects.tolist(), rng.uniform(0.0, section.dropout_max, len(objects))))
    prob = np.array([p[i] for i in instance.tolist()])
    return rng.random(len(instance)) >= prob


def object_range_noise(instance: np.ndarray, objects: np.ndarray, section: NoiseInjections, rng: np.random.Generator) -> np.ndarray:
    """``(p,)`` metres to add along the beam: per object a sigma from U(range_sigma)."""
    lo, hi = section.range_sigma
    if hi <= 0:
        return np.zeros(len(instance))
    sigma = dict(zip(objects.tolist(), rng.uniform(lo, hi, len(objects))))
    return rng.standard_normal(len(instance)) * np.array([sigma[i] for i in instance.tolist()])


def vertical_cutoff(xyz: np.ndarray, instance: np.ndarray, objects: np.ndarray, section: NoiseInjections, rng: np.random.Generator) -> np.ndarray:
    """``(p,)`` bool kept: an object is cut with ``cutoff_probability``, losing a U(cutoff_fraction) share of its
    returns on one side of a vertical plane at a random horizontal heading."""
    keep = np.ones(len(instance), bool)
    if section.cutoff_probability <= 0:
        return keep
    for obj in objects.tolist():
        cut = rng.random() < section.cutoff_probability
        fraction = rng.uniform(*section.cutoff_fraction)
        heading = rng.uniform(0.0, 2 * np.pi)
        mine = np.flatnonzero(instance == obj)
        if not cut or not len(mine):
            continue
        along = xyz[mine, :2] @ np.array([np.cos(heading), np.sin(heading)])
        order = np.argsort(along, kind="stable")
        keep[mine[order[: int(round(fraction * len(mine)))]]] = False
    return keep


def interior_points(centres: np.ndarray, section: NoiseInjections, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random points inside objects: ``(points (k, 3), owner (k,) index into centres)``; radius N(0.3, 0.5) (absolute), uniform angles."""
    if section.interior_points <= 0 or not len(centres):
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    counts = rng.integers(0, section.interior_points + 1, len(centres))
    owner = np.repeat(np.arange(len(centres)), counts)
    k = len(owner)
    radius = np.abs(rng.normal(0.3, 0.5, k))
    az = rng.uniform(0.0, 2 * np.pi, k)
    el = np.arcsin(rng.uniform(-1.0, 1.0, k))
    offset = radius[:, None] * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return centres[owner] + offset, owner


def nearest_firing(firings: Firings, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For ``(k, 3)`` points, the firing whose direction is nearest (from its origin) and the range along it:
    ``(firing (k,), range (k,))``. Brute force over the firings in chunks (k is small)."""
    out, rng_ = np.zeros(len(points), np.int64), np.zeros(len(points))
    for i, p in enumerate(points):
        rel = p - firings.origin
        r = np.linalg.norm(rel, axis=1)
        cos = np.einsum("ij,ij->i", rel, firings.direction) / np.maximum(r, 1e-12)
        out[i] = int(np.argmax(cos))
        rng_[i] = float(rel[out[i]] @ firings.direction[out[i]])
    return out, rng_


def class_flips(semantic: np.ndarray, classes: np.ndarray, section: NoiseInjections, rng: np.random.Generator) -> np.ndarray:
    """``semantic`` with a ``class_flip`` share of points given another class of ``classes`` (the frame's own)."""
    if section.class_flip <= 0 or len(classes) < 2:
        return semantic
    out = semantic.copy()
    flip = np.flatnonzero(rng.random(len(out)) < section.class_flip)
    shift = rng.integers(1, len(classes), len(flip))
    where = np.searchsorted(classes, out[flip])
    out[flip] = classes[(where + shift) % len(classes)]
    return out
