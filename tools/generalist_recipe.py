"""Train the shipped generalist's recipe end to end: the start, then its rounds behind the shield.

    python tools/generalist_recipe.py --out runs/recipe [--rollout-processes 1]
        [--round-minutes 13] [--start FILE] [--rounds K] [--dry-run]

The recipe (docs/MODEL.md §20): ``remarl-fc train --generalist --seed 2 --teacher-horizon 10``
for 60 minutes (DAgger on ORCA through the shield, then PPO), exported; then seven rounds of
DAgger whose teacher is the previous round's policy through the safety shield
(``--teacher self-shield --dagger-fraction 1 --dagger-lr 3e-4``), each from the previous
round's export, with the seeds of `ROUNDS` (the fifth flies the crowded families more often,
`CROWDED`; the seventh charges the separation the student's own view predicts, `OWN_VIEW`);
then 20 minutes of DAgger on the oracle's labels of the late pop-ups, the last round labelling
its own states everywhere else (``python tools/oracle_finetune.py``, `POP_UPS`). Every step is
a command, printed before it runs. On two cores (``--rollout-processes 1``) the whole recipe
takes about 173 wall minutes: 60 for the start, 7 × 13.25 for the rounds, 20.5 for the
fine-tune.

``--rollout-processes 1`` flies each round's rollouts in a second process while the first
learns (`policies.generalist_rollouts`): on a 2-core machine a round does in 13 minutes the
iterations a one-process round does in 20. ``--start FILE`` begins from a policy file instead
of training the start (the shipped recipe's start is the generalist of 2026-11-25).

Resumable: a step whose export exists is skipped; a round whose folder holds a checkpoint but
no export is resumed (the pop-up fine-tune is not resumable: it starts again). ``OUT/recipe.json``
records every step's command and wall minutes, and the whole recipe's; the last round's export
is ``OUT/round-7.safetensors``, the fine-tune's ``OUT/pop-ups.safetensors``, to be judged and
shipped with ``python tools/ship_generalist.py OUT/pop-ups.safetensors --base NAME`` once
``OUT/round-7`` is shipped as NAME (``python tools/ship_generalist.py OUT/round-7 --name NAME
--recipe "…"``).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

START = ("--seed", "2", "--teacher-horizon", "10", "--minutes", "60")
"""The start: DAgger on ORCA through the shield looking 10 s ahead, then PPO, 60 minutes."""

ROUND = ("--teacher", "self-shield", "--dagger-fraction", "1", "--dagger-lr", "3e-4")
"""Every round: DAgger alone on the previous policy's proposals through the shield."""

CROWDED = (
    "--family-weight",
    "beyond-50u8o=3",
    "--family-weight",
    "crossing-50u=3",
    "--family-weight",
    "dense-10u=3",
    "--family-weight",
    "crossing-20u=2",
    "--family-weight",
    "swarms-2x*=2",
    "--family-weight",
    "random-paths-*=2",
)
"""The fifth round's mixture: the crowded families two to three times as often."""

OWN_VIEW = (
    "--own-separation",
    "0.1",
    "--own-separation-intruders",
    "--own-separation-intruder-horizon",
    "10",
)
"""The last round's penalty: the separation its own observation predicts for the student's
action, to its neighbours over 4 s and to the intruders over 10 s (docs/MODEL.md §20)."""

ROUNDS: tuple[tuple[int, tuple[str, ...]], ...] = (
    (1, ()),
    (2, ()),
    (3, ()),
    (4, ()),
    (12, CROWDED),
    (14, ()),
    (42, OWN_VIEW),
)
"""(seed, extra flags) of each round, in order: the shipped chain's, less its fifth and sixth
plain rounds (seeds 6 and 8). Flown on two cores, the nine-round chain's third to ninth rounds
all flew the suite at 91.4–91.7 % (docs/MODEL.md §20, "The whole recipe, flown from nothing"):
two plain rounds fewer leave room in the three hours for the pop-up fine-tune."""

POP_UPS = (
    "--families",
    "pop-up-*",
    "--teacher",
    "oracle",
    "--share",
    "0.25",
    "--minutes",
    "20",
    "--seed",
    "22",
)
"""The last step: the oracle labels the pop-up families' states (until an intruder appears,
the route), a quarter of each supervised step's labels (docs/MODEL.md §20, "Flying the route
until something is seen")."""

FINE_TUNE = Path(__file__).with_name("oracle_finetune.py")
"""The tool that runs `POP_UPS`."""

ROUND_MINUTES = 20.0
"""A round's budget in one process (the shipped chain's)."""

FLEET_ROUND_MINUTES = 13.0
"""A round's budget with one rollout process on the 2-core machine: about the iterations of
a one-process round of `ROUND_MINUTES` (67 in 20 minutes; 54 in 10.5 with the process)."""


def remarl(*args: str) -> list[str]:
    """A ``remarl-fc`` command line, run by this interpreter."""
    return [sys.executable, "-m", "remarl_fc", *args]


def steps(
    out: Path, start: Path | None, processes: int, minutes: float
) -> list[tuple[str, list[list[str]], Path]]:
    """(name, commands, the policy file they leave) of every step of the recipe, in order."""
    plan: list[tuple[str, list[list[str]], Path]] = []
    if start is None:
        run, policy = out / "start", out / "start.safetensors"
        train = ["train", "--generalist", *START, "--out", str(run), "--json"]
        plan.append(
            ("start", [remarl(*train), remarl("export", str(run), "--out", str(policy))], policy)
        )
    else:
        policy = start
    fleet = ("--rollout-processes", str(processes)) if processes else ()
    for number, (seed, extra) in enumerate(ROUNDS, start=1):
        run, made = out / f"round-{number}", out / f"round-{number}.safetensors"
        resume = ("--resume",) if (run / "last.safetensors").is_file() else ()
        train = [
            "train",
            "--generalist",
            "--init",
            str(policy),
            *ROUND,
            "--minutes",
            f"{minutes:g}",
            "--seed",
            str(seed),
            *extra,
            *fleet,
            *resume,
            "--out",
            str(run),
            "--json",
        ]
        if resume:  # a resumed run keeps its settings: only the budget and processes may be said
            train = ["train", "--generalist", "--resume", *fleet, "--out", str(run), "--json"]
        plan.append(
            (
                f"round-{number}",
                [remarl(*train), remarl("export", str(run), "--out", str(made))],
                made,
            )
        )
        policy = made
    made = out / "pop-ups.safetensors"
    tune = [sys.executable, str(FINE_TUNE), "--policy", str(policy), *POP_UPS, "--out", str(made)]
    plan.append(("pop-ups", [[*tune, "--json"]], made))
    return plan


def shown(command: list[str]) -> str:
    """A step's command as a user types it."""
    if command[: len(remarl())] == remarl():
        return "remarl-fc " + shlex.join(command[len(remarl()) :])
    return f"OMP_NUM_THREADS=1 python tools/{Path(command[1]).name} " + shlex.join(command[2:])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--out", type=Path, required=True, help="folder of the runs and their exports")
    p.add_argument(
        "--rollout-processes",
        type=int,
        default=0,
        help="processes flying each round's rollouts (default 0; 1 on a 2-core machine)",
    )
    p.add_argument(
        "--round-minutes",
        type=float,
        help=f"a round's budget (default {ROUND_MINUTES:g}, or {FLEET_ROUND_MINUTES:g} with "
        "rollout processes)",
    )
    p.add_argument("--start", type=Path, help="a policy file to start the rounds from")
    p.add_argument(
        "--rounds",
        type=int,
        default=len(ROUNDS),
        help=f"the first K rounds only (default all {len(ROUNDS)}, then the pop-up fine-tune); "
        "more later go on from them",
    )
    p.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    args = p.parse_args(argv)
    if args.start is not None and not args.start.is_file():
        p.error(f"--start {args.start}: no such policy file")
    if args.rollout_processes < 0:
        p.error("--rollout-processes must be >= 0")
    if not 1 <= args.rounds <= len(ROUNDS):
        p.error(f"--rounds must be 1 to {len(ROUNDS)}")
    # one thread of numpy and torch per process: they would otherwise share the cores with
    # the rollout processes (and each other) and slow every round
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    minutes = args.round_minutes or (
        FLEET_ROUND_MINUTES if args.rollout_processes else ROUND_MINUTES
    )
    args.out.mkdir(parents=True, exist_ok=True)
    record_path = args.out / "recipe.json"
    record: dict[str, Any] = json.loads(record_path.read_text()) if record_path.is_file() else {}
    record.setdefault("steps", {})
    record["start"] = str(args.start) if args.start else "trained (60 minutes)"
    record["rollout_processes"], record["round_minutes"] = args.rollout_processes, minutes
    plan = steps(args.out, args.start, args.rollout_processes, minutes)
    # up to the last round asked for; after the last of all, the pop-up fine-tune
    last = "pop-ups" if args.rounds == len(ROUNDS) else f"round-{args.rounds}"
    upto = [name for name, _, _ in plan].index(last) + 1
    for name, commands, made in plan[:upto]:
        if made.is_file():
            print(f"{name}: {made} is there, skipped", flush=True)
            continue
        began = time.monotonic()
        for command in commands:
            print("$", shown(command), flush=True)
            if not args.dry_run:
                log = (args.out / f"{name}.log").open("a")
                with log:
                    done = subprocess.run(
                        command, stdout=log, stderr=subprocess.STDOUT, env=env, check=False
                    )
                if done.returncode != 0:
                    print(f"{name}: exit code {done.returncode}; see {args.out / f'{name}.log'}")
                    return done.returncode
        if args.dry_run:
            continue
        record["steps"][name] = {
            "commands": [shlex.join(c) for c in commands],
            "wall_minutes": round((time.monotonic() - began) / 60, 2),
        }
        record["wall_minutes"] = round(sum(s["wall_minutes"] for s in record["steps"].values()), 2)
        tmp = record_path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(record, indent=2))
        tmp.replace(record_path)
        print(f"{name}: {made} after {record['steps'][name]['wall_minutes']} minutes", flush=True)
    if not args.dry_run:
        print(f"recipe: {record.get('wall_minutes')} wall minutes in all; the policy: {made}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
