"""MAPPO, IQL, VDN and QMIX on the swarm simulator through BenchMARL (the ``baselines`` extra).

Three pieces:

* `SwarmBaselineEnv`, a PettingZoo ``ParallelEnv`` adapter over the simulator, shaped for
  BenchMARL, which cannot handle agents that leave mid-episode:

  - **Every agent stays present until the episode ends.** A UAV that reached its target keeps
    its place in ``agents``; from its arrival step on it is flagged terminated (BenchMARL's
    per-agent done flag), earns zero reward and observes zeros. Its actions are ignored.
  - **Reward: the Swarming part only** (``reward="swarming"`` of `sim.env`), as the paper trains
    its baselines (SPEC §8).
  - **Actions:** ``Discrete(n_actions)``; index k turns the UAV by ``heading_actions(n)[k]``·π/4
    (normalised heading changes evenly on [−1, 1]). The default 11 hold 0, straight ahead;
    ``n_actions=10`` is the paper's literal grid (no straight ahead).
  - **Global state** (`SwarmBaselineEnv.state`, for the MAPPO critic and the QMIX mixer): the N
    observations, zeroed for UAVs no longer flying, then N flags of the UAVs still flying —
    the state `policies.coma` gives its critic, so every centralised baseline sees the same —
    with the observations divided by 10 (`sim.observation.CLIP`) so that it lies in [−1, 1].
  - The episode ends as the simulator's: a collision or every UAV arrived (all agents
    terminated), or the step limit (all agents truncated). Each finished episode's metrics come
    from `sim.env.episode_metrics`, the code that fills ``infos["episode"]`` of every method.

* `SwarmTask`, the BenchMARL ``TaskClass`` that builds the adapter inside TorchRL's
  ``PettingZooWrapper`` (one group ``"agents"``; the episode is done when all agents are).

* `train_benchmarl`, which trains one algorithm with BenchMARL's ``Experiment`` on CPU with the
  small hyper-parameters of `BaselineHParams`, then evaluates the greedy policy with
  `sim.evaluation` (the evaluation code of every method). It writes in ``out_dir``::

      curve.csv      one row per finished training episode, from the simulator's own episode
                     metrics: env_steps, episode, swarming_return, success
      summary.json   what `train_benchmarl` returns
      benchmarl/     BenchMARL's experiment folder (its configuration; no loggers, no videos)

BenchMARL, TorchRL and TensorDict are imported inside functions only: this module imports
without them, and using them without the extra raises `BaselinesNotInstalledError`. Rendering
stays off, so the CUDA-built torchvision that BenchMARL pulls in from PyPI is never imported
(it does not load beside the CPU torch). Run with ``OMP_NUM_THREADS=1``.

Known behaviour: arrival is worth nothing beyond the arrival step's reward (zero reward after
it, no terminal value, unlike the project's DDPG and COMA, which value arrival as an absorbing
goal), and a collision costs only the rewards it cuts off. On 3u1o with 20k steps (about 50 s
each on one core) MAPPO, IQL, VDN and QMIX all raise their training Swarming return from about
7-12 to about 18-20 and converge towards flying nearly straight at the target (return 20, the
obstacle hit); their greedy success rate stays at 0-12 %.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import functools
import importlib
import itertools
import json
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from pettingzoo import ParallelEnv

from sim.config import ScenarioConfig
from sim.env import SwarmVectorEnv, agent_spaces, episode_metrics
from sim.errors import ConfigError
from sim.observation import CLIP

ALGORITHMS = ("mappo", "iql", "vdn", "qmix")
"""The BenchMARL algorithms `train_benchmarl` runs."""

GROUP = "agents"
"""The one BenchMARL agent group: every UAV, sharing its networks."""

INSTALL_HINT = "pip install 'remarl-fc[baselines]'"

EVAL_SEED_BASE = 2_000_000
"""Evaluation episodes use seeds EVAL_SEED_BASE + 1000·seed on (as `policies.compare`)."""

ENV_SEED_STRIDE = 10_007
"""The k-th environment a `SwarmTask` environment function builds is seeded
seed + k·ENV_SEED_STRIDE, so the collector's environments fly different spawn draws."""

CURVE_FIELDS = ("env_steps", "episode", "swarming_return", "success")


class BaselinesNotInstalledError(ConfigError, ImportError):
    """The BenchMARL baselines need the optional extra ``remarl-fc[baselines]``."""


def heading_actions(n_actions: int = 11) -> NDArray[np.float32]:
    """The discrete action set: ``n_actions`` normalised heading changes evenly on [−1, 1].

    The same set as `policies.coma.heading_actions`. In degrees:

    >>> (heading_actions() * 45).round(1).tolist()
    [-45.0, -36.0, -27.0, -18.0, -9.0, 0.0, 9.0, 18.0, 27.0, 36.0, 45.0]
    >>> (heading_actions(10) * 45).round(1).tolist()
    [-45.0, -35.0, -25.0, -15.0, -5.0, 5.0, 15.0, 25.0, 35.0, 45.0]
    """
    if isinstance(n_actions, bool) or not isinstance(n_actions, int) or n_actions < 2:
        raise ConfigError(f"n_actions must be an integer >= 2, got {n_actions!r}")
    values: NDArray[np.float32] = np.linspace(-1.0, 1.0, n_actions).astype(np.float32)
    return values


@dataclass
class EpisodeLog:
    """Counts environment steps and records finished episodes (to ``path`` as CSV, if given).

    Shared by every training environment of a run (BenchMARL steps them one after the other in
    this process), so ``env_steps`` is the run's total when an episode ends.
    """

    path: Path | None = None
    env_steps: int = 0
    rows: list[dict[str, float]] = field(default_factory=list)

    def start(self) -> None:
        """Write the CSV header (truncating ``path``)."""
        if self.path is not None:
            with self.path.open("w", newline="") as fh:
                csv.writer(fh).writerow(CURVE_FIELDS)

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
        if self.path is not None:
            with self.path.open("a", newline="") as fh:
                csv.writer(fh).writerow(
                    [int(row["env_steps"]), int(row["episode"]), row["swarming_return"],
                     int(row["success"])]
                )  # fmt: skip


class SwarmBaselineEnv(ParallelEnv[str, NDArray[np.float32], np.int64]):  # type: ignore[misc]
    """PettingZoo adapter for BenchMARL: agents stay until the episode ends (module docstring).

    Args:
        scenario: a scenario name, file or config.
        n_actions: size of the discrete heading set (`heading_actions`).
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
        self._vec = SwarmVectorEnv(scenario, 1, reward="swarming", **overrides)
        self.cfg = self._vec.cfg
        self.log = log
        n = self.cfg.uav.count
        self.possible_agents = [f"uav_{i}" for i in range(n)]
        self.agents: list[str] = []
        self._obs_space, _ = agent_spaces(self.cfg)
        self._act_space = spaces.Discrete(n_actions)
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

    @functools.cache  # noqa: B019 - spaces are constant per instance, as PettingZoo recommends
    def observation_space(self, agent: str) -> spaces.Box:
        """Observation space of one UAV (`sim.env`)."""
        return self._obs_space

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Discrete:
        """``Discrete(n_actions)``: an index into `heading_actions`."""
        return self._act_space

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, dict[str, Any]]]:
        """Start a new episode; every agent is present and flying."""
        obs, info = self._vec.reset(seed=seed)
        self._flying = np.asarray(info["active"][0], dtype=bool).copy()
        self._obs = obs[0] * self._flying[:, None]
        self.agents = list(self.possible_agents)
        return {a: self._obs[i] for i, a in enumerate(self.possible_agents)}, {
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
        """Step the swarm; a missing action flies straight, a departed agent's is ignored.

        Every agent of ``possible_agents`` is in every returned dict until the episode ends.
        """
        if not self.agents:
            raise RuntimeError("the episode is over: call reset()")
        n = len(self.possible_agents)
        vec_actions = np.zeros((1, n), dtype=np.float32)
        for agent, action in actions.items():
            k = int(np.asarray(action).reshape(-1)[0])
            if not 0 <= k < len(self.headings):
                raise ValueError(f"{agent}: action {k} outside Discrete({len(self.headings)})")
            vec_actions[0, self.possible_agents.index(agent)] = self.headings[k]
        result = self._vec.step_without_reset(vec_actions)
        state = self._vec.state
        swarming = np.where(result.acted[0], result.reward.swarming[0], 0.0)
        over_terminated, over_truncated = bool(result.terminated[0]), bool(result.truncated[0])
        reached = np.asarray(state.reached[0], dtype=bool)
        self._flying = np.asarray(state.active[0], dtype=bool).copy()
        self._obs = result.obs.flat()[0] * self._flying[:, None]
        obs = {a: self._obs[i] for i, a in enumerate(self.possible_agents)}
        rewards = {a: float(swarming[i]) for i, a in enumerate(self.possible_agents)}
        term = {a: bool(over_terminated or reached[i]) for i, a in enumerate(self.possible_agents)}
        trunc = dict.fromkeys(self.possible_agents, over_truncated)
        infos: dict[str, dict[str, Any]] = {
            a: {"swarming": rewards[a], "arrived": bool(reached[i])}
            for i, a in enumerate(self.possible_agents)
        }
        if self.log is not None:
            self.log.step()
        if over_terminated or over_truncated:
            self.last_episode = {
                k: v[0] for k, v in episode_metrics(state, result, np.ones(1, bool)).items()
            }
            if self.log is not None:
                self.log.episode(self.last_episode)
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
        """No rendering: it would need torchvision in BenchMARL (see the module docstring)."""
        return None

    def close(self) -> None:
        """Nothing to release."""


# ---------------------------------------------------------------------------------- BenchMARL


_QUIET: tuple[tuple[str, type[Warning]], ...] = (
    # TorchRL 0.11 deprecates internals that BenchMARL 1.5.2 still uses: nothing to act on here.
    (r"Creating \w+ which inherits from WeightUpdaterBase is deprecated", DeprecationWarning),
    (r"SyncDataCollector has been deprecated", DeprecationWarning),
    # TorchRL tests against PettingZoo 1.24.3; the adapter uses only the ParallelEnv API.
    (r"PettingZoo in TorchRL is tested using version", UserWarning),
)


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """Silence the notices BenchMARL/TorchRL raise about their own internals and versions."""
    with warnings.catch_warnings():
        for message, category in _QUIET:
            warnings.filterwarnings("ignore", message=message, category=category)
        yield


def require_benchmarl() -> None:
    """Import BenchMARL and TorchRL's PettingZoo wrapper, or raise `BaselinesNotInstalledError`."""
    try:
        with _quiet():
            importlib.import_module("benchmarl")
            importlib.import_module("benchmarl.experiment")
            importlib.import_module("torchrl.envs.libs.pettingzoo")
    except ImportError as exc:
        raise BaselinesNotInstalledError(
            f"the MARL baselines (mappo, iql, vdn, qmix) need BenchMARL: {INSTALL_HINT} ({exc})"
        ) from exc


@functools.cache
def _task_class() -> type[Any]:
    """Define `SwarmTask` (a BenchMARL ``TaskClass``); BenchMARL is imported here."""
    require_benchmarl()
    from benchmarl.environments.pettingzoo.common import PettingZooClass
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    class SwarmTask(PettingZooClass):  # type: ignore[misc]
        """BenchMARL task: the adapter in TorchRL's PettingZoo wrapper (config: see `make_task`).

        The attribute ``episode_log`` (an `EpisodeLog`, or None) receives the episodes of the
        environments this task builds.
        """

        episode_log: EpisodeLog | None = None

        def get_env_fun(
            self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
        ) -> Callable[[], Any]:
            config = dict(self.config)
            counter = itertools.count()
            base = 0 if seed is None else int(seed)
            log = self.episode_log

            def make() -> Any:
                env_seed = base + next(counter) * ENV_SEED_STRIDE
                env = SwarmBaselineEnv(config["scenario"], n_actions=config["n_actions"], log=log)
                with _quiet():
                    return PettingZooWrapper(
                        env=env,
                        return_state=True,
                        group_map={GROUP: list(env.possible_agents)},
                        categorical_actions=True,
                        seed=env_seed,
                        done_on_any=False,  # done when every agent is: arrived agents stay
                        use_mask=False,
                        device=device,
                    )

            return make

        def supports_continuous_actions(self) -> bool:
            return False

        def supports_discrete_actions(self) -> bool:
            return True

        def has_state(self) -> bool:
            return True

        def has_render(self, env: Any) -> bool:
            return False

        def max_steps(self, env: Any) -> int:
            return int(self.config["max_steps"])

        @staticmethod
        def env_name() -> str:
            return "remarl"

    SwarmTask.__module__ = __name__
    SwarmTask.__qualname__ = SwarmTask.__name__ = "SwarmTask"  # pickled by reference
    return SwarmTask


def __getattr__(name: str) -> Any:
    """``SwarmTask`` is defined on first use, when BenchMARL is importable."""
    if name == "SwarmTask":
        return _task_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def make_task(scenario: str, n_actions: int = 11, log: EpisodeLog | None = None) -> Any:
    """A `SwarmTask` for a shipped scenario name or scenario file (BenchMARL must be installed)."""
    from sim.scenarios import load_scenario

    cfg = load_scenario(scenario)
    heading_actions(n_actions)  # validates
    task = _task_class()(
        name=cfg.name.upper(),
        config={"scenario": str(scenario), "n_actions": n_actions, "max_steps": cfg.max_steps},
    )
    task.episode_log = log
    return task


@dataclass(frozen=True)
class BaselineHParams:
    """Small hyper-parameters for short runs on 2 CPU cores.

    BenchMARL's defaults target GPUs and millions of frames (6000-frame batches, 1000 updates
    per batch, lr 5e-5); with these a 20k-step run on 3u1o takes about 50 s on one core.

    Shared: an MLP of ``hidden`` tanh units for actors, Q-networks and critics, shared by all
    agents (one group); Adam at ``lr``; γ; gradient norm clipped at 5; ``n_envs`` environments
    stepped one after the other in this process (no worker processes).

    MAPPO (on-policy): each iteration collects ``on_policy_frames`` environment steps and runs
    ``ppo_epochs`` passes of minibatches of ``ppo_minibatch`` over them; clip 0.2, GAE λ 0.9,
    entropy bonus ``entropy_coef``.

    IQL, VDN, QMIX (off-policy): each iteration collects ``off_policy_frames`` steps with
    ε-greedy actions (ε from ``eps_start`` to ``eps_end`` over the first ``eps_anneal_frac``
    of the budget), then takes ``off_policy_updates`` gradient steps on batches of
    ``batch_size`` transitions from a replay of ``replay_size``; soft target updates τ.
    QMIX's mixer embeds in 32 units.
    """

    hidden: tuple[int, ...] = (64, 64)
    lr: float = 5e-4
    gamma: float = 0.99
    n_envs: int = 4
    threads: int = 1
    on_policy_frames: int = 1000
    ppo_minibatch: int = 250
    ppo_epochs: int = 4
    entropy_coef: float = 0.01
    off_policy_frames: int = 500
    off_policy_updates: int = 50
    batch_size: int = 128
    replay_size: int = 100_000
    tau: float = 0.01
    eps_start: float = 0.8
    eps_end: float = 0.05
    eps_anneal_frac: float = 0.5


def _batches(wanted: int, budget: int, n_envs: int) -> tuple[int, int]:
    """(iterations, frames per batch) for a budget of frames.

    Batches of about ``wanted`` frames (no more than the budget), each a multiple of the
    environments stepped together; they sum to the budget rounded up to a multiple of
    iterations·n_envs.
    """
    iterations = -(-budget // max(min(wanted, budget), 1))
    per_batch = -(-budget // iterations)
    return iterations, -(-per_batch // n_envs) * n_envs


def _experiment_config(
    hp: BaselineHParams, budget_steps: int, folder: Path, on_policy: bool
) -> Any:
    from benchmarl.experiment import ExperimentConfig

    cfg = ExperimentConfig.get_from_yaml()
    iterations, frames = _batches(
        hp.on_policy_frames if on_policy else hp.off_policy_frames, budget_steps, hp.n_envs
    )
    values: dict[str, Any] = {
        "sampling_device": "cpu",
        "train_device": "cpu",
        "buffer_device": "cpu",
        "share_policy_params": True,
        "prefer_continuous_actions": False,
        "parallel_collection": False,
        "gamma": hp.gamma,
        "lr": hp.lr,
        "clip_grad_norm": True,
        "clip_grad_val": 5.0,
        "soft_target_update": True,
        "polyak_tau": hp.tau,
        "exploration_eps_init": hp.eps_start,
        "exploration_eps_end": hp.eps_end,
        "exploration_anneal_frames": max(1, int(hp.eps_anneal_frac * budget_steps)),
        "max_n_iters": None,
        "max_n_frames": iterations * frames,  # whole batches: TorchRL would round up anyway
        "on_policy_collected_frames_per_batch": frames,
        "on_policy_n_envs_per_worker": hp.n_envs,
        "on_policy_n_minibatch_iters": hp.ppo_epochs,
        "on_policy_minibatch_size": min(hp.ppo_minibatch, frames),
        "off_policy_collected_frames_per_batch": frames,
        "off_policy_n_envs_per_worker": hp.n_envs,
        "off_policy_n_optimizer_steps": hp.off_policy_updates,
        "off_policy_train_batch_size": hp.batch_size,
        "off_policy_memory_size": hp.replay_size,
        "off_policy_init_random_frames": 0,
        "evaluation": False,  # the greedy policy is evaluated afterwards by sim.evaluation
        "render": False,
        "evaluation_interval": frames,
        "loggers": [],
        "create_json": False,
        "save_folder": str(folder),
        "checkpoint_interval": 0,
        "checkpoint_at_end": False,
    }
    for key, value in values.items():
        setattr(cfg, key, value)
    return cfg


def _algorithm_config(algorithm: str, hp: BaselineHParams) -> Any:
    from benchmarl.algorithms import IqlConfig, MappoConfig, QmixConfig, VdnConfig

    if algorithm == "mappo":
        mappo = MappoConfig.get_from_yaml()
        mappo.entropy_coef = hp.entropy_coef
        return mappo
    classes = {"iql": IqlConfig, "vdn": VdnConfig, "qmix": QmixConfig}
    return classes[algorithm].get_from_yaml()


def _model_config(hp: BaselineHParams) -> Any:
    import torch
    from benchmarl.models.mlp import MlpConfig

    return MlpConfig(
        num_cells=list(hp.hidden), layer_class=torch.nn.Linear, activation_class=torch.nn.Tanh
    )


def greedy_actions(policy: Any, headings: NDArray[np.float32]) -> Callable[..., Any]:
    """A `sim.evaluation` policy (obs (B, N, D) → normalised actions (B, N)).

    From a BenchMARL policy module: its deterministic action (arg-max Q for IQL, VDN and QMIX;
    the mode of MAPPO's categorical).
    """
    import torch
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    def act(obs: NDArray[np.float32]) -> NDArray[np.float32]:
        x = torch.as_tensor(np.ascontiguousarray(obs), dtype=torch.float32)
        td = TensorDict(
            {GROUP: TensorDict({"observation": x}, batch_size=x.shape[:2])},
            batch_size=x.shape[:1],
        )
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            index = policy(td).get((GROUP, "action")).numpy()
        chosen: NDArray[np.float32] = headings[index.astype(np.int64)]
        return chosen

    return act


def _decile(rows: list[dict[str, float]], last: bool) -> dict[str, float]:
    if not rows:
        return {"episodes": 0.0, "swarming_return": float("nan"), "success": float("nan")}
    k = max(1, len(rows) // 10)
    part = rows[-k:] if last else rows[:k]
    return {
        "episodes": float(len(part)),
        "swarming_return": float(np.mean([r["swarming_return"] for r in part])),
        "success": float(np.mean([r["success"] for r in part])),
    }


def train_benchmarl(
    algorithm: str,
    scenario: str,
    budget_steps: int,
    seed: int,
    out_dir: Path,
    n_actions: int = 11,
    *,
    eval_episodes: int = 100,
    hparams: BaselineHParams | None = None,
) -> dict[str, Any]:
    """Train ``algorithm`` (mappo, iql, vdn, qmix) with BenchMARL on the Swarming reward.

    Args:
        algorithm: one of `ALGORITHMS`.
        scenario: a shipped scenario name (e.g. "3u1o") or a scenario file.
        budget_steps: environment steps of training (BenchMARL frames), rounded up to whole
            batches of whole steps of its ``n_envs`` environments (the summary's ``frames``).
        seed: seeds BenchMARL (torch, numpy) and the environments.
        out_dir: the run folder (see the module docstring).
        n_actions: the discrete heading set (`heading_actions`): 11 by default, 10 = the paper's
            literal grid; said in the summary.
        eval_episodes: episodes of the greedy policy evaluated by `sim.evaluation` after
            training (0: none), seeds `EVAL_SEED_BASE` + 1000·seed on.
        hparams: hyper-parameters (default `BaselineHParams`).

    Returns:
        The summary (also ``summary.json``): run facts, the training curve's first and last
        deciles, and the evaluation's `sim.evaluation.summarize` keys (``success_rate``,
        ``swarming_return``, …).

    Raises:
        BaselinesNotInstalledError: BenchMARL is not installed.
        ConfigError: unknown algorithm, or a budget or action count out of range.
    """
    algorithm = algorithm.lower()
    if algorithm not in ALGORITHMS:
        raise ConfigError(f"unknown BenchMARL algorithm {algorithm!r}; known: {ALGORITHMS}")
    if isinstance(budget_steps, bool) or not isinstance(budget_steps, int) or budget_steps < 1:
        raise ConfigError(f"budget_steps must be an integer >= 1, got {budget_steps!r}")
    headings = heading_actions(n_actions)
    hp = hparams or BaselineHParams()
    require_benchmarl()
    import benchmarl
    import torch
    from benchmarl.experiment import Experiment

    from sim.evaluation import run_episodes, summarize

    out_dir = Path(out_dir)
    folder = out_dir / "benchmarl"
    folder.mkdir(parents=True, exist_ok=True)
    log = EpisodeLog(out_dir / "curve.csv")
    log.start()
    torch.set_num_threads(hp.threads)
    algo_cfg = _algorithm_config(algorithm, hp)
    on_policy = bool(algo_cfg.on_policy())
    exp_cfg = _experiment_config(hp, budget_steps, folder, on_policy)
    start = time.monotonic()
    with _quiet():
        experiment = Experiment(
            task=make_task(scenario, n_actions, log),
            algorithm_config=algo_cfg,
            model_config=_model_config(hp),
            critic_model_config=_model_config(hp),
            seed=seed,
            config=exp_cfg,
        )
        experiment.run()
    train_s = time.monotonic() - start

    evaluation: dict[str, float] = {}
    if eval_episodes > 0:
        act = greedy_actions(experiment.policy, headings)
        rows = run_episodes(
            act, scenario, eval_episodes, seed=EVAL_SEED_BASE + 1000 * seed, num_envs=50
        )
        evaluation = {k: float(v) for k, v in summarize(rows).items()}
    summary: dict[str, Any] = {
        "algorithm": algorithm,
        "scenario": str(scenario),
        "seed": seed,
        "reward": "swarming",
        "n_actions": n_actions,
        "headings_deg": [round(float(h) * 45.0, 3) for h in headings],
        "budget_steps": budget_steps,
        "env_steps": log.env_steps,
        "frames": int(experiment.total_frames),
        "train_episodes": len(log.rows),
        "train_s": round(train_s, 2),
        "env_steps_per_s": round(log.env_steps / max(train_s, 1e-9), 1),
        "train_first_decile": _decile(log.rows, last=False),
        "train_last_decile": _decile(log.rows, last=True),
        "eval_episodes": eval_episodes,
        "hparams": dataclasses.asdict(hp),
        "benchmarl_version": str(getattr(benchmarl, "__version__", "unknown")),
        **evaluation,
    }
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary
