"""The work a run asks for, estimated from its config alone, before Blender builds anything.

:func:`estimate_run` counts, per frame, the rays of every sensor, the scene's triangles and objects
(from the builder's parameters and the population; measured figures for the builders' fixed
content), the points and the bytes the writers will write, and turns them into seconds with a cost
model whose constants are figures of ``benchmarks/results/*.json`` (each constant names its
source; the machine: 2 cores). :func:`check_limits` refuses a run whose estimate exceeds a
``limits.*`` key of the config (config.py ``LimitsConfig``) with one line naming the figure, the
limit and the key to raise. The command line sizes its progress bar's ETA with the same estimate.

The estimate is for one process; ``--workers N`` divides the wall time by about ``0.88 N``
(benchmarks/results/reference_jobs.json). It is an estimate, not a promise: its error against
measured runs on the reference jobs is in docs/datasets.md (benchmarks/bench_hardening.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from .config import Config
from .errors import InputError

# ----------------------------------------------------------------------------- cost model
# benchmarks/results/default_job.json (python run.py, the default railway job: 1,441,800 rays, 614,941 points):
STARTUP_S = 0.69  # startup_s 0.688: Python, bpy and the package imported, before the first frame
SCAN_S_PER_RAY = 0.4141 / 1_441_800  # scan 0.4141 s (trace + effects, 2 threads): 287 ns a ray
HIT_FRACTION = 614_941 / 1_441_800  # points / rays of the default job: 0.43
WRITE_S_PER_POINT_FORMAT = 0.1072 / 614_941 / 2  # write 0.1072 s for ply + semantickitti (+ preview): 87 ns a point and format
# benchmarks/results/scan.json, "default railway (railway_tls)": caster_ns_per_triangle 143.4 (Embree's scene built once a frame)
CASTER_S_PER_TRIANGLE = 143.4e-9
# benchmarks/results/weather_particles.json, "rain 50 mm/h, 3 mrad": 2.45e7 visible drops for 30,000 VLP-16 returns at
# 1..100 m drawn and offered in 3.555 s, 145 ns each
WEATHER_S_PER_PARTICLE = 145e-9
# benchmarks/results/population.json, "parking + car assets", populated in place: build 0.4029 s for 9 placed objects
OBJECT_S = 0.4029 / 9

# A builder's fixed content with its default parameters: (seconds a frame of build + export + boxes, triangles, objects)
BUILDER_BASE: dict[str, tuple[float, int, int]] = {
    "railway": (0.1554 + 0.0522, 215_106, 0),  # default_job.json: build, export; triangles 215,106
    "parking": (0.0132 + 0.0032 + 0.0559, 2_268, 0),  # scenes.json parking re-randomise; caster_reuse.json triangles 2,268
    "industrial_hall": (0.0284 + 0.0055 + 0.127, 19_472, 0),  # scenes.json industrial_hall; caster_reuse.json triangles 19,472
    "street": (0.367 + 0.0307 + 0.297, 215_106, 0),  # street.json "middle camera alone" (triangles: not measured, the railway's taken)
    "blend": (0.0715 + 0.0048 + 0.0867, 215_106, 0),  # population.json hall_twin populated in place (the user's file: not known before it opens)
    "real_scan": (0.0784, 0, 0),  # mixing.json: the exact per-firing cast, 78.35 ms a frame
    "primitives": (0.0132 + 0.0032, 0, 0),  # the parking's build + export as the smallest procedural scene; shapes counted below
}
DEFAULT_BASE = (0.2, 215_106, 0)  # a builder registered later: the default job's figures
TRIANGLES_PER_PLACED_OBJECT = 5_000  # assumed (a procedural person or car is a few thousand triangles); not measured

# Bytes a point takes in each format (the formats' record sizes: PLY 35 B, LAS 46 B, SemanticKITTI 20 B, PCD 41 B, NPY 22 B)
BYTES_PER_POINT = {"ply": 35, "las": 46, "semantickitti": 20, "pcd": 41, "npy": 22}
DEFAULT_BYTES_PER_POINT = 64  # any other writer (dataset.py's generous figure)
PREVIEW_BYTES = 200_000  # a preview PNG


@dataclass(frozen=True)
class Estimate:
    """The work of ``frames`` frames: per-frame counts, and totals for the selected frames in one process.

    rays_per_frame, triangles, objects, points_per_frame : per frame (triangles and objects at most)
    bytes : B written; seconds : s in one process, start-up included; seconds_per_frame : s
    """

    frames: int
    rays_per_frame: int
    triangles: int
    objects: int
    points_per_frame: float
    bytes: float
    seconds_per_frame: float
    seconds: float
    parts: dict = field(default_factory=dict)  # seconds a frame by stage, for the note
    particles: float = 0.0  # visible rain drops and snow flakes drawn a frame (at most)

    def line(self) -> str:
        return (f"estimate: {self.frames:,} x ({self.rays_per_frame:,} rays, {self.triangles:,} triangles, {self.objects:,} objects); "
                f"{_size(self.bytes)} to write, about {_duration(self.seconds)} in one process ({self.seconds_per_frame:.2g} s each)")


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if n < 1000 or unit == "TB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return ""


def _duration(s: float) -> str:
    if s < 120:
        return f"{s:.3g} s"
    if s < 7200:
        return f"{s / 60:.3g} min"
    if s < 3 * 86400:
        return f"{s / 3600:.3g} h"
    return f"{s / 86400:.3g} days"


# ----------------------------------------------------------------------------- counting from the config
def _upper(value) -> float:
    """The most a count can be: an int, or a Distribution's ``max``."""
    if isinstance(value, (int, float)):
        return float(value)
    return float(getattr(value, "max", 0.0))


def _expected(value) -> float:
    """The mean of a count: an int, or a Distribution's mean (normal: clipped to its bounds; uniform: the middle)."""
    if isinstance(value, (int, float)):
        return float(value)
    if getattr(value, "kind", "") == "uniform":
        return (value.min + value.max) / 2
    return float(min(max(value.mean, value.min), value.max))


def _primitives(params) -> tuple[float, float, float]:
    """(triangles, objects, expected objects) of the primitives builder's shapes (geometry/primitives.py tessellation)."""
    triangles = 0
    for shape in params.shapes:
        s = max(int(shape.segments), 3)
        triangles += {"plane": 2, "box": 12, "sphere": 2 * s * max(s // 2, 2), "cylinder": 4 * s}.get(shape.type, 12)
    return triangles, len(params.shapes), len(params.shapes)


def _parking(params) -> tuple[float, float, float]:
    cars = _upper(params.cars)
    return cars * TRIANGLES_PER_PLACED_OBJECT, cars, _expected(params.cars)


def _hall(params) -> tuple[float, float, float]:
    placed = _upper(params.people) + params.robots
    return placed * TRIANGLES_PER_PLACED_OBJECT, placed, _expected(params.people) + params.robots


# builder -> (params -> (triangles, objects, expected objects) beyond the fixed content of BUILDER_BASE);
# the time of the objects a builder's default parameters place is in BUILDER_BASE already
SCENE_COUNTS: dict[str, Callable] = {"primitives": _primitives, "parking": _parking, "industrial_hall": _hall}


def _population(config: Config) -> tuple[float, float]:
    """(most, expected) objects the population places in a frame."""
    population = config.scene.population
    if population is None:
        return 0.0, 0.0
    counts = [getattr(params, "count", 0) for _, params in population.kinds]
    return float(sum(map(_upper, counts))), float(sum(map(_expected, counts)))


def _rays(config: Config) -> int:
    """Rays of a frame: every sensor of the rig (or the one sensor), times the sub-rays of a divergent beam."""
    from .lidar.sensor.sensors import ray_count

    specs = [member.spec for member in config.sensor.rig] if config.sensor.rig else [config.sensor.spec]
    sub_rays = max(int(getattr(config.sensor.divergence, "rays", 1) or 1), 1)
    return int(sum(ray_count(spec) for spec in specs)) * sub_rays


def _particles(config: Config) -> float:
    """The most weather particles (rain drops, snow flakes) a frame draws: each return's cone up to the sensor's max_range
    (:func:`~.lidar.effects.weather.expected_particles`), for the returns of every sensor of the frame."""
    from .lidar.effects.drop.threshold import threshold_model
    from .lidar.effects.apply import fitted_models
    from .lidar.sensor.sensors import ray_count
    from .lidar.effects.weather import expected_particles

    weather = config.effects.weather
    if config.effects.ideal or not weather.active:
        return 0.0
    detect = threshold_model(config.effects, fitted_models(config.effects.drop, "effects.drop.model_file")).detection_probability
    specs = [member.spec for member in config.sensor.rig] if config.sensor.rig else [config.sensor.spec]
    return sum(ray_count(spec) * HIT_FRACTION * expected_particles(config.effects, spec.max_range, detect) for spec in specs)


def _write_bytes_per_point(config: Config) -> float:
    from .io.writers import frame_writers

    return float(sum(BYTES_PER_POINT.get(name, DEFAULT_BYTES_PER_POINT) for name in frame_writers(config) if name != "preview"))


def estimate_run(config: Config, frames: int | None = None) -> Estimate:
    """The :class:`Estimate` of ``frames`` frames of ``config`` (default: all of ``config.frames``); reads no scene."""
    from .io.writers import frame_writers

    frames = config.frames if frames is None else int(frames)
    builder = config.scene.builder
    base_s, base_triangles, base_objects = BUILDER_BASE.get(builder, DEFAULT_BASE)
    triangles, objects, expected = SCENE_COUNTS[builder](config.scene.params) if builder in SCENE_COUNTS else (0, 0, 0)
    if builder in SCENE_COUNTS:  # what the default parameters place is timed in BUILDER_BASE already
        from .builders import BUILDERS

        expected -= SCENE_COUNTS[builder](BUILDERS.get(builder).params())[2]
    placed, placed_expected = _population(config)
    triangles += base_triangles + placed * TRIANGLES_PER_PLACED_OBJECT
    objects += base_objects + placed
    expected = max(expected, 0.0) + placed_expected
    rays = _rays(config)
    points = rays * HIT_FRACTION
    writers = [name for name in frame_writers(config) if name != "preview"]
    parts = {
        "build": base_s + expected * OBJECT_S,
        "caster": triangles * CASTER_S_PER_TRIANGLE,
        "scan": rays * SCAN_S_PER_RAY,
        "write": points * WRITE_S_PER_POINT_FORMAT * max(len(writers), 1),
    }
    particles = _particles(config)
    if particles:
        parts["weather"] = particles * WEATHER_S_PER_PARTICLE
    per_frame = sum(parts.values())
    frame_bytes = points * _write_bytes_per_point(config) + (PREVIEW_BYTES if "preview" in frame_writers(config) else 0)
    return Estimate(frames, rays, int(triangles), int(objects), points, frame_bytes * frames, per_frame, STARTUP_S + per_frame * frames, parts, particles)


# limit key -> (the estimate's figure, what it is)
CHECKS: dict[str, tuple[Callable[[Estimate], float], str]] = {
    "rays_per_frame": (lambda e: e.rays_per_frame, "rays a frame"),
    "triangles": (lambda e: e.triangles, "triangles a frame"),
    "objects": (lambda e: e.objects, "objects a frame"),
    "seconds": (lambda e: e.seconds, "seconds in one process"),
    "bytes": (lambda e: e.bytes, "bytes to write"),
    "particles": (lambda e: e.particles, "rain and snow particles a frame"),
}


def check_limits(estimate: Estimate, config: Config) -> Estimate:
    """``estimate`` when within every ``limits.*`` key of ``config``; else ``InputError`` with the figures and the key."""
    for key, (figure, what) in CHECKS.items():
        value, limit = figure(estimate), getattr(config.limits, key)
        if value > limit:
            raise InputError(
                f"limits.{key}: this run is estimated at {value:.3g} {what}, above the limit of {limit:.3g} "
                f"({estimate.line()}); make less work (frames, sensor resolution, scene size) or raise it with --set limits.{key}={value * 1.1:.3g}"
            )
    return estimate
