"""Wires over a span: the thesis's sag law, sampling and dropper rule; the exact catenary against the parabola."""

import math

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.builders.railway import catenary
from bpy_pipeline.geometry.lod import SensorView, equal_perimeter_radius, polygon_sides


def test_sag_law():
    assert catenary.sag_for_span(50, 0.5, 50, 2) == pytest.approx(0.5)
    assert catenary.sag_for_span(65, 0.5, 50, 2) == pytest.approx(0.5 * 1.3**2)
    assert catenary.sag_for_span(40, 0.5, 50, 1.5) == pytest.approx(0.5 * 0.8**1.5)
    assert catenary.sag_for_span(40, 0.5, 0.0, 2) == 0.5  # no reference length: the reference sag


def test_parabola_between_attachment_points():
    a, b = np.array([10.0, 2.0, 6.0]), np.array([58.0, -4.0, 7.0])
    points = catenary.parabolic_sag(a, b, 0.4, 101)
    np.testing.assert_allclose(points[[0, -1]], [a, b])
    assert (a[2] + b[2]) / 2 - points[50, 2] == pytest.approx(0.4)
    t = np.linspace(0, 1, 101)
    np.testing.assert_allclose(points[:, 2], a[2] + t * (b[2] - a[2]) - 4 * 0.4 * t * (1 - t))


def test_zero_length_span_is_a_clear_error():
    with pytest.raises(InputError, match="zero-length span"):
        catenary.parabolic_sag([1, 2, 3], [1, 2, 3], 0.1, 10)
    with pytest.raises(InputError, match="zero-length span"):  # vertical: the ends share x and y
        catenary.catenary_with_sag([1, 2, 3], [1, 2, 9], 0.1, 10)
    with pytest.raises(InputError, match="three samples"):
        catenary.parabolic_sag([0, 0, 0], [10, 0, 0], 0.1, 2)


def test_thesis_sample_count():
    assert catenary.thesis_sample_count(5.0, 1) == 3  # at least three points
    assert catenary.thesis_sample_count(5.0, 4) == 8  # short spans count as 20 m
    assert catenary.thesis_sample_count(50.0, 20) == 100
    assert catenary.thesis_sample_count(65.0, 3) == 19


@pytest.mark.parametrize("sag", [0.05, 0.5, 1.2])
@pytest.mark.parametrize("tolerance", [0.02, 0.003])
def test_samples_for_tolerance_are_the_fewest_that_keep_it(sag, tolerance):
    span = 55.0
    dense = catenary.parabolic_sag([0, 0, 0], [span, 0, 0], sag, 20001)

    def error(samples):
        coarse = catenary.parabolic_sag([0, 0, 0], [span, 0, 0], sag, samples)
        return np.abs(np.interp(dense[:, 0], coarse[:, 0], coarse[:, 2]) - dense[:, 2]).max()

    n = catenary.samples_for_tolerance(sag, tolerance)
    assert error(n) <= tolerance * (1 + 1e-6)
    assert error(n) == pytest.approx(catenary.chord_error(span, sag, n), rel=1e-3)
    if n > 3:
        assert error(n - 1) > tolerance


def test_dropper_rule():
    for span, spacing in ((50.0, 5.0), (47.3, 6.0), (4.0, 5.0), (65.0, 9.0)):
        assert catenary.dropper_count(span, spacing) == max(1, math.floor(span / spacing))
    rng = np.random.default_rng(1)
    t = catenary.dropper_positions(50.0, 5.0, 0.5, rng)
    assert len(t) == 10 and (np.diff(t) > 0).all() and (t > 0).all() and (t < 1).all()
    np.testing.assert_array_less(np.abs(t - np.arange(1, 11) / 11), 0.5 / 50 + 1e-12)  # jitter within +-0.5 m
    a = catenary.dropper_positions(50.0, 5.0, 0.0, rng, -0.25)
    b = catenary.dropper_positions(50.0, 5.0, 0.0, rng, 0.25)
    merged = np.sort(np.concatenate([a, b]))
    assert (merged[0::2] == a).all() and (merged[1::2] == b).all()  # the two wires' droppers alternate
    np.testing.assert_allclose(b - a, 0.5 / 11)  # half a step apart


def test_exact_catenary():
    a = catenary.catenary_parameter(50.0, 0.5)
    assert a * (math.cosh(25.0 / a) - 1) == pytest.approx(0.5, rel=1e-12)
    assert a == pytest.approx(50.0**2 / (8 * 0.5), rel=1e-3)  # close to the parabola's H / w
    start, end = np.array([0.0, 0.0, 7.0]), np.array([60.0, 20.0, 9.0])
    points = catenary.catenary_points(start, end, 400.0, 201)
    np.testing.assert_allclose(points[[0, -1]], [start, end], atol=1e-9)
    hanging = catenary.catenary_with_sag(start, end, 0.8, 201)
    assert (start[2] + end[2]) / 2 - hanging[100, 2] == pytest.approx(0.8, abs=1e-9)
    x = np.linalg.norm(points[:, :2] - start[:2], axis=1)
    slope = np.gradient(points[:, 2], x)
    curvature = np.gradient(slope, x) / (1 + slope**2) ** 1.5
    lowest = np.argmin(points[:, 2])
    assert 0 < lowest < 200 and curvature[lowest] == pytest.approx(1 / 400.0, rel=1e-3)  # a catenary bends by 1 / a at its vertex


@pytest.mark.parametrize("span,sag", [(50.0, 0.5), (65.0, 1.0), (200.0, 6.0), (100.0, 10.0)])
def test_parabola_error_against_the_catenary(span, sag):
    error = catenary.parabola_error(span, sag)
    assert error == pytest.approx(sag**3 / (3 * span**2), rel=0.05)


def test_lod_helpers():
    view = SensorView(np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]]), math.radians(0.1), 150.0)
    assert view.spacing(10.0) == pytest.approx(10 * math.radians(0.1))
    np.testing.assert_allclose(view.distance([[3.0, 4.0, 0.0], [90.0, 0.0, 0.0]]), [5.0, 10.0])
    np.testing.assert_allclose(view.segment_distance([[-5.0, 3.0, 0.0]], [[5.0, 3.0, 0.0]]), [3.0])
    assert view.resolve_radius(0.045) == pytest.approx(0.045 / (2 * math.radians(0.1)))
    for radius, tolerance in ((0.006, 0.001), (0.006, 0.0001), (0.1, 0.001)):
        n = polygon_sides(radius, tolerance)
        assert radius * (1 - math.cos(math.pi / n)) <= tolerance
    assert polygon_sides(0.006, 0.01) == 4


@pytest.mark.parametrize("sides", [4, 6, 8])
def test_polygonal_wires_keep_their_mean_width(sides):
    r = equal_perimeter_radius(0.006, sides)
    corners = r * np.column_stack([np.cos(np.arange(sides) * 2 * np.pi / sides), np.sin(np.arange(sides) * 2 * np.pi / sides)])
    directions = np.linspace(0, np.pi, 3601)[:-1]
    normals = np.column_stack([np.cos(directions), np.sin(directions)])
    widths = np.ptp(corners @ normals.T, axis=0)  # the shadow the section casts across each viewing direction
    assert widths.mean() == pytest.approx(0.012, rel=1e-4)  # beams meet it as often as the 12 mm round wire
