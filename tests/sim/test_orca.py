"""The ORCA baseline (`sim.orca`): hand-built encounters, a property, and whole episodes."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.contour import ArcWindow
from sim.kinematics import arc_points, heading_velocity, wrap_angle
from sim.orca import MARGIN_M, goal_turn_rad, orca_actions, orca_plan
from sim.scenarios import load_scenario
from sim.state import EpisodeStats, SwarmState
from sim.swarm import SwarmSim

CFG = load_scenario("3u2o")
A_MAX = CFG.uav.max_turn_rad
SPEED = CFG.uav.speed_m_s
R_M = CFG.d_col_m + MARGIN_M


def hand_state(pos, heading, target, obs_pos=(), obs_vel=None, active=None):
    """A one-environment state of N UAVs and M obstacles (batch axis added)."""
    pos = np.asarray(pos, dtype=float)[None]
    n = pos.shape[1]
    obs_pos = np.asarray(obs_pos, dtype=float).reshape(1, -1, 2)
    obs_vel = np.zeros_like(obs_pos) if obs_vel is None else np.reshape(obs_vel, obs_pos.shape)
    return SwarmState(
        pos_m=pos,
        heading_rad=np.asarray(heading, dtype=float)[None],
        active=np.ones((1, n), bool) if active is None else np.asarray(active)[None],
        reached=np.zeros((1, n), bool),
        start_m=pos.copy(),
        target_m=np.asarray(target, dtype=float)[None],
        obstacle_pos_m=obs_pos,
        obstacle_vel_m_s=np.asarray(obs_vel, dtype=float),
        obstacle_speed_m_s=np.linalg.norm(obs_vel, axis=-1),
        obstacle_appear_step=np.zeros(obs_pos.shape[:2], np.int64),
        centre_m=np.zeros((1, 1, 2)),
        swarm_vel_m_s=np.array([[[SPEED, 0.0]]]),
        levels=np.zeros((1, n)),
        avoiding=np.zeros(1, bool),
        window=ArcWindow.empty(1, n, 3),
        steps=np.zeros(1, np.int64),
        stats=EpisodeStats.fresh(1, n),
        vel_m_s=heading_velocity(np.asarray(heading, dtype=float)[None], SPEED),
        speed_m_s=np.full((1, n), SPEED),
        last_turn_rad=np.zeros((1, n)),
        response=None,
        tracks=None,
        gps_error_m=np.zeros((1, n, 2)),
    )


def fly(cfg, state, steps=60):
    """Fly ORCA until the episode ends; (the final state, the last step's result)."""
    sim, rng = SwarmSim(cfg), np.random.default_rng(0)
    for _ in range(steps):
        state, result = sim.step(state, orca_actions(state, cfg), rng)
        if result.terminated[0] or result.truncated[0]:
            break
    return state, result


def test_shape_dtype_range_and_inactive_uavs_do_nothing():
    cfg = load_scenario("5u2o")
    sim, rng = SwarmSim(cfg), np.random.default_rng(1)
    state = sim.initial_state(rng, 6)
    for _ in range(8):  # into the obstacles' sight
        state, _ = sim.step(state, orca_actions(state, cfg), rng)
    actions = orca_actions(state, cfg)
    assert actions.shape == (6, 5) and actions.dtype == np.float32
    assert np.all(np.abs(actions) <= 1.0)
    assert np.all(actions[~state.active] == 0.0)
    assert np.any(actions[state.active] != 0.0)  # someone is avoiding


def test_bad_arguments_are_refused():
    state = hand_state([[0, 0]], [0], [[200, 0]])
    for kwargs in (
        {"candidates": 4},
        {"candidates": 1},
        {"horizon_s": 1.0},
        {"neighbour_horizon_s": math.nan},
        {"margin_m": -1.0},
        {"priority": 0.6},
    ):
        with pytest.raises(ValueError, match=next(iter(kwargs))):
            orca_actions(state, CFG, **kwargs)


@pytest.mark.parametrize("bearing_deg", [0.0, 20.0, -35.0, 44.0, 120.0, -170.0])
def test_with_nothing_around_it_turns_to_its_target_within_the_turn_limit(bearing_deg):
    b = math.radians(bearing_deg)
    heading = 0.3
    target = [[200 * math.cos(heading + b), 200 * math.sin(heading + b)]]
    # An obstacle behind (outside the 270° aperture) and one beyond the sensing range: unseen.
    behind = [-60 * math.cos(heading), -60 * math.sin(heading)]
    far = [150 * math.cos(heading), 150 * math.sin(heading)]
    state = hand_state([[0, 0]], [heading], target, [behind, far], [[0, 0], [-2.5, 0]])
    action = orca_actions(state, CFG)[0, 0]
    assert action == pytest.approx(np.clip(b / A_MAX, -1, 1), abs=1e-6)
    # the turn toward the target, the one a lone UAV flies
    assert goal_turn_rad(state, CFG)[0, 0] == pytest.approx(np.clip(b, -A_MAX, A_MAX), abs=1e-9)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_a_head_on_intruder_is_avoided_on_the_side_that_clears(side):
    """Obstacle 80 m ahead, 4 m to one side, flying at the UAV: it turns the other way."""
    cfg = load_scenario("2u1o", uav={"count": 1}, obstacles={"count": 1})
    state = hand_state([[0, 0]], [0.0], [[250, 0]], [[80, 4 * side]], [[-2.5, 0]])
    plan = orca_plan(state, cfg)
    straight = plan.turn_rad[0, 0] == 0
    assert not plan.free[0, 0][straight].any()  # flying on would collide
    assert np.sign(plan.actions[0, 0]) == -side  # away from the obstacle's side
    assert plan.free[0, 0, plan.choice[0, 0]]
    final, result = fly(cfg, state)
    assert result.success[0] and final.stats.min_u2o_m[0] >= cfg.d_col_m


def test_two_uavs_head_on_turn_to_complementary_sides_and_pass():
    cfg = load_scenario("2u1o", obstacles={"count": 0}, max_steps=60)
    state = hand_state([[-150, 0], [150, 0]], [0, math.pi], [[150, 0], [-150, 0]])
    sim, rng = SwarmSim(cfg), np.random.default_rng(0)
    first = None
    for _ in range(60):
        actions = orca_actions(state, cfg)
        if first is None and np.any(actions != 0):
            first = actions[0].copy()
        state, result = sim.step(state, actions, rng)
        if result.terminated[0] or result.truncated[0]:
            break
    # Both turn right relative to their own heading (complementary in the world frame), by the
    # same amount: each takes half of the avoidance.
    assert first is not None and first[0] < 0 and first[1] < 0
    assert first[0] == pytest.approx(first[1], abs=1e-6)
    assert result.success[0] and state.stats.min_u2u_m[0] >= cfg.d_col_m
    # Flying straight, the same two collide.
    blind = hand_state([[-150, 0], [150, 0]], [0, math.pi], [[150, 0], [-150, 0]])
    for _ in range(20):
        blind, r = sim.step(blind, np.zeros((1, 2)), rng)
        if r.terminated[0]:
            break
    assert r.collided_u2u[0].all()


@pytest.mark.parametrize("angle_deg", [60.0, 100.0, 140.0, -120.0])
def test_two_uavs_crossing_avoid_each_other(angle_deg):
    """Crossing tracks that would meet at the origin, one slightly ahead of the other."""
    cfg = load_scenario("2u1o", obstacles={"count": 0}, max_steps=60)
    b = math.radians(angle_deg)
    d = np.array([math.cos(b), math.sin(b)])
    state = hand_state([[-150, 0], -140 * d], [0, b], [[150, 0], 160 * d])
    final, result = fly(cfg, state)
    assert not result.collided_u2u[0].any()
    assert final.stats.min_u2u_m[0] >= cfg.d_col_m


def test_random_crossings_never_collide():
    """300 two-UAV encounters, crossing at 30°–180° either way, the second UAV up to 30 m early
    or late at the meeting point; 300 m tracks, 60 steps. Measured: no collision, 97% arrive
    (the rest fly side by side to the step limit, the reciprocal "dance"); at a 4 s neighbour
    horizon 16 of the 300 collide."""
    cfg = load_scenario("2u1o", obstacles={"count": 0}, max_steps=60)
    b_num, r = 300, np.random.default_rng(1)
    angle = r.choice([-1, 1], b_num) * r.uniform(math.radians(30), math.pi, b_num)
    early = r.uniform(-30, 30, b_num)
    d = np.stack([np.cos(angle), np.sin(angle)], -1)
    first = np.broadcast_to([[-150.0, 0.0]], (b_num, 2))
    state = dataclasses.replace(
        SwarmSim(cfg).initial_state(np.random.default_rng(0), b_num),
        pos_m=np.stack([first, -(150 + early)[:, None] * d], 1),
        heading_rad=np.stack([np.zeros(b_num), angle], 1),
        target_m=np.stack([-first, (150 - early)[:, None] * d], 1),
    )
    sim, rng = SwarmSim(cfg), np.random.default_rng(0)
    collided = np.zeros(b_num, bool)
    success = np.zeros(b_num, bool)
    for _ in range(cfg.max_steps):
        state, result = sim.step(state, orca_actions(state, cfg), rng)
        collided |= result.collided_u2u.any(-1)
        success |= result.success
    assert not collided.any(), f"{collided.sum()} of {b_num} collided"
    assert success.mean() >= 0.95, f"{success.mean():.1%} arrived"


def test_an_inactive_uav_is_no_neighbour():
    state = hand_state([[0, 0], [30, 0]], [0, 0], [[200, 0], [30, 0]], active=[True, False])
    plan = orca_plan(state, CFG)
    assert plan.actions[0, 0] == 0.0 and plan.actions[0, 1] == 0.0
    assert np.all(plan.neighbour_violation_m_s[0, 0] == -np.inf)
    active = hand_state([[0, 0], [30, 0]], [0, math.pi], [[200, 0], [-200, 0]])
    assert orca_plan(active, CFG).actions[0, 0] != 0.0  # the same UAV, flying, is avoided


def test_permuting_uavs_and_obstacles_permutes_the_actions():
    cfg = load_scenario("7u2o")
    sim, rng = SwarmSim(cfg), np.random.default_rng(3)
    state = sim.initial_state(rng, 4)
    for _ in range(9):
        state, _ = sim.step(state, orca_actions(state, cfg), rng)
    actions = orca_actions(state, cfg)
    assert np.any(actions != 0)
    p = np.random.default_rng(0).permutation(cfg.uav.count)
    q = np.array([1, 0])
    shuffled = dataclasses.replace(
        state,
        pos_m=state.pos_m[:, p],
        heading_rad=state.heading_rad[:, p],
        active=state.active[:, p],
        reached=state.reached[:, p],
        target_m=state.target_m[:, p],
        obstacle_pos_m=state.obstacle_pos_m[:, q],
        obstacle_vel_m_s=state.obstacle_vel_m_s[:, q],
    )
    np.testing.assert_array_equal(orca_actions(shuffled, cfg), actions[:, p])


def reference_clearance(state, turn, horizon_s, samples=2001):
    """Independent check: dense samples of the arc (sim.kinematics) then straight flight."""
    dt = CFG.dt_s
    t = np.linspace(0.0, horizon_s, samples)
    pos, heading = state.pos_m[0, 0], state.heading_rad[0, 0]
    on_arc = t <= dt
    arc = arc_points(pos, np.full(turn.shape, heading), turn, CFG.step_length_m, t[on_arc] / dt)
    end = arc[:, -1]
    final = heading + turn
    rest = (t[~on_arc] - dt)[None, :, None] * SPEED
    line = end[:, None] + rest * np.stack([np.cos(final), np.sin(final)], -1)[:, None]
    path = np.concatenate([arc, line], axis=1)  # (C, T, 2)
    obs = state.obstacle_pos_m[0][:, None] + t[None, :, None] * state.obstacle_vel_m_s[0][:, None]
    rel = path[:, None] - obs[None]  # (C, M, T, 2)
    dist = np.linalg.norm(rel, axis=-1)
    # Sensed now: range and the 270° aperture.
    to = state.obstacle_pos_m[0] - pos
    rng_ok = np.linalg.norm(to, axis=-1) <= CFG.sensing.range_m
    bearing = np.abs(wrap_angle(np.arctan2(to[:, 1], to[:, 0]) - heading))
    sensed = rng_ok & (bearing <= CFG.sensing.aperture_rad / 2)
    now = np.linalg.norm(to, axis=-1)
    radius = np.minimum(R_M, now)
    return np.where(sensed[None], dist.min(axis=-1) - radius[None], np.inf).min(axis=-1)


@given(
    heading=st.floats(-math.pi, math.pi),
    goal=st.floats(-math.pi, math.pi),
    obstacles=st.lists(
        st.tuples(
            st.floats(22.0, 110.0),  # distance, m (outside d_col + margin)
            st.floats(-math.pi, math.pi),  # bearing
            st.floats(0.0, 2.5),  # speed, m/s
            st.floats(-math.pi, math.pi),  # course
        ),
        min_size=1,
        max_size=4,
    ),
)
def test_when_some_candidate_is_clear_the_chosen_one_is_clear(heading, goal, obstacles):
    d, b, v, c = (np.array(x) for x in zip(*obstacles, strict=True))
    obs_pos = np.stack([d * np.cos(b), d * np.sin(b)], -1)
    obs_vel = np.stack([v * np.cos(c), v * np.sin(c)], -1)
    target = [[300 * math.cos(goal), 300 * math.sin(goal)]]
    state = hand_state([[0, 0]], [heading], target, obs_pos, obs_vel)
    plan = orca_plan(state, CFG)
    turn = plan.turn_rad[0, 0]
    ref = reference_clearance(state, turn, 10.0)
    tolerance = 0.2  # the chords of the predicted arc lie within 0.12 m of it
    if np.any(ref >= tolerance):
        assert ref[plan.choice[0, 0]] >= -tolerance
        # and it is the clear candidate nearest the goal heading
        clear = ref >= tolerance
        best = plan.goal_error_rad[0, 0][clear].min()
        assert plan.goal_error_rad[0, 0, plan.choice[0, 0]] <= best + 1e-5  # right-of-way bias
    # the controller's own clearance agrees with the dense reference
    np.testing.assert_allclose(
        np.minimum(plan.obstacle_clearance_m[0, 0], 1e6), np.minimum(ref, 1e6), atol=tolerance
    )


def episodes(cfg, act, num, seed):
    """Success rate of ``num`` episodes flown in one batch."""
    sim, rng = SwarmSim(cfg), np.random.default_rng(seed)
    state = sim.initial_state(rng, num)
    ended = np.zeros(num, bool)
    success = np.zeros(num, bool)
    for _ in range(cfg.max_steps):
        state, result = sim.step(state, act(state, cfg), rng)
        done = (result.terminated | result.truncated) & ~ended
        success |= done & result.success
        ended |= done
        if ended.all():
            break
    return success.mean()


@pytest.mark.parametrize(
    ("scenario", "arrival", "least"),
    [
        # Measured (50 episodes, seed 11): ORCA 100% on all three under the paper's rule;
        # with arrived UAVs hovering, 3u2o 100%, 5u2o 72% (the apex stops 20 m short of its
        # target, in the way of a neighbour that avoided an obstacle toward the centre, too
        # late to turn clear), 10u1o 92%. Straight flight: 0% in every case.
        ("3u2o", "leave", 0.9),
        ("5u2o", "leave", 0.9),
        ("10u1o", "leave", 0.9),
        ("3u2o", "hover", 0.9),
        ("5u2o", "hover", 0.6),
        ("10u1o", "hover", 0.8),
    ],
)
def test_orca_succeeds_where_straight_flight_fails(scenario, arrival, least):
    cfg = load_scenario(scenario, arrival=arrival)
    orca = episodes(cfg, orca_actions, 50, seed=11)
    straight = episodes(cfg, lambda s, c: np.zeros(s.heading_rad.shape), 50, seed=11)
    assert orca >= least and orca - straight >= least - 0.1, (
        f"ORCA {orca:.0%}, straight {straight:.0%}"
    )
