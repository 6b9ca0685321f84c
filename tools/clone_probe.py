"""How well can the generalist's network clone its teacher? Supervised steps alone, measured.

    OMP_NUM_THREADS=1 python tools/clone_probe.py [--sweeps 300] [--steps 16000] [--hidden 64]
        [--seed 11] [--teacher orca-shield|oracle] [--families 'dense-*,...']
        [--sensing-range 200] [--sensing-aperture 360] [--teacher-horizon 20]
        [--turn-weight 0] [--out clone.safetensors] [--json]

Flies the "orca-shield" teacher (ORCA through the shield, `policies.generalist_train
.teacher_actions`; or the oracle replanned at every step, ``--teacher oracle``) over the
training mixture of `remarl-fc train --generalist` (every family of
the standard and generalist-extra suites, a third in the real world) for ``--sweeps`` steps of
every world, with the same N(0, 0.1²) noise on its actions as the TD3 teacher phase, and keeps
every UAV's version-2 observation and the teacher's action there. The last fifth of the sweeps
is held out; a fresh actor of the shipped shape (`policies.generalist.SetNet`) takes
``--steps`` Adam steps (minibatches of 1,024, learning rate 10⁻³ then 3·10⁻⁴ for the second
half, the gradient norm clipped to 1: the DAgger phase's own step) of mean squared error on
the rest, each label weighted as DAgger weighs it with ``--turn-weight`` κ (1 + κ·|a_teacher −
a_goal|, `policies.generalist_dagger.label_weights`). Prints the held-out error, the labels'
variance (the error of an actor that says 0 everywhere) and, per family, the share of the
variance explained (R²) and the turn kept: how far the clone's actions depart from the
straight way to the target, over how far the teacher's do (1: it turns as much). With ``--out`` the
clone is exported as a generalist policy file, to fly it:
``remarl-fc eval --suite standard --policy clone.safetensors --json``.

It is what showed that the student's observation carries the teacher's avoidance of crossing
swarms, where every reinforcement-learning run had failed them (docs/MODEL.md §20).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from policies.config import GeneralistConfig
from policies.export import export_generalist
from policies.generalist import SetNet
from policies.generalist_dagger import clone_update, label_weights
from policies.generalist_train import (
    TEACHER_NOISE,
    advance_world,
    generalist_layout,
    make_worlds,
    teacher_actions,
    with_layout,
)
from policies.train import reward_upper_bound
from sim.config import STATE_TEACHERS
from sim.encounters import family_scenario
from sim.orca import goal_turn_rad
from sim.suite import load_suite

FLOAT_SETTINGS = (
    ("--sensing-range", "sensing_range_m", "metres the student sees (0: the scenarios' 100 m)"),
    (
        "--sensing-aperture",
        "sensing_aperture_deg",
        "degrees around its heading (0: the scenarios' 270)",
    ),
    (
        "--teacher-horizon",
        "teacher_horizon_s",
        "seconds the ORCA teacher looks ahead at intruders (10: ORCA's own)",
    ),
    (
        "--turn-weight",
        "dagger_turn_weight",
        "κ: each label weighs 1 + κ·|a_teacher − a_goal| (DAgger's dagger_turn_weight)",
    ),
)
"""The flags that set a `GeneralistConfig` float of the same default: (flag, setting, help)."""

BATCH = 1024
"""Labels per supervised step."""

TURN_FLOOR = 1e-3
"""Mean departure of the teacher from the straight way (normalised action) below which a
family has no turn to keep."""

HELD_OUT = 0.2
"""Share of the sweeps (the last ones) held out."""


def collect(cfg: GeneralistConfig, sweeps: int, families: str = "*") -> dict[str, Any]:
    """The teacher's flights: observations, its actions, the world and sweep of each row.

    ``families``: comma-separated patterns of the mixture's families to fly (all by default).
    """
    base = family_scenario(load_suite(cfg.suites[0]).families[0])
    layout = generalist_layout(cfg, base)
    rng = np.random.default_rng(cfg.seed)
    patterns = [p.strip() for p in families.split(",") if p.strip()]
    worlds = [
        w
        for w in make_worlds(cfg, layout, np.random.default_rng([cfg.seed, 1]))
        if any(fnmatch.fnmatchcase(w.family.name, p) for p in patterns)
    ]
    if not worlds:
        raise SystemExit(f"--families {families!r} names no family of the mixture")
    goal = reward_upper_bound(base, "remarl") / (1.0 - cfg.gamma)
    obs, labels, goals, world_of, sweep_of = [], [], [], [], []
    for sweep in range(sweeps):
        for k, world in enumerate(worlds):
            taught = teacher_actions(world, cfg.teacher, cfg.teacher_horizon_s)
            noisy = taught + rng.normal(0.0, TEACHER_NOISE, taught.shape)
            flown = np.clip(noisy, -1.0, 1.0).astype(np.float32)
            seen = world.obs
            straight = goal_turn_rad(world.state, world.cfg) / world.cfg.uav.max_turn_rad
            step, _ = advance_world(world, flown, cfg, goal, rng)
            obs.append(seen[step.acted])
            labels.append(taught[step.acted].astype(np.float32))
            goals.append(straight[step.acted].astype(np.float32))
            world_of.append(np.full(len(labels[-1]), k, np.int32))
            sweep_of.append(np.full(len(labels[-1]), sweep, np.int32))
    return {
        "layout": layout,
        "base": base,
        "names": [w.family.name for w in worlds],
        "obs": np.concatenate(obs),
        "label": np.concatenate(labels),
        "goal": np.concatenate(goals),
        "world": np.concatenate(world_of),
        "sweep": np.concatenate(sweep_of),
    }


def fit(
    data: dict[str, Any], hidden: int, steps: int, seed: int, clip: float, turn_weight: float
) -> tuple[SetNet, np.ndarray]:
    """Train a fresh actor on the kept sweeps (the DAgger phase's supervised step,
    `policies.generalist_dagger.clone_update`, its gradient norm clipped to ``clip``, the
    labels weighted by ``turn_weight``); returns it and its actions on the held-out rows."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    held = data["sweep"] >= np.quantile(data["sweep"], 1.0 - HELD_OUT)
    x_fit, y_fit = torch.from_numpy(data["obs"][~held]), torch.from_numpy(data["label"][~held])
    w_fit = torch.from_numpy(label_weights(data["label"][~held], data["goal"][~held], turn_weight))
    net = SetNet(data["layout"], hidden, critic=False)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    for step in range(steps):
        if step == steps // 2:
            for group in opt.param_groups:
                group["lr"] = 3e-4
        idx = torch.from_numpy(rng.integers(0, len(x_fit), BATCH))
        clone_update(net, opt, x_fit[idx], y_fit[idx], clip, w_fit[idx] if turn_weight else None)
    x_held = torch.from_numpy(data["obs"][held])
    with torch.no_grad():
        pred = torch.cat([net(x_held[i : i + 8192]) for i in range(0, len(x_held), 8192)])
    return net, pred.numpy()


def turn_kept(pred: np.ndarray, label: np.ndarray, straight: np.ndarray) -> float | None:
    """Mean |clone − straight| over mean |teacher − straight|: how much of the teacher's
    departure from the straight way to the target the clone keeps (None where the teacher
    departs by less than `TURN_FLOOR` on average: nothing to keep)."""
    taught = float(np.abs(label - straight).mean())
    return float(np.abs(pred - straight).mean()) / taught if taught >= TURN_FLOOR else None


def main() -> None:
    """Collect, fit, report (and export)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweeps", type=int, default=300, help="steps of every world flown")
    parser.add_argument("--steps", type=int, default=16_000, help="supervised steps")
    parser.add_argument("--hidden", type=int, default=GeneralistConfig.hidden)
    parser.add_argument(
        "--max-neighbours",
        type=int,
        default=GeneralistConfig.max_neighbours,
        help="k: neighbouring-UAV rows the student sees",
    )
    parser.add_argument("--seed", type=int, default=11, help="not the training runs' seeds")
    parser.add_argument(
        "--teacher",
        default="orca-shield",
        choices=list(STATE_TEACHERS),
        help="who flies",
    )
    parser.add_argument("--families", default="*", help="patterns of the families flown")
    for flag, setting, meaning in FLOAT_SETTINGS:
        default = getattr(GeneralistConfig, setting)
        parser.add_argument(flag, type=float, default=default, dest=setting, help=meaning)
    parser.add_argument("--out", type=Path, help="export the clone as a generalist policy file")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args()
    cfg = GeneralistConfig(
        teacher=args.teacher,
        seed=args.seed,
        hidden=args.hidden,
        max_neighbours=args.max_neighbours,
        sensing_range_m=args.sensing_range_m,
        sensing_aperture_deg=args.sensing_aperture_deg,
        teacher_horizon_s=args.teacher_horizon_s,
        dagger_turn_weight=args.dagger_turn_weight,
    )
    t0 = time.perf_counter()
    data = collect(cfg, args.sweeps, args.families)
    t1 = time.perf_counter()
    net, pred = fit(data, args.hidden, args.steps, args.seed, cfg.grad_clip, cfg.dagger_turn_weight)
    t2 = time.perf_counter()
    held = data["sweep"] >= np.quantile(data["sweep"], 1.0 - HELD_OUT)
    label, world, straight = data["label"][held], data["world"][held], data["goal"][held]
    err = (pred - label) ** 2
    families = {
        name: {
            "mse": float(err[world == k].mean()),
            "label_variance": float(label[world == k].var()),
            "r2": float(1.0 - err[world == k].mean() / max(label[world == k].var(), 1e-12)),
            "turn_kept": turn_kept(pred[world == k], label[world == k], straight[world == k]),
        }
        for k, name in enumerate(data["names"])
        if (world == k).any()
    }
    result = {
        "rows": len(data["label"]),
        "held_out_rows": int(held.sum()),
        "held_out_mse": float(err.mean()),
        "label_variance": float(label.var()),
        "hidden": args.hidden,
        "turn_weight": cfg.dagger_turn_weight,
        "steps": args.steps,
        "collect_s": t1 - t0,
        "fit_s": t2 - t1,
        "families": families,
    }
    if args.out is not None:
        export_generalist(
            args.out,
            net.state_dict(),
            None,
            base_cfg=with_layout(data["base"], data["layout"]),
            hidden=args.hidden,
            uav_range=(1, cfg.max_uavs),
            reward=f"none (a clone of {args.teacher}, turn weight {cfg.dagger_turn_weight:g})",
            training={"steps": args.steps, "seed": args.seed},
        )
        result["policy"] = str(args.out)
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"{result['rows']} labels ({result['held_out_rows']} held out), collected in "
        f"{result['collect_s']:.0f} s; {args.steps} steps of hidden {args.hidden} in "
        f"{result['fit_s']:.0f} s"
    )
    print(
        f"held-out MSE {result['held_out_mse']:.4f} against the labels' variance "
        f"{result['label_variance']:.4f} "
        f"(R² {1 - result['held_out_mse'] / result['label_variance']:.2f})"
    )
    for name, row in sorted(families.items(), key=lambda kv: kv[1]["r2"] or 0.0):
        print(
            f"  {name:24s} MSE {row['mse']:.4f}  "
            f"variance {row['label_variance']:.4f}  R² {row['r2']:.2f}  "
            "turn kept " + ("–" if row["turn_kept"] is None else f"{row['turn_kept']:.2f}")
        )


if __name__ == "__main__":
    main()
