"""Models fitted to real scans, as the files of ``python -m bpy_pipeline fit`` hold them.

:class:`BinnedTable` (a quantity over range and incidence angle, bilinear between bins) and
:class:`FittedModels` (every model a file may hold), written by :func:`write_model_file` and read by
:func:`read_model_file`. With ``effects.drop.model_file`` the ``uniform``, ``threshold`` and ``table`` drop
models take their parameters from the file, with ``effects.noise.model_file`` the ``range`` and ``table``
noise models do (:mod:`bpy_pipeline.lidar.fit.fitting` writes them).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import yaml

from ...errors import InputError
from ...yaml_text import read_yaml_file
from .drop.mlp import MLP
from .drop.threshold import ThresholdModel

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


def check_model_file(name: str, section, uses: dict) -> None:
    """``InputError`` when ``effects.<name>`` (``drop`` or ``noise``) needs a model file it lacks, gives a model's
    parameters both inline and from a file, or names a file without the model asked of it.

    uses : model name -> ``(FittedModels attribute, parameters given inline, their keys for the message)``
    """
    where = f"effects.{name}.model_file"
    if section.model in ("table", "mlp") and not section.model_file:
        raise InputError(f"{where}: the {section.model} {name} model needs a model file (python -m bpy_pipeline fit ... --out FILE.yaml)")
    if not section.model_file or section.model not in uses:
        return
    attr, inline, keys = uses[section.model]
    if inline:
        raise InputError(f"effects.{name}.{keys.split()[0]}: give either inline parameters ({keys}) or a model_file for the {section.model} model, not both")
    models = read_model_file(section.model_file, where)
    if getattr(models, attr) is None:
        raise InputError(f"{where}: {section.model_file} holds no {section.model} {name} model")
