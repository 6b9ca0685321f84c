"""What ``remarl-fc eval --suite`` prints and draws: the table, the heatmap, the worst episodes.

Pictures are written atomically (a partial file never appears).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from remarl_fc.offline.shielding import Shielded
from remarl_fc.offline.suite import MethodSpec, fly_episodes, resolve_method
from sim.encounters import sample_family
from sim.shield import ShieldConfig
from sim.suite import Suite, family_labels

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


def _draw_episode(ax: Any, cfg: Any, flown: Any, title: str, box: tuple[Any, Any]) -> None:
    """One flown episode's trails, framed by ``box`` (low corner, size: `_frame`)."""
    from sim.render import draw_state

    assert flown.trail_m is not None
    trail, state = flown.trail_m[:, 0], flown.final  # (T, N, 2)
    low, size = box
    shift = -low
    moved = dataclasses.replace(
        state,
        pos_m=state.pos_m + shift,
        target_m=state.target_m + shift,
        obstacle_pos_m=state.obstacle_pos_m + shift,
        centre_m=state.centre_m + shift,
    )
    shown = dataclasses.replace(cfg, arena_length_m=float(size[0]), arena_width_m=float(size[1]))
    draw_state(ax, shown, moved, 0, trail + shift)
    ax.set_title(title, fontsize=9)


def _frame(batch: Any, *flown: Any) -> tuple[Any, Any]:
    """(low corner, size) of a box around the trails, targets and obstacles of episodes."""
    parts = []
    for f in flown:
        assert f.trail_m is not None
        parts += [f.trail_m[:, 0].reshape(-1, 2), f.final.target_m[0], f.final.obstacle_pos_m[0]]
    points = np.concatenate([*parts, batch.obstacle_pos_m[0]])
    low = points.min(axis=0) - PICTURE_MARGIN_M
    return low, points.max(axis=0) + PICTURE_MARGIN_M - low


def draw_worst(suite: Suite, result: dict[str, Any], spec: MethodSpec, out: Path) -> None:
    """Fly a cell's worst episode again (the same episode, alone) and draw its trails."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    family = suite.family(result["family"])
    k = int(result["worst_episode"])
    cfg, batch = sample_family(family, suite.seed, [k])
    act, _ = resolve_method(spec, family, cfg)
    if act is None:
        return
    flown = fly_episodes(cfg, batch, act, trail=True)
    low, size = _frame(batch, flown)
    fig, ax = plt.subplots(figsize=(6, 6 * min(2.0, size[1] / size[0])), constrained_layout=True)
    outcome = "success" if result["success_rate"] == 1.0 else "worst failure"
    title = f"{family.name}, episode {k} ({outcome}): {result['method']}"
    _draw_episode(ax, cfg, flown, title, (low, size))
    _save(fig, out)


def _outcome(row: dict[str, Any]) -> str:
    if row["success"]:
        return "success"
    if row["collision_u2u"]:
        return "UAV-UAV collision"
    return "UAV-intruder collision" if row["collision_u2o"] else "timed out"


def draw_versus(
    suite: Suite,
    family_name: str,
    specs: tuple[MethodSpec, MethodSpec],
    out: Path,
    episodes: int = 40,
    shield: ShieldConfig | None = None,
    solvable: bool = False,
) -> dict[str, Any]:
    """Draw an episode the first method fails and the second flies, side by side.

    The first such episode among the first ``episodes`` of the family's suite stream, both
    flights in the same frame; returns what was found. Draws nothing (and says so:
    ``episode`` None) where no episode differs that way. ``shield``: both methods behind the
    safety shield, each flight with a shield of its own (it holds plans per environment).
    ``solvable``: only among the episodes the oracle proves solvable (`sim.suite.family_labels`),
    those the suite's success counts; the summary adds each method's success over them.
    The drawn episode is flown again alone; ``outcomes`` are that flight's, and
    ``same_as_batch`` says whether they are those the episode had among the others.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    family = suite.family(family_name)
    cfg, batch = sample_family(family, suite.seed, list(range(episodes)))
    acts = []
    for spec in specs:
        act, why = resolve_method(spec, family, cfg)
        if act is None:
            raise ValueError(f"{spec.label} does not apply to {family_name}: {why}")
        acts.append(act)

    def flyer(act: Any) -> Any:
        return act if shield is None else Shielded(act, shield)

    rows = [fly_episodes(cfg, batch, flyer(act)).rows for act in acts]
    success = [np.array([bool(r["success"]) for r in rs]) for rs in rows]
    counted = np.ones(episodes, dtype=bool)
    if solvable:
        counted = np.asarray(family_labels(suite, family, episodes), dtype=bool)
    found = np.flatnonzero(~success[0] & success[1] & counted)
    summary: dict[str, Any] = {
        "family": family_name,
        "episodes": episodes,
        "success": {s.label: float(ok.mean()) for s, ok in zip(specs, success, strict=True)},
        "episode": None,
    }
    if solvable:
        summary["solvable_episodes"] = int(counted.sum())
        summary["success_solvable"] = {
            s.label: float(ok[counted].mean()) if counted.any() else math.nan
            for s, ok in zip(specs, success, strict=True)
        }
    if not found.size:
        return summary
    k = int(found[0])
    one_cfg, one = sample_family(family, suite.seed, [k])
    flown = [fly_episodes(one_cfg, one, flyer(act), trail=True) for act in acts]
    outcomes = [_outcome(f.rows[0]) for f in flown]
    low, size = _frame(one, *flown)
    fig, axes = plt.subplots(
        1, 2, figsize=(11, 5.5 * min(2.0, size[1] / size[0])), constrained_layout=True
    )
    for ax, spec, f, outcome in zip(axes, specs, flown, outcomes, strict=True):
        _draw_episode(ax, one_cfg, f, f"{spec.label}: {outcome}", (low, size))
    behind = ", both behind the safety shield" if shield is not None else ""
    fig.suptitle(f"{family_name}, episode {k} of suite {suite.name}{behind}", fontsize=10)
    _save(fig, out)
    summary["episode"] = k
    summary["outcomes"] = dict(zip((s.label for s in specs), outcomes, strict=True))
    summary["same_as_batch"] = outcomes == [_outcome(r[k]) for r in rows]
    return summary


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
