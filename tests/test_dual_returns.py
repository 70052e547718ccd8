"""Dual returns (``sensor.divergence.return: dual``): a beam whose footprint spans a near box's edge and the
wall behind it gives its strongest and its last return, at the ranges its sub-rays' own geometry says;
the single-return modes are the same points as before, and a dual scan holds them."""

import numpy as np
import pytest

from bpy_pipeline.config import config_from_dict
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.effects.divergence import Divergence, expand, reduce_returns, return_index, scan_footprint
from bpy_pipeline.lidar.cast.raycast import RayCaster
from test_divergence import buffers_of, fan, wall_x, xyz


def box(x0, x1, y0, y1, z0, z1):
    """A closed axis-aligned box, (8, 3) vertices and (12, 3) outward triangles."""
    v = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], float)
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return v, np.array([t for a, b, c, d in faces for t in ((a, b, c), (a, c, d))], np.int32)


NEAR, FAR = 10.0, 14.0  # m: the box's front face and the wall


def scene_and_beams():
    near_box = box(NEAR, NEAR + 1.0, -3.0, 0.0, -2.0, 2.0)  # its edge at y = 0: sub-rays with y < 0 stop on it
    scene = buffers_of([near_box, wall_x(FAR, -50.0, 50.0)], [0.3, 0.8])
    beams = fan(np.linspace(-0.5, 0.5, 101) + 0.00123, np.zeros(101))
    return scene, beams


def test_a_beam_straddling_a_box_edge_gives_its_strongest_and_last_returns():
    scene, beams = scene_and_beams()
    caster = RayCaster(scene, frame=np.eye(4))
    divergence = Divergence(mrad=10.0, rays=37, pick="dual")
    points, facts = scan_footprint(caster, scene, beams, np.eye(4), divergence, 0.2, 150.0)
    sub, beam = expand(beams, divergence)
    d = sub.directions
    on_box = d[:, 1] < 0
    r = np.where(on_box, NEAR, FAR) / d[:, 0]
    w = np.where(on_box, 0.3, 0.8) * d[:, 0]  # reflectivity x |cos incidence|
    box_energy, wall_energy = (np.bincount(beam, w * m, len(beams)) / 37 for m in (on_box, ~on_box))
    box_range = np.bincount(beam, w * r * on_box, len(beams)) / np.maximum(box_energy * 37, 1e-300)
    wall_range = np.bincount(beam, w * r * ~on_box, len(beams)) / np.maximum(wall_energy * 37, 1e-300)
    both = (box_energy > 0) & (wall_energy > 0)
    assert both.sum() >= 5  # 10 mrad at 10 m: beams within +-0.29 deg of the edge see the box and the wall

    index = return_index(points)
    assert len(points) == len(beams) + both.sum() and index.sum() == both.sum()
    first, second = points[index == 0], points[index == 1]
    assert np.array_equal(first["ring"], beams.ring) and np.array_equal(second["ring"], beams.ring[both])
    box_stronger = box_energy > wall_energy
    # the first point of a beam: its strongest return; the second: its last (the wall), or the box when the wall is strongest
    assert np.allclose(first["range"], np.where(box_stronger, box_range, wall_range), atol=2e-5)
    assert np.allclose(first["intensity"], np.maximum(box_energy, wall_energy), atol=1e-6)
    assert np.allclose(second["range"], np.where(box_stronger, wall_range, box_range)[both], atol=2e-5)
    assert np.allclose(second["intensity"], np.minimum(box_energy, wall_energy)[both], atol=1e-6)
    assert np.array_equal(second["instance"], np.where(box_stronger, 2, 1)[both])
    assert (second["range"] > 0).all() and np.abs(second["range"] - first["range"][both]).min() > 3.9  # the two surfaces, 4 m apart
    assert np.allclose(xyz(points), beams.directions[points["ring"].astype(int)] * points["range"][:, None], atol=1e-4)  # along the central beam
    power = facts["reflectivity"] * facts["cos_incidence"] * facts["gain"]  # what the effects' intensity models see, per return
    assert np.allclose(power, points["intensity"], atol=1e-6)


def test_dual_holds_the_strongest_and_last_single_modes_byte_for_byte():
    scene, beams = scene_and_beams()
    caster = RayCaster(scene, frame=np.eye(4))
    run = {pick: scan_footprint(caster, scene, beams, np.eye(4), Divergence(mrad=10.0, rays=37, pick=pick), 0.2,
                                150.0) for pick in ("strongest", "last", "dual")}
    dual, dual_facts = run["dual"]
    index = return_index(dual)
    assert dual[index == 0].tobytes() == run["strongest"][0].tobytes() and dual_facts[index == 0].tobytes() == run["strongest"][1].tobytes()
    # a beam's last return is the farther of its dual points (the second, or the first when the strongest is the last)
    farthest = np.zeros(len(beams), np.float32)
    np.maximum.at(farthest, dual["ring"].astype(int), dual["range"])
    assert np.array_equal(run["last"][0]["range"], farthest)


def test_reduce_returns_dual_takes_the_second_strongest_when_the_last_is_strongest():
    beam = np.array([0, 0, 0, 1, 1, 2])
    distance = np.array([5.0, 9.0, 12.0, 3.0, 20.0, 7.0])
    intensity = np.array([0.2, 0.1, 0.6, 0.5, 0.1, 0.3])  # beam 0: the last (12 m) is strongest, 5 m second
    row, ranges, energy = reduce_returns(beam, distance, intensity, 1, "dual", 0.5)
    assert np.array_equal(row, [2, 0, 3, 4, 5]) and np.allclose(ranges, [12.0, 5.0, 3.0, 20.0, 7.0], rtol=1e-12)
    for pick, rows in (("first", [0, 3, 5]), ("strongest", [2, 3, 5]), ("last", [2, 4, 5])):
        assert np.array_equal(reduce_returns(beam, distance, intensity, 1, pick, 0.5)[0], rows)


def test_dual_from_config_only_for_presets_that_have_it():
    on = config_from_dict({"sensor": {"preset": "vlp16", "divergence": {"mrad": 3.0, "rays": 7, "return": "dual"}}})
    assert on.sensor.divergence.pick == "dual"
    with pytest.raises(InputError, match="^sensor.divergence.return: the os1_64 sensor has no dual return mode"):
        config_from_dict({"sensor": {"preset": "os1_64", "divergence": {"mrad": 3.0, "rays": 7, "return": "dual"}}})
