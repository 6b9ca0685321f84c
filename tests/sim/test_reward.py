import numpy as np
import pytest

from sim.config import FieldConfig, PSOConfig, RewardConfig
from sim.contour import ArcWindow, arc_external, window_terms
from sim.field import FieldSources, potential
from sim.kinematics import arc_points, arc_step
from sim.metrics import substep_fractions
from sim.reward import assign_contour_levels, reward, swarming_reward

A_MAX = np.pi / 4
L = 20.0
FIELD = FieldConfig()


def test_swarming_is_cosine_to_the_target_line_and_zero_on_collision():
    pos = np.zeros((1, 4, 2))
    target = np.tile([[100.0, 0.0]], (1, 4, 1))
    heading = np.array([[0.0, np.pi / 3, np.pi, 0.0]])
    collided = np.array([[False, False, False, True]])
    r = swarming_reward(heading, pos, target, collided)
    np.testing.assert_allclose(r, [[1.0, 0.5, -1.0, 0.0]], atol=1e-12)


def test_preplanned_line_points_back_to_the_target_after_a_detour():
    pos = np.array([[[50.0, 40.0]]])
    target = np.array([[[100.0, 0.0]]])
    toward = np.arctan2(-40.0, 50.0)
    r = swarming_reward(np.array([[toward]]), pos, target, np.array([[False]]))
    assert r.item() == pytest.approx(1.0)
    parallel = swarming_reward(np.array([[0.0]]), pos, target, np.array([[False]]))
    assert parallel.item() < 0.8


@pytest.mark.parametrize("external", ["gradient", "level-edge"])
def test_total_is_contour_plus_swarming_with_weights(external):
    rng = np.random.default_rng(0)
    b, n, k = 3, 4, 3
    window = ArcWindow(
        turn_rad=rng.uniform(-A_MAX, A_MAX, (b, n, k)),
        external=rng.uniform(0, 1, (b, n, k)),
        valid=rng.random((b, n, k)) > 0.2,
    )
    heading = rng.uniform(-np.pi, np.pi, (b, n))
    pos = rng.uniform(0, 300, (b, n, 2))
    target = rng.uniform(0, 300, (b, n, 2))
    collided = rng.random((b, n)) > 0.7
    rcfg = RewardConfig(external=external, w_internal=0.7, w_external=1.3)
    r = reward(window, heading, pos, target, collided, A_MAX, rcfg)
    t = window_terms(window, A_MAX)
    np.testing.assert_allclose(r.contour, -(0.7 * t.internal - 1.3 * t.external))
    np.testing.assert_allclose(r.swarming, swarming_reward(heading, pos, target, collided))
    np.testing.assert_allclose(r.total, r.contour + r.swarming)
    assert np.all((r.internal >= 0) & (r.internal <= 1))
    assert np.all((r.external >= 0) & (r.external <= 1))
    assert np.all(r.swarming[collided] == 0)


@pytest.mark.parametrize("external", ["gradient", "level-edge"])
def test_arc_scores_batched_equal_per_environment(external):
    rng = np.random.default_rng(1)
    b, n, m = 4, 3, 2
    start = rng.uniform(0, 300, (b, n, 2))
    heading = rng.uniform(-np.pi, np.pi, (b, n))
    turn = rng.uniform(-A_MAX, A_MAX, (b, n))
    levels = rng.uniform(0, 0.01, (b, n))
    src = FieldSources(
        rng.uniform(0, 300, (b, m, 2)), np.full((b, m), 2.5), rng.uniform(0, 300, (b, 1, 2)), 10.0
    )
    rcfg = RewardConfig(external=external)
    pts = arc_points(start, heading, turn, L, substep_fractions(8))
    full = arc_external(pts, levels, src, FIELD, rcfg)
    assert np.all((full >= 0) & (full <= 1))
    for e in range(b):
        sl = slice(e, e + 1)
        one_src = FieldSources(
            src.obstacle_pos_m[sl], src.obstacle_speed_m_s[sl], src.centre_m[sl], 10.0
        )
        one = arc_external(pts[sl], levels[sl], one_src, FIELD, rcfg)
        np.testing.assert_allclose(full[e], one[0])


def test_reward_sees_the_arc_of_the_action_just_taken():
    """The newest arc is part of S: three different last actions give three Contour rewards."""
    src = FieldSources(
        np.array([[[60.0, 45.0]]]), np.array([[2.5]]), np.array([[[500.0, 0.0]]]), 10.0
    )
    level = potential(np.array([[[60.0, 0.0]]]), src, FIELD)
    rewards = []
    for last in (-A_MAX, 0.0, A_MAX):
        w = ArcWindow.empty(1, 1, 3)
        p, h = np.zeros((1, 1, 2)), np.zeros((1, 1))
        for a in (0.0, 0.0, last):
            turn = np.full((1, 1), a)
            pts = arc_points(p, h, turn, L, substep_fractions(8))
            ext = arc_external(pts, level, src, FIELD, RewardConfig())
            w = w.push(turn, ext, np.ones((1, 1), dtype=bool))
            p, h = arc_step(p, h, turn, L)
        t = window_terms(w, A_MAX)
        rewards.append((t.internal.item(), t.external.item()))
    assert len(set(rewards)) == 3
    assert rewards[1][0] == 0.0
    assert rewards[0][0] == pytest.approx(1 / 3)


def test_levels_are_the_field_at_the_pso_adjusted_positions():
    src = FieldSources(np.zeros((1, 0, 2)), np.zeros((1, 0)), np.zeros((1, 1, 2)), 10.0)
    positions = np.array([[[30.0, 0.0], [30.0, 10.0], [-40.0, 5.0]]])
    levels, result = assign_contour_levels(
        positions, src, FIELD, PSOConfig(threshold_m=30.0), np.random.default_rng(0)
    )
    assert result.feasible.all()
    assert result.min_distance_m[0] >= 30.0
    np.testing.assert_allclose(levels, potential(result.positions_m, src, FIELD))
