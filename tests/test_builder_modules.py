"""Builder modules no other test imports: the registry entry (builders/base.py) and the railway's pure geometry
(builders/railway/terrain.py, builders/railway/trackside.py), checked against the cross-section they follow."""

import dataclasses

import numpy as np
import pytest

from bpy_pipeline.builders import base
from bpy_pipeline.builders.railway import terrain, trackside
from bpy_pipeline.builders.railway.layout import plan
from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError


@pytest.fixture(scope="module")
def railway():
    """The default railway's parameters (a straight 2-track line unless the defaults say otherwise) and its layout."""
    params = load_config(None, ["scene.builder=railway"]).scene.params
    return params, plan(params, np.random.default_rng(0))


# ----------------------------------------------------------------------------- builders/base
def test_builder_registry_refuses_a_second_entry_and_names_the_builders():
    with pytest.raises(ValueError, match="railway"):
        base.register_builder("railway", base.Builder(dict, lambda p, c: base.BuildResult()))
    with pytest.raises(InputError) as err:
        base.build_scene("castle", None, None)
    assert str(err.value).startswith("scene.builder: unknown scene builder 'castle'; allowed:") and "parking" in str(err.value)
    entry = base.BUILDERS.get("real_scan")
    assert not entry.blender_scene and base.BUILDERS.get("parking").blender_scene


def test_refuse_sensor_placement_names_the_key_unless_the_scene_lets_go():
    release = base.refuse_sensor_placement("hall")
    placed = type("P", (), {"place_sensor": True})()
    with pytest.raises(InputError, match=r"^sensor.trajectory: the hall scene places the sensor itself; set scene.place_sensor: false"):
        release(placed, {}, {"trajectory": {"speed": 1}})
    assert release(placed, {}, {}) is placed
    assert release(type("P", (), {"place_sensor": False})(), {}, {"position": [0, 0, 0]}) is not None


def test_an_indoor_scenes_sizes_are_its_fields_ranges():
    """Sizes positive, counts and gaps >= 0: each field's metadata, checked for parameters built in Python as for YAML."""
    from bpy_pipeline.builders.parking.params import ParkingScene
    from bpy_pipeline.builders.street.params import StreetScene
    from bpy_pipeline.schema import check_ranges

    check_ranges(dataclasses.replace(ParkingScene(), ramp_length=0.0, wall_openings=0), "scene")  # may be zero
    with pytest.raises(InputError, match=r"^scene\.bay_width: must lie in 0\.1\.\.100 m, got 0\.0$"):  # the level group's Bay Width input
        check_ranges(dataclasses.replace(ParkingScene(), bay_width=0.0), "scene")
    with pytest.raises(InputError, match=r"^scene\.setback\[0\]: must be >= 0 m, got -1\.0$"):
        check_ranges(dataclasses.replace(StreetScene(), setback=(-1.0, 8.0)), "scene")
    with pytest.raises(InputError, match=r"^scene\.roadworks: must lie in 0\.\.1, got 1\.5$"):
        load_config({"scene": {"builder": "street", "roadworks": 1.5}})


# ----------------------------------------------------------------------------- railway terrain
def laterals(vertices, alignment, s):
    """Each grid vertex's offset (m, + left) from the alignment; the mesh holds ``len(s)`` rows of vertices."""
    per_row = vertices.shape[0] // len(s)
    offset = vertices.reshape(len(s), per_row, 3) - alignment.point(s)[:, None, :]
    return np.einsum("nkj,nj->nk", offset[..., :2], alignment.lateral(s)[:, :2]).ravel(), np.repeat(alignment.point(s)[:, 2], per_row)


def test_flat_terrain_follows_the_cross_section_and_faces_up(railway):
    params, layout = railway
    section, alignment = layout.section, layout.alignment
    vertices, triangles = terrain.terrain_mesh(alignment, section, 60.0, (0.0, 20.0), 0.0, 30.0, np.random.default_rng(1))
    lateral, base_z = laterals(vertices, alignment, np.linspace(0.0, 20.0, 21))
    expected = np.where(np.abs(lateral) <= section.ballast_toe_half, 0.0, section.surface(lateral))
    assert np.allclose(vertices[:, 2] - base_z, expected, atol=1e-9)
    assert np.isclose(np.abs(lateral).max(), 30.0)
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    assert (np.cross(b - a, c - a)[:, 2] > 0).all()


def test_undulation_stays_within_its_amplitude_and_fades_in_beyond_the_slopes(railway):
    params, layout = railway
    field = terrain.undulation(np.random.default_rng(5), 20.0)
    values = field(np.random.default_rng(6).uniform(-100, 100, (5000, 2)))
    assert np.abs(values).max() <= 1.0 and values.std() > 0.2
    flat, _ = terrain.terrain_mesh(layout.alignment, layout.section, 60.0, (0.0, 20.0), 0.0, 20.0, np.random.default_rng(1))
    rough, _ = terrain.terrain_mesh(layout.alignment, layout.section, 60.0, (0.0, 20.0), 0.8, 20.0, np.random.default_rng(1))
    lateral, _ = laterals(flat, layout.alignment, np.linspace(0.0, 20.0, 21))
    change = np.abs(rough[:, 2] - flat[:, 2])
    edge = layout.section.embankment_toe_half
    fade = np.clip((np.abs(lateral) - edge) / terrain.FADE, 0.0, 1.0)
    assert np.all(change[np.abs(lateral) <= edge] == 0.0)  # the track bed and the slopes stay where the cross-section says
    assert np.all(change <= 0.8 * fade + 1e-9) and change[fade == 1].max() > 0.2


# ----------------------------------------------------------------------------- railway trackside
def test_signal_chainages_every_spacing_within_a_quarter():
    assert len(trackside.signal_chainages(500.0, 0.0, np.random.default_rng(0))) == 0
    s = trackside.signal_chainages(1000.0, 100.0, np.random.default_rng(0))
    centres = 50.0 + 100.0 * np.arange(10)
    assert len(s) == 10 and np.all(np.abs(s - centres) <= 25.0)


def test_signals_stand_clear_of_the_supports_beside_the_track(railway):
    params, layout = railway
    side = dataclasses.replace(params.trackside, signal_spacing=30.0)
    frames = trackside.signal_frames(layout, side, np.random.default_rng(2))
    supports = np.array([s.chainage for s in layout.supports])
    feet = frames[:, :3, 3]
    chainage = np.array([np.argmin(np.linalg.norm(layout.alignment.point(np.linspace(0, layout.alignment.length, 2001)) - f, axis=1)) for f in feet])
    chainage = chainage * layout.alignment.length / 2000
    assert len(frames) >= 2 and np.all(np.abs(chainage[:, None] - supports[None, :]).min(axis=1) >= 3.0 - 0.6)
    mesh_v, _ = trackside.signal(frames[0], side.signal_height, -1.0)
    assert np.isclose(mesh_v[:, 2].max() - frames[0][2, 3], side.signal_height)


def test_fence_posts_and_the_platform_follow_their_parameters(railway):
    params, layout = railway
    side = dataclasses.replace(params.trackside, fence_post_spacing=5.0, platform_length=40.0)
    v, t = trackside.fence(layout.alignment, layout.section.surface, side, 8.0)
    assert len(t) > 0 and np.isclose(v[:, 2].max() - layout.alignment.point(np.zeros(1))[0, 2] - float(layout.section.surface(8.0)), side.fence_height,
                                     atol=0.05)
    nearest = float(layout.section.offsets[-1])
    pv, _ = trackside.platform(layout.alignment, layout.section.surface, side, layout.section.rail_top, nearest)
    assert np.isclose(pv[:, 2].max() - layout.alignment.point(np.zeros(1))[0, 2], layout.section.rail_top + side.platform_height, atol=1e-6)
    assert trackside.platform(layout.alignment, layout.section.surface, params.trackside, layout.section.rail_top, nearest) is None
