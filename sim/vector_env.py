"""The batched training environment of the swarm simulator (`sim.swarm`), and its metrics.

`SwarmVectorEnv` follows Gymnasium's vector conventions with an agent dimension: arrays are
(num_envs, N, ...). The spaces of one UAV (`agent_spaces`), the rewards and the version history
are documented in `sim.env`, whose single-episode faces step this environment.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from sim.arrays import FloatArray
from sim.config import ScenarioConfig
from sim.metrics import path_length_ratio
from sim.observation import CLIP, ObservationLayout
from sim.scenarios import load_scenario
from sim.swarm import StepResult, SwarmSim, SwarmState

RewardMode = Literal["remarl", "swarming"]


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
    envs = np.flatnonzero(done)  # every metric is per environment: select them first
    # Detour measure: distance flown over the straight line to where each UAV arrived.
    ratio = path_length_ratio(s.flown_m[envs], state.start_m[envs], state.pos_m[envs])
    return {
        "success": result.success[envs],
        "collision_u2o": np.asarray(result.collided_u2o[envs].any(axis=-1)),
        "collision_u2u": np.asarray(result.collided_u2u[envs].any(axis=-1)),
        "min_d_u2o_m": s.min_u2o_m[envs],
        "min_d_u2u_m": s.min_u2u_m[envs],
        "energy_rad": s.energy_rad[envs].mean(axis=-1),
        "path_length_ratio": np.where(state.reached[envs], ratio, np.nan),
        "swarming_return": s.swarming_return[envs].sum(axis=-1),
        "total_return": s.total_return[envs].sum(axis=-1),
        "length": state.steps[envs],
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
        self, actions: NDArray[np.float32], speeds_m_s: NDArray[np.floating[Any]] | None = None
    ) -> tuple[
        NDArray[np.float32],
        NDArray[np.float32],
        NDArray[np.bool_],
        NDArray[np.bool_],
        dict[str, Any],
    ]:
        """Step every environment (see the class docstring for the autoreset and ``infos``).

        ``speeds_m_s`` (B, N): commanded speeds (`sim.swarm.SwarmSim.step`); None: full speed.
        """
        state, result = self.sim.step(
            self.state, np.asarray(actions), self._rng, speeds_m_s=speeds_m_s
        )
        rewards = self.rewards_of(result)
        done = result.terminated | result.truncated
        obs = result.obs.flat_shared()  # the step's own observations: no copy needed
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
            state, fresh = self.sim.restart_where(state, done, self._rng)
            assert fresh is not None
            obs[done] = self.sim.observe(fresh).flat_shared()
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
