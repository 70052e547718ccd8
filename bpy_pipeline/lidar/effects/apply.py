"""Sensor effects applied to point records after the trace: intensity, ray drop, range noise.

The intensity models live in :mod:`.intensity`, the drop models in :mod:`.drop` (a registry, one
module per model); this module holds range noise, the fitted models and their files, and applies
all of them in order (:func:`apply_effects`).

Each effect is a small model chosen in the config (``config.EffectsConfig``), takes the
explicit ``numpy.random.Generator`` of the frame, and can be switched off. A sensor preset's
profile (``effects`` in ``sensors.yaml``, fitted to a real scan or from a datasheet) fills what the
config does not give, unless ``effects.ideal: true`` (docs/realism.md). Points are in the
sensor frame, so a beam's direction is the point's direction from the origin (the scanner
reports mirrored returns along the emitted beam at the total path length).

Intensity (``effects.intensity.model``)
    ``reflectance``: ``rho cos(theta) g``, the object's ``lidar_reflectivity`` times the cosine
    of incidence times the mirror gain ``g`` (product of the reflectivities of the mirrors met),
    which is what range-compensated sensors report ("calibrated reflectivity").
    ``lidar``: the lidar equation for an extended Lambertian target,
    ``P ~ rho cos(theta) g exp(-2 alpha R) / R^2``, normalised so that a target of
    ``reference_reflectivity`` at normal incidence at ``reference_range`` reads 1 (nearer or
    brighter returns saturate at 1, as a receiver does).
    ``carla``: CARLA's ``exp(-a R)`` (``attenuation_rate`` a, CARLA's 0.004 per metre by default).
    Then as the sensor writes it: ``cos^k`` instead of ``cos`` (``incidence_exponent``), times
    ``scale`` clipped to 1, rounded to ``k / steps`` (255: an 8-bit intensity; 100: KITTI).

Ray drop (``effects.drop.model``)
    ``none``; ``uniform`` (each point lost with ``probability``; the parking paper drew up to
    0.3 %); ``carla`` (CARLA's RayCastLidar: a general rate dropped before tracing,
    independent of the hit, then with ``I = exp(-a R)`` a point above ``intensity_limit`` is
    kept and one below it is kept with probability ``(zero_intensity / intensity_limit) I +
    1 - zero_intensity``); ``threshold`` (a physical detection threshold: the received power
    ``rho cos g exp(-2 alpha R) / R^n`` against a sensitivity set by a datasheet's range at 10 %
    and 80 % reflectivity, so dark objects vanish nearer than bright ones); ``table`` (a drop
    probability over (range, incidence angle) fitted to real scans, bilinear between bins); ``mlp``
    (the same fitted by a small perceptron over the bins, as the Raphael paper does).

Range noise (``effects.noise``)
    Gaussian along the beam with sigma ``constant``, growing with ``range`` (``sigma +
    sigma_per_metre R``), from a ``table`` over (range, incidence angle) or from an ``mlp`` over it; a fixed per-ring
    range bias (``ring_bias``, metres per ring, as each laser of a multi-beam sensor has its
    own); angular jitter (``angular_jitter_deg``, one sigma in azimuth and in elevation; the
    point turns about the sensor at its range, the small-angle view of a beam pointing
    slightly off).

Fitted models (files written by ``python -m bpy_pipeline fit``, see :mod:`bpy_pipeline.lidar.fit.fitting`): with
``effects.drop.model_file`` the ``uniform``, ``threshold`` and ``table`` drop models take their
parameters from the file, with ``effects.noise.model_file`` the ``range`` and ``table`` noise
models do.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import yaml

from ...errors import InputError
from . import effects_kernels
from .drop import DROP_MODELS
from .drop.carla import carla_keep_probability  # noqa: F401  (stable names)
from .drop.mlp import MLP
from .drop.threshold import ThresholdModel, threshold_model
from .intensity import carla_intensity, compute_intensity, lidar_intensity, reflectance  # noqa: F401
from .materials import apply_materials
from ..points import POINT_DTYPE
from ..cast.sharing import share
from .weather import apply_weather, fog_alpha, fog_soft_table
from ...yaml_text import read_yaml_file

MODEL_FORMAT = "bpy_pipeline effects model"
MODEL_VERSION = 1


# ----------------------------------------------------------------------------- tables
@dataclass(frozen=True)
class BinnedTable:
    """A quantity binned over (range, incidence angle), bilinear between bin centres.

    range_edges : (nr + 1,) float64 increasing, metres
    incidence_edges_deg : (ni + 1,) float64 increasing within 0..90, degrees
    values : (nr, ni) float64; NaN where a bin had too few samples (discarded)
    samples : (nr, ni) int64 samples each bin was estimated from
    Discarded bins take the mean of their measured neighbours, growing outwards from the
    measured ones (:meth:`filled`); queries outside the edges take the outermost bins' values.
    """

    range_edges: np.ndarray
    incidence_edges_deg: np.ndarray
    values: np.ndarray
    samples: np.ndarray

    def __post_init__(self):
        for name, dtype in (("range_edges", np.float64), ("incidence_edges_deg", np.float64), ("values", np.float64), ("samples", np.int64)):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype))

    def check(self, where: str) -> None:
        """``InputError`` naming ``where`` when the table is malformed."""
        r, i, v = self.range_edges, self.incidence_edges_deg, self.values
        if r.ndim != 1 or len(r) < 2 or not (np.diff(r) > 0).all() or r[0] < 0:
            raise InputError(f"{where}.range_edges: need at least 2 increasing ranges >= 0 m")
        if i.ndim != 1 or len(i) < 2 or not (np.diff(i) > 0).all() or i[0] < 0 or i[-1] > 90:
            raise InputError(f"{where}.incidence_edges_deg: need at least 2 increasing angles within 0..90 deg")
        if v.shape != (len(r) - 1, len(i) - 1) or self.samples.shape != v.shape:
            raise InputError(f"{where}: values and samples must be {len(r) - 1} x {len(i) - 1} (range bins x incidence bins), got {v.shape}")
        if np.isnan(v).all():
            raise InputError(f"{where}: every bin is empty (too few samples everywhere)")

    @property
    def shape(self) -> tuple[int, int]:
        return self.values.shape

    @cached_property
    def filled(self) -> np.ndarray:
        """``(nr, ni)`` values with discarded bins filled from their measured neighbours."""
        out = self.values.copy()
        known = ~np.isnan(out)
        while not known.all():
            total, count = np.zeros_like(out), np.zeros_like(out)
            for axis in (0, 1):
                for shift in (1, -1):
                    v = np.roll(np.where(known, out, 0.0), shift, axis)
                    k = np.roll(known, shift, axis).astype(float)
                    edge = [slice(None)] * 2
                    edge[axis] = 0 if shift == 1 else -1
                    v[tuple(edge)], k[tuple(edge)] = 0.0, 0.0  # no wrap-around
                    total, count = total + v, count + k
            grow = ~known & (count > 0)
            out[grow] = total[grow] / count[grow]
            known = known | grow
        return out

    def bilinear(self, range_m: np.ndarray, incidence_deg: np.ndarray) -> np.ndarray:
        """Exact bilinear interpolation between bin centres (clamped outside); ``(p,)`` float64."""
        rc = 0.5 * (self.range_edges[:-1] + self.range_edges[1:])
        ic = 0.5 * (self.incidence_edges_deg[:-1] + self.incidence_edges_deg[1:])
        fr = np.interp(range_m, rc, np.arange(len(rc), dtype=float))
        fi = np.interp(incidence_deg, ic, np.arange(len(ic), dtype=float))
        r0, i0 = np.floor(fr).astype(np.intp), np.floor(fi).astype(np.intp)
        r1, i1 = np.minimum(r0 + 1, len(rc) - 1), np.minimum(i0 + 1, len(ic) - 1)
        tr, ti = fr - r0, fi - i0
        v = self.filled
        return (v[r0, i0] * (1 - tr) + v[r1, i0] * tr) * (1 - ti) + (v[r0, i1] * (1 - tr) + v[r1, i1] * tr) * ti

    # The scan-time lookup: the bilinear surface sampled on a fine regular raster, read at the
    # nearest raster node (a multiply and a gather instead of two binary searches a point).
    RASTER = (2048, 91)  # range nodes from the first to the last bin centre; incidence nodes 0..90 deg

    @cached_property
    def _raster(self):
        rc = 0.5 * (self.range_edges[:-1] + self.range_edges[1:])
        nr, ni = self.RASTER if len(rc) > 1 else (1, self.RASTER[1])
        r_nodes = np.linspace(rc[0], rc[-1], nr)
        i_nodes = np.linspace(0.0, 90.0, ni)
        grid = self.bilinear(np.repeat(r_nodes, ni), np.tile(i_nodes, nr)).reshape(nr, ni)
        r_scale = (nr - 1) / (rc[-1] - rc[0]) if nr > 1 else 0.0
        return grid.astype(np.float32), float(rc[0]), r_scale, (ni - 1) / 90.0

    def lookup(self, range_m: np.ndarray, cos_incidence: np.ndarray) -> np.ndarray:
        """Values at ``(p,)`` ranges (m) and ``(p,)`` cosines of incidence; ``(p,)`` float32.

        The bilinear surface read on a raster of 2048 x 91 nodes (range within the bin centres,
        incidence every 1 deg): within half a node of :meth:`bilinear`.
        """
        grid, r0, r_scale, i_scale = self._raster
        nr, ni = grid.shape
        f = np.asarray(range_m, np.float32) * np.float32(r_scale)
        f += np.float32(0.5 - r0 * r_scale)
        np.clip(f, np.float32(0), np.float32(nr - 1), out=f)
        index = f.astype(np.intp)
        index *= ni
        a = np.clip(np.asarray(cos_incidence, np.float32), np.float32(0), np.float32(1))
        np.arccos(a, out=a)
        a *= np.float32(math.degrees(1.0) * i_scale)
        a += np.float32(0.5)
        index += a.astype(np.intp)  # arccos of 0..1 stays within 0..90 deg: no clip needed
        return grid.ravel().take(index)

    def to_dict(self, name: str) -> dict:
        return {
            "range_edges": [float(x) for x in self.range_edges],
            "incidence_edges_deg": [float(x) for x in self.incidence_edges_deg],
            name: [[None if math.isnan(x) else float(x) for x in row] for row in self.values],
            "samples": [[int(x) for x in row] for row in self.samples],
        }

    @classmethod
    def from_dict(cls, data, name: str, where: str) -> "BinnedTable":
        if not isinstance(data, dict) or any(k not in data for k in ("range_edges", "incidence_edges_deg", name, "samples")):
            raise InputError(f"{where}: expected a mapping with range_edges, incidence_edges_deg, {name} and samples")
        try:
            values = np.array([[np.nan if x is None else float(x) for x in row] for row in data[name]], np.float64)
            table = cls(data["range_edges"], data["incidence_edges_deg"], values, np.array(data["samples"], np.int64))
        except (TypeError, ValueError):
            raise InputError(f"{where}: the table holds something that is not a number") from None
        table.check(where)
        return table


# ----------------------------------------------------------------------------- fitted models on file
@dataclass(frozen=True)
class FittedModels:
    """Models fitted to real scans (:mod:`bpy_pipeline.lidar.fit.fitting`), as a model file holds them; any may be absent.

    uniform : drop probability of the ``uniform`` model
    threshold : the ``threshold`` drop model
    drop_table : drop probability over (range, incidence)
    noise_range : ``(sigma, sigma_per_metre)`` of the ``range`` noise model, metres and m/m
    noise_table : range noise sigma (m) over (range, incidence)
    source : what the models were fitted on, and how (free-form, for people)
    drop_mlp : drop probability over (range, incidence) from a small MLP (:mod:`.drop.mlp`)
    noise_mlp : range noise sigma (m) over (range, incidence) from a small MLP
    """

    uniform: float | None = None
    threshold: ThresholdModel | None = None
    drop_table: BinnedTable | None = None
    noise_range: tuple[float, float] | None = None
    noise_table: BinnedTable | None = None
    source: dict = field(default_factory=dict)
    drop_mlp: MLP | None = None
    noise_mlp: MLP | None = None

    def to_dict(self) -> dict:
        drop, noise = {}, {}
        if self.uniform is not None:
            drop["uniform"] = {"probability": float(self.uniform)}
        if self.threshold is not None:
            drop["threshold"] = self.threshold.to_dict()
        if self.drop_table is not None:
            drop["table"] = self.drop_table.to_dict("probability")
        if self.noise_range is not None:
            noise["range"] = {"sigma": float(self.noise_range[0]), "sigma_per_metre": float(self.noise_range[1])}
        if self.noise_table is not None:
            noise["table"] = self.noise_table.to_dict("sigma")
        if self.drop_mlp is not None:
            drop["mlp"] = self.drop_mlp.to_dict()
        if self.noise_mlp is not None:
            noise["mlp"] = self.noise_mlp.to_dict()
        return {"format": MODEL_FORMAT, "version": MODEL_VERSION, "source": self.source, "drop": drop, "noise": noise}


def write_model_file(path: str | Path, models: FittedModels) -> None:
    """Write ``models`` as YAML (atomically: a temporary name, then renamed)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(yaml.safe_dump(models.to_dict(), sort_keys=False, width=120, default_flow_style=None))
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise InputError(f"{path}: cannot write the model file ({err.strerror or err})") from None


def read_model_file(path: str | Path, where: str = "model_file") -> FittedModels:
    """The models of a file written by :func:`write_model_file` (read once per file version);
    ``InputError`` naming ``where`` (the config key) and the file."""
    path = Path(path)
    try:
        stat = path.stat()
    except OSError as err:
        raise InputError(f"{where}: cannot read {path} ({err.strerror or err})") from None
    return _read_model_file(str(path.resolve()), stat.st_mtime_ns, stat.st_size, where)


@lru_cache(maxsize=8)
def _read_model_file(path: str, mtime_ns: int, size: int, key: str) -> FittedModels:
    where = f"{key} {path}"
    try:
        data = read_yaml_file(path, "model file")
    except InputError as err:
        raise InputError(f"{key}: {err}") from None
    if not isinstance(data, dict) or data.get("format") != MODEL_FORMAT:
        raise InputError(f"{where}: not a model file of `python -m bpy_pipeline fit` (format: {MODEL_FORMAT!r})")
    if data.get("version") != MODEL_VERSION:
        raise InputError(f"{where}: version {data.get('version')!r}; this package reads version {MODEL_VERSION}")
    drop, noise = data.get("drop") or {}, data.get("noise") or {}
    try:
        uniform = float(drop["uniform"]["probability"]) if "uniform" in drop else None
        threshold = None
        if "threshold" in drop:
            t = drop["threshold"]
            threshold = ThresholdModel(float(t["sensitivity"]), float(t["exponent"]), float(t["softness"]), float(t.get("alpha", 0.0)))
        noise_range = (float(noise["range"]["sigma"]), float(noise["range"]["sigma_per_metre"])) if "range" in noise else None
    except (KeyError, TypeError, ValueError) as err:
        raise InputError(f"{where}: a model lacks a parameter or holds a non-number ({err})") from None
    drop_table = BinnedTable.from_dict(drop["table"], "probability", f"{where}: drop.table") if "table" in drop else None
    noise_table = BinnedTable.from_dict(noise["table"], "sigma", f"{where}: noise.table") if "table" in noise else None
    drop_mlp = MLP.from_dict(drop["mlp"], f"{where}: drop.mlp") if "mlp" in drop else None
    noise_mlp = MLP.from_dict(noise["mlp"], f"{where}: noise.mlp") if "mlp" in noise else None
    return FittedModels(uniform, threshold, drop_table, noise_range, noise_table, data.get("source") or {}, drop_mlp, noise_mlp)


def fitted_models(section, where: str = "model_file") -> FittedModels | None:
    """The models of a config section's ``model_file`` (``effects.drop`` or ``effects.noise``),
    or ``None`` when it names none."""
    return read_model_file(section.model_file, where) if section.model_file else None


# ----------------------------------------------------------------------------- applying them
def drop_probability(points: np.ndarray, beam: np.ndarray, effects, models: FittedModels | None = None) -> np.ndarray | None:
    """Probability that each traced point is lost, (p,) float32, for the configured model
    (:mod:`.drop`); ``None`` for a model that drops nothing. ``models``: those of
    ``effects.drop.model_file``, read here when not given."""
    models = fitted_models(effects.drop, "effects.drop.model_file") if models is None else models
    return DROP_MODELS.get(effects.drop.model).probability(points, beam, effects, models)


def drop_mask(points: np.ndarray, beam: np.ndarray, effects, rng: np.random.Generator, models: FittedModels | None = None) -> np.ndarray | None:
    """(p,) bool, True for the points that survive the configured drop model; ``None`` keeps all.

    One draw per point against its probability, unless the model draws itself (``carla``: twice).
    """
    model = DROP_MODELS.get(effects.drop.model)
    if len(points) == 0 or model.probability(points[:0], beam[:0], effects, models) is None:
        return None
    if model.mask is not None:
        return model.mask(points, beam, effects, rng, models)
    return rng.random(len(points), dtype=np.float32) >= drop_probability(points, beam, effects, models)


def noise_sigma(points: np.ndarray, beam: np.ndarray, noise, models: FittedModels | None = None) -> np.ndarray | float:
    """Range noise sigma (m) of each point: a float for ``constant``, else (p,) float32."""
    if noise.model == "constant":
        return noise.sigma
    if noise.model == "range":
        sigma, slope = models.noise_range if models is not None and models.noise_range is not None else (noise.sigma, noise.sigma_per_metre)
        return np.float32(sigma) + np.float32(slope) * points["range"]
    if noise.model == "mlp":
        if models is None or models.noise_mlp is None:
            raise InputError("effects.noise.model_file: the mlp noise model needs a model file holding a noise mlp (python -m bpy_pipeline fit)")
        return models.noise_mlp.lookup(points["range"], beam["cos_incidence"])
    if models is None or models.noise_table is None:
        raise InputError("effects.noise.model_file: the table noise model needs a model file holding a noise table (python -m bpy_pipeline fit)")
    return models.noise_table.lookup(points["range"], beam["cos_incidence"])


_NONE32 = np.zeros(0, np.float32)
_NO_RINGS = np.zeros(0, np.uint16)


def perturb(points: np.ndarray, beam: np.ndarray, noise, rng: np.random.Generator, models: FittedModels | None = None) -> None:
    """Range noise, per-ring bias and angular jitter applied to ``points`` in place (sensor frame).

    The range moves by ``N(0, sigma) + bias[ring]`` (clamped at 0) and the point moves as much
    along its beam (``beam["direction"]``: the emitted ray, or the last segment of a point at its
    true position behind mirrors), so ``x y z`` and ``range`` stay consistent. With jitter the
    point first turns by ``N(0, jitter)`` in azimuth and in elevation about the sensor's origin
    (tangent-plane step, length kept).
    """
    n = len(points)
    sigma = noise_sigma(points, beam, noise, models)
    has_noise = np.any(np.asarray(sigma) > 0)
    jitter = math.radians(noise.angular_jitter_deg)
    if n == 0 or not (has_noise or noise.ring_bias or jitter > 0):
        return
    if noise.ring_bias:
        bias = np.asarray(noise.ring_bias, np.float32)
        ring = points["ring"]
        if ring.max() >= len(bias):
            raise InputError(f"effects.noise.ring_bias: {len(bias)} values but the scan has ring {int(ring.max())}; give one per ring")
    fits = jitter == 0 and points.dtype == POINT_DTYPE and points.flags.c_contiguous and (np.isscalar(sigma) or (sigma.dtype == np.float32 and sigma.shape == (n,)))
    kernels = effects_kernels.compiled() if fits else None
    if kernels is not None:  # the same operations in one compiled pass over the records (effects_kernels.py)
        draw = rng.standard_normal(n, dtype=np.float32) if has_noise else _NONE32
        sigmas = _NONE32 if np.isscalar(sigma) else np.ascontiguousarray(sigma)
        one = np.float32(sigma) if np.isscalar(sigma) else np.float32(0)
        biases, rings = (bias, np.ascontiguousarray(ring)) if noise.ring_bias else (_NONE32, _NO_RINGS)
        kernels.move_along_beam(points, beam["direction"], draw, one, sigmas, biases, rings)
        return
    old = points["range"]
    new = old.copy()
    if has_noise:
        draw = rng.standard_normal(n, dtype=np.float32)
        draw *= np.float32(sigma) if np.isscalar(sigma) else sigma
        new += draw
    if noise.ring_bias:
        new += bias[ring]
    np.maximum(new, np.float32(0), out=new)
    if jitter > 0:
        # p' = p + |p| (a e_az + e e_el), with e_az = (-y, x, 0) / rho and e_el = (-x z, -y z, rho^2) / (rho |p|)
        # orthonormal to p, so |p'| = |p| sqrt(1 + a^2 + e^2): divided by that, the length is kept;
        # beams along z (rho ~ 0) keep still
        x, y, z = (np.ascontiguousarray(points[k]) for k in "xyz")  # packed records: strided math is slower
        a, e = rng.standard_normal((2, n), dtype=np.float32) * np.float32(jitter)
        rho2 = x * x
        rho2 += y * y
        rho = np.sqrt(rho2)
        length = np.sqrt(rho2 + z * z)
        still = rho <= np.float32(1e-6) * length
        if still.any():
            a[still], e[still], rho[still] = 0.0, 0.0, 1.0
        stretch = a * a
        stretch += e * e
        stretch += np.float32(1)
        np.sqrt(stretch, out=stretch)
        keep = np.float32(1) / stretch
        e /= rho  # elevation step per unit of (-x z, -y z, rho^2)
        a *= length
        a /= rho  # azimuth step per unit of (-y, x, 0)
        ez = e * z
        points["x"] = (x - y * a - x * ez) * keep
        points["y"] = (y + x * a - y * ez) * keep
        points["z"] = (z + rho2 * e) * keep
    step = new - old
    direction = beam["direction"]
    for axis, k in enumerate("xyz"):
        points[k] += step * direction[:, axis]
    points["range"] = new


def _copy_records(records: np.ndarray, keep: np.ndarray | None = None) -> np.ndarray:
    """A copy of a structured array, of only its ``keep`` rows when given.

    Through a same-size opaque (void) view: numpy copies packed records field by field
    otherwise, ten times slower for :data:`POINT_DTYPE`.
    """
    records = np.ascontiguousarray(records)
    raw = records.view(np.dtype((np.void, records.dtype.itemsize)))
    return (raw.copy() if keep is None else raw[keep]).view(records.dtype)


CHUNK_POINTS = 1 << 16  # records per work item: a chunk's fields stay in cache across the passes over it


def _apply_chunk(points, beam, effects, rng, drop_models, noise_models, objects=None, detection=None) -> np.ndarray:
    if getattr(effects, "materials", None) is not None:  # per-class or per-object reflectance models (lidar/effects/materials.py), opt-in
        beam = apply_materials(points, beam, effects.materials, effects.intensity.incidence_exponent, objects)
    intensity = compute_intensity(points["range"], beam, effects.intensity, points["ring"], rng)
    seen = beam
    if detection is not None:  # the drop decision sees these reflectivities, the reading the beam's (mixing/paint.py)
        seen = beam.copy()
        seen["reflectivity"] = detection
    keep = drop_mask(points, seen, effects, rng, drop_models)
    points = _copy_records(points, keep)
    if keep is not None:
        beam, intensity = _copy_records(beam, keep), intensity[keep]
    points["intensity"] = intensity
    if weather_active(effects):
        points, keep = apply_weather(points, beam, effects, rng, threshold_model(effects, drop_models).detection_probability)
        points, beam = points[keep], _copy_records(beam, keep)
    perturb(points, beam, effects.noise, rng, noise_models)
    return points


def weather_active(effects) -> bool:
    """True when ``effects.weather`` asks for fog, rain, snow or a wet ground and ``effects.ideal`` does not turn it off."""
    weather = getattr(effects, "weather", None)
    return weather is not None and not effects.ideal and weather.active


def apply_effects(points: np.ndarray, beam: np.ndarray, effects, rng: np.random.Generator, threads: int | None = None, objects=None, pool: Executor | None = None,
                  detection: np.ndarray | None = None) -> np.ndarray:
    """The configured effects (``config.EffectsConfig``) in a fixed order; returns new records.

    points : (p,) POINT_DTYPE records (sensor frame); beam : (p,) BEAM_DTYPE facts of the same points
    1. intensity of the true geometry; 2. ray drop (it sees the true range, as the receiver
    does); 3. weather (``effects.weather``, :mod:`.weather`: attenuation, scatterer returns, the noise
    floor); 4. range noise, ring bias and angular jitter on the points that remain.
    The points go through in chunks of :data:`CHUNK_POINTS` on ``threads`` threads (default: every core;
    1: in this thread): this one and others of ``pool`` (an executor the caller keeps, e.g. the run's: no
    threads started per call) or else started for the call (:func:`bpy_pipeline.lidar.cast.sharing.share`). Chunk k draws from its
    own generator, seeded by the k-th of one draw of seeds from ``rng``, so the same generator state gives
    the same bytes however the threads run.
    ``objects``: the scene's ObjectTable, for ``effects.materials.objects`` (per-object reflectance models).
    ``detection``: (p,) float32 reflectivities the drop decision sees instead of the beam's (None: the beam's), the
    reading still the beam's (``scene.car_paint`` parts' ``detection``, mixing/paint.py).
    """
    drop_models = fitted_models(effects.drop, "effects.drop.model_file")
    noise_models = fitted_models(effects.noise, "effects.noise.model_file")
    if weather_active(effects) and effects.weather.fog.visibility > 0:  # the fog's soft-target table, once, before the threads share it
        fog_soft_table(fog_alpha(effects.weather.fog.visibility), effects.weather.fog.pulse_ns)
    for models in (drop_models, noise_models):
        for table in (models.drop_table, models.noise_table) if models is not None else ():
            if table is not None:
                table._raster  # build the lookup raster once, before the threads share it
    starts = range(0, max(len(points), 1), CHUNK_POINTS)
    seeds = rng.integers(0, 2**63, size=len(starts), dtype=np.int64)

    def chunk(k: int) -> np.ndarray:
        part = slice(starts[k], starts[k] + CHUNK_POINTS)
        return _apply_chunk(points[part], beam[part], effects, np.random.Generator(np.random.PCG64(seeds[k])), drop_models, noise_models, objects,
                            None if detection is None else detection[part])

    if len(starts) == 1:
        return chunk(0)
    threads = threads or os.cpu_count() or 1
    if pool is not None or threads == 1:
        parts = share(pool, chunk, range(len(starts)), threads)
    else:
        with ThreadPoolExecutor(threads - 1) as own:
            parts = share(own, chunk, range(len(starts)), threads)
    raw = np.dtype((np.void, points.dtype.itemsize))
    return np.concatenate([p.view(raw) for p in parts]).view(points.dtype)
