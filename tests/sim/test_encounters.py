"""The encounter geometry, the scenario format that uses it, and the episode generator."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.encounters import DISTRIBUTIONS, Encounter, Family, family_scenario, sample_family
from sim.errors import ConfigError, ScenarioError
from sim.metrics import swept_min_distance
from sim.scenarios import load_scenario, scenario_from_dict
from sim.spawn import EpisodeStart, encounter_tracks, spawn_episodes
from sim.swarm import SwarmSim

SEED = 9_000_000


@settings(max_examples=60, deadline=None)
@given(
    course=st.floats(-math.pi, math.pi),
    crossing=st.floats(-math.pi, math.pi),
    speed=st.floats(0.0, 25.0),
    miss=st.floats(-50.0, 50.0),
    tcpa=st.floats(1.0, 40.0),
)
def test_intruder_passes_at_the_miss_distance_at_tcpa_if_nobody_turns(
    course, crossing, speed, miss, tcpa
):
    start = np.array([12.0, -7.0])
    own_v = 10.0 * np.array([math.cos(course), math.sin(course)])
    pos, vel = encounter_tracks(
        start,
        np.array(course),
        10.0,
        np.array(crossing),
        np.array(speed),
        np.array(miss),
        np.array(tcpa),
    )
    assert np.linalg.norm(vel) == pytest.approx(speed, abs=1e-9)
    rel_at = pos + vel * tcpa - (start + own_v * tcpa)
    assert np.linalg.norm(rel_at) == pytest.approx(abs(miss), abs=1e-6)
    rel_v = vel - own_v
    if np.linalg.norm(rel_v) > 1e-3:  # the closest point of approach is at tcpa
        assert abs(rel_at @ rel_v) <= 1e-6 * max(1.0, np.linalg.norm(rel_v))
        rel = (pos - start)[None] + np.linspace(0, 2 * tcpa, 401)[:, None] * rel_v
        assert swept_min_distance(rel) == pytest.approx(abs(miss), abs=1e-3)


def test_miss_sign_is_the_side_of_the_relative_velocity():
    # Head-on along +x: relative velocity is +x, so a positive miss puts the intruder at +y.
    pos, vel = encounter_tracks(
        np.zeros(2),
        np.array(0.0),
        10.0,
        np.array(math.pi),
        np.array(10.0),
        np.array(5.0),
        np.array(10.0),
    )
    assert pos.tolist() == pytest.approx([200.0, 5.0])
    assert vel.tolist() == pytest.approx([-10.0, 0.0])


def custom_scenario():
    """Two UAVs whose routes cross, a crossing intruder and a static one that pops up late."""
    return scenario_from_dict(
        {
            "uav": {
                "count": 2,
                "starts_m": [[50, 100], [50, 160]],
                "targets_m": [[250, 160], [250, 100]],
            },
            "intruders": [
                {"crossing_deg": 90, "speed_m_s": 8.0, "miss_m": 3.0, "tcpa_s": 9.0, "against": 1},
                {"speed_m_s": 0.0, "miss_m": -25.0, "tcpa_s": 12.0, "appear_s": 3.0},
            ],
        },
        name="custom",
        source="test",
    )


def test_scenario_file_with_per_uav_starts_targets_and_intruders():
    cfg = custom_scenario()
    assert cfg.obstacles.count == 2
    assert cfg.intruders[0].crossing_rad == pytest.approx(math.pi / 2)
    ep = spawn_episodes(cfg, np.random.default_rng(0), 3)
    assert ep.start_m[0].tolist() == [[50, 100], [50, 160]]
    assert ep.target_m[2].tolist() == [[250, 160], [250, 100]]
    assert (ep.obstacle_pos_m[0] == ep.obstacle_pos_m[2]).all()  # geometry, not chance
    assert ep.obstacle_appear_step[0].tolist() == [0, 2]  # 3 s rounds up to step 2 at dt = 2 s
    assert np.linalg.norm(ep.obstacle_vel_m_s[0, 1]) == 0.0


@pytest.mark.parametrize(
    ("data", "key"),
    [
        ({"uav": {"count": 2, "starts_m": [[0, 0]]}}, "uav.starts_m"),
        ({"uav": {"count": 1}, "intruders": [{"against": 3}]}, "intruders[0].against"),
        ({"uav": {"count": 1}, "intruders": [{"bearing_deg": 3}]}, "intruders[0].bearing_deg"),
        ({"uav": {"count": 1}, "obstacles": {"count": 2}, "intruders": [{}]}, "obstacles.count"),
        ({"uav": {"count": 1}, "intruders": {"speed_m_s": 1}}, "intruders"),
    ],
)
def test_bad_intruder_or_start_keys_name_the_key(data, key):
    data.setdefault("obstacles", {}) if "intruders" not in data else None
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(data, name="bad", source="bad.toml")
    assert key in str(err.value)


def test_a_hidden_pop_up_is_not_sensed_until_it_appears_but_still_collides():
    cfg = load_scenario("3u1o", uav={"count": 1}, obstacles={"count": 1})
    ep = EpisodeStart.of_swarm(
        np.array([[[0.0, 0.0]]]),
        np.array([[[300.0, 0.0]]]),
        np.array([[[50.0, 0.0]]]),
        np.zeros((1, 1, 2)),
        np.array([[3]]),
        cfg.uav.speed_m_s,
        cfg.field.swarm_lead_m,
    )
    sim = SwarmSim(cfg, scored=False)
    state = sim.start(ep, np.random.default_rng(0))
    assert not sim.observe(state).sensed.any()  # 50 m ahead, in range, but hidden
    state, result = sim.step(state, np.zeros((1, 1)), np.random.default_rng(0))
    assert not sim.observe(state).sensed.any()
    state, result = sim.step(state, np.zeros((1, 1)), np.random.default_rng(0))
    assert result.collided_u2o.all()  # flew into it, unseen


def test_an_episode_is_the_same_whatever_the_batch():
    family = Family(name="crossing-x", distribution="crossing", uavs=4, formation="random")
    _, all_five = sample_family(family, SEED, range(5))
    _, just_three = sample_family(family, SEED, [3])
    for field in ("start_m", "target_m", "obstacle_pos_m", "obstacle_vel_m_s"):
        assert np.array_equal(getattr(all_five, field)[3], getattr(just_three, field)[0])
    _, again = sample_family(family, SEED, range(5))
    assert np.array_equal(all_five.obstacle_pos_m, again.obstacle_pos_m)
    _, other_seed = sample_family(family, SEED + 1, range(5))
    assert not np.array_equal(all_five.obstacle_pos_m, other_seed.obstacle_pos_m)


@pytest.mark.parametrize("distribution", sorted(DISTRIBUTIONS))
@pytest.mark.parametrize(
    ("uavs", "formation"), [(1, "line"), (5, "wedge"), (12, "grid"), (9, "random")]
)
def test_every_distribution_draws_valid_episodes(distribution, uavs, formation):
    family = Family(
        name=f"{distribution}-t", distribution=distribution, uavs=uavs, formation=formation
    )
    cfg, ep = sample_family(family, SEED, range(6))
    enc = family.encounter
    assert ep.start_m.shape == (6, uavs, 2) and ep.obstacle_pos_m.shape == (6, enc.intruders, 2)
    gap = 1.5 * cfg.d_col_m
    for k in range(6):
        d = np.linalg.norm(ep.start_m[k, :, None] - ep.start_m[k, None], axis=-1)
        assert (d[np.triu_indices(uavs, 1)] >= gap - 1e-9).all()
        if enc.intruders:
            clear = np.linalg.norm(ep.obstacle_pos_m[k, :, None] - ep.start_m[k, None], axis=-1)
            assert clear.min() > 2 * cfg.d_col_m
            speed = np.linalg.norm(ep.obstacle_vel_m_s[k], axis=-1)
            assert ((speed >= enc.speed_m_s[0] - 1e-9) & (speed <= enc.speed_m_s[1] + 1e-9)).all()
    route = np.linalg.norm(ep.target_m - ep.start_m, axis=-1)
    assert route.max() / cfg.step_length_m < cfg.max_steps  # reachable in the step limit
    assert np.isfinite(ep.centre_m).all()


def test_scenario_families_are_the_scenario_spawn():
    family = Family(name="paper-3u2o", distribution="scenario", scenario="3u2o")
    cfg, ep = sample_family(family, SEED, range(4))
    base = load_scenario("3u2o")
    assert (cfg.uav.count, cfg.obstacles.count, cfg.max_steps) == (3, 2, base.max_steps)
    assert np.array_equal(
        ep.start_m[0], spawn_episodes(base, np.random.default_rng(0), 1).start_m[0]
    )
    assert not np.array_equal(ep.obstacle_pos_m[0], ep.obstacle_pos_m[1])  # jitter per episode


def test_family_rejects_bad_settings():
    with pytest.raises(ConfigError, match="unknown distribution"):
        Family(name="x", distribution="tailgating")
    with pytest.raises(ConfigError, match="1 to 50"):
        Family(name="x", distribution="head-on", uavs=51)
    with pytest.raises(ConfigError, match="formation"):
        Family(name="x", distribution="head-on", formation="circle")


def test_a_family_that_cannot_be_placed_says_so():
    crowded = Family(
        name="x",
        distribution="static",
        uavs=1,
        encounter=Encounter(speed_m_s=(0.0, 0.0), intruders=1, tcpa_fraction=(0.001, 0.001)),
    )
    with pytest.raises(ConfigError, match="starting on a UAV"):
        sample_family(crowded, SEED, range(1))


def test_step_limit_leaves_room_for_detours():
    family = Family(name="swarms-big", distribution="swarms", uavs=20, formation="grid")
    cfg = family_scenario(family)
    _, ep = sample_family(family, SEED, range(10))
    longest = np.linalg.norm(ep.target_m - ep.start_m, axis=-1).max()
    assert cfg.max_steps * cfg.step_length_m >= 1.5 * longest


def test_a_policy_file_keeps_per_uav_routes_and_intruders():
    import json

    from sim.policy_metadata import build_metadata, scenario_config

    cfg = custom_scenario()
    meta = build_metadata(
        cfg,
        shared=False,
        hidden=4,
        reward="remarl",
        training={"commit": "x", "steps": 1, "seed": 0},
        metrics={},
    )
    assert scenario_config(json.loads(json.dumps(meta))) == cfg  # through JSON, as in a file
