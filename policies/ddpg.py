"""Per-agent DDPG (paper §Agent), every agent's networks evaluated as one batched ensemble.

Each of the A agents has its own actor and critic (and their targets), exactly the paper's
networks; their weights are stacked on a leading agent dimension so one ``baddbmm`` per layer
evaluates all of them (A = 1 with parameter sharing):

* actor: obs → 256 ReLU → 1 tanh (a normalised heading change in [−1, 1]);
* critic: obs → 256 ReLU and action → 256 ReLU, concatenated → 256 ReLU → 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from policies.config import DDPGConfig

FINAL_INIT = 3e-3
"""Uniform init range of the output layers (as in the DDPG paper): near-zero first actions."""


class EnsembleLinear(nn.Module):
    """A agents' linear layers at once: (A, B, in) → (A, B, out)."""

    def __init__(self, agents: int, fan_in: int, fan_out: int, init: float | None = None) -> None:
        super().__init__()
        bound = init if init is not None else 1.0 / math.sqrt(fan_in)
        self.weight = nn.Parameter(torch.empty(agents, fan_in, fan_out).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(agents, 1, fan_out).uniform_(-bound, bound))

    def forward(self, x: Tensor) -> Tensor:
        """(A, B, in) → (A, B, out)."""
        return torch.baddbmm(self.bias, x, self.weight)


class Actor(nn.Module):
    """obs → 256 ReLU → 1 tanh, for A agents."""

    def __init__(self, agents: int, obs_size: int, hidden: int) -> None:
        super().__init__()
        self.l1 = EnsembleLinear(agents, obs_size, hidden)
        self.out = EnsembleLinear(agents, hidden, 1, init=FINAL_INIT)

    def forward(self, obs: Tensor) -> Tensor:
        """(A, B, obs) → (A, B) actions in [−1, 1]."""
        return torch.tanh(self.out(torch.relu(self.l1(obs)))).squeeze(-1)


class Critic(nn.Module):
    """obs → 256 and action → 256 (ReLU), concat → 256 ReLU → 1, for A agents."""

    def __init__(self, agents: int, obs_size: int, hidden: int) -> None:
        super().__init__()
        self.obs_l = EnsembleLinear(agents, obs_size, hidden)
        self.act_l = EnsembleLinear(agents, 1, hidden)
        self.l2 = EnsembleLinear(agents, 2 * hidden, hidden)
        self.out = EnsembleLinear(agents, hidden, 1, init=FINAL_INIT)

    def forward(self, obs: Tensor, action: Tensor) -> Tensor:
        """(A, B, obs), (A, B) → (A, B) Q-values."""
        h = torch.cat(
            [torch.relu(self.obs_l(obs)), torch.relu(self.act_l(action[..., None]))], dim=-1
        )
        q: Tensor = self.out(torch.relu(self.l2(h))).squeeze(-1)
        return q


@dataclass
class DDPGNets:
    """Actors, critics, their targets and optimisers for A agents."""

    actor: Actor
    critic: Critic
    actor_target: Actor
    critic_target: Critic
    actor_opt: torch.optim.Optimizer
    critic_opt: torch.optim.Optimizer

    @classmethod
    def create(cls, agents: int, obs_size: int, cfg: DDPGConfig) -> DDPGNets:
        """Fresh networks (targets start as copies)."""
        actor, critic = Actor(agents, obs_size, cfg.hidden), Critic(agents, obs_size, cfg.hidden)
        actor_t = Actor(agents, obs_size, cfg.hidden)
        critic_t = Critic(agents, obs_size, cfg.hidden)
        actor_t.load_state_dict(actor.state_dict())
        critic_t.load_state_dict(critic.state_dict())
        for p in (*actor_t.parameters(), *critic_t.parameters()):
            p.requires_grad_(False)
        return cls(
            actor,
            critic,
            actor_t,
            critic_t,
            torch.optim.Adam(actor.parameters(), lr=cfg.actor_lr),
            torch.optim.Adam(critic.parameters(), lr=cfg.critic_lr),
        )

    def modules(self) -> dict[str, nn.Module]:
        """Every network by checkpoint name."""
        return {
            "actor": self.actor,
            "critic": self.critic,
            "actor_target": self.actor_target,
            "critic_target": self.critic_target,
        }

    def optimisers(self) -> dict[str, torch.optim.Optimizer]:
        """Every optimiser by checkpoint name."""
        return {"actor_opt": self.actor_opt, "critic_opt": self.critic_opt}


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    """θ' ← τθ + (1 − τ)θ'."""
    with torch.no_grad():
        for t, s in zip(target.parameters(), source.parameters(), strict=True):
            t.lerp_(s, tau)


@dataclass(frozen=True)
class Batch:
    """Transitions per agent, agent-first: obs (A, B, D), action/reward/... (A, B).

    ``terminal_value`` is the value to bootstrap with where ``terminal`` is set: 0 after a
    collision, the absorbing goal value after an arrival (see `policies.train`).
    """

    obs: Tensor
    action: Tensor
    reward: Tensor
    next_obs: Tensor
    terminal: Tensor
    terminal_value: Tensor
    weight: Tensor


def ddpg_update(nets: DDPGNets, batch: Batch, cfg: DDPGConfig) -> dict[str, float]:
    """One critic and one actor gradient step for every agent; returns the mean losses.

    ``batch.weight`` (A, B) masks transitions an agent did not make (it had left the episode).
    """
    with torch.no_grad():
        next_q = nets.critic_target(batch.next_obs, nets.actor_target(batch.next_obs))
        future = torch.where(batch.terminal, batch.terminal_value, next_q)
        target = batch.reward + cfg.gamma * future
    q = nets.critic(batch.obs, batch.action)
    w = batch.weight
    norm = w.sum().clamp_min(1.0)
    if cfg.huber:
        per = nn.functional.smooth_l1_loss(q, target, reduction="none")
    else:
        per = (q - target) ** 2
    critic_loss = (per * w).sum() / norm
    nets.critic_opt.zero_grad(set_to_none=True)
    critic_loss.backward()
    nn.utils.clip_grad_norm_(nets.critic.parameters(), cfg.grad_clip)
    nets.critic_opt.step()

    actor_loss = -(nets.critic(batch.obs, nets.actor(batch.obs)) * w).sum() / norm
    nets.actor_opt.zero_grad(set_to_none=True)
    actor_loss.backward()
    nn.utils.clip_grad_norm_(nets.actor.parameters(), cfg.grad_clip)
    nets.actor_opt.step()

    soft_update(nets.actor_target, nets.actor, cfg.tau)
    soft_update(nets.critic_target, nets.critic, cfg.tau)
    return {
        "losses/critic": float(critic_loss.detach()),
        "losses/actor": float(actor_loss.detach()),
        "values/q_mean": float((q.detach() * w).sum() / norm),
    }
