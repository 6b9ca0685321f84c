"""Every shipped zoo policy loads, matches its scenario and carries its evaluation."""

import json

import numpy as np
import pytest

from remarl_fc.policy_io import load_policy, zoo_dir, zoo_names
from sim.scenarios import load_scenario, scenario_names


@pytest.mark.parametrize("name", zoo_names())
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
    assert set(zoo_names()) <= set(scenario_names())


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
