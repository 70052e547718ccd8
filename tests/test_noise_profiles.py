"""Named noise profiles (scene.noise: parking_paper_best) reproduce the parking paper's rates; its near rejection in real-scan insertion."""

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry.placement import Distribution
from bpy_pipeline.mixing import NoiseInjections, ParkingRule, RealScanScene, mix_frame
from bpy_pipeline.mixing import noise as injections
from bpy_pipeline.mixing.section import NOISE_PROFILES

BEST = NOISE_PROFILES["parking_paper_best"]
OBJECTS, POINTS = 3000, 300  # objects of the draw, points each


def test_the_profile_is_table_2s_best_row_by_name():
    config = load_config(None, ["scene.builder=real_scan", "scene.path=scan.bin", "scene.noise=parking_paper_best"])
    assert config.scene.params.noise == BEST
    # dropout, per-object range noise, interior points and the cut-off; no class flips (Table 2: they cost 0.4 IoU)
    assert (BEST.dropout_max, BEST.range_sigma, BEST.interior_points, BEST.cutoff_probability, BEST.cutoff_fraction,
            BEST.class_flip) == (0.003, (0.001, 0.03), 15, 0.6, (0.2, 0.8), 0.0)
    assert NOISE_PROFILES["parking_paper_all"].class_flip == 0.02 and NOISE_PROFILES["none"] == NoiseInjections()
    mapping = load_config(None, ["scene.builder=real_scan", "scene.path=scan.bin", "scene.noise={dropout_max: 0.001}"])
    assert mapping.scene.params.noise.dropout_max == 0.001  # a mapping still works
    with pytest.raises(InputError, match=r"^scene\.noise: 'parking_best' is not a noise profile; give a mapping or one of none, parking_paper_best"):
        load_config(None, ["scene.builder=real_scan", "scene.path=scan.bin", "scene.noise=parking_best"])


def test_the_profile_reproduces_the_papers_rates():
    rng = np.random.default_rng(0)
    objects = np.arange(1, OBJECTS + 1)
    instance = np.repeat(objects, POINTS)
    # dropout: per object a probability from U(0, 0.3 %): 0.15 % of the points overall, no object above 0.3 % by much
    kept = injections.object_dropout(instance, objects, BEST, rng)
    assert 0.0013 < 1 - kept.mean() < 0.0017
    # per-object range noise: each object's sigma within 1..30 mm, spread uniformly (mean 15.5 mm)
    step = injections.object_range_noise(instance, objects, BEST, rng).reshape(OBJECTS, POINTS)
    sigma = step.std(axis=1)
    assert 0.0008 < sigma.min() and sigma.max() < 0.034 and abs(sigma.mean() - 0.0155) < 0.0008
    # interior points: 0..15 per object, 7.5 on average, at |N(0.3, 0.5)| m from its centre
    centres = rng.uniform(-20, 20, (OBJECTS, 3))
    pts, owner = injections.interior_points(centres, BEST, rng)
    counts = np.bincount(owner, minlength=OBJECTS)
    assert counts.min() == 0 and counts.max() == 15 and abs(counts.mean() - 7.5) < 0.2
    radius = np.linalg.norm(pts - centres[owner], axis=1)
    assert abs(np.mean(radius) - 0.469) < 0.015  # E|N(0.3, 0.5)| = 0.469 m
    # the cut-off: 60 % of the objects cut, each losing 20 .. 80 % of its points
    xyz = rng.normal(size=(len(instance), 3))
    kept = injections.vertical_cutoff(xyz, instance, objects, BEST, rng).reshape(OBJECTS, POINTS)
    lost = 1 - kept.mean(axis=1)
    cut = lost > 0
    assert abs(cut.mean() - 0.6) < 0.03 and lost[cut].min() >= 0.2 - 1 / POINTS and lost[cut].max() <= 0.8 + 1 / POINTS
    # class flips: none in the best row; 2 % in parking_paper_all
    semantic = rng.integers(0, 4, len(instance)).astype(np.uint16)
    classes = np.arange(4, dtype=np.uint16)
    assert (injections.class_flips(semantic, classes, BEST, rng) == semantic).all()
    flipped = injections.class_flips(semantic, classes, NOISE_PROFILES["parking_paper_all"], rng) != semantic
    assert abs(flipped.mean() - 0.02) < 0.001


def rule_run(path, probability, seed=0):
    """Cars drawn only under 5 m (2.5 .. 4.9 m), one rotation each, until 400 in a row fail: the placement log."""
    rule = ParkingRule(enabled=True, count=Distribution("normal", 1000.0, 0.0, 1000.0, 1000.0), distance=Distribution("uniform", 3.7, 0.0, 2.5, 4.9),
                       rotations=1, max_consecutive_failures=400, near_rejection_probability=probability)
    return mix_frame(RealScanScene(path=str(path), parking_rule=rule), np.random.default_rng(seed)).info


def test_real_scan_insertion_rejects_a_tenth_of_the_cars_under_5_m(real_scan):
    path = real_scan("nuscenes_hdl32e_sweep.bin")
    assert ParkingRule().near_rejection_probability == 0.1 and ParkingRule().near_rejection_distance == 5.0  # the paper's, on by default
    log = rule_run(path, 0.1)
    parking = next(v for k, v in _walk(log) if k == "parking")
    tried, rejected = parking["objects_tried"], parking["near_rejections"]
    assert tried >= 400 and abs(rejected / tried - 0.1) < 0.04
    none = next(v for k, v in _walk(rule_run(path, 0.0)) if k == "parking")
    assert none["near_rejections"] == 0
    every = next(v for k, v in _walk(rule_run(path, 1.0)) if k == "parking")
    assert every["near_rejections"] == every["objects_tried"] and every["attempts"] == [0] * every["objects_tried"]  # none placed


def _walk(info):
    """(key, value) of every nested mapping of ``info``."""
    stack = [info]
    while stack:
        d = stack.pop()
        if isinstance(d, dict):
            for k, v in d.items():
                yield k, v
                stack.append(v)


def test_bad_near_rejection_is_refused_in_one_line():
    with pytest.raises(InputError, match="near_rejection_probability"):
        load_config(None, ["scene.builder=real_scan", "scene.path=scan.bin", "scene.parking_rule.near_rejection_probability=1.5"])
