"""Licence plates and lamps on every builder's vehicles: where they sit, how they are tagged, what a scan reads from them."""

import dataclasses

import numpy as np
import pytest

from bpy_pipeline.geometry.placement import Distribution
from bpy_pipeline.builders.street import layout as street
from bpy_pipeline.builders.street.params import StreetScene
from bpy_pipeline.geometry.objects import FITTINGS
from bpy_pipeline.geometry.vehicles import vehicle_fittings, vehicle_parts

SIZES = {"car": (4.5, 1.8, 1.5), "van": (5.2, 2.0, 2.3), "truck": (8.0, 2.5, 3.4), "bus": (12.0, 2.55, 3.1)}


def _boxes(mesh):
    """The axis-aligned boxes a fittings mesh is made of (8 vertices each): ``(k, 2, 3)`` low and high corners."""
    corners = mesh[0].reshape(-1, 8, 3)
    return np.stack([corners.min(axis=1), corners.max(axis=1)], axis=1)


def test_boxes_made_at_once_are_the_boxes_made_one_by_one():
    from bpy_pipeline.geometry import primitives

    rng = np.random.default_rng(0)
    low = rng.normal(size=(5, 3))
    high = low + rng.random((5, 3))
    at_once = primitives.boxes_mesh(low, high)
    one_by_one = primitives.merge([primitives.box_mesh(a[0], b[0], a[1], b[1], a[2], b[2]) for a, b in zip(low, high)])
    assert np.array_equal(at_once[0], one_by_one[0]) and np.array_equal(at_once[1], one_by_one[1]) and at_once[1].dtype == np.int32


@pytest.mark.parametrize("kind", sorted(SIZES))
def test_each_vehicle_has_a_plate_at_each_end_and_a_lamp_in_each_corner(kind):
    L, W, H = SIZES[kind]
    body = vehicle_parts(kind, SIZES[kind])["body"][0]
    fittings = vehicle_fittings(body, L)
    plates, lamps = _boxes(fittings["plates"]), _boxes(fittings["lights"])
    assert len(plates) == 2 and len(lamps) == 4
    for low, high in plates:
        end = 1.0 if high[0] > 0 else -1.0
        face = high[0] if end > 0 else low[0]
        assert face == pytest.approx(end * (L / 2 + 0.005))  # 5 mm proud of the end face
        assert high[1] - low[1] == pytest.approx(0.52) and high[2] - low[2] == pytest.approx(0.11)
        assert (low[1] + high[1]) / 2 == pytest.approx(0.0)
        # on the body: the body reaches the end face over the plate's whole height
        at_end = body[np.abs(body[:, 0] - end * L / 2) < 1e-9]
        assert at_end[:, 2].min() <= low[2] and high[2] <= at_end[:, 2].max()
    for low, high in lamps:
        assert abs(low[1]) < W / 2 and abs(high[1]) < W / 2 and 0.0 < low[2] < high[2] < H
        assert abs(high[0] if high[0] > 0 else low[0]) == pytest.approx(L / 2 + 0.01)
    assert sorted(np.sign((lamps[:, 0, 0] + lamps[:, 1, 0]) * (lamps[:, 0, 1] + lamps[:, 1, 1])).tolist()) == [-1, -1, 1, 1]


def _placed(seed=0):
    """A busy street's road users (12 driving and 8 parked vehicles wanted), placed from ``seed``."""
    params = dataclasses.replace(StreetScene(), vehicles=Distribution("normal", 12.0, 0.0, 0.0, 40.0), parked=Distribution("normal", 8.0, 0.0, 0.0, 40.0))
    scene_layout = street.street_layout(params, np.random.default_rng(params.layout_seed))
    return params, scene_layout, street.place_users(params, scene_layout, np.random.default_rng(seed))


def test_a_street_vehicle_tags_its_fittings_and_draws_nothing_for_them():
    params, layout, placement = _placed()
    vehicles = [u for u in placement.users if u.kind in street.VEHICLES]
    assert {u.kind for u in vehicles} >= {"car", "van"}
    for user in vehicles:
        with_rng, without_rng = np.random.default_rng(5), np.random.default_rng(5)
        parts = {name: (material, reflectivity, mesh) for name, _, material, reflectivity, mesh in street.user_meshes(user, with_rng)}
        bare = {name: (material, reflectivity, mesh) for name, _, material, reflectivity, mesh in street.user_meshes(user, without_rng, fittings=False)}
        assert with_rng.random() == without_rng.random()  # the same draws: the other users are the same either way
        assert set(parts) - set(bare) == {"plates", "lights"}
        for name in bare:
            assert parts[name][:2] == bare[name][:2] and np.array_equal(parts[name][2][0], bare[name][2][0])
        for name in ("plates", "lights"):
            assert parts[name][:2] == FITTINGS[name]


BUILDERS = {  # config overrides whose scene has procedural cars, and the classes those cars take
    "parking": (["scene.builder=parking", "scene.cars={kind: normal, mean: 4, std: 0, min: 0, max: 40}"], {"car"}),
    "street": (["scene.builder=street", "scene.vehicles={kind: normal, mean: 8, std: 0, min: 0, max: 40}",
                "scene.parked={kind: normal, mean: 6, std: 0, min: 0, max: 40}"],
               set(street.VEHICLES)),
    "population": (["scene.builder=parking", "scene.cars={kind: normal, mean: 0, std: 0, min: 0, max: 0}", "scene.population={car: {count: 3}}"], {"car"}),
}
OFF = {"parking": "scene.car_fittings=false", "street": "scene.car_fittings=false", "population": "scene.population={car: {count: 3, fittings: false}}"}


@pytest.mark.bpy
@pytest.mark.parametrize("builder", sorted(BUILDERS))
def test_every_builders_cars_carry_plates_and_lamps_inside_their_boxes(bpy_scene, builder):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.geometry.boxes import fit_boxes
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.lidar.effects.materials import model_id
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.scene import build_frame_scene

    overrides, classes = BUILDERS[builder]
    counts = {}
    for fittings in (True, False):
        config = load_config(None, overrides + ([] if fittings else [OFF[builder]]))
        result = build_frame_scene(config, 0, frame_rng(config.seed, 0))
        buffers = export_scene(load_class_table())
        objects = buffers.objects
        vehicles = sorted({int(objects.instance[r]) for r in range(len(objects)) if objects.class_names[r] in classes})
        assert len(vehicles) >= 3
        counts[fittings] = len(vehicles)
        boxes = {int(b["instance"]): b for b in fit_boxes(buffers, sorted(classes), result.headings)}
        for instance in vehicles:
            rows = np.flatnonzero(objects.instance == instance)
            plates = rows[objects.surface[rows] == model_id("retroreflector")]
            lamps = rows[objects.surface[rows] == model_id("glossy_paint")]
            if not fittings:
                assert len(plates) == len(lamps) == 0
                continue
            assert len(plates) == len(lamps) == 1
            assert objects.reflectivity[plates[0]] == np.float32(FITTINGS["plates"][1]) and objects.reflectivity[lamps[0]] == np.float32(FITTINGS["lights"][1])
            assert objects.semantic[plates[0]] == objects.semantic[rows[0]]  # the vehicle's class
            box = boxes[instance]
            yaw = float(box["heading"])
            turn = np.array([[np.cos(yaw), np.sin(yaw), 0.0], [-np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
            for row in (plates[0], lamps[0]):
                v = buffers.vertices[np.unique(buffers.triangles[buffers.triangle_object == row])]
                local = (v - box["centre"]) @ turn.T
                assert (np.abs(local) <= np.asarray(box["size"]) / 2 + 1e-4).all()
                # at the vehicle's two ends
                assert local[:, 0].min() < -0.45 * box["size"][0] and local[:, 0].max() > 0.45 * box["size"][0]
    assert counts[True] == counts[False]  # the same vehicles either way


@pytest.mark.bpy
def test_a_parking_cars_plates_read_the_retroreflectors_value_with_material_models(bpy_scene):
    """The plates' points, marked by giving the plates' rows another class before the scan: with
    ``effects.materials.objects`` they read above every body point and are lost only at grazing entrance
    (the model's 60 degrees); without, they read as the diffuse 0.8 they are tagged."""
    from bpy_pipeline.config import load_config
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.lidar.effects.materials import model_id
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.scan import scan_buffers
    from bpy_pipeline.stages.scene import build_frame_scene

    table = load_class_table()
    base = ["scene.builder=parking", "scene.cars={kind: normal, mean: 6, std: 0, min: 0, max: 40}", "sensor.preset=os1_128"]
    config = load_config(None, base)
    build_frame_scene(config, 0, frame_rng(config.seed, 0))
    buffers = export_scene(table)
    marker = table.id_of("traffic sign")
    buffers.objects.semantic[buffers.objects.surface == model_id("retroreflector")] = marker
    read = {}
    for on in (False, True):
        c = load_config(None, base + [f"effects.materials.objects={str(on).lower()}"])
        points, _ = scan_buffers(buffers, c, frame_rng(c.seed, 0))
        plate, car = points["semantic"] == marker, points["semantic"] == table.id_of("car")
        assert plate.sum() >= 20 and car.sum() > 1000
        read[on] = (points["intensity"][plate], points["intensity"][car], plate.sum())
    plates_on, cars_on, n_on = read[True]
    plates_off, cars_off, n_off = read[False]
    assert plates_on.min() > np.percentile(cars_on, 99.9) and plates_on.min() > plates_off.max()
    assert n_on < n_off  # beyond the retroreflector's entrance angle nothing returns
