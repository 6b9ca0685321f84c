"""The swarm controller: headings, arcs and setpoints, and its agreement with the simulator."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from remarl_fc.flight.config import Member
from remarl_fc.flight.control import (
    ControlSpec,
    SwarmController,
    SwarmPicture,
    swarm_picture,
    whereabouts,
)
from remarl_fc.flight.status import Status
from remarl_fc.flight.tracking import VehicleTrack
from remarl_fc.frames import GeoPoint, heading_to_yaw, ne_to_sim, sim_to_ne
from remarl_fc.policy_io import load_policy
from sim.dynamics import brake, response_values
from sim.encounters import Family, sample_family
from sim.observation import NEIGHBOUR_COLUMNS, ObservationLayout, build_observations
from sim.scenarios import load_scenario
from sim.shield import ShieldConfig
from sim.spawn import virtual_centre_and_velocity
from sim.swarm import SwarmSim
from sim.vehicle import load_profile

SPEC = ControlSpec(speed_m_s=10.0, dt_s=2.0, max_turn_rad=math.pi / 4, lead_m=40.0, arrival_m=20.0)
LAYOUT = ObservationLayout(
    max_obstacles=4, range_m=100.0, aperture_rad=math.radians(270.0), speed_m_s=10.0
)


class ConstantPolicy:
    """A fake policy: the same action for every vehicle; remembers what it was shown."""

    def __init__(self, action: float, layout: ObservationLayout = LAYOUT) -> None:
        self.layout = layout
        self.action = action
        self.seen: list[NDArray[np.float32]] = []

    def act(self, obs: NDArray[np.floating]) -> NDArray[np.float32]:
        self.seen.append(np.array(obs, copy=True))
        return np.full(obs.shape[:-1], self.action, dtype=np.float32)


NO_OBSTACLES = np.zeros((0, 2))


def controller(targets_ne, action: float = 0.0, spec: ControlSpec = SPEC) -> SwarmController:
    return SwarmController(ConstantPolicy(action), spec, np.asarray(targets_ne, dtype=np.float64))


def course(north: float, east: float) -> float:
    """NED course of a horizontal velocity, clockwise from north."""
    return math.atan2(east, north)


def same_angle(a: float, b: float, tol: float = 1e-9) -> bool:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi) < tol


# -- start ----------------------------------------------------------------------------------


def test_start_heads_each_vehicle_to_its_target():
    positions = np.array([[0.0, 0.0], [0.0, 0.0], [50.0, 50.0], [10.0, -10.0]])
    targets = np.array([[0.0, 100.0], [100.0, 0.0], [-50.0, -50.0], [10.0, -200.0]])
    c = controller(targets)
    assert not c.started
    c.start(positions, now=5.0)
    assert c.started and c.t_start == 5.0
    for slot in range(4):
        vn, ve, yaw = c.setpoint(slot, 5.0)
        to_target = targets[slot] - positions[slot]
        direction = to_target / np.linalg.norm(to_target)
        np.testing.assert_allclose([vn, ve], SPEC.speed_m_s * direction, atol=1e-12)
        assert same_angle(yaw, course(*to_target))
    # and they keep flying straight until a decision
    for slot in range(4):
        np.testing.assert_allclose(c.setpoint(slot, 60.0), c.setpoint(slot, 5.0))


@pytest.mark.parametrize(
    ("target_ne", "yaw"),
    [
        ((0.0, 100.0), math.pi / 2),  # east
        ((100.0, 0.0), 0.0),  # north
        ((0.0, -100.0), -math.pi / 2),  # west
        ((-100.0, 0.0), -math.pi),  # south: wrapped to [-π, π)
        ((100.0, 100.0), math.pi / 4),  # north-east
        ((-100.0, -100.0), -3 * math.pi / 4),  # south-west
    ],
)
def test_setpoint_velocity_and_ned_yaw(target_ne, yaw):
    c = controller([target_ne])
    c.start(np.zeros((1, 2)), 0.0)
    vn, ve, sp_yaw = c.setpoint(0, 0.0)
    assert math.hypot(vn, ve) == pytest.approx(SPEC.speed_m_s)
    assert sp_yaw == pytest.approx(yaw, abs=1e-12)
    assert -math.pi <= sp_yaw < math.pi
    assert same_angle(course(vn, ve), sp_yaw)  # the nose points where it flies
    # heading (simulator, CCW from east) and NED yaw are the same direction
    assert sp_yaw == pytest.approx(float(heading_to_yaw(c.heading_at(0.0)[0])))


def test_start_fixes_the_virtual_centre_like_the_simulator():
    positions = np.array([[150.0, 60.0], [184.6, 40.0], [115.4, 40.0]])
    targets = np.array([[150.0, 270.0], [184.6, 270.0], [115.4, 270.0]])
    c = controller(targets)
    c.start(positions, 3.0)
    vel, centre = virtual_centre_and_velocity(
        ne_to_sim(positions), ne_to_sim(targets), SPEC.speed_m_s, SPEC.lead_m
    )
    np.testing.assert_allclose(c.swarm_vel, vel)
    np.testing.assert_allclose(c.centre0, centre)
    np.testing.assert_allclose(c.centre_at(3.0), np.repeat(centre, 3, axis=0))
    np.testing.assert_allclose(c.centre_at(7.5), np.repeat(centre + 4.5 * vel, 3, axis=0))
    # one swarm flying east at 10 m/s, 40 m ahead of the foremost (x = 60 m) vehicle
    np.testing.assert_allclose(vel, [[10.0, 0.0]], atol=1e-12)
    assert c.centre0[0, 0] == pytest.approx(100.0)


# -- decide: arcs ---------------------------------------------------------------------------


@pytest.mark.parametrize("action", [1.0, 0.5, -0.3, -1.0, 0.0])
def test_decide_turns_by_action_times_max_turn_over_dt(action):
    c = controller([[0.0, 500.0], [100.0, 500.0]], action)
    c.start(np.array([[0.0, 0.0], [100.0, 0.0]]), 10.0)
    h0 = c.heading_at(10.0).copy()  # east: heading 0
    d = c.decide(10.0, np.array([[0.0, 0.0], [100.0, 0.0]]), NO_OBSTACLES, NO_OBSTACLES)
    turn = action * SPEC.max_turn_rad
    np.testing.assert_allclose(d.action, [action, action])
    assert d.action.dtype == np.float32
    np.testing.assert_allclose(d.turn_rad, [turn, turn], atol=1e-7)
    np.testing.assert_allclose(d.heading_rad, h0)
    assert d.t == 10.0
    dt = SPEC.dt_s
    for frac in (0.0, 0.25, 0.5, 0.75, 1.0):
        np.testing.assert_allclose(c.heading_at(10.0 + frac * dt), h0 + frac * turn, atol=1e-7)
    # after the step: straight on at the new heading
    np.testing.assert_allclose(c.heading_at(10.0 + 3 * dt), h0 + turn, atol=1e-7)
    # the setpoint follows: yaw after dt changed by -turn (NED yaw is clockwise)
    yaw0, yaw1 = c.setpoint(0, 10.0)[2], c.setpoint(0, 10.0 + dt)[2]
    assert same_angle(yaw1 - yaw0, -turn, 1e-6)
    yaw_mid = c.setpoint(0, 10.0 + dt / 2)[2]
    assert same_angle(yaw_mid - yaw0, -turn / 2, 1e-6)  # midpoint: half the turn


def test_actions_are_clipped_to_the_unit_interval():
    c = controller([[0.0, 500.0]], action=3.0)
    c.start(np.zeros((1, 2)), 0.0)
    d = c.decide(0.0, np.zeros((1, 2)), NO_OBSTACLES, NO_OBSTACLES)
    assert d.action.tolist() == [1.0]
    assert d.turn_rad[0] == pytest.approx(SPEC.max_turn_rad)


def test_a_speed_command_slows_the_setpoints_down_to_a_hover():
    c = controller([[0.0, 500.0], [100.0, 500.0]])
    c.start(np.array([[0.0, 0.0], [100.0, 0.0]]), 0.0)
    d = c.decide(0.0, np.zeros((2, 2)), NO_OBSTACLES, NO_OBSTACLES, np.array([4.0, 99.0]))
    np.testing.assert_allclose(d.speed_m_s, [4.0, SPEC.speed_m_s])  # clipped to the policy's
    assert math.hypot(*c.setpoint(0, 1.0)[:2]) == pytest.approx(4.0)
    assert math.hypot(*c.setpoint(1, 1.0)[:2]) == pytest.approx(SPEC.speed_m_s)
    d = c.decide(2.0, np.zeros((2, 2)), NO_OBSTACLES, NO_OBSTACLES, np.array([-1.0, math.nan]))
    assert d.speed_m_s.tolist() == [0.0, 0.0]  # negative or not a number: stop
    assert c.setpoint(0, 3.0)[:2] == (0.0, 0.0)
    d = c.decide(4.0, np.zeros((2, 2)), NO_OBSTACLES, NO_OBSTACLES)
    np.testing.assert_allclose(d.speed_m_s, SPEC.speed_m_s)  # None: back to the policy's


def test_setpoints_fly_the_simulators_arc():
    """Integrating the velocity setpoints over one step lands where the simulator's arc does."""
    action = 0.8
    c = controller([[0.0, 500.0]], action)
    start = np.array([[0.0, -20.0]])  # due west of the target: heading east
    c.start(start, 0.0)
    c.decide(0.0, start, NO_OBSTACLES, NO_OBSTACLES)
    steps = 4000
    h = SPEC.dt_s / steps
    pos = start[0].copy()
    path = [pos.copy()]
    for k in range(steps):  # midpoint rule
        vn, ve, _ = c.setpoint(0, (k + 0.5) * h)
        pos += h * np.array([vn, ve])
        path.append(pos.copy())
    # the simulator's arc (sim/kinematics.py): chord L·sinc(a/2) along h0 + a/2
    turn, length, h0 = action * SPEC.max_turn_rad, SPEC.speed_m_s * SPEC.dt_s, 0.0
    chord = length * math.sin(turn / 2) / (turn / 2)
    end_xy = ne_to_sim(start[0]) + chord * np.array(
        [math.cos(h0 + turn / 2), math.sin(h0 + turn / 2)]
    )
    np.testing.assert_allclose(pos, sim_to_ne(end_xy), atol=1e-4)
    # a circle: every point of the path at the same distance from the centre of curvature
    radius = length / turn
    centre_xy = ne_to_sim(start[0]) + radius * np.array([-math.sin(h0), math.cos(h0)])
    dist = np.linalg.norm(np.array([ne_to_sim(p) for p in path]) - centre_xy, axis=1)
    np.testing.assert_allclose(dist, radius, atol=1e-4)


def test_the_next_decision_starts_from_the_heading_reached():
    c = controller([[0.0, 500.0]], action=0.5)
    c.start(np.zeros((1, 2)), 0.0)
    c.decide(0.0, np.zeros((1, 2)), NO_OBSTACLES, NO_OBSTACLES)
    # decided early (a late tick is as likely): the new arc starts where the old one was
    d = c.decide(1.0, np.zeros((1, 2)), NO_OBSTACLES, NO_OBSTACLES)
    quarter = 0.5 * SPEC.max_turn_rad
    assert d.heading_rad[0] == pytest.approx(0.5 * quarter)
    assert c.heading_at(3.0)[0] == pytest.approx(1.5 * quarter)


# -- reached --------------------------------------------------------------------------------


def test_reached():
    c = controller([[100.0, 200.0], [-50.0, 0.0]])
    assert c.reached(0, np.array([100.0, 200.0]))
    assert c.reached(0, np.array([110.0, 190.0]))  # 14 m
    assert c.reached(0, np.array([100.0, 219.9]))
    assert not c.reached(0, np.array([100.0, 220.0]))  # exactly d_col: not yet
    assert not c.reached(0, np.array([120.0, 220.0]))
    assert not c.reached(1, np.array([100.0, 200.0]))  # another vehicle's target
    assert c.reached(1, np.array([-40.0, 5.0]))


# -- the observation is the simulator's -----------------------------------------------------


def test_observation_is_the_shared_builder():
    targets = np.array([[150.0, 270.0], [185.0, 270.0], [115.0, 270.0]])
    start = np.array([[150.0, 60.0], [185.0, 40.0], [115.0, 40.0]])
    c = controller(targets, action=0.4)
    policy = c.policy
    assert isinstance(policy, ConstantPolicy)
    c.start(start, 100.0)
    c.decide(100.0, start, NO_OBSTACLES, NO_OBSTACLES)
    # a second decision, later, with headings turned, the centre moved and intruders around
    now = 101.3
    positions = np.array([[152.0, 75.0], [190.0, 52.0], [np.nan, np.nan]])  # one lost: NaN
    obstacles = np.array([[160.0, 120.0], [100.0, 90.0], [400.0, 400.0]])
    obstacle_vel = np.array([[-1.0, -2.0], [0.5, 0.0], [3.0, 3.0]])
    heading = c.heading_at(now).copy()
    d = c.decide(now, positions, obstacles, obstacle_vel)

    pos_xy = ne_to_sim(positions)
    pos_xy[2] = 0.0  # NaN rows are replaced (their vehicle is not flown)
    vel_xy = SPEC.speed_m_s * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    swarm_vel, centre = virtual_centre_and_velocity(
        ne_to_sim(start), ne_to_sim(targets), SPEC.speed_m_s, SPEC.lead_m
    )
    expected = build_observations(
        LAYOUT,
        pos_xy[None],
        heading[None],
        vel_xy[None],
        ne_to_sim(targets)[None],
        np.repeat(centre + swarm_vel * (now - 100.0), 3, axis=0)[None],
        ne_to_sim(obstacles)[None],
        ne_to_sim(obstacle_vel)[None],
    ).flat()
    assert len(policy.seen) == 2
    np.testing.assert_array_equal(policy.seen[1], expected)
    np.testing.assert_array_equal(d.obs, expected[0])
    assert np.isfinite(d.obs).all()
    assert expected[0, :, -LAYOUT.max_obstacles :].any()  # some obstacles are sensed
    np.testing.assert_array_equal(d.heading_rad, heading)
    np.testing.assert_allclose(d.obstacles_ne_m, obstacles)
    np.testing.assert_array_equal(d.positions_ne_m, positions)


def test_no_obstacles_gives_an_empty_mask():
    c = controller([[0.0, 500.0]], action=0.0)
    c.start(np.zeros((1, 2)), 0.0)
    d = c.decide(0.0, np.zeros((1, 2)), NO_OBSTACLES, NO_OBSTACLES)
    assert d.obs.shape == (1, LAYOUT.size)
    assert not d.obs[:, -LAYOUT.max_obstacles :].any()
    assert d.obstacles_ne_m.shape == (0, 2)


# -- against the simulator, with the shipped policy -----------------------------------------


def test_control_spec_from_the_zoo_policy():
    spec = ControlSpec.from_policy_meta(load_policy("3u2o").meta)
    cfg = load_scenario("3u2o")
    assert spec == ControlSpec(
        speed_m_s=cfg.uav.speed_m_s,
        dt_s=cfg.dt_s,
        max_turn_rad=cfg.uav.max_turn_rad,
        lead_m=cfg.field.swarm_lead_m,
        arrival_m=cfg.d_col_m,
    )


def test_first_decision_equals_the_simulators():
    """From the scenario's spawn, the controller sees what the simulator's first observation shows.

    The controller recomputes the headings (toward each target) and the virtual centre and
    swarm velocity (`virtual_centre_and_velocity` of the spawn positions) itself; the
    simulator takes them from `swarm_layout`, which calls the same function on the same
    positions, so they agree exactly, and so do the observations and the actions.
    """
    cfg = load_scenario("3u2o")
    policy = load_policy("3u2o")
    sim = SwarmSim(cfg)
    state = sim.initial_state(np.random.default_rng(7), 1)
    obs = sim.observe(state).flat()
    expected = policy.act(obs)[0]

    c = SwarmController(
        policy, ControlSpec.from_policy_meta(policy.meta), sim_to_ne(state.target_m[0])
    )
    spawn = sim_to_ne(state.pos_m[0])
    c.start(spawn, 0.0)
    np.testing.assert_allclose(c.h0, state.heading_rad[0], atol=1e-12)
    np.testing.assert_allclose(c.centre0, state.centre_m[0], atol=1e-9)
    np.testing.assert_allclose(c.swarm_vel, state.swarm_vel_m_s[0], atol=1e-12)
    d = c.decide(
        0.0, spawn, sim_to_ne(state.obstacle_pos_m[0]), sim_to_ne(state.obstacle_vel_m_s[0])
    )
    np.testing.assert_allclose(d.obs, obs[0], atol=1e-6)
    np.testing.assert_allclose(d.action, expected, atol=1e-6)
    assert np.abs(d.action).max() > 0.0  # the policy does something


def test_closed_loop_decisions_equal_the_simulators():
    """Fed the simulator's positions and obstacles every step, the controller decides as the
    simulator's policy does — also once obstacles are sensed. A vehicle that has arrived stays
    put in the simulator while the controller would keep turning it, so only flying ones count.
    """
    cfg = load_scenario("3u2o")
    policy = load_policy("3u2o")
    sim = SwarmSim(cfg)
    rng = np.random.default_rng(3)
    state = sim.initial_state(rng, 1)
    spec = ControlSpec.from_policy_meta(policy.meta)
    c = SwarmController(policy, spec, sim_to_ne(state.target_m[0]))
    c.start(sim_to_ne(state.pos_m[0]), 0.0)
    sensed_steps = 0
    for k in range(cfg.max_steps):
        active = state.active[0]
        if not active.any():
            break
        obs = sim.observe(state).flat()
        actions = policy.act(obs)
        d = c.decide(
            k * spec.dt_s,
            sim_to_ne(state.pos_m[0]),
            sim_to_ne(state.obstacle_pos_m[0]),
            sim_to_ne(state.obstacle_vel_m_s[0]),
        )
        heading_diff = (d.heading_rad - state.heading_rad[0] + np.pi) % (2 * np.pi) - np.pi
        np.testing.assert_allclose(heading_diff[active], 0.0, atol=1e-9)
        np.testing.assert_allclose(d.obs[active], obs[0][active], atol=1e-5)
        np.testing.assert_allclose(d.action[active], actions[0][active], atol=1e-5)
        sensed_steps += int(obs[0][active, -sim.obs_layout.max_obstacles :].any())
        state, result = sim.step(state, actions, rng)
        if result.terminated[0] or result.truncated[0]:
            break
    assert sensed_steps > 0, "the obstacles were never sensed: the comparison missed them"


# -- version 2: the swarm's own vehicles as neighbours ---------------------------------------

LAYOUT_V2 = ObservationLayout(
    max_obstacles=3,
    range_m=100.0,
    aperture_rad=math.radians(270.0),
    speed_m_s=10.0,
    max_neighbours=4,
    version=2,
)


def neighbour_rows(layout: ObservationLayout, obs: NDArray[np.float32]) -> NDArray[np.float32]:
    """(N, k, 8) neighbour rows of flat observations (N, size)."""
    cols = NEIGHBOUR_COLUMNS
    return obs[:, layout.blocks()["neighbours"]].reshape(len(obs), layout.max_neighbours, cols)


def neighbour_mask(layout: ObservationLayout, obs: NDArray[np.float32]) -> NDArray[np.float32]:
    return obs[:, layout.blocks()["neighbour_mask"]]


def v2_controller(targets_ne, action: float = 0.0) -> SwarmController:
    policy = ConstantPolicy(action, LAYOUT_V2)
    return SwarmController(policy, SPEC, np.asarray(targets_ne, dtype=np.float64))


def test_two_vehicles_20_m_apart_see_each_other():
    # vehicle 0 flies east; vehicle 1, 20 m away 60° to its left, flies north-west
    apart = 20.0 * np.array([math.sin(math.radians(60.0)), math.cos(math.radians(60.0))])
    start = np.array([[0.0, 0.0], apart])
    north_west = np.array([1.0, -1.0]) / math.sqrt(2.0)
    targets = np.array([[0.0, 300.0], apart + 300.0 * north_west])
    c = v2_controller(targets)
    c.start(start, 0.0)
    d = c.decide(0.0, start, NO_OBSTACLES, NO_OBSTACLES)
    assert d.obs.shape == (2, LAYOUT_V2.size) and d.action.shape == (2,)
    rows, mask = neighbour_rows(LAYOUT_V2, d.obs), neighbour_mask(LAYOUT_V2, d.obs)
    np.testing.assert_array_equal(mask, [[1, 0, 0, 0], [1, 0, 0, 0]])
    assert not rows[:, 1:].any()  # the empty rows are zero
    r, v, h = LAYOUT_V2.range_m, LAYOUT_V2.speed_m_s, math.radians(135.0)
    # vehicle 0 (heading east): 10 m ahead, 17.3 m to its left, heading 135° more, known
    np.testing.assert_allclose(rows[0, 0, [0, 1, 4]], [10.0 / r, apart[0] / r, 0.2], atol=1e-6)
    np.testing.assert_allclose(rows[0, 0, 5:], [math.cos(h), math.sin(h), 1.0], atol=1e-6)
    rel_v = v * np.array([math.cos(h) - 1.0, math.sin(h)])  # its velocity minus ours
    np.testing.assert_allclose(rows[0, 0, 2:4], rel_v / v, atol=1e-6)
    # vehicle 1 (heading 135°): the same pair seen from the other side, in its own frame
    rel_xy = -np.array([10.0, apart[0]])  # simulator frame: x east, y north
    ahead = np.array([[math.cos(h), math.sin(h)], [-math.sin(h), math.cos(h)]]) @ rel_xy
    assert ahead[1] > 0.0  # vehicle 0 is to its left
    np.testing.assert_allclose(rows[1, 0, :2], ahead / r, atol=1e-6)
    np.testing.assert_allclose(rows[1, 0, 4], 0.2, atol=1e-6)
    np.testing.assert_allclose(rows[1, 0, 5:], [math.cos(-h), math.sin(-h), 1.0], atol=1e-6)


def test_a_vehicle_not_flown_or_not_located_is_no_neighbour():
    start = np.array([[0.0, 0.0], [20.0, 0.0], [-20.0, 0.0], [-40.0, 0.0]])
    targets = start + np.array([0.0, 300.0])
    c = v2_controller(targets)
    c.start(start, 0.0)
    positions = start.copy()
    positions[3] = np.nan  # never located
    swarm = SwarmPicture(
        present=np.array([True, True, False, True]),  # vehicle 2: lost, held or the pilot's
        on_arc=np.array([True, True, False, True]),
        heading_known=np.array([True, True, False, True]),
        vel_ne_m_s=np.zeros((4, 2)),
    )
    d = c.decide(0.0, positions, NO_OBSTACLES, NO_OBSTACLES, swarm=swarm)
    mask = neighbour_mask(LAYOUT_V2, d.obs)
    # vehicles 0 and 1 see only each other; vehicles 2 and 3 (not neighbours) still see them
    np.testing.assert_array_equal(mask.sum(axis=1), [1, 1, 2, 2])
    rows = neighbour_rows(LAYOUT_V2, d.obs)
    np.testing.assert_allclose(rows[0, 0, 1], 20.0 / LAYOUT_V2.range_m, atol=1e-6)


def test_a_peer_processes_vehicle_moves_as_its_telemetry_says_heading_unknown():
    start = np.array([[0.0, 0.0], [20.0, 0.0]])
    c = v2_controller(start + np.array([0.0, 300.0]))
    c.start(start, 0.0)
    swarm = SwarmPicture(
        present=np.array([True, True]),
        on_arc=np.array([True, False]),  # vehicle 1 flown by another process
        heading_known=np.array([True, False]),
        vel_ne_m_s=np.array([[0.0, 0.0], [-5.0, 0.0]]),  # flying south at 5 m/s
    )
    d = c.decide(0.0, start, NO_OBSTACLES, NO_OBSTACLES, swarm=swarm)
    row = neighbour_rows(LAYOUT_V2, d.obs)[0, 0]
    # vehicle 0 flies east at 10 m/s: the other's velocity relative to it, in its frame
    np.testing.assert_allclose(row[2:4], [-1.0, -0.5], atol=1e-6)
    np.testing.assert_array_equal(row[5:], [0.0, 0.0, 0.0])  # heading unknown
    assert neighbour_rows(LAYOUT_V2, d.obs)[1, 0, 7] == 1.0  # vehicle 0's is known


def test_a_peers_arc_from_the_bus_is_its_known_heading_and_what_the_shield_predicts():
    """A peer process's vehicle 30 m east flies north beside ours; its process has commanded a
    45° turn to the left, across our track. Known from the bus, the turn is its commanded
    heading in our neighbour row and the shield turns ours away; unknown, the peer flies
    straight on at its velocity and nothing is in the way. The peer keeps its own arc."""
    start = np.array([[0.0, 0.0], [0.0, 30.0]])
    targets = start + np.array([300.0, 0.0])
    north = np.array([[10.0, 0.0], [10.0, 0.0]])

    def decide(arc_known: bool):
        c = SwarmController(
            ConstantPolicy(0.0, LAYOUT_V2), SPEC, targets, shield=ShieldConfig(mode="on")
        )
        c.start(start, 0.0)
        c.follow(1, (math.pi / 2, math.pi / 4, 10.0, 0.0))  # north, turning left over 2 s
        swarm = SwarmPicture(
            present=np.array([True, True]),
            on_arc=np.array([True, False]),
            heading_known=np.array([True, arc_known]),
            vel_ne_m_s=north,
            peer_arc=np.array([False, arc_known]),
        )
        return c, c.decide(0.0, start, NO_OBSTACLES, NO_OBSTACLES, swarm=swarm)

    c, known = decide(True)
    assert known.shield is not None and known.shield.intervened[0, 0]
    row = neighbour_rows(LAYOUT_V2, known.obs)[0, 0]
    np.testing.assert_allclose(row[5:], [1.0, 0.0, 1.0], atol=1e-6)  # ahead of ours, known
    assert c.turn[1] == math.pi / 4 and c.t0[1] == 0.0  # its own arc, not our decision's
    np.testing.assert_allclose(c.heading_at(1.0)[1], math.pi / 2 + math.pi / 8)
    _, unknown = decide(False)
    assert unknown.shield is not None and not unknown.shield.intervened[0, 0]


def test_swarm_picture_of_the_runtimes_rows():
    def member(slot: int, *, local: bool = True, located: bool = True) -> Member:
        m = Member(slot, slot + 1, VehicleTrack(slot + 1, GeoPoint(47.0, 8.0, 400.0)), local=local)
        m.track.vel_ned_m_s = np.array([1.0, 2.0, 0.0])
        m.track.t_position = 0.0 if located else math.nan
        return m

    rows = [
        (member(0), Status.CONTROLLED),
        (member(1), Status.REACHED),
        (member(2), Status.LOST),
        (member(3, local=False), Status.CONTROLLED),
        (member(4, located=False), Status.CONTROLLED),
        (member(5), Status.PILOT),
    ]
    sw = swarm_picture(rows)
    np.testing.assert_array_equal(sw.present, [True, True, False, True, False, False])
    np.testing.assert_array_equal(sw.on_arc, [True, False, False, False, True, False])
    np.testing.assert_array_equal(sw.heading_known, [True, True, False, False, True, False])
    np.testing.assert_array_equal(sw.vel_ne_m_s[1], [0.0, 0.0])  # holding at its target
    np.testing.assert_array_equal(sw.vel_ne_m_s[3], [1.0, 2.0])  # a peer's: its telemetry


def test_a_vehicle_told_to_hold_is_where_it_stopped_not_flying_on():
    """A vehicle told to hold (this process's own, or a peer whose process last said so and
    fell silent) brakes to rest where the fitted response stops it, and its uncertainty stops
    growing there; one still flying (a peer under control, a lost vehicle on its last setpoint)
    flies on at its last velocity."""

    def member(slot: int, *, local: bool = True, said: str | None = None) -> Member:
        m = Member(slot, slot + 1, VehicleTrack(slot + 1, GeoPoint(47.0, 8.0, 400.0)), local=local)
        m.track.ne_m = np.array([100.0 * slot, 0.0])
        m.track.vel_ned_m_s = np.array([10.0, 0.0, 0.0])  # north at 10 m/s, 30 s ago
        m.track.t_position = 10.0
        m.remote_said = said
        return m

    rows = [
        (member(0), Status.REACHED),
        (member(1), Status.HELD),
        (member(2, local=False, said="reached"), Status.LOST),  # its process ended
        (member(3, local=False, said="controlled"), Status.LOST),  # a bus outage
        (member(4), Status.LOST),  # our own, silent: it flies its last setpoint
        (member(5, local=False, said="controlled"), Status.CONTROLLED),
    ]
    arducopter = response_values(load_profile("arducopter"))
    where = whereabouts(rows, np.array([arducopter] * len(rows)), 40.0)
    stop = brake(np.array([[10.0, 0.0]]), *(np.full(1, x) for x in arducopter), np.full(1, 30.0))
    assert 20.0 < stop.disp_m[0, 0] < 25.0 and stop.moving_s[0] < 6.0
    for k in range(3):
        np.testing.assert_allclose(where.ne_m[k], [100.0 * k + stop.disp_m[0, 0], 0.0])
        np.testing.assert_allclose(where.vel_ne_m_s[k], 0.0, atol=1e-9)
        assert where.age_s[k] == stop.moving_s[0]
    for k in range(3, 6):
        np.testing.assert_allclose(where.ne_m[k], [100.0 * k + 300.0, 0.0])
        np.testing.assert_allclose(where.vel_ne_m_s[k], [10.0, 0.0])
        assert where.age_s[k] == 30.0


def test_version_2_first_decision_equals_the_simulators():
    """A generalist's first observation in flight is the simulator's (`SwarmSim.observe`)."""
    cfg = load_scenario("5u2o")
    sim = SwarmSim(cfg)
    state = sim.initial_state(np.random.default_rng(2), 1)
    expected = sim.observe(state, layout=LAYOUT_V2).flat()
    assert expected[0, :, LAYOUT_V2.blocks()["neighbour_mask"]].any()
    c = v2_controller(sim_to_ne(state.target_m[0]))
    spawn = sim_to_ne(state.pos_m[0])
    c.start(spawn, 0.0)
    d = c.decide(
        0.0, spawn, sim_to_ne(state.obstacle_pos_m[0]), sim_to_ne(state.obstacle_vel_m_s[0])
    )
    np.testing.assert_allclose(d.obs, expected[0], atol=1e-6)


def test_version_1_ignores_the_swarm_picture():
    start = np.array([[0.0, 0.0], [20.0, 0.0]])
    targets = start + np.array([0.0, 300.0])
    plain, given = controller(targets, 0.3), controller(targets, 0.3)
    for c in (plain, given):
        c.start(start, 0.0)
    nobody = SwarmPicture(
        np.zeros(2, dtype=bool), np.zeros(2, dtype=bool), np.zeros(2, dtype=bool), np.ones((2, 2))
    )
    a = plain.decide(0.5, start, NO_OBSTACLES, NO_OBSTACLES)
    b = given.decide(0.5, start, NO_OBSTACLES, NO_OBSTACLES, swarm=nobody)
    np.testing.assert_array_equal(a.obs, b.obs)
    assert a.obs.shape == (2, LAYOUT.size)


def test_two_swarms_decide_as_in_the_simulator():
    """A mission of two crossing swarms: each vehicle's virtual centre is its own swarm's, as
    in the simulator, so the generalist's first decision is the simulator's."""
    family = Family("two", "swarms", uavs=6)
    cfg, episode = sample_family(family, 0, [0])
    policy = load_policy("generalist")
    sim = SwarmSim(cfg)
    state = sim.start(episode, np.random.default_rng(0))
    obs = sim.observe(state, layout=policy.layout).flat()
    spec = ControlSpec.from_policy_meta(policy.meta)
    c = SwarmController(policy, spec, sim_to_ne(state.target_m[0]), groups=cfg.uav.groups)
    spawn = sim_to_ne(state.pos_m[0])
    c.start(spawn, 0.0)
    np.testing.assert_allclose(c.centre0, state.centre_m[0], atol=1e-9)
    assert not np.allclose(c.centre0[0], c.centre0[1])  # two swarms, two centres
    d = c.decide(0.0, spawn, np.zeros((0, 2)), np.zeros((0, 2)))
    np.testing.assert_allclose(d.obs, obs[0], atol=1e-6)
    np.testing.assert_allclose(d.action, policy.act(obs)[0], atol=1e-6)
