"""Fine-tune a generalist by DAgger on a teacher's labels of chosen families (the oracle's).

The shipped generalist's last step (docs/MODEL.md §20, "Flying the route until something is
seen"; `tools/generalist_recipe.py` runs it):

    OMP_NUM_THREADS=1 python tools/oracle_finetune.py --policy ROUND.safetensors \
        --families 'pop-up-*' --teacher oracle --share 0.25 --minutes 20 --seed 22 \
        --out tuned.safetensors

First made to ask whether the oracle teaches the generalist what ORCA could not:

    OMP_NUM_THREADS=1 python tools/oracle_finetune.py [--policy generalist] [--minutes 60]
        [--families 'beyond-20u4o,dense-*,...'] [--teacher oracle|orca-shield|self-shield]
        [--moving] [--share 0.5] [--seed 13]
        --out tuned.safetensors [--json]

Starts from a generalist policy file (the shipped one by default) and runs DAgger (Ross,
Gordon & Bagnell 2011) on the training mixture of `remarl-fc train --generalist`: the student
flies every world (its own action plus N(0, 0.1²) noise, the DAgger phase's); in the worlds of
``--families`` the oracle replanned from the student's own state labels every UAV
(`sim.oracle.oracle_actions`, ORCA through the shield where it finds no plan: the "oracle"
teacher of `policies.generalist_train.teacher_actions`); in every other world the starting
policy labels its own states, an anchor that keeps what it flies well. After every step of
every world the actor takes supervised steps (the DAgger phase's `clone_update`, Adam 3·10⁻⁴)
on minibatches drawn half from the oracle's labels and half from the anchor's (``--share``: the
teacher's share). A copy is exported to ``--out`` every 15 minutes and at the end: fly it with
``remarl-fc eval --suite standard --policy tuned.safetensors --json``. Where the oracle finds
no plan, ORCA through the shield labels, looking as far ahead as a training run's teacher
(`GeneralistConfig.teacher_horizon_s`). ``--teacher orca-shield`` runs the same fine-tune
with ORCA through the shield labelling those families instead: the control, which tells the
oracle's labels from the fine-tune itself. ``--teacher self-shield`` labels with the starting
policy's own proposals through the safety shield (what it flies behind the shield; with
``--moving``, the student's proposals as it learns): the one-off measurement behind
``remarl-fc train --generalist --init POLICY --teacher self-shield``, which runs it as a
training run (docs/MODEL.md §20, "Distilling the shield"). The JSON's ``oracle_labels``,
``oracle_seconds`` and ``oracle_families`` are the teacher's, whichever ``--teacher`` labelled.

Why a tool and not `train --generalist --teacher oracle`: the oracle replanned at every step of
every world costs about 100 times ORCA through the shield (23 s against 0.23 s for one step of
the whole mixture on one core), so a DAgger phase of 30 minutes would take 4 iterations
instead of 80. Labelling only the families where the oracle flies far better than the student
(docs/MODEL.md §20), from a student that already flies the rest, is what one core affords.
"""

from __future__ import annotations

import argparse
import copy
import fnmatch
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from policies.config import GeneralistConfig
from policies.export import export_generalist
from policies.generalist import SetNet
from policies.generalist_dagger import Labels, clone_update
from policies.generalist_init import load_actor as load_generalist_actor
from policies.generalist_train import (
    TEACHER_NOISE,
    advance_world,
    generalist_layout,
    make_worlds,
    shielded,
    teacher_actions,
    with_layout,
)
from policies.train import reward_upper_bound
from remarl_fc.policy_io import load_policy
from sim.config import STATE_TEACHERS
from sim.encounters import family_scenario
from sim.suite import load_suite

HARD_FAMILIES = (
    "beyond-20u4o,crossing-20u,crossing-8u,crossing-12u,dense-3u,dense-6u,dense-10u,"
    "swarms-2x5,swarms-2x8,3u2o-fast-intruders,crossing-fast-5u,overtaken-*,random-formation-5u"
)
"""Where the oracle replanned at every step flies far better than the shipped generalist (the
suite's first 10–20 episodes of each: 90–100 % where the generalist flies 3–86 %), and one of
its steps costs under a second on one core (not the 30- and 50-UAV worlds, nor dense-20u)."""

BATCH = 1024
"""Labels per supervised step (by default half the teacher's, half the anchor's)."""

TEACHER_SHARE = 0.5
"""The teacher's share of each supervised step's labels, the rest the anchor's (``--share``)."""

UPDATES = 20
"""Supervised steps after each step of every world."""

LEARNING_RATE = 3e-4
"""Adam's, a fine-tune's: the DAgger phase's 10⁻³ is for a fresh actor."""

ROWS = 1_000_000
"""Labels kept of each kind (the oldest dropped first)."""

SELF_SHIELD = "self-shield"
"""The teacher that is the starting policy itself, its proposals through the safety shield
(`policies.generalist_train.shielded`): what the policy flies behind the shield, distilled."""

EXPORT_MINUTES = 15.0
"""Minutes between exports of the actor."""


def load_actor(name: str) -> tuple[SetNet, Any]:
    """The actor of a generalist policy file as a torch `SetNet`, and the loaded policy."""
    return load_generalist_actor(name), load_policy(name)


def act(net: SetNet, obs: np.ndarray) -> np.ndarray:
    """(B, N) the actor's actions on flat observations (B, N, D)."""
    with torch.no_grad():
        out: np.ndarray = net(torch.from_numpy(obs.reshape(-1, obs.shape[-1]))).numpy()
    return out.reshape(obs.shape[:-1])


def main() -> None:
    """Fine-tune, export, report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="generalist", help="the starting policy file")
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--families", default=HARD_FAMILIES, help="teacher-labelled (patterns)")
    parser.add_argument(
        "--teacher",
        default="oracle",
        choices=[*STATE_TEACHERS, SELF_SHIELD],
        help="who labels those families (orca-shield: the same fine-tune with the recipe's "
        "teacher, the control; self-shield: the starting policy through the safety shield)",
    )
    parser.add_argument(
        "--moving",
        action="store_true",
        help="self-shield: the proposals are the student's as it learns, not the start's",
    )
    parser.add_argument(
        "--share",
        type=float,
        default=TEACHER_SHARE,
        help="the teacher's share of each supervised step's labels (the rest the anchor's)",
    )
    parser.add_argument("--seed", type=int, default=13, help="not the training runs' seeds")
    parser.add_argument("--out", type=Path, required=True, help="the tuned policy file")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args()
    if not 0.0 < args.share <= 1.0:
        parser.error(f"--share {args.share}: give the teacher's share, over 0 and at most 1")
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    net, policy = load_actor(args.policy)
    anchor = copy.deepcopy(net)
    cfg = GeneralistConfig(  # the mixture seen as the policy sees it
        seed=args.seed,
        hidden=int(policy.meta["hidden"]),
        sensing_range_m=policy.layout.range_m,
        sensing_aperture_deg=math.degrees(policy.layout.aperture_rad),
    )
    base = family_scenario(load_suite(cfg.suites[0]).families[0])
    layout = generalist_layout(cfg, base)
    if layout != policy.layout:
        raise SystemExit(f"{args.policy}: its observation is not the mixture's ({layout})")
    goal = reward_upper_bound(base, "remarl") / (1.0 - cfg.gamma)
    worlds = make_worlds(cfg, layout, np.random.default_rng([args.seed, 1]))
    patterns = [p.strip() for p in args.families.split(",") if p.strip()]
    hard = [any(fnmatch.fnmatchcase(w.family.name, p) for p in patterns) for w in worlds]
    if not any(hard):
        raise SystemExit(f"--families {args.families!r} names no family of the mixture")
    taught_rows, own = Labels.create(ROWS, layout.size), Labels.create(ROWS, layout.size)
    opt = torch.optim.Adam(net.parameters(), lr=LEARNING_RATE)
    start = last_export = time.monotonic()
    label_s = 0.0
    sweeps = updates = 0
    episodes: dict[str, list[float]] = {}
    loss = 0.0

    def export() -> None:
        export_generalist(
            args.out,
            net.state_dict(),
            None,
            base_cfg=with_layout(base, layout),
            hidden=cfg.hidden,
            uav_range=(1, cfg.max_uavs),
            reward=f"none (DAgger on {args.teacher} from {args.policy})",
            training={"steps": updates, "seed": args.seed},
        )

    while time.monotonic() - start < 60.0 * args.minutes:
        for world, by_teacher in zip(worlds, hard, strict=True):
            obs = world.obs
            student = act(net, obs)
            t0 = time.perf_counter()
            taught = act(anchor, obs)
            if by_teacher and args.teacher == SELF_SHIELD:
                proposed = student if args.moving else taught
                taught = shielded(world.state, world.cfg, proposed)
            elif by_teacher:
                taught = teacher_actions(world, args.teacher, cfg.teacher_horizon_s)
            label_s += time.perf_counter() - t0 if by_teacher else 0.0
            noise = rng.normal(0.0, TEACHER_NOISE, student.shape)
            flown = np.clip(student + noise, -1.0, 1.0).astype(np.float32)
            step, ended = advance_world(world, flown, cfg, goal, rng)
            kept = taught[step.acted].astype(np.float32)
            (taught_rows if by_teacher else own).add(obs[step.acted], kept, np.ones_like(kept))
            for row in ended:
                episodes.setdefault(world.family.name, []).append(float(row["success"]))
        sweeps += 1
        for _ in range(UPDATES):
            # every family taught: no anchor rows
            half = round(BATCH * args.share) if own.count else BATCH
            x1, y1, _ = taught_rows.sample(half, rng)
            x2, y2, _ = own.sample(BATCH - half, rng) if own.count else (x1[:0], y1[:0], None)
            x = torch.from_numpy(np.concatenate([x1, x2]))
            y = torch.from_numpy(np.concatenate([y1, y2]))
            loss = clone_update(net, opt, x, y, cfg.grad_clip)
            updates += 1
        if time.monotonic() - last_export >= 60.0 * EXPORT_MINUTES:
            export()
            last_export = time.monotonic()
            print(
                json.dumps({"minutes": (last_export - start) / 60, "sweeps": sweeps}),
                flush=True,
            )
    export()
    result = {
        "policy": str(args.out),
        "from": args.policy,
        "teacher": args.teacher,
        "minutes": (time.monotonic() - start) / 60.0,
        "sweeps": sweeps,
        "updates": updates,
        "oracle_labels": taught_rows.count,
        "anchor_labels": own.count,
        "oracle_seconds": label_s,
        "last_loss": loss,
        "oracle_families": [w.family.name for w, h in zip(worlds, hard, strict=True) if h],
        "flown_success": {k: float(np.mean(v)) for k, v in sorted(episodes.items())},
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(
        f"{sweeps} steps of every world in {result['minutes']:.0f} min ({label_s:.0f} s of "
        f"teacher), {updates} supervised steps; {taught_rows.count} teacher labels, {own.count} "
        f"anchor labels; last loss {loss:.4f}; wrote {args.out}"
    )


if __name__ == "__main__":
    main()
