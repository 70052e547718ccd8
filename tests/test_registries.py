"""Extension points: a builder or a writer registered from a test module is usable from a config, touching no other file."""

from dataclasses import dataclass

import numpy as np
import pytest

from bpy_pipeline.builders import BUILDERS, Builder, BuildResult, register_builder
from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.io import WRITERS, Writer, register_writer
from bpy_pipeline.registry import Registry


@dataclass(frozen=True)
class PillarScene:
    """A toy builder's parameters: one pillar ``height`` m high at ``x`` m."""

    height: float = 3.0
    x: float = 6.0


def check_pillar(params: PillarScene, where: str) -> None:
    if params.height <= 0:
        raise InputError(f"{where}.height: must be > 0, got {params.height}")


def build_pillar(params: PillarScene, context) -> BuildResult:
    import bpy  # noqa: F401  (a builder's Blender side)

    from bpy_pipeline.geometry import primitives
    from bpy_pipeline.blender.mesh_objects import mesh_object, scene_collection, tag

    collection = scene_collection()
    tag(mesh_object("pillar", primitives.box(0.5, 0.5, params.height), collection, (params.x, 0.0, params.height / 2), (0.0, 0.0, 0.0)), "pillar")
    tag(mesh_object("floor", primitives.plane(40.0, 40.0), collection, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), "ground")
    return BuildResult(info={"pillar_x": params.x})


def write_xyz(frame, out):
    """A toy format: x y z per line."""
    path = out / "xyz" / f"{frame.stem}.xyz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, np.column_stack([frame.points["x"], frame.points["y"], frame.points["z"]]), fmt="%.4f")
    return [path]


@pytest.fixture
def toys():
    register_builder("pillar", Builder(PillarScene, build_pillar, check_pillar, sensor={"preset": "vlp16"}))
    register_writer("xyz", Writer(write_xyz))
    yield
    BUILDERS.unregister("pillar")
    WRITERS.unregister("xyz")


def test_registry_refuses_twice_and_names_the_allowed():
    registry = Registry("thing", "things.kind")
    registry.register("a", 1)
    with pytest.raises(ValueError):
        registry.register("a", 2)
    with pytest.raises(InputError, match=r"^things.kind: unknown thing 'b'; allowed: a$"):
        registry.get("b")


def test_toy_builder_and_writer_validate_from_a_config(toys):
    config = load_config({"scene": {"builder": "pillar", "height": 2.5}, "output": {"formats": ["xyz"]}})
    assert config.scene.params == PillarScene(2.5, 6.0) and config.sensor.spec.name == "vlp16"
    with pytest.raises(InputError, match=r"^scene.height: must be > 0"):
        load_config({"scene": {"builder": "pillar", "height": -1}})
    with pytest.raises(InputError, match=r"^scene.width: unknown key"):
        load_config({"scene": {"builder": "pillar", "width": 1}})
    with pytest.raises(InputError, match="allowed: .*xyz"):
        load_config({"output": {"formats": ["xyzw"]}})


@pytest.mark.bpy
def test_toy_builder_and_writer_run(toys, bpy_scene, tmp_path):
    from bpy_pipeline.plan import run

    config = load_config({"scene": {"builder": "pillar", "x": 5.0}, "sensor": {"preset": "vlp16", "position": [0, 0, 1]}, "effects": {"ideal": True},
                          "output": {"formats": ["xyz", "ply"], "preview": False}})
    manifest = run(config, tmp_path, log=lambda *_: None)
    xyz = np.loadtxt(tmp_path / "xyz" / "000000.xyz")
    assert manifest["frames"][0]["scene"] == {"pillar_x": 5.0}
    assert manifest["frames"][0]["files"] == ["xyz/000000.xyz", "ply/000000.ply"]
    front = xyz[(np.abs(xyz[:, 1]) < 0.2) & (xyz[:, 2] > 0)]
    assert len(front) and np.allclose(front[:, 0].min(), 4.75, atol=0.02)  # the pillar's near face


# ----------------------------------------------------------------------------- a toy ray pattern
def halo_rays(spec):
    """``columns`` rays in a horizontal ring, ring 0, all at t = 0."""
    from bpy_pipeline.lidar.sensor.rays import Pattern

    def chunk(start, stop, frame):
        azimuth = 2 * np.pi * np.arange(start, stop) / spec.columns
        return Pattern(np.column_stack([np.cos(azimuth), np.sin(azimuth), np.zeros(stop - start)]), np.zeros(stop - start, np.uint16), np.zeros(stop - start))

    return chunk


def check_halo(spec, where):
    if spec.columns < 3:
        raise InputError(f"{where}.columns: a halo needs >= 3 rays, got {spec.columns}")


@pytest.fixture
def halo():
    from bpy_pipeline.lidar.sensor.patterns import PATTERNS, RayPattern, register_pattern

    register_pattern("halo", RayPattern(halo_rays, lambda spec: spec.columns, lambda spec: (360.0 / spec.columns, None), check_halo, lambda spec: "columns"))
    yield
    PATTERNS.unregister("halo")


def test_toy_pattern_fires_from_a_config(halo):
    import bpy_pipeline
    from bpy_pipeline.geometry import primitives

    config = load_config({"sensor": {"preset": "custom", "pattern": "halo", "columns": 360, "max_range": 50}})
    assert config.sensor.spec.pattern == "halo"
    with pytest.raises(InputError, match=r"^sensor.columns: a halo needs >= 3 rays"):
        load_config({"sensor": {"preset": "custom", "pattern": "halo", "columns": 2}})
    with pytest.raises(InputError, match=r"^sensor.pattern: unknown ray pattern 'hallo'; allowed: .*halo"):
        load_config({"sensor": {"preset": "custom", "pattern": "hallo"}})
    v, t = primitives.box(20.0, 20.0, 4.0)
    points = bpy_pipeline.scan({"room": (v, t, "wall")}, {"preset": "custom", "pattern": "halo", "columns": 360, "max_range": 50})
    assert len(points) == 360 and np.allclose(np.abs(points["z"]), 0.0, atol=1e-6)
    assert np.allclose(np.maximum(np.abs(points["x"]), np.abs(points["y"])), 10.0, atol=1e-4)  # the walls of the 20 m room


# ----------------------------------------------------------------------------- a toy drop model
@dataclass(frozen=True)
class RingDrop:
    """The toy drop model's parameters: rings at or above ``from_ring`` are lost with ``probability``."""

    from_ring: int = 8
    probability: float = 1.0


def ring_drop(points, beam, effects, models):
    params = RingDrop(**effects.drop.params)
    return np.where(points["ring"] >= params.from_ring, np.float32(params.probability), np.float32(0.0))


@pytest.fixture
def ring_model():
    from bpy_pipeline.lidar.effects.drop import DROP_MODELS, DropModel, register_drop_model

    register_drop_model("upper_rings", DropModel(ring_drop, params=RingDrop))
    yield
    DROP_MODELS.unregister("upper_rings")


def test_toy_drop_model_drops_from_a_config(ring_model):
    import bpy_pipeline
    from bpy_pipeline.geometry import primitives

    v, t = primitives.box(40.0, 40.0, 30.0)
    room = {"room": (v, t, "wall")}
    kept = bpy_pipeline.scan(room, "vlp16", effects={"drop": {"model": "upper_rings", "params": {"from_ring": 4}}})
    everything = bpy_pipeline.scan(room, "vlp16")
    assert set(np.unique(everything["ring"])) == set(range(16)) and set(np.unique(kept["ring"])) == set(range(4))
    with pytest.raises(InputError, match=r"^effects.drop.params.from_rings: unknown key"):
        load_config({"effects": {"drop": {"model": "upper_rings", "params": {"from_rings": 4}}}})
    with pytest.raises(InputError, match=r"^effects.drop.params: the uniform drop model takes no params"):
        load_config({"effects": {"drop": {"model": "uniform", "params": {"from_ring": 4}}}})
