"""``remarl-fc train``, ``eval``, ``export`` and ``compare``: parsers and handlers.

torch and `policies` are imported only inside the handlers that need them (train, export,
compare), never when the parser is built.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from remarl_fc.cli.common import (
    EXIT_INTERRUPTED,
    SCENARIO_HELP,
    add_choice,
    add_seed,
    add_shield_flags,
    emit,
    finish,
    positive_int,
    progress_bar,
    shield_from_args,
)
from remarl_fc.cli.suite import add_eval_suite_flags, cmd_eval_suite
from remarl_fc.errors import ConfigError
from sim.config import SWARM_FIELDS, TEACHERS
from sim.evaluation import evaluation_seed
from sim.setnet import POOLINGS
from sim.shield import NEIGHBOUR_ARCS

if TYPE_CHECKING:
    from policies.config import GeneralistConfig

DEFAULT_EVAL_EPISODES = 1000
"""Episodes of ``eval --policy`` on one scenario."""


def add_train(sub: Any) -> None:
    """Add ``train``."""
    p = sub.add_parser("train", help="train per-agent DDPG with the reMARL reward")
    p.add_argument("--scenario", default="3u2o", help=SCENARIO_HELP)
    p.add_argument("--steps", type=positive_int, default=20_000, help="vectorised env steps")
    p.add_argument("--minutes", type=float, default=0.0, help="wall-clock budget (0: none)")
    p.add_argument("--envs", type=positive_int, default=16, help="environments stepped at once")
    add_seed(p)
    p.add_argument("--out", default=None, help="run folder (default runs/SCENARIO-sSEED)")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in --out (a generalist run with its own settings; --minutes "
        "may give it a new budget)",
    )
    p.add_argument("--shared", action="store_true", help="one network for all agents")
    add_choice(
        p,
        "--reward",
        ["remarl", "swarming"],
        help="full reMARL reward (default) or its Swarming part only",
    )
    p.add_argument("--eval-every", type=positive_int, default=2_000, help="steps between evals")
    p.add_argument("--eval-episodes", type=positive_int, default=100)
    p.add_argument(
        "--generalist",
        action="store_true",
        help="train the generalist (one shared set-encoder policy, any N, the encounter "
        "mixture; --minutes is its budget, default the shipped run's (docs/MODEL.md §20); "
        "--scenario, --steps, --envs, "
        "--shared, --reward and --eval-every do not apply)",
    )
    add_choice(
        p,
        "--device",
        ["auto", "cpu", "cuda"],
        unset=True,
        help="generalist: where the networks learn (default auto: cuda when present)",
    )
    p.add_argument(
        "--rollout-processes",
        type=int,
        metavar="P",
        help="generalist, its DAgger phase: P processes fly the rollouts while this one "
        "learns (default 0: here, in turn; 1 on a 2-core machine: about 1.6 times as many "
        "iterations a minute)",
    )
    p.add_argument(
        "--family-weight",
        action="append",
        default=[],
        metavar="PATTERN=W",
        help="generalist: families matching PATTERN (shell-style) run W times their share of "
        "UAVs (repeatable; e.g. 'swarms-*=3')",
    )
    p.add_argument(
        "--separation-horizon",
        type=float,
        metavar="S",
        help="generalist: the separation term also charges the closest approach predicted "
        "within S seconds to every other UAV and intruder (default 0: the step's own)",
    )
    p.add_argument(
        "--sensing-range",
        type=float,
        metavar="M",
        help="generalist: range of the neighbour and intruder rows, metres (default 200, the "
        "shipped run's; 0: the scenarios' 100 m)",
    )
    p.add_argument(
        "--max-neighbours",
        type=int,
        metavar="K",
        help="generalist: neighbouring-UAV rows each UAV sees, the nearest first (default 6; "
        "the policy file carries it)",
    )
    p.add_argument(
        "--teacher-horizon",
        type=float,
        metavar="S",
        help="generalist: how far ahead the ORCA teacher checks its turns against the "
        "intruders, seconds (default 20; ORCA's own 10 s suits 100 m)",
    )
    p.add_argument(
        "--turn-weight",
        type=float,
        metavar="K",
        help="generalist: DAgger weighs each teacher label 1 + K x how far it turns from the "
        "straight way to the target (default 0: every label alike)",
    )
    p.add_argument(
        "--own-separation",
        type=float,
        metavar="W",
        help="generalist: DAgger adds W x the separation penalty the student's own "
        "observation predicts for its action (default 0: imitation alone)",
    )
    p.add_argument(
        "--own-separation-horizon",
        type=float,
        metavar="S",
        help="generalist: how far ahead that penalty predicts, seconds (default 4)",
    )
    p.add_argument(
        "--own-separation-reciprocal",
        action="store_true",
        default=None,
        help="generalist: that penalty predicts each neighbour turning as the UAV itself does "
        "(default: flying straight on)",
    )
    p.add_argument(
        "--own-separation-intruders",
        action="store_true",
        default=None,
        help="generalist: that penalty charges the intruders in view too (default: the "
        "neighbours alone)",
    )
    p.add_argument(
        "--own-separation-intruder-horizon",
        type=float,
        metavar="S",
        help="generalist: how far ahead that penalty predicts the intruders, seconds (default "
        "0: as --own-separation-horizon)",
    )
    p.add_argument(
        "--own-separation-intruder-weight",
        type=float,
        metavar="W",
        help="generalist: the weight of that penalty's intruder rows (default: --own-separation's)",
    )
    p.add_argument(
        "--safe-set-weight",
        type=float,
        metavar="W",
        help="generalist, self-shield DAgger alone: where the shield intervened, fit the set of "
        "headings that pass, at this weight, instead of its one label (default 0: off)",
    )
    p.add_argument(
        "--safe-set-side",
        action="store_true",
        default=None,
        help="generalist, with --safe-set-weight: each safe set only the side the shield "
        "turned to (the passing headings next to its label; default: every passing heading)",
    )
    p.add_argument(
        "--sensing-aperture",
        type=float,
        metavar="DEG",
        help="generalist: full aperture of the sensed sector, degrees (default 360: all "
        "around; 0: the scenarios' 270)",
    )
    p.add_argument(
        "--separation-weight",
        type=float,
        metavar="W",
        help="generalist: reward lost per step at a UAV-UAV closest approach of d_col "
        "(default 0.5; 0: the reMARL reward alone)",
    )
    add_choice(
        p,
        "--swarm-field",
        list(SWARM_FIELDS),
        unset=True,
        help="generalist: worlds whose reward holds the swarm's peak around the virtual centre: "
        "all (the paper, default) or formation (only families that fly one formation)",
    )
    p.add_argument(
        "--ppo-min-std",
        type=float,
        metavar="S",
        help="generalist, PPO: floor of the policy's std on the normalised action (default 0: "
        "none; it falls to 0.05 within an hour)",
    )
    add_choice(
        p,
        "--teacher",
        list(TEACHERS),
        unset=True,
        help="generalist: learn from ORCA through the shield as well (orca-shield, default; "
        "PPO: DAgger, then the teacher labels the states the policy's own rollouts visit; TD3: "
        "clone, then TD3+BC), from the oracle replanned at every step (oracle: far stronger, "
        "about 100 times slower to label, docs/MODEL.md §20), from the --init policy behind "
        "the safety shield (self-shield: distils what it flies behind the shield) or from "
        "scratch (none)",
    )
    p.add_argument(
        "--teacher-truth",
        action="store_true",
        default=None,
        help="generalist: the teacher reads the true state in the real-world families (the "
        "intruders where they are, no GPS error), not what the UAVs sense: a privileged "
        "teacher (default: its shield reads the UAVs' ADS-B tracks, as in flight)",
    )
    p.add_argument(
        "--teacher-neighbours",
        choices=list(NEIGHBOUR_ARCS),
        default=None,
        help="generalist: what the self-shield teacher expects of each UAV's neighbours: "
        "their proposals this step (default, the shield as it flies) or flying straight on "
        "(a label made from what the UAV itself sees)",
    )
    p.add_argument(
        "--real-share",
        type=float,
        metavar="F",
        help="generalist: share of the families flown in the real world (fitted "
        "ArduCopter/PX4 responses, ADS-B intruders, GPS noise; default 0.35)",
    )
    p.add_argument(
        "--real-error-tau",
        type=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
        help="generalist: in the real-world families, the range of the ADS-B report errors' "
        "correlation time, seconds, drawn per intruder (default 0 0: every report's error "
        "drawn afresh)",
    )
    p.add_argument(
        "--real-track-filter",
        action="store_true",
        default=None,
        help="generalist: in the real-world families, ADS-B tracks fuse their reports in the "
        "track filter, as `fly --track-filter on` does (default: a track is its newest report)",
    )
    p.add_argument(
        "--real-hover",
        action="store_true",
        default=None,
        help="generalist: in the real-world families, arrived UAVs hover where they stop, as "
        "`fly` holds them (default: they leave, as in the suite)",
    )
    p.add_argument(
        "--dagger-lr",
        type=float,
        metavar="LR",
        help="generalist: Adam's learning rate of DAgger's supervised steps (default 1e-3, "
        "for fresh networks; 3e-4 distils a started policy, docs/MODEL.md §20)",
    )
    p.add_argument(
        "--init",
        metavar="POLICY",
        help="generalist, PPO: start from this policy file's networks (a zoo name or a "
        ".safetensors path; it must see as the run does); the run keeps a copy",
    )
    p.add_argument(
        "--bc-weight",
        type=float,
        metavar="A",
        help="generalist with a teacher: the cloning term's weight at the start (default 2.5)",
    )
    p.add_argument(
        "--bc-fraction",
        type=float,
        metavar="F",
        help="generalist with a teacher: the share of the run over which the cloning weight "
        "falls to 0 (default 0.75)",
    )
    p.add_argument(
        "--dagger-fraction",
        type=float,
        metavar="F",
        help="generalist, PPO with a teacher: the share of the run spent in DAgger first (the "
        "student flies, the teacher labels, supervised steps on every label; default 0.5; "
        "0: none; td3 and --teacher none have no DAgger phase)",
    )
    add_choice(
        p,
        "--pooling",
        list(POOLINGS),
        unset=True,
        help="generalist: how the set networks pool the neighbour and intruder rows: max and "
        "mean (deep sets, default) or max and attention (a query from the UAV's own state)",
    )
    add_choice(
        p,
        "--learner",
        ["ppo", "td3"],
        unset=True,
        help="generalist: the learner (default ppo, by the side-by-side of docs/MODEL.md §20)",
    )
    finish(p, cmd_train)


TRAIN_FLAGS = {
    "scenario": "scenario",
    "num_envs": "envs",
    "total_steps": "steps",
    "minutes": "minutes",
    "seed": "seed",
    "eval_every": "eval_every",
    "eval_episodes": "eval_episodes",
    "reward": "reward",
}
"""`TrainConfig` settings that ``train`` takes from its flags as they are: setting → flag."""


def add_eval(sub: Any) -> None:
    """Add ``eval``."""
    p = sub.add_parser(
        "eval", help="evaluate a policy file (numpy inference), or methods on a benchmark suite"
    )
    p.add_argument("--policy", default=None, help="zoo name (e.g. 3u2o) or .safetensors path")
    p.add_argument("--scenario", default=None, help="default: the policy's own scenario")
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=None,
        help="episodes (default 1000; with --suite, per family, default the suite's)",
    )
    add_seed(p, default=evaluation_seed(), help="first evaluation seed")
    add_shield_flags(p, default="off", planner=True)
    p.add_argument(
        "--dynamics",
        default=None,
        help="fly every UAV with this vehicle profile: ideal (the paper), arducopter, px4, "
        "px4-sluggish, responsive, or a profile .toml (default: the scenario's)",
    )
    p.add_argument(
        "--sensors",
        choices=["exact", "adsb"],
        default=None,
        help="exact positions, or ADS-B intruders and GPS noise (default: the scenario's)",
    )
    p.add_argument(
        "--track-filter",
        choices=["on", "off"],
        default=None,
        help="ADS-B tracks fuse their reports in a Kalman filter, as `fly --track-filter on` "
        "does, or hold the newest report (default: the scenario's, off)",
    )
    p.add_argument(
        "--arrival",
        choices=["hover", "leave"],
        default=None,
        help="arrived UAVs hover in the way, or leave (the paper's rule); default: the scenario's",
    )
    p.add_argument(
        "--plot",
        default=None,
        help="draw one episode and its Q-values to this file; with --suite, a folder for the "
        "heatmap and every family's worst episode",
    )
    add_eval_suite_flags(p)
    finish(p, cmd_eval)


def add_export(sub: Any) -> None:
    """Add ``export``."""
    p = sub.add_parser("export", help="write a policy file from a training run")
    p.add_argument("run", nargs="?", help="run folder (the --out of train)")
    p.add_argument("--out", help="the .safetensors file to write")
    p.add_argument(
        "--rehash",
        metavar="FILE",
        help="instead: add a checksum to a policy file written before checksums "
        "(in place; tensors unchanged)",
    )
    add_choice(p, "--checkpoint", ["best", "last"])
    p.add_argument("--metrics", default=None, help="eval JSON to embed in the file")
    finish(p, cmd_export)


def add_compare(sub: Any) -> None:
    """Add ``compare``."""
    p = sub.add_parser(
        "compare", help="the paper's comparisons: baselines, E2Coop, Table 2, learning curves"
    )
    p.add_argument("--scenarios", default="3u2o", help="comma-separated (default 3u2o)")
    p.add_argument(
        "--methods", default=None, help="comma-separated: remarl,coma,mappo,iql,vdn,qmix,e2coop"
    )
    p.add_argument("--seeds", type=positive_int, default=3)
    p.add_argument("--budget", type=positive_int, default=200_000, help="env steps per run")
    p.add_argument("--out", default="results", help="results folder (finished cells are kept)")
    p.add_argument("--n-actions", type=positive_int, default=11, help="baselines' heading set")
    p.add_argument("--workers", type=positive_int, default=2, help="cells run in parallel")
    for what, per in (("eval", "trained run"), ("e2coop", "E2Coop seed")):
        p.add_argument(
            f"--{what}-episodes",
            type=positive_int,
            default=None,  # the preset's own
            help=f"evaluation episodes per {per}",
        )
    p.add_argument("--quick", action="store_true", help="small budgets: minutes on 2 cores")
    p.add_argument("--ray-address", default=None, help="run the cells on this Ray cluster")
    finish(p, cmd_compare)


def cmd_train(args: argparse.Namespace) -> int:
    """Train with a progress bar; exit 130 on Ctrl-C (the run folder can be resumed)."""
    if args.generalist:
        return cmd_train_generalist(args)
    from policies.config import DDPGConfig, TrainConfig
    from policies.train import train
    from sim.scenarios import load_scenario

    settings = {setting: getattr(args, flag) for setting, flag in TRAIN_FLAGS.items()}
    cfg = TrainConfig(**settings, ddpg=DDPGConfig(shared=args.shared))
    load_scenario(cfg.scenario)  # a bad name fails here, before anything is written
    out = Path(args.out or f"runs/{Path(cfg.scenario).stem}-s{cfg.seed}")
    with progress_bar(enabled=not args.json) as progress:
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
            return EXIT_INTERRUPTED
    emit(
        args,
        {"config": dataclasses.asdict(cfg), **summary},
        f"trained {summary['env_steps']:,} environment steps in {summary['elapsed_s']:.0f} s; "
        f"best success {summary['best_success']:.1%}; run folder {out}",
    )
    return 0


def family_weight_arg(text: str) -> tuple[str, float]:
    """``PATTERN=W`` of ``--family-weight`` as a (pattern, weight) pair."""
    pattern, sep, weight = text.rpartition("=")
    try:
        value = float(weight)
    except ValueError:
        value = math.nan
    if not sep or not pattern or not math.isfinite(value) or value <= 0:
        raise ConfigError(
            f"--family-weight wants PATTERN=W with W > 0 (e.g. 'swarms-*=3'), got {text!r}"
        )
    return pattern, value


def generalist_config(args: argparse.Namespace) -> GeneralistConfig:
    """The `policies.config.GeneralistConfig` of ``train --generalist``'s flags.

    Raises:
        ConfigError: a flag's value out of range, named with what the config's check says.
    """
    from policies.config import GeneralistConfig

    try:
        cfg = GeneralistConfig(**{"seed": args.seed, **generalist_flags(args)})
    except ValueError as exc:  # the config's own range checks: say so, not a traceback
        raise ConfigError(f"train --generalist: {exc}") from exc
    if args.dagger_fraction and cfg.dagger_share() == 0:  # asked for, and cannot apply
        raise ConfigError(
            "train --generalist: dagger_fraction: DAgger needs a teacher and the ppo learner "
            f"(here --teacher {cfg.teacher} --learner {cfg.learner}): drop --dagger-fraction"
        )
    if args.rollout_processes and cfg.dagger_share() == 0:
        raise ConfigError(
            "train --generalist: rollout_processes: they fly the DAgger phase's rollouts, and "
            f"this run has none (--teacher {cfg.teacher} --learner {cfg.learner}, "
            f"--dagger-fraction {cfg.dagger_fraction}): drop --rollout-processes"
        )
    return cfg


RESUME_MAY_CHANGE = ("minutes", "device", "rollout_processes")
"""The settings a resumed generalist run may be given anew: none changes what it learns from."""


def resumed_generalist_config(args: argparse.Namespace, out: Path) -> GeneralistConfig:
    """The settings of the run in ``out``, for ``train --generalist --resume``.

    A resumed run keeps the settings it started with (its ``config.json``), not today's
    defaults; ``--minutes`` (a new budget), ``--device`` and ``--rollout-processes`` may
    change. Any other flag that disagrees with the stored run is an error, as is a folder
    without a checkpoint.

    Raises:
        ConfigError: nothing to resume in ``out``, an unreadable ``config.json``, or a flag
            that would change the run.
    """
    from policies.config import resumed_config

    where = "train --generalist --resume"
    if not (out / "last.safetensors").is_file():
        raise ConfigError(
            f"{where}: {out} holds no checkpoint (last.safetensors) to resume: start the run "
            "without --resume, or name the run's folder with --out"
        )
    try:
        stored = json.loads((out / "config.json").read_text())["generalist"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(
            f"{where}: {out / 'config.json'} is missing or unreadable ({exc}); it holds the "
            "run's settings, without which the run cannot be resumed as it was"
        ) from exc
    try:
        cfg = resumed_config(
            stored,
            minutes=args.minutes or None,
            device=args.device,
            rollout_processes=args.rollout_processes,
        )
    except (ValueError, TypeError) as exc:  # a setting out of range, or of the wrong type
        raise ConfigError(f"{where}: {out / 'config.json'}: {exc}") from exc
    asked = generalist_config(args)  # the flags as a new run would take them
    clash = [
        f"{name} {getattr(asked, name)!r} (the run's: {getattr(cfg, name)!r})"
        for name in generalist_flags(args)
        if name not in RESUME_MAY_CHANGE and getattr(asked, name) != getattr(cfg, name)
    ]
    if clash:
        raise ConfigError(
            f"{where}: a resumed run keeps the settings it started with; these flags would "
            f"change them: {'; '.join(clash)}. Drop them, or start a new run in another --out"
        )
    return cfg


def generalist_flags(args: argparse.Namespace) -> dict[str, Any]:
    """The `GeneralistConfig` settings that ``train --generalist``'s flags give explicitly.

    A flag left out (None; ``--minutes 0``; ``--seed 0``, the default) is not in it.
    """
    flags = {
        "minutes": args.minutes or None,
        "device": args.device,
        "rollout_processes": args.rollout_processes,
        "learner": args.learner,
        "swarm_field": args.swarm_field,
        "pooling": args.pooling,
        "ppo_min_std": args.ppo_min_std,
        "teacher": args.teacher,
        "init": args.init,
        "bc_weight": args.bc_weight,
        "bc_fraction": args.bc_fraction,
        "dagger_fraction": args.dagger_fraction,
        "dagger_lr": args.dagger_lr,
        "separation_horizon_s": args.separation_horizon,
        "separation_weight": args.separation_weight,
        "sensing_range_m": args.sensing_range,
        "sensing_aperture_deg": args.sensing_aperture,
        "max_neighbours": args.max_neighbours,
        "teacher_horizon_s": args.teacher_horizon,
        "teacher_truth": args.teacher_truth,
        "teacher_neighbours": args.teacher_neighbours,
        "real_share": args.real_share,
        "real_error_tau_s": tuple(args.real_error_tau) if args.real_error_tau else None,
        "real_track_filter": args.real_track_filter,
        "real_hover": args.real_hover,
        "dagger_turn_weight": args.turn_weight,
        "dagger_separation_weight": args.own_separation,
        "dagger_separation_horizon_s": args.own_separation_horizon,
        "dagger_separation_reciprocal": args.own_separation_reciprocal,
        "dagger_separation_intruders": args.own_separation_intruders,
        "dagger_separation_intruder_horizon_s": args.own_separation_intruder_horizon,
        "dagger_separation_intruder_weight": args.own_separation_intruder_weight,
        "dagger_safe_set_weight": args.safe_set_weight,
        "dagger_safe_set_side": args.safe_set_side,
        "seed": args.seed or None,
    }
    if args.family_weight:
        flags["family_weights"] = tuple(family_weight_arg(text) for text in args.family_weight)
    return {name: value for name, value in flags.items() if value is not None}


def cmd_train_generalist(args: argparse.Namespace) -> int:
    """``train --generalist``: the mixture run of `policies.generalist_train`."""
    from policies.generalist_train import train_generalist

    out = Path(args.out or f"runs/generalist-s{args.seed}")
    cfg = resumed_generalist_config(args, out) if args.resume else generalist_config(args)
    with progress_bar(enabled=not args.json, unit="min", digits=1) as progress:
        task = progress.add_task("train", total=cfg.minutes)

        def report(scalars: dict[str, float]) -> None:
            progress.update(
                task,
                completed=scalars["perf/elapsed_min"],
                description=(
                    f"success {scalars['charts/success']:.0%}  "
                    f"UAV-UAV {scalars['charts/collision_u2u']:.0%}  "
                    f"UAV-obstacle {scalars['charts/collision_u2o']:.0%}"
                ),
            )

        try:
            summary = train_generalist(cfg, out, resume=args.resume, progress=report)
        except KeyboardInterrupt:
            print(f"interrupted: resume with --generalist --resume --out {out}", file=sys.stderr)
            return EXIT_INTERRUPTED
    emit(
        args,
        {"config": dataclasses.asdict(cfg), **summary},
        f"trained {summary['transitions']:,} UAV transitions in {summary['elapsed_s']:.0f} s; "
        f"{validation_line(summary)}; run folder {out}",
    )
    return 0


def validation_line(summary: dict[str, Any]) -> str:
    """What a generalist run's validations showed: the best and the final networks' success."""
    last, best = summary.get("last_eval"), summary["best_success"]
    if last is None and best >= 0:  # a resumed run whose networks an earlier sitting flew
        return f"best validation success {best:.1%}"
    if last is None or not math.isfinite(last["success_mean"]):
        return "not validated (no family flies the ideal world)"
    return (
        f"best validation success {summary['best_success']:.1%}, final "
        f"{last['success_mean']:.1%} at {last['elapsed_s'] / 60:.1f} min"
    )


def cmd_eval(args: argparse.Namespace) -> int:
    """Evaluate a policy file with numpy inference; optionally draw one episode."""
    if args.suite:
        if args.dynamics or args.sensors or args.arrival or args.track_filter:
            raise ConfigError(
                "eval --suite flies each family in its own world; --dynamics, --sensors, "
                "--track-filter and --arrival apply to --policy evaluations on a scenario (the "
                "suite's oracle labels are proved for the paper's vehicles)"
            )
        return cmd_eval_suite(args)
    if not args.policy:
        raise ConfigError("eval: give --policy NAME|PATH (or --suite NAME with --method/--policy)")
    from remarl_fc.offline.evaluate import evaluate_policy, plot_episode, world_overrides
    from remarl_fc.policy_io import load_policy

    episodes = args.episodes or DEFAULT_EVAL_EPISODES
    track_filter = None if args.track_filter is None else args.track_filter == "on"
    world = world_overrides(args.dynamics, args.sensors, args.arrival, track_filter)
    shield = shield_from_args(args, load_policy(args.policy).sees_neighbours)
    policy, result = evaluate_policy(args.policy, args.scenario, episodes, args.seed, world, shield)
    result["shield_settings"] = dataclasses.asdict(shield)  # as eval --suite records them
    if args.plot:
        plot_episode(policy, args.scenario, args.seed, Path(args.plot), world)
        result["plot"] = args.plot
    human = (
        f"{result['scenario']} ({result['dynamics']}"
        f"{' randomised' if result['dynamics_randomised'] else ''}, {result['sensors']} "
        f"sensing{', tracks filtered' if result['track_filter'] else ''}, arrived UAVs "
        f"{result['arrival']}), {int(result['episodes'])} episodes: success "
        f"{result['success_rate']:.1%}, collisions {result['collision_rate']:.1%} "
        f"(U2O {result['collision_rate_u2o']:.1%}, U2U {result['collision_rate_u2u']:.1%}), "
        f"min d_U2O {result['min_d_u2o_m']:.1f} m, min d_U2U {result['min_d_u2u_m']:.1f} m, "
        f"energy {result['energy_rad']:.2f} rad, path ratio {result['path_length_ratio']:.3f}, "
        f"swarming return {result['swarming_return']:.1f}, reaction time "
        f"{result['reaction_time_median_ms'] * 1e3:.0f} µs median "
        f"({result['reaction_time_p99_ms'] * 1e3:.0f} µs p99)"
    )
    emit(args, result, human)
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """Write a policy file from a training run folder (or add a checksum to an old one)."""
    from policies.export import export_policy, rehash_policy

    if args.rehash:
        done = rehash_policy(Path(args.rehash))
        what = "added a checksum to" if done.written else "already signed:"
        payload = {"file": args.rehash, "checksum": done.checksum, "written": done.written}
        emit(args, payload, f"{what} {args.rehash} ({done.checksum})")
        return 0
    if not args.run or not args.out:
        raise ConfigError("export: give the run folder and --out FILE (or --rehash FILE)")
    run = Path(args.run)
    if not (run / "config.json").is_file():
        raise ConfigError(f"{run}: not a training run folder (no config.json); pass --out of train")
    metrics = json.loads(Path(args.metrics).read_text()) if args.metrics else None
    if "generalist" in json.loads((run / "config.json").read_text()):
        from policies.generalist_train import export_generalist_run

        meta = export_generalist_run(
            run, Path(args.out), checkpoint=args.checkpoint, metrics=metrics
        )
        emit(args, {"out": args.out, **meta}, f"wrote {args.out} (generalist)")
        return 0
    meta = export_policy(run, Path(args.out), checkpoint=args.checkpoint, metrics=metrics)
    emit(args, {"out": args.out, **meta}, f"wrote {args.out} ({meta['scenario']})")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    """Run the comparison grid (resumable) and write its reports; exit 130 on Ctrl-C."""
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
        return EXIT_INTERRUPTED
    paths = write_reports(cfg, results)
    payload = {"cells": len(results), "out": str(out), **paths}
    emit(args, payload, "\n".join(f"wrote {p}" for p in paths.values()))
    return 0
