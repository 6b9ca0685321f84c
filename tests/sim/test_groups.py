"""Several swarms in one scenario (`UAVConfig.groups`): a virtual centre and a peak per swarm."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.config import FieldConfig, FieldValueError, UAVConfig
from sim.encounters import DISTRIBUTIONS, Family, family_scenario, sample_family, swarm_groups
from sim.errors import ScenarioError
from sim.field import FieldSources, potential_and_gradient
from sim.observation import ROW_SWARM
from sim.scenarios import scenario_from_dict
from sim.spawn import group_index, virtual_centre_and_velocity
from sim.swarm import SwarmSim

SPEED, LEAD = 10.0, 40.0


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 9), g=st.integers(1, 4))
def test_each_swarms_centre_is_the_centre_of_that_swarm_alone(seed, n, g):
    rng = np.random.default_rng(seed)
    g = min(g, n)
    groups = np.concatenate([np.arange(g), rng.integers(0, g, n - g)])
    rng.shuffle(groups)
    pos = rng.uniform(-300, 300, (3, n, 2))
    tgt = rng.uniform(-300, 300, (3, n, 2))
    vel, centre = virtual_centre_and_velocity(pos, tgt, SPEED, LEAD, groups)
    assert vel.shape == centre.shape == (3, g, 2)
    for k in range(g):
        alone_vel, alone_centre = virtual_centre_and_velocity(
            pos[:, groups == k], tgt[:, groups == k], SPEED, LEAD
        )
        np.testing.assert_allclose(vel[:, k], alone_vel[:, 0], atol=1e-9)
        np.testing.assert_allclose(centre[:, k], alone_centre[:, 0], atol=1e-9)


def test_one_swarm_is_the_papers_centre():
    pos = np.array([[0.0, 0.0], [0.0, 10.0]])
    tgt = pos + np.array([100.0, 0.0])
    for groups in (None, np.zeros(2, dtype=int)):
        vel, centre = virtual_centre_and_velocity(pos, tgt, SPEED, 50.0, groups)
        np.testing.assert_allclose(vel, [[10.0, 0.0]])
        np.testing.assert_allclose(centre, [[50.0, 5.0]])


def test_two_peaks_add_up():
    rng = np.random.default_rng(2)
    cfg = FieldConfig()
    pts = rng.uniform(-150, 150, (1, 40, 2))
    a, b = np.array([[[30.0, -20.0]]]), np.array([[[-60.0, 45.0]]])
    none = (np.zeros((1, 0, 2)), np.zeros((1, 0)))

    def field(centres):
        return potential_and_gradient(pts, FieldSources(*none, centres, SPEED), cfg)

    phi, grad = field(np.concatenate([a, b], axis=1))
    phi_a, grad_a = field(a)
    phi_b, grad_b = field(b)
    np.testing.assert_allclose(phi, phi_a + phi_b, rtol=1e-12)
    np.testing.assert_allclose(grad, grad_a + grad_b, rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize(
    ("groups", "why"),
    [((0, 1), "one swarm index per UAV"), ((0, 2, 2), "without gaps"), ((1, 1, 1), "gaps")],
)
def test_bad_groups_name_the_key(groups, why):
    data = {"uav": {"count": 3, "groups": list(groups)}, "obstacles": {"count": 0}}
    with pytest.raises(ScenarioError, match=why) as err:
        scenario_from_dict(data, name="bad", source="bad.toml")
    assert "uav.groups" in str(err.value)
    with pytest.raises(FieldValueError, match=why):
        UAVConfig(count=3, groups=groups)


def test_a_scenario_file_gives_each_swarm_its_centre():
    data = {
        "uav": {
            "count": 4,
            "starts_m": [[50, 100], [50, 160], [150, 30], [210, 30]],
            "targets_m": [[350, 100], [350, 160], [150, 330], [210, 330]],
            "groups": [0, 0, 1, 1],
        },
        "obstacles": {"count": 0},
        "arena_length_m": 400.0,
        "arena_width_m": 400.0,
    }
    cfg = scenario_from_dict(data, name="two", source="two.toml")
    assert group_index(cfg.uav).tolist() == [0, 0, 1, 1]
    sim = SwarmSim(cfg)
    state = sim.initial_state(np.random.default_rng(0), 2)
    assert state.centre_m.shape == (2, 2, 2)
    # The first swarm flies east, the second north: each centre lies ahead of its own swarm.
    np.testing.assert_allclose(state.swarm_vel_m_s[0], [[10.0, 0.0], [0.0, 10.0]], atol=1e-12)
    np.testing.assert_allclose(state.centre_m[0, 0], [50.0 + LEAD, 130.0])
    np.testing.assert_allclose(state.centre_m[0, 1], [180.0, 30.0 + LEAD])
    # Each UAV's observation points at its own swarm's centre, straight ahead of it.
    rows = sim.observe(state).rows[0, :, ROW_SWARM]
    range_m = sim.obs_layout.range_m
    np.testing.assert_allclose(rows[:, 0] * range_m, LEAD, rtol=1e-5)  # ahead
    np.testing.assert_allclose(rows[:, 1] * range_m, [30.0, -30.0, -30.0, 30.0], rtol=1e-5)
    # The swarms' peaks move with their swarms.
    after, _ = sim.step(state, np.zeros((2, 4)), np.random.default_rng(1))
    np.testing.assert_allclose(
        after.centre_m - state.centre_m, state.swarm_vel_m_s * cfg.dt_s, atol=1e-12
    )


@pytest.mark.parametrize(
    ("distribution", "expected"),
    [("swarms", [0, 0, 0, 1, 1]), ("random-paths", [0, 1, 2, 3, 4]), ("crossing", None)],
)
def test_families_fly_as_their_paths_say(distribution, expected):
    fam = Family(name="f", distribution=distribution, uavs=5)
    cfg = family_scenario(fam)
    assert (list(cfg.uav.groups) or None) == expected
    enc = DISTRIBUTIONS[distribution]
    assert swarm_groups(enc.paths, 5) == cfg.uav.groups
    _, episodes = sample_family(fam, 0, range(3))
    g = group_index(cfg.uav)
    assert episodes.centre_m.shape == (3, int(g.max()) + 1, 2)
    # Every UAV starts behind its own swarm's centre, along its swarm's course.
    own = episodes.centre_m[:, g] - episodes.start_m
    course = episodes.swarm_vel_m_s[:, g]
    assert (np.einsum("bni,bni->bn", own, course) > 0).all()
