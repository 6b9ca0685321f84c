"""``remarl-fc suite list|show|label`` and ``remarl-fc eval --suite``: parsers and handlers.

Nothing here imports torch: suites run numpy inference of policy files and the hand-written
controllers.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import Any

from remarl_fc.cli.common import emit, finish, positive_int, shield_from_args
from remarl_fc.errors import ConfigError

SUITE_HELP = "a shipped suite (standard, smoke) or a suite .toml path"


def add_suite(sub: Any) -> None:
    """Add ``suite`` with its ``list``, ``show`` and ``label`` commands."""
    p = sub.add_parser("suite", help="benchmark suites of encounters: list, show, label")
    verbs = p.add_subparsers(dest="verb", required=True, metavar="VERB")
    listing = verbs.add_parser("list", help="the shipped suites and their families")
    finish(listing, cmd_suite_list)
    show = verbs.add_parser("show", help="one suite's families and their parameters")
    show.add_argument("name", help=SUITE_HELP)
    finish(show, cmd_suite_show)
    label = verbs.add_parser(
        "label", help="prove which episodes are solvable (oracle) and cache the labels"
    )
    label.add_argument("name", help=SUITE_HELP)
    label.add_argument("--families", default=None, help="comma-separated (default: all)")
    finish(label, cmd_suite_label)


def add_eval_suite_flags(p: Any) -> None:
    """The ``eval`` flags of a suite evaluation."""
    p.add_argument("--suite", default=None, help=f"evaluate on a benchmark suite: {SUITE_HELP}")
    p.add_argument(
        "--method",
        default=None,
        help="with --suite, comma-separated: straight, potential-field, orca, zoo",
    )
    p.add_argument("--families", default=None, help="with --suite: comma-separated subset")
    p.add_argument("--workers", type=positive_int, default=1, help="with --suite: processes")
    p.add_argument("--ray-address", default=None, help="with --suite: run on this Ray cluster")


def cmd_suite_list(args: argparse.Namespace) -> int:
    """The shipped suites: name, version, families, episodes."""
    from sim.suite import load_suite, suite_names

    rows: list[dict[str, Any]] = []
    for name in suite_names():
        s = load_suite(name)
        rows.append(
            {
                "name": s.name,
                "version": s.version,
                "families": [f.name for f in s.families],
                "episodes": s.episodes,
                "description": s.description,
            }
        )
    human = "\n".join(
        f"{r['name']:<10} v{r['version']}  {len(r['families'])} families × {r['episodes']} "
        f"episodes  {r['description']}"
        for r in rows
    )
    emit(args, {"suites": rows}, human)
    return 0


def cmd_suite_show(args: argparse.Namespace) -> int:
    """One suite's families with every parameter that decides their episodes."""
    from sim.encounters import family_scenario
    from sim.suite import cached_labels, load_suite

    s = load_suite(args.name)
    families = []
    for f in s.families:
        cfg = family_scenario(f)
        labels = cached_labels(s, f, s.episodes)
        families.append(
            {
                "name": f.name,
                "description": f.description or cfg.description,
                "uavs": cfg.uav.count,
                "intruders": cfg.obstacles.count,
                "max_steps": cfg.max_steps,
                "solvable": None if labels is None else float(labels.mean()),
                **f.parameters(),
            }
        )
    lines = [f"{s.name} v{s.version}: {s.description} ({s.episodes} episodes per family)"]
    for row in families:
        solv = "not labelled" if row["solvable"] is None else f"{row['solvable']:.0%} solvable"
        lines.append(
            f"  {row['name']:<22} N={row['uavs']:<3} M={row['intruders']:<2} "
            f"{row['distribution']:<13} {solv}"
        )
    emit(
        args,
        {
            "suite": s.name,
            "version": s.version,
            "episodes": s.episodes,
            "seed": s.seed,
            "families": families,
        },
        "\n".join(lines),
    )
    return 0


def cmd_suite_label(args: argparse.Namespace) -> int:
    """Label every family (or some) with the oracle and cache the labels."""
    import time

    from sim.suite import family_labels, load_suite

    s = load_suite(args.name)
    names = args.families.split(",") if args.families else [f.name for f in s.families]
    out = []
    for name in names:
        t0 = time.perf_counter()
        labels = family_labels(s, s.family(name), s.episodes)
        out.append(
            {"family": name, "solvable": float(labels.mean()), "seconds": time.perf_counter() - t0}
        )
        if not args.json:
            print(
                f"{name:<22} {labels.mean():6.1%} solvable  ({out[-1]['seconds']:.1f} s)",
                flush=True,
            )
    emit(
        args,
        {"suite": s.name, "labels": str(s.labels_path), "families": out},
        f"labels cached in {s.labels_path}",
    )
    return 0


def cmd_eval_suite(args: argparse.Namespace) -> int:
    """Evaluate methods and/or a policy on a suite: a table (or JSON), optionally pictures."""
    from remarl_fc.offline.suite import MethodSpec, evaluate_suite
    from remarl_fc.offline.suite_report import draw_suite, table
    from sim.suite import load_suite

    s = load_suite(args.suite)
    specs = [MethodSpec("method", m) for m in (args.method or "").split(",") if m]
    if args.policy:
        specs.append(MethodSpec("policy", args.policy))
    if not specs:
        raise ConfigError("eval --suite: give --method NAME[,NAME...] and/or --policy NAME|PATH")
    shield = shield_from_args(args)
    results = evaluate_suite(
        s,
        specs,
        families=args.families.split(",") if args.families else None,
        episodes=args.episodes,
        workers=args.workers,
        ray_address=args.ray_address,
        shield=shield,
    )
    payload: dict[str, Any] = {
        "suite": s.name,
        "version": s.version,
        "seed": s.seed,
        "shield_settings": dataclasses.asdict(shield),  # what --shield* asked, to reproduce it
        "results": [_json_ready(r) for r in results],
    }
    if args.plot:
        draw_suite(s, results, specs, Path(args.plot))
        payload["plot"] = args.plot
    emit(args, payload, table(results))
    return 0


def _json_ready(row: dict[str, Any]) -> dict[str, Any]:
    return {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in row.items()}
