"""``remarl-fc fly``, ``demo``, ``plot-flight``, ``bench fly`` and ``bench bus``: parsers, handlers.

Nothing heavy is imported until a handler runs; nothing here imports torch.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
import tempfile
from pathlib import Path
from typing import Any

from remarl_fc.cli.common import (
    EXIT_LINK_ANOMALY,
    EXIT_NOT_ALL_REACHED,
    FLAVOURS,
    add_choice,
    add_seed,
    add_shield_flags,
    emit,
    finish,
    shield_from_args,
)
from remarl_fc.policy_io import GENERALIST_ZOO
from remarl_fc.sitl.traffic import report_errors_text

DEMO_SCENARIO = "3u2o"
"""The scenario ``demo`` flies when given neither ``--scenario`` nor ``--vehicles``."""

MAX_DEMO_VEHICLES = 20
"""``demo --vehicles`` at most (`remarl_fc.demo.MAX_DEMO_VEHICLES`, not imported here: the
parser stays light)."""

MAX_DEMO_INTRUDERS = 8
"""``demo --intruders`` at most (`remarl_fc.demo.MAX_DEMO_INTRUDERS`)."""

DEFAULT_DEMO_INTRUDERS = 2
"""``demo --intruders`` when not given (`remarl_fc.demo.DEFAULT_INTRUDERS`)."""

FLY_SHIELD_MODE = "on"
"""``fly --shield`` and ``demo --shield`` when not given (the mode of
`remarl_fc.flight.config.FLY_SHIELD`, not imported here: the parser stays light)."""

FLY_FLAGS = {
    "dry_run": "dry_run",
    "require_signing": "require_signing",
    "lost_timeout_s": "lost_timeout",
    "setpoint_hz": "setpoint_hz",
    "hold": "hold",
    "system_id": "system_id",
    "speedup": "speedup",
    "max_flight_s": "max_flight",
    "swarm": "swarm",
    "bus_prefix": "bus_prefix",
    "vehicle_profile": "vehicle_profile",
}
"""`FlyConfig` settings that ``fly`` takes from its flags as they are: setting → flag (its dest)."""

BENCH_FLY_SUMMARY = (
    "{vehicles} vehicles, {seconds} s: setpoint tick p50 {tick_ms_p50:.3f} ms, "
    "p99 {tick_ms_p99:.3f} ms ({tick_us_per_vehicle_p50:.1f} µs per vehicle); "
    "decision p50 {decide_ms_p50:.3f} ms, p99 {decide_ms_p99:.3f} ms; "
    "missed setpoint deadlines {setpoint_deadline_misses}; "
    "setpoint rate per vehicle {setpoints_per_vehicle_hz:.2f} Hz"
)
"""``bench fly``'s line for people, filled from its result."""

BENCH_BUS_SUMMARY = (
    "{vehicles} vehicles at {rate_hz:g} Hz, {observers} observers: state latency "
    "p50 {latency_ms_p50} ms, p99 {latency_ms_p99} ms; delivered {delivered_fraction:.1%}"
)
"""``bench bus``'s line for people, filled from its result."""


def add_parsers(sub: Any) -> None:
    """Add ``fly``, ``demo`` and ``plot-flight``."""
    p = sub.add_parser(
        "fly",
        help="fly a swarm policy on ArduPilot/PX4 vehicles over MAVLink",
        description=(
            "Fly a trained swarm policy: MAVLink telemetry → the policy's observations → "
            "velocity + heading setpoints at constant speed. Every vehicle still under control "
            "is told to hold on any exit. Read docs/FLYING.md before a real flight."
        ),
    )
    p.add_argument(
        "--connection",
        action="append",
        required=True,
        metavar="URL",
        help="udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, serial:DEV[:BAUD] (repeatable)",
    )
    p.add_argument(
        "--policy",
        default=GENERALIST_ZOO,
        help=f"zoo name or .safetensors file (default {GENERALIST_ZOO}: any number of "
        "vehicles; a scenario policy such as 3u2o flies its own number)",
    )
    p.add_argument("--mission", required=True, help="mission TOML (docs/examples/)")
    p.add_argument(
        "--takeoff",
        type=float,
        nargs="?",
        const=math.nan,  # given without a value: the mission's heights
        default=None,
        metavar="ALT_M",
        help="take off first: to ALT_M, or without a value to each vehicle's mission alt_m",
    )
    p.add_argument("--dry-run", action="store_true", help="compute and log, send nothing")
    p.add_argument(
        "--no-param-check",
        action="store_true",
        help="do not read and judge the vehicles' failsafe parameters before arming",
    )
    p.add_argument("--log", default=None, metavar="DIR", help="write flight.tlog + decisions")
    p.add_argument("--signing-key", default=None, help="MAVLink 2 signing key file")
    p.add_argument(
        "--require-signing",
        action="store_true",
        help="refuse to fly without --signing-key (an unsigned link believes any sender "
        "at the vehicle's address)",
    )
    p.add_argument(
        "--lost-timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="once every other vehicle is done, wait this long for a lost one (default 30)",
    )
    add_choice(
        p,
        "--hold",
        ["brake", "loiter"],
        help="ArduPilot hold mode (default brake: holds without RC input)",
    )
    p.add_argument("--setpoint-hz", type=float, default=10.0, help="setpoint rate (≥ 10)")
    p.add_argument("--system-id", type=int, default=255, help="this controller's system id")
    p.add_argument("--max-flight", type=float, default=600.0, help="hold all after this many s")
    p.add_argument(
        "--speedup", type=float, default=1.0, help=argparse.SUPPRESS
    )  # only to fly a mock running faster than real time
    add_shield_flags(p, default=FLY_SHIELD_MODE)
    p.add_argument(
        "--vehicle-profile",
        default=None,
        metavar="NAME|FILE",
        help="the vehicle profile (sim/vehicles) the shield predicts this process's vehicles "
        "with (default: the one fitted to each vehicle's autopilot, arducopter or px4; "
        "docs/FLYING.md)",
    )
    add_track_filter_flag(p)
    bus = p.add_argument_group("swarm bus (one process per vehicle)")
    bus.add_argument(
        "--vehicle",
        type=int,
        action="append",
        default=None,
        metavar="ID",
        help="fly only this system id (repeatable); the others come from the bus",
    )
    bus.add_argument(
        "--bus",
        default="memory",
        metavar="URL",
        help="memory (default: one process flies all) or mqtt[s]://HOST[:PORT]",
    )
    bus.add_argument("--swarm", default="swarm", help="swarm name (MQTT topics)")
    bus.add_argument("--bus-prefix", default="remarl", help="MQTT topic prefix")
    bus.add_argument("--bus-user", default=None, help="MQTT user name")
    bus.add_argument(
        "--bus-password-file", default=None, help="MQTT password file (or $REMARL_BUS_PASSWORD)"
    )
    bus.add_argument("--bus-ca", default=None, help="CA certificate for TLS (implies TLS)")
    bus.add_argument("--bus-cert", default=None, help="client certificate for TLS")
    bus.add_argument("--bus-key", default=None, help="client key for TLS")
    p.add_argument("--quiet", action="store_true", help="no live status lines")
    finish(p, cmd_fly, json_help="print the summary as one JSON object")

    p = sub.add_parser(
        "demo",
        help="fly the shipped policy on the built-in mock fleet (no SITL, no training)",
    )
    p.add_argument(
        "--scenario", default=None, help=f"scenario with a zoo policy (default {DEMO_SCENARIO})"
    )
    p.add_argument(
        "--vehicles",
        type=_int_in(1, MAX_DEMO_VEHICLES),
        default=None,
        metavar="N",
        help=f"instead of a scenario: N vehicles (1..{MAX_DEMO_VEHICLES}) with targets and "
        "random intruders, drawn from --seed",
    )
    p.add_argument(
        "--intruders",
        type=_int_in(0, MAX_DEMO_INTRUDERS),
        default=None,
        metavar="M",
        help=f"with --vehicles: M ADS-B intruders (0..{MAX_DEMO_INTRUDERS}, default "
        f"{DEFAULT_DEMO_INTRUDERS})",
    )
    add_seed(p, help="the mock's noise, and the geometry drawn for --vehicles (default 0)")
    p.add_argument(
        "--policy",
        default=None,
        help="zoo name or .safetensors file (default: the zoo's generalist where it is "
        "shipped; else the zoo's robust policy of the scenario where there is one, trained on "
        "fitted vehicles and ADS-B, e.g. robust/3u2o; else the zoo policy of the scenario)",
    )
    add_choice(p, "--flavour", FLAVOURS)
    p.add_argument("--speedup", type=float, default=2.0, help="simulated s per wall s")
    p.add_argument("--out", default="flight.png", help="the flight plot (default flight.png)")
    p.add_argument("--log", default=None, metavar="DIR", help="keep the logs here")
    p.add_argument("--summary", default=None, help="write the ground truth here (JSON)")
    add_shield_flags(p, default=FLY_SHIELD_MODE)
    add_track_filter_flag(p)
    p.add_argument(
        "--adsb-noise",
        action="store_true",
        help="the mock's ADS-B reports carry the simulator's report errors "
        f"({report_errors_text()}; default: exact reports)",
    )
    finish(p, cmd_demo)

    p = sub.add_parser("plot-flight", help="draw a flight from its log folder")
    p.add_argument("log", help="the --log folder of fly or demo")
    p.add_argument("--out", default="flight.png")
    finish(p, cmd_plot_flight)


def add_bench_parsers(bench: Any) -> None:
    """Add ``bench fly`` and ``bench bus``."""
    b = bench.add_parser("fly", help="runtime vs the mock: decision and setpoint tick times")
    b.add_argument("--vehicles", type=int, default=10)
    b.add_argument("--seconds", type=float, default=10.0, help="seconds under control")
    finish(b, cmd_bench_fly)

    b = bench.add_parser("bus", help="swarm bus: state latency through an MQTT broker")
    b.add_argument("--vehicles", type=int, default=50)
    b.add_argument("--seconds", type=float, default=5.0)
    b.add_argument("--bus", default=None, help="mqtt://HOST:PORT (default: start mosquitto)")
    finish(b, cmd_bench_bus)


def _int_in(lo: int, hi: int) -> Any:
    """An argparse type: an integer in [lo, hi]."""

    def parse(text: str) -> int:
        value = int(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be {lo} to {hi}, got {value}")
        return value

    parse.__name__ = "integer"  # argparse's "invalid integer value: 'x'"
    return parse


def _status_printer(enabled: bool) -> Any:
    if not enabled:
        return None

    def show(text: str) -> None:
        print(text, flush=True)

    return show


def cmd_fly(args: argparse.Namespace) -> int:
    """Fly; exit 0 when every vehicle reached its target, 4 otherwise."""
    from remarl_fc.errors import ConfigError
    from remarl_fc.flight.config import FlyConfig
    from remarl_fc.flight.control import ControlSpec
    from remarl_fc.flight.mission import load_mission
    from remarl_fc.flight.runtime import SwarmRuntime
    from remarl_fc.mavlink.codec import SigningConfig, load_signing_key
    from remarl_fc.policy_io import load_policy

    if not args.signing_key and not args.require_signing:
        print(
            "warning: the MAVLink link is not signed: any sender at a vehicle's address can "
            "speak for it (--signing-key FILE; --require-signing refuses to fly unsigned; "
            "docs/FLYING.md, security)",
            file=sys.stderr,
        )
    policy = load_policy(args.policy)
    mission = load_mission(args.mission)
    spec = ControlSpec.from_policy_meta(policy.meta)
    mission.check_policy(policy.uav_range, spec.speed_m_s, spec.dt_s, spec.arrival_m)
    signing = SigningConfig(load_signing_key(args.signing_key)) if args.signing_key else None
    by_mission = args.takeoff is not None and math.isnan(args.takeoff)
    shield = shield_from_args(args, policy.sees_neighbours)
    try:
        cfg = FlyConfig(
            connections=tuple(args.connection),
            mission=mission,
            takeoff_m=None if by_mission else args.takeoff,
            takeoff_to_mission_alt=by_mission,
            check_params=not args.no_param_check,
            log_dir=Path(args.log) if args.log else None,
            signing=signing,
            vehicles=frozenset(args.vehicle) if args.vehicle else None,
            shield=shield,
            track_filter=track_filter_of(args),
            **{setting: getattr(args, flag) for setting, flag in FLY_FLAGS.items()},
        )
    except ValueError as exc:
        raise ConfigError(f"fly: {exc}") from exc
    runtime = SwarmRuntime(
        cfg,
        policy,
        spec,
        on_status=_status_printer(not (args.quiet or args.json)),
        bus=_make_bus(args, cfg),
    )

    async def main() -> None:
        async with runtime:
            await runtime.run()

    try:
        asyncio.run(main())
    except KeyboardInterrupt:
        print("interrupted: every controlled vehicle was told to hold", file=sys.stderr)
    summary = runtime.summary()
    print(json.dumps(summary) if args.json else _fly_text(summary))
    return fly_exit_status(summary)


def fly_exit_status(summary: dict[str, Any]) -> int:
    """The exit status of ``fly`` for its summary.

    0 when every vehicle of this process reached its target on trusted telemetry and no
    anomaly touched what we believed; `EXIT_NOT_ALL_REACHED` when one did not reach it on
    trusted telemetry; else `EXIT_LINK_ANOMALY`.
    """
    mine = [v for v in summary["vehicles"] if v["local"]]
    if not all(v["system_id"] in summary["reached"] for v in mine):
        return EXIT_NOT_ALL_REACHED
    if any(a["affected"] for a in summary["anomalies"]):
        return EXIT_LINK_ANOMALY
    return 0


def _make_bus(args: argparse.Namespace, cfg: Any) -> Any:
    """None for the in-process bus, else an MQTT endpoint for the vehicles this process flies."""
    if args.bus == "memory":
        return None
    from remarl_fc.bus.mqtt import MqttBus, MqttSettings
    from remarl_fc.flight.config import bus_core

    settings = MqttSettings.from_url(
        args.bus,
        username=args.bus_user,
        password_file=args.bus_password_file,
        ca_file=args.bus_ca,
        cert_file=args.bus_cert,
        key_file=args.bus_key,
    )
    ids = frozenset(p.system_id for p in cfg.mission.vehicles)
    return MqttBus(settings, bus_core(cfg, cfg.vehicles or ids))


def _fly_text(summary: dict[str, Any]) -> str:
    from remarl_fc.flight.shielding import summary_line

    lines = [
        f"{summary['decisions']} decisions by {policy_line(summary['policy'])}",
        summary_line(summary["shield"]),
    ]
    for v in summary["vehicles"]:
        last = v["events"][-1][1] if v["events"] else ""
        trust = "" if v["trusted"] else f", telemetry untrusted: {v['untrusted']}"
        lines.append(f"vehicle {v['system_id']}: {v['status']} ({last}{trust})")
    for a in summary["anomalies"]:
        who = f"vehicle {a['system_id']}: " if a["system_id"] is not None else ""
        effect = "touched what we believed" if a["affected"] else "contained"
        lines.append(f"link anomaly ({a['kind']}, {effect}): {who}{a['text']}")
    if not summary["link"]["signed"]:
        lines.append("the link was not signed")
    return "\n".join(lines)


def policy_line(policy: dict[str, Any]) -> str:
    """The policy a flight flew, as its summary gives it: name, range of N, checksum."""
    low, high = policy["vehicles"]
    count = f"{low} to {high} vehicles" if low != high else f"{low} vehicles"
    checksum = policy["checksum"][:19] or "no checksum"
    return f"policy {policy['name']} ({count}, {checksum})"


def add_track_filter_flag(p: Any) -> None:
    """Add ``--track-filter off|on`` (left out: `FlyConfig`'s default, off)."""
    add_choice(
        p,
        "--track-filter",
        ["off", "on"],
        unset=True,
        help="fuse each ADS-B track's reports in a Kalman filter (default off: the newest "
        "report, as the policies trained; docs/FLYING.md says when on helps)",
    )


def track_filter_of(args: argparse.Namespace) -> bool:
    """`FlyConfig.track_filter` as ``--track-filter`` says (left out: its default)."""
    from remarl_fc.flight.config import FlyConfig

    return FlyConfig.track_filter if args.track_filter is None else args.track_filter == "on"


def cmd_demo(args: argparse.Namespace) -> int:
    """Mock fleet + runtime in one process; plot and ground truth at the end."""
    from remarl_fc.demo import demo_policy, fly_on_mock
    from remarl_fc.errors import ConfigError
    from remarl_fc.flight.flightlog import plot_flight
    from remarl_fc.flight.shielding import summary_line
    from remarl_fc.policy_io import load_policy
    from remarl_fc.sitl.groundtruth import write_json_atomic

    if args.vehicles is not None and args.scenario is not None:
        raise ConfigError("demo: give --scenario or --vehicles, not both")
    if args.vehicles is None and args.intruders is not None:
        raise ConfigError("demo: --intruders goes with --vehicles (a scenario has its own)")
    scenario = args.scenario or DEMO_SCENARIO
    intruders = DEFAULT_DEMO_INTRUDERS if args.intruders is None else args.intruders
    flown = args.policy or demo_policy(scenario)
    shield = shield_from_args(args, load_policy(flown).sees_neighbours)
    with tempfile.TemporaryDirectory(prefix="remarl-demo-") as tmp:
        log_dir = Path(args.log) if args.log else Path(tmp)
        flight = asyncio.run(
            fly_on_mock(
                scenario,
                flown,
                flavour=args.flavour,
                speedup=args.speedup,
                log_dir=log_dir,
                on_status=_status_printer(not args.json),
                seed=args.seed,
                vehicles=args.vehicles,
                intruders=intruders,
                shield=shield,
                fly_options={"track_filter": track_filter_of(args)},
                sitl_options={"adsb_noise": True} if args.adsb_noise else None,
            )
        )
        figure = plot_flight(log_dir, args.out)
    truth = flight.ground_truth
    if args.summary:
        write_json_atomic(args.summary, truth)
    overall = {k: v for k, v in truth.items() if k != "vehicles"}
    if args.json:
        print(json.dumps({"ground_truth": overall, "runtime": flight.runtime, "plot": figure}))
    else:
        what = scenario
        if args.vehicles is not None:
            what = f"{args.vehicles} vehicles, {intruders} intruders, seed {args.seed}"
        print(
            f"\nground truth ({args.flavour} mock, {what}): "
            f"{overall['reached_targets']}/{len(truth['vehicles'])} reached their targets, "
            f"collisions {overall['collisions_vehicle_intruder']} with intruders and "
            f"{overall['collisions_vehicle_vehicle']} between vehicles; closest approach "
            f"{overall['min_vehicle_intruder_m']} m to an intruder, "
            f"{overall['min_vehicle_vehicle_m']} m between vehicles (d_col {overall['d_col_m']} m)"
            f"\nflown by {policy_line(flight.runtime['policy'])}; "
            f"{summary_line(flight.runtime['shield'])}"
            f"\nwrote {figure['out']}"
        )
    return demo_exit_status(truth)


def demo_exit_status(truth: dict[str, Any]) -> int:
    """The exit status of ``demo`` for the mock's ground truth.

    0 when every vehicle reached its target and nothing came within d_col, else
    `EXIT_NOT_ALL_REACHED`.
    """
    ok = truth["reached_targets"] == len(truth["vehicles"]) and not (
        truth["collisions_vehicle_intruder"] or truth["collisions_vehicle_vehicle"]
    )
    return 0 if ok else EXIT_NOT_ALL_REACHED


def cmd_plot_flight(args: argparse.Namespace) -> int:
    """Draw a flight log."""
    from remarl_fc.flight.flightlog import plot_flight

    result = plot_flight(args.log, args.out)
    print(json.dumps(result) if args.json else f"wrote {result['out']}")
    return 0


def cmd_bench_fly(args: argparse.Namespace) -> int:
    """Runtime timings against the mock."""
    from remarl_fc.bench.fly import bench_fly

    result = asyncio.run(bench_fly(args.vehicles, args.seconds))
    emit(args, result, BENCH_FLY_SUMMARY.format_map(result))
    return 0


def cmd_bench_bus(args: argparse.Namespace) -> int:
    """State latency through the broker."""
    from remarl_fc.bench.bus import bench_bus
    from remarl_fc.bus.mqtt import MqttSettings

    host, port = "127.0.0.1", None
    if args.bus:
        settings = MqttSettings.from_url(args.bus)
        host, port = settings.host, settings.port
    result = asyncio.run(bench_bus(args.vehicles, args.seconds, port, host))
    emit(args, result, BENCH_BUS_SUMMARY.format_map(result))
    return 0
