"""benchmarks/bench_rangenet.py's ``mixed`` part: which frames the model trained with one real frame learns from
and is tested on, and how often it draws the real frame."""

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("scipy", reason="evaluate needs the evaluate extra (pip install '.[evaluate]')")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from bench_rangenet import mixed_test, mixed_training

from bpy_pipeline.evaluate.labelled import LabelledScan


def _scan(name, group):
    return LabelledScan(name, group, np.zeros((1, 3)), [0], [-1], ("car",))


def test_the_real_frame_is_a_quarter_of_the_draws_and_the_test_leaves_its_group_out():
    synthetic = [_scan(f"s{k}", "street") for k in range(72)]
    real = [_scan("seq08_000720", "seq08"), _scan("spvnas_000000", "spvnas"), _scan("kitti_000001", "kitti_000001"),
            _scan("drive_10", "drive"), _scan("drive_30", "drive")]
    train = mixed_training(synthetic, real[0])
    assert len(train) == 96 and train[:72] == synthetic and all(s is real[0] for s in train[72:])  # 24 of 96 draws
    assert [real[i].name for i in mixed_test(real, real[0])] == ["spvnas_000000", "kitti_000001", "drive_10", "drive_30"]
    assert [real[i].name for i in mixed_test(real, real[3])] == ["seq08_000720", "spvnas_000000", "kitti_000001"]  # its whole drive out
    assert len(mixed_training(synthetic[:2], real[0], 0.25)) == 3  # at least once
