"""``scene.builder: real_scan``: a real scan as the background, synthetic objects cast in by its own firings.

No Blender scene: the real-scan frame plan (:mod:`bpy_pipeline.stages.mixing`: background, place,
cast, effects, annotate) reads the scan, places and meshes the objects in numpy, casts every real
firing at them (bpy_pipeline.mixing) and applies the configured effects (``effects``: the sensor
preset's fitted drop and noise unless ``effects.ideal``) to the inserted returns only.
"""

from __future__ import annotations

from ..errors import InputError
from ..geometry.placement import check_distribution
from ..io.real_scans import FORMATS
from ..mixing.objects import check_type
from ..mixing.section import RealScanScene
from .base import Builder, BuildContext, BuildResult, register_builder


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
        raise InputError(f"{where}.parking_rule.near_rejection_probability / near_rejection_distance: need 0..1 and >= 0 m, got {park.near_rejection_probability:g} and {park.near_rejection_distance:g}")
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


def build(params: RealScanScene, context: BuildContext) -> BuildResult:
    """Nothing to build in Blender: the real-scan frame plan makes the frame."""
    return BuildResult()


def __getattr__(name: str):
    """The frame's stages moved to the real-scan frame plan (:mod:`bpy_pipeline.stages.mixing`); their old names stay importable this round."""
    if name in ("kept_scan", "real_scan_stage"):
        from ..stages import mixing

        return getattr(mixing, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# the nuScenes sweep's sensor by default (give sensor.preset: hdl64e for KITTI scans)
register_builder("real_scan", Builder(RealScanScene, build, check, sensor={"preset": "hdl32e"}, boxes=True, plan="real_scan"))
