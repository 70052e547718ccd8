"""Each ray pattern of lidar/sensor/patterns against its own geometry: counts, directions, rings and firing times.

One test group per module (base, scanning, profile, rosette, camera, file); the presets of sensors.yaml give the specs.
"""

import math

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.sensor.patterns import base as patterns_base
from bpy_pipeline.lidar.sensor.patterns import camera, file as file_pattern, profile, rosette, scanning
from bpy_pipeline.lidar.sensor.patterns.base import PATTERNS, RayPattern, register_pattern
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor


def frame(spec, frame_index: int = 0):
    """All rays of one frame of ``spec``."""
    entry = PATTERNS.get(spec.pattern)
    return entry.rays(spec)(0, entry.count(spec), frame_index)


def elevation_deg(d):
    return np.degrees(np.arcsin(np.clip(d[:, 2], -1, 1)))


def azimuth_deg(d):
    return np.degrees(np.arctan2(d[:, 1], d[:, 0]))


# ----------------------------------------------------------------------------- base
def test_registry_refuses_a_second_pattern_of_one_name_and_names_the_allowed_ones():
    with pytest.raises(ValueError, match="spinning"):
        register_pattern("spinning", RayPattern(None, None, None, None, None))
    with pytest.raises(InputError) as err:
        PATTERNS.get("helical")
    assert str(err.value).startswith("sensor.pattern: unknown ray pattern 'helical'") and "rosette" in str(err.value)


def test_check_rows_names_the_bad_field():
    spec = resolve_sensor({"preset": "vlp16"})
    with pytest.raises(InputError, match=r"^s\.horizontal_fov_deg: expected \[min, max\]"):
        patterns_base.check_rows(spec.__class__(**{**spec.__dict__, "horizontal_fov_deg": (10.0, 5.0)}), "s")
    with pytest.raises(InputError, match=r"^s\.elevations_deg: lists 2 angles for 16 channels"):
        patterns_base.check_rows(spec.__class__(**{**spec.__dict__, "elevations_deg": [0.0, 1.0]}), "s")


def test_derive_columns_gives_the_step_and_refuses_a_disagreeing_one():
    spec = resolve_sensor({"preset": "vlp16"})
    window = spec.__class__(**{**spec.__dict__, "horizontal_fov_deg": (-45.0, 45.0), "columns": 91, "firing_rate_hz": 0.0})
    assert patterns_base.derive_columns(window, {}, "s", window=True) == {"horizontal_resolution_deg": 1.0}
    assert patterns_base.derive_columns(window, {}, "s", window=False) == {"horizontal_resolution_deg": 90.0 / 91}
    with pytest.raises(InputError, match=r"^s\.horizontal_resolution_deg: 0\.5 disagrees with columns"):
        patterns_base.derive_columns(window, {"horizontal_resolution_deg": 0.5}, "s", window=True)


def test_sampled_extent_is_frame_zero_in_degrees():
    spec = resolve_sensor({"preset": "livox_mid40"})
    elevations, azimuths = patterns_base.sampled_extent(spec)
    d = frame(spec).directions
    assert np.allclose(elevations, elevation_deg(d)) and np.allclose(azimuths, azimuth_deg(d))


# ----------------------------------------------------------------------------- scanning (spinning, terrestrial)
def test_spinning_rays_are_column_major_at_the_table_elevations_and_column_azimuths():
    spec = resolve_sensor({"preset": "vlp16", "horizontal_resolution_deg": 2.0})
    p = frame(spec)
    rows, columns = spec.channels, scanning.column_count(spec)
    assert columns == 180 and len(p.directions) == rows * columns == scanning.count(spec)
    assert np.allclose(np.linalg.norm(p.directions, axis=1), 1.0)
    assert np.allclose(elevation_deg(p.directions), scanning.elevations(spec)[p.ring])
    column = np.arange(len(p.ring)) // rows
    turn = (azimuth_deg(p.directions) - scanning.azimuths(spec)[column] + 180) % 360 - 180
    assert np.allclose(turn, 0.0, atol=1e-9)
    assert np.allclose(p.time, column * 2.0 / (360.0 * spec.rotation_hz))  # a column fires at once


def test_terrestrial_window_spans_both_edges_and_fires_rows_one_after_another():
    spec = resolve_sensor({"preset": "railway_tls", "horizontal_fov_deg": [0, 90], "horizontal_resolution_deg": 1.0, "sampling_factor": 1.0})
    assert spec.pattern == "terrestrial"
    assert scanning.column_count(spec) == 91  # 0, 1, ..., 90 deg
    az = scanning.azimuths(spec)
    assert {az[0], az[-1]} == {0.0, 90.0}
    p = frame(spec)
    first_column = p.time[: spec.channels]
    assert (np.diff(first_column) > 0).all()  # bottom to top within the column


# ----------------------------------------------------------------------------- profile
def test_profile_rays_lie_in_the_y_z_plane_one_profile_a_ring_each_at_its_own_time():
    spec = resolve_sensor({"preset": "railway_profiler", "horizontal_resolution_deg": 3.0, "sampling_factor": 1.0, "columns": 4})
    p = frame(spec)
    k = len(profile.angles(spec))
    assert k == 120 and len(p.ring) == 4 * k == profile.count(spec)
    assert np.allclose(p.directions[:, 0], 0.0)
    assert np.allclose(np.degrees(np.arctan2(p.directions[:, 2], p.directions[:, 1])) % 360, np.tile(profile.angles(spec), 4) % 360)
    assert (p.ring == np.repeat(np.arange(4), k)).all()
    assert (np.diff(p.time) > 0).all() and math.isclose(profile.frame_time(spec), 4 / spec.rotation_hz)


def test_profile_check_names_columns():
    spec = resolve_sensor({"preset": "railway_profiler"})
    with pytest.raises(InputError, match=r"^sensor\.columns: profiles per frame"):
        profile.check(spec.__class__(**{**spec.__dict__, "columns": 0}), "sensor")


# ----------------------------------------------------------------------------- rosette
def test_rosette_stays_within_the_two_prisms_deflection_and_continues_across_frames():
    spec = resolve_sensor({"preset": "livox_mid40"})
    n = rosette.count(spec)
    assert n == round(spec.point_rate_hz * rosette.frame_time(spec))
    p0 = frame(spec, 0)
    off_axis = np.degrees(np.arccos(np.clip(p0.directions[:, 0], -1, 1)))
    assert off_axis.max() <= sum(spec.deflection_deg) + 1e-9 and off_axis.max() > 0.95 * sum(spec.deflection_deg)
    chunk = rosette.rays(spec)
    assert np.allclose(chunk(n, n + 5, 0).directions, chunk(0, 5, 1).directions)  # frame 1 goes on where frame 0 stopped
    assert not np.allclose(chunk(0, 5, 1).directions, p0.directions[:5])
    assert PATTERNS.get("rosette").per_frame


# ----------------------------------------------------------------------------- camera (pinhole, grid)
def test_pinhole_rays_pass_through_the_pixel_centres():
    spec = resolve_sensor({"preset": "flash96x16"})
    assert spec.pattern == "pinhole"
    p = frame(spec)
    assert len(p.ring) == camera.count(spec) == spec.columns * spec.channels
    d = p.directions
    y, z = d[:, 1] / d[:, 0], d[:, 2] / d[:, 0]
    assert np.allclose(np.sort(np.unique(np.round(y, 9))), np.sort(camera.pinhole_y(spec)))
    assert np.allclose(np.sort(np.unique(np.round(z, 9))), np.sort(camera.pinhole_z(spec)))
    half = math.radians(spec.horizontal_fov_deg[1])
    assert math.isclose(camera.focal(spec), spec.columns / (2 * math.tan(half)))


def test_grid_camera_rays_sit_on_its_elevation_and_azimuth_grid():
    spec = resolve_sensor({"preset": "flash96x16_grid"})
    p = frame(spec)
    assert np.allclose(np.sort(np.unique(np.round(elevation_deg(p.directions), 9))), np.sort(camera.grid_elevations(spec)))
    assert np.allclose(np.sort(np.unique(np.round(azimuth_deg(p.directions), 9))), np.sort(camera.grid_azimuths(spec)))


def test_pinhole_check_refuses_a_field_of_180_degrees():
    spec = resolve_sensor({"preset": "flash96x16"})
    with pytest.raises(InputError, match=r"^s\.horizontal_fov_deg: a pinhole camera needs \[-a, a\] with a < 90"):
        camera.check(spec.__class__(**{**spec.__dict__, "horizontal_fov_deg": (-90.0, 90.0)}), "s")


# ----------------------------------------------------------------------------- file
def test_file_pattern_reads_and_normalises_the_directions(tmp_path):
    path = tmp_path / "rays.npy"
    np.save(path, np.array([[2.0, 0, 0], [0, 3.0, 4.0], [1.0, 1.0, 0]]))
    spec = resolve_sensor({"preset": "vlp16", "pattern": "file", "rays_file": str(path)})
    assert file_pattern.count(spec) == 3
    p = frame(spec)
    assert np.allclose(p.directions, [[1, 0, 0], [0, 0.6, 0.8], [math.sqrt(0.5), math.sqrt(0.5), 0]])
    assert (p.ring == 0).all() and (p.time == 0).all()


def test_file_pattern_names_a_file_of_the_wrong_shape(tmp_path):
    path = tmp_path / "flat.npy"
    np.save(path, np.zeros((4, 2)))
    spec = resolve_sensor({"preset": "vlp16"})
    with pytest.raises(InputError, match=r"^s\.rays_file: .*flat\.npy has shape \(4, 2\), expected \(n, 3\)"):
        file_pattern.check(spec.__class__(**{**spec.__dict__, "pattern": "file", "rays_file": str(path)}), "s")
