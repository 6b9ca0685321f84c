"""The generalist's torch network against its numpy twin, its invariances, and a tiny run."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from tiny_policy import tiny_suite

from policies.config import GeneralistConfig
from policies.generalist import AgentReplay, SetNet, TD3Nets, td3_update
from policies.generalist_train import separation_penalty, train_generalist
from sim.observation import INTRUDER_COLUMNS, NEIGHBOUR_COLUMNS, ObservationLayout
from sim.setnet import POOLINGS, set_actor, set_critic, set_layers

LAYOUT = ObservationLayout(8, 100.0, np.radians(270), 5.0, max_neighbours=6, version=2)


def random_obs(rng: np.random.Generator, count: int, layout: ObservationLayout = LAYOUT):
    """Flat v2 observations with random rows and random masks (masked rows zeroed)."""
    obs = rng.normal(0, 1, (count, layout.size)).astype(np.float32)
    bl = layout.blocks()
    nb_mask = rng.random((count, layout.max_neighbours)) < 0.6
    in_mask = rng.random((count, layout.max_obstacles)) < 0.5
    obs[:, bl["neighbour_mask"]] = nb_mask
    obs[:, bl["intruder_mask"]] = in_mask
    nb = obs[:, bl["neighbours"]].reshape(count, -1, NEIGHBOUR_COLUMNS)
    nb *= nb_mask[..., None]
    it = obs[:, bl["intruders"]].reshape(count, -1, INTRUDER_COLUMNS)
    it *= in_mask[..., None]
    return obs


def numpy_params(net: SetNet):
    state = net.numpy_state()
    return {
        name: (state[f"{name}.weight"], state[f"{name}.bias"]) for name in set_layers(net.pooling)
    }


def permuted(obs: np.ndarray, rng: np.random.Generator, layout: ObservationLayout = LAYOUT):
    """The same observations with the neighbour and intruder rows (and masks) shuffled."""
    out = obs.copy()
    bl = layout.blocks()
    for rows, mask, width in (
        ("neighbours", "neighbour_mask", NEIGHBOUR_COLUMNS),
        ("intruders", "intruder_mask", INTRUDER_COLUMNS),
    ):
        block = out[:, bl[rows]].reshape(len(out), -1, width)
        order = rng.permutation(block.shape[1])
        out[:, bl[rows]] = block[:, order].reshape(len(out), -1)
        out[:, bl[mask]] = out[:, bl[mask]][:, order]
    return out


@pytest.mark.parametrize("pooling", POOLINGS)
def test_torch_and_numpy_networks_agree(pooling):
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    obs = random_obs(rng, 64)
    actor = SetNet(LAYOUT, 32, critic=False, pooling=pooling)
    critic = SetNet(LAYOUT, 32, critic=True, pooling=pooling)
    for p in (*actor.parameters(), *critic.parameters()):  # beyond the near-zero output init
        torch.nn.init.normal_(p, 0.0, 0.3)
    action = rng.uniform(-1, 1, 64).astype(np.float32)
    with torch.no_grad():
        a_torch = actor(torch.from_numpy(obs)).numpy()
        q_torch = critic(torch.from_numpy(obs), torch.from_numpy(action)).numpy()
    np.testing.assert_allclose(set_actor(numpy_params(actor), obs, LAYOUT), a_torch, atol=1e-5)
    q_numpy = set_critic(numpy_params(critic), obs, action, LAYOUT)
    np.testing.assert_allclose(q_numpy, q_torch, rtol=1e-4, atol=1e-4)


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), pooling=st.sampled_from(POOLINGS))
def test_action_does_not_depend_on_the_order_of_rows(seed, pooling):
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed % 1000)
    net = SetNet(LAYOUT, 16, critic=False, pooling=pooling)
    for p in net.parameters():
        torch.nn.init.normal_(p, 0.0, 0.5)
    params = numpy_params(net)
    obs = random_obs(rng, 8)
    shuffled = permuted(obs, rng)
    np.testing.assert_allclose(
        set_actor(params, shuffled, LAYOUT), set_actor(params, obs, LAYOUT), atol=1e-6
    )
    with torch.no_grad():
        a = net(torch.from_numpy(obs)).numpy()
        b = net(torch.from_numpy(shuffled)).numpy()
    np.testing.assert_allclose(a, b, atol=1e-5)  # float32 products: rounding by position


@pytest.mark.parametrize("pooling", POOLINGS)
def test_empty_sets_and_masked_rows_count_for_nothing(pooling):
    rng = np.random.default_rng(3)
    net = SetNet(LAYOUT, 16, critic=False, pooling=pooling)
    for p in net.parameters():
        torch.nn.init.normal_(p, 0.0, 0.5)
    params = numpy_params(net)
    obs = random_obs(rng, 4)
    bl = LAYOUT.blocks()
    obs[:, bl["neighbour_mask"]] = 0.0
    obs[:, bl["intruder_mask"]] = 0.0
    junk = obs.copy()  # whatever a masked row holds is ignored
    junk[:, bl["neighbours"]] = rng.normal(0, 5, junk[:, bl["neighbours"]].shape)
    junk[:, bl["intruders"]] = rng.normal(0, 5, junk[:, bl["intruders"]].shape)
    np.testing.assert_allclose(set_actor(params, junk, LAYOUT), set_actor(params, obs, LAYOUT))


@pytest.mark.parametrize("pooling", POOLINGS)
def test_no_neighbour_rows_at_all(pooling):
    layout = ObservationLayout(2, 100.0, np.radians(270), 5.0, max_neighbours=0, version=2)
    net = SetNet(layout, 8, critic=False, pooling=pooling)
    obs = random_obs(np.random.default_rng(0), 5, layout)
    with torch.no_grad():
        a = net(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(set_actor(numpy_params(net), obs, layout), a, atol=1e-6)


@given(
    d=st.floats(0.0, 200.0, allow_nan=False),
    weight=st.floats(0.0, 5.0),
    factor=st.floats(1.01, 3.0),
)
def test_separation_penalty_is_bounded_and_monotone(d, weight, factor):
    d_col = 20.0
    p = float(separation_penalty(np.array([d]), d_col, weight, factor)[0])
    assert 0.0 <= p <= weight + 1e-12
    if d <= d_col:
        assert p == pytest.approx(weight)
    if d >= factor * d_col:
        assert p == 0.0
    closer = float(separation_penalty(np.array([0.9 * d]), d_col, weight, factor)[0])
    assert closer >= p - 1e-12


TWO_FAMILIES = """
name = "two"
version = 1
episodes = 4
seed = 1

[[family]]
name = "paper-3u2o"
distribution = "scenario"
scenario = "3u2o"

[[family]]
name = "swarms-2x3"
distribution = "swarms"
uavs = 6
formation = "wedge"
"""


def two_worlds(tmp_path, **changes):
    from policies.generalist_train import make_worlds

    suite = tmp_path / "two.toml"
    suite.write_text(TWO_FAMILIES)
    cfg = GeneralistConfig(suites=(str(suite),), **changes)
    worlds = {w.family.name: w for w in make_worlds(cfg, LAYOUT, np.random.default_rng(0))}
    return cfg, worlds


def test_predicted_closest_approach_is_the_sampled_minimum_over_the_horizon(tmp_path):
    from policies.generalist_train import predicted_closest_approach

    world = two_worlds(tmp_path)[1]["paper-3u2o"]
    b, n, m = world.envs, world.state.pos_m.shape[1], world.state.obstacle_pos_m.shape[1]

    @settings(max_examples=30, deadline=None)
    @given(seed=st.integers(0, 2**31 - 1), horizon=st.floats(0.0, 8.0))
    def check(seed, horizon):
        rng = np.random.default_rng(seed)
        state = world.state.evolve(
            pos_m=rng.uniform(-100, 100, (b, n, 2)),
            vel_m_s=rng.uniform(-10, 10, (b, n, 2)),
            obstacle_pos_m=rng.uniform(-100, 100, (b, m, 2)),
            obstacle_vel_m_s=rng.uniform(-15, 15, (b, m, 2)),
            obstacle_appear_step=rng.integers(0, 3, (b, m)),
            steps=rng.integers(0, 3, b),
        )
        present = rng.random((b, n)) < 0.7
        got = predicted_closest_approach(state, present, horizon)
        t = np.linspace(0.0, horizon, 2001)[:, None, None, None]  # (T, 1, 1, 1)
        uav = state.pos_m[None] + t * state.vel_m_s[None]  # (T, B, N, 2)
        obs = state.obstacle_pos_m[None] + t * state.obstacle_vel_m_s[None]  # (T, B, M, 2)
        seen = state.obstacle_appear_step <= state.steps[:, None]
        for i in range(n):
            own = uav[:, :, i : i + 1]
            d_uav = np.hypot(*np.moveaxis(uav - own, -1, 0)).min(axis=0)  # (B, N)
            d_obs = np.hypot(*np.moveaxis(obs - own, -1, 0)).min(axis=0)  # (B, M)
            others = present.copy()
            others[:, i] = False
            want = np.minimum(
                np.where(others, d_uav, np.inf).min(axis=1),
                np.where(seen, d_obs, np.inf).min(axis=1),
            )
            np.testing.assert_allclose(got[:, i], want, atol=0.05)

    check()


def test_the_separation_horizon_charges_a_conflict_before_it_is_close(tmp_path):
    from policies.generalist_train import advance_world

    def rewards(horizon):
        cfg, worlds = two_worlds(tmp_path, separation_horizon_s=horizon)
        world, rng = worlds["swarms-2x3"], np.random.default_rng(1)
        out = []
        for _ in range(3):  # straight ahead, still far apart: the routes cross later
            straight = np.zeros(world.state.active.shape, np.float32)
            step, _ = advance_world(world, straight, cfg, 1.0, rng)
            out.append(step.reward[step.acted].sum())
        return np.array(out)

    now, ahead = rewards(0.0), rewards(60.0)
    assert (ahead <= now + 1e-5).all() and ahead.sum() < now.sum() - 0.5


def test_td3_update_lowers_the_critic_loss_on_a_fixed_batch():
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    cfg = GeneralistConfig(hidden=16, batch_size=64, critic_lr=3e-3)
    nets = TD3Nets.create(LAYOUT, cfg, "cpu")
    buffer = AgentReplay(256, LAYOUT.size)
    obs = random_obs(rng, 256)
    buffer.add(
        obs=obs,
        next_obs=obs,
        action=rng.uniform(-1, 1, 256).astype(np.float32),
        reward=rng.normal(0, 1, 256).astype(np.float32),
        terminal=np.ones(256, dtype=bool),
        terminal_value=np.zeros(256, dtype=np.float32),
    )
    batch = buffer.sample(256, rng, "cpu")
    first = td3_update(nets, batch, cfg, update_actor=True)["losses/critic"]
    for k in range(60):
        last = td3_update(nets, batch, cfg, update_actor=k % 2 == 0)["losses/critic"]
    assert last < 0.5 * first


def test_replay_wraps_around():
    buffer = AgentReplay(5, 3)
    for k in range(3):
        buffer.add(
            obs=np.full((3, 3), k, np.float32),
            next_obs=np.zeros((3, 3), np.float32),
            action=np.zeros(3, np.float32),
            reward=np.full(3, k, np.float32),
            terminal=np.zeros(3, bool),
            terminal_value=np.zeros(3, np.float32),
        )
    assert buffer.size == 5 and buffer.pos == 4
    assert sorted(buffer.reward.tolist()) == [1, 1, 2, 2, 2]


def tiny_td3(tmp_path: Path, **changes: Any) -> GeneralistConfig:
    """A TD3 run of a few seconds on the tiny suite, counted in iterations (no budget)."""
    settings: dict[str, Any] = {
        "suites": (str(tiny_suite(tmp_path)),),
        "learner": "td3",
        "teacher": "none",
        "agents_per_family": 4,
        "hidden": 8,
        "batch_size": 32,
        "buffer_size": 5_000,
        "warmup_transitions": 40,
        "updates_per_iteration": 1,
        "minutes": 0.0,
        "eval_episodes": 2,
        "device": "cpu",
    }
    return GeneralistConfig(**{**settings, **changes})


def test_real_world_families_take_the_runs_adsb_errors_track_filter_and_arrival(tmp_path):
    from policies.generalist_train import generalist_layout, make_worlds
    from sim.encounters import SUITE_ARRIVAL, family_scenario
    from sim.suite import load_suite

    for tau, filtered, hover in (((0.0, 0.0), False, False), ((10.0, 120.0), True, True)):
        cfg = tiny_td3(
            tmp_path,
            real_share=1.0,
            real_error_tau_s=tau,
            real_track_filter=filtered,
            real_hover=hover,
        )
        base = family_scenario(load_suite(cfg.suites[0]).families[0])
        worlds = make_worlds(cfg, generalist_layout(cfg, base), np.random.default_rng(0))
        assert worlds and all(w.real for w in worlds)
        assert {w.cfg.sensors.model for w in worlds} == {"adsb"}
        assert {w.cfg.sensors.adsb_error_tau_s for w in worlds} == {tau}
        assert {w.cfg.sensors.adsb_filter for w in worlds} == {filtered}
        assert {w.cfg.arrival for w in worlds} == {"hover" if hover else SUITE_ARRIVAL}


def test_tiny_generalist_run_trains_checkpoints_and_resumes(tmp_path):
    cfg = tiny_td3(tmp_path, total_iterations=30, eval_minutes=1e-6, real_share=0.5)
    out = tmp_path / "run"
    summary = train_generalist(cfg, out)
    assert summary["iterations"] == 30 and summary["updates"] > 0
    assert (out / "last.safetensors").is_file() and (out / "best.safetensors").is_file()
    evals = [json.loads(line) for line in (out / "evals.jsonl").read_text().splitlines()]
    assert evals and set(evals[-1]["families"]) <= {"crossing-2u", "paper-2u1o"}
    worlds = json.loads((out / "config.json").read_text())["worlds"]
    assert [w["envs"] for w in worlds] == [2, 2]
    again = train_generalist(
        GeneralistConfig(**{**cfg.__dict__, "total_iterations": 35}), out, resume=True
    )
    assert again["iterations"] == 35 and again["updates"] > summary["updates"]


def test_a_run_ending_between_validations_validates_its_final_networks(tmp_path):
    """The training after the last periodic validation is flown once at the end (and only
    once: a resumed run with nothing left to train adds no validation of the same networks)."""
    # no periodic validation falls inside the run
    cfg = tiny_td3(tmp_path, total_iterations=6, eval_minutes=1e6)
    out = tmp_path / "run"
    summary = train_generalist(cfg, out)
    evals = [json.loads(line) for line in (out / "evals.jsonl").read_text().splitlines()]
    assert [e["iteration"] for e in evals] == [6]
    assert summary["last_eval"]["iteration"] == 6
    assert summary["best_success"] == evals[0]["success_mean"] >= 0
    train_generalist(cfg, out, resume=True)
    assert len((out / "evals.jsonl").read_text().splitlines()) == 1


def test_the_summary_line_says_what_the_validations_showed():
    from remarl_fc.cli.learn import validation_line

    last = {"success_mean": 0.5, "elapsed_s": 90.0}
    line = validation_line({"best_success": 0.75, "last_eval": last})
    assert line == "best validation success 75.0%, final 50.0% at 1.5 min"
    assert "not validated" in validation_line({"best_success": -1.0})
    assert validation_line({"best_success": 0.25}) == "best validation success 25.0%"
    nan = {"success_mean": float("nan"), "elapsed_s": 1.0}
    assert "not validated" in validation_line({"best_success": -1.0, "last_eval": nan})


def test_a_generalist_run_exports_a_policy_fly_can_load_for_any_n(tmp_path):
    from policies.generalist_train import export_generalist_run
    from remarl_fc.policy_io import load_policy
    from sim.scenarios import load_scenario
    from sim.swarm import SwarmSim

    suite = tiny_suite(tmp_path)
    cfg = GeneralistConfig(
        suites=(str(suite),),
        learner="td3",
        teacher="none",
        agents_per_family=2,
        hidden=8,
        batch_size=16,
        warmup_transitions=10,
        updates_per_iteration=1,
        minutes=0.0,
        total_iterations=5,
        eval_episodes=1,
        device="cpu",
    )
    run = tmp_path / "run"
    train_generalist(cfg, run)
    out = tmp_path / "generalist.safetensors"
    meta = export_generalist_run(run, out, checkpoint="last", metrics={"success_rate": 0.5})
    assert meta["network"] == "set" and meta["uavs"] == [1, 50]
    policy = load_policy(str(out))
    assert policy.generalist and policy.uav_range == (1, 50)
    for scenario in ("2u1o", "7u2o", "50u8o"):
        scen = load_scenario(scenario)
        policy.check_scenario(scen)
        sim = SwarmSim(scen, scored=False)
        state = sim.initial_state(np.random.default_rng(0), 2)
        actions = policy.act(sim.observe(state, layout=policy.layout).flat())
        assert actions.shape == (2, scen.uav.count) and np.isfinite(actions).all()


def test_a_teacher_run_flies_the_teacher_clones_it_then_fine_tunes(tmp_path, monkeypatch):
    from test_generalist_ppo import spy_teacher_horizons

    horizons = spy_teacher_horizons(monkeypatch)
    suite = tiny_suite(tmp_path)
    cfg = GeneralistConfig(
        suites=(str(suite),),
        agents_per_family=4,
        hidden=8,
        batch_size=32,
        learner="td3",
        teacher="orca-shield",
        teacher_transitions=200,
        teacher_horizon_s=14,
        bc_updates=20,
        updates_per_iteration=1,
        minutes=0.0,
        total_iterations=4,
        eval_episodes=2,
        device="cpu",
    )
    seen: list[dict[str, float]] = []
    summary = train_generalist(cfg, tmp_path / "run", progress=seen.append)
    assert seen and "teacher/success" in seen[0] and seen[0]["losses/clone"] > 0
    assert summary["iterations"] == 4
    assert horizons and set(horizons) == {14}  # the run's horizon, not ORCA's own
    evals = (tmp_path / "run" / "evals.jsonl").read_text().splitlines()
    assert json.loads(evals[0])["iteration"] == 1  # the clone is validated at once


def test_the_run_sets_how_far_and_how_wide_the_observation_sees():
    """The layout takes the run's range and aperture (else the scenario's), and the training
    worlds — the teacher's sensing with them — are built with the layout's."""
    import math

    from policies.generalist_train import generalist_layout, with_layout
    from sim.scenarios import load_scenario
    from sim.swarm import SwarmSim

    base = load_scenario("3u2o")
    plain = generalist_layout(GeneralistConfig(sensing_range_m=0, sensing_aperture_deg=0), base)
    assert (plain.range_m, plain.aperture_rad) == (base.sensing.range_m, base.sensing.aperture_rad)
    wide = generalist_layout(GeneralistConfig(sensing_range_m=300), base)
    assert (wide.range_m, wide.aperture_rad) == (300.0, 2 * math.pi)  # all around by default
    cfg = with_layout(base, wide)
    assert (cfg.sensing.range_m, cfg.sensing.aperture_rad) == (300.0, 2 * math.pi)
    # an intruder 200 m behind a UAV: outside the scenario's 100 m forward sector, inside the run's
    sim = SwarmSim(cfg)
    state = sim.initial_state(np.random.default_rng(0), 1)
    behind = state.pos_m[:, 0] - 200.0 * np.stack(
        [np.cos(state.heading_rad[:, 0]), np.sin(state.heading_rad[:, 0])], axis=-1
    )
    state.obstacle_pos_m[:, 0] = behind
    state.obstacle_pos_m[:, 1] = behind + 5_000.0  # out of any range
    seen = sim.observe(state, layout=wide).flat()[0, 0, wide.blocks()["intruder_mask"]]
    assert seen.tolist() == [1.0] + [0.0] * (wide.max_obstacles - 1)
    narrow = sim.observe(state, layout=plain).flat()[0, 0, plain.blocks()["intruder_mask"]]
    assert not narrow.any()


def test_the_teacher_is_orca_through_the_shield():
    from policies.generalist_train import World, teacher_actions, with_layout
    from sim.scenarios import load_scenario
    from sim.swarm import SwarmSim

    cfg = with_layout(load_scenario("3u2o"), LAYOUT)
    sim = SwarmSim(cfg)
    state = sim.initial_state(np.random.default_rng(0), 3)
    world = World(None, cfg, False, sim, state, sim.observe(state).flat(), 3)  # type: ignore[arg-type]
    # a few steps in, so ORCA turns and the shield has something to check
    for _ in range(4):
        state, _ = sim.step(state, np.zeros((3, 3), np.float32), np.random.default_rng(0))
    world.state = state
    actions = teacher_actions(world, "orca-shield")
    assert actions.shape == (3, 3) and (np.abs(actions) <= 1).all()
    from sim.orca import orca_actions
    from sim.shield import ShieldConfig, shield_state, vehicle_of

    orca = orca_actions(state, cfg)
    straight_only = dataclasses.replace(vehicle_of(cfg), can_slow=False)
    expected = shield_state(ShieldConfig(mode="on"), cfg, state, orca, straight_only).action
    np.testing.assert_array_equal(actions, expected)
    assert not np.array_equal(actions, np.zeros_like(actions))  # not a constant stand-in


def test_a_privileged_teacher_reads_the_truth_where_the_uavs_sense_adsb():
    from policies.generalist_train import (
        TEACHER_TRACK_GROWTH_M_S,
        World,
        teacher_actions,
        with_layout,
    )
    from sim.orca import orca_actions
    from sim.scenarios import REAL_WORLD, load_scenario
    from sim.shield import ShieldConfig, shield_state, vehicle_of
    from sim.swarm import SwarmSim

    cfg = with_layout(load_scenario("3u2o", **REAL_WORLD), LAYOUT)
    sim, rng = SwarmSim(cfg), np.random.default_rng(2)
    state = sim.initial_state(rng, 32)
    for _ in range(4):  # the first reports are in; the intruders are still ahead
        state, _ = sim.step(state, np.zeros((32, 3), np.float32), rng)
    world = World(None, cfg, True, sim, state, sim.observe(state).flat(), 32)  # type: ignore[arg-type]
    straight_only = dataclasses.replace(vehicle_of(cfg), can_slow=False)

    def through_shield(seen):  # the teachers' shield: its own track growth
        orca = orca_actions(state, cfg)
        shield = ShieldConfig(mode="on", track_growth_m_s=TEACHER_TRACK_GROWTH_M_S)
        return shield_state(shield, cfg, seen, orca, straight_only)

    sensed, truth = through_shield(state), through_shield(state.exactly_sensed())
    np.testing.assert_array_equal(teacher_actions(world, "orca-shield"), sensed.action)
    np.testing.assert_array_equal(teacher_actions(world, "orca-shield", truth=True), truth.action)
    assert not np.array_equal(sensed.action, truth.action)  # the tracks' noise moves its turns


def test_the_teacher_turns_for_an_intruder_as_far_ahead_as_its_horizon_reaches():
    from policies.generalist_train import World, teacher_actions, with_layout
    from sim.orca import orca_actions
    from sim.scenarios import load_scenario
    from sim.swarm import SwarmSim

    wide = dataclasses.replace(LAYOUT, range_m=200.0, aperture_rad=2 * np.pi)
    cfg = with_layout(load_scenario("3u2o"), wide)
    sim = SwarmSim(cfg)
    state = sim.initial_state(np.random.default_rng(0), 1)
    heading = state.heading_rad[0, 0]
    ahead = np.array([np.cos(heading), np.sin(heading)])
    # the UAV flies at its target; the other UAVs and the second intruder are far away
    state.target_m[0, 0] = state.pos_m[0, 0] + 800.0 * ahead
    state.pos_m[0, 1:] = state.pos_m[0, 0] + [[0.0, 5_000.0], [0.0, -5_000.0]]
    state.target_m[0, 1:] = state.pos_m[0, 1:]
    state.obstacle_pos_m[0, 1] = state.pos_m[0, 0] - 5_000.0 * ahead
    # a head-on intruder 170 m ahead, closing at 12.5 m/s: at d_col in 12 s
    state.obstacle_pos_m[0, 0] = state.pos_m[0, 0] + 170.0 * ahead
    state.obstacle_vel_m_s[0, 0] = -state.obstacle_speed_m_s[0, 0] * ahead
    world = World(None, cfg, False, sim, state, sim.observe(state).flat(), 1)  # type: ignore[arg-type]
    assert orca_actions(state, cfg, horizon_s=10.0)[0, 0] == 0.0  # not yet in ORCA's view
    assert orca_actions(state, cfg, horizon_s=20.0)[0, 0] != 0.0  # ORCA alone turns at 20 s
    assert teacher_actions(world, "orca-shield", horizon_s=20.0)[0, 0] != 0.0  # already turning
    # behind ORCA the shield looks 25 s ahead of an exactly sensed intruder: it turns too
    assert teacher_actions(world, "orca-shield", horizon_s=10.0)[0, 0] != 0.0


def test_the_oracle_teacher_flies_its_plans_and_orca_through_the_shield_where_it_has_none(
    monkeypatch,
):
    import policies.generalist_train as generalist_train
    from policies.generalist_train import World, teacher_actions, with_layout
    from sim.scenarios import load_scenario
    from sim.swarm import SwarmSim

    cfg = with_layout(load_scenario("3u2o"), LAYOUT)
    sim = SwarmSim(cfg)
    state = sim.initial_state(np.random.default_rng(0), 3)
    for _ in range(4):
        state, _ = sim.step(state, np.zeros((3, 3), np.float32), np.random.default_rng(0))
    world = World(None, cfg, False, sim, state, sim.observe(state).flat(), 3)  # type: ignore[arg-type]
    planned = np.array([True, False, True])
    plans = np.full((3, 3), 0.25, np.float32)
    monkeypatch.setattr(generalist_train, "oracle_actions", lambda s, c: (plans, planned))
    taught = teacher_actions(world, "oracle")
    np.testing.assert_array_equal(taught[planned], plans[planned])
    np.testing.assert_array_equal(taught[1], teacher_actions(world, "orca-shield")[1])
    monkeypatch.undo()
    real = teacher_actions(world, "oracle")  # the oracle itself, from this mid-flight state
    assert real.shape == (3, 3) and (np.abs(real) <= 1).all()


def test_family_weights_scale_a_familys_environments():
    from policies.generalist_train import family_weight, make_worlds

    cfg = GeneralistConfig(
        suites=("standard",), family_weights=(("swarms-*", 3.0), ("swarms-2x3", 9.0))
    )
    assert family_weight(cfg, "swarms-2x3") == 3.0  # the first pattern that matches
    assert family_weight(cfg, "paper-3u2o") == 1.0
    worlds = {w.family.name: w for w in make_worlds(cfg, LAYOUT, np.random.default_rng(0))}
    assert worlds["swarms-2x3"].envs == 12 and worlds["swarms-2x5"].envs == 8  # ceil(72 / N)
    assert worlds["paper-3u2o"].envs == 8
    with pytest.raises(ValueError, match="family_weights"):
        GeneralistConfig(family_weights=(("swarms-*", 0.0),))


def test_swarm_field_formation_drops_the_peak_where_no_one_formation_flies():
    from policies.generalist_train import make_worlds

    def peaks(swarm_field):
        cfg = GeneralistConfig(suites=("standard",), swarm_field=swarm_field)
        worlds = make_worlds(cfg, LAYOUT, np.random.default_rng(0))
        return {w.family.name: w.cfg.field.swarm_peak for w in worlds}

    assert all(peaks("all").values())  # the paper's reward everywhere
    formation = peaks("formation")
    no_peak = {name for name, peak in formation.items() if not peak}
    assert no_peak == {
        "swarms-2x3",
        "swarms-2x5",
        "converging-5u",
        "diverging-5u",
        "random-paths-7u",
    }
    assert formation["paper-3u2o"] and formation["random-formation-5u"]
    with pytest.raises(ValueError, match="swarm_field"):
        GeneralistConfig(swarm_field="none")


@pytest.mark.parametrize("text", ["swarms-*", "=3", "swarms-*=x", "swarms-*=-1", "a=nan"])
def test_a_bad_family_weight_flag_says_what_to_write(text):
    from remarl_fc.cli.learn import family_weight_arg
    from remarl_fc.errors import ConfigError

    with pytest.raises(ConfigError, match="PATTERN=W"):
        family_weight_arg(text)
    assert family_weight_arg("swarms-*=2.5") == ("swarms-*", 2.5)


@pytest.mark.parametrize(
    ("flag", "value", "setting"),
    [
        ("--bc-fraction", "0", "bc_fraction"),
        ("--ppo-min-std", "2", "ppo_min_std"),
        ("--separation-weight", "-1", "separation_weight"),
        ("--dagger-fraction", "1.5", "dagger_fraction"),
        ("--dagger-fraction 0.5 --teacher", "none", "dagger_fraction"),  # asked, cannot apply
        ("--dagger-fraction 0.5 --learner", "td3", "dagger_fraction"),
        ("--sensing-range", "-5", "sensing_range_m"),
        ("--sensing-aperture", "400", "sensing_aperture_deg"),
        ("--teacher-horizon", "1", "teacher_horizon_s"),
        ("--turn-weight", "-2", "dagger_turn_weight"),
        ("--own-separation", "-1", "dagger_separation_weight"),
        ("--own-separation-horizon", "-4", "dagger_separation_horizon_s"),
        ("--own-separation-intruder-horizon", "nan", "dagger_separation_intruder_horizon_s"),
        ("--own-separation-intruder-weight", "inf", "dagger_separation_intruder_weight"),
        ("--safe-set-weight", "-1", "dagger_safe_set_weight"),
        ("--safe-set-weight", "4", "dagger_safe_set_weight"),  # orca-shield: refused
        ("--safe-set-weight 0", "--safe-set-side", "dagger_safe_set_side"),  # no sets to cut
        ("--max-neighbours", "-1", "max_neighbours"),
        ("--dagger-lr", "0", "dagger_lr"),
        ("--real-share", "1.5", "real_share"),
        ("--real-error-tau 30", "10", "real_error_tau_s"),
        ("--teacher", "self-shield", "teacher"),
        ("--teacher-neighbours", "straight", "teacher_neighbours"),  # orca-shield: refused
        ("--init generalist --learner", "td3", "init"),
    ],
)
def test_a_generalist_flag_out_of_range_is_a_clear_error(tmp_path, capsys, flag, value, setting):
    from remarl_fc.cli import main

    argv = ["train", "--generalist", *flag.split(), value, "--out", str(tmp_path / "run")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"train --generalist: {setting}" in err and "Traceback" not in err
    assert not (tmp_path / "run").exists()  # nothing started, nothing written


def test_cuda_asked_for_where_torch_sees_none_is_a_clear_error(tmp_path, capsys, monkeypatch):
    from remarl_fc.cli import main

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    argv = ["train", "--generalist", "--device", "cuda", "--out", str(tmp_path / "run")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "sees no CUDA device" in err and "--device cpu" in err and "Traceback" not in err
    assert not (tmp_path / "run").exists()  # nothing started, nothing written


def test_train_generalist_flags_reach_the_config(tmp_path, monkeypatch):
    import policies.generalist_train as generalist_train
    from remarl_fc.cli import main

    seen = []

    def fake_train(cfg, out, resume=False, progress=None):
        seen.append((cfg, out, resume))
        return {"transitions": 0, "elapsed_s": 0.0, "best_success": 0.0}

    monkeypatch.setattr(generalist_train, "train_generalist", fake_train)
    argv = ["train", "--generalist", "--json", "--minutes", "2", "--seed", "4"]
    argv += ["--swarm-field", "formation", "--family-weight", "swarms-*=2"]
    argv += ["--separation-horizon", "8", "--separation-weight", "0"]
    argv += ["--pooling", "max-attention", "--ppo-min-std", "0.1"]
    argv += ["--teacher", "orca-shield", "--bc-weight", "1.5", "--bc-fraction", "0.8"]
    argv += ["--dagger-fraction", "0.25", "--sensing-range", "300", "--sensing-aperture", "360"]
    argv += ["--teacher-horizon", "14", "--turn-weight", "6", "--max-neighbours", "12"]
    argv += ["--init", "generalist", "--dagger-lr", "3e-4", "--teacher-truth"]
    argv += ["--real-share", "0.5", "--real-error-tau", "10", "120", "--real-track-filter"]
    argv += ["--real-hover", "--own-separation", "0.3", "--own-separation-horizon", "6"]
    argv += ["--own-separation-reciprocal", "--own-separation-intruders"]
    argv += ["--own-separation-intruder-horizon", "12", "--own-separation-intruder-weight", "0.1"]
    assert main([*argv, "--out", str(tmp_path / "run")]) == 0
    ((cfg, out, resume),) = seen
    assert cfg.swarm_field == "formation" and cfg.family_weights == (("swarms-*", 2.0),)
    assert cfg.separation_horizon_s == 8.0 and cfg.separation_weight == 0.0
    assert cfg.pooling == "max-attention" and cfg.ppo_min_std == 0.1
    assert (cfg.teacher, cfg.bc_weight, cfg.bc_fraction) == ("orca-shield", 1.5, 0.8)
    assert cfg.dagger_fraction == 0.25
    assert (cfg.sensing_range_m, cfg.sensing_aperture_deg) == (300.0, 360.0)
    assert cfg.teacher_horizon_s == 14.0 and cfg.dagger_turn_weight == 6.0
    assert cfg.max_neighbours == 12
    assert cfg.init == "generalist" and cfg.dagger_lr == 3e-4
    assert cfg.teacher_truth and cfg.real_share == 0.5 and cfg.real_error_tau_s == (10.0, 120.0)
    assert cfg.real_track_filter and cfg.real_hover
    assert (cfg.dagger_separation_weight, cfg.dagger_separation_horizon_s) == (0.3, 6.0)
    assert cfg.dagger_separation_reciprocal and cfg.dagger_separation_intruders
    assert cfg.dagger_separation_intruder_horizon_s == 12.0
    assert cfg.dagger_separation_intruder_weight == 0.1
    assert cfg.minutes == 2 and cfg.seed == 4 and out == tmp_path / "run" and not resume
    assert GeneralistConfig().swarm_field == "all"  # the paper's reward unless asked
    assert cfg.teacher_neighbours == "proposals"  # the shield as it flies unless asked
    seen.clear()
    argv = ["train", "--generalist", "--json", "--init", "generalist", "--teacher"]
    argv += ["self-shield", "--teacher-neighbours", "straight", "--out", str(tmp_path / "sv")]
    assert main(argv) == 0
    assert seen[0][0].teacher_neighbours == "straight"
    seen.clear()
    argv = ["train", "--generalist", "--json", "--init", "generalist", "--teacher", "self-shield"]
    argv += ["--dagger-fraction", "1", "--safe-set-weight", "4", "--safe-set-side"]
    assert main([*argv, "--out", str(tmp_path / "ss")]) == 0
    assert seen[0][0].dagger_safe_set_weight == 4.0 and seen[0][0].dagger_safe_set_side
    seen.clear()
    assert main(["train", "--generalist", "--json", "--out", str(tmp_path / "plain")]) == 0
    assert seen[0][0] == GeneralistConfig(seed=seen[0][0].seed)  # no flag: every default


def test_a_world_reads_its_vehicle_profiles_once_for_every_teacher_step(monkeypatch):
    """The shield's vehicle comes from the profile files: read once per world, not per step
    (it was a tenth of a DAgger rollout)."""
    import sim.shield
    from policies.generalist_train import World, teacher_actions, teacher_vehicle, with_layout
    from sim.scenarios import load_scenario
    from sim.swarm import SwarmSim

    reads: list[str] = []
    load = sim.shield.load_profile
    monkeypatch.setattr(sim.shield, "load_profile", lambda name: reads.append(name) or load(name))
    cfg = with_layout(load_scenario("3u2o"), LAYOUT)
    swarm = SwarmSim(cfg)
    state = swarm.initial_state(np.random.default_rng(0), 3)
    world = World(None, cfg, False, swarm, state, swarm.observe(state).flat(), 3)  # type: ignore[arg-type]
    for _ in range(4):
        teacher_actions(world, "orca-shield")
    assert reads == [cfg.dynamics]
    assert world.teacher_vehicle == teacher_vehicle(cfg) and not world.teacher_vehicle.can_slow
