import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.config import FieldConfig, RewardConfig
from sim.contour import (
    ArcWindow,
    arc_bending_energy,
    arc_external,
    external_density,
    window_terms,
)
from sim.field import FieldSources, potential
from sim.kinematics import arc_points, arc_step
from sim.metrics import substep_fractions

A_MAX = np.pi / 4
L = 20.0
FIELD = FieldConfig()
VS = 10.0


def lone_obstacle(at=(0.0, 0.0)):
    """One obstacle, the swarm's virtual centre far away (no swarm field near the obstacle)."""
    return FieldSources(
        np.array([[at]], dtype=float), np.array([[2.5]]), np.array([[[5000.0, 5000.0]]]), VS
    )


def fly(start, heading, turns, level, src, rcfg, substeps=8):
    """Fly consecutive arcs on a static field; return the (1, 1, K) window of their scores."""
    window = ArcWindow.empty(1, 1, len(turns))
    p, h = np.asarray(start, dtype=float).reshape(1, 1, 2), np.full((1, 1), float(heading))
    lv = np.full((1, 1), level)
    for a in turns:
        turn = np.full((1, 1), float(a))
        pts = arc_points(p, h, turn, L, substep_fractions(substeps))
        ext = arc_external(pts, lv, src, FIELD, rcfg)
        window = window.push(turn, ext, np.ones((1, 1), dtype=bool))
        p, h = arc_step(p, h, turn, L)
    return window


def cost(start, heading, turns, level, src, rcfg):
    t = window_terms(fly(start, heading, turns, level, src, rcfg), A_MAX)
    return (rcfg.w_internal * t.internal - rcfg.w_external * t.external).item(), t


@given(a=st.floats(-np.pi / 4, np.pi / 4))
def test_internal_closed_form_matches_dense_integration(a):
    rho = np.linspace(0.0, 1.0, 20001)
    pts = arc_points(np.zeros(2), np.array(0.4), np.array(a), L, rho)
    h = L * (rho[1] - rho[0])
    second = (pts[2:] - 2 * pts[1:-1] + pts[:-2]) / h**2  # S''(ρ) by central differences
    numeric = np.trapezoid(0.5 * np.sum(second**2, axis=-1), dx=h)
    assert numeric == pytest.approx(arc_bending_energy(np.array(a), L), rel=1e-3, abs=1e-9)


def test_internal_term_is_mean_of_squared_normalised_turns_and_grows_with_turning():
    rcfg = RewardConfig()
    src = lone_obstacle((1e4, 1e4))
    values = []
    for a in (0.0, 0.1, 0.3, 0.6, A_MAX):
        _, t = cost((0, 0), 0.0, [a, a, a], 0.0, src, rcfg)
        values.append(t.internal.item())
        assert t.internal.item() == pytest.approx((a / A_MAX) ** 2)
    assert values == sorted(values) and values[0] == 0.0 and values[-1] == pytest.approx(1.0)
    _, mixed = cost((0, 0), 0.0, [0.0, -A_MAX, A_MAX / 2], 0.0, src, rcfg)
    assert mixed.internal.item() == pytest.approx((0 + 1 + 0.25) / 3)


@pytest.mark.parametrize("external", ["gradient", "level-edge"])
def test_straight_path_far_from_everything_costs_nothing(external):
    rcfg = RewardConfig(external=external)
    src = lone_obstacle((1e4, 1e4))
    f, t = cost((0, 0), 0.0, [0.0, 0.0, 0.0], 0.0, src, rcfg)
    assert f == pytest.approx(0.0, abs=1e-12)
    assert t.external.item() == pytest.approx(0.0, abs=1e-12)


def circle(radius, phase=-np.pi / 2):
    """Three arcs following the circle of the given radius around the origin (counter-clockwise)."""
    a = L / radius
    start = radius * np.array([np.cos(phase), np.sin(phase)])
    return start, phase + np.pi / 2, [a, a, a]


@pytest.mark.parametrize("external", ["gradient", "level-edge"])
def test_following_the_level_set_beats_cutting_toward_the_peak_and_staying_far(external):
    rcfg = RewardConfig(external=external)
    src = lone_obstacle()
    # The contour to follow: the obstacle's strongest edge for "gradient" (just outside d_safe),
    # the UAV's own level set for "level-edge" (here the circle of radius 45 m).
    radius = FIELD.d_safe_m + 1.0 if external == "gradient" else 45.0
    level = potential(np.array([[[radius, 0.0]]]), src, FIELD).item()
    follow, _ = cost(*circle(radius), level, src, rcfg)
    # Cut toward the peak: from the same start, head straight at the obstacle.
    start = np.array([0.0, -radius - 30.0])
    cut, _ = cost(start, np.pi / 2, [0.0, 0.0, 0.0], level, src, rcfg)
    # Stay far: a straight pass 95 m abeam.
    far, _ = cost((-30.0, -95.0), 0.0, [0.0, 0.0, 0.0], level, src, rcfg)
    assert follow < cut
    assert follow < far


def test_level_edge_density_is_one_on_the_level_and_falls_with_distance():
    rcfg = RewardConfig()
    src = lone_obstacle()
    r = 50.0
    level = potential(np.array([[[r, 0.0]]]), src, FIELD)
    radii = np.array([r, r + 5.0, r + 15.0, r + 40.0])
    pts = np.stack([radii, np.zeros(4)], axis=-1)[None]
    e = external_density(pts, level, src, FIELD, rcfg)[0]
    assert e[0] == pytest.approx(1.0)
    assert np.all(np.diff(e) < 0)
    # First order: a point δ off the level set has density ≈ exp(−δ²/σ²).
    assert e[1] == pytest.approx(np.exp(-((5.0 / rcfg.edge_width_m) ** 2)), rel=0.1)


def test_gradient_density_saturates_at_one_on_the_strongest_edge():
    rcfg = RewardConfig(external="gradient")
    src = lone_obstacle()
    pts = np.array([[[FIELD.d_safe_m + 1e-9, 0.0], [10.0, 0.0], [60.0, 0.0]]])
    e = external_density(pts, None, src, FIELD, rcfg)[0]
    assert e[0] == pytest.approx(1.0, rel=1e-6)
    assert e[1] == 0.0  # inside the plateau the field is flat
    assert e[2] == pytest.approx((FIELD.d_safe_m / 60.0) ** 6)


def test_quadrature_converges():
    src = lone_obstacle()
    level = potential(np.array([[[42.0, 0.0]]]), src, FIELD).item()
    coarse = window_terms(fly(*circle(40.0), level, src, RewardConfig(), substeps=4), A_MAX)
    fine = window_terms(fly(*circle(40.0), level, src, RewardConfig(), substeps=512), A_MAX)
    assert coarse.external.item() == pytest.approx(fine.external.item(), rel=2e-2)


def test_invalid_arcs_are_ignored_and_a_short_window_is_a_mean():
    w = ArcWindow(
        turn_rad=np.array([[[A_MAX, 0.0, A_MAX / 2]]]),
        external=np.array([[[0.9, 0.2, 0.4]]]),
        valid=np.array([[[False, True, True]]]),
    )
    t = window_terms(w, A_MAX)
    assert t.internal.item() == pytest.approx((0 + 0.25) / 2)
    assert t.external.item() == pytest.approx((0.2 + 0.4) / 2)


def test_push_appends_the_newest_arc_and_respects_the_flown_mask():
    w = ArcWindow.empty(num_envs=1, num_uavs=2, window_steps=3)
    for k in range(4):
        w = w.push(
            np.full((1, 2), 0.1 * k), np.full((1, 2), 0.01 * k), flown=np.array([[True, k < 1]])
        )
    np.testing.assert_allclose(w.turn_rad[0, 0], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(w.external[0, 0], [0.01, 0.02, 0.03])
    assert w.valid[0, 0].all()
    # The second UAV flew only the first step: one valid arc, last in the window.
    assert w.valid[0, 1].tolist() == [False, False, True]
    np.testing.assert_allclose(w.turn_rad[0, 1, -1], 0.0)
    cleared = w.reset(np.array([True]))
    assert not cleared.valid.any()
    assert not cleared.turn_rad.any()
