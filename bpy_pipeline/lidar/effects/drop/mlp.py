"""``mlp``: a drop probability over (range, incidence angle) from a small multi-layer perceptron
fitted to real scans (a model file of ``python -m bpy_pipeline fit``).

The Raphael paper (Realistic 3D Data Generation and Unsupervised Learning for Enhanced
Human-Robot Detection in the Real World) bins the firings by beam range ``d`` and incidence
angle ``phi``, keeps the bins with at least 100 samples, computes each bin's mean range, mean
angle and drop ratio ``(d_mean, phi_mean, P)``, and trains a small MLP to predict ``P`` from
``(d, phi)``, which the simulator then samples at run time; a second MLP predicts the range-noise
sigma from the same bins. This module holds that network in numpy alone: :class:`MLP` (tanh
hidden layers, a sigmoid output for a probability or an exponential one for a positive
quantity such as a sigma), :func:`fit_mlp` (full-batch Adam from one seeded generator: the same
seed gives the same bytes) and the ``mlp`` drop model's registration. The noise MLP
(``effects.noise.model: mlp``) is the same class, fitted by :func:`.fitting.fit_noise_mlp`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ....errors import InputError
from ....schema import meta
from .base import DropModel, register_drop_model

OUTPUTS = ("probability", "positive")  # sigmoid, exp


@dataclass(frozen=True)
class MLP:
    """A small perceptron over (range, incidence angle).

    weights : tuple of (fan_in, fan_out) float64 arrays, first layer fan_in 2
    biases : tuple of (fan_out,) float64 arrays; the last layer has one output
    range_span : (lo, hi) metres the network was fitted over; queries are clamped into it
    output : ``probability`` (sigmoid of the last layer) or ``positive`` (its exponential)
    Features: ``2 (ln R - ln lo) / (ln hi - ln lo) - 1`` and ``phi / 45 - 1`` (phi in degrees),
    both in -1..1; hidden layers use tanh.
    """

    weights: tuple = field(metadata=meta(help="(fan_in, fan_out) weight matrices, the first layer's fan_in 2"))
    biases: tuple = field(metadata=meta(help="(fan_out,) bias vectors; the last layer has one output"))
    range_span: tuple[float, float] = field(metadata=meta("m", 0, low_open=True, help="(lo, hi) the network was fitted over; queries are clamped into it"))
    output: str = field(default="probability", metadata=meta(help="probability (sigmoid of the last layer) or positive (its exponential)"))

    def __post_init__(self):
        object.__setattr__(self, "weights", tuple(np.asarray(w, np.float64) for w in self.weights))
        object.__setattr__(self, "biases", tuple(np.asarray(b, np.float64) for b in self.biases))
        object.__setattr__(self, "range_span", (float(self.range_span[0]), float(self.range_span[1])))

    def check(self, where: str) -> None:
        """``InputError`` naming ``where`` when the network is malformed."""
        if self.output not in OUTPUTS:
            raise InputError(f"{where}.output: expected one of {', '.join(OUTPUTS)}, got {self.output!r}")
        lo, hi = self.range_span
        if not 0 < lo < hi:
            raise InputError(f"{where}.range_span: need 0 < lo < hi metres, got {list(self.range_span)}")
        if not self.weights or len(self.weights) != len(self.biases):
            raise InputError(f"{where}: need as many weight matrices as bias vectors, at least one")
        fan_in = 2
        for k, (w, b) in enumerate(zip(self.weights, self.biases)):
            if w.ndim != 2 or w.shape[0] != fan_in or b.shape != (w.shape[1],):
                raise InputError(f"{where}.layers[{k}]: weights must be {fan_in} x n and bias n, got {w.shape} and {b.shape}")
            if not (np.isfinite(w).all() and np.isfinite(b).all()):
                raise InputError(f"{where}.layers[{k}]: holds a non-finite number")
            fan_in = w.shape[1]
        if fan_in != 1:
            raise InputError(f"{where}: the last layer must have one output, got {fan_in}")

    def features(self, range_m: np.ndarray, incidence_deg: np.ndarray, dtype=np.float64) -> np.ndarray:
        """(p, 2) network inputs of ``(p,)`` ranges (m) and incidence angles (deg), clamped to the fitted span."""
        lo, hi = self.range_span
        r = np.clip(np.asarray(range_m, dtype), dtype(lo), dtype(hi))
        x = np.empty((len(r), 2), dtype)
        x[:, 0] = (np.log(r) - dtype(math.log(lo))) * dtype(2.0 / math.log(hi / lo)) - dtype(1.0)
        x[:, 1] = np.clip(np.asarray(incidence_deg, dtype), 0, 90) * dtype(1.0 / 45.0) - dtype(1.0)
        return x

    def logits(self, x: np.ndarray) -> np.ndarray:
        """(p,) last-layer outputs of (p, 2) features, in the features' dtype."""
        h = x
        for k, (w, b) in enumerate(zip(self.weights, self.biases)):
            h = h @ w.astype(x.dtype) + b.astype(x.dtype)
            if k < len(self.weights) - 1:
                np.tanh(h, out=h)
        return h[:, 0]

    def predict(self, range_m: np.ndarray, incidence_deg: np.ndarray, dtype=np.float64) -> np.ndarray:
        """(p,) outputs at ranges (m) and incidence angles (deg): a probability or a positive value."""
        z = self.logits(self.features(range_m, incidence_deg, dtype))
        if self.output == "probability":
            return (dtype(1.0) / (dtype(1.0) + np.exp(-np.clip(z, -60, 60)))).astype(dtype)
        return np.exp(np.clip(z, -60, 60)).astype(dtype)

    def lookup(self, range_m: np.ndarray, cos_incidence: np.ndarray) -> np.ndarray:
        """(p,) float32 outputs at ranges (m) and cosines of incidence: the scan-time query (as BinnedTable.lookup)."""
        angle = np.degrees(np.arccos(np.clip(np.asarray(cos_incidence, np.float32), 0, 1)))
        return self.predict(range_m, angle, np.float32)

    @property
    def parameters(self) -> int:
        return int(sum(w.size + b.size for w, b in zip(self.weights, self.biases)))

    def to_dict(self) -> dict:
        """A YAML-ready mapping; floats are written exactly (Python's repr), so the file round-trips bit for bit."""
        return {
            "output": self.output, "range_span": [float(v) for v in self.range_span], "activation": "tanh",
            "features": "2 (ln R - ln lo) / (ln hi - ln lo) - 1, incidence_deg / 45 - 1",
            "layers": [{"weights": [[float(v) for v in row] for row in w], "bias": [float(v) for v in b]} for w, b in zip(self.weights, self.biases)],
        }

    @classmethod
    def from_dict(cls, data, where: str) -> "MLP":
        if not isinstance(data, dict) or any(k not in data for k in ("output", "range_span", "layers")) or not isinstance(data["layers"], list):
            raise InputError(f"{where}: expected a mapping with output, range_span and a list of layers (weights, bias)")
        try:
            layers = [(np.array(layer["weights"], np.float64), np.array(layer["bias"], np.float64)) for layer in data["layers"]]
            span = [float(v) for v in data["range_span"]]
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{where}: a layer lacks weights or bias, or holds something that is not a number") from None
        if len(span) != 2:
            raise InputError(f"{where}.range_span: expected [lo, hi] metres, got {data['range_span']!r}")
        model = cls(tuple(w for w, _ in layers), tuple(b for _, b in layers), tuple(span), data["output"])
        model.check(where)
        return model


def fit_mlp(range_m: np.ndarray, incidence_deg: np.ndarray, target: np.ndarray, weight: np.ndarray, range_span: tuple[float, float],
            output: str = "probability", hidden: tuple[int, ...] = (16, 16), steps: int = 3000, learning_rate: float = 0.01,
            decay: float = 1e-4, seed: int = 0) -> MLP:
    """Fit an :class:`MLP` to binned statistics by full-batch Adam.

    range_m, incidence_deg : (b,) float64 bin means (m, deg); target : (b,) float64 the bins'
    statistic (a probability for ``probability``, > 0 for ``positive``); weight : (b,) float64
    each bin's weight (its sample count). Loss: the weighted mean cross-entropy of the targets
    under the sigmoid (``probability``: the binned data's likelihood) or the weighted mean squared
    error of ``ln target`` (``positive``), plus ``decay`` times the squared weights. Glorot-normal
    start from ``numpy.random.default_rng(seed)``; the same arguments give the same bytes.
    """
    if output not in OUTPUTS:
        raise ValueError(f"output must be one of {OUTPUTS}")
    rng = np.random.default_rng(seed)
    sizes = (2, *hidden, 1)
    weights = [rng.standard_normal((a, b)) * math.sqrt(2.0 / (a + b)) for a, b in zip(sizes[:-1], sizes[1:])]
    biases = [np.zeros(b) for b in sizes[1:]]
    target = np.asarray(target, np.float64)
    w_bin = np.asarray(weight, np.float64) / np.sum(weight)
    if output == "probability":
        base = np.clip(np.sum(w_bin * target), 1e-6, 1 - 1e-6)
        biases[-1][0] = math.log(base / (1 - base))  # start at the mean rate
        y = target
    else:
        y = np.log(np.maximum(target, 1e-12))
        biases[-1][0] = float(np.sum(w_bin * y))
    x = MLP(weights, biases, range_span, output).features(range_m, incidence_deg)
    params = weights + biases
    m = [np.zeros_like(p) for p in params]
    v = [np.zeros_like(p) for p in params]
    beta1, beta2, eps = 0.9, 0.999, 1e-8
    n_layers = len(weights)
    for step in range(1, steps + 1):
        acts = [x]
        for k in range(n_layers):
            h = acts[-1] @ weights[k] + biases[k]
            acts.append(np.tanh(h) if k < n_layers - 1 else h)
        z = acts[-1][:, 0]
        if output == "probability":
            grad_z = (1.0 / (1.0 + np.exp(-np.clip(z, -60, 60))) - y) * w_bin  # d(weighted BCE)/dz
        else:
            grad_z = 2.0 * (z - y) * w_bin
        delta = grad_z[:, None]
        grads_w, grads_b = [None] * n_layers, [None] * n_layers
        for k in range(n_layers - 1, -1, -1):
            grads_w[k] = acts[k].T @ delta + 2.0 * decay * weights[k]
            grads_b[k] = delta.sum(axis=0)
            if k:
                delta = (delta @ weights[k].T) * (1.0 - acts[k] ** 2)
        grads = grads_w + grads_b
        correction1, correction2 = 1.0 - beta1**step, 1.0 - beta2**step
        for p, g, mk, vk in zip(params, grads, m, v):
            mk *= beta1
            mk += (1.0 - beta1) * g
            vk *= beta2
            vk += (1.0 - beta2) * g * g
            p -= learning_rate * (mk / correction1) / (np.sqrt(vk / correction2) + eps)
    return MLP(tuple(weights), tuple(biases), range_span, output)


def probability(points, beam, effects, models) -> np.ndarray:
    if models is None or getattr(models, "drop_mlp", None) is None:
        raise InputError("effects.drop.model_file: the mlp drop model needs a model file holding a drop mlp (python -m bpy_pipeline fit)")
    return models.drop_mlp.lookup(points["range"], beam["cos_incidence"])


register_drop_model("mlp", DropModel(probability, fitted="drop_mlp"))
