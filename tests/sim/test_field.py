import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from sim.config import FieldConfig
from sim.field import (
    FieldSources,
    obstacle_terms,
    peak_gradient,
    potential,
    potential_and_gradient,
    swarm_term,
)

CFG = FieldConfig()
VS = 10.0


def sources(obstacles, speeds, centre=(0.0, 0.0), vs=VS, mask=None):
    obs = np.asarray(obstacles, dtype=float).reshape(1, -1, 2)
    return FieldSources(
        obstacle_pos_m=obs,
        obstacle_speed_m_s=np.asarray(speeds, dtype=float).reshape(1, -1),
        centre_m=np.asarray(centre, dtype=float).reshape(1, -1, 2),
        swarm_speed_m_s=vs,
        obstacle_mask=None if mask is None else np.asarray(mask).reshape(1, -1),
    )


coord = st.floats(-150.0, 150.0, allow_nan=False)


def near_boundary(point, centre, radii, margin=0.05):
    d = np.hypot(*(np.asarray(point) - np.asarray(centre)))
    return any(abs(d - r) < margin for r in radii)


@given(px=coord, py=coord, ox=coord, oy=coord, cx=coord, cy=coord, vo=st.floats(0.0, 30.0))
def test_gradient_matches_central_difference(px, py, ox, oy, cx, cy, vo):
    src = sources([[ox, oy]], [vo], centre=(cx, cy))
    assume(not near_boundary((px, py), (ox, oy), [CFG.d_safe_m, CFG.obstacle_range_m]))
    assume(not near_boundary((px, py), (cx, cy), [CFG.swarm_floor_m, CFG.swarm_range_m]))
    h = 1e-4
    p = np.array([[[px, py]]])
    _, grad = potential_and_gradient(p, src, CFG)
    ex, ey = np.array([[[h, 0.0]]]), np.array([[[0.0, h]]])
    fd = np.array(
        [
            (potential(p + ex, src, CFG) - potential(p - ex, src, CFG)) / (2 * h),
            (potential(p + ey, src, CFG) - potential(p - ey, src, CFG)) / (2 * h),
        ]
    ).reshape(2)
    np.testing.assert_allclose(grad.reshape(2), fd, rtol=1e-4, atol=1e-10)


@pytest.mark.parametrize("continuous", [True, False])
@given(r=st.floats(0.0, 29.99), angle=st.floats(0, 2 * np.pi), vo=st.floats(0.0, 30.0))
def test_plateau_inside_d_safe(continuous, r, angle, vo):
    cfg = FieldConfig(continuous=continuous)
    src = sources([[0.0, 0.0]], [vo])
    p = np.array([[[r * np.cos(angle), r * np.sin(angle)]]])
    phi, grad = obstacle_terms(p, src, cfg)
    intensity = max(vo, VS)
    offset = 1 / cfg.obstacle_range_m**2 if continuous else 0.0
    assert phi.item() == pytest.approx(intensity * (1 / cfg.d_safe_m**2 - offset))
    assert np.all(grad == 0.0)


@pytest.mark.parametrize("continuous", [True, False])
def test_zero_beyond_the_ranges(continuous):
    cfg = FieldConfig(continuous=continuous)
    src = sources([[0.0, 0.0]], [2.5], centre=(500.0, 0.0))
    far_o = np.array([[[cfg.obstacle_range_m + 0.01, 0.0], [0.0, -200.0]]])
    phi, grad = obstacle_terms(far_o, src, cfg)
    assert np.all(phi == 0) and np.all(grad == 0)
    far_s = np.array([[[500.0, cfg.swarm_range_m + 0.01], [500.0 - 400.0, 0.0]]])
    phi, grad = swarm_term(far_s, src, cfg)
    assert np.all(phi == 0) and np.all(grad == 0)


def test_inverse_square_between_d_safe_and_range():
    cfg = FieldConfig(continuous=False)
    src = sources([[0.0, 0.0]], [2.5])
    for d in (31.0, 50.0, 99.0):
        phi, _ = obstacle_terms(np.array([[[d, 0.0]]]), src, cfg)
        assert phi.item() == pytest.approx(VS / d**2)  # I = max(v_o, v_s) = v_s


def test_continuous_field_has_no_jump_at_the_ranges():
    src = sources([[0.0, 0.0]], [2.5], centre=(0.0, 0.0))
    r_o = CFG.obstacle_range_m
    phi_in, _ = obstacle_terms(np.array([[[r_o - 1e-6, 0.0]]]), src, CFG)
    assert phi_in.item() == pytest.approx(0.0, abs=1e-9)
    r_s = CFG.swarm_range_m
    phi_in, _ = swarm_term(np.array([[[r_s - 1e-6, 0.0]]]), src, CFG)
    assert phi_in.item() == pytest.approx(0.0, abs=1e-9)


def test_intensity_is_max_of_obstacle_and_swarm_speed():
    p = np.array([[[50.0, 0.0]]])
    static, _ = obstacle_terms(p, sources([[0.0, 0.0]], [0.0]), CFG)
    slow, _ = obstacle_terms(p, sources([[0.0, 0.0]], [2.5]), CFG)
    fast, _ = obstacle_terms(p, sources([[0.0, 0.0]], [20.0]), CFG)
    assert static.item() == slow.item() > 0  # static obstacles are as strong as slow ones
    assert fast.item() == pytest.approx(2.0 * slow.item())


def test_swarm_floor_bounds_the_peak():
    src = sources(np.zeros((0, 2)), np.zeros(0), centre=(10.0, 10.0))
    phi, grad = swarm_term(np.array([[[10.0, 10.0], [11.0, 10.0]]]), src, CFG)
    expected = VS * (1 / CFG.swarm_floor_m**2 - 1 / CFG.swarm_range_m**2)
    np.testing.assert_allclose(phi[0], [expected, expected])
    assert np.all(grad == 0)


@given(
    pts=st.lists(st.tuples(coord, coord), min_size=1, max_size=6),
    obs=st.lists(st.tuples(coord, coord, st.floats(0, 20)), min_size=1, max_size=4),
)
def test_superposition(pts, obs):
    p = np.array([pts], dtype=float)
    positions = [o[:2] for o in obs]
    speeds = [o[2] for o in obs]
    phi, grad = potential_and_gradient(p, sources(positions, speeds, centre=(5.0, -3.0)), CFG)
    phi_s, grad_s = swarm_term(p, sources(positions, speeds, centre=(5.0, -3.0)), CFG)
    total_phi, total_grad = phi_s.copy(), grad_s.copy()
    for pos, speed in zip(positions, speeds, strict=True):
        one_phi, one_grad = obstacle_terms(p, sources([pos], [speed], centre=(5.0, -3.0)), CFG)
        total_phi += one_phi[..., 0]
        total_grad += one_grad[..., 0, :]
    np.testing.assert_allclose(phi, total_phi, rtol=1e-12)
    np.testing.assert_allclose(grad, total_grad, rtol=1e-12, atol=1e-18)


@given(
    pts=st.lists(st.tuples(coord, coord), min_size=1, max_size=6),
    obs=st.lists(st.tuples(coord, coord, st.floats(0, 20)), min_size=1, max_size=4),
)
def test_a_field_without_the_swarm_peak_is_the_obstacles_alone(pts, obs):
    p = np.array([pts], dtype=float)
    src = sources([o[:2] for o in obs], [o[2] for o in obs], centre=(5.0, -3.0))
    no_peak = FieldConfig(swarm_peak=False)
    phi, grad = potential_and_gradient(p, src, no_peak)
    phi_o, grad_o = obstacle_terms(p, src, CFG)
    np.testing.assert_allclose(phi, phi_o.sum(axis=-1), rtol=1e-12)
    np.testing.assert_allclose(grad, grad_o.sum(axis=-2), rtol=1e-12, atol=1e-18)
    phi_s, grad_s = swarm_term(p, src, no_peak)
    assert not phi_s.any() and not grad_s.any()


def test_masked_obstacles_contribute_nothing():
    p = np.array([[[40.0, 0.0]]])
    with_mask = potential(
        p, sources([[0.0, 0.0], [40.0, 5.0]], [2.5, 2.5], mask=[True, False]), CFG
    )
    only_first = potential(p, sources([[0.0, 0.0]], [2.5]), CFG)
    np.testing.assert_allclose(with_mask, only_first)


def test_batch_environments_are_independent_and_any_point_shape_works():
    rng = np.random.default_rng(3)
    obs = rng.uniform(-100, 100, (4, 3, 2))
    cen = rng.uniform(-100, 100, (4, 2, 2))  # two swarms
    src = FieldSources(obs, np.full((4, 3), 2.5), cen, VS)
    pts = rng.uniform(-150, 150, (4, 5, 7, 2))
    phi, grad = potential_and_gradient(pts, src, CFG)
    assert phi.shape == (4, 5, 7) and grad.shape == (4, 5, 7, 2)
    for b in range(4):
        one = FieldSources(obs[b : b + 1], np.full((1, 3), 2.5), cen[b : b + 1], VS)
        phi_b, grad_b = potential_and_gradient(pts[b : b + 1], one, CFG)
        np.testing.assert_allclose(phi[b], phi_b[0])
        np.testing.assert_allclose(grad[b], grad_b[0])


def test_gradient_peaks_just_outside_d_safe():
    src = sources([[0.0, 0.0]], [2.5], centre=(1000.0, 0.0))
    d = np.linspace(CFG.d_safe_m + 1e-6, CFG.obstacle_range_m, 500)
    pts = np.stack([d, np.zeros_like(d)], axis=-1)[None]
    _, grad = potential_and_gradient(pts, src, CFG)
    norm = np.hypot(grad[0, :, 0], grad[0, :, 1])
    assert norm.argmax() == 0
    assert norm[0] == pytest.approx(peak_gradient(CFG, VS), rel=1e-5)
