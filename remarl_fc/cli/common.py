"""What the command modules share: exit statuses, output, and the options many commands take.

Nothing heavy is imported here; the command modules import their libraries inside handlers.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Sequence
from typing import Any

from remarl_fc.errors import ConfigError

EXIT_USAGE = 2
"""Exit status for bad input (also argparse's)."""

EXIT_TIMED_OUT = 3
"""Exit status of ``sitl --until-done`` when the time limit came first."""

EXIT_NOT_ALL_REACHED = 4
"""Exit status of ``fly`` and ``demo`` when the flight ended with a vehicle short of its target."""

EXIT_LINK_ANOMALY = 5
"""Exit status of ``fly`` when every vehicle reached its target but an anomaly of the link
touched what we believed (rejected or untrusted telemetry): read the summary's ``anomalies``."""

EXIT_BROKEN_PIPE = 141
"""Exit status when standard output was closed by its reader (what a shell reports for SIGPIPE)."""

EXIT_INTERRUPTED = 130
"""Exit status of ``train`` and ``compare`` stopped by Ctrl-C (what a shell reports for SIGINT)."""

JSON_HELP = "print one JSON object"
SCENARIO_HELP = "scenario name or .toml path"
FLAVOURS = ("ardupilot", "px4")
"""The autopilots the mock imitates (``--flavour``); the first is the default."""

Handler = Callable[[argparse.Namespace], int]


def emit(args: argparse.Namespace, payload: dict[str, Any], human: str) -> None:
    """Print ``payload`` as one JSON object under ``--json``, else the ``human`` text."""
    print(json.dumps(payload) if getattr(args, "json", False) else human)


def positive_int(text: str) -> int:
    """An argparse type: an integer ≥ 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


# argparse names the type in its "invalid _positive_int value: 'x'" errors; kept as it was.
positive_int.__name__ = "_positive_int"


def add_choice(
    p: Any,
    flag: str,
    choices: Sequence[str],
    *,
    default: str | None = None,
    unset: bool = False,
    help: str | None = None,
) -> None:
    """Add an option taking one of ``choices``.

    The default is the first unless given, or None with ``unset`` (a config's own default then
    applies where the flag is left out).
    """
    first = None if unset else choices[0] if default is None else default
    p.add_argument(flag, choices=list(choices), default=first, help=help)


def add_seed(p: Any, *, default: int = 0, help: str | None = None) -> None:
    """Add ``--seed``."""
    p.add_argument("--seed", type=int, default=default, help=help)


def finish(p: argparse.ArgumentParser, handler: Handler, *, json_help: str = JSON_HELP) -> None:
    """Close a command's parser: its ``--json`` (every command has one) and its handler."""
    p.add_argument("--json", action="store_true", help=json_help)
    p.set_defaults(handler=handler)


def progress_bar(*, enabled: bool, unit: str = "steps", digits: int = 0) -> Any:
    """A rich progress bar counting ``unit``, shown with ``digits`` decimals.

    Its task, added by the caller, carries the total.
    """
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    count = f"{{task.completed:,.{digits}f}}/{{task.total:,.{digits}f}} {unit}"
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn(count),
        TimeElapsedColumn(),
        disable=not enabled,
        transient=False,
    )


def add_shield_flags(p: Any, default: str, planner: bool = False) -> None:
    """Add ``--shield off|monitor|on`` (default ``default``), its horizons, margin and passes.

    The defaults of the horizons, margin and passes are `sim.shield.ShieldConfig`'s.
    ``planner``: also ``--shield-plan-steps`` (the simulator's evaluation alone applies it).
    """
    from sim.shield import (
        BLIND_TRACK_GROWTH_M_S,
        NEIGHBOUR_ARCS,
        SHIELD_MODES,
        VEHICLE_MODELS,
        ShieldConfig,
    )

    base = ShieldConfig()
    p.add_argument(
        "--shield",
        choices=list(SHIELD_MODES),
        default=default,
        help=f"the safety shield: off, monitor (record what it would change) or on (default "
        f"{default})",
    )
    p.add_argument(
        "--shield-horizon",
        type=float,
        default=base.horizon_s,
        help=f"shield look-ahead against exactly sensed intruders (the simulator's), seconds "
        f"(default {base.horizon_s:g})",
    )
    p.add_argument(
        "--shield-track-horizon",
        type=float,
        default=base.track_horizon_s,
        help="shield look-ahead against tracked intruders (ADS-B reports: every intruder of "
        f"fly), seconds (default {base.track_horizon_s:g})",
    )
    p.add_argument(
        "--shield-track-growth",
        type=float,
        default=None,
        help="growth of the clearance the shield keeps from a tracked intruder per second of "
        f"report age and of prediction, m/s (default {base.track_growth_m_s:g}, "
        f"{BLIND_TRACK_GROWTH_M_S:g} behind a policy blind to its neighbours, the zoo's "
        "scenario policies; docs/FLYING.md)",
    )
    p.add_argument(
        "--shield-neighbour-horizon",
        type=float,
        default=base.neighbour_horizon_s,
        help="shield look-ahead against the swarm's own UAVs, which re-plan every step, seconds "
        f"(default {base.neighbour_horizon_s:g})",
    )
    p.add_argument(
        "--shield-margin",
        type=float,
        default=base.margin_m,
        help=f"clearance the shield keeps beyond d_col, metres (default {base.margin_m:g})",
    )
    p.add_argument(
        "--shield-passes",
        type=int,
        default=base.passes,
        help="decisions per step: each pass after the first also keeps clear of the turns the "
        f"earlier ones gave the neighbours (default {base.passes})",
    )
    p.add_argument(
        "--shield-escape-steps",
        type=int,
        default=base.escape_steps,
        help="steps a UAV may hold the full turn for where no one-step heading passes "
        f"(default {base.escape_steps}; 1: one-step headings alone; never against ADS-B tracks)",
    )
    p.add_argument(
        "--shield-return",
        type=float,
        default=base.return_deg,
        metavar="DEG",
        help="a UAV whose heading lies more than DEG from the bearing to its target turns back "
        f"towards it where that passes the check (default {base.return_deg:g}; 180: never)",
    )
    p.add_argument(
        "--shield-fly-out",
        choices=["on", "off"],
        default="on" if base.fly_out else "off",
        help="a UAV circling a target its tightest turn never reaches flies straight on for a "
        "step where that passes the check; only where the vehicles fly their arcs exactly "
        "(the simulator's ideal vehicle, --shield-vehicle-model ideal) (default "
        f"{'on' if base.fly_out else 'off'})",
    )
    p.add_argument(
        "--shield-neighbours",
        choices=list(NEIGHBOUR_ARCS),
        default=base.neighbour_arcs,
        help="what each UAV expects of its neighbours: the swarm's proposals this step, or "
        f"flying straight on, one pass (default {base.neighbour_arcs})",
    )
    p.add_argument(
        "--shield-vehicle-model",
        choices=list(VEHICLE_MODELS),
        default=base.vehicle_model,
        help="how the shield predicts vehicles flown with a fitted autopilot response "
        "(--dynamics): with that response, or on the arcs as commanded (default "
        f"{base.vehicle_model})",
    )
    p.add_argument(
        "--shield-give-way",
        type=int,
        default=base.give_way,
        metavar="N",
        help="where a UAV is boxed in (nothing passes, but a heading clears the intruders), try "
        "up to N such headings with its neighbours deciding again to make room (default "
        f"{base.give_way}; 0: never)",
    )
    if planner:
        p.add_argument(
            "--shield-plan-steps",
            type=int,
            default=base.plan_steps,
            metavar="STEPS",
            help="where some UAV has nothing that passes the check, its whole swarm flies the "
            "oracle's plan for STEPS decisions (default "
            f"{base.plan_steps}; 0: never; the exact world only: never against ADS-B tracks "
            "or a fitted vehicle response)",
        )


def shield_from_args(args: argparse.Namespace, sees_neighbours: bool = True) -> Any:
    """The `sim.shield.ShieldConfig` of ``--shield*``; a bad value is a `ConfigError`.

    ``sees_neighbours``: whether the policy behind it does (`Policy.sees_neighbours`), which
    sets the track growth where ``--shield-track-growth`` is not given
    (`sim.shield.track_growth_behind`).
    """
    from sim.shield import ShieldConfig, track_growth_behind

    growth = args.shield_track_growth
    try:
        return ShieldConfig(
            mode=args.shield,
            horizon_s=args.shield_horizon,
            track_horizon_s=args.shield_track_horizon,
            track_growth_m_s=track_growth_behind(sees_neighbours) if growth is None else growth,
            neighbour_horizon_s=args.shield_neighbour_horizon,
            margin_m=args.shield_margin,
            passes=args.shield_passes,
            escape_steps=args.shield_escape_steps,
            return_deg=args.shield_return,
            fly_out=args.shield_fly_out == "on",
            neighbour_arcs=args.shield_neighbours,
            vehicle_model=args.shield_vehicle_model,
            give_way=args.shield_give_way,
            **(
                {"plan_steps": args.shield_plan_steps}
                if getattr(args, "shield_plan_steps", None) is not None
                else {}
            ),
        )
    except ValueError as exc:
        raise ConfigError(f"--shield: {exc}") from exc
