import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.kinematics import arc_points, arc_step, scale_action, wrap_angle

L = 20.0
angle = st.floats(-np.pi, np.pi)
turn = st.floats(-np.pi / 4, np.pi / 4)


@given(h=angle, a=turn)
def test_arc_end_matches_circle_geometry(h, a):
    end, h_end = arc_step(np.zeros(2), np.array(h), np.array(a), L)
    tol = 1e-6
    if abs(a) > 1e-3:
        r = L / a  # signed radius; centre to the left for a > 0
        centre = r * np.array([-np.sin(h), np.cos(h)])
        expected = centre + r * np.array([np.sin(h + a), -np.cos(h + a)])
    else:
        expected = L * np.array([np.cos(h), np.sin(h)])
        tol += L * abs(a)  # the chord leaves the straight line by at most L·|a|/2
    np.testing.assert_allclose(end, expected, atol=tol)
    assert np.cos(h_end - (h + a)) == pytest.approx(1.0)


@given(h=angle, a=turn)
def test_samples_lie_at_equal_arc_length(h, a):
    pts = arc_points(np.array([5.0, -3.0]), np.array(h), np.array(a), L, np.linspace(0, 1, 401))
    seg = np.hypot(*np.diff(pts, axis=0).T)
    assert seg.sum() == pytest.approx(L, rel=1e-5)
    np.testing.assert_allclose(seg, L / 400, rtol=1e-4)


def test_straight_limit_is_continuous():
    e0, _ = arc_step(np.zeros(2), np.array(0.3), np.array(0.0), L)
    e1, _ = arc_step(np.zeros(2), np.array(0.3), np.array(1e-9), L)
    np.testing.assert_allclose(e0, e1, atol=1e-8)


def test_batched_shapes():
    start = np.zeros((3, 4, 2))
    pts = arc_points(start, np.zeros((3, 4)), np.full((3, 4), 0.2), L, np.linspace(0, 1, 5))
    assert pts.shape == (3, 4, 5, 2)


def test_scale_action_and_wrap():
    np.testing.assert_allclose(
        scale_action(np.array([-1.0, 0.0, 1.0, 3.0]), 0.5), [-0.5, 0, 0.5, 0.5]
    )
    wrapped = wrap_angle(np.linspace(-10, 10, 101))
    assert (wrapped >= -np.pi).all() and (wrapped < np.pi).all()
    np.testing.assert_allclose(np.cos(wrapped), np.cos(np.linspace(-10, 10, 101)), atol=1e-12)
