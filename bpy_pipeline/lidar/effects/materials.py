"""Per-material reflectance at the sensor's wavelength (``effects.materials``): what a surface returns against incidence.

A material model turns a return's ``lidar_reflectivity`` ``rho`` and its cosine of incidence into the
apparent reflectance ``a`` the receiver sees (what the intensity, drop and weather models read; a
Lambertian target gives ``rho cos``). Points take a model by their class (``effects.materials.classes``,
e.g. ``{car: glossy_paint, traffic sign: retroreflector}``), or by the object they hit
(``effects.materials.objects: true``: each object's model as blender/export.py read it from its Blender
material, :func:`model_from_material`: a ``lidar_material`` custom property naming a model, else a
Principled BSDF roughness at or below :data:`GLOSSY_ROUGHNESS` (clear coat, polished metal) is
``glossy_paint``; an object's model wins over its class's). Classes and objects not named keep the
scene's diffuse reflectance, and glass and mirrors are traced as before (lidar/cast/scanner.py). Opt-in: no
point has a model unless the config asks, so scans without it are unchanged.

Per object: the scene's object table carries a model id per object (``ObjectTable.surface``, 0 for
none, else 1 + the model's place in :data:`MATERIAL_MODELS`). A point knows its object's
``instance`` and reflectivity (its beam record), not its row, so the model is looked up by that
pair; parts of one instance with the same reflectivity but different models cannot be told apart
and are refused in one line (give one a different ``lidar_reflectivity``).

Models (:data:`MATERIAL_MODELS`, a registry; each owns the dataclass of its section):

``glossy_paint``
    A clear coat over pigment: a diffuse part ``diffuse cos`` plus a specular lobe
    ``specular exp(-theta^2 / (2 lobe^2))`` back towards the sensor, seen only near normal
    incidence (the Phong/Gaussian-lobe form of microfacet models). At oblique incidence the coat
    sends the beam away and the dark diffuse part is all that returns: few returns and low
    intensity, strong near normal. The object's ``rho`` is not used (the paint's colour in the
    visible says little at 905 nm).
``retroreflector``
    Number plates, signs, lane paint with glass beads: a return of ``reflectivity`` (far above a
    white diffuse target's 1) up to an entrance angle ``max_angle_deg``, falling as ``1 - (theta /
    max)^2``; sensors saturate on it (Velodyne's calibrated reflectivity puts retro-reflectors at
    101-255 above the diffuse 0-100).
``dark_paint``
    A diffuse ``reflectivity`` (black paint about 0.05) whatever the scene says.
``wet``
    The diffuse surface under a water film (Lekner and Dorf's "Why some things are darker when
    wet", :func:`.weather.wet_ground_factor`): about half the dry return.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ...errors import InputError
from ...schema import meta
from ...registry import Registry
from .base import Chunk, Effect, register_effect
from .weather import wet_ground_factor


@dataclass(frozen=True)
class GlossyPaint:
    """``effects.materials.glossy_paint``."""

    diffuse: float = field(default=0.03,
                           metadata=meta("", 0, 1, help="the pigment's diffuse reflectance under the coat at 905 nm (dark: KITTI cars read about 0-0.1)"))
    specular: float = field(default=0.6, metadata=meta("", 0, 10, help="the coat's return at normal incidence"))
    lobe_deg: float = field(default=8.0, metadata=meta("deg", 0.1, 90, help="one sigma of the specular lobe, in incidence"))


@dataclass(frozen=True)
class Retroreflector:
    """``effects.materials.retroreflector``."""

    reflectivity: float = field(default=10.0,
                                metadata=meta("", 0, 1000, help="apparent reflectance at normal entrance, in units of a white diffuse target (saturates)"))
    max_angle_deg: float = field(default=60.0, metadata=meta("deg", 1, 90, help="entrance angle beyond which the sheeting no longer returns"))


@dataclass(frozen=True)
class DarkPaint:
    """``effects.materials.dark_paint``."""

    reflectivity: float = field(default=0.05, metadata=meta("", 0, 1, help="diffuse reflectance at 905 nm"))


@dataclass(frozen=True)
class MaterialModel:
    """A registry entry: ``apparent(rho (p,), cos_incidence (p,), params) -> (p,) float64`` and its parameters' dataclass."""

    apparent: Callable[..., np.ndarray]
    params: type | None = None


MATERIAL_MODELS: Registry[MaterialModel] = Registry("material model", "effects.materials.classes")


def _incidence(cos: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(np.asarray(cos, np.float64), 0.0, 1.0))


def glossy_paint(rho, cos, p: GlossyPaint) -> np.ndarray:
    """``diffuse cos + specular exp(-theta^2 / (2 lobe^2))``."""
    theta = _incidence(cos)
    return p.diffuse * np.clip(cos, 0.0, 1.0) + p.specular * np.exp(-0.5 * (theta / math.radians(p.lobe_deg)) ** 2)


def retroreflector(rho, cos, p: Retroreflector) -> np.ndarray:
    """``reflectivity (1 - (theta / max)^2)`` within the entrance angle, 0 beyond."""
    theta = _incidence(cos)
    return p.reflectivity * np.clip(1.0 - (theta / math.radians(p.max_angle_deg)) ** 2, 0.0, 1.0)


def dark_paint(rho, cos, p: DarkPaint) -> np.ndarray:
    return p.reflectivity * np.clip(np.asarray(cos, np.float64), 0.0, 1.0)


def wet(rho, cos, p=None) -> np.ndarray:
    cos = np.clip(np.asarray(cos, np.float64), 0.0, 1.0)
    return np.asarray(rho, np.float64) * cos * wet_ground_factor(rho, cos)


MATERIAL_MODELS.register("glossy_paint", MaterialModel(glossy_paint, GlossyPaint))
MATERIAL_MODELS.register("retroreflector", MaterialModel(retroreflector, Retroreflector))
MATERIAL_MODELS.register("dark_paint", MaterialModel(dark_paint, DarkPaint))
MATERIAL_MODELS.register("wet", MaterialModel(wet))


GLOSSY_ROUGHNESS = 0.3  # a Principled BSDF roughness at or below this is a clear coat or polished metal: glossy_paint


def model_from_material(lidar_material, roughness, metallic, where: str) -> str:
    """The reflectance model a Blender material's properties select (``""``: none, the diffuse reflectance).

    lidar_material : the ``lidar_material`` custom property of the object or its material (``None`` if
    unset): a name of :data:`MATERIAL_MODELS` is taken as it is, ``diffuse`` (or another tracing
    material: glass, mirror, absorber) means no model. roughness, metallic : the Principled BSDF's inputs
    (``None`` without one): roughness <= :data:`GLOSSY_ROUGHNESS` is ``glossy_paint`` whatever the
    metallic (metal-flake paint and bare metal both send the beam away off normal), else none.
    """
    if lidar_material is not None:
        name = str(lidar_material)
        return name if name in MATERIAL_MODELS else ""
    if roughness is None:
        return ""
    if not 0.0 <= float(roughness) <= 1.0 or (metallic is not None and not 0.0 <= float(metallic) <= 1.0):
        raise InputError(f"{where}: roughness and metallic must lie in 0..1, got {roughness!r} and {metallic!r}")
    return "glossy_paint" if float(roughness) <= GLOSSY_ROUGHNESS else ""


def part_material(name: str, where: str) -> tuple[int, int]:
    """``(material, surface)`` of a mesh part's material name: a tracing material of ``buffers.MATERIALS`` (diffuse,
    mirror, glass, absorber) as it is with no model, or a name of :data:`MATERIAL_MODELS` (``glossy_paint``,
    ``retroreflector``, ...) traced as ``diffuse`` with that model (the object table's ``surface``, read under
    ``effects.materials.objects``); ``InputError`` naming ``where`` for another name."""
    from ...buffers import MATERIAL_ID

    if name in MATERIAL_ID:
        return MATERIAL_ID[name], 0
    if name in GLASS_PANES:  # a car's window: glass, its transmittance from scene.car_glass
        return MATERIAL_ID["glass"], 0
    if name in MATERIAL_MODELS:
        return MATERIAL_ID["diffuse"], model_id(name)
    raise InputError(f"{where}: expected one of {', '.join([*MATERIAL_ID, *MATERIAL_MODELS, *GLASS_PANES])}, got {name!r}")


def model_id(name: str) -> int:
    """0 for ``""`` (no model), else 1 + the place of ``name`` in :data:`MATERIAL_MODELS` (the object table's ``surface``)."""
    return 0 if not name else 1 + list(MATERIAL_MODELS).index(name)


def model_name(identifier: int) -> str:
    return "" if identifier == 0 else list(MATERIAL_MODELS)[identifier - 1]


@dataclass(frozen=True)
class MaterialsConfig:
    """``effects.materials``: a reflectance model per class or per object, and each model's parameters."""

    classes: dict = field(default_factory=dict, metadata=meta(help="class name -> a material model's name"))
    objects: bool = field(default=False, metadata=meta(help="each object's model from its Blender material (the object table's surface column)"))
    glossy_paint: GlossyPaint = field(default_factory=GlossyPaint)
    retroreflector: Retroreflector = field(default_factory=Retroreflector)
    dark_paint: DarkPaint = field(default_factory=DarkPaint)


def check_materials(materials: MaterialsConfig, where: str = "effects.materials") -> None:
    """``InputError`` naming the key of an unknown class or model (the models' parameters have their fields' ranges, the schema's)."""
    from ...labels import load_class_table

    table = load_class_table()
    for name, model in materials.classes.items():
        table.id_of(str(name), f"{where}.classes")
        if not isinstance(model, str) or model not in MATERIAL_MODELS:
            raise InputError(f"{where}.classes.{name}: unknown material model {model!r}; allowed: {', '.join(MATERIAL_MODELS)}")


def object_models(points: np.ndarray, beam: np.ndarray, objects) -> np.ndarray:
    """(p,) uint8 model id of each point's object (0: none), looked up by ``(instance, reflectivity)``.

    objects : the scene's ``ObjectTable`` (its ``surface`` column); ``InputError`` naming two objects
    of one instance and reflectivity whose models differ.
    """
    surface = getattr(objects, "surface", None)
    out = np.zeros(len(points), np.uint8)
    if surface is None or not np.any(surface):
        return out
    bits = np.asarray(objects.reflectivity, np.float32).view(np.uint32).astype(np.uint64)
    keys = (np.asarray(objects.instance, np.uint64) << np.uint64(32)) | bits
    order = np.argsort(keys, kind="stable")
    sorted_keys, sorted_models = keys[order], np.asarray(surface, np.uint8)[order]
    clash = (sorted_keys[1:] == sorted_keys[:-1]) & (sorted_models[1:] != sorted_models[:-1])
    if clash.any():
        a, b = order[np.flatnonzero(clash)[0]], order[np.flatnonzero(clash)[0] + 1]
        raise InputError(
            f"object {objects.names[b]!r}: shares instance {int(objects.instance[a])} and lidar_reflectivity {float(objects.reflectivity[a]):g} with "
            f"{objects.names[a]!r} "
            f"but has another reflectance model ({model_name(int(surface[b])) or 'diffuse'} against {model_name(int(surface[a])) or 'diffuse'}); give one a "
            "different lidar_reflectivity"
        )
    point_keys = (points["instance"].astype(np.uint64) << np.uint64(32)) | beam["reflectivity"].astype(np.float32).view(np.uint32).astype(np.uint64)
    at = np.clip(np.searchsorted(sorted_keys, point_keys), 0, len(sorted_keys) - 1)
    found = sorted_keys[at] == point_keys
    out[found] = sorted_models[at[found]]
    return out


def apply_materials(points: np.ndarray, beam: np.ndarray, materials: MaterialsConfig, incidence_exponent: float, objects=None) -> np.ndarray:
    """``beam`` with the reflectivity of the points of the classes (or objects) named set so that ``rho cos^k`` (the intensity
    model's apparent reflectance, ``k`` its ``incidence_exponent``) is their material's; a copy when any changes.

    points : (p,) POINT_DTYPE (their ``semantic``, ``instance``); beam : (p,) BEAM_DTYPE; objects : the
    scene's ObjectTable, read when ``materials.objects`` is set (an object's model wins over its class's)
    """
    if (not materials.classes and not materials.objects) or len(points) == 0:
        return beam
    from ...labels import load_class_table

    table = load_class_table()
    chosen = np.zeros(len(points), np.uint8)
    for name, model_name_ in materials.classes.items():
        chosen[points["semantic"] == table.id_of(str(name))] = model_id(model_name_)
    if materials.objects and objects is not None:
        per_object = object_models(points, beam, objects)
        chosen = np.where(per_object > 0, per_object, chosen)
    if not chosen.any():
        return beam
    out = beam.copy()
    for identifier in np.unique(chosen[chosen > 0]):
        name = model_name(int(identifier))
        mine = chosen == identifier
        model = MATERIAL_MODELS.get(name)
        params = getattr(materials, name, None)
        cos = beam["cos_incidence"][mine].astype(np.float64)
        a = model.apparent(beam["reflectivity"][mine], cos, params)
        out["reflectivity"][mine] = a / np.maximum(cos, 1e-3) ** incidence_exponent
    return out


class Materials(Effect):
    """The reflectance model of each class or object named (:func:`apply_materials`), before the intensity reads it."""

    name, section, config, order = "materials", "materials", MaterialsConfig, 10

    def check(self, effects, spec=None) -> None:
        check_materials(effects.materials)

    def apply(self, chunk: Chunk, rng: np.random.Generator) -> None:
        materials = getattr(chunk.effects, "materials", None)
        if materials is not None:
            chunk.beam = apply_materials(chunk.points, chunk.beam, materials, chunk.effects.intensity.incidence_exponent, chunk.objects)


register_effect(Materials())


# ----------------------------------------------------------------------------- car glass and cabins (insertion)
GLASS_INDEX = 1.52  # soda-lime (float) glass near 905 nm (about 1.51-1.52 over the near infrared)


def fresnel_reflectance(cos_incidence, index: float = GLASS_INDEX) -> np.ndarray:
    """(k,) unpolarised power reflectance of one air-glass surface (Fresnel: the mean of the s and p shares).

    cos_incidence : (k,) |cos| of the angle of incidence; index : the glass's refractive index (air 1)."""
    ci = np.clip(np.abs(np.asarray(cos_incidence, np.float64)), 0.0, 1.0)
    st = np.sqrt(np.maximum(1.0 - ci**2, 0.0)) / index  # Snell: sin t = sin i / n (never total: air to glass)
    ct = np.sqrt(np.maximum(1.0 - st**2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = ((ci - index * ct) / (ci + index * ct)) ** 2
        rp = ((ct - index * ci) / (ct + index * ci)) ** 2
    return np.where(ci > 0, 0.5 * (rs + rp), 1.0)


def pane_transmission(cos_incidence, internal, index: float = GLASS_INDEX) -> np.ndarray:
    """(k,) one-way power transmission of a pane: ``(1 - R)^2 internal^(1 / cos t)``.

    Two surfaces of Fresnel reflectance ``R`` (:func:`fresnel_reflectance`; the inter-reflections, ``R^2`` about
    0.2 % near normal, left out) and the glass's own absorption (tint, the ferrous-iron band of green glass, an
    infrared-cut layer) along the refracted path: ``internal`` is the pane's internal transmittance at normal
    incidence (a number or one per beam), the path grows as ``1 / cos t`` (``t`` the refracted angle)."""
    ci = np.clip(np.abs(np.asarray(cos_incidence, np.float64)), 0.0, 1.0)
    ct = np.sqrt(np.maximum(1.0 - (1.0 - ci**2) / index**2, 0.0))
    r = fresnel_reflectance(ci, index)
    return (1.0 - r) ** 2 * np.asarray(internal, np.float64) ** (1.0 / np.maximum(ct, 1e-9))


def glass_round_trip(cos_incidence, internal, index: float = GLASS_INDEX) -> np.ndarray:
    """(k,) ``pane_transmission^2``: the share of a beam's power that crosses a pane and comes back through it (the
    echo of what lies behind crosses the same pane at the same angle)."""
    return pane_transmission(cos_incidence, internal, index) ** 2


@dataclass(frozen=True)
class CarGlass:
    """``scene.car_glass`` (real-scan insertion): what an inserted car's windows and cabin do to the beam.

    A beam meeting a window passes with probability :func:`glass_round_trip` (Fresnel at its incidence times the
    pane's internal transmittance, squared for the way back; a Monte Carlo split of the beam's power: the rest is
    reflected away off the glass or absorbed in it, and gives no return), else it is lost; a beam that passes
    meets the cabin, whose surfaces (black plastics and fabrics) have the low reflectivity ``interior``, or
    passes out through the far window. ``windshield`` is the front pane's internal transmittance, ``tinted`` the
    side and rear panes' (privacy glass). ``enabled: false`` (the default): the windows of before (every beam
    passes, gain ``1 - reflectivity``) and the cabin at the interior's reflectivity of geometry/objects.py.
    docs/realism.md's materials table gives the sources and which figures are fitted.
    """

    enabled: bool = field(default=False, metadata=meta(help="opt-in: on KITTI 004747 (held out) it puts no more cars within 0.7-1.4x (docs/realism.md)"))
    index: float = field(default=GLASS_INDEX, metadata=meta("", 1, 3, help="the glass's refractive index near 905 nm"))
    windshield: float = field(
        default=0.6, metadata=meta("", 0, 1, help="the front pane's internal transmittance (fitted on KITTI 000008, benchmarks/bench_materials.py --insertion)")
    )
    tinted: float = field(default=0.7, metadata=meta("", 0, 1, help="the side and rear panes' internal transmittance (fitted on KITTI 000008)"))
    interior: float = field(default=0.15, metadata=meta("", 0, 1, help="the cabin's reflectivity (fitted on KITTI 000008: 0.05 and 0.15 tried)"))


# part material -> the CarGlass field of its internal transmittance (traced as glass)
GLASS_PANES = {"windshield_glass": "windshield", "tinted_glass": "tinted"}


def pane_internal(materials: list[str], glass: CarGlass) -> np.ndarray:
    """(k,) internal transmittance of each object row whose part material is a car pane (:data:`GLASS_PANES`), NaN
    for every other row (plain ``glass`` keeps the trace's rule of before)."""
    return np.array([float(getattr(glass, GLASS_PANES[m])) if m in GLASS_PANES else np.nan for m in materials])


def glass_transmission(internal: np.ndarray, glass: CarGlass):
    """The trace's ``MirrorGlassRules.glass_transmission`` for ``internal`` (:func:`pane_internal`, one per object
    row): ``(cos (k,), rows (k,)) -> (k,)`` the round trip of each pane met, NaN for rows without a pane model."""
    internal = np.asarray(internal, np.float64)

    def transmission(cos_incidence: np.ndarray, rows: np.ndarray) -> np.ndarray:
        tau = internal[rows]
        out = np.full(len(tau), np.nan)
        pane = np.isfinite(tau)
        out[pane] = glass_round_trip(np.asarray(cos_incidence)[pane], tau[pane], glass.index)
        return out

    return transmission
