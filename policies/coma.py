"""COMA, counterfactual multi-agent policy gradients (Foerster et al. 2018): a discrete baseline.

The method, as the paper, on the swarm simulator's vectorised environment (`sim.env`):

* **Actions.** Each UAV picks one of ``n_actions`` heading changes evenly spaced on
  [−π/4, π/4] (`policies.common.heading_actions`); the environment receives them normalised
  to [−1, 1].
* **Actor.** One network shared by every agent, its input the agent's observation with a one-hot
  agent id appended; a softmax policy mixed with ε-uniform exploration, ε annealed linearly.
  It is feed-forward (the paper's actor is a GRU): the observation is the per-step one the
  DDPG actors see too, so τ_a = o_a.
* **Critic.** Centralised: global state, the other agents' actions (one-hot) and the agent id
  in; Q(s, (u_−a, u')) for every action u' of agent a out, so the counterfactual baseline
  Σ_u' π_a(u'|τ_a) Q(s, (u_−a, u')) costs one forward pass (`counterfactual_advantage`).
* **State.** The concatenation of all N agents' observations (zeroed for agents that are no
  longer flying) followed by the N flags of the agents still flying: the global state the
  BenchMARL baselines get too (`policies.baseline_env.SwarmBaselineEnv.state`, observations
  divided by 10), so every centralised baseline sees the same thing; its entries are
  dimensionless and O(1) (the observation builder scales them), so it needs no normalisation,
  and like the observations it does not depend on where the arena is or which way the swarm
  flies. A vector built from the raw simulator state (absolute positions, headings, PSO contour
  levels) would need scales of its own and carry frame information the policies never see.
* **Targets.** TD(λ) returns (λ = 0.8, the paper's) bootstrapped with a target critic that is
  copied from the critic every ``target_update_interval`` batches.
* **Batches.** On-policy: B environments stepped together for T steps; the B·T transitions of
  every agent make one batch, used once (critic, then actor) and thrown away. Episodes that
  run past a batch's end continue into the next one; the batch's last step bootstraps with the
  target critic, as does an episode cut by the step limit (on its final observation).
* **Reward.** The Swarming part of the reward only, as the paper trains its baselines
  (``reward="swarming"``). COMA is a method for one team reward; the team reward of a step is
  the mean over the N agents of the rewards of those that flew it.
* **Departures of UAVs.** An agent that reached its target or whose episode ended is masked:
  it contributes nothing to either loss, and its action is a zero one-hot in the critic's
  input. As in the project's DDPG (`policies.train`, docs/MODEL.md §10), arrival is an
  absorbing goal worth r_max/(1 − γ) (r_max = 1 for the Swarming part), so the team's target
  gains γ·r_max/(1 − γ)/N when one of its N agents arrives; a collision is worth 0; the
  environment's rewards and the logged returns are unchanged.

The training loop, the model file and the greedy policy are in `policies.coma_train`
(``python -m policies.coma_train --scenario 3u1o --budget-steps 200000``).

The method is one concept kept whole (about 420 lines, most of them this account of it); its
training loop, model files and greedy policy are in `policies.coma_train`.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from policies.config import check, check_at_least

REWARD = "swarming"
"""The reward COMA trains on: the Swarming part alone, as the paper's baselines."""


@dataclass(frozen=True)
class ComaConfig:
    """COMA hyper-parameters, each default documented here once."""

    n_actions: int = 11
    """Discrete heading changes (`policies.common.heading_actions`); 11 holds straight ahead,
    10 is the paper's literal grid."""

    hidden: int = 128
    """Units of each of the two hidden ReLU layers of the actor and of the critic."""

    actor_lr: float = 5e-4
    """Adam learning rate of the actor (the COMA reference implementation's 5·10⁻⁴)."""

    critic_lr: float = 5e-4
    """Adam learning rate of the critic."""

    gamma: float = 0.95
    """Discount per decision step (2 s), the project's DDPG one: a horizon of about an
    episode."""

    td_lambda: float = 0.8
    """λ of the critic's TD(λ) targets (the paper's 0.8)."""

    num_envs: int = 16
    """B, environments stepped together."""

    rollout_steps: int = 20
    """T, vectorised steps per on-policy batch (B·T environment steps per update)."""

    critic_steps: int = 2
    """Full-batch critic gradient steps per batch, before the actor's one."""

    epsilon_start: float = 0.5
    """ε of the ε-uniform exploration mixed into the softmax policy at the start ..."""

    epsilon_end: float = 0.02
    """... and at the end of the annealing (linear), kept from then on."""

    epsilon_anneal_frac: float = 0.5
    """Fraction of ``budget_steps`` over which ε is annealed."""

    target_update_interval: int = 10
    """Batches between copies of the critic into the target critic."""

    grad_clip: float = 10.0
    """Max gradient norm of the actor and of the critic (the reference implementation's)."""

    budget_steps: int = 200_000
    """Environment steps of training (one step of one environment counts 1, so a batch is
    B·T); the last batch is finished, so the run may exceed it by up to B·T − 1."""

    eval_episodes: int = 100
    """Greedy evaluation episodes on held-out seeds at the end (0: none)."""

    def __post_init__(self) -> None:
        check(self.n_actions >= 2, "n_actions", "must be >= 2")
        for name in ("actor_lr", "critic_lr", "grad_clip"):
            check(getattr(self, name) > 0, name, "must be > 0")
        check(0 < self.gamma < 1, "gamma", "must be in (0, 1)")
        check(0 <= self.td_lambda <= 1, "td_lambda", "must be in [0, 1]")
        check_at_least(
            self,
            1,
            "hidden",
            "num_envs",
            "rollout_steps",
            "critic_steps",
            "target_update_interval",
            "budget_steps",
        )
        check(0 <= self.epsilon_end <= self.epsilon_start <= 1, "epsilon_end", "must be in [0, 1]")
        check(0 < self.epsilon_anneal_frac <= 1, "epsilon_anneal_frac", "must be in (0, 1]")
        check_at_least(self, 0, "eval_episodes")

    def epsilon(self, env_steps: int) -> float:
        """ε after ``env_steps`` environment steps of training."""
        frac = min(env_steps / (self.epsilon_anneal_frac * self.budget_steps), 1.0)
        return (1.0 - frac) * self.epsilon_start + frac * self.epsilon_end


def counterfactual_advantage(q_all: Tensor, pi: Tensor, actions: Tensor) -> Tensor:
    """COMA's advantage A_a(s, u) = Q(s, u) − Σ_u' π_a(u'|τ_a) Q(s, (u_−a, u')).

    Args:
        q_all: (..., U) Q(s, (u_−a, u')) for each of agent a's U actions u', the other agents'
            actions u_−a held at those they took.
        pi: (..., U) agent a's policy π_a(·|τ_a), the probabilities it acted with.
        actions: (...) integer action u_a that agent a took.

    Returns:
        (...) how much better agent a's action did than its policy's average, the other
        agents' actions held fixed. Its π-weighted mean over u_a is 0.
    """
    if q_all.shape != pi.shape or q_all.shape[:-1] != actions.shape:
        raise ValueError(
            f"shapes: q_all {tuple(q_all.shape)} and pi {tuple(pi.shape)} must be (..., U), "
            f"actions {tuple(actions.shape)} must be (...)"
        )
    taken = q_all.gather(-1, actions.long().unsqueeze(-1)).squeeze(-1)
    return taken - (pi * q_all).sum(-1)


def td_lambda_targets(
    rewards: Tensor,
    terminated: Tensor,
    next_values: Tensor,
    continues: Tensor,
    gamma: float,
    lam: float,
) -> Tensor:
    """TD(λ) returns G_t = r_t + γ[(1 − λ)Q'_{t+1} + λG_{t+1}], backward over a batch of steps.

    Args:
        rewards: (T, B) rewards r_t.
        terminated: (T, B) bool: the episode ended at t with no future (collision, all arrived).
        next_values: (T, B) target-critic value Q'_{t+1} of the next state and actions.
        continues: (T, B) bool: step t + 1 of the batch belongs to the same episode, so G_{t+1}
            exists; where it does not (step limit, the batch's last step), G_t bootstraps on
            ``next_values`` alone. Ignored at t = T − 1.
        gamma: discount.
        lam: λ; 0 gives one-step targets, 1 Monte-Carlo returns (bootstrapped at the cut).

    Returns:
        (T, B) the targets G_t.
    """
    steps = rewards.shape[0]
    targets = torch.empty_like(rewards)
    g_next = torch.zeros_like(rewards[0])
    for t in reversed(range(steps)):
        mixed = (1.0 - lam) * next_values[t] + lam * g_next
        future = (
            torch.where(continues[t], mixed, next_values[t]) if t < steps - 1 else next_values[t]
        )
        targets[t] = rewards[t] + gamma * torch.where(terminated[t], 0.0, future)
        g_next = targets[t]
    return targets


def _mlp(inputs: int, hidden: int, outputs: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(inputs, hidden),
        nn.ReLU(),
        nn.Linear(hidden, hidden),
        nn.ReLU(),
        nn.Linear(hidden, outputs),
    )


class ComaActor(nn.Module):
    """Shared actor: (observation, one-hot agent id) → 2 × ReLU → logits over the actions."""

    def __init__(self, n_agents: int, obs_size: int, n_actions: int, hidden: int) -> None:
        super().__init__()
        self.n_agents, self.obs_size, self.n_actions, self.hidden = (
            n_agents,
            obs_size,
            n_actions,
            hidden,
        )
        self.net = _mlp(obs_size + n_agents, hidden, n_actions)

    def forward(self, obs: Tensor) -> Tensor:
        """(..., N, D) observations → (..., N, U) logits."""
        ids = torch.eye(self.n_agents, dtype=obs.dtype).expand(*obs.shape[:-1], self.n_agents)
        logits: Tensor = self.net(torch.cat([obs, ids], dim=-1))
        return logits


class ComaCritic(nn.Module):
    """Centralised critic: (state, other agents' one-hot actions, agent id) → Q over a's actions."""

    def __init__(self, n_agents: int, obs_size: int, n_actions: int, hidden: int) -> None:
        super().__init__()
        self.n_agents, self.n_actions = n_agents, n_actions
        self.state_size = state_size(n_agents, obs_size)
        self.net = _mlp(self.state_size + n_agents * n_actions + n_agents, hidden, n_actions)

    def forward(self, state: Tensor, actions_onehot: Tensor) -> Tensor:
        """Q(s, (u_−a, ·)) of every agent a.

        Args:
            state: (..., S) global states (`global_state`).
            actions_onehot: (..., N, U) every agent's action, one-hot (zeros for agents that
                do not act); agent a's own row is hidden from its input.

        Returns:
            (..., N, U) for every agent a, its Q for each of its actions, the others' held.
        """
        n, u = self.n_agents, self.n_actions
        lead = state.shape[:-1]
        others = 1.0 - torch.eye(n, dtype=state.dtype)  # [a, j]: agent j is not a
        joint = actions_onehot.unsqueeze(-3) * others[..., None]  # (..., a, j, U)
        x = torch.cat(
            [
                state.unsqueeze(-2).expand(*lead, n, self.state_size),
                joint.reshape(*lead, n, n * u),
                torch.eye(n, dtype=state.dtype).expand(*lead, n, n),
            ],
            dim=-1,
        )
        q: Tensor = self.net(x)
        return q


def state_size(n_agents: int, obs_size: int) -> int:
    """Length S of `global_state`: N observations and N flags."""
    return n_agents * obs_size + n_agents


def global_state(obs: Tensor, active: Tensor) -> Tensor:
    """(..., N, D) observations, (..., N) bool flying → (..., N·D + N) critic state.

    The observations of agents no longer flying are zeroed; the flags follow them.
    """
    flags = active.to(obs.dtype)
    return torch.cat([(obs * flags[..., None]).flatten(-2), flags], dim=-1)


def explore_probs(logits: Tensor, epsilon: float) -> Tensor:
    """The behaviour policy: softmax(logits) mixed with ε-uniform, (..., U)."""
    return (1.0 - epsilon) * torch.softmax(logits, dim=-1) + epsilon / logits.shape[-1]


@dataclass
class ComaNets:
    """Actor, critic, target critic and their optimisers."""

    actor: ComaActor
    critic: ComaCritic
    critic_target: ComaCritic
    actor_opt: torch.optim.Optimizer
    critic_opt: torch.optim.Optimizer

    @classmethod
    def create(cls, n_agents: int, obs_size: int, cfg: ComaConfig) -> ComaNets:
        """Fresh networks (the target critic starts as a copy)."""
        shape = (n_agents, obs_size, cfg.n_actions, cfg.hidden)
        actor, critic, target = ComaActor(*shape), ComaCritic(*shape), ComaCritic(*shape)
        target.load_state_dict(critic.state_dict())
        target.requires_grad_(False)
        return cls(
            actor,
            critic,
            target,
            torch.optim.Adam(actor.parameters(), lr=cfg.actor_lr),
            torch.optim.Adam(critic.parameters(), lr=cfg.critic_lr),
        )


@dataclass(frozen=True)
class ComaBatch:
    """One on-policy batch, time first: T steps of B environments of N agents.

    Attributes:
        obs: (T, B, N, D) observations the actions were chosen on.
        active: (T, B, N) bool, the agents that flew the step (the others are masked).
        actions: (T, B, N) int64 action indices.
        rewards: (T, B) team rewards (with the arrival goal values, see the module docstring).
        terminated: (T, B) bool, episode over with no future.
        truncated: (T, B) bool, episode cut by the step limit.
        truncated_values: (T, B) target values of the final states where ``truncated``.
        last_value: (B,) target value of the state after the batch's last step.
        epsilon: the ε the batch was collected with.
    """

    obs: Tensor
    active: Tensor
    actions: Tensor
    rewards: Tensor
    terminated: Tensor
    truncated: Tensor
    truncated_values: Tensor
    last_value: Tensor
    epsilon: float


def _team_mean(values: Tensor, active: Tensor) -> Tensor:
    """Mean over the agent dimension (last) of the active agents' values; 0 where none."""
    w = active.to(values.dtype)
    return (values * w).sum(-1) / w.sum(-1).clamp_min(1.0)


def sample_actions(probs: Tensor, generator: torch.Generator) -> Tensor:
    """One action index per row of probabilities (..., U), drawn with ``generator``."""
    flat = probs.reshape(-1, probs.shape[-1])
    return torch.multinomial(flat, 1, generator=generator).reshape(probs.shape[:-1])


def sampled_value(
    nets: ComaNets, obs: Tensor, active: Tensor, epsilon: float, generator: torch.Generator
) -> Tensor:
    """Target-critic team value Q'(s, u) of states (K, N, D) with u drawn from the policy, (K,)."""
    with torch.no_grad():
        actions = sample_actions(explore_probs(nets.actor(obs), epsilon), generator)
        onehot = _onehot(actions, active, nets.actor.n_actions)
        q = nets.critic_target(global_state(obs, active), onehot)
        taken = q.gather(-1, actions[..., None]).squeeze(-1)
        return _team_mean(taken, active)


def _onehot(actions: Tensor, active: Tensor, n_actions: int) -> Tensor:
    onehot = nn.functional.one_hot(actions, n_actions).to(torch.float32)
    return onehot * active[..., None].to(torch.float32)


def coma_update(nets: ComaNets, batch: ComaBatch, cfg: ComaConfig) -> dict[str, float]:
    """Critic steps on TD(λ) targets, then one actor step on the counterfactual advantage.

    Only the agents in ``batch.active`` count, in both losses.
    """
    n_actions = nets.actor.n_actions
    active = batch.active
    w = active.to(torch.float32)
    norm = w.sum().clamp_min(1.0)
    state = global_state(batch.obs, active)
    onehot = _onehot(batch.actions, active, n_actions)
    idx = batch.actions[..., None]

    # ---- TD(λ) targets of the team's Q from the target critic
    with torch.no_grad():
        q_target = nets.critic_target(state, onehot).gather(-1, idx).squeeze(-1)
        team_q = _team_mean(q_target, active)  # (T, B)
        next_values = torch.cat([team_q[1:], batch.last_value[None]], dim=0)
        next_values = torch.where(batch.truncated, batch.truncated_values, next_values)
        continues = ~(batch.terminated | batch.truncated)
        targets = td_lambda_targets(
            batch.rewards, batch.terminated, next_values, continues, cfg.gamma, cfg.td_lambda
        )

    # ---- critic: every active agent's Q(s, u) regresses on the team's target
    critic_loss = torch.zeros(())
    for _ in range(cfg.critic_steps):
        q = nets.critic(state, onehot).gather(-1, idx).squeeze(-1)
        critic_loss = (((q - targets[..., None]) ** 2) * w).sum() / norm
        nets.critic_opt.zero_grad(set_to_none=True)
        critic_loss.backward()
        nn.utils.clip_grad_norm_(nets.critic.parameters(), cfg.grad_clip)
        nets.critic_opt.step()

    # ---- actor: policy gradient on the counterfactual advantage
    with torch.no_grad():
        q_all = nets.critic(state, onehot)
    probs = explore_probs(nets.actor(batch.obs), batch.epsilon)
    advantage = counterfactual_advantage(q_all, probs.detach(), batch.actions)
    log_pi = torch.log(probs.gather(-1, idx).squeeze(-1))
    actor_loss = -(advantage * log_pi * w).sum() / norm
    nets.actor_opt.zero_grad(set_to_none=True)
    actor_loss.backward()
    nn.utils.clip_grad_norm_(nets.actor.parameters(), cfg.grad_clip)
    nets.actor_opt.step()
    return {
        "critic_loss": float(critic_loss.detach()),
        "actor_loss": float(actor_loss.detach()),
        "q_mean": float((q_all.gather(-1, idx).squeeze(-1) * w).sum() / norm),
        "advantage_abs": float((advantage.abs() * w).sum() / norm),
    }


if __name__ == "__main__":  # the documented ``python -m policies.coma`` still trains
    from policies.coma_train import main

    main()
