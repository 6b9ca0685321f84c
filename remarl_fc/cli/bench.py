"""``remarl-fc bench``: the ``pso`` and ``sim`` micro-benchmarks, and the wiring of the others.

``bench sitl`` lives in `remarl_fc.cli.sitl`, ``bench fly`` and ``bench bus`` in
`remarl_fc.cli.fly`, next to the commands they measure.
"""

from __future__ import annotations

import argparse
from typing import Any

from remarl_fc.cli import fly, sitl
from remarl_fc.cli.common import SCENARIO_HELP, add_choice, add_seed, emit, finish, positive_int

PSO_SUMMARY = (
    "PSO, {uavs} UAVs x {envs} env(s): {ms_per_call:.2f} ms per call (p90 {ms_p90:.2f}), "
    "{evaluations} cost evaluations; feasible {feasible_fraction:.0%}, "
    "mean max shift {mean_max_shift_m:.2f} m"
)
"""``bench pso``'s line for people, filled from its result."""

SIM_SUMMARY = (
    "{scenario} ({world} world), batch {batch}, {actions} actions: "
    "{agent_steps_per_s:,.0f} agent-steps/s ({ms_per_step:.2f} ms/step)"
)
"""``bench sim``'s line for people, filled from its result."""

SIM_PARTS = "share of a step (profiled separately): {parts}"
"""``bench sim``'s second line: each part's share of a step (`remarl_fc.bench.sim.PARTS`)."""


def add_bench(sub: Any) -> None:
    """Add ``bench`` and its subcommands: pso, sim, sitl, fly, bus."""
    p = sub.add_parser("bench", help="micro-benchmarks")
    bench = p.add_subparsers(dest="what", required=True, metavar="WHAT")

    b = bench.add_parser("pso", help="contour-level PSO: time per call")
    b.add_argument("--uavs", type=positive_int, default=10, help="UAVs per swarm (default 10)")
    b.add_argument("--envs", type=positive_int, default=1, help="environments per call")
    b.add_argument("--repeats", type=positive_int, default=50, help="timed calls")
    b.add_argument(
        "--particles",
        type=positive_int,
        default=200,
        help="particles (default 200: with 30 iterations, the authors' 6,000 evaluations)",
    )
    b.add_argument("--iterations", type=positive_int, default=30, help="iterations (default 30)")
    add_seed(b)
    finish(b, cmd_bench_pso)

    b = bench.add_parser("sim", help="simulator throughput with the full reMARL reward")
    b.add_argument("--scenario", default="5u1o", help=SCENARIO_HELP)
    b.add_argument("--batch", type=positive_int, default=1024, help="environments per step")
    add_choice(
        b,
        "--actions",
        ["uniform", "noise"],
        help="uniform in [-1, 1] (default) or N(0, 0.1) around straight flight",
    )
    b.add_argument("--seconds", type=float, default=2.0, help="how long to time")
    add_choice(
        b,
        "--world",
        ["paper", "real"],
        help="paper: ideal vehicles, exact sensing (default); real: fitted ArduCopter/PX4 "
        "response randomised per UAV, ADS-B intruders, GPS noise, and the generalist's "
        "observation (6 neighbours, 8 intruders)",
    )
    b.add_argument(
        "--no-parts",
        dest="parts",
        action="store_false",
        help="skip the profiled run that gives each part's share of a step",
    )
    add_seed(b)
    finish(b, cmd_bench_sim)

    sitl.add_bench_parser(bench)
    fly.add_bench_parsers(bench)


def cmd_bench_pso(args: argparse.Namespace) -> int:
    """Time the contour-level PSO."""
    from remarl_fc.bench.sim import bench_pso
    from sim.config import PSOConfig

    cfg = PSOConfig(particles=args.particles, iterations=args.iterations)
    result = bench_pso(
        uavs=args.uavs, envs=args.envs, repeats=args.repeats, seed=args.seed, cfg=cfg
    )
    emit(args, result, PSO_SUMMARY.format_map(result))
    return 0


def cmd_bench_sim(args: argparse.Namespace) -> int:
    """Time the simulator with the full reMARL reward."""
    from remarl_fc.bench.sim import bench_sim, format_parts

    result = bench_sim(
        args.scenario,
        args.batch,
        args.actions,
        args.seconds,
        args.seed,
        parts=args.parts,
        world=args.world,
    )
    human = SIM_SUMMARY.format_map(result)
    if "parts" in result:
        human += "\n" + SIM_PARTS.format(parts=format_parts(result["parts"]))
    emit(args, result, human)
    return 0
