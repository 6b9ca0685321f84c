"""Every shipped zoo policy loads, matches its scenario and carries its evaluation."""

import json

import numpy as np
import pytest

from remarl_fc.policy_io import load_policy, zoo_dir, zoo_names
from sim.scenarios import load_scenario, scenario_names

GENERALISTS = [n for n in zoo_names() if load_policy(n).generalist]
"""The zoo's generalists: one policy for any swarm, evaluated on the encounter suite."""


@pytest.mark.parametrize("name", [n for n in zoo_names() if n not in GENERALISTS])
def test_zoo_policy_loads_and_matches_its_scenario(name):
    policy = load_policy(name)
    assert policy.meta["scenario"] == name
    cfg = load_scenario(name)
    policy.check_scenario(cfg)
    obs = np.zeros((cfg.uav.count, policy.layout.size), np.float32)
    assert policy.act(obs).shape == (cfg.uav.count,)
    report = json.loads((zoo_dir() / f"{name}.eval.json").read_text())
    assert report["episodes"] >= 1000
    assert report["success_rate"] == pytest.approx(policy.meta["metrics"]["success_rate"])


def test_zoo_names_are_scenarios():
    assert set(zoo_names()) - set(GENERALISTS) <= set(scenario_names())


@pytest.mark.parametrize("name", [*GENERALISTS, "robust/generalist", "own-separation/generalist"])
def test_a_zoo_generalist_flies_any_swarm_and_carries_its_suite_results(name):
    from sim.swarm import SwarmSim

    policy = load_policy(name)
    assert policy.uav_range == (1, 50)
    for scenario in ("2u1o", "7u2o", "50u8o"):
        cfg = load_scenario(scenario)
        policy.check_scenario(cfg)
        sim = SwarmSim(cfg, scored=False)
        state = sim.initial_state(np.random.default_rng(0), 1)
        actions = policy.act(sim.observe(state, layout=policy.layout).flat())
        assert actions.shape == (1, cfg.uav.count) and np.isfinite(actions).all()
    report = json.loads((zoo_dir() / f"{name}.eval.json").read_text())
    assert report["suite"] == "standard" and len(report["families"]) >= 38
    assert all(f["episodes"] >= 200 for f in report["families"].values())
    assert report["success_rate"] == pytest.approx(policy.meta["metrics"]["success_rate"])


@pytest.mark.parametrize("name", [*GENERALISTS, "robust/generalist", "own-separation/generalist"])
def test_a_zoo_generalists_suite_results_count_todays_solvable_episodes(name):
    """An eval file is flown against the oracle's current labels: a change to the oracle
    that moves a label leaves no eval file dividing by the episodes it used to prove."""
    from sim.suite import cached_labels, load_suite

    suite = load_suite("standard")
    report = json.loads((zoo_dir() / f"{name}.eval.json").read_text())
    for family, row in report["families"].items():
        labels = cached_labels(suite, suite.family(family), int(row["episodes"]))
        assert labels is not None, f"{family}: stale labels (remarl-fc suite label standard)"
        assert row["solvable_episodes"] == int(labels.sum()), family


def test_the_robust_generalist_carries_its_real_world_results():
    policy = load_policy("robust/generalist")
    report = json.loads((zoo_dir() / "robust" / "generalist.eval.json").read_text())
    flown = report["real_world"]["scenarios"]
    assert set(flown) == {"2u1o", "3u1o", "3u2o", "5u1o", "5u2o", "7u1o", "7u2o", "10u1o"}
    assert all(r["episodes"] >= 300 and "shielded" in r for r in flown.values())
    mean = np.mean([r["success_rate"] for r in flown.values()])
    assert mean == pytest.approx(report["real_world_success_rate"])
    assert mean == pytest.approx(policy.meta["metrics"]["real_world_success_rate"])
    assert report["training"]["teacher_truth"] is True  # what makes it the robust one


def test_the_own_separation_generalist_records_the_penalty_it_was_trained_with():
    policy = load_policy("own-separation/generalist")
    report = json.loads((zoo_dir() / "own-separation" / "generalist.eval.json").read_text())
    training = report["training"]
    assert training["dagger_separation_weight"] == 0.05 and training["dagger_separation_intruders"]
    assert training["init"] == "generalist" and training["teacher"] == "self-shield"
    assert report["collision_rate_u2u"] == pytest.approx(
        policy.meta["metrics"]["collision_rate_u2u"]
    )
    assert len(report["real_world"]["scenarios"]) == 8


def test_the_default_generalist_records_its_last_round_and_the_recipe_names_it():
    """The default is the round that charged its own view's separation, intruders over 10 s;
    its recipe records that round after the eighth, as tools/generalist_recipe.py runs it."""
    report = json.loads((zoo_dir() / "generalist.eval.json").read_text())
    training = report["training"]
    assert training["dagger_separation_weight"] == 0.1 and training["dagger_separation_intruders"]
    assert training["dagger_separation_intruder_horizon_s"] == 10.0
    assert training["teacher"] == "self-shield" and training["seed"] == 42
    assert "--own-separation 0.1 --own-separation-intruders" in report["recipe"]
    assert "--own-separation-intruder-horizon 10" in report["recipe"]


def test_the_default_generalist_records_its_fine_tune_on_the_pop_ups():
    """The default is that round fine-tuned on the oracle's labels of the late pop-ups: its eval
    file records the fine-tune after the round, and the recipe names the tool's command."""
    report = json.loads((zoo_dir() / "generalist.eval.json").read_text())
    (finetune,) = report["training"]["finetunes"]
    assert finetune["reward"] == "none (DAgger on oracle from generalist)"
    assert finetune["seed"] == 22 and report["checkpoint"] is None
    assert "tools/oracle_finetune.py --policy generalist --families 'pop-up-*'" in report["recipe"]
    assert "--teacher oracle --share 0.25 --minutes 20 --seed 22" in report["recipe"]


def test_the_robust_3u2o_policy_carries_the_world_it_was_trained_in():
    policy = load_policy("robust/3u2o")
    cfg = load_scenario(zoo_dir() / "robust" / "3u2o.toml")
    policy.check_scenario(cfg)
    trained = policy.meta["scenario_config"]
    assert trained["dynamics"] == cfg.dynamics == "arducopter"
    assert trained["dynamics_randomisation"]["profiles"] == ["arducopter", "px4"]
    assert trained["sensors"]["model"] == "adsb"
    report = json.loads((zoo_dir() / "robust" / "3u2o.eval.json").read_text())
    assert report["episodes"] >= 1000 and report["sensors"] == "adsb"
    assert report["success_rate"] == pytest.approx(policy.meta["metrics"]["success_rate"])


def test_zoo_subfolder_names_resolve_without_path_tricks():
    from remarl_fc.errors import PolicyError
    from remarl_fc.policy_io import resolve

    assert resolve("robust/3u2o") == zoo_dir() / "robust" / "3u2o.safetensors"
    with pytest.raises(PolicyError, match="no such policy file"):
        resolve("../zoo/3u2o")
