"""The reports of `remarl-fc compare`: learning curves, the summary table and Table 2.

`write_reports` writes, in the grid's folder: ``learning_curves.png`` (one panel per scenario,
the per-episode Swarming return of each method, mean ± std over seeds, as the paper's Fig. 3,
from every run's ``curve.csv``), ``summary.md`` (success and Swarming return per scenario and
method), ``table2.md`` and ``table2.csv`` (the paper's Table 2: reaction time, energy and
closest approaches of reMARL against E2Coop, in every scenario of the grid where either ran,
with the paper's figures beside ours where it has them) and ``config.json``.
"""

from __future__ import annotations

import csv
import json
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from policies.common import read_curve

if TYPE_CHECKING:
    from policies.compare.grid import CompareConfig

PAPER_TABLE2_SCENARIO = "3u2o"
"""The scenario of the paper's Table 2 (d_col 20 m)."""

PAPER_TABLE2 = {
    "e2coop": {"reaction_s": 0.48, "energy": 134.88, "min_d_u2o_m": 38.70, "min_d_u2u_m": 40.31},
    "remarl": {"reaction_s": 0.006, "energy": 19.72, "min_d_u2o_m": 24.78, "min_d_u2u_m": 29.45},
}
"""The paper's Table 2 (`PAPER_TABLE2_SCENARIO`): reaction time s, energy, min distances (their
units)."""

TABLE2_METHODS = ("e2coop", "remarl")
"""The methods Table 2 compares, in its row order."""


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
        + episode_counts(cfg, results)
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


def episode_counts(cfg: CompareConfig, results: list[dict[str, Any]]) -> str:
    """'method N' per method, from the results themselves (a range where runs differ)."""
    parts = []
    for m in cfg.methods:
        counts = sorted({int(r["episodes"]) for r in results if r["method"] == m})
        if counts:
            span = str(counts[0]) if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
            parts.append(f"{m} {span}")
    return ", ".join(parts) or "none"


def table2_rows(cfg: CompareConfig, results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Table 2's rows: reMARL and E2Coop in each scenario of the grid (means over seeds).

    The ``paper_*`` columns hold the paper's figures in `PAPER_TABLE2_SCENARIO` and are empty
    (None) in the other scenarios.
    """
    cells = _cells(results)
    rows = []
    for scenario in cfg.scenarios:
        for method in TABLE2_METHODS:
            rs = cells.get((scenario, method), [])
            if not rs:
                continue

            def mean(key: str, rs: list[dict[str, Any]] = rs) -> float:
                return float(np.mean([r[key] for r in rs]))

            paper = PAPER_TABLE2[method] if scenario == PAPER_TABLE2_SCENARIO else None
            rows.append(
                {
                    "scenario": scenario,
                    "method": method,
                    "reaction_ms": round(mean("reaction_ms_median"), 3),
                    "energy_rad": round(mean("energy_rad"), 3),
                    "mean_min_d_u2o_m": round(mean("mean_min_d_u2o_m"), 2),
                    "mean_min_d_u2u_m": round(mean("mean_min_d_u2u_m"), 2),
                    "success_rate": round(mean("success_rate"), 3),
                    "paper_reaction_ms": paper["reaction_s"] * 1000 if paper else None,
                    "paper_energy": paper["energy"] if paper else None,
                    "paper_min_d_u2o_m": paper["min_d_u2o_m"] if paper else None,
                    "paper_min_d_u2u_m": paper["min_d_u2u_m"] if paper else None,
                }
            )
    return rows


def _table2(cfg: CompareConfig, results: list[dict[str, Any]]) -> dict[str, str]:
    rows = table2_rows(cfg, results)
    if not rows:
        return {}
    csv_path, md_path = cfg.out / "table2.csv", cfg.out / "table2.md"
    with csv_path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = [
        "# Table 2: reMARL against the E2Coop meta-heuristic, ours beside the paper's",
        "",
        f"The paper reports {PAPER_TABLE2_SCENARIO} (d_col 20 m) only. Energy is Σ|a| (radians "
        "of heading change per UAV, the same code for both methods); the paper's energy numbers "
        "come from unpublished code in unknown units. Distances are the mean over episodes of "
        "each episode's closest approach (continuous, swept).",
        "",
        "| scenario | method | reaction time (ms) | energy (rad) | min d_U2O (m) | min d_U2U (m) "
        "| success | paper: reaction (ms) / energy / min d_U2O / min d_U2U |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        paper = (
            f"{r['paper_reaction_ms']:g} / {r['paper_energy']} / {r['paper_min_d_u2o_m']} / "
            f"{r['paper_min_d_u2u_m']}"
            if r["paper_reaction_ms"] is not None
            else "—"
        )
        lines.append(
            f"| {r['scenario']} | {r['method']} | {r['reaction_ms']} | {r['energy_rad']} | "
            f"{r['mean_min_d_u2o_m']} | {r['mean_min_d_u2u_m']} | {r['success_rate']:.0%} "
            f"| {paper} |"
        )
    md_path.write_text("\n".join(lines) + "\n")
    return {"table2_md": str(md_path), "table2_csv": str(csv_path)}
