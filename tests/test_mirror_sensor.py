"""The super-resolution mirror LiDAR: its own mirrors, the star pattern, edge-drop masks, range images.

References are analytic: the reflection on each segment's plane, the rotational and mirror
symmetry of the eight segments, ray-plane intersections with a floor.
"""

import dataclasses
import struct

import numpy as np
import pytest

from bpy_pipeline.buffers import MATERIAL_ID, ObjectTable, SceneBuffers
from bpy_pipeline.config import EdgeDropConfig, ReflectorConfig, config_from_dict
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry import primitives
from bpy_pipeline.io.range_image import image_points, organise, read_range_image, write_range_image
from bpy_pipeline.lidar.sensor import grid
from bpy_pipeline.lidar.sensor.mirror_sensor import drop_at_edges, edge_drop_mask, load_edge_mask, reflect_pattern, trace_mirrors
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.scanner import scan
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern

PAPER = ReflectorConfig(enabled=True)  # eight segments at 34 degrees, 0.1 m from the optical centre
OS1 = resolve_sensor({"preset": "os1_128", "columns": 2048})
PER_SEGMENT = 2048 // 8 * 128  # rays of one segment: 256 columns of 128 rings (column-major pattern)


@pytest.fixture(scope="module")
def os1():
    pattern = sensor_pattern(OS1)
    return pattern, trace_mirrors(PAPER, pattern.directions)


def segment_normal(k, reflector=PAPER):
    """The analytic normal of segment ``k``: facing the sensor and the floor, ``inclination`` off the spin axis."""
    phi, i = np.radians(reflector.azimuth_deg + 45.0 * k), np.radians(reflector.inclination_deg)
    return np.array([-np.cos(i) * np.cos(phi), -np.cos(i) * np.sin(phi), -np.sin(i)])


def floor_hits(rays, height=5.0):
    """(n, 3) where the reflected rays meet a floor ``height`` metres below the optical centre."""
    t = (-height - rays.origin[:, 2]) / rays.direction[:, 2]
    return rays.origin + t[:, None] * rays.direction


def rotation_z(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_reflected_directions_are_the_analytic_reflection_on_each_segment(os1):
    pattern, rays = os1
    assert rays.kept.all() and len(rays.segment) == 128 * 2048
    d = pattern.directions
    for k in range(8):
        sel = rays.segment == k
        assert sel.sum() == PER_SEGMENT
        n = segment_normal(k)
        assert np.abs(rays.direction[sel] - (d[sel] - 2.0 * (d[sel] @ n)[:, None] * n)).max() < 1e-12
        assert np.abs(rays.origin[sel] @ n + 0.1 * np.cos(np.radians(34.0))).max() < 1e-12  # on the segment's plane
        assert np.abs(rays.origin[sel] - rays.leg[sel, None] * d[sel]).max() < 1e-12  # along the emitted ray
        azimuth = (np.degrees(np.arctan2(d[sel, 1], d[sel, 0])) - 45.0 * k + 180.0) % 360.0 - 180.0
        assert np.abs(azimuth).max() <= 22.5 + 1e-9  # a segment takes the rays of its own 45 degree wedge
    assert np.degrees(np.arcsin(-rays.direction[:, 2])).min() > 40.0  # everything goes down
    centre = slice(1024 * 128, 1025 * 128)  # column 1024 fires at azimuth 0, the centre of segment 0
    r, elevation = rays.direction[centre], np.degrees(np.arcsin(d[centre, 2]))
    below_inward = np.degrees(np.arctan2(-r[:, 2], -r[:, 0]))  # angle below the horizon, towards the sensor's far side
    assert np.allclose(below_inward, 2 * 34.0 - elevation, atol=1e-9)  # 2 i, less the beam's elevation: 45.5 to 90.5 degrees
    assert np.abs(r[:, 1]).max() < 1e-12


def test_each_segment_maps_its_rays_into_its_own_sector_of_the_star(os1):
    pattern, rays = os1
    floor = floor_hits(rays)
    # The same shape for every segment: the next 256 columns are the previous ones turned by -45 degrees (cw spin).
    assert np.abs(floor[PER_SEGMENT:] - floor[:-PER_SEGMENT] @ rotation_z(-45.0).T).max() < 1e-9
    # Mirror-symmetric about its centre line: segment 0 (centred at azimuth 0, column 1024) maps y -> -y.
    c = np.arange(1, 128)
    left, right = (((1024 + s * c)[:, None] * 128 + np.arange(128)).ravel() for s in (1, -1))
    assert np.abs(floor[left] * [1, -1, 1] - floor[right]).max() < 1e-9
    wedge = (np.degrees(np.arctan2(pattern.directions[:, 1], pattern.directions[:, 0])) + 22.5) % 45.0 - 22.5
    inner = np.abs(wedge) < 22.5 - 1e-6  # leave out the columns fired exactly along a hip (they go to one side)
    for k in range(8):
        sel = (rays.segment == k) & inner
        centre = np.radians(45.0 * k + 180.0)  # a 34 degree segment throws its rays back under the sensor
        azimuth = np.arctan2(floor[sel, 1], floor[sel, 0])
        mean = np.degrees(np.angle(np.exp(1j * (azimuth - centre)).sum()))
        assert abs(mean) < 1e-6  # the sector is centred on the segment's own (opposite) direction
        # Each segment's footprint is a trapezoid whose near edge passes about 2 m from the nadir (5 m
        # below); its outer part, where the eight overlap least, is its own sector: within +-50 degrees.
        outer = np.hypot(floor[sel, 0], floor[sel, 1]) > 0.6 * 5.0
        off = np.degrees(np.angle(np.exp(1j * (azimuth[outer] - centre))))
        assert np.abs(off).max() < 50.0 and outer.mean() > 0.25
    radius = np.hypot(floor[:, 0], floor[:, 1])
    assert 0.9 * 5.0 < np.percentile(radius, 99) and radius.max() < 1.2 * 5.0  # a 45 degree cone around the nadir


def test_inclination_past_45_degrees_throws_the_sector_outward():
    pattern = sensor_pattern(OS1)
    rays = trace_mirrors(dataclasses.replace(PAPER, inclination_deg=56.0, bottom=0.4), pattern.directions)
    assert rays.kept.all()
    floor = floor_hits(rays)
    wedge = (np.degrees(np.arctan2(pattern.directions[:, 1], pattern.directions[:, 0])) + 22.5) % 45.0 - 22.5
    for k in range(8):
        sel = (rays.segment == k) & (np.abs(wedge) < 22.5 - 1e-6)
        azimuth = np.arctan2(floor[sel, 1], floor[sel, 0])
        assert abs(np.degrees(np.angle(np.exp(1j * (azimuth - np.radians(45.0 * k))).sum()))) < 1e-6
    assert np.degrees(np.arcsin(-rays.direction[:, 2])).min() > 40.0


def test_rays_that_miss_every_segment_are_lost():
    pattern = sensor_pattern(OS1)
    short = dataclasses.replace(PAPER, bottom=0.02, top=0.02)  # segments too short for the lower and upper beams
    rays = trace_mirrors(short, pattern.directions)
    i = np.radians(34.0)
    phi = np.radians(45.0 * rays.segment)
    u = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(len(phi))])
    up = -np.sin(i) * u + np.cos(i) * np.array([0.0, 0.0, 1.0])
    b = np.einsum("ij,ij->i", rays.origin - 0.1 * u, up)  # up the slope from the segment's centre point
    assert 0.3 < rays.kept.mean() < 0.9 and (np.abs(b[rays.kept]) <= 0.02 + 1e-9).all()
    assert np.isnan(rays.direction[~rays.kept]).all() and (rays.segment[~rays.kept] == -1).all()
    narrow = trace_mirrors(dataclasses.replace(PAPER, width=0.05), pattern.directions)  # gaps between the segments
    a = np.einsum("ij,ij->i", narrow.origin, np.column_stack([-np.sin(np.radians(45.0 * narrow.segment)), np.cos(np.radians(45.0 * narrow.segment)),
                                                              np.zeros(len(pattern))]))
    assert 0.3 < narrow.kept.mean() < 0.9 and (np.abs(a[narrow.kept]) <= 0.025 + 1e-9).all()
    reflected = reflect_pattern(pattern, short)
    assert len(reflected) == rays.kept.sum() and np.array_equal(reflected.ring, pattern.ring[rays.kept])
    # Mirrors nearly parallel to the axis turn beams back into the opposite segment: those are lost too.
    steep_reflector = dataclasses.replace(PAPER, inclination_deg=10.0, bottom=0.12, top=0.1)
    steep = trace_mirrors(steep_reflector, pattern.directions)
    i, k = np.radians(10.0), np.floor((np.degrees(np.arctan2(pattern.directions[:, 1], pattern.directions[:, 0])) + 22.5) / 45.0 + 1e-9) % 8
    u = np.column_stack([np.cos(np.radians(45 * k)), np.sin(np.radians(45 * k)), np.zeros(len(k))])
    n = -np.cos(i) * u - np.sin(i) * np.array([0.0, 0.0, 1.0])
    point = (0.1 * np.cos(i) / -np.einsum("ij,ij->i", pattern.directions, n))[:, None] * pattern.directions
    b = np.einsum("ij,ij->i", point - 0.1 * u, -np.sin(i) * u + np.cos(i) * np.array([0.0, 0.0, 1.0]))
    on_own = (b > -0.12 + 1e-9) & (b < 0.1 - 1e-9)
    assert steep.kept[~on_own].sum() == 0 and 0.1 < steep.kept.mean() and (on_own & ~steep.kept).mean() > 0.1  # blocked after reflecting


def test_a_scan_through_the_sensor_mirrors_puts_points_at_their_true_positions():
    floor = primitives.translated(primitives.plane(40.0, 40.0), [0.0, 0.0, -4.0])
    person = primitives.translated(primitives.cylinder(0.3, 1.8, 32), [1.5, 0.5, -3.1])
    vertices = np.concatenate([floor[0], person[0]])
    triangles = np.concatenate([floor[1], person[1] + len(floor[0])]).astype(np.int32)
    rows = np.concatenate([np.zeros(len(floor[1]), np.int32), np.ones(len(person[1]), np.int32)])
    table = ObjectTable(["floor", "person"], ["", ""], ["floor", "person"], np.array([15, 21], np.uint16), np.array([1, 2], np.uint32),
                        np.array([MATERIAL_ID["diffuse"]] * 2, np.uint8), np.array([0.5, 0.5], np.float32))
    buffers = SceneBuffers(vertices, triangles, rows, table)
    pose = np.eye(4)
    pose[:3, 3] = [0.0, 0.0, 0.0]
    spec = resolve_sensor({"preset": "os1_128", "columns": 512})
    pattern = reflect_pattern(sensor_pattern(spec), PAPER)
    points, _ = scan(RayCaster(buffers, frame=pose), buffers, pattern, pose, 0.1, 50.0)
    assert len(points) == len(pattern)  # every reflected ray meets the floor or the person
    on_floor = points["semantic"] == 15
    assert np.allclose(points["z"][on_floor], -4.0, atol=1e-5) and 500 < (~on_floor).sum()
    person = points[~on_floor]
    radial = np.hypot(person["x"] - 1.5, person["y"] - 0.5)
    on_side = (radial > 0.3 * np.cos(np.pi / 32) - 1e-5) & (radial < 0.3 + 1e-5)  # the 32-sided prism inscribed in r = 0.3
    on_top = np.abs(person["z"] + 2.2) < 1e-5
    assert (on_side | on_top).all() and on_side.sum() > 100
    # Each point lies on its reflected ray at its range from the mirror.
    rays = trace_mirrors(PAPER, sensor_pattern(spec).directions)
    col = np.rint(points["time"] / grid.column_period(spec)).astype(int)
    ray = col * 128 + points["ring"].astype(int)
    xyz = rays.origin[ray] + rays.direction[ray] * points["range"][:, None].astype(np.float64)
    assert np.abs(xyz - np.column_stack([points["x"], points["y"], points["z"]])).max() < 1e-4


# ----------------------------------------------------------------------------- mirror-edge drop
def test_edge_drop_mask_repeats_once_per_mirror_and_sits_on_the_segment_edges(os1):
    mask = edge_drop_mask(PAPER, OS1, 0.95, 0.01)
    assert mask.shape == (128, 2048) and mask.dtype == np.float32
    assert set(np.unique(mask)) <= {0.0, np.float32(0.95), 1.0}
    assert np.array_equal(mask, np.roll(mask, 256, axis=1))  # once per mirror: eight times round
    dropped = np.flatnonzero((mask > 0).any(axis=0))
    hips = 128 + 256 * np.arange(8)  # columns whose azimuth lies exactly on a segment edge (22.5 + 45 k degrees)
    assert np.abs((dropped[:, None] - hips[None, :] + 1024) % 2048 - 1024).min(axis=1).max() < 40
    assert (mask[:, hips] == np.float32(0.95)).all()  # a beam centred on an edge always splits
    assert (mask[:, (hips + 128) % 2048] == 0).all()  # the segment centres never do
    _, rays = os1
    clearance = rays.clearance.reshape(2048, 128).T[::-1]  # column-major rays -> (row 0 = top ring, column)
    assert np.array_equal(mask > 0, clearance < 0.005)
    wider = edge_drop_mask(PAPER, OS1, 0.95, 0.02)
    assert (wider >= mask).all() and (wider > 0).sum() > 1.5 * (mask > 0).sum()
    assert not edge_drop_mask(PAPER, OS1, 0.95, 0.0).any()  # a zero-width beam never splits


def test_edge_drop_is_drawn_per_point_from_the_mask():
    spec = resolve_sensor({"preset": "os1_128", "columns": 512})
    pattern = sensor_pattern(spec)
    from bpy_pipeline.lidar.points import empty_points

    points = empty_points(len(pattern))
    points["ring"], points["time"] = pattern.ring, pattern.time
    mask = np.zeros((128, 512), np.float32)
    mask[:, :64] = 1.0
    mask[:, 64:128] = 0.5
    keep = drop_at_edges(points, mask, spec, np.random.default_rng(3))
    row, col = grid.pixels(spec, points["ring"], points["time"])
    assert not keep[col < 64].any() and keep[col >= 128].all()
    half = keep[(col >= 64) & (col < 128)]
    assert abs(half.mean() - 0.5) < 4 * np.sqrt(0.25 / len(half))
    assert np.array_equal(keep, drop_at_edges(points, mask, spec, np.random.default_rng(3)))


def test_a_measured_mask_is_loaded_and_checked(tmp_path):
    path = tmp_path / "mask.npy"
    measured = np.zeros((128, 2048), bool)
    measured[:, 120:136] = True
    np.save(path, measured)
    assert np.array_equal(load_edge_mask(path, (128, 2048)), measured.astype(np.float32))
    np.save(path, np.zeros((128, 1024)))
    with pytest.raises(InputError, match=r"^sensor\.reflector\.edge_drop\.mask: .* shape \(128, 1024\), expected \(128, 2048\)"):
        load_edge_mask(path, (128, 2048))
    np.save(path, np.full((128, 2048), 1.5))
    with pytest.raises(InputError, match="0..1"):
        load_edge_mask(path, (128, 2048))
    with pytest.raises(InputError, match="cannot read"):
        load_edge_mask(tmp_path / "absent.npy", (128, 2048))


# ----------------------------------------------------------------------------- the image grid and range images
@pytest.mark.parametrize("fields", [{"preset": "os1_128", "columns": 2048}, {"preset": "hdl64e"}, {"preset": "railway_tls", "sampling_factor": 0.05}])
def test_pixels_follow_the_firing_order(fields):
    spec = resolve_sensor(fields)
    pattern = sensor_pattern(spec)
    rows, columns = grid.image_shape(spec)
    assert rows * columns == len(pattern)
    row, col = grid.pixels(spec, pattern.ring, pattern.time)
    i = np.arange(len(pattern))
    assert np.array_equal(col, i // rows)  # column-major pattern
    elevation = np.degrees(np.arcsin(pattern.directions[:rows, 2]))
    assert np.array_equal(row[:rows], np.argsort(np.argsort(-elevation, kind="stable"), kind="stable"))  # row 0 the highest beam


def test_range_image_round_trip(tmp_path):
    spec = resolve_sensor({"preset": "os1_128", "columns": 2048})
    pattern = sensor_pattern(spec)
    rng = np.random.default_rng(0)
    from bpy_pipeline.lidar.points import empty_points

    points = empty_points(len(pattern))
    points["ring"], points["time"] = pattern.ring, pattern.time
    points["range"] = rng.uniform(0.5, 20.0, len(points))
    points["x"], points["y"], points["z"] = (pattern.directions * points["range"][:, None].astype(np.float64)).T
    points["semantic"] = rng.integers(0, 26, len(points))
    points["instance"] = rng.integers(0, 50, len(points))
    points = points[rng.random(len(points)) > 0.3]  # some beams without a return
    from bpy_pipeline.labels import load_class_table

    paths = write_range_image(tmp_path / "000000.npy", points, spec, load_class_table().color_lut())
    image = read_range_image(paths[0])
    assert image.shape == (128, 2048)
    row, col = grid.pixels(spec, points["ring"], points["time"])
    assert image[row, col].tobytes() == points.tobytes()  # every record at its pixel, unchanged
    assert (image["range"] > 0).sum() == len(points)
    back = image_points(image)
    order = np.lexsort((col, row))
    assert back.tobytes() == points[order].tobytes()
    png = paths[1].read_bytes()
    width, height = struct.unpack(">II", png[16:24])
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and (width, height) == (2048, 256)
    doubled = np.concatenate([points[:1], points[:1]])
    doubled["range"] = [7.0, 3.0]
    assert organise(doubled, spec)["range"].max() == 3.0  # two returns on one pixel: the nearer is kept


# ----------------------------------------------------------------------------- config
def test_reflector_config_defaults_round_trip_and_errors(tmp_path):
    from bpy_pipeline.config import config_to_dict

    base = {"sensor": {"preset": "os1_128", "columns": 2048, "reflector": {"enabled": True}}, "output": {"formats": ["ply", "range_image"]}}
    config = config_from_dict(base)
    assert config.sensor.reflector == PAPER and config.sensor.reflector.edge_drop == EdgeDropConfig()
    assert config_from_dict(config_to_dict(config)) == config
    bad = [
        ({"inclination_deg": 0}, r"^sensor\.reflector\.inclination_deg: "),
        ({"segments": 2}, r"^sensor\.reflector\.width: "),
        ({"top": 0.5}, r"^sensor\.reflector\.top: .*meet"),
        ({"distance": -1}, r"^sensor\.reflector\.distance: "),
        ({"edge_drop": {"probability": 2}}, r"^sensor\.reflector\.edge_drop\.probability: "),
        ({"edge_drop": {"mask": str(tmp_path / "absent.npy")}}, r"^sensor\.reflector\.edge_drop\.mask: cannot read"),
        ({"colour": "silver"}, r"^sensor\.reflector\.colour: unknown key"),
    ]
    for fields, message in bad:
        data = {"sensor": {**base["sensor"], "reflector": {"enabled": True, **fields}}}
        with pytest.raises(InputError, match=message):
            config_from_dict(data)
    with pytest.raises(InputError, match=r"^output\.formats: range_image: needs a sensor whose frames are a rows x columns image"):
        config_from_dict({"sensor": {"preset": "flash96x16"}, "output": {"formats": ["range_image"]}})
    with pytest.raises(InputError, match=r"^effects\.mirrors\.glass\.reflect_fraction: "):
        config_from_dict({"effects": {"mirrors": {"glass": {"reflect_fraction": 1.5}}}})
    with pytest.raises(InputError, match=r"^effects\.mirrors\.max_bounces: "):
        config_from_dict({"effects": {"mirrors": {"max_bounces": 300}}})


@pytest.mark.bpy
def test_pipeline_frame_of_the_mirror_sensor(tmp_path):
    """Blender scene -> the OS1-128 through its eight mirrors, 4 m up -> edge drop -> PLY and range image."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.lidar.sensor.sensor_rays import SensorRays
    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, [
        "scene.builder=primitives",
        "scene.shapes=[{type: plane, size: [30, 30], class: floor}, {type: cylinder, size: [0.25, 1.75], position: [1.2, 0.4, 0.875], class: person}]",
        "sensor.preset=os1_128", "sensor.columns=2048", "sensor.position=[0, 0, 4]", "sensor.reflector={enabled: true}",
        "output.formats=[ply, range_image]", "output.preview=false", "effects.ideal=true",
    ])
    manifest = run(config, tmp_path, log=lambda *_: None)
    assert sorted(manifest["frames"][0]["files"]) == ["ply/000000.ply", "range_image/000000.npy", "range_image/000000.png"]
    points = read_ply(tmp_path / "ply" / "000000.ply")
    image = read_range_image(tmp_path / "range_image" / "000000.npy")
    assert image.shape == (128, 2048) and (image["range"] > 0).sum() == len(points)
    floor = points["semantic"] == 15
    assert np.allclose(points["z"][floor], -4.0, atol=1e-4) and (points["semantic"] == 21).sum() > 500  # true positions, sensor frame
    mask = SensorRays(config).edge_mask(0)
    hit = image["range"] > 0
    assert not hit[mask == 1].any()  # rays that miss the mirrors never return
    kept_at_edges = hit[mask == np.float32(0.95)].mean()
    assert kept_at_edges < 0.1 and hit[mask == 0].mean() > 0.99  # about 5 % survive on the edges
