"""What a weather kind is (``effects.weather.<name>``): its config section, its check and its part of each phase.

The weather works on the returns of a clear scan in phases (:func:`bpy_pipeline.lidar.effects.weather.apply_weather`),
each kind in the order of :data:`WEATHER_KINDS` within each phase: :meth:`WeatherKind.surface` (what the kind does
to the targets themselves: a wet ground), :meth:`WeatherKind.attenuate` (the hard targets' power through the medium),
:meth:`WeatherKind.scatter` (the medium's own returns, offered per beam: the strongest wins), then the noise floor
decides which returns are seen, then :meth:`WeatherKind.range_noise` (on the returns of hard targets). Every phase
but ``check`` and ``active`` does nothing unless a kind overrides it; the phases draw from the frame's generator in
this order. A kind whose scatterers return points names their class in ``label`` (assets_manifest/labels.yaml).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ....registry import Registry
from .particles import _Medium, _Particles, _offer_particles


@dataclass
class Returns:
    """The clear scan's returns as the weather phases see them.

    points : (p,) POINT_DTYPE records (sensor frame); beam : (p,) BEAM_DTYPE; effects : the config's ``effects``
    r : (p,) float64 clear ranges (m, at least MIN_RANGE); a : (p,) float64 apparent reflectance ``rho cos^k g``
    medium : what the weather does to each return so far; divergence : full-angle beam divergence (rad)
    detect : ``detect(apparent, range_m) -> (p,) float32`` the noise floor's detection probability; table : the class table
    """

    points: np.ndarray
    beam: np.ndarray
    effects: object
    r: np.ndarray
    a: np.ndarray
    medium: _Medium
    divergence: float
    detect: object
    table: object

    def offer(self, kind: str, rows, range_m, apparent, intensity=None) -> None:
        """Scatterers of ``kind`` for ``rows``; each replaces the row's current one where its received power is stronger."""
        self.medium.offer(rows, range_m, apparent, WEATHER_KINDS.names().index(kind), intensity)

    def offer_particles(self, kind: str, particles: _Particles, extinction: float, rng: np.random.Generator) -> None:
        """The strongest visible particle of each beam's cone, offered as a scatterer of ``kind`` (:func:`.particles._offer_particles`)."""
        _offer_particles(self.medium, self.r, particles, self.divergence, self.detect, extinction, WEATHER_KINDS.names().index(kind), rng)


class WeatherKind:
    """One kind of weather. name : its key under ``effects.weather``; config : that section's dataclass (its
    defaults are the weather off); label : the class its scatterer returns get (``None``: it offers none)."""

    name: str = ""
    config: type | None = None
    label: str | None = None

    def check(self, section, where: str) -> None:
        """``InputError`` naming ``where.<key>`` of the first value the model cannot take beyond its field's metadata range
        (which the schema checks: :func:`~bpy_pipeline.schema.from_dict`, :func:`~bpy_pipeline.schema.check_ranges`)."""

    def check_labels(self, section, where: str, table) -> None:
        """``InputError`` for a class name of the section that ``table`` (the class table) does not know."""

    def active(self, section) -> bool:
        """True when the section asks for this weather."""
        return False

    def prepare(self, section) -> None:
        """Once per call, before the chunks share them: build what the phases only read."""

    def particles(self, section) -> tuple[_Particles, float] | None:
        """``(particles, extinction 1/m)`` of a medium of particles (for the estimate of a run's work), or ``None``."""
        return None

    def surface(self, section, returns: Returns) -> None:
        """Change the targets themselves (``returns.medium.transmit`` of some rows)."""

    def attenuate(self, section, returns: Returns) -> None:
        """Multiply ``returns.medium.transmit`` by the medium's two-way transmission to each hard target."""

    def scatter(self, section, returns: Returns, rng: np.random.Generator) -> None:
        """Offer the medium's own returns (:meth:`Returns.offer`, :meth:`Returns.offer_particles`)."""

    def range_noise(self, section, range_m: np.ndarray, hard: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """``(p,)`` float64 ranges (m) after the medium's range noise; ``hard`` (p,) bool the returns of hard targets."""
        return range_m


WEATHER_KINDS: Registry[WeatherKind] = Registry("weather kind", "effects.weather")


def register_weather_kind(kind: WeatherKind) -> WeatherKind:
    """Make ``effects.weather.<kind.name>`` a section of the weather, applied in the registration order."""
    return WEATHER_KINDS.register(kind.name, kind)
