"""The public Python API, re-exported from :mod:`bpy_pipeline`: a handful of stable names over a moving implementation.

Example (runs as a test, tests/test_api.py)::

    import numpy as np
    import bpy_pipeline as bp

    # a scan without Blender: a 20 m box room around a VLP-16 1.5 m above the floor
    v = np.array([[x, y, z] for x in (-10, 10) for y in (-10, 10) for z in (0, 4)], float)
    t = np.array([[0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5]])
    pose = np.eye(4)
    pose[2, 3] = 1.5
    points = bp.scan({"room": (v, t, "wall")}, "vlp16", pose, effects={"ideal": True}, seed=1)  # ideal: no noise, no drop
    assert len(points) == 16 * 1809                 # every ray of the VLP-16 (16 x 1809 at 10 Hz) hits the room
    print(points.dtype.names)                         # x y z intensity semantic instance ring time range bounces

    # a run with Blender (the bpy module): two parking frames into a dataset folder
    config = bp.load_config({"scene": {"builder": "parking"}, "frames": 2})
    manifest = bp.run(config, "out/parking")
    cloud = bp.read_ply("out/parking/ply/000001.ply")
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from .buffers import ObjectTable, SceneBuffers
from .config import Config, config_from_dict
from .config import load_config as _load_config
from .errors import InputError
from .schema import check_ranges
from .evaluate import evaluate  # noqa: F401  (train on generated scans, IoU on real ones: docs/evaluate.md)


def load_config(path_or_dict: str | Path | Mapping | None = None, overrides: Iterable[str] = ()) -> Config:
    """The validated :class:`~.config.Config` of a YAML file or of a mapping (``None``: the defaults),
    with ``key.path=value`` overrides (``["sensor.preset=vlp16", "frames=10"]``)."""
    if isinstance(overrides, (str, bytes)) or not isinstance(overrides, Iterable):
        raise InputError(f"overrides: expected a list of 'key.path=value' strings, got {overrides!r}")
    return _load_config(dict(path_or_dict) if isinstance(path_or_dict, Mapping) else path_or_dict, list(overrides))


def run(config: Config, out: str | Path, frames: Iterable[int] | None = None, mode: str = "new", log=print) -> dict:
    """Make frames ``frames`` (default: all) of ``config`` into the dataset folder ``out``; returns the
    manifest with the frames' records. Blender's scene is reset to an empty one first (needs ``bpy``).

    mode : ``new`` (refuse a folder holding another run), ``resume`` or ``overwrite`` (see :mod:`.dataset`)
    Every argument is checked before anything is written: a bad one raises :class:`InputError` and commits no frame;
    a Config built or changed in Python (``dataclasses.replace``) has every field's range checked as a loaded one.
    """
    from .errors import path_argument
    from .estimate import check_limits, estimate_run

    if not isinstance(config, Config):
        raise InputError(f"config: expected a Config (bpy_pipeline.load_config(...) of a file or a mapping), got {type(config).__name__}")
    check_ranges(config)  # every field's metadata range, as load_config checks them: a Config built or changed in Python too
    path_argument(out, "out")
    frames = checked_frames(frames, config.frames)
    if mode not in ("new", "resume", "overwrite"):
        raise InputError(f"mode: {mode!r} is not one of new, resume, overwrite")
    if not callable(log):
        raise InputError(f"log: expected a function of one str (print, or lambda text: None to print nothing), got {type(log).__name__}")

    check_limits(estimate_run(config, config.frames if frames is None else len(frames) if hasattr(frames, "__len__") else None), config)  # before any work
    try:
        import bpy
    except ImportError:
        raise InputError("bpy: bpy_pipeline.run needs Blender's Python module (pip install 'bpy==4.5.*'); bpy_pipeline.scan needs none") from None
    from .plan import run as run_pipeline

    bpy.ops.wm.read_factory_settings(use_empty=True)
    return run_pipeline(config, out, log=log, frames=frames, mode=mode)


def checked_frames(frames, count: int):
    """``frames`` (frame indices, default all) when each is an int in ``0 .. count - 1``; else :class:`InputError`."""
    if frames is None:
        return None
    if isinstance(frames, range):
        if len(frames) and not (0 <= min(frames[0], frames[-1]) and max(frames[0], frames[-1]) < count):
            raise InputError(f"frames: {frames} reaches past the run's frames 0..{count - 1}")
        return frames
    if isinstance(frames, (str, bytes, Mapping)) or not isinstance(frames, Iterable):
        raise InputError(f"frames: expected frame indices (a list or range of ints), got {type(frames).__name__}")
    frames = list(frames)
    bad = [f for f in frames if isinstance(f, bool) or not isinstance(f, (int, np.integer)) or not 0 <= f < count]
    if bad:
        raise InputError(f"frames: {bad[0]!r} is not a frame index of this run (ints 0..{count - 1}); nothing was made")
    return frames


def scene_buffers(meshes: SceneBuffers | Mapping) -> SceneBuffers:
    """Scene buffers of ``meshes``: buffers as they are, or ``{name: (vertices (n, 3) m, triangles (m, 3))}``
    with an optional class name, material and reflectivity after the triangles
    (``(v, t, "car", "diffuse", 0.3)``); objects are ``unlabeled``, ``diffuse``, 0.5 by default. The material is a tracing
    one (diffuse, mirror, glass, absorber) or a reflectance model of lidar/effects/materials.py (``glossy_paint``,
    ``retroreflector``, ``dark_paint``, ``wet``: traced as diffuse, applied with ``effects.materials.objects: true``)."""
    from .geometry.checks import check_fraction, check_mesh

    if isinstance(meshes, SceneBuffers):
        check_mesh(meshes.vertices, meshes.triangles, "meshes (scene buffers)")
        for k, value in enumerate(np.asarray(meshes.objects.reflectivity).tolist()):
            check_fraction(value, f"meshes (scene buffers) object {meshes.objects.names[k]!r} reflectivity")
        return meshes
    if not isinstance(meshes, Mapping):
        raise InputError(
            f"meshes: expected scene buffers or a mapping {{name: (vertices (n, 3), triangles (m, 3)[, class, material, reflectivity])}}, got "
            f"{type(meshes).__name__}"
        )
    from .labels import load_class_table
    from .lidar.effects.materials import part_material

    table = load_class_table()
    checked = {}
    for name, mesh in meshes.items():
        if not isinstance(mesh, (tuple, list)) or not 2 <= len(mesh) <= 5:
            raise InputError(f"meshes[{name!r}]: expected (vertices (n, 3), triangles (m, 3)[, class, material, reflectivity]), got {type(mesh).__name__}")
        checked[name] = check_mesh(mesh[0], mesh[1], f"meshes[{name!r}]")
    buffers = SceneBuffers.from_meshes(checked)
    classes, materials, reflectivity, surface = [], [], [], []
    for name, mesh in meshes.items():
        extra = list(mesh[2:]) + [None] * 3
        classes.append(table.names[table.id_of(extra[0] or "unlabeled", f"meshes[{name!r}] class")])
        traced, model = part_material(extra[1] or "diffuse", f"meshes[{name!r}] material")  # a tracing material or a reflectance model
        materials.append(traced)
        surface.append(model)
        reflectivity.append(0.5 if extra[2] is None else check_fraction(extra[2], f"meshes[{name!r}] reflectivity"))
    objects = buffers.objects
    buffers.objects = ObjectTable(objects.names, objects.parents, classes, np.array([table.id_of(c) for c in classes], np.uint16), objects.instance,
                                  np.array(materials, np.uint8), np.array(reflectivity, np.float32),
                                  np.array(surface, np.uint8) if any(surface) else None)
    return buffers


def scan(meshes: SceneBuffers | Mapping, sensor: str | Mapping = "vlp16", pose: np.ndarray | None = None, effects: Mapping | None = None, seed: int = 0,
         frame: int = 0) -> np.ndarray:
    """Scan meshes with a sensor without touching Blender: ``(p,)`` POINT_DTYPE records in the sensor frame.

    meshes : scene buffers, or ``{name: (vertices (n, 3), triangles (m, 3)[, class, material, reflectivity])}`` in world metres
    sensor : a preset name (``python -m bpy_pipeline sensors``) or a mapping as the config's ``sensor`` section
    pose : (4, 4) sensor-to-world transform (default: identity); the preset's mount height is not added
    effects : a mapping as the config's ``effects`` section (``None``: the config's defaults, as run.py uses)
    seed, frame : the frame's generator is the one frame ``frame`` of a run seeded ``seed`` gets
    """
    from .frame import Frame, Run, frame_rng
    from .geometry.checks import check_pose
    from .stages.scan import effects_stage, scan_stage

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed: expected an integer >= 0, got {seed!r}")
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or frame < 0:
        raise InputError(f"frame: expected an integer >= 0, got {frame!r}")
    if not isinstance(sensor, (str, Mapping)):
        raise InputError(f"sensor: expected a preset name or a mapping as the config's sensor section, got {type(sensor).__name__}")
    if effects is not None and not isinstance(effects, Mapping):
        raise InputError(f"effects: expected a mapping as the config's effects section, got {type(effects).__name__}")
    pose = np.eye(4) if pose is None else check_pose(pose, "pose")
    section = {"preset": sensor} if isinstance(sensor, str) else dict(sensor)
    config = config_from_dict({"seed": seed, "sensor": section, **({} if effects is None else {"effects": dict(effects)}), "output": {"formats": ["ply"]}})
    out = Frame(frame, config, frame_rng(seed, frame), buffers=scene_buffers(meshes))
    out.place(pose)
    run = Run(config, build=False)
    scan_stage(out, run)
    effects_stage(out, run)
    return out.points
