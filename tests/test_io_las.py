"""LAS 1.4 point format 6: checked against laspy as the independent reader, PDAL where it is installed, and our own reader."""

import json
import shutil
import subprocess

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import read_las, write_las
from bpy_pipeline.io.class_maps import load_class_maps
from bpy_pipeline.io.las import HEADER_DTYPE, RECORD_DTYPE
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.points import empty_points


def random_points(n, rng, centre=(0.0, 0.0, 0.0), spread=100.0):
    pts = empty_points(n)
    for axis, name in enumerate("xyz"):
        pts[name] = centre[axis] + rng.uniform(-spread, spread, n)
    pts["intensity"] = rng.uniform(0, 1, n)
    pts["intensity"][:2] = [0.0, 1.0]
    pts["semantic"] = rng.integers(0, 256, n)
    pts["instance"] = rng.integers(0, 2**32, n, dtype=np.uint64)
    pts["ring"] = rng.integers(0, 2**16, n)
    pts["time"] = rng.uniform(0, 0.1, n)
    pts["range"] = rng.uniform(0.5, 120, n)
    pts["bounces"] = rng.integers(0, 256, n)
    return pts


def laspy_or_skip():
    return pytest.importorskip("laspy", reason="laspy is the independent LAS reader (pip install laspy)")


@pytest.mark.parametrize("centre", [(0.0, 0.0, 0.0), (1e4, -1e4, 1e4)])
def test_laspy_reads_every_field(tmp_path, centre):
    laspy = laspy_or_skip()
    scale = 0.001
    pts = random_points(1000, np.random.default_rng(0), centre, spread=50.0)
    las = laspy.read(write_las(tmp_path / "c.las", pts, scale=scale))
    assert str(las.header.version) == "1.4" and las.header.point_format.id == 6
    assert las.header.point_count == 1000
    np.testing.assert_array_equal(las.header.scales, [scale] * 3)
    np.testing.assert_array_equal(las.header.offsets, np.floor([pts[a].min() for a in "xyz"]))
    for name in "xyz":
        err = np.abs(np.asarray(las[name], np.float64) - pts[name].astype(np.float64))
        assert err.max() <= scale / 2 + 1e-9, (name, err.max())
    np.testing.assert_array_equal(las.classification, load_class_maps().asprs[pts["semantic"]])
    np.testing.assert_array_equal(las.intensity, np.rint(pts["intensity"].astype(np.float64) * 65535))
    assert las.intensity.min() == 0 and las.intensity.max() == 65535
    np.testing.assert_array_equal(las.gps_time, pts["time"])
    assert (np.asarray(las.return_number) == 1).all() and (np.asarray(las.number_of_returns) == 1).all()
    assert list(las.point_format.extra_dimension_names) == ["semantic", "instance", "ring", "range", "bounces"]
    for name in ("semantic", "instance", "ring", "range", "bounces"):
        assert np.asarray(las[name]).dtype == pts[name].dtype, name
        np.testing.assert_array_equal(las[name], pts[name], err_msg=name)
    for axis, name in enumerate("xyz"):
        assert las.header.mins[axis] == pytest.approx(np.asarray(las[name]).min(), abs=1e-9)
        assert las.header.maxs[axis] == pytest.approx(np.asarray(las[name]).max(), abs=1e-9)


def test_huge_coordinates_keep_millimetres(tmp_path):
    # 10 km from the origin, float32 still resolves about 1 mm; the LAS file must not lose more.
    pts = empty_points(4)
    pts["x"] = np.float32(1e4) + np.float32([0.0, 0.001, 0.002, 12.345])
    pts["y"] = np.float32(-1e4) - np.float32([0.0, 0.001, 0.5, 7.0])
    pts["z"] = [1e4, 1e4, 1e4, 1e4]
    back = read_las(write_las(tmp_path / "c.las", pts))
    for name in "xyz":
        assert np.abs(back[name].astype(np.float64) - pts[name].astype(np.float64)).max() <= 0.0005 + 1e-9, name
    assert len(np.unique(back["x"])) == 4  # one millimetre apart stays apart


def test_own_reader_round_trip_and_layout(tmp_path):
    pts = random_points(300, np.random.default_rng(0))
    path = write_las(tmp_path / "c.las", pts)
    raw = path.read_bytes()
    header = np.frombuffer(raw, HEADER_DTYPE, count=1)[0]
    assert header["header_size"] == 375 and header["point_data_record_length"] == 43 == RECORD_DTYPE.itemsize
    assert header["offset_to_point_data"] == 375 + 54 + 5 * 192 + 54 + 256 * 16
    assert len(raw) == header["offset_to_point_data"] + 300 * 43
    back = read_las(path)
    for name in "xyz":
        assert np.abs(back[name].astype(np.float64) - pts[name]).max() <= 0.0005 + 1e-6, name
    assert np.abs(back["intensity"] - pts["intensity"]).max() <= 0.5 / 65535 + 1e-7
    for name in ("semantic", "time", "instance", "ring", "range", "bounces"):
        np.testing.assert_array_equal(back[name], pts[name], err_msg=name)


def test_empty_cloud(tmp_path):
    path = write_las(tmp_path / "empty.las", empty_points(0))
    assert len(read_las(path)) == 0
    laspy = pytest.importorskip("laspy", reason="laspy is the independent LAS reader (pip install laspy)")
    las = laspy.read(path)
    assert las.header.point_count == 0 and len(las.points) == 0


def test_same_points_same_bytes(tmp_path):
    pts = random_points(50, np.random.default_rng(0))
    assert write_las(tmp_path / "a.las", pts).read_bytes() == write_las(tmp_path / "b.las", pts).read_bytes()


def test_refuses_what_las_cannot_hold(tmp_path):
    pts = random_points(5, np.random.default_rng(0))
    pts["x"][0] = np.nan
    with pytest.raises(InputError, match="non-finite"):
        write_las(tmp_path / "a.las", pts)
    pts["x"][0] = 5e6  # 5,000 km from the offset does not fit int32 millimetres
    with pytest.raises(InputError, match="do not fit"):
        write_las(tmp_path / "a.las", pts, offset=(0, 0, 0))
    assert list(tmp_path.iterdir()) == []
    write_las(tmp_path / "a.las", pts, scale=0.01, offset=(0, 0, 0))  # a coarser scale fits


CLASS = {name: i for i, name in load_class_table().names.items()}


def asprs_sample(n=600):
    """Points of every class of the table, in order, so each classification code occurs."""
    pts = random_points(n, np.random.default_rng(3), spread=20.0)
    pts["semantic"] = np.arange(n) % (max(CLASS.values()) + 1)
    return pts


def test_classification_is_asprs_where_the_meaning_matches(tmp_path):
    laspy = laspy_or_skip()
    las = laspy.read(write_las(tmp_path / "c.las", asprs_sample()))
    code = dict(zip(np.asarray(las.semantic).tolist(), np.asarray(las.classification).tolist()))
    expected = {"unlabeled": 1, "ground": 2, "wall": 6, "building": 6, "rail": 10, "road": 11, "contact wire": 14, "earth wire": 13, "mast": 15,
                "insulator": 16}
    for name, asprs in expected.items():
        assert code[CLASS[name]] == asprs, name
    for name in ("ballast", "pillar", "reflection", "car", "person", "robot arm"):  # no ASPRS meaning: user-definable 64 + raw id
        if name == "pillar":
            continue  # a building part: 6
        assert code[CLASS[name]] == 64 + CLASS[name], name
    assert code[CLASS["pillar"]] == 6
    assert not np.asarray(las.synthetic).any()  # see las.py's docstring for why the flag stays clear


def test_classification_lookup_vlr_names_every_code(tmp_path):
    laspy = laspy_or_skip()
    las = laspy.read(write_las(tmp_path / "c.las", asprs_sample()))
    (vlr,) = [v for v in las.header.vlrs if v.user_id == "LASF_Spec" and v.record_id == 0]
    names = vlr.lookups  # laspy parses the Classification Lookup VLR: {code: description}
    for code in np.unique(np.asarray(las.classification)):
        assert names.get(int(code)), f"code {code} is not named in the lookup VLR"
    assert names[2] == "ground" and names[14] == "wire conductor" and names[64 + CLASS["car"]] == "car"


def test_pdal_reads_the_file(tmp_path):
    pdal = shutil.which("pdal")
    try:
        import pdal as pdal_module
    except ImportError:
        pdal_module = None
    if pdal is None and pdal_module is None:
        pytest.skip(
            "PDAL is not installed (neither the pdal command nor the Python bindings; pip install pdal needs libpdal, which Debian 12 does not package)"
        )
    pts = asprs_sample(200)
    path = write_las(tmp_path / "c.las", pts)
    if pdal_module is not None:
        pipeline = pdal_module.Reader.las(filename=str(path), extra_dims="semantic=uint16,instance=uint32").pipeline()
        pipeline.execute()
        arr = pipeline.arrays[0]
        np.testing.assert_array_equal(arr["semantic"], pts["semantic"])
        np.testing.assert_array_equal(arr["Classification"], load_class_maps().asprs[pts["semantic"]])
    else:
        info = json.loads(subprocess.run([pdal, "info", "--stats", str(path)], capture_output=True, text=True, check=True).stdout)
        names = {s["name"] for s in info["stats"]["statistic"]}
        assert {"semantic", "instance", "Classification"} <= names
