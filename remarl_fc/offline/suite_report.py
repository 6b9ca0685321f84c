"""What ``remarl-fc eval --suite`` prints and draws: the table, the heatmap, the worst episodes.

Pictures are written atomically (a partial file never appears).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from remarl_fc.offline.suite import MethodSpec, fly_episodes, resolve_method
from sim.encounters import sample_family
from sim.suite import Suite

PICTURE_MARGIN_M = 60.0
"""Free space around everything a worst-episode picture shows, metres."""


def _cell(r: dict[str, Any]) -> str:
    if not r.get("applicable"):
        return "n/a"
    solv = r["success_rate_solvable"]
    solv_text = "  –" if math.isnan(solv) else f"{solv:4.0%}"
    return f"{r['success_rate']:4.0%} {solv_text}"


def table(results: list[dict[str, Any]]) -> str:
    """Families × methods: success over all episodes, then over the solvable ones."""
    methods = list(dict.fromkeys(r["method"] for r in results))
    families = list(dict.fromkeys(r["family"] for r in results))
    cell = {(r["family"], r["method"]): r for r in results}
    solvable = {r["family"]: r for r in results if r.get("applicable")}
    width = max(len(f) for f in families)
    cols = [max(len(m), 9) for m in methods]
    lines = [
        f"{'family':<{width}}  {'N':>2} {'solv':>5}  "
        + "  ".join(f"{m:>{c}}" for m, c in zip(methods, cols, strict=True)),
        f"{'':<{width}}  {'':>2} {'':>5}  " + "  ".join(f"{'all solv':>{c}}" for c in cols),
    ]
    for f in families:
        any_row = next(r for (fam, _), r in cell.items() if fam == f)
        ref = solvable.get(f)
        solv = f"{ref['solvable_episodes'] / ref['episodes']:5.0%}" if ref else "    –"
        row = "  ".join(
            f"{_cell(cell[(f, m)]):>{c}}" if (f, m) in cell else f"{'':>{c}}"
            for m, c in zip(methods, cols, strict=True)
        )
        lines.append(f"{f:<{width}}  {any_row['uavs']:>2} {solv}  {row}")
    return "\n".join(lines)


def draw_heatmap(results: list[dict[str, Any]], out: Path, title: str) -> None:
    """Success over solvable episodes, families (rows) × methods (columns); grey: n/a."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(dict.fromkeys(r["method"] for r in results))
    families = list(dict.fromkeys(r["family"] for r in results))
    grid = np.full((len(families), len(methods)), np.nan)
    for r in results:
        if r.get("applicable"):
            grid[families.index(r["family"]), methods.index(r["method"])] = r[
                "success_rate_solvable"
            ]
    fig, ax = plt.subplots(
        figsize=(2.0 + 1.3 * len(methods), 1.2 + 0.28 * len(families)), constrained_layout=True
    )
    ax.set_facecolor("0.85")
    image = ax.imshow(grid, cmap="RdYlGn", vmin=0.0, vmax=1.0, aspect="auto")
    for (i, j), value in np.ndenumerate(grid):
        text = "n/a" if np.isnan(value) else f"{value:.0%}"
        ax.text(j, i, text, ha="center", va="center", fontsize=7)
    ax.set_xticks(range(len(methods)), methods, rotation=20, ha="right")
    ax.set_yticks(range(len(families)), families, fontsize=7)
    ax.set_title(title, fontsize=9)
    bar = fig.colorbar(image, ax=ax, shrink=0.6)
    bar.set_label("success, solvable episodes", fontsize=8)
    _save(fig, out)


def draw_worst(suite: Suite, result: dict[str, Any], spec: MethodSpec, out: Path) -> None:
    """Fly a cell's worst episode again (the same episode, alone) and draw its trails."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.render import draw_state

    family = suite.family(result["family"])
    k = int(result["worst_episode"])
    cfg, batch = sample_family(family, suite.seed, [k])
    act, _ = resolve_method(spec, family, cfg)
    if act is None:
        return
    flown = fly_episodes(cfg, batch, act, trail=True)
    assert flown.trail_m is not None
    trail, state = flown.trail_m[:, 0], flown.final  # (T, N, 2)
    points = np.concatenate(
        [trail.reshape(-1, 2), state.target_m[0], state.obstacle_pos_m[0], batch.obstacle_pos_m[0]]
    )
    low = points.min(axis=0) - PICTURE_MARGIN_M
    size = points.max(axis=0) + PICTURE_MARGIN_M - low
    shift = -low
    moved = dataclasses.replace(
        state,
        pos_m=state.pos_m + shift,
        target_m=state.target_m + shift,
        obstacle_pos_m=state.obstacle_pos_m + shift,
        centre_m=state.centre_m + shift,
    )
    shown = dataclasses.replace(cfg, arena_length_m=float(size[0]), arena_width_m=float(size[1]))
    fig, ax = plt.subplots(figsize=(6, 6 * min(2.0, size[1] / size[0])), constrained_layout=True)
    draw_state(ax, shown, moved, 0, trail + shift)
    outcome = "success" if result["success_rate"] == 1.0 else "worst failure"
    ax.set_title(f"{family.name}, episode {k} ({outcome}): {result['method']}", fontsize=9)
    _save(fig, out)


def draw_suite(
    suite: Suite, results: list[dict[str, Any]], specs: list[MethodSpec], folder: Path
) -> None:
    """The heatmap and every cell's worst episode, under ``folder``.

    Files: ``heatmap.png`` and ``worst/METHOD/FAMILY.png``.
    """
    draw_heatmap(results, folder / "heatmap.png", f"suite {suite.name} v{suite.version}")
    for r in results:
        if r.get("applicable"):
            spec = next(p for p in specs if p.label == r["method"])
            name = r["method"].replace(":", "-").replace("/", "-")
            draw_worst(suite, r, spec, folder / "worst" / name / f"{r['family']}.png")


def _save(fig: Any, out: Path) -> None:
    import matplotlib.pyplot as plt

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".part")
    fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    tmp.replace(out)
