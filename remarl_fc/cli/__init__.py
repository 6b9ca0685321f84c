"""The ``remarl-fc`` command line.

Commands that report figures take ``--json`` and then print exactly one JSON object on stdout.
Errors of the project (`remarl_fc.errors.RemarlError`) print one line on stderr and exit 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from remarl_fc._version import __version__
from remarl_fc.cli.fly import add_parsers as add_fly_parsers
from remarl_fc.cli.sitl import add_bench_parser, add_sitl_parser
from remarl_fc.errors import ConfigError, RemarlError

EXIT_USAGE = 2
"""Exit status for bad input (also argparse's)."""

Handler = Callable[[argparse.Namespace], int]


def _emit(args: argparse.Namespace, payload: dict[str, Any], human: str) -> None:
    print(json.dumps(payload) if getattr(args, "json", False) else human)


def _cmd_scenarios(args: argparse.Namespace) -> int:
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
    _emit(args, {"scenarios": rows}, "\n".join(lines))
    return 0


def _cmd_field(args: argparse.Namespace) -> int:
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
    _emit(args, payload, f"wrote {out} (scenario {cfg.name}, seed {args.seed})")
    return 0


def _cmd_rollout(args: argparse.Namespace) -> int:
    from remarl_fc.offline.rollout import rollout

    result = rollout(args.scenario, args.policy, Path(args.out), seed=args.seed)
    outcome = "success" if result.get("success") else "no success"
    human = (
        f"wrote {result['out']}: {result['scenario']} with {result['policy']}, "
        f"{result.get('length', '?')} steps, {outcome}"
    )
    _emit(args, result, human)
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    import dataclasses

    from policies.config import DDPGConfig, TrainConfig
    from policies.train import train

    ddpg = DDPGConfig(shared=args.shared)
    cfg = TrainConfig(
        scenario=args.scenario,
        num_envs=args.envs,
        total_steps=args.steps,
        minutes=args.minutes,
        seed=args.seed,
        eval_every=args.eval_every,
        eval_episodes=args.eval_episodes,
        reward=args.reward,
        ddpg=ddpg,
    )
    from sim.scenarios import load_scenario

    load_scenario(cfg.scenario)  # a bad name fails here, before anything is written
    out = Path(args.out or f"runs/{Path(cfg.scenario).stem}-s{cfg.seed}")
    bar = _progress_bar(cfg.total_steps, enabled=not args.json)
    with bar as progress:
        task = progress.add_task("train", total=cfg.total_steps)

        def report(scalars: dict[str, float]) -> None:
            progress.update(
                task,
                completed=scalars["step"],
                description=(
                    f"success {scalars['charts/success']:.0%}  "
                    f"swarming return {scalars['charts/episodic_swarming_return']:.1f}"
                ),
            )

        try:
            summary = train(cfg, out, resume=args.resume, progress=report)
        except KeyboardInterrupt:
            print(f"interrupted: resume with --resume --out {out}", file=sys.stderr)
            return 130
    _emit(
        args,
        {"config": dataclasses.asdict(cfg), **summary},
        f"trained {summary['env_steps']:,} environment steps in {summary['elapsed_s']:.0f} s; "
        f"best success {summary['best_success']:.1%}; run folder {out}",
    )
    return 0


def _progress_bar(total: int, *, enabled: bool) -> Any:
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} steps"),
        TimeElapsedColumn(),
        disable=not enabled,
        transient=False,
    )


def _cmd_eval(args: argparse.Namespace) -> int:
    from remarl_fc.offline.evaluate import evaluate_policy, plot_episode

    policy, result = evaluate_policy(args.policy, args.scenario, args.episodes, args.seed)
    if args.plot:
        plot_episode(policy, args.scenario, args.seed, Path(args.plot))
        result["plot"] = args.plot
    human = (
        f"{result['scenario']}, {int(result['episodes'])} episodes: success "
        f"{result['success_rate']:.1%}, collisions {result['collision_rate']:.1%} "
        f"(U2O {result['collision_rate_u2o']:.1%}, U2U {result['collision_rate_u2u']:.1%}), "
        f"min d_U2O {result['min_d_u2o_m']:.1f} m, min d_U2U {result['min_d_u2u_m']:.1f} m, "
        f"energy {result['energy_rad']:.2f} rad, path ratio {result['path_length_ratio']:.3f}, "
        f"swarming return {result['swarming_return']:.1f}, reaction time "
        f"{result['reaction_time_median_ms'] * 1e3:.0f} µs median "
        f"({result['reaction_time_p99_ms'] * 1e3:.0f} µs p99)"
    )
    _emit(args, result, human)
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    import json

    from policies.export import export_policy

    run = Path(args.run)
    if not (run / "config.json").is_file():
        raise ConfigError(f"{run}: not a training run folder (no config.json); pass --out of train")
    metrics = json.loads(Path(args.metrics).read_text()) if args.metrics else None
    meta = export_policy(run, Path(args.out), checkpoint=args.checkpoint, metrics=metrics)
    _emit(args, {"out": args.out, **meta}, f"wrote {args.out} ({meta['scenario']})")
    return 0


def _cmd_bench_sim(args: argparse.Namespace) -> int:
    from remarl_fc.bench.sim import bench_sim

    result = bench_sim(args.scenario, args.batch, args.actions, args.seconds, args.seed)
    human = (
        f"{result['scenario']}, batch {result['batch']}, {result['actions']} actions: "
        f"{result['agent_steps_per_s']:,.0f} agent-steps/s ({result['ms_per_step']:.2f} ms/step)"
    )
    _emit(args, result, human)
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    from remarl_fc.bench.sim import bench_pso
    from sim.config import PSOConfig

    cfg = PSOConfig(particles=args.particles, iterations=args.iterations)
    result = bench_pso(
        uavs=args.uavs, envs=args.envs, repeats=args.repeats, seed=args.seed, cfg=cfg
    )
    human = (
        f"PSO, {result['uavs']} UAVs x {result['envs']} env(s): "
        f"{result['ms_per_call']:.2f} ms per call (p90 {result['ms_p90']:.2f}), "
        f"{result['evaluations']} cost evaluations; feasible {result['feasible_fraction']:.0%}, "
        f"mean max shift {result['mean_max_shift_m']:.2f} m"
    )
    _emit(args, result, human)
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from policies.compare import METHODS, CompareConfig, cell_line, run_grid, write_reports

    scenarios = tuple(s for s in args.scenarios.split(",") if s)
    methods = tuple(m for m in (args.methods or ",".join(METHODS)).split(",") if m)
    out = Path(args.out)
    if args.quick:
        cfg = CompareConfig.quick_preset(scenarios, methods, out)
    else:
        cfg = CompareConfig(
            scenarios,
            methods,
            seeds=args.seeds,
            budget_steps=args.budget,
            out=out,
            n_actions=args.n_actions,
            workers=args.workers,
        )
    episodes = {
        name: value
        for name, value in (
            ("eval_episodes", args.eval_episodes),
            ("e2coop_episodes", args.e2coop_episodes),
        )
        if value is not None  # unset: the preset's own
    }
    cfg = dataclasses.replace(cfg, **episodes)
    try:
        results = run_grid(
            cfg,
            ray_address=args.ray_address,
            on_cell=lambda done, total, result: print(
                cell_line(done, total, result), file=sys.stderr, flush=True
            ),
        )
    except KeyboardInterrupt:
        print(
            f"interrupted: the finished cells are kept in {out}; run the same command to resume",
            file=sys.stderr,
        )
        return 130
    paths = write_reports(cfg, results)
    payload = {"cells": len(results), "out": str(out), **paths}
    _emit(args, payload, "\n".join(f"wrote {p}" for p in paths.values()))
    return 0


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every command."""
    parser = argparse.ArgumentParser(
        prog="remarl-fc",
        description="Train, evaluate and fly collision-avoidance policies for UAV swarms.",
    )
    parser.add_argument("--version", action="version", version=f"remarl-fc {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("scenarios", help="list the shipped scenarios")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_scenarios)

    p = sub.add_parser("field", help="draw a scenario's potential field and contours to a PNG")
    p.add_argument("--scenario", default="3u2o", help="scenario name or .toml path (default 3u2o)")
    p.add_argument("--out", default="field.png", help="output image (default field.png)")
    p.add_argument("--seed", type=int, default=0, help="seed of the obstacle spawn and PSO")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_field)

    p = sub.add_parser("train", help="train per-agent DDPG with the reMARL reward")
    p.add_argument("--scenario", default="3u2o", help="scenario name or .toml path")
    p.add_argument("--steps", type=_positive_int, default=20_000, help="vectorised env steps")
    p.add_argument("--minutes", type=float, default=0.0, help="wall-clock budget (0: none)")
    p.add_argument("--envs", type=_positive_int, default=16, help="environments stepped at once")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="run folder (default runs/SCENARIO-sSEED)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out")
    p.add_argument("--shared", action="store_true", help="one network for all agents")
    p.add_argument(
        "--reward",
        choices=["remarl", "swarming"],
        default="remarl",
        help="full reMARL reward (default) or its Swarming part only",
    )
    p.add_argument("--eval-every", type=_positive_int, default=2_000, help="steps between evals")
    p.add_argument("--eval-episodes", type=_positive_int, default=100)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_train)

    p = sub.add_parser("eval", help="evaluate a policy file (numpy inference)")
    p.add_argument("--policy", required=True, help="zoo name (e.g. 3u2o) or .safetensors path")
    p.add_argument("--scenario", default=None, help="default: the policy's own scenario")
    p.add_argument("--episodes", type=_positive_int, default=1000)
    p.add_argument("--seed", type=int, default=2_000_000, help="first evaluation seed")
    p.add_argument("--plot", default=None, help="also draw one episode and its Q-values here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_eval)

    p = sub.add_parser("export", help="write a policy file from a training run")
    p.add_argument("run", help="run folder (the --out of train)")
    p.add_argument("--out", required=True, help="the .safetensors file to write")
    p.add_argument("--checkpoint", choices=["best", "last"], default="best")
    p.add_argument("--metrics", default=None, help="eval JSON to embed in the file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_export)

    p = sub.add_parser("rollout", help="fly one episode with a hand-written policy and draw it")
    p.add_argument("--scenario", default="3u2o", help="scenario name or .toml path (default 3u2o)")
    p.add_argument("--policy", choices=["straight", "potential-field"], default="potential-field")
    p.add_argument("--out", default="run.png", help="run.png (last frame) or run.gif (animated)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_rollout)

    p = sub.add_parser("bench", help="micro-benchmarks")
    bench = p.add_subparsers(dest="what", required=True, metavar="WHAT")
    b = bench.add_parser("pso", help="contour-level PSO: time per call")
    b.add_argument("--uavs", type=_positive_int, default=10, help="UAVs per swarm (default 10)")
    b.add_argument("--envs", type=_positive_int, default=1, help="environments per call")
    b.add_argument("--repeats", type=_positive_int, default=50, help="timed calls")
    b.add_argument(
        "--particles",
        type=_positive_int,
        default=200,
        help="particles (default 200: with 30 iterations, the authors' 6,000 evaluations)",
    )
    b.add_argument("--iterations", type=_positive_int, default=30, help="iterations (default 30)")
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(handler=_cmd_bench)
    b = bench.add_parser("sim", help="simulator throughput with the full reMARL reward")
    b.add_argument("--scenario", default="5u1o", help="scenario name or .toml path")
    b.add_argument("--batch", type=_positive_int, default=1024, help="environments per step")
    b.add_argument(
        "--actions",
        choices=["uniform", "noise"],
        default="uniform",
        help="uniform in [-1, 1] (default) or N(0, 0.1) around straight flight",
    )
    b.add_argument("--seconds", type=float, default=2.0, help="how long to time")
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(handler=_cmd_bench_sim)
    add_bench_parser(bench)

    p = sub.add_parser(
        "compare", help="the paper's comparisons: baselines, E2Coop, Table 2, learning curves"
    )
    p.add_argument("--scenarios", default="3u2o", help="comma-separated (default 3u2o)")
    p.add_argument(
        "--methods", default=None, help="comma-separated: remarl,coma,mappo,iql,vdn,qmix,e2coop"
    )
    p.add_argument("--seeds", type=_positive_int, default=3)
    p.add_argument("--budget", type=_positive_int, default=200_000, help="env steps per run")
    p.add_argument("--out", default="results", help="results folder (finished cells are kept)")
    p.add_argument("--n-actions", type=_positive_int, default=11, help="baselines' heading set")
    p.add_argument("--workers", type=_positive_int, default=2, help="cells run in parallel")
    p.add_argument(
        "--eval-episodes",
        type=_positive_int,
        default=None,
        help="evaluation episodes per trained run",
    )
    p.add_argument(
        "--e2coop-episodes",
        type=_positive_int,
        default=None,
        help="evaluation episodes per E2Coop seed",
    )
    p.add_argument("--quick", action="store_true", help="small budgets: minutes on 2 cores")
    p.add_argument("--ray-address", default=None, help="run the cells on this Ray cluster")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_cmd_compare)
    add_sitl_parser(sub)
    add_fly_parsers(sub, bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    handler: Handler = args.handler
    try:
        return handler(args)
    except RemarlError as exc:
        print(f"remarl-fc: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
