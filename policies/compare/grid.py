"""The grid of `remarl-fc compare`: its cells (`CompareConfig`, `jobs`) and how they run.

`run_grid` runs every unfinished cell (`policies.compare.methods.run_job`) in a local process
pool whose workers end with their `compare` (`worker_setup`), or on a Ray cluster
(`policies.compare.cluster`), and reports each finished cell (`cell_line`).
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from policies.compare.methods import run_job
from policies.e2coop import E2CoopConfig
from sim.errors import ConfigError

METHODS = ("remarl", "coma", "mappo", "iql", "vdn", "qmix", "e2coop")
"""Every method the grid knows."""

BENCHMARL_METHODS = frozenset({"mappo", "iql", "vdn", "qmix"})
"""The methods trained by BenchMARL (`policies.benchmarl_train`, the ``baselines`` extra)."""


@dataclass(frozen=True)
class CompareConfig:
    """One grid.

    Attributes:
        scenarios, methods: the grid's axes. seeds: seeds per cell (0..seeds−1).
        budget_steps: environment steps of training per run.
        out: the results folder. n_actions: the discrete heading set of the MARL baselines.
        eval_episodes: evaluation episodes per run (E2Coop: `e2coop_episodes`).
        workers: parallel cells (local process pool).
        e2coop_particles, e2coop_iterations: the planner's PSO budget (by default
            `E2CoopConfig`'s: the original's 200×100).
    """

    scenarios: tuple[str, ...]
    methods: tuple[str, ...]
    seeds: int = 3
    budget_steps: int = 200_000
    out: Path = Path("results")
    n_actions: int = 11
    eval_episodes: int = 200
    e2coop_episodes: int = 50
    workers: int = 2
    e2coop_particles: int = E2CoopConfig.particles
    e2coop_iterations: int = E2CoopConfig.iterations
    quick: bool = False

    def __post_init__(self) -> None:
        unknown = [m for m in self.methods if m not in METHODS]
        if unknown:
            raise ConfigError(f"unknown method(s) {unknown}; known: {', '.join(METHODS)}")
        if self.seeds < 1 or self.budget_steps < 1 or self.workers < 1:
            raise ConfigError("seeds, budget and workers must be ≥ 1")

    @classmethod
    def quick_preset(
        cls, scenarios: tuple[str, ...], methods: tuple[str, ...], out: Path
    ) -> CompareConfig:
        """Small budgets: the whole grid of a few cells in minutes on 2 cores."""
        return cls(
            scenarios, methods, seeds=1, budget_steps=3_000, out=out, eval_episodes=20,
            e2coop_episodes=5, workers=2, e2coop_particles=40, e2coop_iterations=15, quick=True,
        )  # fmt: skip


@dataclass(frozen=True)
class Job:
    """One cell of the grid."""

    scenario: str
    method: str
    seed: int
    cfg: CompareConfig = field(repr=False)

    @property
    def folder(self) -> Path:
        """Where the cell writes."""
        return self.cfg.out / "runs" / self.scenario / self.method / f"seed{self.seed}"


def jobs(cfg: CompareConfig) -> list[Job]:
    """Every cell (E2Coop once per scenario and seed: its PSO is random)."""
    return [Job(s, m, k, cfg) for s in cfg.scenarios for m in cfg.methods for k in range(cfg.seeds)]


PARENT_POLL_S = 1.0
"""How often a pool worker checks that it should go on (its `compare` alive, no stop), s."""

EXIT_STOPPED = 70
"""Exit status of a pool worker told to stop, or whose `compare` process is gone."""


def worker_setup(parent_pid: int, stop: Any) -> None:
    """Pool initializer: leave Ctrl-C to the parent, and end when told or orphaned.

    The parent handles Ctrl-C (the terminal sends it to every worker too: ignored here) and
    sets ``stop`` (a `multiprocessing.Event`); a `compare` killed by a signal it cannot catch
    is noticed by its changed parent id. Either way the worker exits within `PARENT_POLL_S`
    instead of training on, for up to hours. Its cell is unfinished (no result.json) and is
    trained again on the next run.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch() -> None:
        while os.getppid() == parent_pid and not stop.wait(PARENT_POLL_S):
            pass
        os._exit(EXIT_STOPPED)

    threading.Thread(target=watch, name="worker-watch", daemon=True).start()


CellReport = Callable[[int, int, dict[str, Any]], None]
"""Called as each cell finishes: (cells finished so far, cells in all, its result)."""


def cell_line(done: int, total: int, result: dict[str, Any]) -> str:
    """One progress line for a finished cell.

    >>> cell_line(3, 9, {"scenario": "7u2o", "method": "remarl", "seed": 1,
    ...                  "success_rate": 0.995, "swarming_return": 71.23, "wall_s": 812.4})
    '[3/9] 7u2o remarl seed 1: success 99.5%, Swarming return 71.2 (812 s)'
    """
    return (
        f"[{done}/{total}] {result['scenario']} {result['method']} seed {result['seed']}: "
        f"success {result['success_rate']:.1%}, Swarming return {result['swarming_return']:.1f} "
        f"({result['wall_s']:.0f} s)"
    )


def run_grid(
    cfg: CompareConfig, *, ray_address: str | None = None, on_cell: CellReport | None = None
) -> list[dict[str, Any]]:
    """Run every unfinished cell; returns every cell's result, in `jobs` order.

    ``on_cell`` hears of each cell as it finishes (finished ones from an earlier run first).
    On Ctrl-C (KeyboardInterrupt) or any error the workers stop at once and the exception
    propagates; the finished cells are kept and the next run resumes from them.
    """
    todo = jobs(cfg)
    report: CellReport = on_cell or (lambda done, total, result: None)
    if ray_address is not None:
        from policies.compare.cluster import run_on_ray

        return run_on_ray(todo, ray_address)
    if cfg.workers == 1:
        results = []
        for k, job in enumerate(todo):
            results.append(run_job(job))
            report(k + 1, len(todo), results[-1])
        return results
    ctx = multiprocessing.get_context("spawn")
    stop = ctx.Event()
    pool = concurrent.futures.ProcessPoolExecutor(
        cfg.workers, mp_context=ctx, initializer=worker_setup, initargs=(os.getpid(), stop)
    )
    try:
        futures = [pool.submit(run_job, job) for job in todo]
        for k, fut in enumerate(concurrent.futures.as_completed(futures)):
            report(k + 1, len(todo), fut.result())
        return [fut.result() for fut in futures]
    except BaseException:
        stop.set()  # running cells end now instead of at their budget
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
