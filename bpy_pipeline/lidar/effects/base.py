"""What an effect is: one interface and one registry for everything the sensor adds to the exact trace.

An effect (:class:`Effect`) owns its config section (``effects.<section>``, the dataclass :attr:`Effect.config`),
checks it (:meth:`Effect.check`, one-line :class:`~bpy_pipeline.errors.InputError` naming the key) and applies
it to a chunk of points (:meth:`Effect.apply`, drawing only from the chunk's generator). :data:`EFFECTS` holds
them; :func:`~.apply.apply_effects` runs them in :attr:`Effect.order` on every chunk, so the order in which the
frame's generator is consumed is the order of the effects. Adding an effect is one module that calls
:func:`register_effect`, plus its import in the registration line of :mod:`.apply`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...registry import Registry


def copy_records(records: np.ndarray, keep: np.ndarray | None = None) -> np.ndarray:
    """A copy of a structured array, of only its ``keep`` rows when given.

    Through a same-size opaque (void) view: numpy copies packed records field by field
    otherwise, ten times slower for POINT_DTYPE.
    """
    records = np.ascontiguousarray(records)
    raw = records.view(np.dtype((np.void, records.dtype.itemsize)))
    return (raw.copy() if keep is None else raw[keep]).view(records.dtype)


@dataclass
class Chunk:
    """The points an effect works on, and what it may read.

    points : (p,) POINT_DTYPE records in the sensor frame; the caller's until :attr:`records` first copies them
    beam : (p,) BEAM_DTYPE facts of the same points (direction, reflectivity, cos_incidence, ...)
    effects : the config's ``effects`` (``config.EffectsConfig``)
    models : ``{"drop": FittedModels | None, "noise": FittedModels | None}``, the model files read once per call
    objects : the scene's ObjectTable or ``None`` (``effects.materials.objects``)
    detection : (p,) float32 reflectivities the drop decision sees instead of the beam's, or ``None``
    intensity : (p,) float32 intensity computed but not yet written into the records, or ``None``
    """

    points: np.ndarray
    beam: np.ndarray
    effects: object
    models: dict
    objects: object = None
    detection: np.ndarray | None = None
    intensity: np.ndarray | None = None
    owned: bool = False

    def keep(self, keep: np.ndarray | None) -> None:
        """Keep only the rows where ``keep`` (p,) bool is True (``None``: all) of the points, beam and pending intensity."""
        if keep is None:
            return
        self.points = self.points[keep] if self.owned else copy_records(self.points, keep)
        self.owned = True
        self.beam = copy_records(self.beam, keep)
        if self.intensity is not None:
            self.intensity = self.intensity[keep]
        if self.detection is not None:
            self.detection = self.detection[keep]

    @property
    def records(self) -> np.ndarray:
        """The chunk's own records (copied from the caller's on first use), the pending intensity written in."""
        if not self.owned:
            self.points, self.owned = copy_records(self.points), True
        if self.intensity is not None:
            self.points["intensity"], self.intensity = self.intensity, None
        return self.points


class Effect:
    """One effect of ``effects``.

    name : its name in :data:`EFFECTS`; section : its key under ``effects``; config : that section's dataclass
    order : effects run in increasing order on every chunk (the frame's generator is consumed in this order)
    """

    name: str = ""
    section: str = ""
    config: type | None = None
    order: int = 0

    def check(self, effects, spec=None) -> None:
        """``InputError`` naming the key of the first bad value of ``effects.<section>`` (``spec``: the sensor, or ``None``)
        beyond its fields' metadata ranges, which the schema checks (:func:`~bpy_pipeline.schema.from_dict`)."""

    def prepare(self, effects, models: dict) -> None:
        """Once per call before the chunks share them: build what the chunks only read (tables, rasters)."""

    def apply(self, chunk: Chunk, rng: np.random.Generator) -> None:
        """Apply the effect to ``chunk`` in place (its records, beam or pending intensity), drawing from ``rng``."""
        raise NotImplementedError


EFFECTS: Registry[Effect] = Registry("effect", "effects")


def register_effect(effect: Effect) -> Effect:
    """Make :func:`~.apply.apply_effects` run ``effect`` at its :attr:`~Effect.order`."""
    return EFFECTS.register(effect.name, effect)


def ordered_effects() -> list[Effect]:
    """The registered effects in the order they run."""
    return sorted((effect for _, effect in EFFECTS.items()), key=lambda effect: effect.order)
