import dataclasses

import numpy as np
import pytest

from sim.scenarios import load_scenario
from sim.swarm import SwarmSim, initial_state, reset_where, step

NO_OBSTACLES = {"obstacles": {"count": 0}}


def run(cfg, state, policy, rng, steps=100):
    results = []
    for _ in range(steps):
        state, result = step(state, policy(state), rng, cfg)
        results.append(result)
        if (result.terminated | result.truncated).all():
            break
    return state, results


def straight(state):
    return np.zeros(state.heading_rad.shape)


def test_straight_flight_with_no_obstacles_arrives_with_success():
    cfg = load_scenario("3u2o", **NO_OBSTACLES)
    rng = np.random.default_rng(0)
    state, results = run(cfg, initial_state(cfg, rng, 2), straight, rng)
    last = results[-1]
    assert last.terminated.all() and last.success.all() and not last.truncated.any()
    assert state.reached.all() and not state.active.any()
    arrivals = np.sum([r.arrived for r in results], axis=0)
    np.testing.assert_array_equal(arrivals, 1)  # every UAV arrives exactly once
    assert state.stats.energy_rad.sum() == 0.0
    # Straight lines: flown distance ≈ straight distance (within one step of the target).
    straight_m = np.hypot(*(state.target_m - state.start_m).transpose(2, 0, 1))
    assert np.all(state.stats.flown_m >= straight_m - cfg.d_col_m)
    assert np.all(state.stats.flown_m <= straight_m + cfg.step_length_m)
    # Swarming reward is 1 per step on the pre-planned line, and nothing collides.
    for r in results:
        np.testing.assert_allclose(r.reward.swarming[r.acted], 1.0)
        assert not (r.collided_u2o | r.collided_u2u).any()


def test_arrived_uavs_leave_stay_put_and_earn_nothing():
    cfg = load_scenario("3u2o", **NO_OBSTACLES)
    rng = np.random.default_rng(0)
    state = initial_state(cfg, rng, 1)
    first_arrival = None
    for _ in range(30):
        state, r = step(state, np.zeros((1, 3)), rng, cfg)
        if r.arrived.any() and first_arrival is None:
            first_arrival = r.arrived.copy()
            frozen = state.pos_m[first_arrival].copy()
        elif first_arrival is not None and not r.terminated.any():
            assert not r.acted[first_arrival].any()
            np.testing.assert_array_equal(state.pos_m[first_arrival], frozen)
            assert (r.reward.total[first_arrival] == 0).all()
        if r.terminated.all():
            break
    assert first_arrival is not None


def test_collision_with_an_obstacle_ends_the_episode_and_zeroes_r_collide():
    cfg = load_scenario("2u1o", obstacles={"speed_m_s": 0.0})
    rng = np.random.default_rng(0)
    state = initial_state(cfg, rng, 1)
    state = dataclasses.replace(state, obstacle_pos_m=state.pos_m[:, :1] + [[[30.0, 0.0]]])
    state, r = step(state, np.zeros((1, 2)), rng, cfg)
    assert r.terminated.item() and not r.success.item()
    assert r.collided_u2o[0].tolist() == [True, False]
    assert r.reward.swarming[0, 0] == 0.0 and r.reward.swarming[0, 1] == pytest.approx(1.0)
    assert not state.active.any()
    assert state.stats.min_u2o_m[0] < cfg.d_col_m


def test_uavs_crossing_between_steps_collide():
    """Two UAVs 20 m apart fly head-on and swap places: 20 m apart at both step ends."""
    cfg = load_scenario("2u1o", **NO_OBSTACLES)
    rng = np.random.default_rng(0)
    state = initial_state(cfg, rng, 1)
    pos = np.array([[[100.0, 140.0], [100.0, 160.0]]])
    heading = np.array([[np.pi / 2, -np.pi / 2]])  # toward each other: they pass through
    state = dataclasses.replace(state, pos_m=pos, heading_rad=heading)
    after, r = step(state, np.zeros((1, 2)), rng, cfg)
    end_gap = np.hypot(*(after.pos_m[0, 0] - after.pos_m[0, 1]))
    assert end_gap == pytest.approx(20.0)  # a check at the step ends sees exactly d_col
    assert r.collided_u2u.all() and r.terminated.item()
    assert r.min_u2u_m[0, 0] == pytest.approx(0.0, abs=1e-6)


def test_step_limit_truncates():
    cfg = load_scenario("2u1o", max_steps=5, **NO_OBSTACLES)
    rng = np.random.default_rng(0)
    circles = lambda s: np.ones(s.heading_rad.shape)  # noqa: E731 - max left turn: circles
    state, results = run(cfg, initial_state(cfg, rng, 3), circles, rng)
    assert len(results) == 5
    assert results[-1].truncated.all() and not results[-1].terminated.any()
    assert not any(r.truncated.any() for r in results[:-1])
    np.testing.assert_allclose(state.stats.energy_rad, 5 * cfg.uav.max_turn_rad)


def test_partial_reset_touches_only_the_masked_environments():
    cfg = load_scenario("3u2o")
    rng = np.random.default_rng(0)
    state = initial_state(cfg, rng, 4)
    for _ in range(3):
        state, _ = step(state, np.full((4, 3), 0.3), rng, cfg)
    mask = np.array([True, False, True, False])
    fresh = reset_where(state, mask, cfg, rng)
    np.testing.assert_array_equal(fresh.steps, [0, 3, 0, 3])
    np.testing.assert_array_equal(fresh.pos_m[~mask], state.pos_m[~mask])
    np.testing.assert_array_equal(fresh.window.turn_rad[~mask], state.window.turn_rad[~mask])
    np.testing.assert_array_equal(fresh.pos_m[mask], fresh.start_m[mask])
    assert not fresh.window.valid[mask].any()
    assert np.isinf(fresh.stats.min_u2o_m[mask]).all()


def test_same_seed_same_trajectories():
    cfg = load_scenario("5u2o")

    def trajectory(seed):
        rng = np.random.default_rng(seed)
        state = initial_state(cfg, rng, 3)
        act_rng = np.random.default_rng(99)
        out = []
        for _ in range(12):
            state, r = step(state, act_rng.uniform(-1, 1, (3, 5)), rng, cfg)
            out.append((state.pos_m.copy(), state.obstacle_pos_m.copy(), r.reward.total.copy()))
        return out

    a, b, c = trajectory(5), trajectory(5), trajectory(6)
    for x, y in zip(a, b, strict=True):
        for u, v in zip(x, y, strict=True):
            np.testing.assert_array_equal(u, v)
    assert not np.array_equal(a[0][1], c[0][1])


def test_levels_are_reassigned_once_when_avoidance_begins():
    cfg = load_scenario("3u2o")
    rng = np.random.default_rng(2)
    state = initial_state(cfg, rng, 8)
    levels0 = state.levels.copy()
    assert (levels0 > 0).all()  # every UAV has a contour from the start
    assigned = np.zeros(8, dtype=int)
    for _ in range(cfg.max_steps):
        before_sensing = ~state.avoiding
        state, r = step(state, np.zeros((8, 3)), rng, cfg)
        assigned += r.levels_assigned
        assert not (r.levels_assigned & ~before_sensing).any()
        if (r.terminated | r.truncated).all():
            break
    assert (assigned <= 1).all() and assigned.sum() > 0


def test_rewards_include_both_parts_and_inactive_agents_get_zero():
    cfg = load_scenario("3u2o")
    rng = np.random.default_rng(0)
    state = initial_state(cfg, rng, 2)
    state, r = step(state, np.array([[0.5, -0.5, 0.0], [1.0, 0.0, -1.0]]), rng, cfg)
    np.testing.assert_allclose(r.reward.total, r.reward.contour + r.reward.swarming)
    np.testing.assert_allclose(
        r.reward.internal, (np.array([[0.5, 0.5, 0.0], [1.0, 0.0, 1.0]])) ** 2
    )
    assert (r.reward.external > 0).all()


def test_the_unscored_simulator_flies_the_same_episodes_without_the_reward():
    from sim.heuristics import potential_field_actions
    from sim.scenarios import load_scenario
    from sim.spawn import spawn_episodes
    from sim.swarm import SwarmSim

    cfg = load_scenario("5u2o")
    episodes = spawn_episodes(cfg, np.random.default_rng(3), 16)
    runs = []
    for scored in (True, False):
        sim, rng = SwarmSim(cfg, scored=scored), np.random.default_rng(0)
        state, outcomes = sim.start(episodes, rng), []
        for _ in range(cfg.max_steps):
            obs = sim.observe(state).flat()
            act = potential_field_actions(obs, cfg.sensing.max_obstacles, cfg.uav.max_turn_rad)
            state, result = sim.step(state, act, rng)
            outcomes.append((result.success, result.collided_u2o, result.collided_u2u))
        runs.append((state, outcomes))
    (scored, out_s), (unscored, out_u) = runs
    np.testing.assert_array_equal(scored.pos_m, unscored.pos_m)
    np.testing.assert_array_equal(scored.stats.min_u2o_m, unscored.stats.min_u2o_m)
    for a, b in zip(out_s, out_u, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    assert np.abs(scored.stats.total_return).sum() > 0
    assert not unscored.stats.total_return.any() and not unscored.levels.any()


def v2_on_5u1o(envs):
    """5u1o's simulator, a state of ``envs`` environments, a version-2 layout (4 and 2 rows)."""
    from sim.observation import ObservationLayout

    cfg = load_scenario("5u1o")
    sim = SwarmSim(cfg)
    state = sim.initial_state(np.random.default_rng(0), envs)
    layout = ObservationLayout(
        8, cfg.sensing.range_m, cfg.sensing.aperture_rad, cfg.uav.speed_m_s, 4, 2
    )
    return sim, state, layout


def test_a_policys_v2_layout_sees_the_other_uavs_of_a_v1_scenario():
    sim, state, layout = v2_on_5u1o(4)
    obs = sim.observe(state, layout=layout)
    bl = layout.blocks()
    assert obs.storage.shape == (4, 5, layout.size)
    assert obs.storage[..., bl["neighbour_mask"]].sum(axis=-1).min() >= 1  # a swarm in formation
    own_v1 = sim.observe(state)  # the scenario's own observation is untouched
    assert own_v1.storage.shape[-1] == sim.obs_layout.size
    np.testing.assert_array_equal(obs.rows, own_v1.rows[:, :, :2])


def test_a_commanded_heading_shows_in_the_neighbours_rows_only():
    from sim.observation import NEIGHBOUR_COLUMNS

    sim, state, layout = v2_on_5u1o(2)
    flown = sim.observe(state, layout=layout).flat()
    same = sim.observe(state, layout=layout, commanded_heading_rad=state.heading_rad).flat()
    np.testing.assert_array_equal(flown, same)
    turned = state.heading_rad.copy()
    turned[:, 0] += 0.3  # UAV 0 is told to turn left
    told = sim.observe(state, layout=layout, commanded_heading_rad=turned).flat()
    bl = layout.blocks()
    rows = lambda o: o[..., bl["neighbours"]].reshape(*o.shape[:2], 4, NEIGHBOUR_COLUMNS)  # noqa: E731
    differs = np.abs(rows(told) - rows(flown)).max(axis=-1) > 1e-6  # (B, N, K)
    assert not differs[:, 0].any()  # UAV 0 does not see itself, nor do its own rows change
    assert differs[:, 1:].any()  # the others see it
    np.testing.assert_array_equal(
        np.delete(told, bl["neighbours"], -1), np.delete(flown, bl["neighbours"], -1)
    )
    # only the Δψ entries (cos, sin) change: positions, velocities, distance, "ψ known" do not
    np.testing.assert_array_equal(
        rows(told)[..., [0, 1, 2, 3, 4, 7]], rows(flown)[..., [0, 1, 2, 3, 4, 7]]
    )
    # the rows that differ show UAV 0's turn: its Δψ went up by 0.3 rad
    a = np.arctan2(rows(told)[..., 6], rows(told)[..., 5])
    b = np.arctan2(rows(flown)[..., 6], rows(flown)[..., 5])
    np.testing.assert_allclose(np.angle(np.exp(1j * (a - b)))[differs], 0.3, atol=1e-5)


def test_a_v2_scenario_trains_with_neighbours_in_its_observations():
    from sim.env import make_vector_env

    env = make_vector_env(
        "3u2o", 3, sensing={"observation": 2, "max_neighbours": 2, "max_obstacles": 4}
    )
    obs, _ = env.reset(seed=0)
    assert obs.shape == (3, 3, env.sim.obs_layout.size)
    for _ in range(5):
        obs, *_ = env.step(np.zeros((3, 3), np.float32))
    assert np.isfinite(obs).all()


def test_evolve_is_dataclasses_replace():
    cfg = load_scenario("3u2o")
    state = initial_state(cfg, np.random.default_rng(0), 4)
    levels = np.ones_like(state.levels)
    evolved = state.evolve(levels=levels, steps=state.steps + 1)
    replaced = dataclasses.replace(state, levels=evolved.levels, steps=evolved.steps)
    assert all(
        getattr(evolved, f.name) is getattr(replaced, f.name) for f in dataclasses.fields(state)
    )
    assert evolved.levels is levels and state.levels is not levels  # the state is not changed
    with pytest.raises(TypeError, match="no field level"):
        state.evolve(level=levels)
