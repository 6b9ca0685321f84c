"""The safety shield: it never changes what passes, it finds what passes, monitor mode only
watches. Checked against an independent dense simulation of the predicted motion."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import pytest
from dense_response import dense_track
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.dynamics import Motion
from sim.prediction import displacements
from sim.scenarios import load_scenario
from sim.shield import (
    COLLISION_INTRUDER_SOON,
    COLLISION_NEIGHBOUR_SOON,
    COLLISION_NOW,
    ESCAPE_STEPS_MAX,
    ShieldConfig,
    Swarm,
    Threats,
    Vehicle,
    _rank,
    _severity,
    _turns,
    candidate_grid,
    give_way,
    nearest_candidate,
    passing_side,
    shield,
    shield_state,
)
from sim.swarm import SwarmSim
from sim.vehicle import load_profile

VEHICLE = Vehicle(d_col_m=20.0, dt_s=2.0, max_turn_rad=math.pi / 4, cruise_m_s=5.0)
DENSE = 2000
"""Instants of the dense check over the horizon."""


def dense_path(pos, heading, action, speed, horizon_s, vehicle=VEHICLE, held=1):
    """(..., T, 2) positions of the arc-then-straight motion at `DENSE` instants (midpoint rule
    on a fine grid: an independent integration of the same motion). ``speed`` holds over the
    arc; the UAV goes on at the cruise speed after it (a slowed step is one step). ``held``:
    steps the turn is held for (a held turn of the shield, `ShieldConfig.escape_steps`)."""
    t = np.linspace(0.0, horizon_s, DENSE + 1)
    mid = 0.5 * (t[1:] + t[:-1])
    step = np.diff(t)
    turn = np.asarray(action)[..., None] * vehicle.max_turn_rad
    frac = np.clip(mid / vehicle.dt_s, 0.0, held)
    h = np.asarray(heading)[..., None] + turn * frac
    v = np.where(mid < vehicle.dt_s, np.asarray(speed)[..., None], vehicle.cruise_m_s)
    dx = np.cumsum(v * step * np.cos(h), axis=-1)
    dy = np.cumsum(v * step * np.sin(h), axis=-1)
    start = np.asarray(pos)
    x = np.concatenate([start[..., 0, None], start[..., 0, None] + dx], axis=-1)
    y = np.concatenate([start[..., 1, None], start[..., 1, None] + dy], axis=-1)
    return np.stack([x, y], axis=-1), t


def dense_clearance(cfg, swarm, threats, own, uav, action, speed, proposed, held=1):
    """Smallest (distance − required) of UAV ``uav`` of environment ``own`` flying (action,
    speed), its turn held for ``held`` steps, against the intruders and the other UAVs on their
    proposed arcs."""
    horizon = cfg.horizon_s
    me, t = dense_path(
        swarm.pos_m[own, uav], swarm.heading_rad[own, uav], action, speed, horizon, held=held
    )
    worst = np.inf
    required = VEHICLE.d_col_m + cfg.margin_m
    for m in np.flatnonzero(threats.intruder_known[own]):
        path = threats.intruder_pos_m[own, m] + threats.intruder_vel_m_s[own, m] * t[:, None]
        d = np.hypot(*(me - path).T)
        need = required + cfg.track_growth_m_s * (threats.intruder_age_s[own, m] + t)
        worst = min(worst, float((d - need).min()))
    for j in range(swarm.pos_m.shape[1]):
        if j == uav or not swarm.present[own, j]:
            continue
        other, _ = dense_path(
            swarm.pos_m[own, j],
            swarm.heading_rad[own, j],
            proposed[own, j],
            swarm.speed_m_s[own, j],
            horizon,
        )
        ahead = t <= cfg.neighbour_horizon_s  # the swarm's own UAVs: a shorter look-ahead
        worst = min(worst, float((np.hypot(*(me - other).T) - required)[ahead].min()))
    return worst


def random_world(rng, b, n, m):
    pos = rng.uniform(-60, 60, (b, n, 2))
    heading = rng.uniform(-np.pi, np.pi, (b, n))
    swarm = Swarm(
        pos_m=pos,
        heading_rad=heading,
        target_m=pos + 1e4 * np.stack([np.cos(heading), np.sin(heading)], -1),
        deciding=np.ones((b, n), bool),
        present=np.ones((b, n), bool),
        speed_m_s=np.full((b, n), VEHICLE.cruise_m_s),
    )
    angle = rng.uniform(-np.pi, np.pi, (b, m))
    dist = rng.uniform(40, 160, (b, m))
    ipos = np.stack([dist * np.cos(angle), dist * np.sin(angle)], -1)
    ispeed = rng.uniform(0, 15, (b, m))
    course = rng.uniform(-np.pi, np.pi, (b, m))
    ivel = np.stack([ispeed * np.cos(course), ispeed * np.sin(course)], -1)
    # keep intruders off the UAVs at the start
    gap = np.hypot(*(pos[:, :, None] - ipos[:, None]).transpose(3, 0, 1, 2)).min(axis=1)
    known = gap > 30.0
    threats = Threats(ipos, ivel, known, np.zeros((b, m)))
    return swarm, threats


def test_off_flies_the_proposal_and_computes_nothing():
    rng = np.random.default_rng(0)
    swarm, threats = random_world(rng, 4, 3, 2)
    prop = rng.uniform(-1, 1, (4, 3))
    d = shield(ShieldConfig(mode="off"), VEHICLE, swarm, threats, prop)
    np.testing.assert_array_equal(d.action, prop.astype(np.float32))
    assert not d.intervened.any() and (d.speed_m_s == VEHICLE.cruise_m_s).all()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 4), m=st.integers(0, 4))
def test_monitor_never_changes_the_action_and_reports_what_on_would_do(seed, n, m):
    rng = np.random.default_rng(seed)
    swarm, threats = random_world(rng, 8, n, m)
    prop = rng.uniform(-1, 1, (8, n))
    watch = shield(ShieldConfig(mode="monitor"), VEHICLE, swarm, threats, prop)
    act = shield(ShieldConfig(mode="on"), VEHICLE, swarm, threats, prop)
    np.testing.assert_array_equal(watch.action, prop.astype(np.float32))
    assert (watch.speed_m_s == VEHICLE.cruise_m_s).all()
    np.testing.assert_array_equal(watch.intervened, act.intervened)
    np.testing.assert_array_equal(watch.shield_action, act.action)
    np.testing.assert_array_equal(watch.shield_speed_m_s, act.speed_m_s)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_where_some_admissible_action_keeps_separation_the_shielded_one_does(seed):
    """About three thousand random decisions (100 examples × 16 environments × 1–3 UAVs), each
    UAV's decision checked by the dense simulation, and every admissible candidate too where
    the shield intervened. Against the neighbours' proposals: without giving way, which checks
    a freed UAV against its neighbours' new arcs instead (its own test)."""
    rng = np.random.default_rng(seed)
    cfg = ShieldConfig(mode="on", track_growth_m_s=0.0, headings=11, give_way=0)
    b, n, m = 16, int(rng.integers(1, 4)), int(rng.integers(1, 4))
    swarm, threats = random_world(rng, b, n, m)
    prop = rng.uniform(-1, 1, (b, n))
    d = shield(cfg, VEHICLE, swarm, threats, prop)
    speeds = [VEHICLE.cruise_m_s] + [f * VEHICLE.cruise_m_s for f in cfg.slow_fractions]
    headings = np.linspace(-1, 1, cfg.headings)
    for e in range(b):
        for i in range(n):
            flown = dense_clearance(
                cfg, swarm, threats, e, i, d.action[e, i], d.speed_m_s[e, i], prop
            )
            if abs(d.action[e, i]) == 1.0 and d.speed_m_s[e, i] == VEHICLE.cruise_m_s:
                # a full turn may be the first step of a held one: that plan keeps separation
                held = dense_clearance(
                    cfg, swarm, threats, e, i, d.action[e, i], d.speed_m_s[e, i], prop,
                    held=cfg.escape_steps,
                )  # fmt: skip
                flown = max(flown, held)
            if not d.intervened[e, i]:
                assert flown >= -0.5  # the proposal passed: it keeps separation
                continue
            best = max(
                dense_clearance(cfg, swarm, threats, e, i, a, v, prop)
                for v in speeds
                for a in headings
            )
            if best >= 1.0:  # some admissible action keeps separation, with room
                assert flown >= -0.5, (e, i, flown, best)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_safe_headings_are_the_candidates_that_pass_at_cruise(seed):
    """Lone UAVs (one pass decides): where the proposal fails, every candidate heading the
    decision calls safe keeps separation in the dense simulation at the cruise speed, every one
    it calls unsafe does not (0.5 m either way for the chords), and a decision at cruise speed
    is one of them, or, where none passes, a full turn (`ShieldConfig.escape_steps`); where the
    proposal passes, the set is empty."""
    rng = np.random.default_rng(seed)
    cfg = ShieldConfig(mode="on", track_growth_m_s=0.0, headings=11)
    b, m = 16, int(rng.integers(1, 5))
    swarm, threats = random_world(rng, b, 1, m)
    prop = rng.uniform(-1, 1, (b, 1))
    d = shield(cfg, VEHICLE, swarm, threats, prop)
    grid = candidate_grid(cfg.headings)
    assert d.safe_headings.shape == (b, 1, cfg.headings)
    assert not d.safe_headings[~d.intervened].any()
    for e in np.flatnonzero(d.intervened[:, 0]):
        clear = [
            dense_clearance(cfg, swarm, threats, e, 0, a, VEHICLE.cruise_m_s, prop) for a in grid
        ]
        for k, c in enumerate(clear):
            assert (c >= -0.5) if d.safe_headings[e, 0, k] else (c < 0.5), (e, k, c)
        if d.speed_m_s[e, 0] == VEHICLE.cruise_m_s and d.safe_exists[e, 0]:
            if d.safe_headings[e, 0].any():
                assert d.safe_headings[e, 0, np.argmin(np.abs(grid - d.action[e, 0]))]
            else:  # no heading of one step passes: a full turn held over the next step
                assert abs(d.action[e, 0]) == 1.0


@settings(max_examples=200, deadline=None)
@given(
    headings=st.integers(2, 25),
    heading=st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=1, max_size=6),
)
def test_the_nearest_candidate_is_no_farther_than_any_other(headings, heading):
    """Batched: no candidate of the grid lies nearer a heading than the one returned."""
    h = np.array(heading)
    at = nearest_candidate(h, headings)
    grid = candidate_grid(headings)
    assert at.shape == h.shape and ((at >= 0) & (at < headings)).all()
    assert (np.abs(grid[at] - h)[:, None] <= np.abs(grid[None, :] - h[:, None]) + 1e-12).all()


@settings(max_examples=200, deadline=None)
@given(
    safe=st.lists(st.booleans(), min_size=1, max_size=25),
    heading=st.floats(-1.0, 1.0, allow_nan=False),
)
def test_the_passing_side_is_the_run_of_passing_candidates_around_the_choice(safe, heading):
    """Written out one candidate at a time: from the candidate nearest the heading, walk each
    way while the candidates pass; nothing is kept where that candidate fails."""
    row = np.array(safe)
    at = int(np.argmin(np.abs(candidate_grid(row.size) - heading)))
    want = np.zeros_like(row)
    if row[at]:
        lo, hi = at, at
        while lo > 0 and row[lo - 1]:
            lo -= 1
        while hi < row.size - 1 and row[hi + 1]:
            hi += 1
        want[lo : hi + 1] = True
    got = passing_side(row, np.float64(heading))
    assert got.shape == row.shape and (got == want).all()
    assert not (got & ~row).any()  # a subset of the passing candidates


def test_the_passing_side_is_batched_and_keeps_the_side_the_shield_chose():
    """(B, N, K) at once: a threat straight ahead leaves both sides passing; each row keeps
    the side of its own choice, whole, and drops the other."""
    both = np.array([1, 1, 1, 0, 0, 0, 1, 1, 1], dtype=bool)  # K = 9: -1 ... 1
    grid = candidate_grid(9)
    safe = np.broadcast_to(both, (2, 3, 9)).copy()
    safe[1, 2] = False  # nothing passes: nothing kept
    heading = np.array([[grid[2], grid[6], grid[0]], [grid[8], grid[1], 0.0]])
    got = passing_side(safe, heading)
    left, right = both & (np.arange(9) < 3), both & (np.arange(9) > 5)
    assert (got[0, 0] == left).all() and (got[0, 1] == right).all() and (got[0, 2] == left).all()
    assert (got[1, 0] == right).all() and (got[1, 1] == left).all() and not got[1, 2].any()


def test_off_keeps_no_safe_headings():
    rng = np.random.default_rng(1)
    swarm, threats = random_world(rng, 4, 3, 2)
    d = shield(ShieldConfig(mode="off"), VEHICLE, swarm, threats, rng.uniform(-1, 1, (4, 3)))
    assert d.safe_headings.shape == (4, 3, ShieldConfig().headings)
    assert not d.safe_headings.any()


def lone_uav() -> Swarm:
    """One UAV at the origin heading east at 5 m/s, its target far ahead."""
    return Swarm(
        pos_m=np.zeros((1, 1, 2)),
        heading_rad=np.zeros((1, 1)),
        target_m=np.array([[[1e4, 0.0]]]),
        deciding=np.ones((1, 1), bool),
        present=np.ones((1, 1), bool),
        speed_m_s=np.full((1, 1), 5.0),
    )


def test_a_head_on_intruder_is_avoided_by_the_nearest_turn():
    swarm = lone_uav()
    threats = Threats(
        np.array([[[100.0, 0.0]]]),
        np.array([[[-5.0, 0.0]]]),
        np.ones((1, 1), bool),
        np.zeros((1, 1)),
    )
    straight = shield(ShieldConfig(mode="on"), VEHICLE, swarm, threats, np.zeros((1, 1)))
    assert straight.intervened[0, 0] and straight.proposed_cpa_m[0, 0] < 1.0
    assert abs(straight.action[0, 0]) > 0.1
    assert straight.flown_cpa_m[0, 0] >= VEHICLE.d_col_m + ShieldConfig().margin_m - 1e-6
    # a hard turn away that already passes is flown as proposed
    away = shield(ShieldConfig(mode="on"), VEHICLE, swarm, threats, np.ones((1, 1)))
    assert not away.intervened[0, 0] and away.action[0, 0] == 1.0


def test_the_default_look_ahead_sees_a_head_on_conflict_past_ten_seconds():
    """An intruder 300 m ahead closing head-on at 15 m/s meets the 5 m/s UAV in 15 s: a 10 s
    look-ahead lets the straight proposal pass (the conflict lies past it, and two steps later
    no turn clears it), the default 25 s turns now; a tracked intruder (ADS-B) is checked over
    the shorter track horizon."""
    swarm = lone_uav()
    threats = Threats(
        np.array([[[300.0, 0.0]]]), np.array([[[-15.0, 0.0]]]), np.ones((1, 1), bool),
        np.zeros((1, 1)),
    )  # fmt: skip
    short = shield(
        ShieldConfig(mode="on", horizon_s=10.0), VEHICLE, swarm, threats, np.zeros((1, 1))
    )
    default = shield(ShieldConfig(mode="on"), VEHICLE, swarm, threats, np.zeros((1, 1)))
    assert not short.intervened[0, 0] and math.isinf(short.proposed_cpa_m[0, 0])
    assert default.intervened[0, 0] and default.proposed_cpa_m[0, 0] < 1.0
    assert default.flown_cpa_m[0, 0] >= VEHICLE.d_col_m + ShieldConfig().margin_m - 1e-6
    # the same intruder known from a report 0.5 s old: checked over the track horizon (10 s)
    tracked = dataclasses.replace(threats, intruder_age_s=np.full((1, 1), 0.5))
    cfg = ShieldConfig(mode="on")
    assert not shield(cfg, VEHICLE, swarm, tracked, np.zeros((1, 1))).intervened[0, 0]
    longer = dataclasses.replace(cfg, track_horizon_s=25.0)
    assert shield(longer, VEHICLE, swarm, tracked, np.zeros((1, 1))).intervened[0, 0]


def test_boxed_in_multirotor_slows_down_and_a_fixed_speed_uav_takes_the_best_clearance():
    # Intruders converging from ahead and both sides: no heading at full speed passes.
    swarm = lone_uav()
    pos = np.array([[[70.0, 0.0], [45.0, 45.0], [45.0, -45.0], [0.0, 70.0], [0.0, -70.0]]])
    vel = -0.06 * pos  # all closing on the UAV
    threats = Threats(pos, vel, np.ones((1, 5), bool), np.zeros((1, 5)))
    cfg = ShieldConfig(mode="on", horizon_s=20.0)
    hover = shield(cfg, VEHICLE, swarm, threats, np.zeros((1, 1)))
    fixed = shield(
        cfg,
        Vehicle(20.0, 2.0, math.pi / 4, 5.0, can_slow=False),
        swarm,
        threats,
        np.zeros((1, 1)),
    )
    assert hover.intervened[0, 0] and fixed.intervened[0, 0]
    assert hover.speed_m_s[0, 0] <= fixed.speed_m_s[0, 0]
    assert fixed.speed_m_s[0, 0] == 5.0


def test_with_nothing_passing_the_nearest_collision_in_time_is_avoided_first():
    """A fixed-speed UAV with a neighbour 24 m to its left and an intruder from the left that
    no turn clears within the look-ahead. The largest clearance over the whole look-ahead turns
    hard left, behind the intruder and into the neighbour within the coming two steps; the
    shield keeps clear of the neighbour and leaves the intruder, ten seconds away, to the
    decisions still to come."""
    fixed = Vehicle(20.0, 2.0, math.pi / 4, 5.0, can_slow=False)
    swarm = Swarm(
        pos_m=np.array([[[0.0, 0.0], [0.0, 24.0]]]),
        heading_rad=np.zeros((1, 2)),
        target_m=np.array([[[1e4, 0.0], [1e4, 24.0]]]),
        deciding=np.array([[True, False]]),
        present=np.ones((1, 2), bool),
        speed_m_s=np.full((1, 2), 5.0),
    )
    threats = Threats(
        np.array([[[25.0, 100.0]]]), np.array([[[1.5, -13.5]]]), np.ones((1, 1), bool),
        np.zeros((1, 1)),
    )  # fmt: skip
    cfg = ShieldConfig(mode="on", escape_steps=1)  # the one-step candidates alone
    proposed = np.zeros((1, 2))
    decision = shield(cfg, fixed, swarm, threats, proposed)
    assert not decision.safe_exists[0, 0]
    grid = np.linspace(-1.0, 1.0, cfg.headings)
    clearance = [dense_clearance(cfg, swarm, threats, 0, 0, a, 5.0, proposed) for a in grid]
    assert max(clearance) < 0.0
    neighbour, t = dense_path(swarm.pos_m[0, 1], 0.0, 0.0, 5.0, cfg.horizon_s)

    def closest_to_neighbour(action):
        me, _ = dense_path(swarm.pos_m[0, 0], 0.0, action, 5.0, cfg.horizon_s)
        return np.hypot(*(me - neighbour).T)[t <= cfg.neighbour_horizon_s].min()

    widest = grid[int(np.argmax(clearance))]
    assert widest > 0.5 and closest_to_neighbour(widest) < fixed.d_col_m
    assert decision.action[0, 0] < 0.0
    assert closest_to_neighbour(decision.action[0, 0]) >= fixed.d_col_m + cfg.margin_m


@settings(max_examples=100, deadline=None)
@given(
    heading=st.floats(-math.pi, math.pi),
    first=st.floats(-1.0, 1.0),
    second=st.floats(-1.0, 1.0),
    t=st.floats(0.0, 25.0),
)
def test_turns_held_over_steps_are_the_arcs_the_vehicle_flies(heading, first, second, t):
    """`_turns` against a dense integration of the turn rate, and one step of it against the
    one-step prediction (`sim.prediction.displacements`, what every other candidate uses)."""
    a_max, dt = VEHICLE.max_turn_rad, VEHICLE.dt_s
    z = _turns(np.array(heading), np.array([first, second]) * a_max, dt, np.array([t]))[0]
    fine = np.linspace(0.0, t, 4001)
    mid = 0.5 * (fine[1:] + fine[:-1])
    turned = np.where(mid < dt, first * mid / dt, first + second * np.clip(mid / dt - 1, 0, 1))
    h = heading + a_max * turned
    dense = complex(np.sum(np.diff(fine) * np.cos(h)), np.sum(np.diff(fine) * np.sin(h)))
    assert abs(z - dense) < 1e-5
    times = np.array([0.0, 1.0, 2.0, 7.5, 25.0])
    dx, dy = displacements(np.array(heading), np.array([first * a_max]), 1.0, dt, 25.0, 2)
    one = _turns(np.array(heading), np.array([first, 0.0]) * a_max, dt, times)
    assert np.allclose(one.real[[0, 1, 2, 4]], dx[0], atol=1e-9)
    assert np.allclose(one.imag[[0, 1, 2, 4]], dy[0], atol=1e-9)


@pytest.mark.parametrize("neighbour_horizon_s", [4.0, 6.0, 3.0])
def test_a_turn_wider_than_one_step_is_held_over_the_next_decision(neighbour_horizon_s):
    """A fixed-speed UAV 30 m from a static obstacle just right of its course: no heading of
    one step (at most 45°, then straight) clears it, a full left turn held for two steps (90°)
    does. The shield turns fully left now, whatever the proposal; with one-step candidates
    alone, nothing passes."""
    fixed = dataclasses.replace(VEHICLE, can_slow=False)
    swarm = lone_uav()
    threats = Threats(
        np.array([[[30.0, -4.0]]]), np.zeros((1, 1, 2)), np.ones((1, 1), bool), np.zeros((1, 1))
    )
    proposed = np.full((1, 1), -0.5)  # towards the obstacle's side
    cfg = ShieldConfig(mode="on", neighbour_horizon_s=neighbour_horizon_s)
    one_step = shield(dataclasses.replace(cfg, escape_steps=1), fixed, swarm, threats, proposed)
    assert not one_step.safe_exists[0, 0]
    decision = shield(cfg, fixed, swarm, threats, proposed)
    assert decision.safe_exists[0, 0] and not decision.safe_headings.any()
    assert decision.action[0, 0] == 1.0
    required = fixed.d_col_m + ShieldConfig().margin_m
    assert decision.flown_cpa_m[0, 0] >= required
    # the plan flown densely: a full left turn for two steps, then straight on
    t = np.linspace(0.0, ShieldConfig().horizon_s, 20001)
    h = fixed.max_turn_rad * np.clip(t / fixed.dt_s, 0.0, 2.0)
    step = np.diff(t) * fixed.cruise_m_s
    x = np.concatenate([[0.0], np.cumsum(step * np.cos(0.5 * (h[1:] + h[:-1])))])
    y = np.concatenate([[0.0], np.cumsum(step * np.sin(0.5 * (h[1:] + h[:-1])))])
    flown = np.hypot(x - 30.0, y + 4.0).min()
    assert flown >= required - 0.05
    assert abs(decision.flown_cpa_m[0, 0] - flown) < 0.25  # the chords' error, within the margin
    # the same obstacle known from an ADS-B report: no turn is held against a track
    tracked = dataclasses.replace(threats, intruder_age_s=np.full((1, 1), 0.5))
    assert not shield(cfg, fixed, swarm, tracked, proposed).safe_exists[0, 0]


def pacing_world(intruder_m: float) -> tuple[Swarm, Threats]:
    """A UAV heading east at 5 m/s, its target 1 km away 140° to its right; an intruder
    ``intruder_m`` away 120° to its right flies its way a little faster, between it and the
    target: flying straight on passes, and leads away from the target."""
    bearing, side = math.radians(-140.0), math.radians(-120.0)
    swarm = dataclasses.replace(
        lone_uav(), target_m=np.array([[[1e3 * math.cos(bearing), 1e3 * math.sin(bearing)]]])
    )
    threats = Threats(
        np.array([[[intruder_m * math.cos(side), intruder_m * math.sin(side)]]]),
        np.array([[[5.5, 0.0]]]),
        np.ones((1, 1), bool),
        np.zeros((1, 1)),
    )
    return swarm, threats


def test_a_uav_pacing_an_intruder_away_from_its_target_turns_back_behind_it():
    """The proposal (straight on) passes, but leads away from the target while the turn back
    towards it passes too: full right turns until the UAV points at the target, then straight
    on, checked against a dense integration of that plan. Only its first step is flown."""
    swarm, threats = pacing_world(60.0)
    proposed = np.zeros((1, 1))
    never = shield(ShieldConfig(mode="on", return_deg=180.0), VEHICLE, swarm, threats, proposed)
    assert not never.intervened[0, 0] and never.action[0, 0] == 0.0
    decision = shield(ShieldConfig(mode="on"), VEHICLE, swarm, threats, proposed)
    assert decision.intervened[0, 0] and decision.safe_exists[0, 0]
    assert decision.action[0, 0] == -1.0  # a full turn towards the target, on its side
    assert decision.proposed_cpa_m[0, 0] == never.flown_cpa_m[0, 0]
    # the plan flown densely: 45° right in each of three steps, 5° in the fourth (140°), then
    # straight on
    t, me = dense_turns([-45.0, -45.0, -45.0, -5.0], ShieldConfig().horizon_s)
    other = threats.intruder_pos_m[0, 0] + threats.intruder_vel_m_s[0, 0] * t[:, None]
    flown = np.hypot(*(me - other).T).min()
    required = VEHICLE.d_col_m + ShieldConfig().margin_m
    assert flown >= required
    assert abs(decision.flown_cpa_m[0, 0] - flown) < 0.25  # the chords' error, within the margin
    # monitor mode records it and flies the proposal
    watch = shield(ShieldConfig(mode="monitor"), VEHICLE, swarm, threats, proposed)
    assert watch.intervened[0, 0] and watch.action[0, 0] == 0.0
    assert watch.shield_action[0, 0] == -1.0


def dense_turns(turns_deg, horizon_s):
    """(times, positions (T, 2)) of the ideal test UAV from the origin heading east, turning by
    ``turns_deg`` in its successive steps, each at a constant rate over its step, then straight:
    a dense integration of the motion the simulator flies."""
    t = np.linspace(0.0, horizon_s, 25001)
    mid = 0.5 * (t[1:] + t[:-1])
    rates = np.radians(turns_deg) / VEHICLE.dt_s  # rad/s in each step
    into = np.clip(mid[:, None] - VEHICLE.dt_s * np.arange(len(rates)), 0.0, VEHICLE.dt_s)
    h = (into * rates).sum(axis=-1)
    step = np.diff(t) * VEHICLE.cruise_m_s
    x = np.concatenate([[0.0], np.cumsum(step * np.cos(h))])
    y = np.concatenate([[0.0], np.cumsum(step * np.sin(h))])
    return t, np.stack([x, y], axis=-1)


def test_with_no_room_to_turn_towards_the_target_the_uav_loops_the_other_way():
    """10 m nearer, the turn towards the target passes too close to the intruder; the long way
    round, a left loop of 220°, passes behind it (a dense integration agrees): its first step
    is flown. A second intruder pacing on the left, 30 m abeam, leaves neither way: the
    proposal stands."""
    swarm, threats = pacing_world(50.0)
    decision = shield(ShieldConfig(mode="on"), VEHICLE, swarm, threats, np.zeros((1, 1)))
    assert decision.intervened[0, 0] and decision.action[0, 0] == 1.0
    t, me = dense_turns([45.0, 45.0, 45.0, 45.0, 40.0], ShieldConfig().horizon_s)
    other = threats.intruder_pos_m[0, 0] + threats.intruder_vel_m_s[0, 0] * t[:, None]
    flown = np.hypot(*(me - other).T).min()
    assert flown >= VEHICLE.d_col_m + ShieldConfig().margin_m
    assert abs(decision.flown_cpa_m[0, 0] - flown) < 0.25
    left = Threats(
        np.concatenate([threats.intruder_pos_m, [[[0.0, 30.0]]]], axis=1),
        np.concatenate([threats.intruder_vel_m_s, [[[5.5, 0.0]]]], axis=1),
        np.ones((1, 2), bool),
        np.zeros((1, 2)),
    )
    boxed = shield(ShieldConfig(mode="on"), VEHICLE, swarm, left, np.zeros((1, 1)))
    assert not boxed.intervened[0, 0] and boxed.action[0, 0] == 0.0


BACK_DEG = 170.0
"""The bearing of the turn-back worlds' target, 1 km away, degrees (the UAV heads east)."""

OTHER_M = (-60.0, 25.0)
"""Where the turn-back worlds' other UAV is: 60 m behind the first and 25 m to its left."""


def no_intruders() -> Threats:
    """One environment without intruders."""
    return Threats(
        np.zeros((1, 0, 2)), np.zeros((1, 0, 2)), np.zeros((1, 0), bool), np.zeros((1, 0))
    )


def turn_back_world(
    heading_rad: float, target_m: Sequence[float], *, deciding: bool, speed_m_s: float
) -> Swarm:
    """A UAV at the origin heading east, its target 1 km away at `BACK_DEG`, and another UAV
    at `OTHER_M` heading ``heading_rad`` to ``target_m`` at ``speed_m_s`` (0: hovering where it
    arrived), decided in this decision or not (``deciding``: elsewhere, or parked)."""
    bearing = math.radians(BACK_DEG)
    return Swarm(
        pos_m=np.array([[[0.0, 0.0], OTHER_M]]),
        heading_rad=np.array([[0.0, heading_rad]]),
        target_m=np.array([[[1e3 * math.cos(bearing), 1e3 * math.sin(bearing)], target_m]]),
        deciding=np.array([[True, deciding]]),
        present=np.ones((1, 2), dtype=bool),
        speed_m_s=np.array([[5.0, speed_m_s]]),
    )


def test_the_turn_back_keeps_clear_of_a_parked_uav_over_the_whole_look_ahead():
    """The target 1 km behind, 170° to the left; a UAV hovers where it arrived 60 m behind and
    25 m to the left, on the way back, reached some 20 s after the turn: past the 4 s the
    shield checks the swarm's flying UAVs over, inside the look-ahead. It is kept clear of as
    a static intruder: the turn to the left does not pass, and the UAV loops back to the right
    instead. Without it, the UAV turns back to the left."""
    swarm = turn_back_world(0.0, OTHER_M, deciding=False, speed_m_s=0.0)
    none = no_intruders()
    cfg = ShieldConfig(mode="on")
    parked = shield(cfg, VEHICLE, swarm, none, np.zeros((1, 2)))
    assert parked.intervened[0, 0] and parked.action[0, 0] == -1.0
    gone = dataclasses.replace(swarm, present=np.array([[True, False]]))
    decision = shield(cfg, VEHICLE, gone, none, np.zeros((1, 2)))
    assert decision.intervened[0, 0] and decision.action[0, 0] == 1.0


def test_the_turn_back_keeps_a_uav_decided_elsewhere_on_its_arc_not_parked():
    """The parked world above, but the other UAV flies: another process decides it (`fly`
    over the swarm bus, where only this process's vehicles decide here), heading 170° at the
    cruise speed, the way the turn back to the left goes and as fast. It is a neighbour on its
    arc, gone ahead by the time the UAV follows: the turn to the left passes. Taken for parked
    where it is now, it would block it."""
    bearing = math.radians(BACK_DEG)
    ahead = [OTHER_M[0] + 1e3 * math.cos(bearing), OTHER_M[1] + 1e3 * math.sin(bearing)]
    swarm = turn_back_world(bearing, ahead, deciding=False, speed_m_s=5.0)
    none = no_intruders()
    cfg = ShieldConfig(mode="on")
    decision = shield(cfg, VEHICLE, swarm, none, np.zeros((1, 2)))
    assert decision.intervened[0, 0] and decision.action[0, 0] == 1.0
    assert decision.flown_cpa_m[0, 0] >= VEHICLE.d_col_m + cfg.margin_m
    stopped = dataclasses.replace(swarm, speed_m_s=np.array([[5.0, 0.0]]))
    parked = shield(cfg, VEHICLE, stopped, none, np.zeros((1, 2)))
    assert parked.intervened[0, 0] and parked.action[0, 0] == -1.0


def test_a_fitted_vehicle_turns_back_as_its_response_flies_it():
    """The pacing world flown by a fitted ArduCopter: its turn back is predicted through the
    response over two steps (90°), then its heading held; at 60 and 70 m the short way passes
    too close to the intruder and the UAV turns back the long way, away from it, at 80 m the
    short way passes, within the prediction's tolerance of the command stream replayed at
    10 ms."""
    prof = load_profile("arducopter")
    a_max, dt = VEHICLE.max_turn_rad, VEHICLE.dt_s
    t, ref, vel0 = dense_track(prof, 0.0, 0.0, 5.0, -a_max, 5.0, 5.0, dt, 25.0, -a_max)
    one = np.ones((1, 1))
    motion = Motion(
        vel0[None, None], 0 * one, 5 * one, prof.delay_s * one, prof.velocity_tau_s * one,
        prof.max_accel_m_s2 * one,
    )  # fmt: skip
    for intruder_m, way in ((60.0, 1.0), (70.0, 1.0), (80.0, -1.0)):
        swarm, threats = pacing_world(intruder_m)
        swarm = dataclasses.replace(swarm, motion=motion)
        decision = shield(ShieldConfig(mode="on"), VEHICLE, swarm, threats, np.zeros((1, 1)))
        assert decision.intervened[0, 0] and decision.action[0, 0] == way
        assert decision.flown_cpa_m[0, 0] >= VEHICLE.d_col_m + ShieldConfig().margin_m
    other = threats.intruder_pos_m[0, 0] + threats.intruder_vel_m_s[0, 0] * t[:, None]
    flown = np.hypot(*(ref - other).T).min()
    assert flown >= VEHICLE.d_col_m
    assert abs(decision.flown_cpa_m[0, 0] - flown) < 1.5


FAST = dataclasses.replace(VEHICLE, cruise_m_s=10.0)
"""The paper's speed: 20 m a step, its tightest turn a circle of 25.5 m radius, wider than d_col."""


def fast_arducopter() -> Motion:
    """The `Motion` of one fitted ArduCopter flying east at `FAST`'s 10 m/s, steady."""
    prof = load_profile("arducopter")
    one = np.ones((1, 1))
    return Motion(
        np.array([[[10.0, 0.0]]]), 0 * one, 10 * one, prof.delay_s * one,
        prof.velocity_tau_s * one, prof.max_accel_m_s2 * one,
    )  # fmt: skip


def circling_uav(target_m: tuple[float, float]) -> Swarm:
    """One UAV of `FAST` at the origin heading east at 10 m/s, its target at ``target_m``."""
    return dataclasses.replace(
        lone_uav(), target_m=np.array([[target_m]]), speed_m_s=np.full((1, 1), 10.0)
    )


def test_a_uav_circling_its_target_out_of_reach_flies_straight_out_of_the_circle():
    """The target at the centre of the UAV's tightest right turn: turning right (the proposal,
    towards the target) circles it 25.5 m away. The shield flies straight on instead, which
    passes; with ``fly_out`` off, with the target 10 m off the centre (the circle then comes
    within d_col of it), or for a fitted vehicle, the proposal stands."""
    radius = FAST.cruise_m_s * FAST.dt_s / FAST.max_turn_rad
    none = no_intruders()
    right = -np.ones((1, 1))
    swarm = circling_uav((0.0, -radius))
    decision = shield(ShieldConfig(mode="on"), FAST, swarm, none, right)
    assert decision.intervened[0, 0] and decision.safe_exists[0, 0]
    assert decision.action[0, 0] == 0.0 and decision.speed_m_s[0, 0] == FAST.cruise_m_s
    off = shield(ShieldConfig(mode="on", fly_out=False), FAST, swarm, none, right)
    assert not off.intervened[0, 0] and off.action[0, 0] == -1.0
    reached = shield(ShieldConfig(mode="on"), FAST, circling_uav((10.0, -radius)), none, right)
    assert not reached.intervened[0, 0] and reached.action[0, 0] == -1.0
    # a vehicle flown with its fitted response turns later and wider than the circle: left
    # to the policy
    motion = fast_arducopter()
    fitted = dataclasses.replace(swarm, motion=motion)
    assert not shield(ShieldConfig(mode="on"), FAST, fitted, none, right).intervened[0, 0]
    # flying away from the target (a left turn) is not circling it: the turn back's business
    left = shield(ShieldConfig(mode="on", return_deg=180.0), FAST, swarm, none, -right)
    assert not left.intervened[0, 0] and left.action[0, 0] == 1.0


def test_flying_out_is_checked_like_any_candidate():
    """An intruder at rest 45 m ahead: straight on passes within d_col of it, the circle does
    not. The proposal stands."""
    radius = FAST.cruise_m_s * FAST.dt_s / FAST.max_turn_rad
    ahead = Threats(
        np.array([[[45.0, 0.0]]]), np.zeros((1, 1, 2)), np.ones((1, 1), bool), np.zeros((1, 1))
    )
    decision = shield(
        ShieldConfig(mode="on"), FAST, circling_uav((0.0, -radius)), ahead, -np.ones((1, 1))
    )
    assert not decision.intervened[0, 0] and decision.action[0, 0] == -1.0


def test_a_uav_that_circled_its_target_arrives_once_it_flies_out():
    """Closed loop, a controller that always turns towards its target at full rate (as the
    policy circling it does), flown on exact arcs: alone it circles the target for 30 steps,
    never within d_col; behind the shield it flies one step straight out, then turns in, half
    way round the circle that now comes within d_col of the target, by the fifth step."""
    radius = FAST.cruise_m_s * FAST.dt_s / FAST.max_turn_rad
    target = np.array([0.0, -radius])
    none = no_intruders()

    def arc(pos, heading, turn, fraction):
        """Where an exact arc turning by ``turn`` over the step is at ``fraction`` of it."""
        chord = FAST.cruise_m_s * FAST.dt_s * fraction * np.sinc(turn * fraction / (2 * math.pi))
        mid = heading + 0.5 * turn * fraction
        return pos + chord * np.array([math.cos(mid), math.sin(mid)])

    def closest(cfg: ShieldConfig | None, steps: int) -> tuple[float, int]:
        """(closest approach to the target, first step within d_col or -1) over ``steps``."""
        pos, heading, best, when = np.zeros(2), 0.0, np.inf, -1
        for k in range(steps):
            gap = target - pos
            error = math.remainder(math.atan2(gap[1], gap[0]) - heading, math.tau)
            action = np.array([[np.clip(error / FAST.max_turn_rad, -1.0, 1.0)]])
            if cfg is not None:
                swarm = dataclasses.replace(
                    circling_uav(tuple(target)), pos_m=pos[None, None],
                    heading_rad=np.array([[heading]]),
                )  # fmt: skip
                action = shield(cfg, FAST, swarm, none, action).action
            turn = float(action[0, 0]) * FAST.max_turn_rad
            near = min(
                np.hypot(*(target - arc(pos, heading, turn, f))) for f in np.linspace(0, 1, 41)
            )
            best = min(best, float(near))
            if near < FAST.d_col_m and when < 0:
                when = k
            pos, heading = arc(pos, heading, turn, 1.0), heading + turn
        return best, when

    alone, never = closest(None, 30)
    assert never == -1 and alone > FAST.d_col_m
    shielded, step = closest(ShieldConfig(mode="on"), 30)
    assert 0 < step <= 5 and shielded < FAST.d_col_m


def test_the_turn_back_keeps_clear_of_a_flying_neighbour_for_longer():
    """The target 1 km behind, 170° to the left; a UAV of the swarm 60 m behind and 25 m to the
    left flies east on the line the turn back to the left would follow west: they would meet
    some 10 s on. Checked over the 4 s of any other candidate, the turn to the left passes
    (its predicted closest approach to that UAV a few metres); over the turn back's own 12 s it
    does not, and the UAV loops back to the right, clear of it."""
    swarm = turn_back_world(0.0, [1e4, OTHER_M[1]], deciding=True, speed_m_s=5.0)
    none = no_intruders()
    short = ShieldConfig(mode="on", return_neighbour_horizon_s=4.0)
    brief = shield(short, VEHICLE, swarm, none, np.zeros((1, 2)))
    assert brief.action[0, 0] == 1.0 and brief.flown_cpa_m[0, 0] < VEHICLE.d_col_m
    decision = shield(ShieldConfig(mode="on"), VEHICLE, swarm, none, np.zeros((1, 2)))
    assert decision.action[0, 0] == -1.0
    assert decision.flown_cpa_m[0, 0] >= VEHICLE.d_col_m + ShieldConfig().margin_m
    assert not decision.intervened[0, 1] and decision.action[0, 1] == 0.0


@pytest.mark.parametrize(
    ("beside_m", "way", "fitted_way"),
    [(25.5, 1.0, 1.0), (40.0, -1.0, 1.0), (60.0, -1.0, -1.0)],
)
def test_a_target_its_tightest_turn_circles_out_of_reach_is_reached_the_long_way(
    beside_m, way, fitted_way
):
    """A target beside the UAV of `FAST`, 5 m behind it on the right, the UAV flying straight
    away (the proposal): turning right at a_max flies a circle of 25.5 m radius centred 25.5 m
    to the right. 25.5 m beside, the target is 5 m from that centre: the circle never comes
    within d_col of it, so the UAV turns back the long way, to the left. 40 m beside (15.3 m
    from the centre) the circle passes 10 m from it, and 60 m beside outside it: the UAV turns
    right. Nothing else around. A fitted vehicle turns later and wider than the circle: a
    target anywhere inside it counts as out of reach the short way, and it turns back the
    long way to it; to a target outside the circle, the short way."""
    swarm = circling_uav((-5.0, -beside_m))
    none = no_intruders()
    decision = shield(ShieldConfig(mode="on"), FAST, swarm, none, np.zeros((1, 1)))
    assert decision.intervened[0, 0] and decision.action[0, 0] == way
    motion = fast_arducopter()
    fitted = shield(
        ShieldConfig(mode="on"), FAST, dataclasses.replace(swarm, motion=motion), none,
        np.zeros((1, 1)),
    )  # fmt: skip
    assert fitted.intervened[0, 0] and fitted.action[0, 0] == fitted_way


def test_with_a_circle_no_wider_than_d_col_every_target_is_reached_the_short_way():
    """At 5 m/s the tightest turn's circle (12.7 m) lies within d_col of anything inside it: a
    target beside the UAV and behind it is turned to the short way, however near."""
    none = no_intruders()
    for beside_m in (10.0, 24.0, 30.0):
        swarm = dataclasses.replace(lone_uav(), target_m=np.array([[[-5.0, -beside_m]]]))
        decision = shield(ShieldConfig(mode="on"), VEHICLE, swarm, none, np.zeros((1, 1)))
        assert decision.intervened[0, 0] and decision.action[0, 0] == -1.0


def test_a_fitted_vehicle_holds_its_turn_as_its_response_flies_it():
    """A fitted ArduCopter at 5 m/s that cannot slow, 34 m from a static obstacle just right of
    its course: late and wide, no heading of one step clears it; a full left turn held for two
    steps does, predicted through the response within the prediction's tolerance of the
    command stream replayed at 10 ms."""
    prof = load_profile("arducopter")
    fixed = dataclasses.replace(VEHICLE, can_slow=False)
    a_max, dt = fixed.max_turn_rad, fixed.dt_s
    _, ref, vel0 = dense_track(prof, 0.0, 0.0, 5.0, a_max, 5.0, 5.0, dt, 25.0, a_max)
    one = np.ones((1, 1))
    motion = Motion(
        vel0[None, None], 0 * one, 5 * one, prof.delay_s * one, prof.velocity_tau_s * one,
        prof.max_accel_m_s2 * one,
    )  # fmt: skip
    swarm = dataclasses.replace(lone_uav(), motion=motion)
    obstacle = np.array([34.0, -4.0])
    threats = Threats(obstacle[None, None], np.zeros((1, 1, 2)), np.ones((1, 1), bool), 0 * one)
    proposed = np.full((1, 1), -0.5)
    cfg = ShieldConfig(mode="on")
    one_step = shield(dataclasses.replace(cfg, escape_steps=1), fixed, swarm, threats, proposed)
    assert not one_step.safe_exists[0, 0]
    decision = shield(cfg, fixed, swarm, threats, proposed)
    assert decision.safe_exists[0, 0] and decision.action[0, 0] == 1.0
    flown = np.hypot(*(ref - obstacle).T).min()
    assert abs(decision.flown_cpa_m[0, 0] - flown) < 1.5


def test_where_nothing_passes_a_held_turn_can_be_the_least_dangerous():
    """A fixed-speed UAV between two static obstacles, one 32 m ahead just right of its course,
    one to its left: nothing passes, of one step or held. The least dangerous heading of one
    step turns left, into a collision; a full right turn held for two steps keeps d_col from
    both (not the margin): the fallback flies its first step, and says how close it comes."""
    fixed = dataclasses.replace(VEHICLE, can_slow=False)
    swarm = lone_uav()
    obstacles = np.array([[32.0, -4.0], [23.0, 29.0]])
    threats = Threats(obstacles[None], np.zeros((1, 2, 2)), np.ones((1, 2), bool), np.zeros((1, 2)))
    proposed = np.full((1, 1), 0.5)
    cfg = ShieldConfig(mode="on")
    one_step = shield(dataclasses.replace(cfg, escape_steps=1), fixed, swarm, threats, proposed)
    assert not one_step.safe_exists[0, 0] and one_step.action[0, 0] > 0.0
    assert one_step.flown_cpa_m[0, 0] < fixed.d_col_m
    decision = shield(cfg, fixed, swarm, threats, proposed)
    assert not decision.safe_exists[0, 0] and decision.intervened[0, 0]
    assert decision.action[0, 0] == -1.0 and decision.speed_m_s[0, 0] == fixed.cruise_m_s
    # the plan flown densely: a full right turn for two steps, then straight on
    t = np.linspace(0.0, cfg.horizon_s, 20001)
    h = -fixed.max_turn_rad * np.clip(t / fixed.dt_s, 0.0, 2.0)
    step = np.diff(t) * fixed.cruise_m_s
    x = np.concatenate([[0.0], np.cumsum(step * np.cos(0.5 * (h[1:] + h[:-1])))])
    y = np.concatenate([[0.0], np.cumsum(step * np.sin(0.5 * (h[1:] + h[:-1])))])
    flown = np.hypot(x[:, None] - obstacles[:, 0], y[:, None] - obstacles[:, 1]).min()
    assert fixed.d_col_m <= flown < fixed.d_col_m + cfg.margin_m
    assert abs(decision.flown_cpa_m[0, 0] - flown) < 0.25  # the chords' error


def test_the_fallback_weighs_a_collision_by_how_near_and_how_sure_it_is():
    """The coming step's segments weigh most for any threat; within the neighbour look-ahead an
    intruder's (flown straight, as predicted) more than a neighbour's (it decides again)."""
    times = np.array([0.0, 1.0, 2.0, 4.0, 25.0])
    weight = _severity(times, 2.0, 4.0, np.array([False, True]))
    # the segments past the neighbour look-ahead weigh nothing: they are not kept
    assert weight[:, 0].tolist() == [COLLISION_NOW, COLLISION_NOW, COLLISION_INTRUDER_SOON]
    assert weight[:, 1].tolist() == [COLLISION_NOW, COLLISION_NOW, COLLISION_NEIGHBOUR_SOON]
    # a look-ahead inside the coming step still weighs the whole of it
    assert _severity(times, 2.0, 1.0, np.array([True])).ravel().tolist() == [COLLISION_NOW] * 2
    assert COLLISION_NOW > COLLISION_INTRUDER_SOON > COLLISION_NEIGHBOUR_SOON > 0


METRES = st.integers(-30_000, 30_000).map(lambda dm: dm / 10)
"""Clearances to a decimetre, within the few kilometres a check sees."""


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(METRES, METRES, st.integers(0, COLLISION_NOW)), min_size=2, max_size=8))
def test_a_less_dangerous_candidate_always_ranks_higher(candidates):
    clearance, near, danger = (np.array([c[i] for c in candidates])[None] for i in range(3))
    rank = _rank(clearance, near, danger.astype(np.uint8))[0]
    for a, (ca, na, da) in enumerate(candidates):
        for b, (cb, nb, db) in enumerate(candidates):
            if da < db:
                assert rank[a] > rank[b]
            elif da == db == 0 and ca > cb:
                assert rank[a] > rank[b]  # no predicted collision: the largest clearance
            elif da == db > 0 and na > nb:
                assert rank[a] > rank[b]  # the same danger: the most room where it weighs


def test_uncertainty_of_old_reports_widens_what_is_required():
    swarm = lone_uav()
    # An intruder passing 26 m abeam: clear with a fresh report, not with a 10 s old one.
    pos, vel = np.array([[[60.0, 26.0]]]), np.array([[[-5.0, 0.0]]])
    fresh = Threats(pos, vel, np.ones((1, 1), bool), np.zeros((1, 1)))
    stale = Threats(pos, vel, np.ones((1, 1), bool), np.full((1, 1), 20.0))
    cfg = ShieldConfig(mode="on", track_growth_m_s=0.2)
    assert not shield(cfg, VEHICLE, swarm, fresh, np.zeros((1, 1))).intervened[0, 0]
    assert shield(cfg, VEHICLE, swarm, stale, np.zeros((1, 1))).intervened[0, 0]


@pytest.mark.parametrize(
    ("scenario", "dynamics"), [("3u2o", "ideal"), ("50u8o", "ideal"), ("7u2o", "arducopter")]
)
def test_on_a_simulator_state_every_output_is_in_range(scenario, dynamics):
    cfg = load_scenario(scenario, dynamics=dynamics)
    sim = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(1)
    state = sim.initial_state(rng, 3)
    for _ in range(6):
        prop = rng.uniform(-1, 1, state.heading_rad.shape)
        d = shield_state(ShieldConfig(mode="on"), cfg, state, prop)
        assert ((d.action >= -1) & (d.action <= 1)).all()
        assert ((d.speed_m_s >= 0) & (d.speed_m_s <= cfg.uav.speed_m_s)).all()
        assert not d.intervened[~state.active].any()
        state, _ = sim.step(state, d.action, rng, speeds_m_s=d.speed_m_s)


def test_the_fitted_vehicle_is_predicted_on_the_track_it_flies():
    """A fitted ArduCopter at 10 m/s that was turning right, its velocity still 24° left of
    its commanded heading, proposes a full left turn past a static intruder: the shield with
    its response (``motion``) predicts the closest approach of the command stream replayed at
    10 ms within 0.5 m; the ideal arc misses it by metres."""
    prof, a_max = load_profile("arducopter"), math.pi / 4
    fast = Vehicle(d_col_m=20.0, dt_s=2.0, max_turn_rad=a_max, cruise_m_s=10.0)
    _, track, vel0 = dense_track(prof, 0.0, -a_max, 10.0, a_max, 10.0, 10.0, 2.0, 25.0)
    intruder = np.array([30.0, 40.0])
    flown = float(np.hypot(*(track - intruder).T).min())
    motion = Motion(
        vel0[None, None], np.full((1, 1), -a_max), np.full((1, 1), 10.0),
        np.full((1, 1), prof.delay_s), np.full((1, 1), prof.velocity_tau_s),
        np.full((1, 1), prof.max_accel_m_s2),
    )  # fmt: skip
    fitted = dataclasses.replace(lone_uav(), speed_m_s=np.full((1, 1), 10.0), motion=motion)
    threats = Threats(
        intruder[None, None], np.zeros((1, 1, 2)), np.ones((1, 1), bool), np.zeros((1, 1))
    )
    cfg = ShieldConfig(mode="on")
    left = np.ones((1, 1))
    predicted = shield(cfg, fast, fitted, threats, left).proposed_cpa_m[0, 0]
    ideal = shield(cfg, fast, dataclasses.replace(fitted, motion=None), threats, left)
    assert abs(predicted - flown) < 0.5
    assert ideal.proposed_cpa_m[0, 0] < flown - 3.0


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="mode"):
        ShieldConfig(mode="maybe")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="vehicle_model"):
        ShieldConfig(vehicle_model="exact")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="headings"):
        ShieldConfig(headings=4)
    with pytest.raises(ValueError, match="horizon"):
        ShieldConfig(horizon_s=0.0)
    with pytest.raises(ValueError, match="track_horizon_s"):
        ShieldConfig(track_horizon_s=0.0)
    for degrees in (0.0, -5.0, 180.5, math.nan):
        with pytest.raises(ValueError, match="return_deg must be in"):
            ShieldConfig(return_deg=degrees)
    for seconds in (0.0, -1.0, math.inf):
        with pytest.raises(ValueError, match="return_neighbour_horizon_s must be"):
            ShieldConfig(return_neighbour_horizon_s=seconds)
    for steps in (0, ESCAPE_STEPS_MAX + 1):
        with pytest.raises(ValueError, match="escape_steps must be 1 to 4"):
            ShieldConfig(escape_steps=steps)


@pytest.mark.parametrize(
    ("dt_s", "horizon_s", "neighbour_s"),
    [(2.0, 10.0, 4.0), (2.0, 2.0, 4.0), (1.5, 7.3, 3.1), (0.3, 0.9, 5.0), (2.0, 10.0, 1.0)],
)
def test_shield_times_are_the_predictions_time_points(
    dt_s: float, horizon_s: float, neighbour_s: float
) -> None:
    """The shield's instants are `time_points`' at its chords, bit for bit, plus the split."""
    from sim.prediction import time_points
    from sim.shield import CHORDS, _times

    times, split = _times(dt_s, horizon_s, (neighbour_s,))
    if not split:
        np.testing.assert_array_equal(times, time_points(dt_s, horizon_s, CHORDS))
    else:
        assert times[-2] == neighbour_s
        np.testing.assert_array_equal(np.delete(times, -2), time_points(dt_s, horizon_s, CHORDS))
        assert split == [pytest.approx((neighbour_s - dt_s) / (horizon_s - dt_s))]


def test_two_cuts_split_the_straight_part_in_order_and_interpolate_it_exactly():
    """The neighbour and the track horizons both cut the straight part; the displacements at
    the cuts lie on the straight line, the time flown from the arc's end."""
    from sim.prediction import displacements
    from sim.shield import CHORDS, _at_times, _times

    times, split = _times(2.0, 25.0, (10.0, 4.0, 30.0))
    np.testing.assert_array_equal(times[CHORDS:], [2.0, 4.0, 10.0, 25.0])
    xy = displacements(np.array([0.3]), np.array([[0.5]]), 1.0, 2.0, 25.0, CHORDS)
    x, y = _at_times(xy, split)
    run = np.hypot(x[..., CHORDS:] - x[..., CHORDS, None], y[..., CHORDS:] - y[..., CHORDS, None])
    np.testing.assert_allclose(run[0, 0], times[CHORDS:] - 2.0, atol=1e-9)


def final_conflicts(cfg, swarm, decision):
    """UAV pairs (env, i, j) whose flown decisions come within d_col inside the neighbour
    horizon (dense simulation of both)."""
    b, n = decision.action.shape
    t = np.linspace(0.0, cfg.horizon_s, DENSE + 1)
    ahead = t <= cfg.neighbour_horizon_s
    out = set()
    for e in range(b):
        paths = [
            dense_path(
                swarm.pos_m[e, i],
                swarm.heading_rad[e, i],
                decision.action[e, i],
                decision.speed_m_s[e, i],
                cfg.horizon_s,
            )[0]
            for i in range(n)
        ]
        for i in range(n):
            for j in range(i + 1, n):
                gap = np.hypot(*(paths[i] - paths[j]).T)[ahead].min()
                if gap < VEHICLE.d_col_m:
                    out.add((e, i, j))
    return out


def test_the_second_pass_keeps_uavs_from_turning_into_each_others_turns():
    """One pass checks each UAV against its neighbours' proposals; where both turn, their
    turns can meet. The second checks against the turns too: the pair of this world (found
    among random ones) collides after one pass and not after two, and over 20 random worlds
    of 16 environments the second pass leaves fewer pairs in conflict."""
    total = {1: 0, 2: 0}
    for seed in range(20):
        rng = np.random.default_rng(seed)
        swarm, threats = random_world(rng, 16, 3, 2)
        prop = rng.uniform(-1, 1, (16, 3))
        found = {}
        for passes in (1, 2):
            cfg = ShieldConfig(mode="on", passes=passes)
            found[passes] = final_conflicts(cfg, swarm, shield(cfg, VEHICLE, swarm, threats, prop))
            total[passes] += len(found[passes])
        if seed == 4:
            assert (6, 0, 2) in found[1] and (6, 0, 2) not in found[2]
    assert total[2] < total[1]


def test_a_second_pass_changes_nothing_where_the_first_changed_nothing():
    """Environments where the first pass turned no UAV keep its decisions, while the second
    pass runs for the others of the batch."""
    rng = np.random.default_rng(3)
    swarm, _ = random_world(rng, 16, 3, 0)
    none = Threats(
        np.zeros((16, 0, 2)), np.zeros((16, 0, 2)), np.zeros((16, 0), bool), np.zeros((16, 0))
    )
    prop = rng.uniform(-1, 1, (16, 3))
    one = shield(ShieldConfig(mode="on", passes=1), VEHICLE, swarm, none, prop)
    keep = ~one.intervened.any(axis=-1)
    assert keep.any() and not keep.all()
    two = shield(ShieldConfig(mode="on", passes=2), VEHICLE, swarm, none, prop)
    for field in ("action", "speed_m_s", "intervened"):
        np.testing.assert_array_equal(getattr(one, field)[keep], getattr(two, field)[keep])
    for field in ("flown_cpa_m", "proposed_cpa_m"):  # float32 sums over other batch shapes
        np.testing.assert_allclose(getattr(one, field)[keep], getattr(two, field)[keep], 1e-6)


def test_passes_must_be_at_least_one():
    with pytest.raises(ValueError, match="passes must be >= 1"):
        ShieldConfig(passes=0)


def test_the_second_pass_is_skipped_where_the_first_passed_every_float64_proposal(monkeypatch):
    """A passing proposal comes back as float32: that rounding is no change, and no second
    pass runs (nor any arc is added) for it."""
    import sim.shield as shield_module

    calls = []
    real = shield_module._decide
    monkeypatch.setattr(shield_module, "_decide", lambda *a: calls.append(len(a[-1])) or real(*a))
    rng = np.random.default_rng(5)
    swarm, _ = random_world(rng, 4, 1, 0)  # one UAV each, nothing around: every proposal passes
    none = Threats(
        np.zeros((4, 0, 2)), np.zeros((4, 0, 2)), np.zeros((4, 0), bool), np.zeros((4, 0))
    )
    prop = rng.uniform(-1, 1, (4, 1))  # float64, not float32-exact
    d = shield(ShieldConfig(mode="on", passes=2), VEHICLE, swarm, none, prop)
    assert not d.intervened.any() and calls == [1]


def test_straight_neighbours_make_each_decision_the_uavs_own():
    """With ``neighbour_arcs="straight"`` each UAV keeps clear of its neighbours flying on at
    their heading: its decision is the one-pass decision of a swarm whose other UAVs all propose
    to fly straight on, whatever they do propose (so it is a function of what that UAV sees)."""
    straight = ShieldConfig(mode="on", neighbour_arcs="straight")
    one_pass = ShieldConfig(mode="on", passes=1, give_way=0)  # no neighbour makes room
    changed = 0
    for seed in range(12):
        rng = np.random.default_rng(seed)
        swarm, threats = random_world(rng, 8, 3, 2)
        prop = rng.uniform(-1, 1, (8, 3))
        got = shield(straight, VEHICLE, swarm, threats, prop)
        for uav in range(3):
            alone = np.zeros_like(prop)
            alone[:, uav] = prop[:, uav]
            want = shield(one_pass, VEHICLE, swarm, threats, alone)
            np.testing.assert_array_equal(got.action[:, uav], want.action[:, uav])
            np.testing.assert_array_equal(got.intervened[:, uav], want.intervened[:, uav])
        proposals = shield(ShieldConfig(mode="on"), VEHICLE, swarm, threats, prop)
        changed += int((proposals.action != got.action).sum())
    assert changed > 0  # the two expectations do differ on these worlds


def test_unknown_neighbour_arcs_are_refused():
    with pytest.raises(ValueError, match="neighbour_arcs must be one of proposals, straight"):
        ShieldConfig(neighbour_arcs="guess")  # type: ignore[arg-type]


def test_fitted_vehicles_carry_their_motion_and_a_hovering_one_is_held_where_it_is(monkeypatch):
    """On a state flown with a fitted response the shield gets every UAV's velocity, last
    command and response; a UAV hovering at its target, braking still, at rest where it is;
    with ``vehicle_model`` "ideal", or an ideal vehicle, no motion at all."""
    import sim.shield as shield_module

    seen = []

    def spy(cfg, vehicle, swarm, threats, proposed):
        seen.append(swarm)
        return shield(cfg, vehicle, swarm, threats, proposed)

    monkeypatch.setattr(shield_module, "shield", spy)
    cfg = load_scenario("3u1o", dynamics="arducopter", arrival="hover")
    sim = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(3)
    state = sim.initial_state(rng, 1)
    # one UAV arrives now: its target put right under it, the others' far ahead
    target = state.target_m.copy()
    target[0, 0] = state.pos_m[0, 0] + 12.0 * state.vel_m_s[0, 0] / 10.0
    state = dataclasses.replace(state, target_m=target)
    state, _ = sim.step(state, np.zeros((1, 3)), rng)
    hovering = state.hovering(cfg.arrival)
    assert hovering[0, 0] and not hovering[0, 1:].any()
    assert np.hypot(*state.vel_m_s[0, 0]) > 1.0  # still braking
    on = ShieldConfig(mode="on")
    shield_state(on, cfg, state, np.zeros((1, 3)))
    motion = seen[-1].motion
    assert motion is not None
    np.testing.assert_array_equal(motion.vel_m_s[0, 0], 0.0)
    assert motion.last_speed_m_s[0, 0] == 0.0
    np.testing.assert_array_equal(motion.vel_m_s[0, 1:], state.vel_m_s[0, 1:])
    assert (motion.delay_s == load_profile("arducopter").delay_s).all()
    shield_state(dataclasses.replace(on, vehicle_model="ideal"), cfg, state, np.zeros((1, 3)))
    assert seen[-1].motion is None
    ideal = load_scenario("3u1o", arrival="hover")
    shield_state(on, ideal, SwarmSim(ideal, scored=False).initial_state(rng, 1), np.zeros((1, 3)))
    assert seen[-1].motion is None


def two_abreast() -> tuple[Swarm, Threats]:
    """Two fixed-speed UAVs flying east 24 m apart (d_col 20 m), an intruder closing from ahead
    a little to the left of the right-hand one (A, at the origin; B to its left)."""
    swarm = Swarm(
        pos_m=np.array([[[0.0, 0.0], [0.0, 24.0]]]),
        heading_rad=np.zeros((1, 2)),
        target_m=np.array([[[1e4, 0.0], [1e4, 24.0]]]),
        deciding=np.ones((1, 2), bool),
        present=np.ones((1, 2), bool),
        speed_m_s=np.full((1, 2), 5.0),
    )
    threats = Threats(
        np.array([[[66.0, 6.0]]]), np.array([[[-4.7, -1.1]]]), np.ones((1, 1), bool),
        np.zeros((1, 1)),
    )  # fmt: skip
    return swarm, threats


def test_a_boxed_in_uav_gets_room_from_its_neighbour():
    """A has nothing that passes: the headings that clear the intruder (left) run into B, who
    flies on. Giving way, B turns left too and A follows it past the intruder; both decisions
    checked again by the independent dense simulation against the other's flown arc."""
    fixed = Vehicle(20.0, 2.0, math.pi / 4, 5.0, can_slow=False)
    swarm, threats = two_abreast()
    proposed = np.zeros((1, 2))
    boxed = ShieldConfig(mode="on", escape_steps=1, give_way=0, track_growth_m_s=0.0)
    before = shield(boxed, fixed, swarm, threats, proposed)
    assert not before.safe_exists[0, 0] and before.safe_exists[0, 1]
    assert before.action[0, 1] == 0.0  # B's proposal passed: it flies on
    given = dataclasses.replace(boxed, give_way=6)
    after = shield(given, fixed, swarm, threats, proposed)
    assert after.safe_exists.all() and after.intervened.all()
    assert after.action[0, 0] > 0.0 and after.action[0, 1] > 0.0  # both turn left
    for uav in (0, 1):
        action = after.action[0, uav]
        assert dense_clearance(given, swarm, threats, 0, uav, action, 5.0, after.action) >= -0.3
    # monitor mode records the same decision and flies the proposals
    watched = shield(dataclasses.replace(given, mode="monitor"), fixed, swarm, threats, proposed)
    np.testing.assert_array_equal(watched.shield_action, after.shield_action)
    np.testing.assert_array_equal(watched.action, proposed.astype(np.float32))


def test_giving_way_needs_a_neighbour_that_decides():
    """A neighbour that does not decide (hovering, or another controller's) cannot make room:
    the decision is the one without giving way."""
    fixed = Vehicle(20.0, 2.0, math.pi / 4, 5.0, can_slow=False)
    swarm, threats = two_abreast()
    swarm = dataclasses.replace(swarm, deciding=np.array([[True, False]]))
    proposed = np.zeros((1, 2))
    cfg = ShieldConfig(mode="on", escape_steps=1)
    without = shield(dataclasses.replace(cfg, give_way=0), fixed, swarm, threats, proposed)
    with_it = shield(cfg, fixed, swarm, threats, proposed)
    for f in dataclasses.fields(without):
        np.testing.assert_array_equal(getattr(with_it, f.name), getattr(without, f.name))


GIVE_WAY_CHECK = ShieldConfig(mode="on", escape_steps=1, horizon_s=10.0, track_growth_m_s=0.0)
"""The random crowds' shield: one-step headings alone, an exact dense check."""


def random_crowd(seed):
    """Three environments of six UAVs and three intruders at random, and their proposals,
    decided without and with giving way."""
    rng = np.random.default_rng(seed)
    swarm, threats = random_world(rng, 3, 6, 3)
    proposed = rng.uniform(-1.0, 1.0, (3, 6))
    cfg = GIVE_WAY_CHECK
    without = shield(dataclasses.replace(cfg, give_way=0), VEHICLE, swarm, threats, proposed)
    with_it = shield(cfg, VEHICLE, swarm, threats, proposed)
    return swarm, threats, proposed, without, with_it


def test_giving_way_frees_uavs_in_random_crowds():
    """The property below is not empty: in the crowds of seeds 0–9, UAVs with nothing that
    passed do pass once their neighbours give way (7 of 48 at the defaults)."""
    freed = 0
    for seed in range(10):
        *_, without, with_it = random_crowd(seed)
        freed += int((with_it.safe_exists & ~without.safe_exists).sum())
    assert freed > 0


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_giving_way_never_takes_a_passing_candidate_away(seed):
    """Crowds at random: with giving way, every UAV that had something that passes still
    has, the proposals that passed are flown unchanged unless a neighbour gave way, and a UAV
    freed now passes against what its neighbours fly (the dense check)."""
    swarm, threats, _, without, with_it = random_crowd(seed)
    cfg = GIVE_WAY_CHECK
    assert not (without.safe_exists & ~with_it.safe_exists).any()
    unchanged = (with_it.action == without.action).all(axis=-1)
    freed = with_it.safe_exists & ~without.safe_exists
    assert (unchanged | freed.any(axis=-1)).all()
    flown = dataclasses.replace(swarm, speed_m_s=with_it.speed_m_s)  # the neighbours' speeds
    for env, uav in zip(*np.nonzero(freed), strict=True):
        action, speed = with_it.action[env, uav], with_it.speed_m_s[env, uav]
        clear = dense_clearance(cfg, flown, threats, env, uav, action, speed, with_it.action)
        assert clear >= -0.3


def test_giving_way_in_some_environments_decides_them_as_the_whole_shield_does():
    """`give_way` on a subset of environments (the offline evaluation's, where its planner found
    no plan): each environment's decision is the one `shield` makes for the whole batch, and
    it frees UAVs there, so the comparison is not of decisions nothing changed."""
    freed = 0
    for seed in range(10):
        swarm, threats, proposed, without, with_it = random_crowd(seed)
        envs = np.array([2, 0])
        some = give_way(GIVE_WAY_CHECK, VEHICLE, swarm, threats, proposed, without, envs)
        for f in dataclasses.fields(with_it):
            np.testing.assert_array_equal(getattr(some, f.name), getattr(with_it, f.name)[envs])
        freed += int((some.safe_exists & ~without.safe_exists[envs]).sum())
    assert freed > 0


def test_give_way_below_zero_is_refused():
    with pytest.raises(ValueError, match="give_way"):
        ShieldConfig(give_way=-1)
