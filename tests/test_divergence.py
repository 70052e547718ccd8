"""Beam divergence: the sub-ray pattern, the reduction to returns, and footprints traced through Embree
against exact answers (a wire is returned iff a sub-ray meets it; a step edge splits into the
first, strongest and last returns computed from the sub-rays' own geometry)."""

import numpy as np
import pytest

from bpy_pipeline.buffers import ObjectTable, SceneBuffers
from bpy_pipeline.config import config_from_dict, config_to_dict
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry import primitives
from bpy_pipeline.lidar.effects.divergence import Divergence, expand, footprint_offsets, reduce_returns, scan_footprint
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.scanner import scan
from bpy_pipeline.lidar.sensor.sensors import spherical_directions
from bpy_pipeline.lidar.sensor.rays import Pattern
from bpy_pipeline.frame import frame_rng
from bpy_pipeline.stages.scan import scan_buffers


def fan(azimuth_deg, elevation_deg) -> Pattern:
    """Beams at matching azimuths and elevations (degrees), ring = index, time 0."""
    directions = spherical_directions(np.asarray(azimuth_deg, float), np.asarray(elevation_deg, float))
    return Pattern(directions, np.arange(len(directions), dtype=np.uint16), np.zeros(len(directions)))


def buffers_of(meshes, reflectivity) -> SceneBuffers:
    """One object per ``(vertices, triangles)`` mesh, with its reflectivity."""
    vertices, triangles, owner, offset = [], [], [], 0
    for i, (v, t) in enumerate(meshes):
        vertices.append(v)
        triangles.append(t + offset)
        owner.append(np.full(len(t), i, np.int32))
        offset += len(v)
    k = len(meshes)
    objects = ObjectTable([f"o{i}" for i in range(k)], [""] * k, ["wall"] * k, np.full(k, 17, np.uint16), np.arange(1, k + 1, dtype=np.uint32),
                          np.zeros(k, np.uint8), np.asarray(reflectivity, np.float32))
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(owner), objects)


def wall_x(x, y0, y1, half_z=50.0):
    """A wall in the plane x = const spanning y0..y1."""
    return np.array([[x, y0, -half_z], [x, y1, -half_z], [x, y1, half_z], [x, y0, half_z]], float), np.array([[0, 1, 2], [0, 2, 3]], np.int32)


def xyz(points):
    return np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64)


# ----------------------------------------------------------------------------- the sub-ray pattern
def test_footprint_offsets_a_centre_and_an_equal_area_spiral():
    assert np.array_equal(footprint_offsets(1), [[0.0, 0.0]])
    for rays in (2, 3, 4, 7, 8, 19, 20, 37, 1000, 1001):
        offsets = footprint_offsets(rays)
        radius = np.hypot(offsets[:, 0], offsets[:, 1])
        assert offsets.shape == (rays, 2) and (np.diff(radius) >= -1e-12).all() and radius.max() < 1
        assert np.abs(offsets.mean(axis=0)).max() < 1e-15  # centred: no bias to one side
        # equal-area cells: the squared radii add up to the cells' mid-area fractions (k + 0.5) / rays
        assert np.sum(radius**2) == pytest.approx((rays**2 - 1) / (2 * rays) if rays > 2 else 1.0)
    assert radius[0] == 0 and np.array_equal(offsets, footprint_offsets(1001))  # no seed: the same pattern every time
    many = footprint_offsets(20001)
    assert np.cov(many.T) == pytest.approx(np.eye(2) / 4, abs=2e-3)  # a uniform disk's second moments


def test_expand_spreads_each_beam_over_its_cone():
    beams = fan([0.0, 90.0, 30.0], [0.0, 10.0, 89.0])
    divergence = Divergence(mrad=4.0, rays=7, aperture=0.01)
    sub, beam = expand(beams, divergence)
    assert len(sub) == 21 and np.array_equal(beam, np.repeat([0, 1, 2], 7))
    assert np.array_equal(sub.ring, np.repeat(beams.ring, 7)) and np.array_equal(sub.time, np.repeat(beams.time, 7))
    assert np.allclose(np.linalg.norm(sub.directions, axis=1), 1.0)
    radius = np.hypot(*footprint_offsets(7).T)
    central = beams.directions[beam]
    off_axis = np.arctan2(np.linalg.norm(np.cross(sub.directions, central), axis=1), np.einsum("ij,ij->i", sub.directions, central))
    assert np.allclose(off_axis, np.tile(radius, 3) * 2e-3, atol=1e-9)  # half of 4 mrad at the cone's edge
    assert np.array_equal(sub.directions[::7], beams.directions)  # sub-ray 0 is the central ray
    assert np.allclose(np.linalg.norm(sub.origins, axis=1), np.tile(radius, 3) * 0.005)  # over the 10 mm exit window
    assert np.abs(np.einsum("ij,ij->i", sub.origins, beams.directions[beam])).max() < 1e-15  # across the beam


# ----------------------------------------------------------------------------- returns of a beam
def test_reduce_returns_groups_hits_by_range_then_picks():
    beam = np.array([0, 0, 0, 2, 3, 3])
    distance = np.array([10.0, 10.2, 20.0, 5.0, 7.0, 7.0])
    intensity = np.array([0.2, 0.6, 0.9, 0.5, 0.0, 0.0])
    shuffle = np.array([4, 2, 0, 5, 3, 1])
    b, d, w = beam[shuffle], distance[shuffle], intensity[shuffle]
    row, rng, energy = reduce_returns(b, d, w, 4, "first", 0.5)
    assert np.array_equal(b[row], [0, 2, 3])
    assert np.allclose(rng, [(10.0 * 0.2 + 10.2 * 0.6) / 0.8, 5.0, 7.0]) and np.allclose(energy, [0.2, 0.125, 0.0])
    assert d[row][0] == 10.2  # the return's strongest sub-ray stands for it
    row, rng, energy = reduce_returns(b, d, w, 4, "last", 0.5)
    assert np.allclose(rng, [20.0, 5.0, 7.0]) and np.allclose(energy, [0.225, 0.125, 0.0])
    row, rng, _ = reduce_returns(b, d, w, 4, "strongest", 0.5)
    assert np.allclose(rng, [20.0, 5.0, 7.0])  # 0.9 beats 0.2 + 0.6
    row, rng, _ = reduce_returns(b, d, w, 4, "strongest", 50.0)
    assert np.allclose(rng[0], (10.0 * 0.2 + 10.2 * 0.6 + 20.0 * 0.9) / 1.7)  # one return when the pulse cannot split them
    row, rng, _ = reduce_returns(b, d, w, 4, "first", 0.0)
    assert np.allclose(rng, [10.0, 5.0, 7.0])  # separation 0: every sub-ray range its own return
    assert all(len(a) == 0 for a in reduce_returns(np.zeros(0, int), np.zeros(0), np.zeros(0), 4, "first", 0.5))


# ----------------------------------------------------------------------------- footprints through Embree
def test_a_wire_returns_exactly_when_a_sub_ray_meets_it():
    radius, distance = 0.006, 30.0
    vertices, triangles = primitives.cylinder(radius, 40.0, 64)  # along z: turn it horizontal, along y, at x = 30
    wire = buffers_of([(vertices[:, [0, 2, 1]] + [distance, 0, 0], triangles[:, [0, 2, 1]])], [0.7])
    beams = fan(np.zeros(2001), np.linspace(-0.3, 0.3, 2001))  # 0.0003 deg (5 um at 30 m) apart
    divergence = Divergence(mrad=3.0, rays=19, pick="first")
    caster = RayCaster(wire, frame=np.eye(4))
    points, _ = scan_footprint(caster, wire, beams, np.eye(4), divergence, 0.2, 150.0)
    returned = np.zeros(len(beams), bool)
    returned[points["ring"]] = True
    # exact: the sub-ray passes within the radius of the wire's axis (the line x = 30, z = 0)
    sub, beam = expand(beams, divergence)
    miss_distance = distance * np.abs(sub.directions[:, 2]) / np.hypot(sub.directions[:, 0], sub.directions[:, 2])
    sure = np.zeros(len(beams), bool)
    sure[beam[miss_distance < radius * np.cos(np.pi / 64) - 1e-6]] = True  # inside the inscribed 64-gon
    possible = np.zeros(len(beams), bool)
    possible[beam[miss_distance <= radius + 1e-6]] = True
    assert (returned >= sure).all() and (returned <= possible).all()
    # a beam the wire only touches at its footprint's edge is still reported along its central direction
    width = returned.sum() * np.radians(0.6 / 2000) * distance
    assert 0.012 + 0.8 * 0.09 < width < 0.012 + 0.09  # 12 mm wire widened by up to the 90 mm footprint
    central = beams.directions[points["ring"]]
    assert np.allclose(xyz(points) / np.linalg.norm(xyz(points), axis=1, keepdims=True), central, atol=1e-6)
    assert np.abs(points["range"] - distance).max() < 0.01
    zero_width, _ = scan(caster, wire, beams, np.eye(4), 0.2, 150.0)
    assert abs(len(zero_width) * np.radians(0.6 / 2000) * distance - 0.012) < 0.0005  # the bare wire: 12 mm


def test_a_step_edge_gives_the_first_strongest_and_last_returns_of_its_sub_rays():
    near, far = wall_x(10.0, -50.0, 0.0), wall_x(12.0, -50.0, 50.0)  # near wall left of y = 0 (seen to the right)
    scene = buffers_of([near, far], [0.2, 0.9])
    beams = fan(np.linspace(-0.6, 0.6, 121) + 0.00123, np.zeros(121))  # no sub-ray exactly on the edge
    caster = RayCaster(scene, frame=np.eye(4))
    divergence = Divergence(mrad=10.0, rays=37)
    sub, beam = expand(beams, divergence)
    d = sub.directions
    assert np.abs(d[:, 1]).min() > 1e-9
    hits_near = d[:, 1] < 0  # sub-rays right of the near wall's edge (seen from the sensor, y < 0) stop at x = 10
    r = np.where(hits_near, 10.0, 12.0) / d[:, 0]
    w = np.where(hits_near, 0.2, 0.9) * d[:, 0]  # reflectivity x |cos incidence|
    for pick in ("first", "strongest", "last"):
        points, facts = scan_footprint(caster, scene, beams, np.eye(4), Divergence(mrad=10.0, rays=37, pick=pick), 0.2, 150.0)
        assert np.array_equal(points["ring"], beams.ring)  # every beam returns once
        near_energy = np.bincount(beam, w * hits_near, len(beams)) / 37
        far_energy = np.bincount(beam, w * ~hits_near, len(beams)) / 37
        near_range = np.bincount(beam, w * r * hits_near, len(beams)) / np.maximum(near_energy * 37, 1e-300)
        far_range = np.bincount(beam, w * r * ~hits_near, len(beams)) / np.maximum(far_energy * 37, 1e-300)
        take_near = {"first": near_energy > 0, "last": far_energy == 0, "strongest": near_energy > far_energy}[pick]
        assert np.allclose(points["range"], np.where(take_near, near_range, far_range), atol=2e-5)
        assert np.allclose(points["intensity"], np.where(take_near, near_energy, far_energy), atol=1e-6)
        assert np.array_equal(points["instance"], np.where(take_near, 1, 2))
        assert np.allclose(xyz(points), beams.directions * points["range"][:, None], atol=1e-4)  # along the central beam
        assert np.allclose(facts["reflectivity"], np.where(take_near, 0.2, 0.9))
        power = facts["reflectivity"] * facts["cos_incidence"] * facts["gain"]  # what the effects' intensity models see
        assert np.allclose(power, points["intensity"], atol=1e-6)
        straddling = (near_energy > 0) & (far_energy > 0)
        assert straddling.sum() >= 5  # 10 mrad at 10 m: beams within +-0.29 deg of the edge see both walls


def test_chunks_change_nothing_and_a_plane_looks_the_same_through_a_footprint():
    scene = buffers_of([wall_x(25.0, -100.0, 100.0, 100.0)], [0.5])
    beams = fan(np.repeat(np.linspace(-30, 30, 61), 11), np.tile(np.linspace(-20, 20, 11), 61))
    caster = RayCaster(scene, frame=np.eye(4))
    divergence = Divergence(mrad=3.0, rays=19)
    whole, _ = scan_footprint(caster, scene, beams, np.eye(4), divergence, 0.2, 150.0)
    pieces, _ = scan_footprint(caster, scene, beams, np.eye(4), divergence, 0.2, 150.0, chunk_rays=100)  # 5 beams a chunk
    assert whole.tobytes() == pieces.tobytes()
    bare, _ = scan(caster, scene, beams, np.eye(4), 0.2, 150.0)
    assert np.array_equal(whole["ring"], bare["ring"])
    # on a plane, one return: its range the intensity-weighted mean of the sub-rays' (25 / d_x weighted by 0.5 d_x)
    sub, beam = expand(beams, divergence)
    cos = np.bincount(beam, sub.directions[:, 0]) / 19
    assert np.abs(whole["range"] - 25.0 / cos).max() < 2e-5
    assert np.abs(whole["intensity"] - 0.5 * cos).max() < 1e-6
    assert np.abs(whole["range"] - bare["range"]).max() < 25.0 / np.cos(np.radians(40)) * 1.5e-3**2  # second order: centred footprint


# ----------------------------------------------------------------------------- config and pipeline
def test_divergence_from_config_through_the_pipeline_with_a_moving_sensor():
    sensor = {"preset": "custom", "pattern": "spinning", "channels": 8, "vertical_fov_deg": [-10, 10], "horizontal_fov_deg": [-30, 30],
              "horizontal_resolution_deg": 0.5, "rotation_hz": 10.0, "min_range": 0.5, "max_range": 150.0}
    moving = {"trajectory": {"waypoints": [[0, 0, 0], [50, 0, 0]], "speed": 20.0}}
    on = config_from_dict({"sensor": {**sensor, **moving, "divergence": {"mrad": 2.0, "rays": 7, "return": "last"}}})
    assert on.sensor.divergence == Divergence(2.0, 7, "last") and config_from_dict(config_to_dict(on)) == on
    off = config_from_dict({"sensor": {**sensor, **moving}})
    assert not off.sensor.divergence.active
    scene = buffers_of([wall_x(30.0, -100.0, 100.0, 100.0)], [0.5])
    with_footprint, _ = scan_buffers(scene, on, frame_rng(0, 0))
    bare, _ = scan_buffers(scene, off, frame_rng(0, 0))
    assert np.array_equal(with_footprint["time"], bare["time"]) and np.array_equal(with_footprint["ring"], bare["ring"])
    assert np.abs(with_footprint["x"] - 30.0).max() < 1e-3 and np.abs(bare["x"] - 30.0).max() < 1e-4  # the footprint adds < 1 mm here
    again, _ = scan_buffers(scene, on, frame_rng(7, 0))
    assert again.tobytes() == with_footprint.tobytes()  # deterministic: no seed in the footprint


@pytest.mark.parametrize(
    "section, message",
    [
        ({"mrad": -1}, "^sensor.divergence.mrad: must lie in 0..100"),
        ({"mrad": 1e9}, "^sensor.divergence.mrad: must lie in 0..100"),
        ({"mrad": 3, "rays": 0}, "^sensor.divergence.rays: must lie in 1..1024"),
        ({"mrad": 3, "rays": 5000}, "^sensor.divergence.rays: must lie in 1..1024"),
        ({"rays": 7}, "^sensor.divergence.rays: 7 sub-rays of a zero-width beam"),
        ({"mrad": 3, "rays": 7, "return": "middle"}, "^sensor.divergence.return: expected 'first'"),
        ({"mrad": 3, "rays": 7, "separation": -0.1}, "^sensor.divergence.separation: must be >= 0"),
        ({"mrad": 3, "rays": 7, "aperture": -0.01}, "^sensor.divergence.aperture: must be >= 0"),
        ({"mrad": 3, "cone": 7}, "^sensor.divergence.cone"),
    ],
)
def test_bad_divergence_config_names_its_key(section, message):
    with pytest.raises(InputError, match=message):
        config_from_dict({"sensor": {"preset": "vlp16", "divergence": section}})
