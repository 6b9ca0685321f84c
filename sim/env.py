"""Gymnasium and PettingZoo faces of the swarm simulator (`sim.swarm`).

* `make_vector_env` → `SwarmVectorEnv`, the batched environment for training (Gymnasium vector
  conventions, with an agent dimension: arrays are (num_envs, N, ...)).
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
from typing import Any, Literal

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray
from pettingzoo import ParallelEnv

from sim.config import ScenarioConfig
from sim.metrics import path_length_ratio
from sim.observation import CLIP, ObservationLayout
from sim.scenarios import load_scenario
from sim.swarm import StepResult, SwarmSim, SwarmState

ENV_ID = "remarl/Swarm-v0"
"""Gymnasium id of the single-agent face, after `register` is called."""

RewardMode = Literal["remarl", "swarming"]
FloatArray = NDArray[np.float64]


def _scenario(scenario: str | Path | ScenarioConfig, overrides: dict[str, Any]) -> ScenarioConfig:
    if isinstance(scenario, ScenarioConfig):
        if overrides:
            raise ValueError("overrides apply to scenario names or files, not to a ScenarioConfig")
        return scenario
    return load_scenario(scenario, **overrides)


def agent_spaces(cfg: ScenarioConfig) -> tuple[spaces.Box, spaces.Box]:
    """(observation space, action space) of one UAV."""
    layout = ObservationLayout.from_scenario(cfg)
    low = np.full(layout.size, -CLIP, dtype=np.float32)
    high = np.full(layout.size, CLIP, dtype=np.float32)
    low[-layout.max_obstacles :], high[-layout.max_obstacles :] = 0.0, 1.0  # the mask
    obs = spaces.Box(low, high, dtype=np.float32)
    act = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
    return obs, act


def episode_metrics(
    state: SwarmState, result: StepResult, done: NDArray[np.bool_]
) -> dict[str, Any]:
    """Per-environment episode metrics (SPEC §9) for the environments in ``done`` (B,)."""
    s = state.stats
    # Detour measure: distance flown over the straight line to where each UAV arrived.
    ratio = path_length_ratio(s.flown_m, state.start_m, state.pos_m)
    return {
        "success": result.success[done],
        "collision_u2o": np.asarray(result.collided_u2o.any(axis=-1))[done],
        "collision_u2u": np.asarray(result.collided_u2u.any(axis=-1))[done],
        "min_d_u2o_m": s.min_u2o_m[done],
        "min_d_u2u_m": s.min_u2u_m[done],
        "energy_rad": s.energy_rad.mean(axis=-1)[done],
        "path_length_ratio": np.where(state.reached, ratio, np.nan)[done],
        "swarming_return": s.swarming_return.sum(axis=-1)[done],
        "total_return": s.total_return.sum(axis=-1)[done],
        "length": state.steps[done],
    }


class SwarmVectorEnv(VectorEnv[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]):
    """B swarm environments stepped as one batch (see the module docstring for the spaces).

    Arrays carry an agent dimension: observations (B, N, D), actions (B, N), rewards (B, N);
    terminations and truncations are per environment (B,).

    Autoreset: ``AutoresetMode.SAME_STEP``. An environment whose episode ends is reset within
    the same ``step``: the returned observation is the first of its new episode, the last one
    of the old episode is in ``infos["final_obs"]`` (valid where ``infos["_final_obs"]``), and its
    metrics are in ``infos["episode"]`` (arrays over the environments that ended, in order).

    ``infos`` of every step: ``acted`` (B, N) agents that flew this step; ``agent_done`` (B, N)
    agents whose trajectory ended this step (arrived, or the episode terminated); ``active``
    (B, N) agents that act next; ``swarming``, ``contour`` (B, N) reward parts;
    ``collided_u2o``, ``collided_u2u``, ``arrived`` (B, N).
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - Gymnasium's class-level convention
        "autoreset_mode": AutoresetMode.SAME_STEP,
        "render_modes": ["rgb_array"],
        "render_fps": 4,
    }

    def __init__(
        self,
        scenario: str | Path | ScenarioConfig,
        num_envs: int,
        *,
        reward: RewardMode = "remarl",
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        if reward not in ("remarl", "swarming"):
            raise ValueError(f'reward must be "remarl" or "swarming", got {reward!r}')
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f'render_mode must be None or "rgb_array", got {render_mode!r}')
        self.cfg = _scenario(scenario, overrides)
        self.sim = SwarmSim(self.cfg)
        self.num_envs = num_envs
        self.num_agents = self.cfg.uav.count
        self.reward_mode: RewardMode = reward
        self.render_mode = render_mode
        obs, _ = agent_spaces(self.cfg)
        n = self.num_agents
        self.single_observation_space = spaces.Box(
            np.broadcast_to(obs.low, (n, *obs.shape)),
            np.broadcast_to(obs.high, (n, *obs.shape)),
            dtype=np.float32,
        )
        self.single_action_space = spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.obs_layout_size = int(obs.shape[0])
        """D, the length of one UAV's flat observation."""
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._rng = np.random.default_rng()
        self._state: SwarmState | None = None
        self._trails: list[list[FloatArray]] = []

    @property
    def state(self) -> SwarmState:
        """The simulator state (raises if `reset` was not called)."""
        if self._state is None:
            raise RuntimeError("call reset() before step() or state")
        return self._state

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start new episodes; ``options={"reset_mask": (B,) bool}`` resets only some."""
        if isinstance(seed, list):
            seed = seed[0]
        if seed is not None or self._state is None:
            self._rng = np.random.default_rng(seed)
        mask = None if options is None else options.get("reset_mask")
        if mask is None or self._state is None:
            self._state = self.sim.initial_state(self._rng, self.num_envs)
        else:
            mask = np.asarray(mask, dtype=bool)
            self._state = self.sim.reset_where(self._state, mask, self._rng)
        self._trails = [[self._state.pos_m[0].copy()]]
        obs = self.sim.observe(self._state).flat()
        return obs, {"active": self._state.active.copy()}

    def step(  # type: ignore[override]
        self, actions: NDArray[np.float32]
    ) -> tuple[
        NDArray[np.float32],
        NDArray[np.float32],
        NDArray[np.bool_],
        NDArray[np.bool_],
        dict[str, Any],
    ]:
        """Step every environment (see the class docstring for the autoreset and ``infos``)."""
        state, result = self.sim.step(self.state, np.asarray(actions), self._rng)
        rewards = self.rewards_of(result)
        done = result.terminated | result.truncated
        obs = result.obs.flat()
        infos: dict[str, Any] = {
            "acted": result.acted,
            "agent_done": result.acted & (result.arrived | result.terminated[:, None]),
            "swarming": result.reward.swarming,
            "contour": result.reward.contour,
            "collided_u2o": result.collided_u2o,
            "collided_u2u": result.collided_u2u,
            "arrived": result.arrived,
        }
        if done.any():
            infos["episode"] = episode_metrics(state, result, done)
            infos["final_obs"] = obs.copy()
            infos["_final_obs"] = done.copy()
            state = self.sim.reset_where(state, done, self._rng)
            obs[done] = self.sim.observe(state, done).flat()
        self._state = state
        infos["active"] = state.active.copy()
        if self.render_mode is not None:
            if done[0]:
                self._trails = [[state.pos_m[0].copy()]]
            else:
                self._trails[0].append(state.pos_m[0].copy())
        return obs, rewards.astype(np.float32), result.terminated, result.truncated, infos

    def step_without_reset(self, actions: NDArray[Any]) -> StepResult:
        """Step every environment and keep finished episodes finished (no autoreset).

        The single-episode faces (`SwarmParallelEnv`, `SwarmEnv`) step this way; the caller
        resets when it wants a new episode.
        """
        state, result = self.sim.step(self.state, np.asarray(actions), self._rng)
        self._state = state
        if self.render_mode is not None:
            self._trails[0].append(state.pos_m[0].copy())
        return result

    def rewards_of(self, result: StepResult) -> NDArray[np.float64]:
        """The rewards this environment pays: the reMARL reward or its Swarming part, (B, N)."""
        return result.reward.total if self.reward_mode == "remarl" else result.reward.swarming

    def render(self) -> NDArray[np.uint8] | None:  # type: ignore[override]
        """An RGB picture of environment 0: field contours, UAVs, obstacles, targets, trails."""
        if self.render_mode is None:
            return None
        from sim.render import render_frame

        return render_frame(self.cfg, self.state, 0, np.asarray(self._trails[0]))


def make_vector_env(
    scenario: str | Path | ScenarioConfig, num_envs: int, **overrides: Any
) -> SwarmVectorEnv:
    """The batched training environment of a scenario (name, file or config).

    Keyword arguments ``reward`` and ``render_mode`` configure the environment; any other
    keyword overrides the scenario (``reward_cfg={"external": "gradient"}`` is spelled
    ``**{"reward": ...}`` only through `sim.scenarios.load_scenario`).
    """
    return SwarmVectorEnv(scenario, num_envs, **overrides)


class SwarmParallelEnv(ParallelEnv[str, NDArray[np.float32], NDArray[np.float32]]):  # type: ignore[misc]
    """PettingZoo face: one environment; agents "uav_0"… leave when they reach their target.

    An agent is terminated when it arrives or when the episode ends on a collision; all agents
    are truncated at the step limit. ``infos[agent]`` holds its Swarming and Contour rewards.
    See the module docstring for the spaces.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - PettingZoo's class-level convention
        "name": "remarl_swarm_v0",
        "render_modes": ["rgb_array"],
        "render_fps": 4,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str | Path | ScenarioConfig,
        *,
        reward: RewardMode = "remarl",
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        self._vec = SwarmVectorEnv(scenario, 1, reward=reward, render_mode=render_mode, **overrides)
        self.cfg = self._vec.cfg
        self.render_mode = render_mode
        self.possible_agents = [f"uav_{i}" for i in range(self.cfg.uav.count)]
        self.agents: list[str] = []
        self._obs_space, self._act_space = agent_spaces(self.cfg)

    @functools.cache  # noqa: B019 - spaces are constant per instance, as PettingZoo recommends
    def observation_space(self, agent: str) -> spaces.Box:
        """Observation space of one UAV."""
        return self._obs_space

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Box:
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

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[
        dict[str, NDArray[np.float32]],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        """Step the live agents; agents missing from ``actions`` fly straight."""
        vec_actions = np.zeros((1, self.cfg.uav.count), dtype=np.float32)
        for agent, action in actions.items():
            vec_actions[0, self.possible_agents.index(agent)] = np.asarray(action).reshape(-1)[0]
        result = self._vec.step_without_reset(vec_actions)
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

    def render(self) -> NDArray[np.uint8] | None:
        """An RGB picture of the episode so far."""
        return self._vec.render()

    def close(self) -> None:
        """Nothing to release."""

    def state(self) -> NDArray[np.float32]:
        """Global state: every UAV's observation, concatenated."""
        flat: NDArray[np.float32] = self._vec.sim.observe(self._vec.state).flat()[0].reshape(-1)
        return flat


def make_parallel_env(scenario: str | Path | ScenarioConfig, **overrides: Any) -> SwarmParallelEnv:
    """The PettingZoo ``ParallelEnv`` of a scenario (name, file or config)."""
    return SwarmParallelEnv(scenario, **overrides)


class SwarmEnv(gymnasium.Env[NDArray[np.float32], NDArray[np.float32]]):
    """Single-agent face: one controller commands all N UAVs of one environment.

    Observation (N, D) and action (N,) as in the module docstring; the reward is the sum of
    the agents' rewards; the episode terminates on a collision or when all UAVs arrived.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - Gymnasium's class-level convention
        "render_modes": ["rgb_array"],
        "render_fps": 4,
    }

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
        result = self._vec.step_without_reset(np.asarray(action)[None])
        state = self._vec.state
        rewards = self._vec.rewards_of(result)
        info: dict[str, Any] = {"active": state.active[0].copy()}
        if result.terminated[0] or result.truncated[0]:
            info["episode"] = {
                k: v[0] for k, v in episode_metrics(state, result, np.ones(1, bool)).items()
            }
        return (
            result.obs.flat()[0],
            float(rewards[0].sum()),
            bool(result.terminated[0]),
            bool(result.truncated[0]),
            info,
        )

    def render(self) -> NDArray[np.uint8] | None:
        """An RGB picture of the episode so far."""
        return self._vec.render()


def make_env(scenario: str | Path | ScenarioConfig = "3u2o", **overrides: Any) -> SwarmEnv:
    """The single-agent Gymnasium face of a scenario."""
    return SwarmEnv(scenario, **overrides)


def register() -> None:
    """Register `ENV_ID` with Gymnasium (explicit: importing this module registers nothing)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(ENV_ID, entry_point="sim.env:SwarmEnv")
