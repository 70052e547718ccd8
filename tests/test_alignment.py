"""Track alignment: the arc through three points, its tangent and lateral axis, and its fallbacks."""

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.builders.railway.alignment import arc_through

CASES = [
    ((0, 0, 0), (50, 10, 0), (100, 0, 0)),  # a left... right-hand curve in plan
    ((-40, 5, 2), (0, -20, 3), (35, 30, 1)),  # a turning, climbing arc
    ((0, 0, 0), (50, 0, 1.5), (100, 0, 0)),  # a crest in a vertical plane
    ((3, -7, 11), (-20, 40, 5), (60, 80, -9)),
]


@pytest.mark.parametrize("points", CASES)
def test_arc_passes_through_its_points_in_order(points):
    a, b, c = (np.array(p, float) for p in points)
    arc = arc_through(a, b, c)
    assert not arc.straight
    for p in (a, b, c):
        assert abs(np.linalg.norm(p - arc.centre) - arc.radius) < 1e-9 * arc.radius
    np.testing.assert_allclose(arc.point([0.0, arc.length]), [a, c], atol=1e-9)
    s_mid = arc.nearest_chainage(b)[0]
    assert 0 < s_mid < arc.length  # the mid point lies between start and end
    np.testing.assert_allclose(arc.point(s_mid)[0], b, atol=1e-9)
    assert arc.length == pytest.approx(arc.radius * arc.sweep)


@pytest.mark.parametrize("points", CASES)
def test_tangent_and_lateral(points):
    arc = arc_through(*points)
    s = np.linspace(0, arc.length, 11)
    t = arc.tangent(s)
    h = 1e-5
    numeric = (arc.point(s + h) - arc.point(s - h)) / (2 * h)
    np.testing.assert_allclose(t, numeric, atol=1e-6)
    np.testing.assert_allclose(np.einsum("ij,ij->i", t, arc.point(s) - arc.centre), 0, atol=1e-8)  # t is perpendicular to r
    lateral = arc.lateral(s)
    np.testing.assert_allclose(np.linalg.norm(lateral, axis=1), 1)
    np.testing.assert_allclose(lateral[:, 2], 0)
    np.testing.assert_allclose(np.einsum("ij,ij->i", lateral, t), 0, atol=1e-12)
    assert (np.cross(t, lateral)[:, 2] > 0).all()  # to the left of travel
    frames = arc.frames(s, 2.0, 1.0)
    np.testing.assert_allclose(frames[:, :3, :3].transpose(0, 2, 1) @ frames[:, :3, :3], np.broadcast_to(np.eye(3), (11, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(frames[:, :3, 3], arc.point(s) + 2.0 * lateral + [0, 0, 1.0])


def test_collinear_points_give_a_straight_track():
    for mid in ((30, 40, 0), (30, 40 + 1e-9, 0), (120, 160, 0)):  # exactly, numerically, and beyond the end
        line = arc_through((0, 0, 0), mid, (60, 80, 0))
        assert line.straight and line.length == pytest.approx(100.0)
        s = np.linspace(0, 100, 5)
        np.testing.assert_allclose(line.point(s), np.outer(s, [0.6, 0.8, 0.0]), atol=1e-12)
        np.testing.assert_allclose(line.lateral(s), np.tile([-0.8, 0.6, 0.0], (5, 1)))
        np.testing.assert_allclose(line.chainage_samples(0.001), [0.0, 100.0])
    assert not arc_through((0, 0, 0), (30, 40.01, 0), (60, 80, 0)).straight  # 1 cm off the line is a curve


def test_coincident_ends_are_a_clear_error():
    with pytest.raises(InputError, match=r"^scene.track: start and end coincide"):
        arc_through((5, 5, 0), (10, 0, 0), (5, 5, 0), "scene.track")
    with pytest.raises(InputError, match="finite"):
        arc_through((0, 0, 0), (np.nan, 0, 0), (5, 5, 0))


def test_vertical_tangent_falls_back_to_a_horizontal_axis():
    arc = arc_through((-10, 0, 0), (0, 0, 10), (10, 0, 0))  # a half circle in the x-z plane: vertical at both ends
    t = arc.tangent([0.0, arc.length])
    np.testing.assert_allclose(np.abs(t[:, 2]), 1, atol=1e-12)
    lateral = arc.lateral([0.0, arc.length / 2, arc.length])
    assert np.isfinite(lateral).all()
    np.testing.assert_allclose(np.abs(lateral[:, 1]), 1)  # the arc's plane normal, +-y
    vertical = arc_through((0, 0, 0), (0, 0, 5), (0, 0, 10))  # a straight vertical line
    np.testing.assert_allclose(vertical.lateral([1.0]), [[0, 1, 0]])


def test_chainage_samples_keep_the_chord_error():
    arc = arc_through((0, 0, 0), (300, 40, 0), (600, 0, 0))
    for tolerance in (0.1, 0.01, 0.001):
        s = arc.chainage_samples(tolerance)
        chords_mid = (arc.point(s[:-1]) + arc.point(s[1:])) / 2
        error = arc.radius - np.linalg.norm(chords_mid - arc.centre, axis=1)
        assert error.max() <= tolerance * (1 + 1e-9)
        assert error.max() > tolerance / 4  # not needlessly fine


def test_transition_curves_keep_the_ends_and_follow_the_clothoid():
    from bpy_pipeline.builders.railway.alignment import arc_through, with_transitions

    arc = arc_through((-150, 0, 0), (0, 19.05, 0), (150, 0, 0))
    curve = with_transitions(arc, 40.0)
    np.testing.assert_allclose(curve.point([0.0, curve.length]), arc.point([0.0, arc.length]), atol=1e-6)
    np.testing.assert_allclose(curve.tangent([0.0, curve.length]), arc.tangent([0.0, arc.length]), atol=1e-9)
    assert curve.radius < arc.radius and curve.length > arc.length
    kappa = curve.curvature([0.0, 10.0, 40.0, curve.length / 2, curve.length - 10.0, curve.length])
    np.testing.assert_allclose(kappa, np.array([0, 0.25, 1, 1, 0.25, 0]) / curve.radius, atol=1e-12)
    # the entry clothoid against its series (A^2 = R L), in the frame of the start tangent
    A2 = curve.radius * 40.0
    s = np.array([10.0, 25.0, 40.0])
    t0 = arc.tangent([0.0])[0][:2]
    n0 = np.array([-t0[1], t0[0]])
    rel = curve.point(s)[:, :2] - curve.start[:2]
    x, y = rel @ t0, rel @ n0
    np.testing.assert_allclose(x, s - s**5 / (40 * A2**2) + s**9 / (3456 * A2**4), atol=1e-4)
    np.testing.assert_allclose(np.abs(y), s**3 / (6 * A2) - s**7 / (336 * A2**3), atol=1e-4)
    probe = curve.offset([5.0, 150.0, 290.0], [2.0, -3.0, 1.0])
    np.testing.assert_allclose(curve.nearest_chainage(probe), [5.0, 150.0, 290.0], atol=1e-3)
    assert with_transitions(arc, 0.0) is arc


def test_transition_curves_refuse_what_cannot_hold_them():
    from bpy_pipeline.builders.railway.alignment import arc_through, with_transitions

    with pytest.raises(InputError, match="transition_length"):
        with_transitions(arc_through((-150, 0, 0), (0, 19.05, 0), (150, 0, 0)), 200.0, "scene.track")
    with pytest.raises(InputError, match="level curve"):
        with_transitions(arc_through((-150, 0, 0), (0, 19.05, 5), (150, 0, 0)), 20.0, "scene.track")
