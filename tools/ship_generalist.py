"""Evaluate a generalist run on the standard suite and ship it to the zoo with its results.

    python tools/ship_generalist.py runs/generalist-s1 [--checkpoint best] [--workers 1]
        [--recipe "how the run's start was made, for a run started with --init"]
        [--name generalist | robust/generalist] [--real-world-episodes 300]

Exports the run's checkpoint to a temporary policy file, flies it on every family of the
standard suite with and without the safety shield (`remarl-fc eval --suite standard --policy
FILE --shield on`) and on the eight paper scenarios in the real world (`remarl-fc eval
--scenario S --dynamics arducopter --sensors adsb --arrival hover --shield on`, the episodes
flown without the shield too), writes ``policies/zoo/NAME.eval.json`` (per family: success
over all and over the solvable episodes, collisions, interventions; with and without the
shield; per real-world scenario: success and collisions, with and without the shield), and
exports ``policies/zoo/NAME.safetensors`` again with the suite means in its metadata.

    python tools/ship_generalist.py TUNED.safetensors [--base generalist] [--name generalist]
        [--recipe "the fine-tune's command"]

ships a policy file made outside a training run, a fine-tune of the zoo's ``--base`` generalist
(`tools/oracle_finetune.py`): flown as a run's export is, its eval file records the base's
training and recipe, then the fine-tune's (its policy file's ``reward`` and ``training``, last
in ``finetunes``, and ``--recipe``).

    python tools/ship_generalist.py --reshield [--name generalist] [--workers 2]

flies the shipped ``policies/zoo/NAME.safetensors`` again behind today's shield and rewrites
only what the shield decides in its eval file (every figure under ``shielded``, the
interventions, the shielded suite mean), after checking that the flights without the shield
repeat the recorded ones: the shield is not part of the policy, and a change to it leaves the
policy and the rest of its evaluation as shipped (its tensors bit for bit; the policy file's
metadata takes the new shielded suite mean, as its eval file does, and is signed again).

    python tools/ship_generalist.py --refly [--name generalist] [--workers 2]

flies the shipped policy again, with and without the shield, where the simulator changed what a
policy sees or does (not the policy): every figure of its eval file is rewritten, and the
figures its policy file carries (its tensors, training and recipe are kept).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import tempfile
from pathlib import Path
from typing import Any

from policies.export import remeasure_policy
from policies.generalist_train import export_generalist_run
from remarl_fc.offline.evaluate import REAL_WORLD_FLOWN, evaluate_policy, world_overrides
from remarl_fc.offline.suite import MethodSpec, evaluate_suite
from remarl_fc.policy_io import load_policy, zoo_dir
from sim.evaluation import evaluation_seed
from sim.heap import keep_freed_memory
from sim.shield import ShieldConfig
from sim.suite import Suite, load_suite

KEPT = (
    "uavs",
    "obstacles",
    "episodes",
    "solvable_episodes",
    "success_rate",
    "success_rate_solvable",
    "collision_rate_u2o",
    "collision_rate_u2u",
    "energy_rad",
    "intervention_rate",
    "reaction_time_median_ms",
)


def _mean(values: list[float]) -> float:
    finite = [v for v in values if v is not None and not math.isnan(v)]
    return sum(finite) / len(finite) if finite else math.nan


REAL_WORLD_KEPT = ("success_rate", "collision_rate_u2o", "collision_rate_u2u")
"""What the eval file keeps of each real-world scenario, with and without the shield."""

TRAINING_KEPT = (
    "learner",
    "suites",
    "minutes",
    "seed",
    "init",
    "teacher",
    "teacher_truth",
    "teacher_neighbours",
    "teacher_horizon_s",
    "real_share",
    "real_error_tau_s",
    "bc_weight",
    "bc_fraction",
    "dagger_fraction",
    "dagger_beta",
    "dagger_updates",
    "dagger_lr",
    "dagger_separation_weight",
    "dagger_separation_horizon_s",
    "dagger_separation_intruders",
    "dagger_separation_reciprocal",
    "dagger_separation_intruder_horizon_s",
    "dagger_separation_intruder_weight",
    "dagger_safe_set_weight",
    "dagger_safe_set_side",
    "hidden",
    "pooling",
    "family_weights",
    "swarm_field",
    "separation_horizon_s",
    "separation_weight",
    "ppo_min_std",
)
"""The run's settings the eval file records."""


def real_world(policy: Path, episodes: int, suite: Suite) -> dict[str, dict[str, Any]]:
    """Each paper scenario (the suite's paper-* families) flown in the real world, behind the
    shield and without it."""
    world = world_overrides(*REAL_WORLD_FLOWN)
    out: dict[str, dict[str, Any]] = {}
    for scenario in suite.paper_scenarios():
        _, r = evaluate_policy(
            str(policy), scenario, episodes, evaluation_seed(), world, ShieldConfig(mode="on")
        )
        out[scenario] = {k: r[f"{k}_unshielded"] for k in REAL_WORLD_KEPT} | {
            "episodes": r["episodes"],
            "shielded": {k: r[k] for k in REAL_WORLD_KEPT},
        }
    return out


SHIELDED_KEPT = (
    "success_rate",
    "success_rate_solvable",
    "collision_rate_u2o",
    "collision_rate_u2u",
)
"""What the eval file keeps of each family flown behind the shield."""


def shielded(result: dict[str, Any]) -> dict[str, Any]:
    """A family's figures behind the shield, from its row of `evaluate_suite`."""
    return {k: result[k] for k in SHIELDED_KEPT}


def family_rows(results: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The eval file's row of each family, alone and behind the shield (`evaluate_suite`'s)."""
    families: dict[str, dict[str, Any]] = {}
    for r in results:
        row = {k: r.get(k) for k in KEPT}
        row["success_rate"] = r["success_rate_unshielded"]
        row["success_rate_solvable"] = r["success_rate_solvable_unshielded"]
        row["collision_rate_u2o"] = r["collision_rate_u2o_unshielded"]
        row["collision_rate_u2u"] = r["collision_rate_u2u_unshielded"]
        row["shielded"] = shielded(r)
        families[r["family"]] = row
    return families


def suite_metrics(
    families: dict[str, dict[str, Any]], flown: dict[str, dict[str, Any]]
) -> dict[str, Any]:
    """The eval file's means (and the policy file's metadata): suite, shield, real world."""
    episodes = sum(f["episodes"] for f in families.values())
    u2u = sum(f["collision_rate_u2u"] * f["episodes"] for f in families.values()) / episodes
    metrics = {
        "success_rate": _mean([f["success_rate"] for f in families.values()]),
        "success_rate_solvable": _mean([f["success_rate_solvable"] for f in families.values()]),
        "collision_rate_u2u": u2u,
        "shielded_success_rate_solvable": _mean(
            [f["shielded"]["success_rate_solvable"] for f in families.values()]
        ),
    }
    if flown:
        metrics["real_world_success_rate"] = _mean([r["success_rate"] for r in flown.values()])
    return metrics


def _shipped_flown(
    name: str, workers: int
) -> tuple[Path, dict[str, Any], Path, list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """A shipped generalist's eval file (path, contents) and policy file, flown again as its
    eval file records: the suite with and without the shield (`evaluate_suite`'s rows), and
    the real world's scenarios with the episodes recorded (`real_world`; none if none)."""
    path = zoo_dir() / f"{name}.eval.json"
    report = json.loads(path.read_text())
    suite = load_suite(report["suite"])
    policy = zoo_dir() / f"{name}.safetensors"
    scenarios = report["real_world"]["scenarios"]
    episodes = int(next(iter(scenarios.values()))["episodes"]) if scenarios else 0
    results, flown = flown_on_suite(policy, suite, workers, episodes)
    return path, report, policy, results, flown


def refly(name: str, workers: int) -> dict[str, Any]:
    """`--refly`: every figure of a shipped generalist's eval file, flown again."""
    path, report, policy, results, flown = _shipped_flown(name, workers)
    families = family_rows(results)
    metrics = suite_metrics(families, flown)
    report.update(metrics)
    report["families"] = families
    report["real_world"]["scenarios"] = flown
    path.write_text(json.dumps(report, indent=2, default=float) + "\n")
    remeasure_policy(policy, metrics)  # the file carries its suite's figures, as shipped
    return metrics


def reshield(name: str, workers: int) -> dict[str, Any]:
    """`--reshield`: the shielded figures of a shipped generalist's eval file, flown again, and
    the one its policy file carries."""
    path, report, policy, results, real = _shipped_flown(name, workers)
    for r in results:
        row = report["families"][r["family"]]
        if r["success_rate_unshielded"] != row["success_rate"]:
            raise SystemExit(
                f"{r['family']}: without the shield {r['success_rate_unshielded']} where the eval "
                f"file records {row['success_rate']}: the policy or the simulator changed since "
                "it shipped; ship it again (python tools/ship_generalist.py RUN) instead"
            )
        row["intervention_rate"] = r["intervention_rate"]
        row["shielded"] = shielded(r)
    families = report["families"].values()
    report["shielded_success_rate_solvable"] = _mean(
        [f["shielded"]["success_rate_solvable"] for f in families]
    )
    scenarios = report["real_world"]["scenarios"]
    for scenario, flown in real.items():
        if flown["success_rate"] != scenarios[scenario]["success_rate"]:
            raise SystemExit(
                f"{scenario} in the real world: without the shield {flown['success_rate']} "
                f"where the eval file records {scenarios[scenario]['success_rate']}; ship "
                "it again instead"
            )
        scenarios[scenario]["shielded"] = flown["shielded"]
    path.write_text(json.dumps(report, indent=2, default=float) + "\n")
    remeasure_policy(policy, suite_metrics(report["families"], scenarios))
    return {
        "shielded_success_rate_solvable": report["shielded_success_rate_solvable"],
        "shielded_collision_rate_u2u": _mean(
            [f["shielded"]["collision_rate_u2u"] for f in families]
        ),
        "real_world_shielded": _mean([r["shielded"]["success_rate"] for r in scenarios.values()]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "run",
        nargs="?",
        help="the --out folder of remarl-fc train --generalist, or a policy file tuned from the "
        "zoo's --base (tools/oracle_finetune.py)",
    )
    parser.add_argument(
        "--base",
        default="generalist",
        help="a policy file's: the zoo generalist it was tuned from (its training and recipe "
        "are recorded before the fine-tune's)",
    )
    parser.add_argument(
        "--reshield",
        action="store_true",
        help="fly the shipped NAME again behind today's shield and rewrite only the shielded "
        "figures of its eval file (no run)",
    )
    parser.add_argument(
        "--refly",
        action="store_true",
        help="fly the shipped NAME again, with and without the shield, and rewrite every figure "
        "of its eval file (no run): after a change to what the simulator shows a policy",
    )
    parser.add_argument("--checkpoint", default="best", choices=["best", "last"])
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument(
        "--recipe",
        default=None,
        help="the commands behind the run, recorded with its results (a run started with "
        "--init records only its last step)",
    )
    parser.add_argument(
        "--name", default="generalist", help="the zoo name it ships as (default generalist)"
    )
    parser.add_argument(
        "--real-world-episodes",
        type=int,
        default=300,
        help="episodes of each paper scenario in the real world (0: none)",
    )
    args = parser.parse_args()
    keep_freed_memory()
    if args.reshield and args.refly:
        parser.error("--reshield flies the shield again, --refly everything: give one")
    if args.reshield or args.refly:
        again = reshield if args.reshield else refly
        print(json.dumps(again(args.name, args.workers), indent=2))
        return
    if args.run is None:
        parser.error("a run folder or a policy file is required (or --reshield, --refly)")
    run = Path(args.run)
    suite = load_suite("standard")
    out = zoo_dir() / args.name
    if run.is_file():  # a policy file made outside a run: a fine-tune
        base = zoo_dir() / f"{args.base}.eval.json"
        if not base.is_file():
            parser.error(
                f"--base {args.base}: no {base.name} in the zoo to record it as tuned from"
            )
        metrics = ship_tuned(run, json.loads(base.read_text()), out, suite, args)
        print(json.dumps(metrics, indent=2))
        return
    with tempfile.TemporaryDirectory() as tmp:
        policy = Path(tmp) / "generalist.safetensors"
        export_generalist_run(run, policy, checkpoint=args.checkpoint)
        results, flown = flown_on_suite(policy, suite, args.workers, args.real_world_episodes)
    raw = run / f"suite-{args.checkpoint}.json"  # kept beside the run, whatever happens next
    raw.write_text(json.dumps({"results": results}, indent=1, default=float))
    config = json.loads((run / "config.json").read_text())["generalist"]
    # a key a run's config.json predates: not recorded (None), since defaults change (the
    # teacher and DAgger became the default after the first runs)
    training = {k: config.get(k) for k in TRAINING_KEPT}
    metrics = write_report(out, suite, args.checkpoint, args.recipe, training, results, flown)
    export_generalist_run(
        run, out.with_suffix(".safetensors"), checkpoint=args.checkpoint, metrics=metrics
    )
    print(json.dumps(metrics, indent=2))


def ship_tuned(
    tuned: Path, base: dict[str, Any], out: Path, suite: Suite, args: argparse.Namespace
) -> dict[str, Any]:
    """A policy file tuned from the zoo generalist whose eval file is ``base``, flown and
    shipped as ``out``: its eval file records the base's training and recipe, then this
    fine-tune (last in ``finetunes``); the zoo copy carries its figures. Returns its means."""
    results, flown = flown_on_suite(tuned, suite, args.workers, args.real_world_episodes)
    meta = load_policy(str(tuned)).meta
    done = [*base["training"].get("finetunes", []), {"reward": meta["reward"], **meta["training"]}]
    training = {**base["training"], "finetunes": done}
    recipe = f"{base['recipe']}; then {args.recipe}" if args.recipe else base["recipe"]
    metrics = write_report(out, suite, None, recipe, training, results, flown)
    part = out.with_name(out.name + ".safetensors.part")
    shutil.copyfile(tuned, part)
    remeasure_policy(part, metrics)  # signed again, with the figures it flew
    part.replace(out.with_suffix(".safetensors"))
    return metrics


def flown_on_suite(
    policy: Path, suite: Suite, workers: int, episodes: int
) -> tuple[list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """A policy file on every family of the suite, with and without the shield, and in the real
    world (``episodes`` of each paper scenario; none: 0)."""
    results = evaluate_suite(
        suite, [MethodSpec("policy", str(policy))], workers=workers, shield=ShieldConfig(mode="on")
    )
    return results, real_world(policy, episodes, suite) if episodes else {}


def write_report(
    out: Path,
    suite: Suite,
    checkpoint: str | None,
    recipe: str | None,
    training: dict[str, Any],
    results: list[dict[str, Any]],
    flown: dict[str, dict[str, Any]],
) -> dict[str, Any]:
    """Write ``out``.eval.json (the zoo name ``out`` relative to the zoo); returns its means.

    ``checkpoint``: the run's checkpoint shipped (None: a policy file, not a run)."""
    families = family_rows(results)
    metrics = suite_metrics(families, flown)
    name = out.relative_to(zoo_dir()).as_posix()
    report = {
        "policy": f"{name} (policies/zoo/{name}.safetensors)",
        "suite": suite.name,
        "suite_version": suite.version,
        "seed": suite.seed,
        "checkpoint": checkpoint,
        "recipe": recipe,
        "training": training,
        **metrics,
        "families": families,
        "real_world": {
            "world": "fitted ArduCopter response, ADS-B intruders, GPS noise, arrived UAVs "
            "hover (remarl-fc eval --scenario S --dynamics arducopter --sensors adsb "
            "--arrival hover)",
            "seed": evaluation_seed(),
            "scenarios": flown,
        },
    }
    out.parent.mkdir(parents=True, exist_ok=True)  # a new zoo folder (robust/, …)
    path = out.with_suffix(".eval.json")
    part = path.with_name(path.name + ".part")
    part.write_text(json.dumps(report, indent=2, default=float) + "\n")
    part.replace(path)
    return metrics


if __name__ == "__main__":
    main()
