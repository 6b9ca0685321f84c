import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.kinematics import arc_points, straight_points
from sim.metrics import energy, path_length_ratio, substep_fractions, swept_min_distance

L, DT = 20.0, 2.0


def uav_substep_positions(start, heading, turn, length):
    return arc_points(start, heading, turn, length, substep_fractions())


def obstacle_substep_positions(start, velocity, dt):
    return straight_points(start, velocity, dt, substep_fractions())


def swept_uav_obstacle_distance(uav_path, obstacle_path):
    return swept_min_distance(uav_path[:, :, None] - obstacle_path[:, None])


def swept_uav_uav_distance(uav_path):
    dist = swept_min_distance(uav_path[:, :, None] - uav_path[:, None])
    n = uav_path.shape[1]
    dist[:, np.arange(n), np.arange(n)] = np.inf
    return dist


def test_head_on_pass_between_samples_is_caught():
    """Head-on: 22.5 m apart at the start, 2.5 m (the other way round) at the end, 0 between."""
    uav = uav_substep_positions(np.zeros((1, 1, 2)), np.zeros((1, 1)), np.zeros((1, 1)), L)
    obs = obstacle_substep_positions(np.array([[[22.5, 0.0]]]), np.array([[[-2.5, 0.0]]]), DT)
    end_gap = np.hypot(*(uav[0, 0, -1] - obs[0, 0, -1]))
    assert end_gap == pytest.approx(2.5)
    start_gap = np.hypot(*(uav[0, 0, 0] - obs[0, 0, 0]))
    assert start_gap == pytest.approx(22.5)
    d = swept_uav_obstacle_distance(uav, obs)
    assert d.item() == pytest.approx(0.0, abs=1e-9)


def test_crossing_uavs_tunnel_through_each_other_at_the_step_ends_only():
    start = np.array([[[0.0, -10.0], [0.0, 10.0]]])
    heading = np.array([[np.pi / 2, -np.pi / 2]])
    paths = uav_substep_positions(start, heading, np.zeros((1, 2)), L)
    ends = np.hypot(*(paths[0, 0, [0, -1]] - paths[0, 1, [0, -1]]).T)
    np.testing.assert_allclose(ends, [20.0, 20.0])  # a discrete check sees 20 m at both ends
    d = swept_uav_uav_distance(paths)
    assert d[0, 0, 1] == pytest.approx(0.0, abs=1e-9)
    assert d[0, 0, 0] == np.inf
    np.testing.assert_allclose(d, np.swapaxes(d, 1, 2))


@given(
    h=st.floats(-np.pi, np.pi),
    a=st.floats(-np.pi / 4, np.pi / 4),
    ox=st.floats(-40, 60),
    oy=st.floats(-50, 50),
    vh=st.floats(-np.pi, np.pi),
    vo=st.floats(0, 10),
)
def test_swept_distance_agrees_with_dense_sampling(h, a, ox, oy, vh, vo):
    start = np.zeros((1, 1, 2))
    uav = uav_substep_positions(start, np.full((1, 1), h), np.full((1, 1), a), L)
    vel = vo * np.array([[[np.cos(vh), np.sin(vh)]]])
    obs = obstacle_substep_positions(np.array([[[ox, oy]]]), vel, DT)
    swept = swept_uav_obstacle_distance(uav, obs).item()
    u = np.linspace(0, 1, 20001)
    dense_uav = arc_points(start[0, 0], np.array(h), np.array(a), L, u)
    dense_obs = straight_points(np.array([ox, oy]), vel[0, 0], DT, u)
    brute = np.hypot(*(dense_uav - dense_obs).T).min()
    sagitta = L * abs(a) / (8 * 8**2)  # chord error bound with 8 sub-steps
    assert abs(swept - brute) <= sagitta + 1e-3


def test_swept_min_distance_of_static_points_is_their_distance():
    rel = np.tile([[3.0, 4.0]], (9, 1))
    assert swept_min_distance(rel) == pytest.approx(5.0)


@given(turns=st.lists(st.floats(-np.pi / 4, np.pi / 4), min_size=1, max_size=6))
def test_energy_is_integral_of_curvature(turns):
    """E = ∫|S''| dρ on a path of arcs equals Σ|a| (checked by dense numerical integration)."""
    p, h, total = np.zeros(2), 0.0, 0.0
    for a in turns:
        rho = np.linspace(0, 1, 4001)
        pts = arc_points(p, np.array(h), np.array(a), L, rho)
        step = L * (rho[1] - rho[0])
        second = (pts[2:] - 2 * pts[1:-1] + pts[:-2]) / step**2
        total += np.trapezoid(np.hypot(*second.T), dx=step)
        p, h = pts[-1], h + a
    e = energy(np.array(turns), np.ones(len(turns), dtype=bool))
    assert float(e) == pytest.approx(total, rel=2e-3, abs=1e-6)


def test_energy_counts_only_flown_steps_and_batches():
    turns = np.array([[0.1, -0.2, 0.3], [0.5, 0.5, 0.5]])
    flown = np.array([[True, True, False], [True, False, False]])
    np.testing.assert_allclose(energy(turns, flown), [0.3, 0.5])


def test_path_length_ratio():
    start = np.array([[0.0, 0.0], [0.0, 0.0]])
    target = np.array([[200.0, 0.0], [120.0, 160.0]])
    ratio = path_length_ratio(np.array([200.0, 300.0]), start, target)
    np.testing.assert_allclose(ratio, [1.0, 1.5])


@given(seed=st.integers(0, 2**31), steps=st.integers(1, 9), kind=st.sampled_from("rzst"))
def test_the_two_component_kernel_gives_the_general_kernels_numbers(seed, steps, kind):
    """`swept_min_distance_parts` on (x, y) (its lean kernel) and on (x, y, 0) (the general
    one): the same float32 numbers, bit for bit, degenerate motions included."""
    from sim.metrics import swept_min_distance_parts

    rng = np.random.default_rng(seed)
    shape = (steps + 1, 300)
    if kind == "r":  # anywhere
        x, y = rng.normal(0, 50, shape), rng.normal(0, 50, shape)
    elif kind == "z":  # on a grid: zeros, equal instants, ties
        x, y = rng.integers(-2, 3, shape) * 1.0, rng.integers(-2, 3, shape) * 1.0
    elif kind == "s":  # standing still: no motion in a sub-interval
        x = np.repeat(rng.normal(0, 5, (1, 300)), steps + 1, axis=0)
        y = -0.5 * x
    else:  # tiny: squares below float32's smallest normal
        x, y = rng.normal(0, 1e-20, shape), rng.normal(0, 1e-20, shape)
    x, y = x.astype(np.float32), y.astype(np.float32)
    lean = swept_min_distance_parts((x, y))
    general = swept_min_distance_parts((x, y, np.zeros_like(x)))
    np.testing.assert_array_equal(lean.view(np.uint32), general.view(np.uint32))
