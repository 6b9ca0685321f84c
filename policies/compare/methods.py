"""The methods of `remarl-fc compare`: what one cell of the grid trains, and how it is scored.

`run_job` trains a cell's method on its budget (E2Coop is a planner: nothing to train), scores
the result with `sim.evaluation` on the run's evaluation seed (`sim.evaluation.evaluation_seed`,
the same episodes for every method of a seed) and times one swarm decision (`reaction_ms`), then
writes ``result.json`` whole (a cell with one is finished: a rerun reads it instead).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from sim.evaluation import evaluation_seed

if TYPE_CHECKING:
    from policies.compare.grid import Job


def run_job(job: Job) -> dict[str, Any]:
    """Train and evaluate one cell (or read its finished result)."""
    done = job.folder / "result.json"
    if done.exists():
        result: dict[str, Any] = json.loads(done.read_text())
        return result
    job.folder.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    evaluation = RUNNERS.get(job.method, run_benchmarl)(job)
    result = {
        "scenario": job.scenario,
        "method": job.method,
        "seed": job.seed,
        "budget_steps": job.cfg.budget_steps if job.method != "e2coop" else 0,
        "n_actions": job.cfg.n_actions if job.method not in ("remarl", "e2coop") else None,
        "wall_s": round(time.monotonic() - start, 2),
        **evaluation,
    }
    tmp = done.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(done)  # a cell is finished only when its result is whole
    return result


def evaluate(
    act: Any, scenario: str, episodes: int, run_seed: int, num_envs: int
) -> dict[str, Any]:
    """`sim.evaluation.summarize` of ``episodes`` on the evaluation seed of ``run_seed``."""
    from sim.evaluation import run_episodes, summarize

    rows = run_episodes(act, scenario, episodes, seed=evaluation_seed(run_seed), num_envs=num_envs)
    return {k: float(v) for k, v in summarize(rows).items()}


def reaction_ms(act: Any, scenario: str, calls: int = 50) -> dict[str, float]:
    """Median and p99 wall time of one decision of one swarm."""
    from sim.env import make_vector_env

    env = make_vector_env(scenario, 1)
    obs, _ = env.reset(seed=0)
    uses_state = bool(getattr(act, "uses_state", False))
    times = []
    for _ in range(calls):
        t0 = time.perf_counter()
        actions = act(obs, env.state) if uses_state else act(obs)
        times.append(time.perf_counter() - t0)
        obs, *_ = env.step(actions)
    arr = np.array(times) * 1e3
    return {
        "reaction_ms_median": float(np.median(arr)),
        "reaction_ms_p99": float(np.percentile(arr, 99)),
    }


def scored(act: Any, job: Job, episodes: int, num_envs: int, calls: int = 50) -> dict[str, Any]:
    """The evaluation (`evaluate`) and the reaction time (`reaction_ms`) of a cell's policy."""
    return {
        **evaluate(act, job.scenario, episodes, job.seed, num_envs),
        **reaction_ms(act, job.scenario, calls),
    }


def run_remarl(job: Job) -> dict[str, Any]:
    """Per-agent DDPG on the full reMARL reward (`policies.train`); its best checkpoint scored."""
    from policies.config import TrainConfig
    from policies.ddpg import DDPGNets
    from policies.train import load_checkpoint, policy_actions, train
    from sim.env import make_vector_env

    num_envs = 16
    cfg = TrainConfig(
        scenario=job.scenario,
        num_envs=num_envs,
        total_steps=max(1, job.cfg.budget_steps // num_envs),
        seed=job.seed,
        eval_every=max(1, job.cfg.budget_steps // num_envs // 4),
        eval_episodes=min(50, job.cfg.eval_episodes),
        reward="remarl",
    )
    train(cfg, job.folder)
    env = make_vector_env(job.scenario, 1)
    nets = DDPGNets.create(1 if cfg.ddpg.shared else env.num_agents, env.obs_layout_size, cfg.ddpg)
    load_checkpoint(job.folder / "best.safetensors", nets)

    def act(obs: Any) -> Any:
        return policy_actions(nets, obs, cfg.ddpg.shared)

    return scored(act, job, job.cfg.eval_episodes, 50)


def run_e2coop(job: Job) -> dict[str, Any]:
    """The E2Coop planner (`policies.e2coop`) with the grid's PSO budget: nothing to train.

    One planner is evaluated, then timed: it starts each new episode afresh, so the timing
    runs from a clean start too.
    """
    from policies.e2coop import E2Coop, E2CoopConfig
    from sim.scenarios import load_scenario

    planner = E2CoopConfig(particles=job.cfg.e2coop_particles, iterations=job.cfg.e2coop_iterations)
    act = E2Coop(load_scenario(job.scenario), planner, seed=job.seed)
    return scored(act, job, job.cfg.e2coop_episodes, 1, calls=10)


def run_coma(job: Job) -> dict[str, Any]:
    """COMA on the Swarming reward (`policies.coma_train`); its greedy actor scored."""
    from policies.coma import ComaConfig
    from policies.coma_train import coma_policy, load_coma, train_coma

    cfg = ComaConfig(budget_steps=job.cfg.budget_steps, n_actions=job.cfg.n_actions)
    train_coma(cfg, job.scenario, job.folder, job.seed)
    act = coma_policy(load_coma(job.folder / "model.safetensors"))
    return scored(act, job, job.cfg.eval_episodes, 50)


def run_benchmarl(job: Job) -> dict[str, Any]:
    """MAPPO, IQL, VDN or QMIX through BenchMARL (`policies.benchmarl_train`, the extra)."""
    from policies.benchmarl_train import train_benchmarl

    return train_benchmarl(
        job.method,
        job.scenario,
        job.cfg.budget_steps,
        job.seed,
        job.folder,
        job.cfg.n_actions,
        eval_episodes=job.cfg.eval_episodes,
    )


RUNNERS: dict[str, Callable[[Job], dict[str, Any]]] = {
    "remarl": run_remarl,
    "e2coop": run_e2coop,
    "coma": run_coma,
}
"""The cell of each method that is not BenchMARL's (`run_benchmarl` runs the others)."""
