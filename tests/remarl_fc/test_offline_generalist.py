"""The offline evaluation flies a generalist with its own observation layout (version 2) on
scenarios of version 1, building each step's observations once; zoo policies and hand-written
methods observe as before."""

from __future__ import annotations

import numpy as np
import pytest
from tiny_policy import write_tiny_generalist

from remarl_fc.offline.evaluate import RecordingAct, evaluate_policy
from remarl_fc.offline.rollout import PolicyFileAct, observe_for, policy_by_name
from remarl_fc.offline.suite import MethodSpec, fly_episodes, reaction_time, resolve_method
from remarl_fc.policy_io import load_policy
from sim.encounters import sample_family
from sim.scenarios import load_scenario
from sim.suite import load_suite
from sim.swarm import SwarmSim


@pytest.fixture(scope="module")
def generalist_path(tmp_path_factory):
    return write_tiny_generalist(tmp_path_factory.mktemp("g") / "g.safetensors", uavs=(1, 8))


def test_only_a_generalist_brings_its_own_layout(generalist_path):
    assert PolicyFileAct(load_policy("3u2o")).layout is None
    policy = load_policy(generalist_path)
    assert PolicyFileAct(policy).layout == policy.layout
    cfg = load_scenario("3u2o")
    sim = SwarmSim(cfg, scored=False)
    state = sim.initial_state(np.random.default_rng(0), 2)
    np.testing.assert_array_equal(
        observe_for(sim, state, policy_by_name("orca")), sim.observe(state).flat()
    )
    assert observe_for(sim, state, PolicyFileAct(policy)).shape == (2, 3, policy.layout.size)


def test_the_suite_flies_a_generalist_with_its_layout(generalist_path):
    suite = load_suite("smoke")
    family = suite.family("paper-3u2o")
    cfg, batch = sample_family(family, suite.seed, range(2))
    act, note = resolve_method(MethodSpec("policy", str(generalist_path)), family, cfg)
    assert isinstance(act, PolicyFileAct) and note == str(generalist_path)
    rows = fly_episodes(cfg, batch, act).rows
    policy, sim = load_policy(generalist_path), SwarmSim(cfg, scored=False)

    def rebuilt(obs, state, c):  # no layout: handed the scenario's observations, rebuilds its own
        return policy.act(sim.observe(state, layout=policy.layout).flat())

    expected = fly_episodes(cfg, batch, rebuilt).rows
    assert len(rows) == 2
    for got, want in zip(rows, expected, strict=True):
        assert got.keys() == want.keys()
        for key in got:
            np.testing.assert_array_equal(got[key], want[key])
    timing = reaction_time(cfg, batch.take(slice(0, 1)), act)
    assert timing["reaction_time_median_ms"] > 0


def test_evaluate_policy_flies_a_generalist_on_a_version_1_scenario(generalist_path):
    policy, result = evaluate_policy(str(generalist_path), "5u2o", 3, seed=0)
    assert policy.generalist and result["scenario"] == "5u2o" and result["uavs"] == 5
    assert result["episodes"] == 3 and 0.0 <= result["success_rate"] <= 1.0
    assert result["reaction_time_median_ms"] > 0


def test_the_recording_act_observes_a_generalists_layout(generalist_path):
    policy = load_policy(generalist_path)
    cfg = load_scenario("3u2o")
    act = RecordingAct(policy, cfg)
    assert act.uses_state
    sim = SwarmSim(cfg, scored=False)
    state = sim.initial_state(np.random.default_rng(1), 2)
    v1 = sim.observe(state).flat()
    actions = act(v1, state)
    np.testing.assert_array_equal(
        actions, policy.act(sim.observe(state, layout=policy.layout).flat())
    )
    assert act.seen[0].shape == (3, policy.layout.size)
    zoo = RecordingAct(load_policy("3u2o"), cfg)
    assert not zoo.uses_state
    np.testing.assert_array_equal(zoo(v1), load_policy("3u2o").act(v1))
