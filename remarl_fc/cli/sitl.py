"""``remarl-fc sitl`` and ``remarl-fc bench sitl``: parsers and handlers.

Nothing heavy is imported until a handler runs; nothing here imports torch.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from collections.abc import Callable
from typing import Any

from remarl_fc.cli.common import EXIT_TIMED_OUT, FLAVOURS, add_choice, add_seed, finish
from remarl_fc.sitl.faults import parse_glitch, parse_pilot_switch, parse_window
from remarl_fc.sitl.params import parse_override
from remarl_fc.sitl.traffic import report_errors_text


def _arg(parse: Any) -> Any:
    """Wrap a ValueError-raising parser as an argparse type."""

    def convert(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from exc

    convert.__name__ = getattr(parse, "__name__", "value")
    return convert


def _repeatable(
    p: Any, flag: str, parse: Callable[[str], Any], metavar: str, help: str | None = None
) -> None:
    """Add an option that may be given many times, each value read by ``parse``."""
    p.add_argument(flag, type=_arg(parse), action="append", default=[], metavar=metavar, help=help)


def _host_port(text: str) -> tuple[str, int]:
    from remarl_fc.mavlink.udp import parse_host_port

    return parse_host_port(text, what="--out")


def _geo(text: str) -> Any:
    from remarl_fc.frames import GeoPoint

    return GeoPoint.parse(text)


def add_sitl_parser(sub: Any) -> None:
    """Add ``sitl`` to the command parsers."""
    p = sub.add_parser(
        "sitl",
        help="start a fleet of mock ArduPilot/PX4 autopilots speaking MAVLink 2 over UDP",
        description=(
            "Start N simulated multirotors, each a MAVLink 2 endpoint on its own UDP port "
            "(system id i+1, component 1). A vehicle answers whoever it last heard from and, "
            "with --out, also sends to that address from the start (PX4 style). Times given "
            "to fault options are simulated seconds since start."
        ),
    )
    who = p.add_mutually_exclusive_group()
    who.add_argument("--scenario", help="place vehicles, targets and intruders as this scenario")
    who.add_argument("--vehicles", type=int, default=None, help="N vehicles on a grid (default 1)")
    add_choice(p, "--flavour", FLAVOURS)
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument(
        "--base-port",
        type=int,
        default=None,
        help="port of vehicle 0 (default UDP 14550 ArduPilot, 18570 PX4, TCP 5760; 0 = any free)",
    )
    p.add_argument(
        "--tcp",
        action="store_true",
        help="each vehicle a TCP server for one client (ArduPilot SITL's 5760, 5770, ...) "
        "instead of a UDP endpoint",
    )
    p.add_argument(
        "--port-step", type=int, default=None, help="port increment (default 10 / 1 for PX4)"
    )
    p.add_argument("--out", type=_arg(_host_port), default=None, help="HOST:PORT to send to")
    p.add_argument("--out-step", type=int, default=0, help="--out port increment per vehicle")
    p.add_argument("--home", type=_arg(_geo), default=None, help="LAT,LON,ALT of the origin")
    p.add_argument("--speedup", type=float, default=1.0, help="simulated s per wall s")
    add_seed(p)
    p.add_argument("--summary", default=None, help="write the ground truth here on exit (JSON)")
    p.add_argument(
        "--until-done",
        action="store_true",
        help="exit once every vehicle has landed or reached its target",
    )
    p.add_argument("--timeout", type=float, default=None, help="stop after this many sim s")
    p.add_argument("--traffic-start", type=float, default=None, help="intruders start at (s)")
    p.add_argument("--cruise-alt", type=float, default=20.0, help="intruder height, m")
    p.add_argument("--signing-key", default=None, help="MAVLink 2 signing key file (32 bytes)")
    p.add_argument("--gps-noise", type=float, default=0.0, help="position noise σ, m")
    p.add_argument("--gust", type=float, default=0.0, help="gust velocity σ, m/s")
    p.add_argument(
        "--adsb-noise",
        action="store_true",
        help=f"ADS-B reports carry the simulator's report errors ({report_errors_text()}); "
        "default: exact, as ArduPilot's SITL",
    )
    p.add_argument(
        "--vehicle",
        default="flavour",
        help="vehicle profile: flavour (default: fitted to the flavour's real SITL traces, "
        "arducopter or px4), arducopter, px4, px4-sluggish, responsive (the mock's tuning "
        "before the fits), ideal, or a .toml path",
    )
    p.add_argument(
        "--quick-start",
        action="store_true",
        help="ArduPilot: the EKF is ready after 5 s and the climb starts at once after the "
        "take-off ACK (real ArduCopter SITL: about 39 s and 4.5 s; for tests and rehearsals)",
    )
    _repeatable(
        p,
        "--param",
        parse_override,
        "NAME=VALUE",
        help="start with this autopilot parameter, in its own units (repeatable; e.g. "
        "COM_OBL_RC_ACT=5 or RTL_ALT=2500); clients can also set them over MAVLink",
    )
    faults = p.add_argument_group("faults")
    faults.add_argument("--loss", type=float, default=0.0, help="packet loss, percent")
    faults.add_argument("--latency-ms", type=float, default=0.0, help="one-way latency")
    faults.add_argument("--jitter-ms", type=float, default=0.0, help="extra uniform delay")
    _repeatable(faults, "--cut-link", parse_window, "V:S:E")
    _repeatable(faults, "--heartbeat-dropout", parse_window, "V:S:E")
    _repeatable(faults, "--gps-glitch", parse_glitch, "V:S:E:M")
    _repeatable(faults, "--pilot-mode", parse_pilot_switch, "V:AT:MODE")
    finish(p, cmd_sitl, json_help="print the summary as one JSON object")


def add_bench_parser(bench: Any) -> None:
    """Add ``bench sitl`` to the bench parsers."""
    b = bench.add_parser("sitl", help="SITL mock: telemetry rate achieved and CPU per sim s")
    b.add_argument("--vehicles", type=int, default=100)
    b.add_argument("--rate", type=float, default=10.0, help="Hz asked for each message")
    b.add_argument("--seconds", type=float, default=5.0, help="simulated seconds measured")
    add_choice(b, "--flavour", FLAVOURS)
    b.add_argument("--speedup", type=float, default=1.0)
    finish(b, cmd_bench_sitl)


def cmd_sitl(args: argparse.Namespace) -> int:
    """Run the fleet until Ctrl-C, --until-done or --timeout; write the summary."""
    from remarl_fc.errors import ConfigError
    from remarl_fc.mavlink.codec import load_signing_key
    from remarl_fc.sitl.config import (
        ARDUPILOT_QUICK_START,
        DEFAULT_HOME,
        ArduPilotParams,
        Px4Params,
        SitlConfig,
        VehicleModelConfig,
    )
    from remarl_fc.sitl.faults import Faults
    from remarl_fc.sitl.params import ARDUPILOT_PARAMS, PX4_PARAMS, with_overrides
    from sim.scenarios import load_scenario

    scenario = load_scenario(args.scenario) if args.scenario else None
    try:
        model = VehicleModelConfig(
            gps_noise_m=args.gps_noise, gust_m_s=args.gust, profile=args.vehicle
        )
        ardupilot = ARDUPILOT_QUICK_START if args.quick_start else ArduPilotParams()
        px4 = Px4Params()
        if args.flavour == "px4":
            px4 = with_overrides(px4, PX4_PARAMS, args.param)
        else:
            ardupilot = with_overrides(ardupilot, ARDUPILOT_PARAMS, args.param)
        cfg = SitlConfig(
            vehicles=scenario.uav.count if scenario else (args.vehicles or 1),
            flavour=args.flavour,
            host=args.host,
            transport="tcp" if args.tcp else "udp",
            base_port=args.base_port,
            port_step=args.port_step,
            out=args.out,
            out_step=args.out_step,
            home=args.home or DEFAULT_HOME,
            speedup=args.speedup,
            seed=args.seed,
            cruise_alt_m=args.cruise_alt,
            adsb_noise=args.adsb_noise,
            model=model,
            ardupilot=ardupilot,
            px4=px4,
        )
        faults = Faults(
            loss=args.loss / 100.0,
            latency_s=args.latency_ms / 1000.0,
            jitter_s=args.jitter_ms / 1000.0,
            link_cuts=list(args.cut_link),
            heartbeat_dropouts=list(args.heartbeat_dropout),
            gps_glitches=list(args.gps_glitch),
            pilot_switches=list(args.pilot_mode),
        )
    except ValueError as exc:
        raise ConfigError(f"sitl: {exc}") from exc
    key = load_signing_key(args.signing_key) if args.signing_key else None
    summary: dict[str, Any] = {}
    try:
        finished = asyncio.run(_serve(args, cfg, scenario, faults, key, summary))
    except KeyboardInterrupt:
        finished = False
    if args.json:
        print(json.dumps(summary))
    else:
        overall = {k: v for k, v in summary.items() if k != "vehicles"}
        print(json.dumps(overall, indent=1), file=sys.stderr)
    if args.until_done and not finished:
        return EXIT_TIMED_OUT
    return 0


async def _serve(
    args: argparse.Namespace,
    cfg: Any,
    scenario: Any,
    faults: Any,
    key: bytes | None,
    summary: dict[str, Any],
) -> bool:
    from remarl_fc.sitl.fleet import SitlFleet
    from remarl_fc.sitl.groundtruth import write_json_atomic

    fleet = SitlFleet(
        cfg, scenario=scenario, faults=faults, signing_key=key, traffic_start_s=args.traffic_start
    )
    finished = started = False
    try:
        async with fleet:
            started = True
            if not args.json:
                for i, (host, port) in enumerate(fleet.addresses):
                    out = cfg.out_address(i)
                    to = f", sending to {out[0]}:{out[1]}" if out else ""
                    kind = cfg.transport
                    print(f"vehicle {i + 1} ({cfg.flavour}): {kind} {host}:{port}{to}", flush=True)
            finished = await fleet.wait(until_done=args.until_done, timeout_s=args.timeout)
    finally:
        if started:  # a fleet that never bound its ports has nothing to report
            summary.update(fleet.summary())
            if args.summary:
                write_json_atomic(args.summary, summary)
    return finished


def cmd_bench_sitl(args: argparse.Namespace) -> int:
    """Print the SITL benchmark figures."""
    from remarl_fc.bench.sitl import bench_sitl

    result = asyncio.run(
        bench_sitl(
            vehicles=args.vehicles,
            rate_hz=args.rate,
            seconds=args.seconds,
            flavour=args.flavour,
            speedup=args.speedup,
        )
    )
    if args.json:
        print(json.dumps(result))
        return 0
    lines = [
        f"{result['vehicles']} {result['flavour']} vehicles, {result['simulated_s']:.1f} sim s "
        f"(speedup {result['achieved_speedup']:.2f}): "
        f"{result['cpu_s_per_simulated_s']:.3f} CPU s per simulated s"
    ]
    for name, m in result["messages"].items():
        lines.append(
            f"  {name:20} asked {m['requested_hz']:5.1f} Hz: mean {m['mean_hz']:6.2f} Hz, "
            f"worst vehicle {m['worst_vehicle_hz']:6.2f} Hz"
        )
    print("\n".join(lines))
    return 0
