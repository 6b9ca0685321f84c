"""The own-view separation penalty: its prediction, its shape, its gradient, and a run using it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from test_generalist_ppo import tiny_ppo_run

from policies.generalist_train import with_layout
from policies.own_view import OwnView
from sim.errors import ConfigError
from sim.observation import NEIGHBOUR_COLUMNS, ObservationLayout
from sim.prediction import closest_approach, displacements
from sim.scenarios import load_scenario
from sim.swarm import SwarmSim

LAYOUT = ObservationLayout(8, 200.0, 2 * math.pi, 10.0, max_neighbours=6, version=2)


def scenario():
    """3u2o with the generalist's sensing: every other UAV is in a row."""
    return with_layout(load_scenario("3u2o"), LAYOUT)


def view(cfg, horizon_s=4.0, factor=1.5):
    return OwnView.of(LAYOUT, [cfg], horizon_s, factor)


def test_the_prediction_from_the_rows_is_the_worlds_own():
    """Each UAV's closest approaches, read from its rows, are those of the true state's paths."""
    cfg = scenario()
    sim = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(3)
    state = sim.initial_state(rng, 4)
    for _ in range(2):  # somewhere along the way, headings apart
        state, _ = sim.step(state, rng.uniform(-0.5, 0.5, (4, cfg.uav.count)), rng)
    assert state.active.all()  # every UAV still flying, each seen by the others
    obs = sim.observe(state, layout=LAYOUT).flat()  # (B, N, D)
    action = rng.uniform(-1, 1, obs.shape[:-1])
    got = view(cfg).closest(torch.from_numpy(obs), torch.from_numpy(action)).numpy()

    h = 4.0
    t = np.append(np.linspace(0.0, cfg.dt_s, 5), h)
    own_x, own_y = displacements(
        state.heading_rad,
        (action * cfg.uav.max_turn_rad)[..., None],
        cfg.uav.speed_m_s,
        cfg.dt_s,
        h,
    )  # (B, N, 1, P): one candidate each
    n = cfg.uav.count
    for b in range(4):
        for i in range(n):
            expected = []
            for j in range(n):
                if j == i:
                    continue
                rel = state.pos_m[b, j] - state.pos_m[b, i]
                vel = state.vel_m_s[b, j]
                rx = rel[0] + vel[0] * t - own_x[b, i, 0]
                ry = rel[1] + vel[1] * t - own_y[b, i, 0]
                expected.append(float(closest_approach(rx, ry)))
            finite = np.sort(got[b, i][np.isfinite(got[b, i])])
            np.testing.assert_allclose(finite, np.sort(expected), atol=0.02)  # float32 rows
            assert np.isinf(got[b, i]).sum() == LAYOUT.max_neighbours - (n - 1)


def one_neighbour(x_m, y_m, vx_m_s=0.0, vy_m_s=0.0):
    """A flat observation (D,) of a UAV flying at 10 m/s with one neighbour at (x, y), Δv."""
    obs = np.zeros(LAYOUT.size, dtype=np.float32)
    blocks = LAYOUT.blocks()
    obs[2] = 1.0  # own velocity: the UAV speed, straight ahead
    row = obs[blocks["neighbours"]].reshape(LAYOUT.max_neighbours, NEIGHBOUR_COLUMNS)
    row[0, :5] = [x_m / 200.0, y_m / 200.0, vx_m_s / 10.0, vy_m_s / 10.0, np.hypot(x_m, y_m) / 200]
    obs[blocks["neighbours"]] = row.reshape(-1)
    obs[blocks["neighbour_mask"].start] = 1.0
    return torch.from_numpy(obs)


@pytest.mark.parametrize(
    ("distance_m", "expected"), [(40.0, 0.0), (30.0, 0.0), (25, 0.25), (20, 1)]
)
def test_the_penalty_starts_at_f_dcol_and_is_one_at_dcol(distance_m, expected):
    """A wingman abeam at the same velocity stays where it is: the closest approach is d."""
    cfg = scenario()
    obs = one_neighbour(0.0, distance_m)
    assert view(cfg).closest(obs, torch.tensor(0.0))[0] == pytest.approx(distance_m, abs=1e-3)
    assert float(view(cfg).penalty(obs, torch.tensor(0.0))) == pytest.approx(expected, abs=1e-4)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_the_gradient_turns_away_from_a_neighbour_ahead(side):
    """A neighbour 40 m ahead, 5 m to one side, flying at us: turning away lowers the penalty."""
    cfg = scenario()
    obs = one_neighbour(40.0, 5.0 * side, vx_m_s=-20.0)
    action = torch.tensor(0.0, requires_grad=True)
    view(cfg).penalty(obs, action).backward()
    assert action.grad is not None and float(action.grad) * side > 0  # away: the other sign


def test_no_neighbour_costs_nothing_and_has_a_finite_gradient():
    cfg = scenario()
    obs = torch.zeros(3, LAYOUT.size)
    obs[:, 2] = 1.0
    action = torch.zeros(3, requires_grad=True)
    penalty = view(cfg).penalty(obs, action)
    penalty.sum().backward()
    assert torch.all(penalty == 0) and torch.all(torch.isfinite(action.grad))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16), action=st.floats(-1, 1))
def test_the_order_of_the_rows_does_not_matter(seed, action):
    cfg = scenario()
    rng = np.random.default_rng(seed)
    k = LAYOUT.max_neighbours
    obs = np.zeros(LAYOUT.size, dtype=np.float32)
    obs[2] = 1.0
    blocks = LAYOUT.blocks()
    rows = rng.uniform(-0.3, 0.3, (k, NEIGHBOUR_COLUMNS)).astype(np.float32)
    mask = (rng.random(k) < 0.7).astype(np.float32)
    rows *= mask[:, None]
    order = rng.permutation(k)
    shuffled = obs.copy()
    obs[blocks["neighbours"]], obs[blocks["neighbour_mask"]] = rows.reshape(-1), mask
    shuffled[blocks["neighbours"]] = rows[order].reshape(-1)
    shuffled[blocks["neighbour_mask"]] = mask[order]
    a = torch.tensor(action)
    one = view(cfg).penalty(torch.from_numpy(obs), a)
    other = view(cfg).penalty(torch.from_numpy(shuffled), a)
    assert float(one) == pytest.approx(float(other), rel=1e-6, abs=1e-9)  # float32 out


def test_a_view_needs_version_2_and_one_kinematics():
    cfg = scenario()
    with pytest.raises(ConfigError, match="version 2"):
        OwnView.of(dataclasses.replace(LAYOUT, version=1), [cfg], 4.0, 1.5)
    other = dataclasses.replace(cfg, dt_s=1.0)
    with pytest.raises(ConfigError, match="dagger_separation_weight"):
        OwnView.of(LAYOUT, [cfg, other], 4.0, 1.5)


@pytest.mark.parametrize("weight", [0.0, 2.0])
def test_dagger_charges_the_penalty_only_when_asked(tmp_path, monkeypatch, weight):
    charged: list[int] = []
    penalty = OwnView.penalty

    def spied(self, obs, action):
        charged.append(obs.shape[0])
        return penalty(self, obs, action)

    monkeypatch.setattr(OwnView, "penalty", spied)
    _, rows = tiny_ppo_run(
        tmp_path,
        teacher="orca-shield",
        dagger_fraction=0.5,
        dagger_updates=3,
        dagger_batch=16,
        dagger_separation_weight=weight,
    )
    assert bool(charged) == (weight > 0)
    assert all(size == 16 for size in charged[:-1])  # each step's minibatch, then the logged one
    logged = [row["losses/own_separation"] for row in rows if "losses/own_separation" in row]
    assert bool(logged) == (weight > 0) and all(np.isfinite(logged))


@settings(max_examples=30, deadline=None)
@given(action=st.floats(-1, 1), distance_m=st.floats(21.0, 60.0))
def test_a_reciprocal_view_lets_a_formation_turn_together(action, distance_m):
    """A wingman abeam at the same velocity, turning as we do, stays where it is."""
    cfg = scenario()
    obs = one_neighbour(0.0, distance_m)
    reciprocal = OwnView.of(LAYOUT, [cfg], 4.0, 1.5, reciprocal=True)
    closest = reciprocal.closest(obs, torch.tensor(action))[0]
    assert float(closest) == pytest.approx(distance_m, abs=1e-3)
    if action > 0.2:  # flying straight on, a turn to the left would close in on it
        assert float(view(cfg).closest(obs, torch.tensor(action))[0]) < distance_m - 0.5


def test_a_reciprocal_neighbour_flies_the_arc_the_simulator_flies():
    """The neighbour's predicted path is `sim.prediction`'s arc of the same turn from its course."""
    cfg = scenario()
    heading = 2.0  # the neighbour's course in our heading frame, rad
    v = 10.0 * np.array([np.cos(heading), np.sin(heading)])
    obs = one_neighbour(60.0, -30.0, vx_m_s=v[0] - 10.0, vy_m_s=v[1])
    action = 0.6
    got = float(
        OwnView.of(LAYOUT, [cfg], 4.0, 1.5, reciprocal=True).closest(obs, torch.tensor(action))[0]
    )
    turn = np.array([[action * cfg.uav.max_turn_rad]])
    own_x, own_y = displacements(np.zeros(1), turn, 10.0, cfg.dt_s, 4.0)
    nb_x, nb_y = displacements(np.full(1, heading), turn, 10.0, cfg.dt_s, 4.0)
    rx = 60.0 + nb_x[0, 0] - own_x[0, 0]
    ry = -30.0 + nb_y[0, 0] - own_y[0, 0]
    assert got == pytest.approx(float(closest_approach(rx, ry)), abs=0.02)


def test_intruders_are_charged_only_when_the_view_reads_them():
    """An intruder 60 m ahead, flying at us: charged after the neighbour rows where asked."""
    cfg = scenario()
    obs = one_neighbour(0.0, 50.0)  # a wingman out of reach
    blocks = LAYOUT.blocks()
    intruder = np.array([60.0 / 200, 2.0 / 200, -20.0 / 10, 0.0, 60.0 / 200], dtype=np.float32)
    obs[blocks["intruders"].start : blocks["intruders"].start + 5] = torch.from_numpy(intruder)
    obs[blocks["intruder_mask"].start] = 1.0
    straight = torch.tensor(0.0)
    alone = view(cfg)
    both = OwnView.of(LAYOUT, [cfg], 4.0, 1.5, intruders=True)
    assert alone.closest(obs, straight).shape == (LAYOUT.max_neighbours,)
    closest = both.closest(obs, straight)
    assert closest.shape == (LAYOUT.max_neighbours + LAYOUT.max_obstacles,)
    assert float(closest[LAYOUT.max_neighbours]) == pytest.approx(2.0, abs=1e-3)  # head-on
    assert torch.isinf(closest[LAYOUT.max_neighbours + 1 :]).all()  # empty rows
    assert float(alone.penalty(obs, straight)) == 0.0
    assert float(both.penalty(obs, straight)) == pytest.approx(((30 - 2) / 10) ** 2, rel=1e-4)


def test_intruders_may_be_predicted_further_ahead_than_the_neighbours():
    """An intruder 180 m ahead closing at 20 m/s meets us at 9 s: beyond a 4 s look, inside 10 s;
    the neighbour rows keep their own 4 s (a wingman 50 m ahead, slower, is not charged)."""
    cfg = scenario()
    obs = one_neighbour(50.0, 0.0, -5.0)  # 5 m/s slower: 20 m nearer in 4 s, 50 m in 10 s
    blocks = LAYOUT.blocks()
    intruder = np.array([180.0 / 200, 2.0 / 200, -20.0 / 10, 0.0, 180.0 / 200], dtype=np.float32)
    obs[blocks["intruders"].start : blocks["intruders"].start + 5] = torch.from_numpy(intruder)
    obs[blocks["intruder_mask"].start] = 1.0
    straight = torch.tensor(0.0)
    short = OwnView.of(LAYOUT, [cfg], 4.0, 1.5, intruders=True)
    far = OwnView.of(LAYOUT, [cfg], 4.0, 1.5, intruders=True, intruder_horizon_s=10.0)
    k = LAYOUT.max_neighbours
    near, ahead = short.closest(obs, straight), far.closest(obs, straight)
    assert float(near[k]) == pytest.approx(180.0 - 20.0 * 4.0, abs=0.5)  # 100 m off at 4 s
    assert float(ahead[k]) == pytest.approx(2.0, abs=1e-3)  # head-on inside 10 s
    assert torch.equal(near[:k], ahead[:k])  # the neighbours' look is the same
    assert float(near[0]) == pytest.approx(30.0, abs=0.5)
    assert float(short.penalty(obs, straight)) == 0.0
    assert float(far.penalty(obs, straight)) == pytest.approx(((30 - 2) / 10) ** 2, rel=1e-4)
    same = OwnView.of(LAYOUT, [cfg], 4.0, 1.5, intruders=True, intruder_horizon_s=0.0)
    assert same == short  # 0: as the neighbours


def test_the_intruder_rows_carry_their_own_share_of_the_penalty():
    """A neighbour 25 m ahead (0.25) and a head-on intruder (7.84): the intruder part scales
    by ``intruder_scale``, the neighbour part does not."""
    cfg = scenario()
    obs = one_neighbour(25.0, 0.0)
    blocks = LAYOUT.blocks()
    intruder = np.array([60.0 / 200, 2.0 / 200, -20.0 / 10, 0.0, 60.0 / 200], dtype=np.float32)
    obs[blocks["intruders"].start : blocks["intruders"].start + 5] = torch.from_numpy(intruder)
    obs[blocks["intruder_mask"].start] = 1.0
    straight = torch.tensor(0.0)
    neighbour, head_on = 0.25, ((30 - 2) / 10) ** 2
    for scale in (1.0, 1 / 3, 0.0):
        view = OwnView.of(LAYOUT, [cfg], 4.0, 1.5, intruders=True, intruder_scale=scale)
        got = float(view.penalty(obs, straight))
        assert got == pytest.approx(neighbour + scale * head_on, rel=1e-4)


@pytest.mark.parametrize(
    ("weight", "intruder_weight", "scale"), [(0.3, -1.0, 1.0), (0.3, 0.1, 1 / 3)]
)
def test_the_run_gives_the_intruder_rows_their_weight(weight, intruder_weight, scale):
    from types import SimpleNamespace

    from policies.config import GeneralistConfig
    from policies.generalist_dagger import separation_view

    cfg = GeneralistConfig(
        dagger_separation_weight=weight,
        dagger_separation_intruders=True,
        dagger_separation_intruder_weight=intruder_weight,
        dagger_separation_intruder_horizon_s=10.0,
    )
    book = SimpleNamespace(cfg=cfg, layout=LAYOUT, worlds=[SimpleNamespace(cfg=scenario())])
    view = separation_view(book)
    assert view is not None and view.intruder_scale == pytest.approx(scale)
    assert (view.horizon_s, view.intruder_horizon_s) == (4.0, 10.0)  # both looks reach it


@pytest.mark.parametrize("reciprocal", [False, True])
def test_the_penalty_stays_on_the_observations_device(reciprocal):
    """Every tensor it makes follows the observations (a run on a GPU learns there): on torch's
    meta device, one tensor made elsewhere would raise."""
    cfg = scenario()
    meta = OwnView.of(LAYOUT, [cfg], 4.0, 1.5, reciprocal=reciprocal, intruders=True)
    obs = torch.zeros(3, LAYOUT.size, device="meta")
    assert meta.penalty(obs, torch.zeros(3, device="meta")).device.type == "meta"


def test_a_supervised_step_with_the_penalty_turns_away_from_a_neighbour_ahead():
    """The penalty enters the actor's update: with labels equal to the actor's own actions the
    imitation alone moves nothing, and with the penalty the action turns away from a neighbour
    closing in ahead and to the left."""
    from policies.config import GeneralistConfig
    from policies.generalist_dagger import clone_update
    from policies.generalist_ppo import PPONets

    cfg = scenario()
    obs = one_neighbour(40.0, 5.0, vx_m_s=-20.0).repeat(8, 1)
    actions = {}
    for weight in (0.0, 1.0):
        torch.manual_seed(0)
        nets = PPONets.create(LAYOUT, GeneralistConfig(hidden=16), "cpu")
        with torch.no_grad():
            before = nets.actor(obs).clone()
        opt = torch.optim.Adam(nets.actor.parameters(), lr=1e-2)
        separation = (view(cfg), weight) if weight else None
        for _ in range(20):
            clone_update(nets.actor, opt, obs, before, 1.0, None, separation)
        with torch.no_grad():
            actions[weight] = (float(before[0]), float(nets.actor(obs)[0]))
    start, after = actions[0.0]
    assert after == pytest.approx(start, abs=1e-6)  # the labels are its own: nothing to learn
    start, after = actions[1.0]
    assert after < start - 0.05  # to the right, away from the neighbour on the left
