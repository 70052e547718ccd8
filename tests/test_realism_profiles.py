"""Realistic by default: each sensor preset's effects profile (lidar/sensor/sensors.yaml), ``effects.ideal``,
intensities in the real sensor's units, and reflectivity read from Blender materials."""

import numpy as np
import pytest

import bpy_pipeline
from bpy_pipeline.config import config_from_dict, config_to_dict, load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.sensor.sensors import preset_effects, preset_sources, presets

# a 12 m box room, 6 m high, around the sensor: every preset's rays meet a wall within the flash cameras' 10 m
V = np.array([[x, y, z] for x in (-6, 6) for y in (-6, 6) for z in (-1.5, 4.5)], float)
T = np.array([[0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5]])
ROOM = {"room": (V, T, "wall", "diffuse", 0.3)}

# fields that keep every preset's frame small (the railway scanner fires 23 M rays at its own resolution)
SMALL = {"railway_tls": {"sampling_factor": 0.05}, "os1_128": {"columns": 512}, "os1_64": {"columns": 512}}


def sensor(name: str) -> dict:
    return {"preset": name, **SMALL.get(name, {})}


@pytest.mark.parametrize("name", list(presets()))
def test_every_preset_carries_a_profile_with_its_sources(name):
    profile = preset_effects(name)
    assert profile and set(profile) <= {"noise", "drop", "intensity"} and "drop" in profile and "intensity" in profile
    sources = preset_sources(name)
    for section in profile:  # every section is covered by a source naming it or one of its keys
        assert any(key == section or key.startswith(section + ".") for key in sources), (name, section, sources)
    assert all(isinstance(text, str) and len(text) > 20 for text in sources.values())
    config = load_config({"scene": {"builder": "primitives"}, "sensor": sensor(name)})
    assert not config.effects.ideal and config.effects.drop.model == profile["drop"]["model"]
    assert config_from_dict(config_to_dict(config)) == config  # merging the profile again changes nothing


@pytest.mark.parametrize("name", list(presets()))
def test_default_effects_are_seeded_and_reproducible(name):
    first = bpy_pipeline.scan(ROOM, sensor(name), seed=4)
    again = bpy_pipeline.scan(ROOM, sensor(name), seed=4)
    other = bpy_pipeline.scan(ROOM, sensor(name), seed=5)
    ideal = bpy_pipeline.scan(ROOM, sensor(name), effects={"ideal": True}, seed=4)
    assert len(first) > 0 and first.tobytes() == again.tobytes()
    assert first.tobytes() != ideal.tobytes() and len(first) <= len(ideal)
    profile = preset_effects(name)
    draws = profile.get("noise", {}).get("sigma", 0) > 0 or profile["drop"].get("model", "none") != "none"
    if draws:
        assert first.tobytes() != other.tobytes()
    else:  # a profile that draws nothing (flash96x16, the thesis's depth camera: exact ranges, intensity 0)
        assert first.tobytes() == other.tobytes() and len(first) == len(ideal) and (first["intensity"] == 0).all()


@pytest.mark.parametrize("name", ["vlp16", "hdl64e", "livox_mid40"])
def test_ideal_is_the_exact_scan(name):
    """``ideal: true`` leaves the profile out: the trace as it is, with today's reflectance intensity."""
    ideal = bpy_pipeline.scan(ROOM, sensor(name), effects={"ideal": True}, seed=4)
    exact = bpy_pipeline.scan(ROOM, sensor(name), effects={"ideal": True, "noise": {"sigma": 0.0}, "drop": {"model": "none"}}, seed=9)
    assert ideal.tobytes() == exact.tobytes()
    assert np.allclose(np.abs(ideal["x"]).max(), 6.0, atol=1e-4)  # the walls are where they are
    walls = np.maximum(np.abs(ideal["x"]), np.abs(ideal["y"]))
    side = (np.abs(ideal["z"]) < 1.4) & (walls > 5.999)
    assert side.sum() > 0 and np.allclose(walls[side], 6.0, atol=1e-4)
    assert np.all(ideal["intensity"] <= 0.3 + 1e-6)  # rho cos, no scale, no steps


def test_the_config_refines_the_profile_and_another_model_replaces_it():
    base = {"scene": {"builder": "primitives"}, "sensor": {"preset": "hdl32e"}}
    merged = load_config({**base, "effects": {"noise": {"sigma": 0.01}, "drop": {"threshold": {"softness": 1.0}}}}).effects
    assert merged.noise.model == "range" and merged.noise.sigma == 0.01 and merged.noise.sigma_per_metre == pytest.approx(0.00061)
    assert merged.drop.model == "threshold" and merged.drop.threshold.softness == 1.0 and merged.drop.threshold.range_at_10 == 446.5
    replaced = load_config({**base, "effects": {"drop": {"model": "uniform", "probability": 0.1}}}).effects
    assert replaced.drop.model == "uniform" and replaced.drop.threshold.range_at_10 == 40.0 and replaced.intensity.steps == 255
    ideal = load_config({**base, "effects": {"ideal": True}}).effects
    assert ideal.drop.model == "none" and ideal.noise.sigma == 0.0 and ideal.intensity.scale == 1.0 and ideal.intensity.steps == 0
    with pytest.raises(InputError, match="effects.intensity.steps"):
        load_config({**base, "effects": {"intensity": {"steps": -1}}})
    with pytest.raises(InputError, match="effects.drop.threshold.floor"):
        load_config({**base, "effects": {"drop": {"threshold": {"floor": 1.5}}}})


def test_intensity_in_the_real_sensors_units(real_scan):
    """HDL-32E as nuScenes writes it (integers 0..255 over 255), HDL-64E as KITTI (0..1 in 0.01 steps)."""
    nuscenes = np.fromfile(real_scan("nuscenes_hdl32e_sweep.bin"), np.float32).reshape(-1, 5)[:, 3]
    kitti = np.fromfile(real_scan("kitti_hdl64e_000008_frontfov.bin"), np.float32).reshape(-1, 4)[:, 3]
    assert np.all(nuscenes == np.rint(nuscenes)) and nuscenes.min() >= 0 and nuscenes.max() <= 255
    assert np.allclose(kitti * 100, np.rint(kitti * 100), atol=1e-4) and kitti.min() >= 0 and kitti.max() <= 1
    hdl32e = bpy_pipeline.scan(ROOM, "hdl32e", seed=1)["intensity"]
    as_byte = hdl32e.astype(np.float64) * 255
    assert hdl32e.dtype == np.float32 and np.allclose(as_byte, np.rint(as_byte), atol=1e-3) and 0 <= as_byte.min() and as_byte.max() <= 255
    assert as_byte.max() <= 30.0 + 1e-3  # a 30 % diffuse wall reads at most 30 of Velodyne's 0..100 diffuse scale
    hdl64e = bpy_pipeline.scan(ROOM, "hdl64e", seed=1)["intensity"].astype(np.float64)
    assert np.allclose(hdl64e * 100, np.rint(hdl64e * 100), atol=1e-3) and 0 <= hdl64e.min() and hdl64e.max() <= 1
    for name in presets():
        values = bpy_pipeline.scan(ROOM, sensor(name), seed=1)["intensity"]
        assert values.dtype == np.float32 and values.min() >= 0 and values.max() <= 1, name


@pytest.mark.bpy
def test_reflectivity_from_the_material_base_colour(bpy_scene):
    """No ``lidar_reflectivity``: the albedo of the base colour; the property stays the override."""
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table

    bpy = bpy_scene
    names = []
    for name, colour, prop in (("grey", (0.2, 0.2, 0.2), None), ("red", (0.9, 0.0, 0.0), None), ("tagged", (0.9, 0.9, 0.9), 0.05), ("bare", None, None)):
        bpy.ops.mesh.primitive_cube_add(location=(len(names) * 3.0, 0, 0))
        obj = bpy.context.active_object
        obj.name = name
        obj["lidar_class"] = "wall"
        if colour is not None:
            material = bpy.data.materials.new(name)
            if hasattr(material, "use_nodes"):
                material.use_nodes = True
            principled = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
            principled.inputs["Base Color"].default_value = (*colour, 1.0)
            obj.data.materials.append(material)
        if prop is not None:
            obj["lidar_reflectivity"] = prop
        names.append(name)
    buffers = export_scene(load_class_table())
    got = dict(zip(buffers.objects.names, buffers.objects.reflectivity))
    assert got["grey"] == pytest.approx(0.2) and got["red"] == pytest.approx(0.3) and got["tagged"] == pytest.approx(0.05) and got["bare"] == pytest.approx(0.5)


def test_incidence_exponent_sets_how_intensity_and_drop_follow_incidence():
    """``incidence_exponent`` 0: a wall reads its reflectivity at any incidence (as real roads do); 1: rho cos."""
    lambert = bpy_pipeline.scan(ROOM, "vlp16", effects={"ideal": True}, seed=2)
    flat = bpy_pipeline.scan(ROOM, "vlp16", effects={"ideal": True, "intensity": {"incidence_exponent": 0.0}}, seed=2)
    assert len(lambert) == len(flat) and np.allclose(flat["intensity"], 0.3)
    cos = lambert["intensity"] / np.float32(0.3)
    assert cos.min() < 0.5 and np.all(cos <= 1 + 1e-6)  # grazing returns read less under Lambert's law
    from bpy_pipeline.lidar.effects.drop.threshold import probability

    effects = load_config({"scene": {"builder": "primitives"}, "sensor": {"preset": "vlp16"},
                           "effects": {"ideal": True, "drop": {"model": "threshold"}}}).effects
    from bpy_pipeline.lidar.points import BEAM_DTYPE, empty_points

    points, beam = empty_points(2), np.zeros(2, BEAM_DTYPE)
    points["range"] = 30.0
    beam["reflectivity"], beam["cos_incidence"], beam["gain"] = 0.2, (1.0, 0.1), 1.0
    steep, grazing = probability(points, beam, effects, None)
    assert grazing > steep  # Lambertian: a grazing return is weaker and lost more often
    from dataclasses import replace

    flat_effects = replace(effects, intensity=replace(effects.intensity, incidence_exponent=0.0))
    assert np.allclose(*probability(points, beam, flat_effects, None))


@pytest.mark.slow
def test_realism_benchmark_runs_small_and_its_figures_hold(tmp_path, real_scan):
    """benchmarks/bench_realism.py --small (as CI runs it): the replay covers the real sweep, the
    preset's drop model loses what the real sensor loses, and every KITTI car is counted."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    for name in ("nuscenes_hdl32e_sweep.bin", "kitti_hdl64e_000008_frontfov.bin", "kitti_000008_boxes.json"):
        real_scan(name)
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, str(root / "benchmarks" / "bench_realism.py"), "--small", "--out", str(tmp_path)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    result = json.loads((tmp_path / "realism_small.json").read_text())
    assert (tmp_path / "realism_small.png").stat().st_size > 10_000
    rows = {(r["case"], r["quantity"]): r for r in result["rows"]}
    returns = rows[("hdl32e replay", "returns (all rings)")]
    assert 0.85 < returns["ideal"] / returns["real"] <= 1.0 and returns["sim"] < returns["ideal"]
    drop = rows[("hdl32e sweep", "drop fraction (all firings with a target)")]
    assert abs(drop["sim"] - drop["real"]) < 0.01
    cars = result["notes"]["kitti"]["cars"]
    assert len(cars) == 6 and all(c["default"]["points"] > 0 and c["default"]["points"] <= c["ideal"]["points"] for c in cars)
    assert all(abs(c["real_in_box"] - c["real_label"]) <= 0.08 * c["real_label"] + 2 for c in cars)  # the boxes sit where the labels say
