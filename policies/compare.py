"""``remarl-fc compare``: the paper's comparisons as one repeatable grid.

A grid is scenarios × methods × seeds. Each cell trains its method on its budget (E2Coop is a
planner: nothing to train), evaluates the result with the one evaluation code of the project
(`sim.evaluation`), and writes ``runs/SCENARIO/METHOD/seedK/{curve.csv, result.json}``. A cell
with a ``result.json`` is finished: a rerun skips it (resume). Cells run in a local process
pool, or on a Ray cluster with ``ray_address``. `write_reports` then draws
``learning_curves.png`` (one panel per scenario, mean ± std over seeds of the per-episode
Swarming return, as the paper's Fig. 3) and writes ``summary.md``, ``table2.md`` and
``table2.csv`` (3u2o: reaction time, energy, min d_U2O and min d_U2U of reMARL against E2Coop,
the paper's numbers beside ours).

Methods: ``remarl`` (per-agent DDPG with the full reMARL reward), ``coma`` (policies/coma.py),
``mappo``, ``iql``, ``vdn``, ``qmix`` (BenchMARL, the ``baselines`` extra) and ``e2coop``
(policies/e2coop.py). The MARL baselines train on the Swarming reward only, with a discrete
heading set (`n_actions`, said in every output).
"""

from __future__ import annotations

import concurrent.futures
import csv
import importlib
import json
import multiprocessing
import os
import signal
import threading
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sim.errors import ConfigError

METHODS = ("remarl", "coma", "mappo", "iql", "vdn", "qmix", "e2coop")
"""Every method the grid knows."""

BENCHMARL_METHODS = frozenset({"mappo", "iql", "vdn", "qmix"})

PAPER_TABLE2 = {
    "e2coop": {"reaction_s": 0.48, "energy": 134.88, "min_d_u2o_m": 38.70, "min_d_u2u_m": 40.31},
    "remarl": {"reaction_s": 0.006, "energy": 19.72, "min_d_u2o_m": 24.78, "min_d_u2u_m": 29.45},
}
"""The paper's Table 2 (3u2o, d_col 20): reaction time s, energy, min distances (their units)."""


@dataclass(frozen=True)
class CompareConfig:
    """One grid.

    Attributes:
        scenarios, methods: the grid's axes. seeds: seeds per cell (0..seeds−1).
        budget_steps: environment steps of training per run.
        out: the results folder. n_actions: the discrete heading set of the MARL baselines.
        eval_episodes: evaluation episodes per run (E2Coop: `e2coop_episodes`).
        workers: parallel cells (local process pool).
        e2coop_particles, e2coop_iterations: the planner's PSO budget (the original's 200×100).
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
    e2coop_particles: int = 200
    e2coop_iterations: int = 100
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


def run_job(job: Job) -> dict[str, Any]:
    """Train and evaluate one cell (or read its finished result)."""
    done = job.folder / "result.json"
    if done.exists():
        result: dict[str, Any] = json.loads(done.read_text())
        return result
    job.folder.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    if job.method == "remarl":
        evaluation = _run_remarl(job)
    elif job.method == "e2coop":
        evaluation = _run_e2coop(job)
    elif job.method == "coma":
        evaluation = _run_coma(job)
    else:
        evaluation = _run_benchmarl(job)
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


def _evaluate(act: Any, scenario: str, episodes: int, seed: int, num_envs: int) -> dict[str, Any]:
    from sim.evaluation import run_episodes, summarize

    rows = run_episodes(act, scenario, episodes, seed=2_000_000 + 1000 * seed, num_envs=num_envs)
    return {k: float(v) for k, v in summarize(rows).items()}


def _reaction_ms(act: Any, scenario: str, calls: int = 50) -> dict[str, float]:
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


def _run_remarl(job: Job) -> dict[str, Any]:
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

    return {
        **_evaluate(act, job.scenario, job.cfg.eval_episodes, job.seed, 50),
        **_reaction_ms(act, job.scenario),
    }


def _run_e2coop(job: Job) -> dict[str, Any]:
    from policies.e2coop import E2Coop, E2CoopConfig
    from sim.scenarios import load_scenario

    planner = E2CoopConfig(particles=job.cfg.e2coop_particles, iterations=job.cfg.e2coop_iterations)
    act = E2Coop(load_scenario(job.scenario), planner, seed=job.seed)
    return {
        **_evaluate(act, job.scenario, job.cfg.e2coop_episodes, job.seed, 1),
        **_reaction_ms(
            E2Coop(load_scenario(job.scenario), planner, seed=job.seed), job.scenario, 10
        ),
    }


def _run_coma(job: Job) -> dict[str, Any]:
    try:
        from policies import coma
    except ImportError as exc:  # pragma: no cover - present in this tree
        raise ConfigError(f"COMA is not available: {exc}") from exc
    cfg = coma.ComaConfig(budget_steps=job.cfg.budget_steps, n_actions=job.cfg.n_actions)
    coma.train_coma(cfg, job.scenario, job.folder, job.seed)
    act = coma.coma_policy(coma.load_coma(job.folder / "model.safetensors"))
    return {
        **_evaluate(act, job.scenario, job.cfg.eval_episodes, job.seed, 50),
        **_reaction_ms(act, job.scenario),
    }


def _run_benchmarl(job: Job) -> dict[str, Any]:
    try:  # the adapter needs the optional BenchMARL stack
        task = importlib.import_module("policies.benchmarl_task")
    except ImportError as exc:
        raise ConfigError(
            f"{job.method} needs BenchMARL: pip install 'remarl-fc[baselines]' ({exc})"
        ) from exc
    summary: dict[str, Any] = task.train_benchmarl(
        job.method,
        job.scenario,
        job.cfg.budget_steps,
        job.seed,
        job.folder,
        job.cfg.n_actions,
        eval_episodes=job.cfg.eval_episodes,
    )
    return summary


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
        try:
            import ray
        except ImportError as exc:
            raise ConfigError("--ray-address needs Ray: pip install 'ray[default]'") from exc
        ray.init(address=ray_address)
        remote = ray.remote(run_job)
        return list(ray.get([remote.remote(j) for j in todo]))
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


def read_curve(path: Path) -> np.ndarray:
    """(E, 3) rows env_steps, swarming_return, success of a run's curve.csv."""
    with path.open() as fh:
        rows = [
            (float(r["env_steps"]), float(r["swarming_return"]), float(r["success"]))
            for r in csv.DictReader(fh)
        ]
    return np.array(rows).reshape(-1, 3)


def write_reports(cfg: CompareConfig, results: list[dict[str, Any]]) -> dict[str, str]:
    """learning_curves.png, summary.md, table2.md, table2.csv; returns their paths."""
    out = cfg.out
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "learning_curves": str(_plot_curves(cfg)),
        "summary": str(_summary(cfg, results)),
    }
    paths.update(_table2(cfg, results))
    (out / "config.json").write_text(json.dumps(asdict(cfg), default=str, indent=1))
    return paths


def _binned(
    curves: list[np.ndarray], budget: int, bins: int = 20
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    edges = np.linspace(0, budget, bins + 1)
    means = np.full((len(curves), bins), np.nan)
    for k, c in enumerate(curves):
        idx = np.clip(np.searchsorted(edges, c[:, 0], side="right") - 1, 0, bins - 1)
        for b in range(bins):
            sel = c[idx == b, 1]
            if sel.size:
                means[k, b] = sel.mean()
    centre = (edges[:-1] + edges[1:]) / 2
    with warnings.catch_warnings():  # bins no episode ended in stay NaN: not drawn
        warnings.simplefilter("ignore", RuntimeWarning)
        return centre, np.nanmean(means, axis=0), np.nanstd(means, axis=0)


def _plot_curves(cfg: CompareConfig) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(cfg.scenarios)
    cols = min(4, n)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
    for ax, scenario in zip(axes.flat, cfg.scenarios, strict=False):
        for method in cfg.methods:
            if method == "e2coop":
                continue
            curves = []
            for k in range(cfg.seeds):
                path = cfg.out / "runs" / scenario / method / f"seed{k}" / "curve.csv"
                if path.exists():
                    c = read_curve(path)
                    if len(c):
                        curves.append(c)
            if not curves:
                continue
            x, mean, std = _binned(curves, cfg.budget_steps)
            ax.plot(x, mean, label=method)
            ax.fill_between(x, mean - std, mean + std, alpha=0.2)
        ax.set_title(scenario)
        ax.set_xlabel("environment steps")
        ax.set_ylabel("Swarming return / episode")
        ax.legend(fontsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.suptitle(
        f"learning curves (mean ± std over {cfg.seeds} seed{'s' if cfg.seeds > 1 else ''}; "
        f"baselines: {cfg.n_actions} headings)",
        fontsize=12 if cols > 2 else 8,  # one or two panels: keep the title inside the figure
    )
    fig.tight_layout()
    path = cfg.out / "learning_curves.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _cells(results: list[dict[str, Any]]) -> dict[tuple[str, str], list[dict[str, Any]]]:
    cells: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in results:
        cells.setdefault((r["scenario"], r["method"]), []).append(r)
    return cells


def _summary(cfg: CompareConfig, results: list[dict[str, Any]]) -> Path:
    cells = _cells(results)
    lines = [
        f"# Comparison ({'quick preset' if cfg.quick else 'full'}; budget {cfg.budget_steps:,} "
        f"env steps; {cfg.seeds} seed(s); baselines on {cfg.n_actions} headings)",
        "",
        "Final evaluation (mean ± std over seeds): success rate and Swarming return per episode.",
        "",
        "Episodes evaluated per run (greedy, seeds never used in training): "
        + _episode_counts(cfg, results)
        + ".",
        "",
        "| scenario | " + " | ".join(cfg.methods) + " |",
        "|---|" + "---|" * len(cfg.methods),
    ]
    for s in cfg.scenarios:
        row = [s]
        for m in cfg.methods:
            rs = cells.get((s, m), [])
            if not rs:
                row.append("—")
                continue
            succ = np.array([r["success_rate"] for r in rs])
            ret = np.array([r["swarming_return"] for r in rs])
            row.append(f"{succ.mean():.0%} ± {succ.std():.0%}, {ret.mean():.1f} ± {ret.std():.1f}")
        lines.append("| " + " | ".join(row) + " |")
    path = cfg.out / "summary.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _episode_counts(cfg: CompareConfig, results: list[dict[str, Any]]) -> str:
    """'method N' per method, from the results themselves (a range where runs differ)."""
    parts = []
    for m in cfg.methods:
        counts = sorted({int(r["episodes"]) for r in results if r["method"] == m})
        if counts:
            span = str(counts[0]) if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
            parts.append(f"{m} {span}")
    return ", ".join(parts) or "none"


def _table2(cfg: CompareConfig, results: list[dict[str, Any]]) -> dict[str, str]:
    cells = _cells(results)
    rows = []
    for method in ("e2coop", "remarl"):
        rs = cells.get(("3u2o", method), [])
        if not rs:
            continue

        def mean(key: str, rs: list[dict[str, Any]] = rs) -> float:
            return float(np.mean([r[key] for r in rs]))

        paper = PAPER_TABLE2[method]
        rows.append(
            {
                "method": method,
                "reaction_ms": round(mean("reaction_ms_median"), 3),
                "energy_rad": round(mean("energy_rad"), 3),
                "mean_min_d_u2o_m": round(mean("mean_min_d_u2o_m"), 2),
                "mean_min_d_u2u_m": round(mean("mean_min_d_u2u_m"), 2),
                "success_rate": round(mean("success_rate"), 3),
                "paper_reaction_ms": paper["reaction_s"] * 1000,
                "paper_energy": paper["energy"],
                "paper_min_d_u2o_m": paper["min_d_u2o_m"],
                "paper_min_d_u2u_m": paper["min_d_u2u_m"],
            }
        )
    if not rows:
        return {}
    csv_path, md_path = cfg.out / "table2.csv", cfg.out / "table2.md"
    with csv_path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = [
        "# Table 2 (3u2o, d_col 20 m): ours beside the paper's",
        "",
        "Energy is Σ|a| (radians of heading change per UAV, the same code for both methods); the "
        "paper's energy numbers come from unpublished code in unknown units. Distances are the "
        "mean over episodes of each episode's closest approach (continuous, swept).",
        "",
        "| method | reaction time (ms) | energy (rad) | min d_U2O (m) | min d_U2U (m) | success "
        "| paper: reaction (ms) / energy / min d_U2O / min d_U2U |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['method']} | {r['reaction_ms']} | {r['energy_rad']} | {r['mean_min_d_u2o_m']} | "
            f"{r['mean_min_d_u2u_m']} | {r['success_rate']:.0%} | {r['paper_reaction_ms']:g} / "
            f"{r['paper_energy']} / {r['paper_min_d_u2o_m']} / {r['paper_min_d_u2u_m']} |"
        )
    md_path.write_text("\n".join(lines) + "\n")
    return {"table2_md": str(md_path), "table2_csv": str(csv_path)}
