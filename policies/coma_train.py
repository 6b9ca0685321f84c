"""COMA training (`policies.coma`): the loop, the model file and the greedy policy.

`train_coma` writes, in ``out_dir``::

    config.json         the ComaConfig, scenario and seed
    curve.csv           one row per finished training episode:
                        env_steps, episode, swarming_return, success
    model.safetensors   the actor (weights, and its shapes as JSON metadata)
    summary.json        what `train_coma` returns

Run it from the shell with ``python -m policies.coma_train --scenario 3u1o --budget-steps
200000``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from safetensors import safe_open
from safetensors.torch import load_file, save_file

from policies.coma import (
    REWARD,
    ComaActor,
    ComaBatch,
    ComaConfig,
    ComaNets,
    coma_update,
    explore_probs,
    sample_actions,
    sampled_value,
)
from policies.common import CurveWriter, heading_actions
from policies.train import reward_upper_bound
from sim.config import ScenarioConfig
from sim.env import SwarmVectorEnv, make_vector_env
from sim.evaluation import evaluation_seed, run_episodes, summarize

MODEL_SCHEMA = 1
"""Version of ``model.safetensors``'s layout."""


def save_coma(path: Path, actor: ComaActor, meta: dict[str, Any]) -> None:
    """The actor as safetensors, its shapes and ``meta`` as JSON metadata (atomic)."""
    info = {
        "schema": MODEL_SCHEMA,
        "n_agents": actor.n_agents,
        "obs_size": actor.obs_size,
        "n_actions": actor.n_actions,
        "hidden": actor.hidden,
        **meta,
    }
    tensors = {k: v.contiguous() for k, v in actor.state_dict().items()}
    tmp = path.with_name(path.name + ".part")
    save_file(tensors, str(tmp), metadata={"remarl_coma": json.dumps(info)})
    tmp.replace(path)


def load_coma(path: Path) -> ComaActor:
    """The actor saved by `save_coma` (nothing is unpickled)."""
    with safe_open(str(path), framework="pt") as f:
        info: dict[str, Any] = json.loads(f.metadata()["remarl_coma"])
    if info.get("schema") != MODEL_SCHEMA:
        raise ValueError(f"{path}: COMA model schema {info.get('schema')}, expected {MODEL_SCHEMA}")
    actor = ComaActor(info["n_agents"], info["obs_size"], info["n_actions"], info["hidden"])
    actor.load_state_dict(load_file(str(path)))
    return actor


def coma_policy(model: ComaActor) -> Callable[[NDArray[np.float32]], NDArray[np.float32]]:
    """Greedy policy for `sim.evaluation.run_episodes`: flat obs (B, N, D) → actions (B, N).

    Each agent takes its most probable action (the mode of the softmax, no ε), returned as the
    normalised heading change in [−1, 1].
    """
    values = torch.from_numpy(heading_actions(model.n_actions))

    def act(obs: NDArray[np.float32]) -> NDArray[np.float32]:
        if obs.ndim != 3 or obs.shape[1:] != (model.n_agents, model.obs_size):
            raise ValueError(
                f"observations {obs.shape}: expected (B, {model.n_agents}, {model.obs_size})"
            )
        with torch.no_grad():
            best = model(torch.from_numpy(np.ascontiguousarray(obs, np.float32))).argmax(-1)
        actions: NDArray[np.float32] = values[best].numpy()
        return actions

    return act


def train_coma(
    cfg: ComaConfig,
    scenario: str | Path | ScenarioConfig,
    out_dir: Path,
    seed: int,
) -> dict[str, Any]:
    """Train COMA on the Swarming reward for ``cfg.budget_steps`` environment steps.

    Writes ``config.json``, ``curve.csv``, ``model.safetensors`` and ``summary.json`` in
    ``out_dir`` (see the module docstring) and returns the summary: counts, time, the first
    and last 100 training episodes' mean Swarming return and success, and the greedy
    evaluation (`sim.evaluation.summarize`) when ``cfg.eval_episodes`` > 0.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    # ---- seeding: the only place training seeds anything
    torch.manual_seed(seed)  # network initialisation
    generator = torch.Generator().manual_seed(seed)  # action sampling
    env: SwarmVectorEnv = make_vector_env(scenario, cfg.num_envs, reward=REWARD)
    obs_np, info = env.reset(seed=seed)  # episodes (the environment's own generator)

    # ---- networks, constants
    n, b, steps = env.num_agents, cfg.num_envs, cfg.rollout_steps
    nets = ComaNets.create(n, env.obs_layout_size, cfg)
    action_values = heading_actions(cfg.n_actions)
    goal_bonus = cfg.gamma * reward_upper_bound(env.cfg, REWARD) / (1.0 - cfg.gamma)
    (out_dir / "config.json").write_text(
        json.dumps(
            {"coma": dataclasses.asdict(cfg), "scenario": env.cfg.name, "seed": seed}, indent=2
        )
    )
    curve = CurveWriter(out_dir / "curve.csv")

    env_steps = updates = 0
    episodes: list[tuple[float, float]] = []  # (swarming_return, success)
    losses: dict[str, float] = {}
    active_np = info["active"]
    start = time.monotonic()
    while env_steps < cfg.budget_steps:
        epsilon = cfg.epsilon(env_steps)
        obs_b = torch.zeros(steps, b, n, env.obs_layout_size)
        active_b = torch.zeros(steps, b, n, dtype=torch.bool)
        actions_b = torch.zeros(steps, b, n, dtype=torch.int64)
        rewards_b = torch.zeros(steps, b)
        terminated_b = torch.zeros(steps, b, dtype=torch.bool)
        truncated_b = torch.zeros(steps, b, dtype=torch.bool)
        truncated_values = torch.zeros(steps, b)
        # ---- collect T steps of the B environments with the behaviour policy
        for t in range(steps):
            obs = torch.from_numpy(obs_np)
            with torch.no_grad():
                actions = sample_actions(explore_probs(nets.actor(obs), epsilon), generator)
            obs_np, rewards, terminated, truncated, info = env.step(action_values[actions.numpy()])
            env_steps += b
            acted = info["acted"]
            # team reward: mean over the N agents of those that flew, with arrivals' goal
            team = np.where(acted, rewards + goal_bonus * info["arrived"], 0.0).sum(-1) / n
            obs_b[t], actions_b[t] = obs, actions
            active_b[t] = torch.from_numpy(acted)
            rewards_b[t] = torch.from_numpy(team.astype(np.float32))
            terminated_b[t] = torch.from_numpy(terminated)
            truncated_b[t] = torch.from_numpy(truncated)
            if truncated.any():  # bootstrap on the final observation of the cut episodes
                cut = np.flatnonzero(truncated)
                flying = torch.from_numpy(acted[cut] & ~info["arrived"][cut])
                final = torch.from_numpy(info["final_obs"][cut])
                truncated_values[t, cut] = sampled_value(nets, final, flying, epsilon, generator)
            if "episode" in info:
                ep = info["episode"]
                for k in range(len(ep["success"])):
                    row = (float(ep["swarming_return"][k]), float(ep["success"][k]))
                    episodes.append(row)
                    curve.add(env_steps, row[0], bool(row[1]))
            active_np = info["active"]
        last_value = sampled_value(
            nets, torch.from_numpy(obs_np), torch.from_numpy(active_np), epsilon, generator
        )

        # ---- learn from the batch, once
        batch = ComaBatch(
            obs_b,
            active_b,
            actions_b,
            rewards_b,
            terminated_b,
            truncated_b,
            truncated_values,
            last_value,
            epsilon,
        )
        losses = coma_update(nets, batch, cfg)
        updates += 1
        if updates % cfg.target_update_interval == 0:
            nets.critic_target.load_state_dict(nets.critic.state_dict())

    model_path = out_dir / "model.safetensors"
    save_coma(model_path, nets.actor, {"scenario": env.cfg.name, "reward": REWARD})
    summary: dict[str, Any] = {
        "scenario": env.cfg.name,
        "seed": seed,
        "env_steps": env_steps,
        "updates": updates,
        "episodes": len(episodes),
        "train_seconds": time.monotonic() - start,
        "first_100": _mean_episodes(episodes[:100]),
        "last_100": _mean_episodes(episodes[-100:]),
        "final_losses": losses,
        "model": str(model_path),
        "curve": str(out_dir / "curve.csv"),
    }
    if cfg.eval_episodes:
        rows = run_episodes(
            coma_policy(nets.actor), env.cfg, cfg.eval_episodes, evaluation_seed(seed)
        )
        summary["eval"] = summarize(rows)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def _mean_episodes(rows: list[tuple[float, float]]) -> dict[str, float]:
    if not rows:
        return {"swarming_return": float("nan"), "success": float("nan")}
    ret, success = np.asarray(rows, dtype=np.float64).mean(axis=0)
    return {"swarming_return": float(ret), "success": float(success)}


def main(argv: list[str] | None = None) -> None:
    """``python -m policies.coma``: train once, print the summary as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--scenario", default="3u1o")
    parser.add_argument("--out", type=Path, default=Path("runs/coma"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--budget-steps", type=int, default=ComaConfig.budget_steps)
    parser.add_argument("--n-actions", type=int, default=ComaConfig.n_actions)
    parser.add_argument("--num-envs", type=int, default=ComaConfig.num_envs)
    args = parser.parse_args(argv)
    cfg = ComaConfig(
        budget_steps=args.budget_steps, n_actions=args.n_actions, num_envs=args.num_envs
    )
    summary = train_coma(cfg, args.scenario, args.out, args.seed)
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
