"""The insertion-based comparison of benchmarks/bench_materials.py (``--insertion``) on one KITTI car: the real car is
cut out of the real scan and a synthetic one cast in at its label box by the real firings, real returns in front of
it still hiding it; its count against the real one, and glossy paint against diffuse. (That a glossy car loses
returns at oblique incidence while a matte one does not is tests/test_materials.py and test_materials_objects.py.)"""

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bench_materials

    return bench_materials


@pytest.fixture
def car_3(real_scan, bench):
    """KITTI 000008's car 3 (14.8 m, occlusion level 1) alone, as the benchmark sets it up."""
    path = real_scan("kitti_hdl64e_000008_frontfov.bin")
    real_scan("kitti_000008_boxes.json")
    from bench_realism import image_slopes, kitti_boxes

    box = kitti_boxes()[3]
    frame = bench.Frame("000008", np.fromfile(path, np.float32).reshape(-1, 4), [box], image_slopes)
    return bench.Insertion("000008 car 3", path, [box], image_slopes, frame.window)


def test_the_real_car_is_cut_and_the_synthetic_one_cast_behind_the_real_returns(car_3, bench):
    from bpy_pipeline.mixing import mix_frame
    from bpy_pipeline.mixing.ground import in_box

    box = car_3.boxes[0]
    assert abs(car_3.real_counts[0] - 659) <= 0.08 * 659  # the label's own count: the box is where the car is
    frame = mix_frame(car_3.section, np.random.default_rng(0))
    xyz = np.column_stack([frame.points["x"], frame.points["y"], frame.points["z"]]).astype(np.float64)
    cut = car_3.section.remove[0]
    assert not in_box(xyz[~frame.inserted], cut.center, cut.size, cut.yaw_deg).any()  # no real return left in the cut
    assert bench.in_box(xyz[frame.inserted], box, 0.05).all()  # the synthetic car fills its label box, nothing outside it
    firings = frame.firings
    assert len(np.unique(frame.firing)) == len(frame.firing)  # one return per firing
    f = frame.firing[frame.inserted]
    real_there = firings.valid[f] & ~in_box(firings.returns[f], cut.center, cut.size, cut.yaw_deg)
    assert (frame.points["range"][frame.inserted][real_there] < firings.range[f][real_there]).all()  # a real return in front wins
    assert frame.inserted.sum() > 300


def test_counts_against_the_real_car_and_glossy_paint_against_diffuse(car_3, bench):
    diffuse = car_3.score({}, seeds=(0,))
    glossy = car_3.score(bench.glossy(0.03, 0.6, 8.0), seeds=(0,))
    # on firings that returned in the real scan the synthetic car is within the target band; the recovered lattice's
    # empty firings add more (real drops and lattice gaps alike), never fewer
    assert 0.7 <= diffuse["on real-returned firings only"][0] <= 1.4, diffuse
    assert diffuse["sim/real per car"][0] >= diffuse["on real-returned firings only"][0]
    assert glossy["sim/real per car"][0] < diffuse["sim/real per car"][0]  # 15 m, oblique sides: the coat sends some beams away
    assert glossy["sim zero share"] > diffuse["sim zero share"]
    assert glossy["overlap"] > diffuse["overlap"]  # dark paint reads nearer KITTI's mostly-dark car returns
