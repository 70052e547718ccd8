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
    """``InputError`` naming the key of a missing scan, an unknown format or type, or a rule between fields (the fields' ranges: the schema's)."""
    if not params.path:
        raise InputError(f"{where}.path: the real_scan builder needs the path of a scan file ({', '.join(FORMATS)}), a folder of them or a glob pattern")
    if params.format and params.format not in FORMATS:
        raise InputError(f"{where}.format: {params.format!r} is not one of {', '.join(FORMATS)}")
    for k, o in enumerate(params.objects):
        check_type(o.type, f"{where}.objects[{k}].type")
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
    """``scene.population`` of a real scan (:class:`~bpy_pipeline.mixing.section.RealPopulation`): one line naming the key
    of an unknown surface kind or a bad height distribution (the fields' ranges: the schema's)."""
    for key in ("people_on", "arms_on"):
        bad = [k for k in getattr(pop, key) if k not in SURFACE_KINDS]
        if bad or not getattr(pop, key):
            raise InputError(f"{where}.{key}: a non-empty list of {', '.join(SURFACE_KINDS)}, got {list(getattr(pop, key))}")
    check_distribution(pop.person_height, f"{where}.person_height", low=0.3)
    s = pop.supports
    if s.desk_height[0] > s.desk_height[1]:
        raise InputError(f"{where}.supports.desk_height: expected [min, max] with min <= max, got {list(s.desk_height)}")


def build(params: RealScanScene, context: BuildContext) -> BuildResult:
    """Nothing to build in Blender: the real-scan frame plan makes the frame."""
    return BuildResult()


# the nuScenes sweep's sensor by default (give sensor.preset: hdl64e for KITTI scans)
register_builder("real_scan", Builder(RealScanScene, build, check, sensor={"preset": "hdl32e"}, boxes=True, plan="real_scan"))
