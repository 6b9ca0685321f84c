"""Replay buffer, batch first: one slot per environment step holds every agent's transition."""

from __future__ import annotations

import numpy as np
import torch
from numpy.typing import NDArray

from policies.ddpg import Batch


class ReplayBuffer:
    """A ring of ``capacity`` environment steps of N agents (numpy storage, float32).

    Each slot stores, per agent, the observation, action, reward, next observation, whether the
    trajectory ended there (``terminal``), the value to bootstrap with if it did, and whether the
    agent acted at all (agents that left the episode did not: their weight is 0).
    """

    def __init__(self, capacity: int, agents: int, obs_size: int) -> None:
        self.capacity, self.size, self.pos = capacity, 0, 0
        self.obs = np.zeros((capacity, agents, obs_size), np.float32)
        self.next_obs = np.zeros((capacity, agents, obs_size), np.float32)
        self.action = np.zeros((capacity, agents), np.float32)
        self.reward = np.zeros((capacity, agents), np.float32)
        self.terminal = np.zeros((capacity, agents), bool)
        self.terminal_value = np.zeros((capacity, agents), np.float32)
        self.weight = np.zeros((capacity, agents), np.float32)

    def add(
        self,
        obs: NDArray[np.float32],
        action: NDArray[np.float32],
        reward: NDArray[np.float32],
        next_obs: NDArray[np.float32],
        terminal: NDArray[np.bool_],
        terminal_value: NDArray[np.float32],
        acted: NDArray[np.bool_],
    ) -> None:
        """Store B environment steps at once: obs (B, N, D), the rest (B, N)."""
        b = obs.shape[0]
        idx = (self.pos + np.arange(b)) % self.capacity
        self.obs[idx], self.next_obs[idx] = obs, next_obs
        self.action[idx], self.reward[idx] = action, reward
        self.terminal[idx], self.terminal_value[idx] = terminal, terminal_value
        self.weight[idx] = acted
        self.pos = int((self.pos + b) % self.capacity)
        self.size = min(self.size + b, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator, shared: bool) -> Batch:
        """A uniform sample of slots as agent-first tensors (A = N, or 1 with ``shared``)."""
        idx = rng.integers(0, self.size, batch_size)

        def agent_first(x: NDArray[np.generic]) -> torch.Tensor:
            t = torch.from_numpy(np.ascontiguousarray(np.swapaxes(x[idx], 0, 1)))
            return t.reshape(1, -1, *t.shape[2:]) if shared else t

        return Batch(
            obs=agent_first(self.obs),
            action=agent_first(self.action),
            reward=agent_first(self.reward),
            next_obs=agent_first(self.next_obs),
            terminal=agent_first(self.terminal),
            terminal_value=agent_first(self.terminal_value),
            weight=agent_first(self.weight),
        )
