"""The offline evaluation's shield wrapper (`remarl_fc.offline.shielding.Shielded`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import remarl_fc.offline.shielding as shielding
import sim.shield
from remarl_fc.offline.shielding import Shielded
from sim.config import SensorConfig
from sim.encounters import sample_family
from sim.kinematics import wrap_angle
from sim.scenarios import load_scenario
from sim.shield import ShieldConfig, shield_state
from sim.suite import load_suite
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
    alone = ShieldConfig(mode="on", plan_steps=0)  # the shield's own decision, step by step
    shielded = Shielded(lambda obs, state, cfg: proposals.pop(), alone)
    for _ in range(3):
        expected = proposals[-1]
        action, speed = shielded(np.zeros((4, 3, 1), np.float32), state, cfg)
        decision = shield_state(alone, cfg, state, expected)
        np.testing.assert_array_equal(action, decision.action)
        np.testing.assert_array_equal(speed, decision.speed_m_s)
        state, _ = swarm.step(state, action, rng, speeds_m_s=speed)
    assert reads.count(cfg.dynamics) == 1 + 3  # once for the wrapper, once per direct call above
    other = dataclasses.replace(cfg, dynamics="arducopter")
    shielded(np.zeros((4, 3, 1), np.float32), state, other)
    assert reads[-1] == "arducopter"


def seek(obs, state, cfg):
    """Turn straight for the target: a controller that never avoids anything."""
    gap = state.target_m - state.pos_m
    error = wrap_angle(np.arctan2(gap[..., 1], gap[..., 0]) - state.heading_rad)
    return np.clip(error / cfg.uav.max_turn_rad, -1.0, 1.0).astype(np.float32)


def fly(cfg, batch, shielded):
    """Fly ``batch`` behind ``shielded`` to its end: (success, collided) per episode."""
    swarm, rng = SwarmSim(cfg, scored=False), np.random.default_rng(0)
    state = swarm.start(batch, rng)
    done = np.zeros(state.num_envs, dtype=bool)
    success, collided = done.copy(), done.copy()
    for _ in range(cfg.max_steps):
        action, speed = shielded(None, state, cfg)
        state, result = swarm.step(state, action, rng, speeds_m_s=speed)
        end = (result.terminated | result.truncated) & ~done
        success[end] = result.success[end]
        collided[end] = (result.collided_u2o | result.collided_u2u).any(axis=-1)[end]
        done |= end
        if done.all():
            break
    return success, collided


def test_the_swarm_planner_saves_a_swarm_the_shield_leaves_boxed_in():
    # dense-3u's first episode: behind the shield alone, no neighbour giving way, the
    # target-seeking swarm is boxed in between its own UAVs and the traffic, and collides; the
    # planner flies it through, and so does the shield alone where neighbours give way
    suite = load_suite("standard")
    family = next(f for f in suite.families if f.name == "dense-3u")
    cfg, batch = sample_family(family, suite.seed, range(1))
    alone = Shielded(seek, ShieldConfig(mode="on", plan_steps=0, give_way=0))
    success, collided = fly(cfg, batch, alone)
    assert collided.all() and not success.any()
    assert alone.planned == 0
    planner = Shielded(seek, ShieldConfig(mode="on", plan_steps=4, give_way=0))
    success, collided = fly(cfg, batch, planner)
    assert success.all() and not collided.any()
    report = planner.report()
    assert report["shield_planned"] > 0 and report["shield_plans"] > 0
    giving = Shielded(seek, ShieldConfig(mode="on", plan_steps=0))
    success, collided = fly(cfg, batch, giving)
    assert success.all() and not collided.any() and giving.planned == 0


@pytest.mark.parametrize("found", [True, False])
def test_where_the_planner_runs_neighbours_give_way_only_where_it_finds_no_plan(monkeypatch, found):
    calls: list[int] = []
    real, real_give_way = shielding.shield_state, shielding.give_way

    def spy(shield_cfg, cfg, state, proposed, vehicle=None):
        calls.append(shield_cfg.give_way)
        return real(shield_cfg, cfg, state, proposed, vehicle)

    def spy_give_way(shield_cfg, *args):
        calls.append(shield_cfg.give_way)
        return real_give_way(shield_cfg, *args)

    def planned(state, cfg, oracle=None, envs=None):
        e, n = len(envs), state.pos_m.shape[1]
        return np.zeros((e, 3, n), np.float32), np.full(e, found)

    monkeypatch.setattr(shielding, "shield_state", spy)
    monkeypatch.setattr(shielding, "give_way", spy_give_way)
    monkeypatch.setattr(shielding, "oracle_plan", planned)
    suite = load_suite("standard")
    family = next(f for f in suite.families if f.name == "dense-3u")
    cfg, batch = sample_family(family, suite.seed, range(1))
    shielded = Shielded(seek, ShieldConfig(mode="on", plan_steps=4, give_way=6))
    fly(cfg, batch, shielded)
    assert shielded.plans > 0
    assert calls[0] == 0  # the planner first: the shield decides without giving way
    assert (6 in calls) is not found  # and gives way only where no plan was found


class Stuck:
    """`shield_state` stand-in: the proposal passes, but nothing does for the UAVs given."""

    def __init__(self):
        self.stuck: dict[int, tuple[int, int]] = {}  # step → (env, uav) with nothing passing

    def __call__(self, shield_cfg, cfg, state, proposed, vehicle=None):
        decision = shield_state(dataclasses.replace(shield_cfg, mode="off"), cfg, state, proposed)
        safe = np.ones(state.heading_rad.shape, dtype=bool)
        at = self.stuck.get(int(state.steps.max()))
        if at is not None:
            safe[at] = False
        return dataclasses.replace(decision, safe_exists=safe)


def test_the_planner_holds_its_plan_for_its_steps_then_hands_back(monkeypatch):
    cfg = load_scenario("3u2o")
    swarm, rng = SwarmSim(cfg, scored=False), np.random.default_rng(1)
    state = swarm.initial_state(rng, 3)
    stand_in = Stuck()
    stand_in.stuck[1] = (1, 2)  # environment 1's UAV 2 is stuck at step 1
    monkeypatch.setattr(shielding, "shield_state", stand_in)
    asked: list[list[int]] = []

    def planner(state, cfg, oracle=None, envs=None):
        asked.append(list(envs))
        plans = np.full((len(envs), 8, state.pos_m.shape[1]), 0.5, dtype=np.float32)
        return plans, np.ones(len(envs), dtype=bool)

    monkeypatch.setattr(shielding, "oracle_plan", planner)
    shielded = Shielded(lambda obs, state, cfg: np.zeros(state.heading_rad.shape), ShieldConfig(
        mode="on", plan_steps=3))  # fmt: skip
    flown = []
    for _ in range(6):
        action, speed = shielded(None, state, cfg)
        flown.append(action.copy())
        state, _ = swarm.step(state, action, rng, speeds_m_s=speed)
    assert asked == [[1], [1], [1]]  # steps 1, 2 and 3: the stuck step and two more
    for step, action in enumerate(flown):
        planned = 1 <= step <= 3
        assert (action[1] == 0.5).all() == planned  # the whole swarm of environment 1
        assert (action[[0, 2]] == 0.0).all()  # the others fly their controller's
    assert shielded.planned == 3 * 3
    assert shielded.interventions == 3 * 3  # every planned decision changed the proposal
    stand_in.stuck[6] = (0, 1)
    planner_flies = lambda state, cfg, oracle=None, envs=None: (  # noqa: E731
        np.zeros((len(envs), 8, state.pos_m.shape[1]), dtype=np.float32),
        np.ones(len(envs), dtype=bool),
    )
    monkeypatch.setattr(shielding, "oracle_plan", planner_flies)
    shielded(None, state, cfg)  # a plan that is the proposal changes nothing
    assert shielded.planned == 3 * 4 and shielded.interventions == 3 * 3


def test_the_planner_restarts_with_each_episode_and_yields_where_it_finds_nothing(monkeypatch):
    """Found at step 1, a plan of two steps; nothing found after. Step 2 flies the plan's
    second step (held: the swarm flew its first); step 3 is past its end, and the shield's
    decision stands. A new episode holds nothing."""
    cfg = load_scenario("3u2o")
    swarm, rng = SwarmSim(cfg, scored=False), np.random.default_rng(1)
    start = swarm.initial_state(rng, 2)
    stand_in = Stuck()
    stand_in.stuck[1] = (0, 0)
    monkeypatch.setattr(shielding, "shield_state", stand_in)
    asked: list[list[int]] = []

    def planner(state, cfg, oracle=None, envs=None):
        asked.append(list(envs))
        found = np.array([e == 0 and len(asked) == 1 for e in envs])
        plans = np.zeros((len(envs), 2, 3), dtype=np.float32)
        plans[:, 0], plans[:, 1] = 0.5, 0.25
        return np.where(found[:, None, None], plans, 0.0), found

    monkeypatch.setattr(shielding, "oracle_plan", planner)
    shielded = Shielded(lambda obs, state, cfg: np.zeros(state.heading_rad.shape), ShieldConfig(
        mode="on", plan_steps=4))  # fmt: skip
    state = start
    flown = []
    for _ in range(4):
        action, speed = shielded(None, state, cfg)
        flown.append(action[0].copy())
        state, _ = swarm.step(state, action, rng, speeds_m_s=speed)
    assert (flown[1] == 0.5).all()  # planned at step 1
    assert (flown[2] == 0.25).all()  # nothing found at step 2: the held plan's next step
    assert (flown[3] == 0.0).all()  # past its end: the shield's decision stands
    assert shielded.plans_kept == 1 and shielded.report()["shield_plans_kept"] == 1
    shielded(None, start, cfg)  # a new episode (its step went back to 0): no plan held
    assert len(asked) == 3


def test_a_held_plan_is_dropped_when_an_intruder_appears_or_the_swarm_leaves_it(monkeypatch):
    """A plan found at step 1, nothing found after. An intruder that appears at step 2 ends it
    (the plan did not know it); so does a step flown by the controller (planned for the stuck
    step alone, stuck again at step 3)."""
    cfg = load_scenario("3u2o")
    swarm, rng = SwarmSim(cfg, scored=False), np.random.default_rng(1)
    stand_in = Stuck()
    monkeypatch.setattr(shielding, "shield_state", stand_in)
    asked: list[int] = []

    def planner(state, cfg, oracle=None, envs=None):
        asked.append(int(state.steps[0]))
        found = np.full(len(envs), len(asked) == 1)
        return np.full((len(envs), 8, 3), 0.5, dtype=np.float32) * found[:, None, None], found

    monkeypatch.setattr(shielding, "oracle_plan", planner)

    def flight(plan_steps, stuck, state):
        asked.clear()
        stand_in.stuck = stuck
        # the stand-in decides where no plan flies: no giving way on top of it
        shielded = Shielded(lambda obs, state, cfg: np.zeros(state.heading_rad.shape),
                            ShieldConfig(mode="on", plan_steps=plan_steps, give_way=0))  # fmt: skip
        flown = []
        for _ in range(4):
            action, speed = shielded(None, state, cfg)
            flown.append(action[0].copy())
            state, _ = swarm.step(state, action, rng, speeds_m_s=speed)
        return flown, shielded

    state = swarm.initial_state(rng, 1)
    appear = state.obstacle_appear_step.copy()
    appear[0, 0] = 2  # hidden until step 2
    flown, shielded = flight(
        4, {1: (0, 0)}, dataclasses.replace(state, obstacle_appear_step=appear)
    )
    assert asked[:2] == [1, 2] and (flown[1] == 0.5).all()
    assert (flown[2] == 0.0).all() and shielded.plans_kept == 0
    flown, shielded = flight(1, {1: (0, 0), 3: (0, 0)}, swarm.initial_state(rng, 1))
    assert asked == [1, 3] and (flown[1] == 0.5).all() and (flown[2] == 0.0).all()
    assert (flown[3] == 0.0).all() and shielded.plans_kept == 0
    flown, shielded = flight(4, {1: (0, 0)}, swarm.initial_state(rng, 1))  # the control
    assert (flown[2] == 0.5).all() and (flown[3] == 0.5).all() and shielded.plans_kept == 2


@pytest.mark.parametrize("world", ["adsb", "arducopter", "monitor", "off"])
def test_the_planner_flies_only_the_exact_world_and_only_with_the_shield_on(monkeypatch, world):
    cfg = load_scenario("3u2o")
    mode = world if world in ("monitor", "off") else "on"
    if world == "adsb":
        cfg = dataclasses.replace(cfg, sensors=SensorConfig(model="adsb"))
    if world == "arducopter":
        cfg = dataclasses.replace(cfg, dynamics="arducopter")
    swarm, rng = SwarmSim(cfg, scored=False), np.random.default_rng(1)
    state = swarm.initial_state(rng, 2)
    stand_in = Stuck()
    stand_in.stuck[0] = (0, 0)
    monkeypatch.setattr(shielding, "shield_state", stand_in)

    def planner(*args, **kwargs):
        raise AssertionError("planned where the plan would not be exact")

    monkeypatch.setattr(shielding, "oracle_plan", planner)
    shielded = Shielded(lambda obs, state, cfg: np.zeros(state.heading_rad.shape), ShieldConfig(
        mode=mode, plan_steps=4))  # fmt: skip
    shielded(None, state, cfg)
    assert shielded.planned == 0


def test_plan_steps_must_not_be_negative():
    with pytest.raises(ValueError, match="plan_steps must be >= 0"):
        ShieldConfig(plan_steps=-1)
