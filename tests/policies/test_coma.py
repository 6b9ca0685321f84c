"""COMA: the counterfactual advantage on a matrix game, TD(λ), masking, a tiny training run."""

import copy
import csv
import dataclasses
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="needs the train extra: pip install 'remarl-fc[train]'")

import policies.coma as coma_module  # noqa: E402 - after the skip
from policies.coma import (  # noqa: E402
    ComaBatch,
    ComaConfig,
    ComaCritic,
    ComaNets,
    coma_update,
    counterfactual_advantage,
    global_state,
    td_lambda_targets,
)
from policies.coma_train import coma_policy, load_coma, train_coma  # noqa: E402
from policies.common import CURVE_COLUMNS, heading_actions  # noqa: E402
from sim.evaluation import run_episodes, summarize  # noqa: E402
from sim.scenarios import load_scenario  # noqa: E402

# A one-step two-agent matrix game: R[u1, u2] is the team's payoff, so Q(s, u) = R[u].
PAYOFF = torch.tensor([[4.0, 0.0], [2.0, 6.0]])
PI_1 = torch.tensor([0.25, 0.75])
PI_2 = torch.tensor([0.5, 0.5])
# By hand, A_1(u1, u2) = R[u1, u2] − Σ_u' π_1(u') R[u', u2] and
#          A_2(u1, u2) = R[u1, u2] − Σ_u' π_2(u') R[u1, u'].
# Baselines: agent 1 given u2 = 0: .25·4 + .75·2 = 2.5; given u2 = 1: .25·0 + .75·6 = 4.5.
#            agent 2 given u1 = 0: .5·4 + .5·0 = 2;     given u1 = 1: .5·2 + .5·6 = 4.
EXPECTED = {
    (0, 0): (4 - 2.5, 4 - 2.0),
    (0, 1): (0 - 4.5, 0 - 2.0),
    (1, 0): (2 - 2.5, 2 - 4.0),
    (1, 1): (6 - 4.5, 6 - 4.0),
}


def test_counterfactual_advantage_on_a_matrix_game():
    joint = list(EXPECTED)
    actions = torch.tensor(joint)  # (4 joint actions, 2 agents)
    q_all = torch.stack(
        [torch.stack([PAYOFF[:, u2], PAYOFF[u1, :]]) for u1, u2 in joint]
    )  # (4, 2 agents, 2 actions): Q(s, (u_−a, u')) for every u' of agent a
    pi = torch.stack([PI_1, PI_2]).expand(4, 2, 2)
    adv = counterfactual_advantage(q_all, pi, actions)
    assert adv.shape == (4, 2)
    assert torch.allclose(adv, torch.tensor([EXPECTED[j] for j in joint]))
    # The baseline is the policy's average: the π-weighted advantage of each agent is 0.
    for agent, other, p in ((0, 1, PI_1), (1, 0, PI_2)):
        for held in (0, 1):
            rows = [k for k, j in enumerate(joint) if j[other] == held]
            mean = sum(p[joint[k][agent]] * adv[k, agent] for k in rows)
            assert float(mean) == pytest.approx(0.0, abs=1e-6)


def test_counterfactual_advantage_checks_shapes():
    with pytest.raises(ValueError, match="shapes"):
        counterfactual_advantage(torch.zeros(3, 2), torch.zeros(3, 3), torch.zeros(3))
    with pytest.raises(ValueError, match="shapes"):
        counterfactual_advantage(torch.zeros(3, 2), torch.zeros(3, 2), torch.zeros(2))


DOMINANT = torch.tensor([[0.0, 1.0], [1.0, 5.0]])
"""A game whose action 1 dominates for both agents: (1, 1) is its only equilibrium."""


def test_coma_update_solves_a_matrix_game():
    """Agents with a constant observation learn the best joint action (1, 1) of DOMINANT."""
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(0)
    cfg = ComaConfig(n_actions=2, hidden=32, actor_lr=1e-2, critic_lr=1e-2, epsilon_start=0.1)
    nets = ComaNets.create(2, 1, cfg)
    b = 64
    obs = torch.zeros(1, b, 2, 1)
    for _ in range(150):
        with torch.no_grad():
            probs = coma_module.explore_probs(nets.actor(obs), 0.1)
        actions = torch.multinomial(probs.reshape(-1, 2), 1, generator=gen).reshape(1, b, 2)
        batch = ComaBatch(
            obs=obs,
            active=torch.ones(1, b, 2, dtype=torch.bool),
            actions=actions,
            rewards=DOMINANT[actions[..., 0], actions[..., 1]],
            terminated=torch.ones(1, b, dtype=torch.bool),
            truncated=torch.zeros(1, b, dtype=torch.bool),
            truncated_values=torch.zeros(1, b),
            last_value=torch.zeros(b),
            epsilon=0.1,
        )
        coma_update(nets, batch, cfg)
    greedy = nets.actor(torch.zeros(2, 1)).argmax(-1)
    assert greedy.tolist() == [1, 1]
    # The critic learnt the payoff of the joint action the agents now take: Q(s, (1, 1)) ≈ 5.
    state = global_state(torch.zeros(2, 1), torch.ones(2, dtype=torch.bool))
    q = nets.critic(state, torch.eye(2)[[1, 1]])  # (agents, actions)
    assert q[:, 1].tolist() == pytest.approx([5.0, 5.0], abs=0.5)


def test_td_lambda_targets():
    r = torch.tensor([[1.0], [2.0], [3.0]])
    v = torch.tensor([[10.0], [20.0], [30.0]])
    no = torch.zeros(3, 1, dtype=torch.bool)
    yes = torch.ones(3, 1, dtype=torch.bool)
    g = 0.5
    # λ = 0: one-step targets r + γV'.
    assert torch.allclose(td_lambda_targets(r, no, v, yes, g, 0.0), r + g * v)
    # λ = 1: discounted returns, bootstrapped at the batch's end.
    mc = torch.tensor([[1 + g * 2 + g * g * 3 + g**3 * 30], [2 + g * 3 + g * g * 30], [3 + g * 30]])
    assert torch.allclose(td_lambda_targets(r, no, v, yes, g, 1.0), mc)
    # λ = 0.8 by hand (v[t] is the value of step t + 1):
    # G2 = 3 + γ·30; G1 = 2 + γ(.2·20 + .8·G2); G0 = 1 + γ(.2·10 + .8·G1).
    g2 = 3 + g * 30
    g1 = 2 + g * (0.2 * 20 + 0.8 * g2)
    g0 = 1 + g * (0.2 * 10 + 0.8 * g1)
    out = td_lambda_targets(r, no, v, yes, g, 0.8)
    assert torch.allclose(out, torch.tensor([[g0], [g1], [g2]]))
    # Terminated at t = 1: no future there; t = 0 still sees G1 = r1.
    term = torch.tensor([[False], [True], [False]])
    cont = ~term
    out = td_lambda_targets(r, term, v, cont, g, 1.0)
    assert torch.allclose(out[:2], torch.tensor([[1 + g * 2], [2.0]]))
    # A cut (step limit) at t = 0: bootstrap on its own next value, not on G1.
    cut = torch.tensor([[False], [True], [True]])
    out = td_lambda_targets(r, no, v, cut, g, 1.0)
    assert float(out[0, 0]) == pytest.approx(1 + g * 10)


def test_config_checks():
    with pytest.raises(ValueError, match="td_lambda"):
        ComaConfig(td_lambda=1.5)
    with pytest.raises(ValueError, match="epsilon_end"):
        ComaConfig(epsilon_start=0.1, epsilon_end=0.2)
    with pytest.raises(ValueError, match="n_actions"):
        ComaConfig(n_actions=1)
    cfg = ComaConfig(budget_steps=1000, epsilon_anneal_frac=0.5)
    assert cfg.epsilon(0) == cfg.epsilon_start
    assert cfg.epsilon(250) == pytest.approx((cfg.epsilon_start + cfg.epsilon_end) / 2)
    assert cfg.epsilon(10_000) == cfg.epsilon_end


def test_critic_hides_own_action_and_state_hides_departed_agents():
    torch.manual_seed(0)
    critic = ComaCritic(3, 4, 5, 16)
    obs, active = torch.randn(2, 3, 4), torch.tensor([[True, True, False], [True, True, True]])
    state = global_state(obs, active)
    assert state.shape == (2, 3 * 4 + 3)
    # A departed agent's observation does not reach the state.
    moved = obs.clone()
    moved[0, 2] += 1.0
    assert torch.equal(global_state(moved, active)[0], state[0])
    onehot = torch.eye(5)[torch.tensor([[0, 1, 2], [3, 4, 0]])]
    q = critic(state, onehot)
    assert q.shape == (2, 3, 5)
    other = onehot.clone()
    other[:, 0] = torch.eye(5)[4]  # change agent 0's own action only
    q2 = critic(state, other)
    assert torch.equal(q[:, 0], q2[:, 0])  # agent 0's Q row does not see its own action
    assert not torch.allclose(q[:, 1], q2[:, 1])  # the others' rows do


def test_masked_agents_contribute_nothing():
    torch.manual_seed(0)
    cfg = ComaConfig(n_actions=3, hidden=16)
    t, b, n, d = 4, 5, 3, 6
    active = torch.ones(t, b, n, dtype=torch.bool)
    active[:, :, 2] = False  # agent 2 has left
    batch = ComaBatch(
        obs=torch.randn(t, b, n, d),
        active=active,
        actions=torch.randint(0, 3, (t, b, n)),
        rewards=torch.randn(t, b),
        terminated=torch.zeros(t, b, dtype=torch.bool),
        truncated=torch.zeros(t, b, dtype=torch.bool),
        truncated_values=torch.zeros(t, b),
        last_value=torch.zeros(b),
        epsilon=0.1,
    )
    other_obs = batch.obs.clone()
    other_obs[..., 2, :] = torch.randn(t, b, d)
    other_actions = batch.actions.clone()
    other_actions[..., 2] = (other_actions[..., 2] + 1) % 3
    nets = ComaNets.create(n, d, cfg)
    twin = copy.deepcopy(nets)
    a = coma_update(nets, batch, cfg)
    changed = dataclasses.replace(batch, obs=other_obs, actions=other_actions)
    c = coma_update(twin, changed, cfg)
    assert a == pytest.approx(c)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("coma")
    cfg = ComaConfig(budget_steps=2_000, num_envs=8, rollout_steps=10, eval_episodes=4)
    return out, cfg, train_coma(cfg, "2u1o", out, seed=3)


def test_tiny_training_run_writes_a_curve(tiny_run):
    out, cfg, summary = tiny_run
    with (out / "curve.csv").open() as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0]) == CURVE_COLUMNS
    body = rows[1:]
    assert len(body) == summary["episodes"] > 0
    steps = [int(r[0]) for r in body]
    assert steps == sorted(steps)
    assert all(s % cfg.num_envs == 0 for s in steps)
    assert steps[-1] <= summary["env_steps"]
    assert [int(r[1]) for r in body] == list(range(1, len(body) + 1))
    returns = [float(r[2]) for r in body]
    assert all(math.isfinite(x) for x in returns)
    assert {r[3] for r in body} <= {"0", "1"}
    # Episodes end at most at the step limit, and each step pays at most 1 per agent.
    assert max(abs(x) for x in returns) <= 2 * load_scenario("2u1o").max_steps
    assert summary["env_steps"] >= cfg.budget_steps
    assert summary["env_steps"] == summary["updates"] * cfg.num_envs * cfg.rollout_steps
    assert summary["eval"]["episodes"] == 4
    assert (out / "config.json").exists()
    assert (out / "summary.json").exists()


def test_greedy_policy_runs_through_the_shared_metrics(tiny_run):
    out, cfg, _ = tiny_run
    actor = load_coma(out / "model.safetensors")
    policy = coma_policy(actor)
    obs = np.zeros((7, 2, actor.obs_size), np.float32)
    actions = policy(obs)
    assert actions.shape == (7, 2)
    assert actions.dtype == np.float32
    assert set(actions.ravel().tolist()) <= set(heading_actions(cfg.n_actions).tolist())
    rows = run_episodes(policy, "2u1o", 3, seed=11)
    assert len(rows) == 3
    result = summarize(rows)
    assert 0.0 <= result["success_rate"] <= 1.0
    assert math.isfinite(result["swarming_return"])
    with pytest.raises(ValueError, match="expected"):
        policy(np.zeros((1, 3, actor.obs_size), np.float32))


def test_training_is_seeded(tiny_run, tmp_path):
    out, cfg, _ = tiny_run
    again = dataclasses.replace(cfg, eval_episodes=0)
    train_coma(again, "2u1o", tmp_path, seed=3)
    assert (tmp_path / "curve.csv").read_text() == (out / "curve.csv").read_text()
    a = load_coma(out / "model.safetensors").state_dict()
    b = load_coma(tmp_path / "model.safetensors").state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
