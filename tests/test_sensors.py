"""Sensor presets and their ray patterns: tables, sweeps, timing, chunking, the CLI, bad input,
and the HDL-32E preset against a real nuScenes sweep."""

import math

import numpy as np
import pytest
import yaml

from bpy_pipeline.cli.commands import main
from bpy_pipeline.config import config_from_dict, config_to_dict, load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.lidar.sensor.sensors import (
    angular_resolution,
    azimuths,
    elevations,
    iter_pattern,
    mount_offset,
    preset_effects,
    presets,
    ray_count,
    resolve_sensor,
    sensor_pattern,
    spec_summary,
)


def preset(name, **overrides):
    return resolve_sensor({"preset": name, **overrides})


def elevation_deg(directions):
    return np.degrees(np.arcsin(np.clip(directions[:, 2], -1.0, 1.0)))


def azimuth_deg(directions):
    return np.degrees(np.arctan2(directions[:, 1], directions[:, 0]))


# ----------------------------------------------------------------------------- spinning presets against their tables
HDL64E_TABLE = np.sort(np.r_[2.0 - np.arange(32) / 3.0, np.linspace(-8.83, -24.9, 32)])
SPINNING = {
    # name: (channels, expected elevations (ring order), columns, azimuth step deg, rotation Hz, max range)
    "vlp16": (16, np.arange(-15.0, 15.1, 2.0), 1809, 0.2, 10.0, 100.0),
    "hdl32e": (32, -30.0 - 2.0 / 3.0 + np.arange(32) * 4.0 / 3.0, 1084, 0.3321, 20.0, 100.0),
    "hdl64e": (64, HDL64E_TABLE, 2118, 0.17, 10.0, 120.0),
    "pandar64": (64, None, 1800, 0.2, 10.0, 200.0),
    "os1_64": (64, np.linspace(-16.6, 16.6, 64), 1024, 360 / 1024, 10.0, 120.0),
    "os1_128": (128, np.linspace(-22.5, 22.5, 128), 1024, 360 / 1024, 10.0, 120.0),
}
ELEVATION_TOLERANCE = {"hdl32e": 0.025, "hdl64e": 0.001}  # hdl32e: a calibrated unit against the datasheet's 4/3 deg


@pytest.mark.parametrize("name", SPINNING)
def test_spinning_preset_directions_match_its_table(name):
    channels, table, columns, step, rotation_hz, max_range = SPINNING[name]
    spec = preset(name)
    pattern = sensor_pattern(spec)
    assert spec.channels == channels and spec.rotation_hz == rotation_hz and spec.max_range == max_range
    assert len(pattern) == channels * columns == spec_summary(spec)["rays_per_frame"]
    assert pattern.directions.dtype == np.float64 and pattern.ring.dtype == np.uint16 and pattern.time.dtype == np.float64
    np.testing.assert_allclose(np.linalg.norm(pattern.directions, axis=1), 1.0, atol=1e-12)

    grid = pattern.directions.reshape(columns, channels, 3)  # column-major: every ring of a column, then the next column
    assert (pattern.ring.reshape(columns, channels) == np.arange(channels)).all()
    el = elevation_deg(grid.reshape(-1, 3)).reshape(columns, channels)
    assert np.ptp(el, axis=0).max() < 1e-9  # a ring keeps its elevation all the way round
    if table is not None:
        np.testing.assert_allclose(el[0], table, atol=ELEVATION_TOLERANCE.get(name, 1e-9))
    assert (np.diff(el[0]) > 0).all()  # ring 0 is the lowest beam

    az = azimuth_deg(grid[:, 0])
    steps = np.diff(np.unwrap(np.radians(az)))
    assert np.degrees(np.abs(steps)).max() == pytest.approx(np.degrees(np.abs(steps)).min(), abs=1e-9)
    assert (steps < 0).all()  # these sensors turn clockwise seen from above
    assert math.degrees(abs(steps[0])) == pytest.approx(step, rel=0.01)
    assert len(np.unique(np.round(az, 6))) == columns  # no column fired twice in one revolution

    time = pattern.time.reshape(columns, channels)
    assert np.ptp(time, axis=1).max() == 0.0  # a column's channels fire together
    assert (np.diff(time[:, 0]) > 0).all() and time[0, 0] == 0.0 and time.max() < 1.0 / rotation_hz


def test_pandar64_table_is_finer_near_the_horizon():
    el = elevations(preset("pandar64"))
    assert len(el) == 64 and el.min() == pytest.approx(-25.0, abs=0.2) and el.max() == pytest.approx(15.0, abs=0.2)
    spacing = np.diff(el)
    near = (el[:-1] >= -6.1) & (el[1:] <= 2.1)
    assert spacing[near].max() < 0.18 and near.sum() >= 45  # 0.17 deg steps from -6 to +2 deg
    assert spacing[~near].min() > 0.9  # coarse above and below


def test_hdl64e_has_two_blocks_with_their_own_spacing():
    el = elevations(preset("hdl64e"))[::-1]  # top first
    np.testing.assert_allclose(np.diff(el[:32]), -1 / 3, atol=1e-3)
    np.testing.assert_allclose(np.diff(el[32:]), -(24.9 - 8.83) / 31, atol=1e-3)
    assert el[31] - el[32] == pytest.approx(0.497, abs=0.01)  # the gap between the blocks


@pytest.mark.parametrize("name, hz, step", [("vlp16", 5, 0.1), ("vlp16", 20, 0.4), ("hdl64e", 5, 0.085), ("pandar64", 20, 0.4)])
def test_azimuth_step_follows_the_spin_rate(name, hz, step):
    spec = preset(name, rotation_hz=hz)
    assert angular_resolution(spec)[0] == pytest.approx(step, rel=0.01)
    pattern = sensor_pattern(spec)
    assert pattern.time.max() < 1 / hz


@pytest.mark.parametrize("columns", [512, 1024, 2048])
def test_ouster_columns_are_selectable(columns):
    spec = preset("os1_128", columns=columns)
    az = azimuths(spec)
    assert len(az) == columns and ray_count(spec) == 128 * columns
    assert spec.horizontal_resolution_deg == pytest.approx(360 / columns)
    assert az[0] == 180.0 and az[-1] == pytest.approx(-180 + 360 / columns)  # column 0 at the back, as Ouster counts


@pytest.mark.parametrize("spin, first, last", [("ccw", -45.0, 45.0), ("cw", 45.0, -45.0)])
def test_a_window_spans_both_edges_and_fires_within_its_share_of_the_sweep(spin, first, last):
    spec = resolve_sensor({"preset": "custom", "horizontal_fov_deg": [-45, 45], "horizontal_resolution_deg": 0.5, "spin": spin})
    az = azimuths(spec)
    assert len(az) == 181 and az[0] == first and az[-1] == pytest.approx(last)
    pattern = sensor_pattern(spec)
    assert pattern.time.max() == pytest.approx(0.25 / spec.rotation_hz)  # 90 of 360 deg
    by_columns = preset("os1_64", horizontal_fov_deg=[-45, 45], columns=100)
    assert len(azimuths(by_columns)) == 100 and azimuths(by_columns)[[0, -1]] == pytest.approx([45, -45])


# ----------------------------------------------------------------------------- terrestrial scanner of the railway thesis
def test_railway_tls_matches_table_4_3():
    spec = preset("railway_tls")
    s = spec_summary(spec)
    assert s["columns"] == 7200 and s["channels"] == 3201 and s["rays_per_frame"] == 7200 * 3201 == 23_047_200
    assert s["elevation_deg"] == [-70.0, 90.0] and s["azimuth_deg"] == [0.0, 359.95]
    assert s["range_m"] == [0.2, 150.0] and angular_resolution(spec) == pytest.approx((0.05, 0.05))
    np.testing.assert_array_equal(mount_offset(spec), [0.0, 0.0, 2.0])


def test_sampling_factor_above_one_densifies_both_axes():
    """Table 4.3: 1.0 = full resolution, below 1 fewer points; the thesis's 1.5 divides both steps by 1.5."""
    full, thesis, coarse = (preset("railway_tls", sampling_factor=f) for f in (1.0, 1.5, 0.5))
    assert angular_resolution(thesis) == pytest.approx((0.05 / 1.5, 0.05 / 1.5))
    assert ray_count(thesis) == 10800 * 4801
    assert ray_count(coarse) == 3600 * 1601 < ray_count(full) < ray_count(thesis)


def test_terrestrial_rays_fire_column_by_column_bottom_to_top():
    spec = preset("railway_tls", sampling_factor=0.1)  # 0.5 deg: 720 columns x 321 rows
    pattern = sensor_pattern(spec)
    rows = spec.channels
    assert rows == 321 and len(pattern) == 720 * rows
    grid = pattern.directions.reshape(720, rows, 3)
    np.testing.assert_allclose(elevation_deg(grid[0]), -70 + 0.5 * np.arange(rows), atol=1e-9)
    np.testing.assert_allclose(np.mod(azimuth_deg(grid[:, 0]), 360), 0.5 * np.arange(720), atol=1e-9)
    assert (np.diff(pattern.time) > 0).all() and pattern.time.max() < 1 / spec.rotation_hz  # the mirror sweeps each column


def test_a_full_terrestrial_scan_streams_in_bounded_chunks():
    spec = preset("railway_tls")
    chunk, total, last = 1 << 21, 0, -1.0
    for part in iter_pattern(spec, chunk):
        assert 0 < len(part) <= chunk and part.time[0] > last
        total += len(part)
        last = part.time[-1]
    assert total == 23_047_200 and last < 1 / spec.rotation_hz


# ----------------------------------------------------------------------------- chunked patterns equal the whole
@pytest.mark.parametrize("name", [n for n in presets() if n != "railway_tls"] + ["railway_tls_coarse"])
def test_iter_pattern_chunks_concatenate_to_sensor_pattern(name):
    spec = preset("railway_tls", sampling_factor=0.2) if name == "railway_tls_coarse" else preset(name)
    for frame in (0, 3):
        whole = sensor_pattern(spec, frame=frame)
        parts = list(iter_pattern(spec, 7777, frame=frame))
        assert all(len(p) <= 7777 for p in parts) and sum(map(len, parts)) == len(whole)
        for field in ("directions", "ring", "time"):
            assert np.array_equal(np.concatenate([getattr(p, field) for p in parts]), getattr(whole, field)), field


# ----------------------------------------------------------------------------- flash camera: pinhole against angular grid
def test_flash_grid_is_uniform_in_angle():
    spec = preset("flash96x16_grid")
    pattern = sensor_pattern(spec)
    image = pattern.directions.reshape(16, 96, 3)  # row-major image, top-left pixel first
    az = azimuth_deg(image.reshape(-1, 3)).reshape(16, 96)
    el = elevation_deg(image.reshape(-1, 3)).reshape(16, 96)
    np.testing.assert_allclose(np.diff(az, axis=1), -80 / 96, atol=1e-9)  # left to right, 0.833 deg a pixel
    np.testing.assert_allclose(np.diff(el, axis=0), -15 / 16, atol=1e-9)  # top to bottom, 0.9375 deg a pixel
    assert az.max() == pytest.approx(40 - 40 / 96) and el.max() == pytest.approx(7.5 - 7.5 / 16)
    assert (pattern.ring.reshape(16, 96) == np.arange(16)[:, None]).all()
    assert (pattern.time == 0).all()  # a flash: every pixel at once


def test_flash_pinhole_is_a_flat_image_plane():
    spec = preset("flash96x16")
    pattern = sensor_pattern(spec)
    d = pattern.directions.reshape(16, 96, 3)
    fx = 96 / (2 * math.tan(math.radians(40)))
    u, v = -d[..., 1] / d[..., 0] * fx + 48, -d[..., 2] / d[..., 0] * fx + 8  # project back to pixels
    np.testing.assert_allclose(u, np.broadcast_to(np.arange(96) + 0.5, (16, 96)), atol=1e-9)
    np.testing.assert_allclose(v, np.broadcast_to(np.arange(16)[:, None] + 0.5, (16, 96)), atol=1e-9)
    assert (pattern.time == 0).all()

    az = azimuth_deg(d[8])
    pitch = -np.diff(az)
    centre, edge = pitch[47], pitch[0]
    assert centre == pytest.approx(math.degrees(math.atan(1 / fx)), rel=1e-3)  # widest at the centre ...
    assert edge == pytest.approx(centre * math.cos(math.radians(40)) ** 2, rel=0.02)  # ... cos^2 narrower at the edges
    assert edge < 0.65 < 80 / 96 < centre
    vertical_fov = math.degrees(2 * math.atan(8 / fx))
    assert vertical_fov == pytest.approx(15.9, abs=0.05)  # fy = fx: the vertical fov follows, not the 15 deg of the grid


# ----------------------------------------------------------------------------- rosette
def test_rosette_is_bounded_by_its_deflection_and_fills_it():
    spec = preset("livox_mid40")
    pattern = sensor_pattern(spec)
    off_axis = np.degrees(np.arccos(np.clip(pattern.directions[:, 0], -1, 1)))
    assert len(pattern) == 10_000 and off_axis.max() <= 19.2 + 1e-9 and off_axis.max() > 19.0
    np.testing.assert_allclose(np.linalg.norm(pattern.directions, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.diff(pattern.time), 1e-5, rtol=1e-6)
    assert pattern.time[0] == 0 and pattern.time[-1] < spec.frame_time_s and (pattern.ring == 0).all()


def test_rosette_never_repeats_and_coverage_grows():
    spec = preset("livox_mid40")

    def cells(frames):
        d = np.concatenate([sensor_pattern(spec, frame=f).directions for f in frames])
        return set(map(tuple, np.floor(np.degrees(d[:, 1:] / d[:, :1]) / 0.5).astype(int)))

    first, second = sensor_pattern(spec, frame=0), sensor_pattern(spec, frame=1)
    assert np.abs(first.directions - second.directions).max() > 0.1  # frame 1 goes on where frame 0 stopped
    np.testing.assert_array_equal(first.time, second.time)  # times count from each frame's start
    coverage = [len(cells(range(n))) for n in (1, 2, 5, 10)]
    assert coverage == sorted(set(coverage))  # strictly growing
    assert coverage[-1] > 2 * coverage[0]
    fov_cells = math.pi * (math.tan(math.radians(19.2)) * 180 / math.pi / 0.5) ** 2
    assert coverage[-1] > 0.6 * fov_cells  # one second covers most of the circle


# ----------------------------------------------------------------------------- user-defined patterns
def test_file_pattern_normalises_its_rays(tmp_path):
    path = tmp_path / "rays.npy"
    np.save(path, np.array([[2.0, 0, 0], [0, 0, -3], [1, 1, 0]], np.float32))
    spec = resolve_sensor({"preset": "custom", "pattern": "file", "rays_file": str(path)})
    pattern = sensor_pattern(spec)
    np.testing.assert_allclose(pattern.directions, [[1, 0, 0], [0, 0, -1], [math.sqrt(0.5), math.sqrt(0.5), 0]], atol=1e-7)
    assert ray_count(spec) == 3 and (pattern.ring == 0).all() and (pattern.time == 0).all()


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "cannot read"),
        (np.zeros((4, 2)), "shape (4, 2)"),
        (np.zeros((0, 3)), "holds no rays"),
        (np.array([[1.0, 0, 0], [np.nan, 0, 1]]), "row 1 is not finite"),
        (np.array([[1.0, 0, 0], [0, 0, 0]]), "row 1 has zero length"),
        (np.array(["a", "b", "c"]).reshape(1, 3), "expected numbers"),
    ],
)
def test_bad_rays_file_names_key_and_file(tmp_path, content, message):
    path = tmp_path / "rays.npy"
    if content is not None:
        np.save(path, content)
    with pytest.raises(InputError) as err:
        resolve_sensor({"preset": "custom", "pattern": "file", "rays_file": str(path)})
    text = str(err.value)
    assert text.startswith("sensor.rays_file:") and str(path) in text and message in text


# ----------------------------------------------------------------------------- overrides and bad input
def test_every_preset_round_trips_through_the_config():
    for name in presets():
        for extra in ([], ["sensor.rotation_hz=20"], ["sensor.max_range=50"]):
            config = load_config(None, [f"sensor.preset={name}", *extra])
            assert config_from_dict(config_to_dict(config)) == config, (name, extra)
    from bpy_pipeline.config import DEFAULT_SENSOR

    assert load_config().sensor.spec.name == DEFAULT_SENSOR["preset"]
    assert load_config(None, ["sensor.max_range=50"]).sensor.spec.name == DEFAULT_SENSOR["preset"]
    assert load_config(None, ["sensor.preset=custom"]).sensor.spec.sampling_factor == 1.0


def test_overrides_replace_what_they_name():
    assert preset("os1_64", horizontal_resolution_deg=0.5).columns == 0  # the preset's columns stop applying
    assert len(azimuths(preset("os1_64", horizontal_resolution_deg=0.5))) == 720
    fan = preset("hdl32e", channels=8)  # a channel count replaces the table by a uniform fan over the fov
    np.testing.assert_allclose(elevations(fan), np.linspace(-30.67, 10.67, 8))
    assert preset("hdl32e", elevations_deg=[-10, 0, 10]).channels == 3
    assert preset("hdl64e", vertical_fov_deg=[-10, 10]).elevations_deg == []
    assert preset("vlp16", max_range=30).channels == 16
    spec = preset("vlp16", rotation_hz=20.0)  # columns follow the firing rate at the faster spin
    assert spec.horizontal_resolution_deg == pytest.approx(2 * preset("vlp16").horizontal_resolution_deg)


@pytest.mark.parametrize(
    "overrides, key",
    [
        ({"min_range": 100.0}, "sensor.min_range"),
        ({"min_range": 5, "max_range": 2}, "sensor.min_range"),
        ({"channels": "many"}, "sensor.channels"),
        ({"channels": 16.5}, "sensor.channels"),
        ({"channels": 0}, "sensor.channels"),
        ({"rotation_hz": "fast"}, "sensor.rotation_hz"),
        ({"rotation_hz": 0}, "sensor.rotation_hz"),
        ({"vertical_fov_deg": [10, -10]}, "sensor.vertical_fov_deg"),
        ({"vertical_fov_deg": [-15]}, "sensor.vertical_fov_deg"),
        ({"horizontal_fov_deg": [0, 400]}, "sensor.horizontal_fov_deg"),
        ({"horizontal_resolution_deg": -1}, "sensor.horizontal_resolution_deg"),
        ({"horizontal_resolution_deg": 1e-6}, "sensor.horizontal_resolution_deg"),
        ({"elevations_deg": [0, 95]}, "sensor.elevations_deg[1]"),  # the item outside the range
        ({"channels": 4, "elevations_deg": [1, 2]}, "sensor.elevations_deg"),
        ({"pattern": "lissajous"}, "sensor.pattern"),
        ({"spin": "up"}, "sensor.spin"),
        ({"sampling_factor": 0}, "sensor.sampling_factor"),
        ({"mount_height": -1}, "sensor.mount_height"),
        ({"pattern": "file"}, "sensor.rays_file"),
        ({"beams": 16}, "sensor.beams"),
        ({"preset": "hdl999"}, "sensor.preset"),
        ({"preset": "os1_64", "columns": 2048, "horizontal_resolution_deg": 0.5}, "sensor.horizontal_resolution_deg"),
        ({"preset": "os1_64", "columns": 2.5}, "sensor.columns"),
        ({"preset": "os1_64", "columns": 1024, "firing_rate_hz": 2e4}, "sensor.columns"),
        ({"preset": "railway_tls", "sampling_factor": 30}, "sensor.sampling_factor"),
        ({"preset": "railway_tls", "channels": 10, "vertical_resolution_deg": 0.05}, "sensor.channels"),
        ({"preset": "flash96x16", "horizontal_fov_deg": [-10, 50]}, "sensor.horizontal_fov_deg"),
        ({"preset": "flash96x16", "columns": 0}, "sensor.columns"),
        ({"preset": "flash96x16", "horizontal_resolution_deg": 0.3}, "sensor.horizontal_resolution_deg"),  # the key given, not the columns it unset
        ({"preset": "flash96x16_grid", "firing_rate_hz": 1e4}, "sensor.firing_rate_hz"),
        ({"preset": "livox_mid40", "deflection_deg": [60, 40]}, "sensor.deflection_deg"),
        ({"preset": "livox_mid40", "point_rate_hz": 0}, "sensor.point_rate_hz"),
    ],
)
def test_bad_overrides_name_their_key(overrides, key):
    with pytest.raises(InputError) as err:
        resolve_sensor({"preset": "vlp16", **overrides})
    assert str(err.value).startswith(key + ":"), str(err.value)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name", list(presets()))
def test_every_preset_has_a_field_of_view_for_placement_and_culling(name):
    """Every builder asks the sensor's field of view before its first frame (placement in view, levels of detail). A pattern
    without rows (a profile, a rosette) covers every direction; a profiler on any builder crashed here."""
    from bpy_pipeline.rig import field_of_view, out_of_reach

    spec = preset(name)
    fov = field_of_view(spec, np.eye(4))
    assert -180.0 <= fov.azimuth[0] < fov.azimuth[1] <= 360.0 and -90.0 - 1.0 <= fov.elevation[0] < fov.elevation[1] <= 90.0 + 1.0, (fov.azimuth, fov.elevation)
    if len(elevations(spec)) == 0:
        assert (fov.azimuth, fov.elevation) == ((-180.0, 180.0), (-90.0, 90.0))
    centres = np.array([[5.0, 0.0, 0.0], [0.0, 0.0, 30.0], [0.0, 0.0, -30.0], [2 * spec.max_range + 10.0, 0.0, 0.0]])
    reach = out_of_reach(spec, np.eye(4), centres, np.ones(len(centres)))
    assert reach[-1] and reach.dtype == bool  # beyond the range: out of reach for every pattern


def test_bad_override_through_the_config_names_the_full_key():
    with pytest.raises(InputError, match=r"^sensor\.max_range:"):
        load_config(None, ["sensor.preset=hdl64e", "sensor.max_range=true"])
    with pytest.raises(InputError, match=r"^sensor\.min_range:"):
        load_config(None, ["sensor.preset=os1_64", "sensor.min_range=150"])


# ----------------------------------------------------------------------------- command line
def test_cli_lists_every_preset_on_one_line(capsys):
    assert main(["sensors"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line for line in lines[1:]}
    assert list(rows) == list(presets()) and len(lines) == len(presets()) + 1
    assert "23,047,200" in rows["railway_tls"] and "-70.00..+90.00" in rows["railway_tls"]
    assert rows["vlp16"].split()[1:4] == ["spinning", "16", "-15.00..+15.00"]
    assert "1,536" in rows["flash96x16"] and "0.1-35" in rows["flash96x16"]
    assert main(["sensors", "list"]) == 0 and capsys.readouterr().out.splitlines() == lines


def test_cli_show_prints_fields_and_summary_and_saves_rays(tmp_path, capsys):
    path = tmp_path / "os1.npy"
    assert main(["sensors", "show", "os1_64", "--rays", str(path)]) == 0
    out = capsys.readouterr().out
    shown = yaml.safe_load(out[: out.index("rays:")])
    assert shown["fields"]["preset"] == "os1_64" and shown["fields"]["columns"] == 1024
    assert shown["summary"]["rays_per_frame"] == 65536 and shown["summary"]["range_m"] == [0.5, 120.0]
    rays = np.load(path)
    assert rays.shape == (65536, 3) and rays.dtype == np.float32
    np.testing.assert_array_equal(rays, sensor_pattern(preset("os1_64")).directions.astype(np.float32))
    assert not list(tmp_path.glob("*.tmp"))


def test_cli_unknown_preset_exits_2_naming_the_allowed_ones(capsys):
    assert main(["sensors", "show", "hdl999"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "hdl999" in err and all(name in err for name in presets())


def test_cli_unwritable_rays_file_exits_2(tmp_path, capsys):
    assert main(["sensors", "show", "vlp16", "--rays", str(tmp_path / "missing" / "r.npy")]) == 2
    assert "--rays" in capsys.readouterr().err


# ----------------------------------------------------------------------------- HDL-32E against a real sweep
def test_hdl32e_preset_matches_a_real_nuscenes_sweep(real_scan):
    """Per-ring elevations and the azimuth step of the preset against one nuScenes LIDAR_TOP sweep.

    nuScenes frames are x right, y forward, z up: a rotation about z away from ours, which
    leaves elevations and azimuth steps unchanged. The sweep is ego-motion compensated: every
    return was moved to the sensor pose at the sweep's end, so near returns (the lower rings
    hit the road 3-6 m away) are off by up to 2 deg, and plain per-ring medians miss the lowest
    rings by 0.2 deg. The empty returns show where the sensor was: a zero range moved by that
    compensation lands on the sensor's own position at firing time, a line from about 0.45 m
    behind the origin (start of the sweep) to the origin (its end). Measuring from that position
    undoes the compensation.
    """
    data = np.fromfile(real_scan("nuscenes_hdl32e_sweep.bin"), np.float32).reshape(-1, 5).astype(np.float64)
    xyz, ring = data[:, :3], data[:, 4].astype(int)
    rings, columns = 32, len(data) // 32
    assert columns == 1084 and columns * rings == len(data)
    assert (ring == np.tile(np.arange(rings), columns)).all()  # column-major, ring 0..31 in each column
    column = np.arange(len(data)) // rings
    empty = np.linalg.norm(xyz, axis=1) < 0.5
    assert 5000 < empty.sum() < 5400

    left = 1.0 - column / (columns - 1)  # fraction of the sweep still to come when the column fired
    start = np.median(xyz[empty & (left > 0.05)] / left[empty & (left > 0.05), None], axis=0)
    assert 0.3 < np.linalg.norm(start) < 0.6  # about 9 m/s over the 50 ms sweep
    rel = xyz - start * left[:, None]
    el = np.degrees(np.arctan2(rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])))
    measured = np.array([np.median(el[~empty & (ring == k)]) for k in range(rings)])

    spec = preset("hdl32e")
    pattern = sensor_pattern(spec)
    preset_el = elevation_deg(pattern.directions[:rings])
    assert (pattern.ring[:rings] == np.arange(rings)).all() and (np.diff(measured) > 0).all()  # same ring order
    np.testing.assert_allclose(preset_el, measured, atol=0.05)

    slopes = []
    for k in range(rings):
        keep = ~empty & (ring == k)
        az = np.unwrap(np.arctan2(rel[keep, 1], rel[keep, 0]))
        slopes.append(np.polyfit(column[keep], np.degrees(az), 1)[0])
    measured_step = float(np.median(slopes))
    assert measured_step < 0  # clockwise from above, as the preset spins
    assert abs(measured_step) == pytest.approx(360 / 1084, rel=0.01)
    assert len(azimuths(spec)) == columns
    assert spec.horizontal_resolution_deg == pytest.approx(abs(measured_step), rel=0.01)
    assert np.diff(np.unwrap(np.radians(azimuth_deg(pattern.directions[::rings])))).max() < 0


def test_the_thesis_table_4_3_example_resolves_to_its_numbers():
    """examples/railway/thesis_table_4_3.yaml: the preset at the thesis's sampling factor 1.5 and 0.1 mm noise."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "railway" / "thesis_table_4_3.yaml"
    config = config_from_dict(yaml.safe_load(path.read_text()))
    assert config.sensor.spec.sampling_factor == 1.5 and ray_count(config.sensor.spec) == 10800 * 4801 == 51_850_800
    assert config.effects.noise.model == "constant" and config.effects.noise.sigma == pytest.approx(1e-4)
    assert preset_effects("railway_tls")["noise"]["sigma"] == pytest.approx(0.002)  # the preset keeps table 4.3's ACCURACY
