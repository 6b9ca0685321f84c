"""``remarl-fc scenarios``, ``field`` and ``rollout``: parsers and handlers.

Nothing heavy is imported until a handler runs; nothing here imports torch.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from remarl_fc.cli.common import SCENARIO_HELP, add_choice, add_seed, emit, finish

SCENARIO_3U2O_HELP = f"{SCENARIO_HELP} (default 3u2o)"


def add_scenarios(sub: Any) -> None:
    """Add ``scenarios``."""
    p = sub.add_parser("scenarios", help="list the shipped scenarios")
    finish(p, cmd_scenarios)


def add_field(sub: Any) -> None:
    """Add ``field``."""
    p = sub.add_parser("field", help="draw a scenario's potential field and contours to a PNG")
    p.add_argument("--scenario", default="3u2o", help=SCENARIO_3U2O_HELP)
    p.add_argument("--out", default="field.png", help="output image (default field.png)")
    add_seed(p, help="seed of the obstacle spawn and PSO")
    finish(p, cmd_field)


def add_rollout(sub: Any) -> None:
    """Add ``rollout``."""
    p = sub.add_parser("rollout", help="fly one episode with a hand-written policy and draw it")
    p.add_argument("--scenario", default="3u2o", help=SCENARIO_3U2O_HELP)
    add_choice(p, "--policy", ["straight", "potential-field", "orca"], default="potential-field")
    p.add_argument("--out", default="run.png", help="run.png (last frame) or run.gif (animated)")
    add_seed(p)
    finish(p, cmd_rollout)


def cmd_scenarios(args: argparse.Namespace) -> int:
    """List the shipped scenarios: a table, or their figures as JSON."""
    from sim.scenarios import load_scenario, scenario_names

    rows: list[dict[str, Any]] = []
    for name in scenario_names():
        cfg = load_scenario(name)
        rows.append(
            {
                "name": name,
                "uavs": cfg.uav.count,
                "obstacles": cfg.obstacles.count,
                "arena_m": [cfg.arena_length_m, cfg.arena_width_m],
                "formation": cfg.uav.formation,
                "dt_s": cfg.dt_s,
                "uav_speed_m_s": cfg.uav.speed_m_s,
                "obstacle_speed_m_s": cfg.obstacles.speed_m_s,
                "d_col_m": cfg.d_col_m,
                "max_steps": cfg.max_steps,
                "description": cfg.description,
            }
        )
    lines = [f"{'name':7} {'UAVs':>4} {'obst':>4} {'arena [m]':>11} {'formation':9}  description"]
    lines += [
        f"{r['name']:7} {r['uavs']:>4} {r['obstacles']:>4} "
        f"{r['arena_m'][0]:>5.0f}x{r['arena_m'][1]:<5.0f} {r['formation']:9}  {r['description']}"
        for r in rows
    ]
    emit(args, {"scenarios": rows}, "\n".join(lines))
    return 0


def cmd_field(args: argparse.Namespace) -> int:
    """Draw a scenario's field, contours and UAVs."""
    from remarl_fc.offline.plots import draw_field
    from sim.scenarios import load_scenario

    cfg = load_scenario(args.scenario)
    out = Path(args.out)
    snap = draw_field(cfg, out, seed=args.seed)
    payload = {
        "scenario": cfg.name,
        "out": str(out),
        "levels": snap.levels.tolist(),
        "uav_m": snap.uav_m.tolist(),
        "adjusted_m": snap.adjusted_m.tolist(),
        "obstacle_m": snap.obstacle_m.tolist(),
        "centre_m": snap.centre_m.tolist(),
    }
    emit(args, payload, f"wrote {out} (scenario {cfg.name}, seed {args.seed})")
    return 0


def cmd_rollout(args: argparse.Namespace) -> int:
    """Fly one episode with a hand-written policy and draw it."""
    from remarl_fc.offline.rollout import rollout

    result = rollout(args.scenario, args.policy, Path(args.out), seed=args.seed)
    outcome = "success" if result.get("success") else "no success"
    human = (
        f"wrote {result['out']}: {result['scenario']} with {result['policy']}, "
        f"{result.get('length', '?')} steps, {outcome}"
    )
    emit(args, result, human)
    return 0
