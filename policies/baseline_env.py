"""The swarm as a PettingZoo environment shaped for the BenchMARL baselines (no BenchMARL needed).

`SwarmBaselineEnv` is `sim.env.SwarmParallelEnv` with what BenchMARL (MAPPO, IQL, VDN, QMIX;
`policies.benchmarl_train`) needs, since it cannot handle agents that leave mid-episode:

- **Every agent stays present until the episode ends.** A UAV that reached its target keeps
  its place in ``agents``; from its arrival step on it is flagged terminated (BenchMARL's
  per-agent done flag), earns zero reward and observes zeros. Its actions are ignored.
- **Reward: the Swarming part only** (``reward="swarming"`` of `sim.env`), as the paper trains
  its baselines (SPEC §8).
- **Actions:** ``Discrete(n_actions)``; index k turns the UAV by ``heading_actions(n)[k]``·π/4
  (`policies.common.heading_actions`: normalised heading changes evenly on [−1, 1]). The
  default 11 hold 0, straight ahead; ``n_actions=10`` is the paper's literal grid (no straight
  ahead).
- **Global state** (`SwarmBaselineEnv.state`, for the MAPPO critic and the QMIX mixer): the N
  observations, zeroed for UAVs no longer flying, then N flags of the UAVs still flying —
  the state `policies.coma` gives its critic, so every centralised baseline sees the same —
  with the observations divided by 10 (`sim.observation.CLIP`) so that it lies in [−1, 1].
- The episode ends as the simulator's: a collision or every UAV arrived (all agents
  terminated), or the step limit (all agents truncated). Each finished episode's metrics come
  from `sim.env.episode_metrics`, the code that fills ``infos["episode"]`` of every method,
  and go to an `EpisodeLog` (the run's ``curve.csv``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from policies.common import CurveWriter, heading_actions
from sim.config import ScenarioConfig
from sim.env import ParallelStep, SwarmParallelEnv
from sim.observation import CLIP


@dataclass
class EpisodeLog:
    """Counts environment steps and records finished episodes (to ``path`` as CSV, if given).

    Shared by every training environment of a run (BenchMARL steps them one after the other in
    this process), so ``env_steps`` is the run's total when an episode ends. The file is
    `policies.common.CurveWriter`'s ``curve.csv``.
    """

    path: Path | None = None
    env_steps: int = 0
    rows: list[dict[str, float]] = field(default_factory=list)
    _curve: CurveWriter | None = field(default=None, repr=False, compare=False)

    def start(self) -> None:
        """Write the CSV header (truncating ``path``)."""
        if self.path is not None:
            self._curve = CurveWriter(self.path)

    def step(self) -> None:
        """One environment step happened."""
        self.env_steps += 1

    def episode(self, metrics: dict[str, Any]) -> None:
        """An episode ended; ``metrics`` from `sim.env.episode_metrics` (one environment)."""
        row = {
            "env_steps": float(self.env_steps),
            "episode": float(len(self.rows) + 1),
            "swarming_return": float(np.asarray(metrics["swarming_return"]).reshape(-1)[0]),
            "success": float(np.asarray(metrics["success"]).reshape(-1)[0]),
        }
        self.rows.append(row)
        if self._curve is not None:
            self._curve.add(self.env_steps, row["swarming_return"], bool(row["success"]))


class SwarmBaselineEnv(SwarmParallelEnv):
    """PettingZoo adapter for BenchMARL: agents stay until the episode ends (module docstring).

    Args:
        scenario: a scenario name, file or config.
        n_actions: size of the discrete heading set (`policies.common.heading_actions`).
        log: where finished episodes and steps are counted (optional).
        **overrides: scenario overrides, as `sim.env.make_vector_env`.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - PettingZoo's class-level convention
        "name": "remarl_swarm_baseline_v0",
        "render_modes": [],
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str | Path | ScenarioConfig,
        *,
        n_actions: int = 11,
        log: EpisodeLog | None = None,
        **overrides: Any,
    ) -> None:
        self.headings = heading_actions(n_actions)
        self.log = log
        super().__init__(scenario, reward="swarming", **overrides)

    def _setup(self) -> None:
        super()._setup()
        n = len(self.possible_agents)
        self._act_space = spaces.Discrete(len(self.headings))
        d = int(self._obs_space.shape[0])
        low = np.concatenate([np.tile(np.minimum(self._obs_space.low, 0.0), n) / CLIP, np.zeros(n)])
        high = np.concatenate(
            [np.tile(np.maximum(self._obs_space.high, 0.0), n) / CLIP, np.ones(n)]
        )
        self.state_space = spaces.Box(
            low.astype(np.float32), high.astype(np.float32), dtype=np.float32
        )
        self._obs = np.zeros((n, d), dtype=np.float32)
        self._flying = np.zeros(n, dtype=bool)
        self.last_episode: dict[str, Any] | None = None
        """Metrics of the last finished episode (`sim.env.episode_metrics`, one environment)."""

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, dict[str, Any]]]:
        """Start a new episode; every agent is present and flying."""
        obs, infos = super().reset(seed, options)
        self._flying = self._vec.state.active[0].copy()
        self._obs = np.stack([obs[a] for a in self.possible_agents]) * self._flying[:, None]
        return {a: self._obs[i] for i, a in enumerate(self.possible_agents)}, infos

    def _action_value(self, agent: str, action: Any) -> Any:
        """The heading change of discrete action ``action`` (an index into the heading set)."""
        k = int(np.asarray(action).reshape(-1)[0])
        if not 0 <= k < len(self.headings):
            raise ValueError(f"{agent}: action {k} outside Discrete({len(self.headings)})")
        return self.headings[k]

    def step(self, actions: dict[str, Any]) -> ParallelStep:
        """Step the swarm; a missing action flies straight, a departed agent's is ignored.

        Every agent of ``possible_agents`` is in every returned dict until the episode ends.
        """
        if not self.agents:
            raise RuntimeError("the episode is over: call reset()")
        result = self._advance(self._joint_action(actions))
        state = self._vec.state
        swarming = np.where(result.acted[0], result.reward.swarming[0], 0.0)
        over_terminated, over_truncated = bool(result.terminated[0]), bool(result.truncated[0])
        reached = np.asarray(state.reached[0], dtype=bool)
        self._flying = np.asarray(state.active[0], dtype=bool).copy()
        self._obs = result.obs.flat()[0] * self._flying[:, None]
        agents = self.possible_agents
        obs = {a: self._obs[i] for i, a in enumerate(agents)}
        rewards = {a: float(swarming[i]) for i, a in enumerate(agents)}
        term = {a: bool(over_terminated or reached[i]) for i, a in enumerate(agents)}
        trunc = dict.fromkeys(agents, over_truncated)
        infos: dict[str, dict[str, Any]] = {
            a: {"swarming": rewards[a], "arrived": bool(reached[i])} for i, a in enumerate(agents)
        }
        if self.log is not None:
            self.log.step()
        episode = self._finished_episode(result)
        if episode is not None:
            self.last_episode = episode
            if self.log is not None:
                self.log.episode(episode)
            self.agents = []
        return obs, rewards, term, trunc, infos

    def state(self) -> NDArray[np.float32]:
        """Global state: the N observations / CLIP (zeroed for UAVs not flying), N flying flags.

        `policies.coma.global_state` with its observation part divided by
        `sim.observation.CLIP` (10), so that every entry lies in [−1, 1]: QMIX's hypernetworks,
        fed the unscaled state (entries up to ±10), drove the swarm away from its targets.
        """
        flat: NDArray[np.float32] = np.concatenate(
            [self._obs.reshape(-1) / CLIP, self._flying.astype(np.float32)]
        ).astype(np.float32)
        return flat

    def render(self) -> None:
        """No rendering: it would need torchvision in BenchMARL (`policies.benchmarl_train`)."""
        return None
