"""The generalist network in torch, and its learner: shared TD3 over per-UAV transitions.

`SetNet` is `sim.setnet`'s network (the same layers, parameter names and shapes, so the
exported tensors run unchanged in numpy): one actor and two critics shared by every UAV of
every swarm, each reading the neighbour and intruder sets with a permutation-invariant
encoder. Transitions are per UAV, so swarms of any size feed one replay buffer
(`AgentReplay`).

The off-policy learner here is TD3 (Fujimoto et al. 2018): the paper's DDPG with twin critics
(the smaller target of the two), target-policy smoothing and a delayed actor. The default
learner is PPO (`policies.generalist_ppo`), by the side-by-side of ``docs/MODEL.md`` §20.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor, nn

from policies.config import GeneralistConfig
from policies.ddpg import FINAL_INIT, EnsembleLinear, soft_update
from sim.observation import INTRUDER_COLUMNS, NEIGHBOUR_COLUMNS, ObservationLayout
from sim.setnet import ATTENTION_HEADS, set_shapes


class SetNet(nn.Module):
    """Actor (``critic`` False: obs → action in [−1, 1]) or critic (obs, action → Q).

    Every layer is an `EnsembleLinear` of one member: ``<layer>.weight`` (1, in, out),
    ``<layer>.bias`` (1, 1, out), `sim.setnet.set_layers` of its ``pooling``.
    """

    def __init__(
        self, layout: ObservationLayout, hidden: int, critic: bool, pooling: str = "max-mean"
    ) -> None:
        super().__init__()
        self.layout, self.critic, self.pooling = layout, critic, pooling
        self.blocks = layout.blocks()
        for name, (fan_in, fan_out) in set_shapes(hidden, critic, pooling).items():
            init = FINAL_INIT if name == "out" else None
            self.add_module(name, EnsembleLinear(1, fan_in, fan_out, init=init))

    def _layer(self, name: str, x: Tensor, relu: bool = True) -> Tensor:
        layer: EnsembleLinear = self._modules[name]  # type: ignore[assignment]
        lead = x.shape[:-1]
        y = layer(x.reshape(1, -1, x.shape[-1])).reshape(*lead, layer.weight.shape[-1])
        return torch.relu(y) if relu else y

    def _pool(
        self, rows: Tensor, mask: Tensor, first: str, second: str, query: Tensor | None
    ) -> list[Tensor]:
        e = self._layer(second, self._layer(first, rows)) * mask[..., None]  # (B, R, h) ≥ 0
        if e.shape[-2] == 0:
            zero = e.new_zeros(*e.shape[:-2], e.shape[-1])
            return [zero, zero]
        if query is not None:
            return [e.max(dim=-2).values, self._attend(e, mask, query)]
        count = mask.sum(dim=-1, keepdim=True).clamp_min(1.0)
        # In the rows' order, as the numpy forward (a sort before the sum cost a third of a
        # forward and backward pass).
        return [e.max(dim=-2).values, e.sum(dim=-2) / count]

    @staticmethod
    def _attend(e: Tensor, mask: Tensor, query: Tensor) -> Tensor:
        """`sim.setnet.attend`."""
        b, rows, h = e.shape
        d = h // ATTENTION_HEADS
        heads = e.reshape(b, rows, ATTENTION_HEADS, d)
        score = (heads * query.reshape(b, 1, ATTENTION_HEADS, d)).sum(-1) / d**0.5  # (B, R, H)
        keep = mask[..., None] > 0
        score = score.masked_fill(~keep, float("-inf"))
        top = score.max(dim=-2, keepdim=True).values
        top = torch.where(torch.isfinite(top), top, torch.zeros_like(top)).detach()
        weight = torch.exp(score - top) * keep
        weight = weight / weight.sum(dim=-2, keepdim=True).clamp_min(1e-30)
        return (heads * weight[..., None]).sum(dim=-3).reshape(b, h)

    def encode(self, obs: Tensor) -> Tensor:
        """(B, 5h) pooled features of flat version-2 observations (B, D)."""
        b, k, m = obs.shape[0], self.layout.max_neighbours, self.layout.max_obstacles
        bl = self.blocks
        nb = obs[:, bl["neighbours"]].reshape(b, k, NEIGHBOUR_COLUMNS)
        it = obs[:, bl["intruders"]].reshape(b, m, INTRUDER_COLUMNS)
        own = self._layer("self", obs[:, bl["self"]])
        attention = self.pooling == "max-attention"
        nb_q = self._layer("nbq", own, relu=False) if attention else None
        it_q = self._layer("inq", own, relu=False) if attention else None
        parts = [
            own,
            *self._pool(nb, obs[:, bl["neighbour_mask"]], "nb1", "nb2", nb_q),
            *self._pool(it, obs[:, bl["intruder_mask"]], "in1", "in2", it_q),
        ]
        return torch.cat(parts, dim=-1)

    def forward(self, obs: Tensor, action: Tensor | None = None) -> Tensor:
        """Actor: (B, D) → (B,) actions. Critic: (B, D), (B,) → (B,) Q-values."""
        z = self.encode(obs)
        if self.critic:
            assert action is not None
            z = torch.cat([z, action[:, None]], dim=-1)
        h = self._layer("l2", self._layer("l1", z))
        out = self._layer("out", h, relu=False)[:, 0]
        return out if self.critic else torch.tanh(out)

    def numpy_state(self) -> dict[str, NDArray[np.float32]]:
        """``<layer>.weight`` / ``.bias`` as float32 arrays (what the policy file holds)."""
        return {
            k: v.detach().cpu().numpy().astype(np.float32) for k, v in self.state_dict().items()
        }


@dataclass
class TD3Nets:
    """The actor, the twin critics, their targets and optimisers."""

    actor: SetNet
    critics: nn.ModuleList
    actor_target: SetNet
    critic_targets: nn.ModuleList
    actor_opt: torch.optim.Optimizer
    critic_opt: torch.optim.Optimizer

    @classmethod
    def create(cls, layout: ObservationLayout, cfg: GeneralistConfig, device: str) -> TD3Nets:
        """Fresh networks on ``device`` (targets start as copies)."""
        actor = SetNet(layout, cfg.hidden, critic=False, pooling=cfg.pooling).to(device)
        critics = nn.ModuleList(
            [SetNet(layout, cfg.hidden, critic=True, pooling=cfg.pooling) for _ in range(2)]
        )
        critics = critics.to(device)
        actor_t, critics_t = copy.deepcopy(actor), copy.deepcopy(critics)
        for p in (*actor_t.parameters(), *critics_t.parameters()):
            p.requires_grad_(False)
        return cls(
            actor,
            critics,
            actor_t,
            critics_t,
            torch.optim.Adam(actor.parameters(), lr=cfg.actor_lr),
            torch.optim.Adam(critics.parameters(), lr=cfg.critic_lr),
        )

    def modules(self) -> dict[str, nn.Module]:
        """Every network by checkpoint name."""
        return {
            "actor": self.actor,
            "critics": self.critics,
            "actor_target": self.actor_target,
            "critic_targets": self.critic_targets,
        }

    def optimisers(self) -> dict[str, torch.optim.Optimizer]:
        """Every optimiser by checkpoint name."""
        return {"actor_opt": self.actor_opt, "critic_opt": self.critic_opt}


@dataclass(frozen=True)
class AgentBatch:
    """Per-UAV transitions: obs, next_obs (B, D); action, reward, terminal_value (B,).

    ``terminal`` (B,) bool: the UAV's trajectory ended (bootstrap with ``terminal_value``).
    ``teacher`` (B,): the teacher's action where a teacher flew the transition, NaN elsewhere.
    """

    obs: Tensor
    action: Tensor
    reward: Tensor
    next_obs: Tensor
    terminal: Tensor
    terminal_value: Tensor
    teacher: Tensor


class AgentReplay:
    """A ring of per-UAV transitions (numpy, float32): swarms of any size share it."""

    def __init__(self, capacity: int, obs_size: int) -> None:
        self.capacity, self.size, self.pos = capacity, 0, 0
        self.obs = np.zeros((capacity, obs_size), np.float32)
        self.next_obs = np.zeros((capacity, obs_size), np.float32)
        self.action = np.zeros(capacity, np.float32)
        self.reward = np.zeros(capacity, np.float32)
        self.terminal = np.zeros(capacity, bool)
        self.terminal_value = np.zeros(capacity, np.float32)
        self.teacher = np.full(capacity, np.nan, np.float32)

    def add(self, **columns: NDArray[Any]) -> None:
        """Store T transitions at once (the newest ``capacity`` if T exceeds it).

        Columns: ``obs``, ``next_obs`` (T, D); ``action``, ``reward``, ``terminal``,
        ``terminal_value`` (T,); optionally ``teacher`` (T,) (absent: NaN, no teacher).
        """
        count = len(columns["obs"])
        columns.setdefault("teacher", np.full(count, np.nan, np.float32))
        if count > self.capacity:
            columns = {k: v[-self.capacity :] for k, v in columns.items()}
            count = self.capacity
        idx = (self.pos + np.arange(count)) % self.capacity
        for name, value in columns.items():
            getattr(self, name)[idx] = value
        self.pos = int((self.pos + count) % self.capacity)
        self.size = min(self.size + count, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator, device: str) -> AgentBatch:
        """A uniform sample of transitions as tensors on ``device``."""
        idx = rng.integers(0, self.size, batch_size)

        def tensor(x: NDArray[Any]) -> Tensor:
            return torch.from_numpy(x[idx]).to(device)

        return AgentBatch(
            obs=tensor(self.obs),
            action=tensor(self.action),
            reward=tensor(self.reward),
            next_obs=tensor(self.next_obs),
            terminal=tensor(self.terminal),
            terminal_value=tensor(self.terminal_value),
            teacher=tensor(self.teacher),
        )


def clone_step(nets: TD3Nets, batch: AgentBatch) -> float:
    """One supervised step of the actor toward the teacher's actions of the batch (MSE)."""
    has = ~torch.isnan(batch.teacher)
    if not bool(has.any()):
        return 0.0
    loss = ((nets.actor(batch.obs[has]) - batch.teacher[has]) ** 2).mean()
    nets.actor_opt.zero_grad(set_to_none=True)
    loss.backward()
    nets.actor_opt.step()
    return float(loss.detach())


def td3_update(
    nets: TD3Nets,
    batch: AgentBatch,
    cfg: GeneralistConfig,
    update_actor: bool,
    bc_weight: float = 0.0,
) -> dict[str, float]:
    """One critic step (and, with ``update_actor``, one actor step and the soft updates).

    ``bc_weight`` > 0: TD3+BC's actor loss, −Q/mean|Q| + α·(π − a_teacher)² over the batch's
    transitions a teacher flew.
    """
    with torch.no_grad():
        noise = (torch.randn_like(batch.action) * cfg.target_noise).clamp(
            -cfg.target_noise_clip, cfg.target_noise_clip
        )
        next_action = (nets.actor_target(batch.next_obs) + noise).clamp(-1.0, 1.0)
        next_q = torch.min(*(critic(batch.next_obs, next_action) for critic in nets.critic_targets))
        future = torch.where(batch.terminal, batch.terminal_value, next_q)
        target = batch.reward + cfg.gamma * future
    losses = [
        nn.functional.smooth_l1_loss(critic(batch.obs, batch.action), target)
        for critic in nets.critics
    ]
    critic_loss = losses[0] + losses[1]
    nets.critic_opt.zero_grad(set_to_none=True)
    critic_loss.backward()
    nn.utils.clip_grad_norm_(nets.critics.parameters(), cfg.grad_clip)
    nets.critic_opt.step()
    out = {"losses/critic": float(critic_loss.detach())}
    if update_actor:
        action = nets.actor(batch.obs)
        q_pi = nets.critics[0](batch.obs, action)
        actor_loss = -q_pi.mean()
        has = ~torch.isnan(batch.teacher)
        if bc_weight > 0 and bool(has.any()):
            actor_loss = actor_loss / q_pi.abs().mean().detach().clamp_min(1e-6)
            actor_loss = actor_loss + bc_weight * ((action[has] - batch.teacher[has]) ** 2).mean()
        nets.actor_opt.zero_grad(set_to_none=True)
        actor_loss.backward()
        nn.utils.clip_grad_norm_(nets.actor.parameters(), cfg.grad_clip)
        nets.actor_opt.step()
        soft_update(nets.actor_target, nets.actor, cfg.tau)
        soft_update(nets.critic_targets, nets.critics, cfg.tau)
        out["losses/actor"] = float(actor_loss.detach())
    return out
