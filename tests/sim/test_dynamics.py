"""The simulator's vehicles with a fitted response: lag, limits, hovering after arrival."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from dense_response import dense_track
from hypothesis import given, settings
from hypothesis import strategies as st

from sim import dynamics as sim_dynamics
from sim.dynamics import (
    AT_REST_M_S,
    INTEGRATION_STEP_S,
    Motion,
    ResponseSpec,
    brake,
    integration_grid,
    predict_response,
    response_values,
)
from sim.errors import ScenarioError
from sim.scenarios import load_scenario
from sim.swarm import SwarmSim
from sim.vehicle import load_profile, respond


def run(cfg, actions, steps, seed=0, envs=4):
    sim, rng = SwarmSim(cfg, scored=False), np.random.default_rng(seed)
    state = sim.initial_state(rng, envs)
    out = []
    for k in range(steps):
        state, result = sim.step(state, actions(k, state), rng)
        out.append((state, result))
    return out


def test_ideal_is_the_default_and_draws_nothing():
    cfg = load_scenario("3u2o")
    assert cfg.dynamics == "ideal" and ResponseSpec.from_scenario(cfg) is None
    assert SwarmSim(cfg).initial_state(np.random.default_rng(0), 2).response is None
    fitted = ResponseSpec.from_scenario(load_scenario("3u2o", dynamics="arducopter"))
    assert fitted is not None
    rng = np.random.default_rng(0)
    fitted.draw(2, 3, rng)  # one profile, no ranges: nothing to draw
    assert rng.random() == np.random.default_rng(0).random()  # nothing consumed


def test_straight_flight_at_cruise_is_the_same_with_any_profile():
    """In steady straight flight the command never changes: no lag shows."""
    zero = lambda k, s: np.zeros(s.heading_rad.shape)  # noqa: E731
    ideal = run(load_scenario("3u1o"), zero, 3)
    lagged = run(load_scenario("3u1o", dynamics="arducopter"), zero, 3)
    for (a, _), (b, _) in zip(ideal, lagged, strict=True):
        np.testing.assert_allclose(a.pos_m, b.pos_m, atol=1e-9)


def test_a_turn_is_flown_late_and_wide_as_the_fitted_model_says():
    """One UAV, one full turn, then straight: the sim's track matches `sim.vehicle.respond`."""
    cfg = load_scenario("2u1o", dynamics="arducopter")
    prof = load_profile("arducopter")
    sim, rng = SwarmSim(cfg, scored=False), np.random.default_rng(0)
    state = sim.initial_state(rng, 1)
    turn = np.array([[1.0, 0.0]])
    h0 = float(state.heading_rad[0, 0])
    vel = [state.vel_m_s[0, 0].copy()]
    for k in range(3):
        state, _ = sim.step(state, turn if k == 0 else np.zeros_like(turn), rng)
        vel.append(state.vel_m_s[0, 0].copy())
    # The same command stream replayed through the fitted model at 10 ms
    dt, v = cfg.dt_s, cfg.uav.speed_m_s
    times = np.arange(0, 3 * dt + 1e-9, 0.01)
    heading = h0 + cfg.uav.max_turn_rad * np.clip(times / dt, 0, 1)
    cmd = v * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    ref = respond(prof, times, cmd, cmd[0])
    at = [round(k * dt / 0.01) for k in range(4)]
    np.testing.assert_allclose(np.array(vel), ref[at], atol=0.15)
    # and the ideal vehicle would already fly the new heading at the end of step 1
    assert abs(math.atan2(vel[1][1], vel[1][0]) - (h0 + cfg.uav.max_turn_rad)) > math.radians(10)


def test_randomisation_is_seeded_and_within_its_ranges():
    cfg = load_scenario(
        "3u2o",
        dynamics="arducopter",
        dynamics_randomisation={
            "profiles": ["arducopter", "px4"],
            "delay_scale": [0.5, 2.0],
            "velocity_tau_scale": [0.8, 1.5],
            "max_accel_scale": [0.7, 1.2],
        },
    )
    spec = ResponseSpec.from_scenario(cfg)
    assert spec is not None
    a = spec.draw(64, 3, np.random.default_rng(5))
    b = spec.draw(64, 3, np.random.default_rng(5))
    np.testing.assert_array_equal(a.tau_s, b.tau_s)
    ardu, px4 = load_profile("arducopter"), load_profile("px4")
    lo_d, hi_d = 0.5 * min(ardu.delay_s, px4.delay_s), 2.0 * max(ardu.delay_s, px4.delay_s)
    assert (a.delay_s >= lo_d).all() and (a.delay_s <= hi_d).all()
    assert len(np.unique(a.accel_m_s2.round(3))) > 100  # per UAV, not per batch
    lo_a, hi_a = 0.7 * ardu.max_accel_m_s2, 1.2 * px4.max_accel_m_s2
    assert (a.accel_m_s2 >= lo_a - 1e-9).all() and (a.accel_m_s2 <= hi_a + 1e-9).all()


def test_a_delay_reaching_the_decision_step_is_refused():
    with pytest.raises(ScenarioError, match="decision step") as err:
        load_scenario(
            "3u2o", dynamics="arducopter", dynamics_randomisation={"delay_scale": [7.0, 7.0]}
        )
    assert err.value.key == "dynamics_randomisation.delay_scale"
    fixed = load_scenario(
        "3u2o", dynamics="arducopter", dynamics_randomisation={"delay_scale": [2.0, 2.0]}
    )
    spec = ResponseSpec.from_scenario(fixed)
    assert spec is not None
    response = spec.draw(1, 3, np.random.default_rng(0))
    np.testing.assert_allclose(response.delay_s, 2.0 * load_profile("arducopter").delay_s)


def test_integration_grid_is_fine_enough():
    assert integration_grid(8, 2.0) * 8 * INTEGRATION_STEP_S >= 2.0 - 1e-9
    assert integration_grid(8, 0.5) == 1


def in_file(arrival, dynamics):
    """One UAV stopping at its target on the line of a second one (no obstacle near)."""
    cfg = load_scenario(
        "2u1o",
        arrival=arrival,
        dynamics=dynamics,
        uav={
            "starts_m": [[100.0, 150.0], [40.0, 150.0]],
            "targets_m": [[160.0, 150.0], [270.0, 150.0]],
        },
    )
    sim, rng = SwarmSim(cfg, scored=False), np.random.default_rng(0)
    state = sim.initial_state(rng, 1)
    state = dataclasses.replace(state, obstacle_pos_m=np.array([[[10_000.0, 0.0]]]))
    results = []
    for _ in range(20):
        state, result = sim.step(state, np.zeros((1, 2)), rng)
        results.append(result)
        if result.terminated.any() or result.truncated.any():
            break
    return cfg, state, results


@pytest.mark.parametrize("dynamics", ["ideal", "arducopter"])
def test_arrived_uavs_hover_and_stay_in_the_separation_checks(dynamics):
    cfg, state, results = in_file("hover", dynamics)
    assert any(r.collided_u2u.any() for r in results), "flew through the hovering UAV"
    assert state.reached[0, 0] and not state.reached[0, 1]
    assert np.isfinite(state.stats.min_u2u_m[0]) and state.stats.min_u2u_m[0] < cfg.d_col_m


def test_under_the_paper_rule_arrived_uavs_leave():
    _, _, results = in_file("leave", "ideal")
    assert results[-1].success.all()


def test_a_speed_command_slows_the_ideal_and_the_fitted_vehicle():
    for dynamics in ("ideal", "px4"):
        cfg = load_scenario("3u1o", dynamics=dynamics)
        sim, rng = SwarmSim(cfg, scored=False), np.random.default_rng(0)
        state = sim.initial_state(rng, 2)
        start = state.pos_m.copy()
        for _ in range(3):
            state, _ = sim.step(state, np.zeros((2, 3)), rng, speeds_m_s=np.full((2, 3), 2.0))
        flown = np.hypot(*(state.pos_m - start).transpose(2, 0, 1))
        assert (flown < 3 * 2.0 * cfg.dt_s + 20.0).all()
        np.testing.assert_allclose(np.hypot(*state.vel_m_s.transpose(2, 0, 1)), 2.0, atol=0.3)


def test_adsb_sensing_shows_late_noisy_intruders_and_is_seeded():
    exact_cfg = load_scenario("3u1o")
    adsb_cfg = load_scenario("3u1o", sensors={"model": "adsb"})
    pictures = []
    for cfg in (exact_cfg, adsb_cfg, adsb_cfg):
        sim, rng = SwarmSim(cfg, scored=False), np.random.default_rng(7)
        state = sim.initial_state(rng, 64)
        for _ in range(4):
            state, _ = sim.step(state, np.zeros((64, 3)), rng)
        pictures.append((sim.observe(state), state))
    (exact, truth), (adsb, state), (again, _) = pictures
    np.testing.assert_array_equal(adsb.rows, again.rows)  # same seed, same picture
    assert state.tracks is not None and truth.tracks is None
    assert not np.allclose(exact.rows, adsb.rows)
    assert np.abs(state.gps_error_m).max() > 0 and np.abs(truth.gps_error_m).max() == 0
    # the tracked intruder lies within a few tens of metres of the truth
    from sim.sensors import picture

    pos, _, valid = picture(state.tracks, (state.steps * adsb_cfg.dt_s)[:, None].astype(float))
    err = np.hypot(*(pos - state.obstacle_pos_m).transpose(2, 0, 1))[valid]
    assert valid.mean() > 0.8 and np.median(err) < 30.0 and err.max() < 120.0


def test_correlated_adsb_errors_load_from_a_scenario_and_a_negative_time_is_refused():
    cfg = load_scenario("3u2o", sensors={"model": "adsb", "adsb_error_tau_s": [10.0, 60.0]})
    assert cfg.sensors.adsb_error_tau_s == (10.0, 60.0)
    assert load_scenario("3u2o").sensors.adsb_error_tau_s == (0.0, 0.0)  # afresh unless asked
    with pytest.raises(ScenarioError) as err:
        load_scenario("3u2o", sensors={"model": "adsb", "adsb_error_tau_s": [-1.0, 5.0]})
    assert err.value.key == "sensors.adsb_error_tau_s"


def test_exactly_sensed_is_the_truth_behind_the_adsb_picture():
    exact_cfg, adsb_cfg = load_scenario("3u1o"), load_scenario("3u1o", sensors={"model": "adsb"})
    sim, rng = SwarmSim(adsb_cfg, scored=False), np.random.default_rng(7)
    state = sim.initial_state(rng, 16)
    for _ in range(4):
        state, _ = sim.step(state, np.zeros((16, 3)), rng)
    truth = state.exactly_sensed()
    assert state.tracks is not None and np.abs(state.gps_error_m).max() > 0
    assert truth.tracks is None and not truth.gps_error_m.any()
    assert truth.pos_m is state.pos_m and truth.obstacle_pos_m is state.obstacle_pos_m
    assert state.tracks is not None and state.gps_error_m.any()  # the state itself is unchanged
    # seen through exact sensors: the intruder rows are the truth, the ADS-B rows are not
    exact_sim = SwarmSim(exact_cfg, scored=False)
    np.testing.assert_array_equal(sim.observe(truth).rows, exact_sim.observe(truth).rows)
    assert not np.allclose(sim.observe(state).rows, sim.observe(truth).rows)
    exact_state = exact_sim.initial_state(np.random.default_rng(7), 2)
    assert exact_state.exactly_sensed() is exact_state


def test_perfect_adsb_is_exact_sensing_up_to_the_report_lag():
    perfect = {
        "model": "adsb",
        "adsb_rate_hz": [1000.0, 1000.0],
        "adsb_latency_s": [0.0, 0.0],
        "adsb_epu_m": [0.0, 0.0],
        "adsb_nacv_m_s": 0.0,
        "adsb_drop_probability": 0.0,
        "gps_sigma_m": 0.0,
    }
    outs = []
    for cfg in (load_scenario("3u2o"), load_scenario("3u2o", sensors=perfect)):
        sim, rng = SwarmSim(cfg, scored=False), np.random.default_rng(3)
        state = sim.initial_state(rng, 16)
        for _ in range(3):
            state, _ = sim.step(state, np.zeros((16, 3)), rng)
        outs.append(sim.observe(state).rows)
    np.testing.assert_allclose(outs[0], outs[1], atol=1e-3)


@settings(max_examples=25, deadline=None)
@given(
    name=st.sampled_from(["arducopter", "px4", "px4-sluggish", "responsive"]),
    heading=st.floats(-math.pi, math.pi),
    last_turn=st.floats(-1.0, 1.0),
    last_speed=st.sampled_from([0.0, 5.0, 10.0]),
    turn=st.floats(-1.0, 1.0),
    first=st.floats(0.0, 10.0),
    then=st.sampled_from([0.0, 10.0]),
)
def test_a_predicted_response_is_the_track_the_vehicle_flies(
    name, heading, last_turn, last_speed, turn, first, then
):
    """`predict_response` against the decision's command stream replayed at 10 ms: within
    1.5 m at every point (the simulator's own 0.25 s integration, which takes the delayed
    command at the middle of each step: 1.05 m for PX4 from rest); and its closed-form tail
    within 0.05 m of flying on step by step."""
    prof = load_profile(name)
    dt, a_max = 2.0, math.pi / 4
    _, ref, vel0 = dense_track(
        prof, heading, last_turn * a_max, last_speed, turn * a_max, first, then, dt, 25.0
    )
    motion = Motion(
        vel0[None],
        np.array([last_turn * a_max]),
        np.array([last_speed]),
        np.array([prof.delay_s]),
        np.array([prof.velocity_tau_s]),
        np.array([prof.max_accel_m_s2]),
    )
    later = np.array([4.0, 10.0, 25.0])
    x, y = predict_response(
        np.array([heading]), np.array([[turn * a_max]]), first, then, motion, dt, 2, later
    )
    at = [round(s / 0.01) for s in (0.0, 1.0, 2.0, *later)]
    np.testing.assert_allclose(np.stack([x[0, 0], y[0, 0]], -1), ref[at], atol=1.5)
    knots = np.array([4.0, 8.0, 12.0, 24.0])
    args = (np.array([heading]), np.array([[turn * a_max]]), first, then, motion, dt, 2, knots)
    tail = np.stack(predict_response(*args))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sim_dynamics, "PREDICTED_STEPS", 12)
        flown = np.stack(predict_response(*args))
    np.testing.assert_allclose(tail, flown, atol=0.05)


@pytest.mark.parametrize("profile", ["arducopter", "px4"])
@pytest.mark.parametrize("second", [-1.0, 0.0, 1.0])
def test_a_turn_in_the_next_step_is_flown_as_the_replay_flies_it(profile, second):
    """The next step's arc (`predict_response`'s ``second_rad``, the shield's turns held over
    two steps) against the command stream replayed at 10 ms, at its chord and after it; no
    second turn is the prediction without one, exactly."""
    prof = load_profile(profile)
    a_max, dt = math.pi / 4, 2.0
    _, ref, vel0 = dense_track(prof, 0.3, 0.0, 10.0, a_max, 10.0, 10.0, dt, 25.0, second * a_max)
    motion = Motion(
        vel0[None], np.zeros(1), np.full(1, 10.0), np.array([prof.delay_s]),
        np.array([prof.velocity_tau_s]), np.array([prof.max_accel_m_s2]),
    )  # fmt: skip
    later = np.array([3.0, 4.0, 10.0, 25.0])
    turn = np.array([[a_max]])
    args = (np.full(1, 0.3), turn, 10.0, 10.0, motion, dt, 2, later)
    x, y = predict_response(*args, second_rad=np.array([[second * a_max]]))
    at = np.rint(np.concatenate([[0.0, 1.0, 2.0], later]) / 0.01).astype(int)
    gap = np.hypot(x[0, 0] - ref[at, 0], y[0, 0] - ref[at, 1])
    assert gap.max() < 1.5, gap
    if second == 0.0:
        plain = predict_response(*args)
        assert np.array_equal(plain[0], x) and np.array_equal(plain[1], y)


def test_between_the_steps_flown_a_prediction_is_the_chord_and_a_stop_is_braked():
    """An instant between two chords of the next step lies on the chord between them; a
    commanded stop from 10 m/s still coasts metres (what the ideal vehicle, stopping at once,
    never does)."""
    prof = load_profile("arducopter")
    motion = Motion(
        np.array([[10.0, 0.0]]), np.zeros(1), np.full(1, 10.0), np.full(1, prof.delay_s),
        np.full(1, prof.velocity_tau_s), np.full(1, prof.max_accel_m_s2),
    )  # fmt: skip
    x, y = predict_response(
        np.zeros(1), np.array([[0.5, 0.0]]), 0.0, 10.0, motion, 2.0, 2, np.array([2.5, 3.0])
    )
    np.testing.assert_allclose(x[..., 3], 0.5 * (x[..., 2] + x[..., 4]))
    np.testing.assert_allclose(y[..., 3], 0.5 * (y[..., 2] + y[..., 4]))
    assert (np.hypot(x[..., 2], y[..., 2]) > 5.0).all()


@settings(max_examples=25, deadline=None)
@given(
    name=st.sampled_from(["arducopter", "px4", "px4-sluggish", "responsive"]),
    speed=st.floats(0.0, 15.0),
    course=st.floats(-math.pi, math.pi),
    elapsed=st.floats(0.0, 12.0),
)
def test_a_vehicle_told_to_stop_brakes_as_the_replayed_model_does(name, speed, course, elapsed):
    """`brake` in closed form against the stop command replayed through `sim.vehicle.respond`
    at 10 ms: where it is, how fast, and how long of the time it was still moving."""
    prof = load_profile(name)
    v0 = speed * np.array([math.cos(course), math.sin(course)])
    t, pos, vel = dense_stop(prof, v0, elapsed)
    got = brake(v0[None], *(np.full(1, x) for x in response_values(prof)), np.full(1, elapsed))
    # (the replay's command changes on its 10 ms grid: up to a sample of full speed later)
    np.testing.assert_allclose(got.disp_m[0], pos[-1], atol=0.01 * speed + 0.01)
    np.testing.assert_allclose(got.vel_m_s[0], vel[-1], atol=0.01 * prof.max_accel_m_s2 + 0.01)
    moving = np.hypot(vel[:, 0], vel[:, 1]) > AT_REST_M_S
    last = t[moving][-1] if moving.any() else 0.0
    assert got.moving_s[0] <= elapsed + 1e-9
    assert abs(got.moving_s[0] - min(last, elapsed)) < 0.05


def dense_stop(prof, v0, elapsed):
    """(times, positions, velocities) of a stop commanded at 0 from ``v0``, at 10 ms."""
    t = np.arange(-1.0, elapsed + 0.005, 0.01)
    cmd = np.where((t < 0)[:, None], v0, 0.0)
    vel = respond(prof, t, cmd, v0)[t > -0.005]
    steps = 0.5 * (vel[1:] + vel[:-1]) * 0.01
    return t[t > -0.005], np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)]), vel


def test_from_full_speed_a_fitted_arducopter_stops_in_23_m():
    """The figure the runtime relies on for a peer told to hold (`remarl_fc.flight.control`)."""
    got = brake(
        np.array([[0.0, 10.0]]),
        *(np.full(1, x) for x in response_values(load_profile("arducopter"))),
        np.full(1, 60.0),
    )
    np.testing.assert_allclose(got.disp_m, [[0.0, 23.3]], atol=0.05)
    np.testing.assert_allclose(got.vel_m_s, 0.0, atol=1e-9)
    assert 4.5 < got.moving_s[0] < 5.5
