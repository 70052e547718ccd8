"""The boxes' visible counts per instance (``visibility.counts_per_instance``): the table of every id's count and the
search among the boxes' ids give the same counts, ids beyond the table included."""

import numpy as np

from bpy_pipeline.lidar.cast import visibility


def test_table_and_search_give_the_same_counts(monkeypatch):
    rng = np.random.default_rng(1)
    for _ in range(100):
        values = rng.integers(0, rng.integers(1, 3000), rng.integers(0, 5000)).astype(np.int64)
        boxes = rng.choice(4000, rng.integers(1, 80), replace=False).astype(np.uint32)
        table = visibility.counts_per_instance(boxes, values)
        with monkeypatch.context() as m:
            m.setattr(visibility, "COUNTED_IDS", 0)
            searched = visibility.counts_per_instance(boxes, values)
        assert table.dtype == searched.dtype == np.int64 and np.array_equal(table, searched)
    huge = np.array([visibility.COUNTED_IDS + 5, 3, visibility.COUNTED_IDS + 5], np.int64)
    np.testing.assert_array_equal(visibility.counts_per_instance(np.array([visibility.COUNTED_IDS + 5, 3, 9]), huge), [2, 1, 0])
