"""Would telling each UAV what its neighbours are about to do let it copy the shield? Measured.

    OMP_NUM_THREADS=1 python tools/intent_probe.py [--policy generalist]
        [--families 'beyond-50u8o,dense-10u,...'] [--episodes 30] [--steps 4000]
        [--variants heading,proposal,last-turn] [--safe-set-weight 0] [--seed 0] [--json]

The "self-shield" teacher of `remarl-fc train --generalist` labels each state with the policy's
own proposals through the safety shield. The shield decides on every neighbour's proposal for
this very step, which no observation holds: a neighbour row's Δψ is the heading the neighbour is
commanded to fly, and in the simulator that is the heading it flies. This tool asks whether that
missing piece is why the student copies the shield's interventions so poorly (docs/MODEL.md §20,
"What the neighbours are about to do").

The policy flies ``--episodes`` episodes of each family of the standard suite (episodes 1000
onward, never the suite's own), deterministically, as a DAgger round's student does when it
flies alone; at every state the teacher labels every flying UAV. Each row is kept with one
observation per ``--variants`` entry, which differ only in the neighbours' Δψ:

- ``heading``: the heading each neighbour flies (what the student sees today);
- ``proposal``: the heading each neighbour's proposal for this step turns it to (what a
  controller deciding twice, or a bus carrying each UAV's decision, could show);
- ``last-turn``: the heading each neighbour's last turn, repeated, would take it to.

The episodes are split four fifths to one fifth, whole episodes each. For each variant a copy of
the policy's actor takes ``--steps`` Adam steps (3·10⁻⁴, minibatches of 1,024, gradient norm
clipped to 1: a DAgger round's own step) of squared error on the four fifths. Printed: the
error on the held-out fifth before and after, over all rows and over the rows where the teacher
changed the policy's proposal by more than `INTERVENED` (the interventions), for each variant.
If a variant's held-out error on the interventions falls well below the others', that variant's
message is worth adding to the observation. Also printed, for the held-out interventions: how
the fitted actor moved from the proposal (toward the label's side in what share, how far along
the way) and in what share it landed in the shield's safe set (the candidate heading nearest its
action passes: `sim.shield.ShieldDecision.safe_headings`). ``--safe-set-weight W`` fits those
sets instead of the labels where the shield intervened, as ``remarl-fc train --generalist
--safe-set-weight W`` does (`policies.generalist_dagger.safe_set_error`).
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np
import torch

from policies.generalist import SetNet
from policies.generalist_dagger import safe_set_error
from policies.generalist_init import load_actor
from policies.generalist_train import shielded_sets, teacher_vehicle
from remarl_fc.offline.suite import MethodSpec, resolve_method
from sim.encounters import sample_family
from sim.shield import nearest_candidate
from sim.suite import load_suite
from sim.swarm import SwarmSim

FAMILIES = (
    "beyond-50u8o,dense-10u,swarms-2x5,crossing-20u,crossing-50u,beyond-20u4o,swarms-2x3,"
    "dense-3u,random-paths-7u,crossing-fast-5u"
)
"""The default families: the crowded ones below the issue's bar, and a few smaller ones."""

VARIANTS = ("heading", "proposal", "last-turn")
"""What a neighbour row's Δψ may say (the module docstring)."""

FIRST_EPISODE = 1000
"""The first episode drawn of each family: past the suite's own (it evaluates 0–199)."""

INTERVENED = 0.1
"""A row is an intervention where the label departs from the proposal by more than this
(normalised heading change, on [−1, 1])."""

HELD_OUT = 0.2
"""The share of episodes held out."""

BATCH = 1024
LEARNING_RATE = 3e-4
CLIP = 1.0


def collect(policy: str, families: list[str], episodes: int) -> dict[str, Any]:
    """Fly and label (the module docstring): every variant's observations, labels, proposals.

    Returns arrays of one row per flying UAV and state: ``obs`` {variant: (R, D)}, ``label``,
    ``proposal`` (R,), ``episode`` (R,) a global episode number.
    """
    suite = load_suite("standard")
    out: dict[str, Any] = {"obs": {v: [] for v in VARIANTS}, "label": [], "proposal": []}
    out["safe"] = []
    out["episode"] = []
    for k, name in enumerate(families):
        family = suite.family(name)
        cfg, batch = sample_family(
            family, suite.seed, range(FIRST_EPISODE, FIRST_EPISODE + episodes)
        )
        act, _ = resolve_method(MethodSpec.from_label(f"policy:{policy}"), family, cfg)
        if act is None:
            raise SystemExit(f"intent_probe: {policy} does not fly {name}")
        layout = act.layout  # type: ignore[attr-defined]
        sim = SwarmSim(cfg, scored=False)
        rng = np.random.default_rng(0)  # unused when unscored
        state = sim.start(batch, rng)
        vehicle = teacher_vehicle(cfg)
        a_max = cfg.uav.max_turn_rad
        running = np.ones(episodes, dtype=bool)
        for _ in range(cfg.max_steps):
            seen = sim.observe(state, layout=layout).flat()
            proposal = np.clip(np.asarray(act(seen, state, cfg), np.float32), -1.0, 1.0)
            taught = shielded_sets(state, cfg, proposal, vehicle, "proposals")
            label, safe = taught[..., 0], taught[..., 1:] > 0.5
            told = {
                "heading": seen,
                "proposal": sim.observe(
                    state, layout=layout, commanded_heading_rad=state.heading_rad + proposal * a_max
                ).flat(),
                "last-turn": sim.observe(
                    state,
                    layout=layout,
                    commanded_heading_rad=state.heading_rad + state.last_turn_rad,
                ).flat(),
            }
            rows = state.active & running[:, None]
            for v in VARIANTS:
                out["obs"][v].append(told[v][rows])
            out["label"].append(label[rows])
            out["safe"].append(safe[rows])
            out["proposal"].append(proposal[rows])
            ids = k * episodes + np.arange(episodes)
            out["episode"].append(np.broadcast_to(ids[:, None], rows.shape)[rows])
            state, result = sim.step(state, proposal, rng)
            running &= ~(result.terminated | result.truncated)
            if not running.any():
                break
    return {
        "obs": {v: np.concatenate(rows) for v, rows in out["obs"].items()},
        **{key: np.concatenate(out[key]) for key in ("label", "proposal", "episode", "safe")},
    }


def actions_of(actor: SetNet, obs: torch.Tensor) -> torch.Tensor:
    """``actor``'s actions on every row, in chunks."""
    with torch.no_grad():
        return torch.cat([actor(obs[i : i + 8192]) for i in range(0, len(obs), 8192)])


def errors(
    action: torch.Tensor, label: torch.Tensor, rows: dict[str, torch.Tensor]
) -> dict[str, float]:
    """Mean squared error of ``action`` on each named set of rows."""
    error = (action - label) ** 2
    return {name: float(error[mask].mean()) for name, mask in rows.items()}


def landed_safe(action: torch.Tensor, safe: torch.Tensor) -> float:
    """The share of rows whose action lies nearest a candidate heading of its safe set (K)."""
    nearest = torch.from_numpy(nearest_candidate(action.numpy(), safe.shape[-1]))
    return float(safe.gather(1, nearest[:, None])[:, 0].float().mean())


def toward(action: torch.Tensor, label: torch.Tensor, proposal: torch.Tensor) -> dict[str, float]:
    """On some rows, how the fitted actor moved from the proposal relative to the teacher.

    "toward": the share of rows where it moved to the label's side of the proposal (0.5 is a
    coin's); "of the way": its mean move along the label's direction over the label's mean
    distance from the proposal (1: all the way on average, 0: not at all).
    """
    moved, wanted = action - proposal, label - proposal
    return {
        "toward": float(((moved * wanted) > 0).float().mean()),
        "of the way": float((moved * wanted.sign()).mean() / wanted.abs().mean().clamp_min(1e-12)),
    }


def probe(
    policy: str,
    data: dict[str, Any],
    variants: list[str],
    steps: int,
    seed: int,
    safe_set_weight: float = 0.0,
) -> dict[str, Any]:
    """Fit a copy of the actor per variant on the kept episodes; the errors before and after.

    ``safe_set_weight`` > 0: where the teacher intervened and some heading passes, the fit is
    to the nearest heading of the set, at that weight (a round's ``--safe-set-weight``).
    """
    rng = np.random.default_rng(seed)
    episodes = np.unique(data["episode"])
    held = rng.choice(episodes, max(1, round(HELD_OUT * len(episodes))), replace=False)
    val = torch.from_numpy(np.isin(data["episode"], held))
    label = torch.from_numpy(data["label"]).float()
    proposal = torch.from_numpy(data["proposal"]).float()
    safe = torch.from_numpy(data["safe"])
    has_set = safe.any(dim=-1)
    intervened = torch.from_numpy(np.abs(data["label"] - data["proposal"]) > INTERVENED)
    rows = {
        "kept": ~val,
        "kept, interventions": ~val & intervened,
        "held out": val,
        "held out, interventions": val & intervened,
    }
    train = torch.from_numpy(np.flatnonzero(~val.numpy()))
    report: dict[str, Any] = {
        "rows": len(label),
        "episodes": len(episodes),
        "interventions": float(intervened.float().mean()),
        "variants": {},
    }
    for variant in variants:
        obs = torch.from_numpy(data["obs"][variant]).float()
        torch.manual_seed(seed)
        actor = load_actor(policy)
        opt = torch.optim.Adam(actor.parameters(), lr=LEARNING_RATE)
        before = errors(actions_of(actor, obs), label, rows)
        t0 = time.perf_counter()
        for _ in range(steps):
            idx = train[torch.randint(0, len(train), (BATCH,))]
            action = actor(obs[idx])
            error = (action - label[idx]) ** 2
            if safe_set_weight > 0:
                to_set = safe_set_weight * safe_set_error(action, safe[idx])
                error = torch.where(has_set[idx], to_set, error)
            loss = error.mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(list(actor.parameters()), CLIP)
            opt.step()
        fitted = actions_of(actor, obs)
        held_iv = rows["held out, interventions"]
        landed = held_iv & has_set
        moved = toward(fitted[held_iv], label[held_iv], proposal[held_iv])
        report["variants"][variant] = {
            "before": before,
            "after": errors(fitted, label, rows),
            "held-out interventions": moved | {"safe": landed_safe(fitted[landed], safe[landed])},
            "seconds": time.perf_counter() - t0,
        }
    return report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--policy", default="generalist", help="zoo name or policy file")
    parser.add_argument("--families", default=FAMILIES, help="comma-separated suite families")
    parser.add_argument("--episodes", type=int, default=30, help="episodes flown per family")
    parser.add_argument("--steps", type=int, default=4000, help="Adam steps per variant")
    parser.add_argument("--variants", default=",".join(VARIANTS), help=f"of {', '.join(VARIANTS)}")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--safe-set-weight",
        type=float,
        default=0.0,
        help="fit the shield's safe sets where it intervened, at this weight (default 0: labels)",
    )
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    args = parser.parse_args()
    variants = args.variants.split(",")
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        parser.error(f"--variants: unknown {', '.join(unknown)}; choose from {', '.join(VARIANTS)}")
    if args.episodes < 2 or args.steps < 1:
        parser.error("--episodes must be at least 2 and --steps at least 1")
    t0 = time.perf_counter()
    data = collect(args.policy, args.families.split(","), args.episodes)
    flying = time.perf_counter() - t0
    report = probe(args.policy, data, variants, args.steps, args.seed, args.safe_set_weight)
    report |= {"policy": args.policy, "families": args.families.split(","), "steps": args.steps}
    report["safe_set_weight"] = args.safe_set_weight
    report["flying_seconds"] = flying
    if args.json:
        print(json.dumps(report, indent=1))
        return
    print(
        f"{report['rows']:,} rows of {report['episodes']} episodes; the teacher intervenes on "
        f"{report['interventions']:.1%} (label off the proposal by more than {INTERVENED})"
    )
    print(
        "squared error, before → after fitting | kept: all, interventions | "
        "held out: all, interventions"
    )
    for variant, r in report["variants"].items():
        cells = " | ".join(
            f"{r['before'][k]:.4f} → {r['after'][k]:.4f}"
            for k in ("kept", "kept, interventions", "held out", "held out, interventions")
        )
        moved = r["held-out interventions"]
        print(
            f"{variant:10s} {cells} | held-out interventions: moved toward the label in "
            f"{moved['toward']:.0%}, {moved['of the way']:.0%} of the way; landed in the safe "
            f"set in {moved['safe']:.0%}"
        )


if __name__ == "__main__":
    main()
