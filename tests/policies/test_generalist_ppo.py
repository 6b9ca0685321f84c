"""The generalist's PPO learner: its advantages, its density, and a tiny run end to end."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from tiny_policy import tiny_suite

from policies.config import GeneralistConfig
from policies.generalist_ppo import LOG_2PI, PPONets, advantages, log_prob, ppo_update
from policies.generalist_train import train_generalist
from sim.observation import ObservationLayout

LAYOUT = ObservationLayout(8, 100.0, np.radians(270), 5.0, max_neighbours=6, version=2)


def slow_advantages(reward, value, next_value, terminal, terminal_value, cut, gamma, lam):
    """GAE(λ) of each UAV's trajectory, one entry at a time (the definition)."""
    t_len = reward.shape[0]
    adv = np.zeros_like(reward)
    for idx in np.ndindex(reward.shape[1:]):
        for t in range(t_len):
            total, weight, s = 0.0, 1.0, t
            while True:
                boot = terminal_value[(s, *idx)] if terminal[(s, *idx)] else next_value[(s, *idx)]
                delta = reward[(s, *idx)] + gamma * boot - value[(s, *idx)]
                total += weight * delta
                if terminal[(s, *idx)] or cut[(s, *idx)]:
                    break
                weight *= gamma * lam
                s += 1
            adv[(t, *idx)] = total
    return adv


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    steps=st.integers(1, 7),
    gamma=st.floats(0.5, 0.99),
    lam=st.floats(0.0, 1.0),
)
def test_advantages_are_gae_of_each_trajectory(seed, steps, gamma, lam):
    rng = np.random.default_rng(seed)
    shape = (steps, 3, 2)
    reward, value, next_value, terminal_value = (
        rng.normal(0, 1, shape).astype(np.float32) for _ in range(4)
    )
    terminal = rng.random(shape) < 0.2
    cut = rng.random(shape) < 0.2
    cut[-1] = True
    adv, target = advantages(reward, value, next_value, terminal, terminal_value, cut, gamma, lam)
    expected = slow_advantages(reward, value, next_value, terminal, terminal_value, cut, gamma, lam)
    np.testing.assert_allclose(adv, expected, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(target, adv + value, rtol=1e-6)


def test_a_terminal_step_bootstraps_its_terminal_value_and_nothing_after():
    ones = np.ones((3, 1), np.float32)
    terminal = np.array([[False], [True], [False]])
    cut = np.array([[False], [False], [True]])
    next_value = np.array([[0.0], [-50.0], [100.0]], np.float32)  # V(s1) = 0 = value[1]
    adv, _ = advantages(ones, 0 * ones, next_value, terminal, 10 * ones, cut, 0.5, 1.0)
    # step 1 ends the trajectory with the goal's value 10 (its V(next) unused): 1 + 0.5·10;
    # step 0 adds its reward and half of that; step 2 (a new trajectory, cut by the rollout's
    # end) bootstraps V(next) = 100
    np.testing.assert_allclose(adv[:, 0], [1 + 0.5 * 6, 6, 1 + 0.5 * 100])


def test_log_prob_is_the_gaussian_density():
    mean, sample = torch.tensor([0.1, -0.4, 0.9]), torch.tensor([0.3, -0.4, -1.2])
    log_std = torch.tensor(-1.2)
    expected = torch.distributions.Normal(mean, torch.exp(log_std)).log_prob(sample)
    torch.testing.assert_close(log_prob(mean, log_std, sample), expected)
    assert pytest.approx(np.log(2 * np.pi)) == LOG_2PI


def test_the_value_network_is_the_critic_read_at_action_0():
    from sim.setnet import set_shapes

    nets = PPONets.create(LAYOUT, GeneralistConfig(hidden=8), "cpu")
    obs = torch.from_numpy(np.random.default_rng(0).normal(0, 1, (5, LAYOUT.size)).astype("f4"))
    v = nets.values(obs)
    assert v.shape == (5,) and torch.isfinite(v).all()
    torch.testing.assert_close(v, nets.value(obs, torch.zeros(5)))
    # the critic's shapes, so the policy file's critic slot holds it
    shapes = {k: tuple(w.shape[1:]) for k, w in nets.value.state_dict().items() if "weight" in k}
    assert shapes == {f"{k}.weight": v for k, v in set_shapes(8, critic=True).items()}


@pytest.mark.parametrize("floor", [0.0, 0.2])
def test_the_std_floor_holds_where_the_update_pushes_sigma_down(floor):
    cfg = GeneralistConfig(hidden=8, ppo_log_std=np.log(0.21), ppo_lr=0.05, ppo_min_std=floor)
    torch.manual_seed(0)
    nets = PPONets.create(LAYOUT, cfg, "cpu")
    obs = torch.from_numpy(np.random.default_rng(0).normal(0, 1, (64, LAYOUT.size)).astype("f4"))
    with torch.no_grad():
        mean = nets.actor(obs)
    # samples right at the mean with a positive advantage: the likelihood rises as σ falls
    sample, adv = mean.clone(), torch.ones(64)
    old = log_prob(mean, nets.log_std.value.detach(), sample)
    for _ in range(20):
        ppo_update(nets, obs, sample, old, adv, torch.zeros(64), cfg)
    sigma = float(torch.exp(nets.log_std.value.detach()))
    if floor:
        assert sigma == pytest.approx(floor, rel=1e-6)
    else:
        assert sigma < 0.2


@pytest.mark.parametrize(("pooling", "neighbours"), [("max-mean", 6), ("max-attention", 2)])
def test_a_tiny_ppo_run_trains_validates_resumes_and_exports(tmp_path, pooling, neighbours):
    tiny_ppo_run(tmp_path, pooling=pooling, max_neighbours=neighbours)


def test_a_tiny_ppo_run_with_a_teacher_clones_it_on_its_own_states(tmp_path, monkeypatch):
    horizons = spy_teacher_horizons(monkeypatch)
    summary, seen = tiny_ppo_run(
        tmp_path, teacher="orca-shield", bc_fraction=1.0, dagger_fraction=0.0, teacher_horizon_s=14
    )
    assert horizons and set(horizons) == {14}  # the run's horizon, not ORCA's own
    assert seen[0]["charts/bc_weight"] == pytest.approx(2.5) and seen[0]["losses/clone"] > 0
    assert summary["teacher"] == "orca-shield"


def spy_teacher_horizons(monkeypatch) -> list[float]:
    """Every horizon the training's ORCA teacher is asked to look ahead, in order."""
    import policies.generalist_train as generalist_train

    horizons: list[float] = []
    orca = generalist_train.orca_actions

    def spied(state, cfg, **settings):
        horizons.append(settings["horizon_s"])
        return orca(state, cfg, **settings)

    monkeypatch.setattr(generalist_train, "orca_actions", spied)
    return horizons


def tiny_ppo_run(tmp_path, **changes):
    """A 3-iteration PPO run (from scratch unless ``changes`` say otherwise), resumed to 5,
    exported; its summary and progress rows."""
    changes = {"teacher": "none", **changes}
    from policies.generalist_train import export_generalist_run
    from remarl_fc.policy_io import load_policy
    from sim.scenarios import load_scenario
    from sim.swarm import SwarmSim

    suite = tiny_suite(tmp_path)
    cfg = GeneralistConfig(
        suites=(str(suite),),
        learner="ppo",
        agents_per_family=4,
        hidden=8,
        ppo_rollout=4,
        ppo_epochs=2,
        ppo_minibatch=8,
        minutes=0.0,
        total_iterations=3,
        eval_minutes=1e-6,
        eval_episodes=2,
        real_share=0.5,
        device="cpu",
        **changes,
    )
    out = tmp_path / "run"
    seen: list[dict[str, float]] = []
    summary = train_generalist(cfg, out, progress=seen.append)
    assert summary["learner"] == "ppo" and summary["iterations"] == 3
    # it learned: the actor and the log std moved away from their seeded start
    from policies.train import load_checkpoint

    layout = dataclasses.replace(LAYOUT, max_neighbours=cfg.max_neighbours)
    torch.manual_seed(cfg.seed)
    start = PPONets.create(layout, cfg, "cpu")
    trained = PPONets.create(layout, cfg, "cpu")
    load_checkpoint(out / "last.safetensors", trained)
    assert not torch.equal(trained.log_std.value, start.log_std.value)
    moved = [
        not torch.equal(a, b)
        for a, b in zip(start.actor.parameters(), trained.actor.parameters(), strict=True)
    ]
    assert any(moved)
    assert summary["updates"] > 0 and summary["transitions"] > 0
    assert seen and "losses/policy" in seen[-1] and "charts/log_std" in seen[-1]
    # where the time went: flying the worlds, and learning, each counted
    assert summary["simulator_s"] > 0 and summary["learner_s"] > 0
    share = summary["simulator_s"] / (summary["simulator_s"] + summary["learner_s"])
    assert seen[-1]["perf/simulator_share"] == pytest.approx(share)
    if cfg.teacher == "none":  # no DAgger phase without a teacher, whatever dagger_fraction says
        assert cfg.dagger_fraction > 0 or "dagger_fraction" in changes
        assert not any("charts/dagger_beta" in row for row in seen)
    evals = [json.loads(line) for line in (out / "evals.jsonl").read_text().splitlines()]
    assert evals and set(evals[-1]["families"]) <= {"crossing-2u", "paper-2u1o"}
    again = train_generalist(
        GeneralistConfig(**{**cfg.__dict__, "total_iterations": 5}), out, resume=True
    )
    assert again["iterations"] == 5 and again["updates"] > summary["updates"]

    policy_file = tmp_path / "generalist.safetensors"
    meta = export_generalist_run(out, policy_file, checkpoint="last")
    assert meta["network"] == "set" and meta.get("pooling", "max-mean") == cfg.pooling
    policy = load_policy(str(policy_file))
    assert policy.layout.max_neighbours == cfg.max_neighbours  # the file carries k
    load_checkpoint(out / "last.safetensors", trained)  # the resumed run's last weights
    obs = np.random.default_rng(1).normal(size=(5, layout.size)).astype(np.float32)
    with torch.no_grad():
        expected = trained.actor(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(policy.act(obs), expected, atol=1e-5)
    scen = load_scenario("3u2o")
    sim = SwarmSim(scen, scored=False)
    state = sim.initial_state(np.random.default_rng(0), 2)
    actions = policy.act(sim.observe(state, layout=policy.layout).flat())
    assert actions.shape == (2, 3) and np.isfinite(actions).all()
    return summary, seen


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_each_observation_is_valued_once_and_the_next_values_are_the_naive_ones(seed):
    from policies.generalist_ppo import _values

    rng = np.random.default_rng(seed)
    t, b, n = 5, 3, 2
    obs = rng.normal(0, 1, (t, b, n, LAYOUT.size)).astype(np.float32)
    done = rng.random((t, b)) < 0.3
    nxt = np.empty_like(obs)
    nxt[:-1] = obs[1:]  # the observation after a step is the next one acted on ...
    fresh = rng.normal(0, 1, obs.shape).astype(np.float32)
    nxt[done] = fresh[done]  # ... unless the episode ended: its final one
    nxt[-1] = fresh[-1]
    torch.manual_seed(seed % 1000)
    nets = PPONets.create(LAYOUT, GeneralistConfig(hidden=8), "cpu")
    value, next_value = _values(nets, obs, nxt, done, "cpu")
    with torch.no_grad():
        naive = [nets.values(torch.from_numpy(x.reshape(-1, LAYOUT.size))) for x in (obs, nxt)]
    np.testing.assert_allclose(value, naive[0].numpy().reshape(t, b, n), atol=1e-6)
    np.testing.assert_allclose(next_value, naive[1].numpy().reshape(t, b, n), atol=1e-6)


def test_an_unknown_learner_is_refused():
    with pytest.raises(ValueError, match="learner"):
        GeneralistConfig(learner="sac")


def test_the_default_is_the_shipped_recipe_dagger_on_the_teacher_then_ppo():
    cfg = GeneralistConfig()
    assert (cfg.learner, cfg.teacher, cfg.dagger_fraction, cfg.bc_fraction) == (
        "ppo",
        "orca-shield",
        0.5,
        0.75,
    )
    assert GeneralistConfig(teacher="none").dagger_share() == 0.0  # from scratch: no DAgger
    with pytest.raises(ValueError, match="teacher"):
        GeneralistConfig(teacher="orca")
    with pytest.raises(ValueError, match="bc_fraction"):
        GeneralistConfig(teacher="orca-shield", bc_fraction=0.0)


def test_the_cloning_weight_falls_to_zero_over_its_share_of_the_run():
    from policies.generalist_train import bc_weight

    cfg = GeneralistConfig(teacher="orca-shield", bc_weight=2.0, bc_fraction=0.5)
    assert [bc_weight(cfg, f) for f in (0.0, 0.25, 0.5, 0.9)] == [2.0, 1.0, 0.0, 0.0]
    scratch = GeneralistConfig(bc_weight=2.0, teacher="none", dagger_fraction=0.0)
    assert bc_weight(scratch, 0.0) == 0.0  # no teacher, no term


def test_the_cloning_term_pulls_the_mean_to_the_teacher_where_it_labelled():
    cfg = GeneralistConfig(hidden=8, ppo_lr=0.01)
    torch.manual_seed(0)
    nets = PPONets.create(LAYOUT, cfg, "cpu")
    obs = torch.from_numpy(np.random.default_rng(0).normal(0, 1, (64, LAYOUT.size)).astype("f4"))
    teacher = torch.full((64,), 0.5)
    teacher[32:] = float("nan")  # unlabelled: no pull
    zero = torch.zeros(64)
    with torch.no_grad():
        start = nets.actor(obs)
    old = log_prob(start, nets.log_std.value.detach(), start)
    for _ in range(100):
        out = ppo_update(nets, obs, start, old, zero, zero, cfg, teacher, bc=5.0)
    with torch.no_grad():
        end = nets.actor(obs)
    assert out["losses/clone"] < 0.01
    assert float((end[:32] - 0.5).abs().max()) < 0.15 < float((start[:32] - 0.5).abs().min())
