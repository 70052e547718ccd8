"""``scene.car_paint`` (real-scan insertion): a reflectance model per part of an inserted car, the body's paint drawn per car.

KITTI 000008's real cars read 0 by height on the car, not by laser or range (docs/realism.md): the lower body reads like
the road, the windows, cabin and roof read 0. So each part of an inserted car carries its own model here, set apart in
config, instead of one model for the class ``car`` (``effects.materials.classes``, which also sets the cabin seen through
the glass). The parts are :data:`CAR_PARTS`, the one place that names them (a registry: each part is the car mesh's
parts it takes, :func:`~bpy_pipeline.mixing.cast.car_part_names`, and which of their triangles):

``body``    the body below ``upper_from`` of the car's height (hood, doors, sills, bumpers, trunk); its pigment drawn per car
``upper``   the body from ``upper_from`` up (pillars and roof)
``glass``   the window panes' own returns (what a pane passes is traced as ``scene.car_glass`` says)
``cabin``   dashboard and seats, seen through the glass
``tyres``, ``plates``, ``lights``

Each part is ``{model: NAME, ...its parameters}`` with ``NAME`` one of ``lidar/effects/materials.py`` ``MATERIAL_MODELS``
(``glossy_paint``: a clear coat's lobe over a diffuse pigment; ``dark_paint``: a fixed diffuse reflectivity;
``retroreflector``; ``wet``), or ``{}``: the part keeps its material of before (the scene's diffuse reflectivity, a
plate's retroreflector). The body's pigment (``glossy_paint``'s ``diffuse``, ``dark_paint``'s ``reflectivity``, else the
part's own reflectivity) is drawn per car from ``paints`` (name -> ``[share, reflectance at 905 nm]``) unless the body
sets it, by a generator of its own per car (:func:`car_generator`: the frame's generator jumped, never advanced, so the
rest of the frame draws as before). Applied to the inserted returns with the effects (:func:`paint_beam`), where a
part's model wins over ``effects.materials``. A part may also set ``detection`` (0..1): the reflectivity the drop decision
sees at least, ``max(own, detection)``, while the reading stays the part's own (:func:`detection_reflectivity`; the
receiver's reading floor lies above its detection floor, docs/realism.md); unset by default. Opt-in (``enabled``; its defaults fitted on KITTI
000008): held out on 004747 it lifts the reflectance overlap but loses the 28-37 m cars' points (docs/realism.md); off: nothing is drawn or changed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..errors import InputError
from ..schema import check_ranges, meta
from ..geometry.objects import ObjectPart
from ..lidar.effects.materials import MATERIAL_MODELS, apply_materials
from ..registry import Registry


@dataclass(frozen=True)
class CarPart:
    """A registry entry: the car mesh parts it takes (names of ``cast.car_part_names``) and which of their triangles,
    ``pick(centroid_z (m,) as a fraction of the car's height from its bottom, upper_from) -> (m,) bool`` (None: all)."""

    sources: tuple[str, ...]
    pick: Callable[[np.ndarray, float], np.ndarray] | None = None


CAR_PARTS: Registry[CarPart] = Registry("car part", "scene.car_paint.parts")
CAR_PARTS.register("body", CarPart(("body",), lambda z, upper_from: z < upper_from))
CAR_PARTS.register("upper", CarPart(("body",), lambda z, upper_from: z >= upper_from))
CAR_PARTS.register("glass", CarPart(("windows", "windshield")))
CAR_PARTS.register("cabin", CarPart(("interior",)))
CAR_PARTS.register("tyres", CarPart(("tyres",)))
CAR_PARTS.register("plates", CarPart(("plates",)))
CAR_PARTS.register("lights", CarPart(("lights",)))

PIGMENT = {"glossy_paint": "diffuse", "dark_paint": "reflectivity"}  # model -> its parameter the drawn body paint sets (others: the part's reflectivity)

# The body paints (name -> [share of cars, diffuse reflectance at 905 nm under the coat]). Shares: the global colour
# popularity of geometry/objects.py COLOURS grouped (black; grey and blue "dark"; red and beige "mid"; white and silver
# "light"); reflectances: the groups' 905 nm reflectances there (assumed: black 0.05, dark 0.26, mid 0.43, light 0.66)
# times the share a clear-coated paint returns diffusely, 0.5, FITTED on KITTI 000008 (0.1 / 0.2 / 0.35 / 0.5 tried:
# benchmarks/bench_materials.py --parts; docs/realism.md).
PAINTS = {"black": [0.19, 0.025], "dark": [0.25, 0.13], "mid": [0.12, 0.215], "light": [0.44, 0.33]}
DEFAULT_PARTS = {
    "body": {"model": "glossy_paint", "specular": 0.3, "lobe_deg": 8.0},  # the drawn pigment under a clear coat (0.3 / 8 and 0.6 / 6 tried: fitted)
    "upper": {"model": "glossy_paint", "diffuse": 0.03, "specular": 0.3, "lobe_deg": 8.0},  # roof and pillars: dark, glossy (diffuse 0.01 / 0.03 tried: fitted)
    "glass": {"model": "glossy_paint", "diffuse": 0.0, "specular": 0.043, "lobe_deg": 3.0},  # Fresnel's 4.3 % near normal, nothing else
    "cabin": {"model": "dark_paint", "reflectivity": 0.02},  # black plastics and fabrics behind the glass
    "tyres": {}, "plates": {}, "lights": {},
}


@dataclass(frozen=True)
class PartModel:
    """One part's reflectance: ``model`` a name of ``MATERIAL_MODELS`` and ``params`` its dataclass (None for ``wet``)."""

    model: str
    params: object = None
    detection: float | None = None  # the reflectivity the drop decision sees at least (the part's ``detection``; None: its own)

    def apparent(self, rho: np.ndarray, cos: np.ndarray) -> np.ndarray:
        """(p,) apparent reflectance of returns of reflectivity ``rho`` (p,) at ``cos`` (p,) of incidence."""
        return MATERIAL_MODELS.get(self.model).apparent(rho, cos, self.params)


def part_model(spec, where: str, pigment: float | None = None) -> PartModel | None:
    """The :class:`PartModel` of a part's ``{model: NAME, ...}`` (None for ``{}``); ``pigment`` sets the model's pigment
    field (:data:`PIGMENT`) when the spec leaves it out. ``InputError`` naming ``where`` for a bad name or value."""
    if not isinstance(spec, dict):
        raise InputError(f"{where}: expected a mapping {{model: NAME, ...}}, got {spec!r}")
    if not spec:
        return None
    rest = dict(spec)
    name = rest.pop("model", None)
    detection = rest.pop("detection", None)
    if detection is not None and (isinstance(detection, bool) or not isinstance(detection, (int, float)) or not 0.0 <= detection <= 1.0):
        raise InputError(f"{where}.detection: must be a reflectivity in 0..1, got {detection!r}")
    detection = None if detection is None else float(detection)
    if not isinstance(name, str) or name not in MATERIAL_MODELS:
        raise InputError(f"{where}.model: expected one of {', '.join(MATERIAL_MODELS)}, got {name!r}")
    params_type = MATERIAL_MODELS.get(name).params
    if params_type is None:
        if rest:
            raise InputError(f"{where}.{sorted(rest)[0]}: unknown key; {name} has no parameters")
        return PartModel(name, None, detection)
    known = params_type.__dataclass_fields__
    unknown = sorted(set(rest) - set(known))
    if unknown:
        raise InputError(f"{where}.{unknown[0]}: unknown key; allowed: model, detection, {', '.join(known)}")
    for key, value in rest.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{where}.{key}: must be a number, got {value!r}")
    if pigment is not None and PIGMENT.get(name) and PIGMENT[name] not in rest:
        rest[PIGMENT[name]] = float(pigment)
    params = params_type(**{k: float(v) for k, v in rest.items()})
    check_ranges(params, where)  # the model's own ranges (its fields' metadata), named as this part's keys
    return PartModel(name, params, detection)


@dataclass(frozen=True)
class CarPaint:
    """``scene.car_paint`` (module notes): ``parts`` over :data:`DEFAULT_PARTS` (a part named replaces its default),
    ``paints`` the body's pigments drawn per car, ``upper_from`` the height (a fraction of the car's) from which the body
    is ``upper``."""

    enabled: bool = field(default=False, metadata=meta(help="paint the inserted cars' parts by their material models"))
    paints: dict = field(default_factory=lambda: {k: list(v) for k, v in PAINTS.items()}, metadata=meta(help="the body's pigments drawn per car"))
    upper_from: float = field(default=0.58,
                              metadata=meta("", 0, 1, help="fraction of the car's height from which the body is upper (beltlines lie at 0.50-0.62; fitted)"))
    parts: dict = field(default_factory=dict, metadata=meta(help="part name -> its material model, over the default parts"))

    def __post_init__(self):
        if not isinstance(self.enabled, bool):
            raise InputError(f"scene.car_paint.enabled: must be true or false, got {self.enabled!r}")
        if not isinstance(self.paints, dict) or not self.paints:
            raise InputError(f"scene.car_paint.paints: expected a mapping name -> [share, reflectance], got {self.paints!r}")
        for name, value in self.paints.items():
            ok = isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            if not ok or not 0 <= value[0] <= 1 or not 0 <= value[1] <= 1:
                raise InputError(f"scene.car_paint.paints.{name}: expected [share 0..1, reflectance 0..1], got {value!r}")
        if sum(v[0] for v in self.paints.values()) <= 0:
            raise InputError("scene.car_paint.paints: the shares sum to 0")
        if not isinstance(self.parts, dict):
            raise InputError(f"scene.car_paint.parts: expected a mapping part -> {{model: NAME, ...}}, got {self.parts!r}")
        for name, spec in self.parts.items():
            CAR_PARTS.get(str(name), "scene.car_paint.parts")
            part_model(spec, f"scene.car_paint.parts.{name}", 0.0)

    def spec(self, part: str) -> dict:
        """The part's ``{model: ...}``: the config's, else :data:`DEFAULT_PARTS`'."""
        return self.parts.get(part, DEFAULT_PARTS[part])

    def draw_paint(self, rng: np.random.Generator) -> float:
        """One car's body pigment: a paint of ``paints`` by share (one draw of ``rng``), its reflectance."""
        values = list(self.paints.values())
        shares = np.array([v[0] for v in values], float)
        return float(values[int(rng.choice(len(values), p=shares / shares.sum()))][1])


def car_generator(rng: np.random.Generator, k: int) -> np.random.Generator:
    """Car ``k``'s own generator: ``rng``'s bit generator jumped ``k + 1`` times (``rng`` itself is not advanced)."""
    return np.random.Generator(rng.bit_generator.jumped(k + 1))


def paint_car(parts: list[ObjectPart], names: list[str], paint: CarPaint, rng: np.random.Generator) -> list[ObjectPart]:
    """A car's parts (its own frame, centred, ``names[j]`` the name of ``parts[j]``) with each :data:`CAR_PARTS` part's
    model on it (``ObjectPart.paint``): a part taking some triangles of a mesh part is split off it and appended (the
    mesh part keeps its place, so part j is still ``names[j]``). One draw of ``rng``: the body's pigment."""
    pigment = paint.draw_paint(rng)
    models = {part: part_model(paint.spec(part), f"scene.car_paint.parts.{part}", pigment if part == "body" else None) for part in CAR_PARTS}
    z = np.concatenate([p.vertices[p.triangles].reshape(-1, 3)[:, 2] for p in parts if len(p.triangles)])
    bottom, height = float(z.min()), max(float(np.ptp(z)), 1e-9)
    out, extra = list(parts), []
    for j, source in enumerate(names):
        base = parts[j]
        centroid = (base.vertices[base.triangles][:, :, 2].mean(axis=1) - bottom) / height
        takers = [part for part in CAR_PARTS if source in CAR_PARTS.get(part).sources]
        for n, part in enumerate(takers):
            pick, model = CAR_PARTS.get(part).pick, models[part]
            mine = np.ones(len(base.triangles), bool) if pick is None else pick(centroid, paint.upper_from)
            reflectivity = pigment if part == "body" and (model is None or model.model not in PIGMENT) else base.reflectivity
            piece = ObjectPart(base.vertices, base.triangles[mine], base.material, reflectivity, model)
            if n == 0:
                out[j] = piece
            elif mine.any():
                extra.append(piece)
    return out + extra


def paint_beam(points: np.ndarray, beam: np.ndarray, rows: np.ndarray, paints: list, materials, incidence_exponent: float, objects=None) -> np.ndarray:
    """``beam`` with every return's reflectivity set so that the intensity model's ``rho cos^k`` is its model's apparent
    reflectance: the returns on a part with its own model (``paints[rows]``, :class:`PartModel`) by that model, the
    others by ``effects.materials`` as before (:func:`~bpy_pipeline.lidar.effects.materials.apply_materials`); a copy.

    points : (p,) POINT_DTYPE; beam : (p,) BEAM_DTYPE; rows : (p,) object row of each return; paints : per object row
    (PartModel or None); materials : ``effects.materials``; incidence_exponent : ``effects.intensity``'s ``k``."""
    out = apply_materials(points, beam, materials, incidence_exponent, objects).copy()
    rows = np.asarray(rows, np.int64)
    for row in np.unique(rows):
        model = paints[int(row)]
        if model is None:
            continue
        mine = rows == row
        cos = beam["cos_incidence"][mine].astype(np.float64)
        a = model.apparent(beam["reflectivity"][mine].astype(np.float64), cos)
        out["reflectivity"][mine] = a / np.maximum(cos, 1e-3) ** incidence_exponent
    return out


def detection_reflectivity(beam: np.ndarray, rows: np.ndarray, paints: list) -> np.ndarray | None:
    """(p,) float32: the reflectivity the drop decision sees for each return, ``max(own, detection)`` on a part whose
    model sets ``detection`` (its reading stays the beam's own), the beam's elsewhere; None when no part sets one.

    beam : (p,) BEAM_DTYPE after :func:`paint_beam`; rows : (p,) object row of each return; paints : per object row."""
    floor = np.array([np.nan if m is None or m.detection is None else m.detection for m in paints], np.float32)
    if not np.isfinite(floor).any():
        return None
    mine = floor[np.asarray(rows, np.int64)]
    own = beam["reflectivity"].astype(np.float32)
    return np.where(np.isfinite(mine), np.maximum(own, np.nan_to_num(mine)), own).astype(np.float32)
