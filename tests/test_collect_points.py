"""pipeline.collect_points copies records as raw bytes: the same bytes as numpy's concatenation, any part sizes."""

import numpy as np

from bpy_pipeline.lidar.points import POINT_DTYPE
from bpy_pipeline.stages.scan import collect_points


def records(k: int, rng) -> np.ndarray:
    out = np.zeros(k, POINT_DTYPE)
    for name in POINT_DTYPE.names:
        out[name] = rng.random(k) * 100
    return out


def test_parts_joined_byte_for_byte_through_growth():
    rng = np.random.default_rng(3)
    parts = [records(k, rng) for k in (5, 0, 7, 300, 1)]
    assert collect_points(iter(parts), 4).tobytes() == np.concatenate(parts).tobytes()  # reserve of 4 grown twice


def test_strided_and_other_layout_parts():
    rng = np.random.default_rng(4)
    strided = records(50, rng)[::3]
    aligned = np.dtype([(name, POINT_DTYPE.fields[name][0]) for name in POINT_DTYPE.names], align=True)  # same fields, padded
    other = records(6, rng).astype(aligned)
    assert aligned != POINT_DTYPE
    joined = collect_points(iter([strided, other]), 100)
    assert joined[: len(strided)].tobytes() == strided.copy().tobytes()
    for name in POINT_DTYPE.names:
        assert np.array_equal(joined[name][len(strided) :], other[name])
