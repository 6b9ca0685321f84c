"""The offline evaluation's shield wrapper (`remarl_fc.offline.shielding.Shielded`)."""

from __future__ import annotations

import dataclasses

import numpy as np

import sim.shield
from remarl_fc.offline.shielding import Shielded
from sim.scenarios import load_scenario
from sim.shield import ShieldConfig, shield_state
from sim.swarm import SwarmSim


def test_it_shields_as_the_simulator_does_and_reads_each_scenarios_vehicle_once(monkeypatch):
    reads: list[str] = []
    load = sim.shield.load_profile
    monkeypatch.setattr(sim.shield, "load_profile", lambda name: reads.append(name) or load(name))
    cfg = load_scenario("3u2o")
    swarm = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(3)
    state = swarm.initial_state(rng, 4)
    proposals = [rng.uniform(-1, 1, state.heading_rad.shape) for _ in range(5)]
    shielded = Shielded(lambda obs, state, cfg: proposals.pop(), ShieldConfig(mode="on"))
    for _ in range(3):
        expected = proposals[-1]
        action, speed = shielded(np.zeros((4, 3, 1), np.float32), state, cfg)
        decision = shield_state(ShieldConfig(mode="on"), cfg, state, expected)
        np.testing.assert_array_equal(action, decision.action)
        np.testing.assert_array_equal(speed, decision.speed_m_s)
        state, _ = swarm.step(state, action, rng, speeds_m_s=speed)
    assert reads.count(cfg.dynamics) == 1 + 3  # once for the wrapper, once per direct call above
    other = dataclasses.replace(cfg, dynamics="arducopter")
    shielded(np.zeros((4, 3, 1), np.float32), state, other)
    assert reads[-1] == "arducopter"
