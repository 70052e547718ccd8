"""A hypothesis fuzzer over config trees and file headers, bounded to a minute in all (460 examples: about 6 s on a quiet machine).

Every input must end as a valid result or as one ``InputError`` line (the CLI's exit code 2): never
another exception (a traceback), and never a result that disagrees with what the file claims
(a silent wrong result). Config trees are the resolved defaults of each builder with a few leaves
replaced, removed or added; files are headers drawn field by field with data of any length.
"""

from __future__ import annotations

import collections
import copy
import os
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from bpy_pipeline.errors import InputError  # noqa: E402

FUZZ = settings(deadline=None, derandomize=True, suppress_health_check=list(HealthCheck), database=None)
OUTCOMES: collections.Counter = collections.Counter()  # examples by outcome (benchmarks/bench_hardening.py reports them)
BASES = [{}, {"scene": {"builder": "parking"}}, {"scene": {"builder": "industrial_hall"}}, {"scene": {"builder": "primitives"}},
         {"scene": {"builder": "street"}}]


def one_line(err: InputError) -> None:
    assert "\n" not in str(err) and str(err).strip() and err.exit_code == 2, str(err)
    OUTCOMES["refused in one line"] += 1


def valid() -> None:
    OUTCOMES["valid"] += 1


# ----------------------------------------------------------------------------- config trees
_TREES: list = []


def trees() -> list:
    """The resolved config of each base, as plain data (made once)."""
    if not _TREES:
        from bpy_pipeline.config import config_to_dict, load_config

        _TREES.extend(config_to_dict(load_config(copy.deepcopy(b))) for b in BASES)
    return _TREES


def paths(tree, prefix=()) -> list[tuple]:
    out = [prefix] if prefix else []
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += paths(v, prefix + (k,))
    elif isinstance(tree, list):
        for i, v in enumerate(tree[:4]):
            out += paths(v, prefix + (i,))
    return out


scalars = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-(2**70), max_value=2**70), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8), st.sampled_from(["railway", "parking", "vlp16", "ply", "auto", "1e9", "nan", "-1", "", "none"]),
)
values = st.one_of(scalars, st.lists(scalars, max_size=4), st.dictionaries(st.text(max_size=6), scalars, max_size=3))


@st.composite
def mutated_trees(draw):
    tree = copy.deepcopy(trees()[draw(st.sampled_from(range(len(BASES))))])
    for _ in range(draw(st.integers(1, 4))):
        where = draw(st.sampled_from(paths(tree)))
        node = tree
        for key in where[:-1]:
            node = node[key]
        action = draw(st.sampled_from(["set", "set", "delete", "add"]))
        if action == "set":
            node[where[-1]] = draw(values)
        elif action == "delete" and isinstance(node, dict):
            node.pop(where[-1], None)
        elif isinstance(node, dict):
            node[draw(st.text(min_size=1, max_size=6))] = draw(values)
    return tree


@settings(FUZZ, max_examples=60)
@given(mutated_trees())
def test_config_trees_load_or_refuse_in_one_line(tree):
    from bpy_pipeline.config import load_config
    from bpy_pipeline.estimate import check_limits, estimate_run

    try:
        config = load_config(tree)
        check_limits(estimate_run(config), config)
    except InputError as err:
        one_line(err)
        return
    valid()


# ----------------------------------------------------------------------------- file headers
def temp_file(data: bytes, suffix: str) -> Path:
    handle, name = tempfile.mkstemp(suffix=suffix)
    with os.fdopen(handle, "wb") as f:
        f.write(data)
    return Path(name)


counts = st.one_of(st.integers(-3, 40), st.integers(0, 10**13), st.sampled_from(["x", "", "1e9", "-0"]))


@settings(FUZZ, max_examples=100)
@given(
    fields=st.lists(st.sampled_from(["x", "y", "z", "intensity", "ring", "rgb"]), min_size=0, max_size=5),
    sizes=st.lists(st.sampled_from(["1", "2", "4", "8", "3", "x"]), max_size=5),
    types=st.lists(st.sampled_from(["F", "I", "U", "f", "Q"]), max_size=5),
    count_field=st.lists(st.sampled_from(["1", "2", "0", "-1"]), max_size=5),
    width=counts, height=counts, points=counts,
    kind=st.sampled_from(["binary", "ascii", "binary_compressed", "ASCII"]),
    payload=st.binary(max_size=400),
)
def test_pcd_headers_read_whole_or_refuse(fields, sizes, types, count_field, width, height, points, kind, payload):
    from bpy_pipeline.io.pcd import read_pcd_fields

    lines = ["FIELDS " + " ".join(fields), "SIZE " + " ".join(sizes), "TYPE " + " ".join(types), "COUNT " + " ".join(count_field),
             f"WIDTH {width}", f"HEIGHT {height}", f"POINTS {points}", f"DATA {kind}"]
    path = temp_file(("\n".join(lines) + "\n").encode() + payload, ".pcd")
    try:
        data = read_pcd_fields(path)
    except InputError as err:
        one_line(err)
        return
    finally:
        path.unlink()
    assert {len(v) for v in data.values()} == {int(points)}, "every field holds the POINTS the header claims"
    valid()


@settings(FUZZ, max_examples=100)
@given(
    fmt=st.sampled_from(["binary_little_endian", "binary_big_endian", "ascii", "binary"]),
    elements=st.lists(st.tuples(st.sampled_from(["vertex", "face", "extra"]), counts,
                                st.lists(st.sampled_from(["float x", "float y", "float z", "uchar intensity", "list uchar int vertex_indices", "double time",
                                                          "bogus t"]), max_size=4)), max_size=3),
    payload=st.binary(max_size=300),
)
def test_ply_headers_read_whole_or_refuse(fmt, elements, payload):
    from bpy_pipeline.io.ply import read_ply

    head = ["ply", f"format {fmt} 1.0"]
    for name, count, props in elements:
        head += [f"element {name} {count}"] + [f"property {p}" for p in props]
    path = temp_file(("\n".join(head + ["end_header"]) + "\n").encode() + payload, ".ply")
    try:
        cloud = read_ply(path)
    except InputError as err:
        one_line(err)
        return
    finally:
        path.unlink()
    vertex = next(e for e in elements if e[0] == "vertex")
    assert len(cloud) == int(vertex[1])
    valid()


@settings(FUZZ, max_examples=60)
@given(fmt=st.sampled_from(["kitti", "nuscenes", "semantickitti"]), payload=st.binary(max_size=400), floats=st.lists(st.floats(width=32), max_size=60))
def test_scan_bins_read_whole_or_refuse(fmt, payload, floats):
    from bpy_pipeline.io.real_scans import read_real_scan

    data = np.array(floats, np.float32).tobytes() + payload
    path = temp_file(data, ".bin")
    try:
        scan = read_real_scan(path, fmt)
    except InputError as err:
        one_line(err)
        return
    finally:
        path.unlink()
    fields = 5 if fmt == "nuscenes" else 4
    assert len(data) % (4 * fields) == 0 and len(scan) <= len(data) // (4 * fields)
    assert np.isfinite(scan.points).all() and np.isfinite(scan.intensity).all()
    valid()


obj_lines = st.one_of(
    st.builds(lambda v: "v " + " ".join(v), st.lists(st.sampled_from(["0", "1", "-2.5", "nan", "inf", "x", "1e400"]), max_size=4)),
    st.builds(lambda f: "f " + " ".join(f), st.lists(st.sampled_from(["1", "2", "3", "-1", "0", "99", "2/2", "3//3", "a"]), max_size=5)),
    st.sampled_from(["# comment", "", "vn 0 0 1", "o thing", "g", "s off"]),
)


@settings(FUZZ, max_examples=80)
@given(st.lists(obj_lines, max_size=12))
def test_obj_meshes_fit_or_refuse(lines):
    from bpy_pipeline.mixing.cast import mesh_file_parts

    path = temp_file("\n".join(lines).encode(), ".obj")
    try:
        parts = mesh_file_parts(str(path), (2.0, 1.0, 1.5))
    except InputError as err:
        one_line(err)
        return
    finally:
        path.unlink()
    for part in parts:
        assert np.isfinite(part.vertices).all() and part.triangles.min() >= 0 and part.triangles.max() < len(part.vertices)
    valid()


def las_file(n_claimed: int, n_records: int, version: int, point_format: int, record: int, offset: int, vlrs: int) -> bytes:
    header = bytearray(375)
    header[0:4] = b"LASF"
    header[24:26] = bytes([1, version])
    struct.pack_into("<H", header, 94, 375 if version == 4 else 227)
    struct.pack_into("<I", header, 96, offset)
    struct.pack_into("<I", header, 100, vlrs)
    header[104] = point_format
    struct.pack_into("<H", header, 105, record)
    struct.pack_into("<I", header, 107, min(n_claimed, 2**32 - 1))
    struct.pack_into("<3d", header, 131, 0.01, 0.01, 0.01)
    struct.pack_into("<Q", header, 247, n_claimed)
    return bytes(header) + bytes(max(record, 1) * n_records)


@settings(FUZZ, max_examples=60)
@given(
    n_claimed=st.integers(0, 2**40), n_records=st.integers(0, 30), version=st.sampled_from([2, 4]), point_format=st.sampled_from([0, 6, 99]),
    record=st.integers(0, 64), offset=st.integers(0, 600), vlrs=st.integers(0, 2**32 - 1),
)
def test_las_headers_read_whole_or_refuse(n_claimed, n_records, version, point_format, record, offset, vlrs):
    from bpy_pipeline.io.las import read_las
    from bpy_pipeline.io.real_scans import read_real_scan

    path = temp_file(las_file(n_claimed, n_records, version, point_format, record, offset, vlrs), ".las")
    try:
        for reader in (read_las, read_real_scan):
            try:
                cloud = reader(path)
            except InputError as err:
                one_line(err)
                continue
            assert len(cloud) == n_claimed, "a LAS file read whole holds the points its header claims"
            valid()
    finally:
        path.unlink()
