"""MAPPO, IQL, VDN and QMIX on the swarm simulator through BenchMARL (the ``baselines`` extra).

`train_benchmarl` trains one algorithm with BenchMARL's ``Experiment`` on CPU with the small
hyper-parameters of `BaselineHParams`, on `policies.benchmarl_task.SwarmTask` (the environment
`policies.baseline_env.SwarmBaselineEnv` in TorchRL's PettingZoo wrapper), then evaluates the
greedy policy with `sim.evaluation` (the evaluation code of every method). It writes in
``out_dir``::

    curve.csv      one row per finished training episode, from the simulator's own episode
                   metrics: env_steps, episode, swarming_return, success
    summary.json   what `train_benchmarl` returns
    benchmarl/     BenchMARL's experiment folder (its configuration; no loggers, no videos)

This module imports without BenchMARL; BenchMARL, TorchRL and TensorDict are imported inside
functions (and by `policies.benchmarl_task`, which needs them), and using them without the
extra raises `BaselinesNotInstalledError`. Rendering stays off, so the CUDA-built torchvision
that BenchMARL pulls in from PyPI is never imported (it does not load beside the CPU torch).
Run with ``OMP_NUM_THREADS=1``.

Known behaviour: arrival is worth nothing beyond the arrival step's reward (zero reward after
it, no terminal value, unlike the project's DDPG and COMA, which value arrival as an absorbing
goal), and a collision costs only the rewards it cuts off. On 3u1o with 20k steps (about 50 s
each on one core) MAPPO, IQL, VDN and QMIX all raise their training Swarming return from about
7-12 to about 18-20 and converge towards flying nearly straight at the target (return 20, the
obstacle hit); their greedy success rate stays at 0-12 %.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import json
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from policies.baseline_env import EpisodeLog
from policies.common import heading_actions
from sim.errors import ConfigError
from sim.evaluation import evaluation_seed

ALGORITHMS = ("mappo", "iql", "vdn", "qmix")
"""The BenchMARL algorithms `train_benchmarl` runs."""

INSTALL_HINT = "pip install 'remarl-fc[baselines]'"


class BaselinesNotInstalledError(ConfigError, ImportError):
    """The BenchMARL baselines need the optional extra ``remarl-fc[baselines]``."""


_QUIET: tuple[tuple[str, type[Warning]], ...] = (
    # TorchRL 0.11 deprecates internals that BenchMARL 1.5.2 still uses: nothing to act on here.
    (r"Creating \w+ which inherits from WeightUpdaterBase is deprecated", DeprecationWarning),
    (r"SyncDataCollector has been deprecated", DeprecationWarning),
    # TorchRL tests against PettingZoo 1.24.3; the adapter uses only the ParallelEnv API.
    (r"PettingZoo in TorchRL is tested using version", UserWarning),
)


@contextlib.contextmanager
def quiet_benchmarl() -> Iterator[None]:
    """Silence the notices BenchMARL/TorchRL raise about their own internals and versions."""
    with warnings.catch_warnings():
        for message, category in _QUIET:
            warnings.filterwarnings("ignore", message=message, category=category)
        yield


def require_benchmarl() -> None:
    """Import BenchMARL and TorchRL's PettingZoo wrapper, or raise `BaselinesNotInstalledError`."""
    try:
        with quiet_benchmarl():
            importlib.import_module("benchmarl")
            importlib.import_module("benchmarl.experiment")
            importlib.import_module("torchrl.envs.libs.pettingzoo")
    except ImportError as exc:
        raise BaselinesNotInstalledError(
            f"the MARL baselines (mappo, iql, vdn, qmix) need BenchMARL: {INSTALL_HINT} ({exc})"
        ) from exc


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

    from policies.benchmarl_task import GROUP

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
            training (0: none), on the run's evaluation seed (`sim.evaluation.evaluation_seed`).
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

    from policies.benchmarl_task import make_task
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
    with quiet_benchmarl():
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
        rows = run_episodes(act, scenario, eval_episodes, seed=evaluation_seed(seed), num_envs=50)
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
