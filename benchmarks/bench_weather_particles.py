"""What a rain drop or snow flake costs to draw (lidar/effects/weather/), and the memory of drawing them in passes.

VLP-16 returns at ranges uniform in 1..100 m, its realistic profile's noise floor; the visible particles of
each return's cone are drawn and the strongest offered (``_offer_particles``), timed best of the rounds. The
seconds per particle is the estimate's ``WEATHER_S_PER_PARTICLE`` (bpy_pipeline/estimate.py). Beside it, the
peak memory (tracemalloc) of the heaviest documented case, rain at 300 mm/h through a 100 mrad beam, against
the estimate's particle count: drawn in passes of ``PARTICLES_PER_PASS``, the peak stays that of one pass.
Pure: no Blender. Run: python benchmarks/bench_weather_particles.py [--small]
"""

import time
import tracemalloc

import numpy as np
from common import arguments, report

from bpy_pipeline.config import load_config
from bpy_pipeline.lidar.effects import weather
from bpy_pipeline.lidar.effects.drop.threshold import threshold_model
from bpy_pipeline.lidar.effects.apply import fitted_models


def draw(config, r: np.ndarray, seed: int = 0):
    """Draw and offer the rain of ``config`` for returns at ranges ``r``; (seconds, peak bytes, expected particles)."""
    rain, divergence = config.effects.weather.rain, (config.effects.weather.divergence_mrad or weather.DEFAULT_DIVERGENCE_MRAD) * 1e-3
    detect = threshold_model(config.effects, fitted_models(config.effects.drop)).detection_probability
    particles = weather._rain_particles(rain)
    grid, cumulative, _ = weather._visible_mass(float(r.max()), particles, divergence, detect, 0.0)
    expected = float(np.interp(r, grid, cumulative).sum())
    medium = weather._Medium(np.ones(len(r)), r.copy(), np.zeros(len(r)), np.full(len(r), -1, np.int8), np.full(len(r), np.nan))
    tracemalloc.start()
    start = time.perf_counter()
    weather._offer_particles(medium, r, particles, divergence, detect, 0.0, 1, np.random.default_rng(seed))
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return seconds, peak, expected


def main() -> None:
    args = arguments(__doc__)
    rounds = 2 if args.small else 3
    rows = []
    for name, settings, returns in (("rain 50 mm/h, 3 mrad", {"rain": {"rate": 50}}, 3000 if args.small else 30000),
                                    ("rain 300 mm/h, 100 mrad", {"rain": {"rate": 300}, "divergence_mrad": 100}, 100 if args.small else 1000)):
        config = load_config({"sensor": {"preset": "vlp16"}, "effects": {"weather": settings}})
        r = np.random.default_rng(1).uniform(1.0, 100.0, returns)
        runs = [draw(config, r, seed) for seed in range(rounds)]
        seconds, peak, expected = min(run[0] for run in runs), max(run[1] for run in runs), runs[0][2]
        rows.append({"weather": name, "returns": returns, "particles": round(expected), "seconds": round(seconds, 3),
                     "ns per particle": round(seconds / expected * 1e9, 1), "peak MB": round(peak / 1e6, 1),
                     "peak bytes per particle": round(peak / expected, 2)})
    report("weather_particles", rows, args.out, {"rounds": rounds, "pass": weather.PARTICLES_PER_PASS,
                                                 "method": "_offer_particles timed best of the rounds; peak by tracemalloc; particles: the Poisson mean drawn"})


if __name__ == "__main__":
    main()
