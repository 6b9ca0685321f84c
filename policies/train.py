"""Per-agent DDPG training on the vectorised simulator, CleanRL style: read it top to bottom.

Run folder layout (``--out``)::

    config.json         the resolved TrainConfig and scenario
    last.safetensors    networks, optimiser moments and counters (resumable)
    best.safetensors    the networks of the best evaluation so far
    evals.jsonl         one line per evaluation (seeds `sim.evaluation.evaluation_seed`, suite
                        "training": the same episodes for every run seed)
    curve.csv           one row per finished training episode (`policies.common.CurveWriter`)
    events.*            TensorBoard scalars (when tensorboard is installed)

Checkpoints are safetensors files (tensors) with JSON metadata: nothing is pickled, so loading
a checkpoint never executes code. The replay buffer is not saved; a resumed run refills it with
the current policy before it learns again.

Terminal values. A UAV that reaches its target leaves the episode; if its value there were 0,
a UAV earning positive rewards would learn to avoid arriving. Arrival is therefore an
absorbing goal state worth the best possible continuation, r_max/(1 − γ), with r_max the upper
bound of the per-step reward (`reward_upper_bound`); a collision is worth 0. See
`docs/MODEL.md`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from numpy.typing import NDArray
from safetensors.torch import save_file

from policies.buffer import ReplayBuffer
from policies.common import CurveWriter
from policies.config import DDPGConfig, TrainConfig
from policies.ddpg import DDPGNets, ddpg_update
from sim.config import ScenarioConfig
from sim.env import SwarmVectorEnv, make_vector_env
from sim.evaluation import evaluation_seed, run_episodes, summarize

CHECKPOINT_SCHEMA = 1
"""Version of the checkpoint layout."""


def reward_upper_bound(cfg: ScenarioConfig, reward: str) -> float:
    """Largest per-step reward: Swarming ≤ 1, plus w_ext·1 for the contour's external term."""
    return 1.0 + (cfg.reward.w_external if reward == "remarl" else 0.0)


def policy_actions(nets: DDPGNets, obs: NDArray[np.float32], shared: bool) -> NDArray[np.float32]:
    """Deterministic actions (B, N) of the current actors for observations (B, N, D)."""
    with torch.no_grad():
        x = torch.from_numpy(np.ascontiguousarray(np.swapaxes(obs, 0, 1)))  # (N, B, D)
        if shared:
            n, b = x.shape[:2]
            out = nets.actor(x.reshape(1, n * b, -1)).reshape(n, b)
        else:
            out = nets.actor(x)
    actions: NDArray[np.float32] = out.numpy().T.copy()
    return actions


class Checkpointable(Protocol):
    """Networks and optimisers by checkpoint name (`DDPGNets`, `policies.generalist.TD3Nets`)."""

    def modules(self) -> dict[str, torch.nn.Module]:
        """Every network by name."""
        ...

    def optimisers(self) -> dict[str, torch.optim.Optimizer]:
        """Every optimiser by name."""
        ...


def optimiser_tensors(name: str, opt: torch.optim.Optimizer) -> dict[str, torch.Tensor]:
    """``opt``'s moments as checkpoint tensors ``<name>.<param index>.<field>``."""
    return {
        f"{name}.{i}.{key}": torch.as_tensor(value).detach().cpu().contiguous()
        for i, state in opt.state_dict()["state"].items()
        for key, value in state.items()
    }


def restore_optimiser(
    name: str, opt: torch.optim.Optimizer, tensors: Mapping[str, torch.Tensor]
) -> None:
    """Load ``opt``'s moments from the ``<name>.…`` tensors `optimiser_tensors` wrote."""
    prefix = f"{name}."
    sd = opt.state_dict()
    state: dict[int, dict[str, torch.Tensor]] = {}
    for key, value in tensors.items():
        if key.startswith(prefix):
            idx, field = key[len(prefix) :].split(".", 1)
            state.setdefault(int(idx), {})[field] = value
    sd["state"] = state
    opt.load_state_dict(sd)


def save_checkpoint(
    path: Path,
    nets: Checkpointable,
    meta: dict[str, Any],
    extra: Mapping[str, torch.Tensor] | None = None,
) -> None:
    """Networks and optimiser moments as safetensors, counters as JSON metadata (atomic).

    ``extra``: more run state to keep with them (a generalist's DAgger labels), read back with
    `load_checkpoint_tensors`; its names must not start with a network's or optimiser's.
    """
    tensors: dict[str, torch.Tensor] = {}
    for name, module in nets.modules().items():
        for key, value in module.state_dict().items():
            tensors[f"{name}.{key}"] = value.detach().cpu().contiguous()
    for name, opt in nets.optimisers().items():
        tensors |= optimiser_tensors(name, opt)
    owners = {*nets.modules(), *nets.optimisers()}
    for key, value in (extra or {}).items():
        if key.split(".", 1)[0] in owners:
            raise ValueError(f"checkpoint: extra tensor {key!r} collides with the networks'")
        tensors[key] = value.detach().cpu().contiguous()
    tmp = path.with_name(path.name + ".part")
    save_file(tensors, str(tmp), metadata={"remarl_checkpoint": json.dumps(meta)})
    tmp.replace(path)


def load_checkpoint(path: Path, nets: Checkpointable) -> dict[str, Any]:
    """Restore networks and optimiser moments; returns the saved counters."""
    from safetensors import safe_open

    with safe_open(str(path), framework="pt") as f:
        meta: dict[str, Any] = json.loads(f.metadata()["remarl_checkpoint"])
        names = tuple(f"{name}." for name in (*nets.modules(), *nets.optimisers()))
        tensors = {k: f.get_tensor(k) for k in f.keys() if k.startswith(names)}  # noqa: SIM118 - not a dict
    for name, module in nets.modules().items():
        prefix = f"{name}."
        module.load_state_dict(
            {k[len(prefix) :]: v for k, v in tensors.items() if k.startswith(prefix)}
        )
    for name, opt in nets.optimisers().items():
        restore_optimiser(name, opt, tensors)
    return meta


def load_checkpoint_tensors(path: Path, prefix: str) -> dict[str, torch.Tensor]:
    """The tensors of the checkpoint at ``path`` whose names start with ``prefix``.

    The extra run state `save_checkpoint` kept (none: an empty dict); only those are read.
    """
    from safetensors import safe_open

    with safe_open(str(path), framework="pt") as f:
        return {k: f.get_tensor(k) for k in f.keys() if k.startswith(prefix)}  # noqa: SIM118 - not a dict


def train(
    cfg: TrainConfig,
    out_dir: Path,
    *,
    resume: bool = False,
    progress: Callable[[dict[str, float]], None] | None = None,
) -> dict[str, Any]:
    """Train, evaluate periodically, checkpoint; returns the final summary.

    Ctrl-C (KeyboardInterrupt) saves ``last.safetensors`` before it propagates, so the run can
    be resumed with ``resume=True``.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    d: DDPGConfig = cfg.ddpg

    # ---- seeding: the only place training seeds anything
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)

    # ---- environment, networks, replay
    env: SwarmVectorEnv = make_vector_env(cfg.scenario, cfg.num_envs, reward=cfg.reward)
    n, obs_size = env.num_agents, env.obs_layout_size
    nets = DDPGNets.create(1 if d.shared else n, obs_size, d)
    buffer = ReplayBuffer(max(d.buffer_steps // cfg.num_envs, 1) * cfg.num_envs, n, obs_size)
    goal_value = reward_upper_bound(env.cfg, cfg.reward) / (1.0 - d.gamma)
    (out_dir / "config.json").write_text(
        json.dumps({"train": dataclasses.asdict(cfg), "scenario": env.cfg.name}, indent=2)
    )
    step, best, start_time, elapsed_before = 0, -1.0, time.monotonic(), 0.0
    last_path, best_path = out_dir / "last.safetensors", out_dir / "best.safetensors"
    if resume and last_path.exists():
        meta = load_checkpoint(last_path, nets)
        step, best, elapsed_before = meta["step"], meta["best_success"], meta["elapsed_s"]
        rng = np.random.default_rng([cfg.seed, step])
    writer = summary_writer(out_dir)
    curve = CurveWriter(out_dir / "curve.csv", resume=resume)

    def checkpoint(path: Path) -> None:
        save_checkpoint(
            path,
            nets,
            {
                "schema": CHECKPOINT_SCHEMA,
                "step": step,
                "best_success": best,
                "elapsed_s": elapsed_before + time.monotonic() - start_time,
                "scenario": env.cfg.name,
                "agents": n,
                "shared": d.shared,
                "obs_size": obs_size,
                "reward": cfg.reward,
            },
        )

    obs, _ = env.reset(seed=cfg.seed + step)
    episodes: list[dict[str, float]] = []
    summary: dict[str, Any] = {}
    env_seconds = learn_seconds = 0.0
    warm = 0 if resume and step > 0 else d.warmup_steps // cfg.num_envs
    try:
        while step < cfg.total_steps:
            elapsed = elapsed_before + time.monotonic() - start_time
            if cfg.minutes and elapsed >= 60 * cfg.minutes:
                break
            # ---- act: random during warm-up, then the actors plus decaying Gaussian noise
            if warm > 0:
                actions = rng.uniform(-1.0, 1.0, (cfg.num_envs, n)).astype(np.float32)
                warm -= 1
            else:
                frac = min(step / cfg.total_steps, 1.0)
                sigma = d.noise_start + (d.noise_end - d.noise_start) * frac
                actions = policy_actions(nets, obs, d.shared)
                actions += rng.normal(0.0, sigma, actions.shape).astype(np.float32)
                np.clip(actions, -1.0, 1.0, out=actions)
            t_env = time.perf_counter()
            next_obs, rewards, _, _, info = env.step(actions)
            env_seconds += time.perf_counter() - t_env

            # ---- store: the real next observation of finished episodes is in final_obs
            real_next = next_obs
            if "final_obs" in info:
                real_next = np.where(info["_final_obs"][:, None, None], info["final_obs"], next_obs)
                ep = info["episode"]
                for k in range(len(ep["success"])):
                    episodes.append(
                        {
                            "collision": float(ep["collision_u2o"][k] or ep["collision_u2u"][k]),
                            "success": float(ep["success"][k]),
                            "swarming_return": float(ep["swarming_return"][k]),
                            "total_return": float(ep["total_return"][k]),
                        }
                    )
                    curve.add(
                        (step + 1) * cfg.num_envs,
                        float(ep["swarming_return"][k]),
                        bool(ep["success"][k]),
                    )
            terminal = info["agent_done"]
            terminal_value = np.where(info["arrived"], goal_value, 0.0).astype(np.float32)
            buffer.add(obs, actions, rewards, real_next, terminal, terminal_value, info["acted"])
            obs = next_obs
            step += 1

            # ---- learn
            losses: dict[str, float] = {}
            if warm == 0 and buffer.size >= d.batch_size:
                t_learn = time.perf_counter()
                for _ in range(d.updates_per_step):
                    losses = ddpg_update(nets, buffer.sample(d.batch_size, rng, d.shared), d)
                learn_seconds += time.perf_counter() - t_learn

            # ---- log, evaluate, checkpoint
            if step % 100 == 0 and episodes:
                recent = episodes[-200:]
                scalars = {
                    "charts/success": float(np.mean([e["success"] for e in recent])),
                    "charts/collision": float(np.mean([e["collision"] for e in recent])),
                    "charts/episodic_swarming_return": float(
                        np.mean([e["swarming_return"] for e in recent])
                    ),
                    "charts/episodic_return": float(np.mean([e["total_return"] for e in recent])),
                    "charts/SPS": step * cfg.num_envs / max(time.monotonic() - start_time, 1e-9),
                    # Where the time goes: the simulator (reward, PSO, field) against learning.
                    "perf/simulator_share": env_seconds / max(env_seconds + learn_seconds, 1e-9),
                    "perf/simulator_ms_per_step": 1e3 * env_seconds / step,
                    **losses,
                }
                for key, value in scalars.items():
                    if writer is not None and math.isfinite(value):
                        writer.add_scalar(key, value, step)
                if progress is not None:
                    progress({"step": step, **scalars})
            if step % cfg.eval_every == 0 or step >= cfg.total_steps:
                result = summarize(
                    run_episodes(
                        lambda o: policy_actions(nets, o, d.shared),
                        env.cfg,
                        cfg.eval_episodes,
                        evaluation_seed(suite="training", offset=step),
                    )
                )
                record = {
                    "step": step,
                    "elapsed_s": elapsed_before + time.monotonic() - start_time,
                    **result,
                }
                with (out_dir / "evals.jsonl").open("a") as f:
                    f.write(json.dumps(record) + "\n")
                if writer is not None:
                    writer.add_scalar("eval/success", result["success_rate"], step)
                    writer.add_scalar("eval/swarming_return", result["swarming_return"], step)
                if result["success_rate"] >= best:
                    best = result["success_rate"]
                    checkpoint(best_path)
                checkpoint(last_path)
                summary = {"last_eval": record, "best_success": best}
    except KeyboardInterrupt:
        checkpoint(last_path)
        raise
    checkpoint(last_path)
    if not best_path.exists():
        checkpoint(best_path)
    if writer is not None:
        writer.close()
    summary.update(
        {
            "steps": step,
            "env_steps": step * cfg.num_envs,
            "elapsed_s": elapsed_before + time.monotonic() - start_time,
            "out": str(out_dir),
        }
    )
    return summary


def summary_writer(out_dir: Path) -> Any:
    """A TensorBoard writer logging to ``out_dir``; None where tensorboard is not installed."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:  # tensorboard is optional
        return None
    return SummaryWriter(str(out_dir))
