"""``scene.builder: real_scan``: a real scan as the background, synthetic objects cast in by its own firings.

No Blender scene: the real-scan frame plan (:mod:`bpy_pipeline.stages.mixing`: background, place,
cast, effects, annotate) reads the scan, places and meshes the objects in numpy, casts every real
firing at them (bpy_pipeline.mixing) and applies the configured effects (``effects``: the sensor
preset's fitted drop and noise unless ``effects.ideal``) to the inserted returns only.
"""

from __future__ import annotations

from ...errors import InputError
from ...geometry.placement import check_distribution
from ...io.real_scans import FORMATS
from ...mixing.objects import check_type
from ...mixing.section import RealScanScene
from ...mixing.supports import KINDS_OF_SURFACE as SURFACE_KINDS
from ..base import Builder, BuildContext, BuildResult, register_builder


def check(params: RealScanScene, where: str) -> None:
    if not params.path:
        raise InputError(f"{where}.path: the real_scan builder needs the path of a scan file ({', '.join(FORMATS)}), a folder of them or a glob pattern")
    if params.format and params.format not in FORMATS:
        raise InputError(f"{where}.format: {params.format!r} is not one of {', '.join(FORMATS)}")
    for k, o in enumerate(params.objects):
        check_type(o.type, f"{where}.objects[{k}].type")
        if any(s < 0 for s in o.size):
            raise InputError(f"{where}.objects[{k}].size: must be >= 0 (0: the type's nominal size), got {list(o.size)}")
    for k, r in enumerate(params.remove):
        if any(s <= 0 for s in r.size):
            raise InputError(f"{where}.remove[{k}].size: must be > 0, got {list(r.size)}")
    if params.max_range < 0:
        raise InputError(f"{where}.max_range: must be >= 0, got {params.max_range}")
    park = params.parking_rule
    if not 0.0 <= park.near_rejection_probability <= 1.0 or park.near_rejection_distance < 0:
        raise InputError(
            f"{where}.parking_rule.near_rejection_probability / near_rejection_distance: need 0..1 and >= 0 m, got {park.near_rejection_probability:g} and "
            f"{park.near_rejection_distance:g}"
        )
    rule = params.kitti_rule
    if rule.enabled:
        check_type(rule.type, f"{where}.kitti_rule.type")
    if not 0 <= rule.min_range <= rule.max_range:
        raise InputError(f"{where}.kitti_rule.min_range: must be 0 .. kitti_rule.max_range ({rule.max_range:g}), got {rule.min_range:g}")
    for k, parking in enumerate([params.parking_rule, *params.parking_rules]):
        key = f"{where}.parking_rule" if k == 0 else f"{where}.parking_rules[{k - 1}]"
        if parking.enabled:
            check_type(parking.type, f"{key}.type")
        check_distribution(parking.count, f"{key}.count", low=0.0)
        check_distribution(parking.distance, f"{key}.distance", low=0.0)
        check_distribution(parking.heading, f"{key}.heading", low=-180.0, high=180.0)
    check_population(params.population, f"{where}.population")


def check_population(pop, where: str) -> None:
    """``scene.population`` of a real scan (:class:`~bpy_pipeline.mixing.section.RealPopulation`): one line naming the key."""
    for key in ("people", "arms", "max_points"):
        if getattr(pop, key) < 0:
            raise InputError(f"{where}.{key}: must be >= 0, got {getattr(pop, key)}")
    for key in ("people_on", "arms_on"):
        bad = [k for k in getattr(pop, key) if k not in SURFACE_KINDS]
        if bad or not getattr(pop, key):
            raise InputError(f"{where}.{key}: a non-empty list of {', '.join(SURFACE_KINDS)}, got {list(getattr(pop, key))}")
    for key in ("tries",):
        if getattr(pop, key) < 1:
            raise InputError(f"{where}.{key}: must be >= 1, got {getattr(pop, key)}")
    for key in ("keep_out", "clearance", "margin", "reach", "arm_reach", "step", "min_range", "max_range"):
        if not getattr(pop, key) >= 0:
            raise InputError(f"{where}.{key}: must be >= 0 m, got {getattr(pop, key)}")
    check_distribution(pop.person_height, f"{where}.person_height", low=0.3)
    s = pop.supports
    for key in ("threshold", "voxel", "eps", "min_area", "min_width", "headroom", "floor_band"):
        if not getattr(s, key) > 0:
            raise InputError(f"{where}.supports.{key}: must be > 0 m, got {getattr(s, key)}")
    for key in ("iterations", "max_planes", "min_inliers", "min_samples", "sample"):
        if getattr(s, key) < 1:
            raise InputError(f"{where}.supports.{key}: must be >= 1, got {getattr(s, key)}")
    if not 0 <= s.max_tilt_deg < 90:
        raise InputError(f"{where}.supports.max_tilt_deg: must be 0 .. 90 (exclusive), got {s.max_tilt_deg}")
    if not 0 <= s.max_covered <= 1:
        raise InputError(f"{where}.supports.max_covered: must be 0 .. 1, got {s.max_covered}")
    if not 0 <= s.desk_height[0] <= s.desk_height[1]:
        raise InputError(f"{where}.supports.desk_height: expected 0 <= min <= max m, got {list(s.desk_height)}")


def build(params: RealScanScene, context: BuildContext) -> BuildResult:
    """Nothing to build in Blender: the real-scan frame plan makes the frame."""
    return BuildResult()


# the nuScenes sweep's sensor by default (give sensor.preset: hdl64e for KITTI scans)
register_builder("real_scan", Builder(RealScanScene, build, check, sensor={"preset": "hdl32e"}, boxes=True, plan="real_scan"))
