"""Reflectance models per object (``effects.materials.objects``): chosen from a Blender material's roughness,
metallic and ``lidar_material`` at export, looked up per point by (instance, reflectivity); an object's model wins
over its class's; clashing parts are one line; off by default."""

import numpy as np
import pytest

from bpy_pipeline.buffers import ObjectTable
from bpy_pipeline.config import effects_from_dict
from bpy_pipeline.errors import InputError
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.effects.apply import apply_effects
from bpy_pipeline.lidar.effects.materials import GLOSSY_ROUGHNESS, model_from_material, model_id, object_models
from test_materials import returns

TABLE = load_class_table()


def objects(instance, reflectivity, surface):
    k = len(instance)
    return ObjectTable([f"o{i}" for i in range(k)], [""] * k, ["car"] * k, np.full(k, TABLE.id_of("car"), np.uint16), np.asarray(instance, np.uint32),
                       np.zeros(k, np.uint8), np.asarray(reflectivity, np.float32), np.asarray([model_id(s) for s in surface], np.uint8))


def effects(**materials):
    """The HDL-64E's datasheet floor (hard), intensity rho cos^0 as its profile reads it, no noise."""
    return effects_from_dict({"drop": {"model": "threshold", "threshold": {"range_at_10": 50.0, "range_at_80": 120.0, "softness": 0.0}},
                              "intensity": {"incidence_exponent": 0.0}, "materials": materials})


def test_blender_properties_select_the_model():
    assert model_from_material(None, 0.1, 1.0, "o") == model_from_material(None, GLOSSY_ROUGHNESS, 0.0, "o") == "glossy_paint"
    assert model_from_material(None, 0.5, 0.0, "o") == model_from_material(None, None, None, "o") == ""  # Blender's default roughness: diffuse
    assert model_from_material("retroreflector", 0.9, 0.0, "o") == "retroreflector"  # the custom property wins
    assert model_from_material("glass", 0.0, 0.0, "o") == ""  # a tracing material, not a reflectance model
    with pytest.raises(InputError, match="^object 'x': material 'm': roughness and metallic must lie in 0..1"):
        model_from_material(None, 1.5, 0.0, "object 'x': material 'm'")


def test_a_glossy_object_loses_oblique_returns_its_matte_part_of_the_same_car_does_not():
    angles = [0, 5, 45, 60]
    body, body_beam = returns(30.0, angles, "car", reflectivity=0.5)
    trim, trim_beam = returns(30.0, angles, "car", reflectivity=0.6)
    body["instance"] = trim["instance"] = 7
    points, beam = np.concatenate([body, trim]), np.concatenate([body_beam, trim_beam])
    table = objects([7, 7], [0.5, 0.6], ["glossy_paint", ""])
    assert np.array_equal(object_models(points, beam, table), np.r_[np.full(len(body), model_id("glossy_paint")), np.zeros(len(trim))])
    off = apply_effects(points, beam, effects(), np.random.default_rng(0), objects=table)
    on = apply_effects(points, beam, effects(objects=True), np.random.default_rng(0), objects=table)
    assert len(off) == len(points)  # opt-in: the table alone changes nothing
    glossy_kept = {a: int((on["time"] == a).sum()) - 200 for a in angles}  # minus the trim's 200, all kept
    assert glossy_kept[0] == glossy_kept[5] == 200 and glossy_kept[45] == glossy_kept[60] == 0, glossy_kept
    # an object's model wins over its class's: the class says retroreflector, the trim has none, the body glossy
    both = apply_effects(points, beam, effects(objects=True, classes={"car": "retroreflector"}), np.random.default_rng(0), objects=table)
    # the trim, as a retroreflector, saturates; the body stays glossy
    assert len(both[both["time"] == 45]) == 200 and (both["intensity"][both["time"] == 45] == 1.0).all()


def test_parts_that_cannot_be_told_apart_are_one_line():
    points, beam = returns(30.0, [0], "car", reflectivity=0.5)
    points["instance"] = 3
    with pytest.raises(InputError, match=r"^object 'o1': shares instance 3 and lidar_reflectivity 0.5 with 'o0' but has another reflectance model"):
        apply_effects(points, beam, effects(objects=True), np.random.default_rng(0), objects=objects([3, 3], [0.5, 0.5], ["", "glossy_paint"]))


def test_export_reads_roughness_metallic_and_lidar_material():
    bpy = pytest.importorskip("bpy")
    from bpy_pipeline.blender.export import export_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    made = {}
    for name, setup in (("paint", {"Roughness": 0.1, "Metallic": 0.8}), ("matte", {"Roughness": 0.7}),
                        ("plate", {"Roughness": 0.7, "lidar_material": "retroreflector"}), ("bare", None)):
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
        obj = bpy.data.objects.new(name, mesh)
        bpy.context.scene.collection.objects.link(obj)
        if setup is not None:
            material = bpy.data.materials.new(name)
            material.use_nodes = True
            bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
            for key, value in setup.items():
                if key == "lidar_material":
                    material[key] = value
                else:
                    bsdf.inputs[key].default_value = value
            mesh.materials.append(material)
        made[name] = obj
    made["bare"]["lidar_material"] = "dark_paint"
    buffers = export_scene(load_class_table())
    got = dict(zip(buffers.objects.names, buffers.objects.surface))
    assert got == {"paint": model_id("glossy_paint"), "matte": 0, "plate": model_id("retroreflector"), "bare": model_id("dark_paint")}
    assert set(buffers.objects.material) == {0}  # all diffuse surfaces for the tracer


def test_a_cars_plate_is_seen_far_beyond_its_glossy_body():
    from bpy_pipeline.buffers import SceneBuffers
    from bpy_pipeline.config import config_from_dict
    from bpy_pipeline.geometry.objects import FITTINGS, STYLES, car_fittings, car_parts
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.scan import scan_buffers

    parts = {**{k: car_parts(STYLES[0])[k] for k in ("body",)}, **car_fittings(STYLES[0])}
    models = {"body": ("glossy_paint", 0.5), **FITTINGS}
    turn = np.diag([-1.0, -1.0, 1.0])  # nose towards the sensor
    scene = SceneBuffers.from_meshes({name: (v @ turn.T + [150.0, 0.0, -1.0], t) for name, (v, t) in parts.items()})
    names = list(parts)
    scene.objects.instance[:] = 1
    scene.objects.reflectivity[:] = [models[n][1] for n in names]
    scene.objects.semantic[:] = TABLE.id_of("car")
    scene.objects.surface = np.array([model_id(models[n][0]) for n in names], np.uint8)
    sensor = {"preset": "custom", "pattern": "spinning", "channels": 40, "vertical_fov_deg": [-1.0, 0.3], "horizontal_fov_deg": [-1.5, 1.5],
              "horizontal_resolution_deg": 0.01, "min_range": 1.0, "max_range": 200.0}
    drop = {"model": "threshold", "threshold": {"range_at_10": 50.0, "range_at_80": 120.0, "softness": 0.0}}
    seen = {}
    for on in (False, True):
        config = config_from_dict({"sensor": sensor, "effects": {"drop": drop, "intensity": {"incidence_exponent": 0.0}, "materials": {"objects": on}}})
        points, _ = scan_buffers(scene, config, frame_rng(0, 0))
        seen[on] = points
    assert len(seen[False]) == 0  # 150 m: beyond the diffuse range of a 0.5-0.8 target at this sensitivity
    assert len(seen[True]) > 0 and (seen[True]["intensity"] == 1.0).all()  # the plate alone: retroreflective, saturating
    assert np.abs(seen[True]["z"] - (-1.0 + 0.25 * 1.625 + 0.055)).max() < 0.15  # at the plate's height
