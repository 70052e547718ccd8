"""The effects' compiled pass gives the numpy path's bytes, and the run's pool gives the bytes of a pool per call."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest

from bpy_pipeline.config import NoiseConfig, load_config
from bpy_pipeline.lidar.effects import effects_kernels
from bpy_pipeline.lidar.effects.apply import apply_effects, perturb
from bpy_pipeline.lidar.points import BEAM_DTYPE, POINT_DTYPE


def cloud(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points on rays from the origin at 0.5-120 m (a few at 0.001 m, so a negative bias clamps), with their beam facts."""
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    r = rng.uniform(0.5, 120.0, n)
    r[:50] = 1e-3
    points = np.zeros(n, POINT_DTYPE)
    for axis, k in enumerate("xyz"):
        points[k] = d[:, axis] * r
    points["range"], points["ring"] = r, rng.integers(0, 16, n)
    beam = np.zeros(n, BEAM_DTYPE)
    beam["direction"], beam["cos_incidence"] = d, rng.uniform(0, 1, n)
    beam["reflectivity"], beam["gain"] = rng.uniform(0.05, 0.9, n), 1.0
    return points, beam


NOISES = {
    "constant": {"model": "constant", "sigma": 0.02},
    "range": {"model": "range", "sigma": 0.01, "sigma_per_metre": 0.0005},
    "ring bias": {"model": "constant", "sigma": 0.01, "ring_bias": [float(b) for b in np.linspace(-0.5, 0.5, 16)]},
    "bias alone": {"model": "constant", "sigma": 0.0, "ring_bias": [-0.01 * k for k in range(16)]},
}


@pytest.mark.parametrize("name", NOISES)
def test_compiled_noise_pass_gives_the_numpy_bytes(name, monkeypatch):
    pytest.importorskip("numba")
    noise = NoiseConfig(**NOISES[name])
    points, beam = cloud(20_000)
    runs = {}
    for kernel in ("numba", "numpy"):
        monkeypatch.setenv("BPY_PIPELINE_SCAN_KERNEL", kernel)
        assert (effects_kernels.compiled() is None) == (kernel == "numpy")
        out = points.copy()
        perturb(out, beam, noise, np.random.default_rng(3))
        runs[kernel] = out.tobytes()
    assert runs["numba"] == runs["numpy"]
    assert runs["numba"] != points.tobytes()  # the noise moved the points
    if name == "ring bias":  # the clamp at 0 was met
        assert (np.frombuffer(runs["numba"], POINT_DTYPE)["range"] == 0).any()


def test_preset_effects_give_the_same_bytes_compiled_numpy_on_a_kept_pool_or_a_pool_per_call(monkeypatch):
    effects = load_config(None, ["sensor.preset=os1_128"]).effects
    effects = replace(effects, noise=replace(effects.noise, ring_bias=[0.001 * k for k in range(16)]))
    points, beam = cloud(150_000, seed=1)  # three chunks of CHUNK_POINTS
    outs = []
    with ThreadPoolExecutor(2) as pool:
        for kernel in ("numba", "numpy"):
            monkeypatch.setenv("BPY_PIPELINE_SCAN_KERNEL", kernel)
            outs.append(apply_effects(points, beam, effects, np.random.default_rng(7), pool=pool).tobytes())
            outs.append(apply_effects(points, beam, effects, np.random.default_rng(7)).tobytes())
            outs.append(apply_effects(points, beam, effects, np.random.default_rng(7), threads=1).tobytes())
    assert len(set(outs)) == 1
    assert len(outs[0]) < points.nbytes  # the drop took points
