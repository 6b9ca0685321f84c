"""Gymnasium and PettingZoo faces of the swarm simulator (`sim.swarm`).

* `make_vector_env` → `SwarmVectorEnv`, the batched environment for training (Gymnasium vector
  conventions, with an agent dimension: arrays are (num_envs, N, ...); in `sim.vector_env`).
* `make_parallel_env` → `SwarmParallelEnv`, a PettingZoo ``ParallelEnv`` of one environment.
* `make_env` → `SwarmEnv`, a single-agent Gymnasium ``Env`` in which one controller commands the
  whole swarm (for ``check_env`` and single-agent libraries).

Observation of one UAV (float32, length (2 + m)·4 + m; m = ``sensing.max_obstacles``), all in
the UAV's heading frame (x ahead, y to the left), positions / sensing range, velocities / UAV
speed:

| Num          | Observation                               | Unit              | Min  | Max |
|--------------|-------------------------------------------|-------------------|------|-----|
| 0, 1         | target − own position                     | m / range_m       | -10  | 10  |
| 2, 3         | own velocity                              | (m/s) / speed_m_s | -10  | 10  |
| 4, 5         | virtual centre p* − own position          | m / range_m       | -10  | 10  |
| 6, 7         | pre-planned velocity v̄ (toward target)    | (m/s) / speed_m_s | -10  | 10  |
| 8 + 4k, +1   | k-th nearest sensed obstacle − own pos.   | m / range_m       | -1   | 1   |
| 10 + 4k, +1  | its velocity                              | (m/s) / speed_m_s | -10  | 10  |
| (2+m)·4 + k  | 1 if obstacle row k holds an obstacle     | –                 | 0    | 1   |

Entries are clipped to ±10 (`sim.observation.CLIP`).

Action of one UAV (float32): the heading change over the next decision step, normalised:

| Num | Action                              | Unit        | Min | Max |
|-----|-------------------------------------|-------------|-----|-----|
| 0   | heading change / a_max (π/4 rad)    | –           | -1  | 1   |

Reward: the reMARL reward r = −f(S, Φ) + r_form·r_collide (``reward="remarl"``) or its Swarming
part alone (``reward="swarming"``, what the baselines train on); ``infos`` carry both.

Version History:
* v0: initial release.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from pettingzoo import ParallelEnv

from sim.config import ScenarioConfig
from sim.swarm import StepResult
from sim.vector_env import (
    RewardMode,
    SwarmVectorEnv,
    agent_spaces,
    episode_metrics,
    make_vector_env,
)

__all__ = [
    "ENV_ID",
    "ParallelStep",
    "RewardMode",
    "SwarmEnv",
    "SwarmParallelEnv",
    "SwarmVectorEnv",
    "agent_spaces",
    "episode_metrics",
    "make_env",
    "make_parallel_env",
    "make_vector_env",
    "register",
]

ENV_ID = "remarl/Swarm-v0"
"""Gymnasium id of the single-agent face, after `register` is called."""

ParallelStep = tuple[
    dict[str, NDArray[np.float32]],
    dict[str, float],
    dict[str, bool],
    dict[str, bool],
    dict[str, dict[str, Any]],
]
"""What a PettingZoo ``step`` returns: observations, rewards, terminations, truncations and
infos, each keyed by agent."""


class OneSwarm:
    """One environment of `SwarmVectorEnv`, stepped without autoreset: the single-episode faces.

    Args:
        scenario: a scenario name, file or config.
        reward: "remarl" (the full reward) or "swarming" (its Swarming part).
        render_mode: None or "rgb_array".
        **overrides: scenario overrides, as `sim.scenarios.load_scenario`.
    """

    def __init__(
        self,
        scenario: str | Path | ScenarioConfig = "3u2o",
        *,
        reward: RewardMode = "remarl",
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        self._vec = SwarmVectorEnv(scenario, 1, reward=reward, render_mode=render_mode, **overrides)
        self.cfg = self._vec.cfg
        self.render_mode = render_mode
        self._setup()

    def _setup(self) -> None:
        """What a face adds to the environment (called at the end of ``__init__``)."""

    def _advance(self, actions: NDArray[Any]) -> StepResult:
        """Step the swarm with (1, N) normalised actions; the episode stays finished."""
        return self._vec.step_without_reset(actions)

    def _finished_episode(self, result: StepResult) -> dict[str, Any] | None:
        """The episode's metrics (`episode_metrics`) if it ended on ``result``, else None."""
        if not (result.terminated[0] or result.truncated[0]):
            return None
        metrics = episode_metrics(self._vec.state, result, np.ones(1, bool))
        return {k: v[0] for k, v in metrics.items()}

    def render(self) -> NDArray[np.uint8] | None:
        """An RGB picture of the episode so far."""
        return self._vec.render()


class SwarmParallelEnv(OneSwarm, ParallelEnv[str, NDArray[np.float32], NDArray[np.float32]]):  # type: ignore[misc]
    """PettingZoo face: one environment; agents "uav_0"… leave when they reach their target.

    An agent is terminated when it arrives or when the episode ends on a collision; all agents
    are truncated at the step limit. ``infos[agent]`` holds its Swarming and Contour rewards.
    See the module docstring for the spaces, and `OneSwarm` for the arguments.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - PettingZoo's class-level convention
        "name": "remarl_swarm_v0",
        "render_modes": ["rgb_array"],
        "render_fps": 4,
        "is_parallelizable": True,
    }

    def _setup(self) -> None:
        self.possible_agents = [f"uav_{i}" for i in range(self.cfg.uav.count)]
        self.agents: list[str] = []
        self._obs_space: spaces.Box
        self._act_space: spaces.Space[Any]
        self._obs_space, self._act_space = agent_spaces(self.cfg)

    @functools.cache  # noqa: B019 - spaces are constant per instance, as PettingZoo recommends
    def observation_space(self, agent: str) -> spaces.Box:
        """Observation space of one UAV."""
        return self._obs_space

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Space[Any]:
        """Action space of one UAV."""
        return self._act_space

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, dict[str, Any]]]:
        """Start a new episode."""
        obs, _ = self._vec.reset(seed=seed)
        self.agents = list(self.possible_agents)
        return {a: obs[0, i] for i, a in enumerate(self.possible_agents)}, {
            a: {} for a in self.agents
        }

    def _joint_action(self, actions: dict[str, Any]) -> NDArray[np.float32]:
        """(1, N) normalised heading changes from ``actions``; a missing agent flies straight."""
        joint = np.zeros((1, len(self.possible_agents)), dtype=np.float32)
        for agent, action in actions.items():
            joint[0, self.possible_agents.index(agent)] = self._action_value(agent, action)
        return joint

    def _action_value(self, agent: str, action: Any) -> Any:
        """The normalised heading change of one agent's action (a (1,) array or a number)."""
        return np.asarray(action).reshape(-1)[0]

    def step(self, actions: dict[str, Any]) -> ParallelStep:
        """Step the live agents; agents missing from ``actions`` fly straight."""
        result = self._advance(self._joint_action(actions))
        obs = result.obs.flat()[0]
        rewards = self._vec.rewards_of(result)
        live = list(self.agents)
        idx = {a: self.possible_agents.index(a) for a in live}
        ended = bool(result.terminated[0])
        term = {a: bool(ended or result.arrived[0, i]) for a, i in idx.items()}
        trunc = {a: bool(result.truncated[0]) for a in live}
        infos = {
            a: {
                "swarming": float(result.reward.swarming[0, i]),
                "contour": float(result.reward.contour[0, i]),
                "arrived": bool(result.arrived[0, i]),
                "collided": bool(result.collided_u2o[0, i] or result.collided_u2u[0, i]),
            }
            for a, i in idx.items()
        }
        out_obs = {a: obs[i] for a, i in idx.items()}
        out_rew = {a: float(rewards[0, i]) for a, i in idx.items()}
        self.agents = [a for a in live if not (term[a] or trunc[a])]
        return out_obs, out_rew, term, trunc, infos

    def close(self) -> None:
        """Nothing to release."""

    def state(self) -> NDArray[np.float32]:
        """Global state: every UAV's observation, concatenated."""
        flat: NDArray[np.float32] = self._vec.sim.observe(self._vec.state).flat()[0].reshape(-1)
        return flat


def make_parallel_env(scenario: str | Path | ScenarioConfig, **overrides: Any) -> SwarmParallelEnv:
    """The PettingZoo ``ParallelEnv`` of a scenario (name, file or config)."""
    return SwarmParallelEnv(scenario, **overrides)


class SwarmEnv(OneSwarm, gymnasium.Env[NDArray[np.float32], NDArray[np.float32]]):
    """Single-agent face: one controller commands all N UAVs of one environment.

    Observation (N, D) and action (N,) as in the module docstring; the reward is the sum of
    the agents' rewards; the episode terminates on a collision or when all UAVs arrived.
    Arguments: `OneSwarm` (the scenario defaults to "3u2o").
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - Gymnasium's class-level convention
        "render_modes": ["rgb_array"],
        "render_fps": 4,
    }

    def _setup(self) -> None:
        self.observation_space = self._vec.single_observation_space
        self.action_space = self._vec.single_action_space

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start a new episode."""
        super().reset(seed=seed)
        if seed is None:
            seed = int(self.np_random.integers(2**63))
        obs, info = self._vec.reset(seed=seed)
        return obs[0], {"active": info["active"][0]}

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        """Step the swarm (no autoreset: call `reset` after the episode ends)."""
        result = self._advance(np.asarray(action)[None])
        rewards = self._vec.rewards_of(result)
        info: dict[str, Any] = {"active": self._vec.state.active[0].copy()}
        episode = self._finished_episode(result)
        if episode is not None:
            info["episode"] = episode
        return (
            result.obs.flat()[0],
            float(rewards[0].sum()),
            bool(result.terminated[0]),
            bool(result.truncated[0]),
            info,
        )


def make_env(scenario: str | Path | ScenarioConfig = "3u2o", **overrides: Any) -> SwarmEnv:
    """The single-agent Gymnasium face of a scenario."""
    return SwarmEnv(scenario, **overrides)


def register() -> None:
    """Register `ENV_ID` with Gymnasium (explicit: importing this module registers nothing)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(ENV_ID, entry_point="sim.env:SwarmEnv")
