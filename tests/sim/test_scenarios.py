import math
import re
from pathlib import Path

import numpy as np
import pytest

from sim.errors import ScenarioError
from sim.scenarios import load_scenario, scenario_names
from sim.spawn import SPAWN_SPACING_FACTOR, min_pairwise_distance, spawn_obstacles, swarm_layout

PAPER = ["2u1o", "3u1o", "5u1o", "7u1o", "10u1o", "3u2o", "5u2o", "7u2o"]


def test_paper_and_larger_scenarios_are_shipped():
    names = scenario_names()
    assert set(PAPER) <= set(names)
    assert {"20u4o", "50u8o"} <= set(names)


@pytest.mark.parametrize("name", scenario_names())
def test_scenario_counts_match_name_and_spawn_is_safe(name):
    cfg = load_scenario(name)
    n, m = map(int, re.fullmatch(r"(\d+)u(\d+)o", name).groups())
    assert (cfg.uav.count, cfg.obstacles.count) == (n, m)
    layout = swarm_layout(cfg)
    assert layout.positions_m.shape == (n, 2)
    assert min_pairwise_distance(layout.positions_m) >= SPAWN_SPACING_FACTOR * cfg.d_col_m
    assert (layout.positions_m >= 0).all()
    assert (layout.positions_m[:, 0] <= cfg.arena_length_m).all()
    assert (layout.positions_m[:, 1] <= cfg.arena_width_m).all()
    # Targets on the right, each on its UAV's straight line.
    np.testing.assert_allclose(layout.targets_m[:, 1], layout.positions_m[:, 1])
    assert (layout.targets_m[:, 0] > layout.positions_m[:, 0]).all()
    np.testing.assert_allclose(layout.headings_rad, 0.0, atol=1e-12)
    # Every UAV starts inside the swarm field, so it has a contour.
    assert layout.centre_m.shape == (1, 2)  # one swarm
    dist = np.hypot(*(layout.positions_m - layout.centre_m[0]).T)
    assert (dist < cfg.field.swarm_range_m).all()
    # The virtual centre is ahead of the swarm.
    assert layout.centre_m[0, 0] > layout.positions_m[:, 0].mean()


@pytest.mark.parametrize("name", scenario_names())
def test_obstacles_spawn_on_the_right_flying_toward_the_swarm(name):
    cfg = load_scenario(name)
    pos, vel = spawn_obstacles(cfg, np.random.default_rng(1), num_envs=16)
    assert pos.shape == vel.shape == (16, cfg.obstacles.count, 2)
    assert (pos[..., 0] > swarm_layout(cfg).positions_m[:, 0].max()).all()
    assert (pos[..., 1] >= 0).all() and (pos[..., 1] <= cfg.arena_width_m).all()
    np.testing.assert_allclose(np.hypot(vel[..., 0], vel[..., 1]), cfg.obstacles.speed_m_s)
    assert (vel[..., 0] < 0).all()


def test_unknown_name_lists_the_known_ones():
    with pytest.raises(ScenarioError) as err:
        load_scenario("4u4o")
    assert "3u2o" in str(err.value) and "10u1o" in str(err.value)
    assert isinstance(err.value, ValueError)


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "mine.toml"
    path.write_text(text)
    return path


def test_user_file_by_path_with_degrees(tmp_path):
    path = write(
        tmp_path,
        'description = "x"\n[uav]\ncount = 4\nformation = "line"\nmax_turn_deg = 30\n'
        "[obstacles]\ncount = 0\n",
    )
    cfg = load_scenario(str(path))
    assert cfg.name == "mine"
    assert cfg.uav.count == 4 and cfg.obstacles.count == 0
    assert cfg.uav.max_turn_rad == pytest.approx(math.radians(30))


@pytest.mark.parametrize(
    ("body", "key", "fragment"),
    [
        ("[uav]\ncont = 3\n[obstacles]\ncount = 1\n", "uav.cont", "unknown key"),
        ("[uav]\ncount = 3\nspeed_m_s = -1.0\n[obstacles]\ncount = 1\n", "uav.speed_m_s", "> 0"),
        (
            "[uav]\ncount = 3\n[obstacles]\ncount = 1\nspeed_m_s = -2\n",
            "obstacles.speed_m_s",
            ">= 0",
        ),
        ("[uav]\ncount = 3.5\n[obstacles]\ncount = 1\n", "uav.count", "integer"),
        (
            "[uav]\ncount = 3\n[obstacles]\ncount = 1\n[reward]\nexternal = 'edge'\n",
            "reward.external",
            "level-edge",
        ),
        ("[uav]\ncount = 3\nspacing_m = 25.0\n[obstacles]\ncount = 1\n", "uav.spacing_m", "1.5"),
        (
            "[uav]\ncount = 3\nmax_turn_rad = 0.5\n[obstacles]\ncount = 1\n",
            "uav.max_turn_rad",
            "unknown key",
        ),
        ("[obstacles]\ncount = 1\n", "uav.count", "missing"),
        ("max_steps = 0\n[uav]\ncount = 3\n[obstacles]\ncount = 1\n", "max_steps", ">= 1"),
        (
            "[uav]\ncount = 3\n[obstacles]\ncount = 1\n[sensing]\naperture_deg = 400\n",
            "sensing.aperture_deg",
            "2π",
        ),
        (
            "[uav]\ncount = 30\nformation = 'line'\n[obstacles]\ncount = 1\n",
            "uav.center_m",
            "arena",
        ),
        (
            "[uav]\ncount = 3\n[obstacles]\ncount = 1\n[field]\ncontinuous = 1\n",
            "field.continuous",
            "true or false",
        ),
        (
            "[uav]\ncount = 4\nformation = 'grid'\n[obstacles]\ncount = 1\n",
            "uav.target_layout",
            "hover",
        ),
        (
            "[uav]\ncount = 2\nformation = 'line'\ntargets_m = [[270, 150], [270, 175]]\n"
            "[obstacles]\ncount = 1\n",
            "uav.targets_m",
            "25.0 m apart",
        ),
        (
            "[uav]\ncount = 3\ntarget_layout = 'column'\n[obstacles]\ncount = 1\n",
            "uav.target_layout",
            "line, formation",
        ),
        (
            "dynamics = 'glider'\n[uav]\ncount = 3\n[obstacles]\ncount = 1\n",
            "dynamics",
            "unknown vehicle profile",
        ),
        (
            "[uav]\ncount = 3\n[obstacles]\ncount = 1\n[sensors]\nadsb_latency_s = [2, 1]\n",
            "sensors.adsb_latency_s",
            "low <= high",
        ),
        (
            "[uav]\ncount = 3\n[obstacles]\ncount = 1\n[dynamics_randomisation]\n"
            "profiles = ['glider']\n",
            "dynamics_randomisation.profiles",
            "unknown vehicle profile",
        ),
    ],
)
def test_bad_values_name_file_and_key(tmp_path, body, key, fragment):
    path = write(tmp_path, body)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    message = str(err.value)
    assert str(path) in message
    assert err.value.key == key
    assert fragment in message


def test_invalid_toml_and_missing_file(tmp_path):
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(write(tmp_path, "[uav\ncount = 3"))
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "absent.toml")


def test_overrides_replace_file_values():
    cfg = load_scenario("3u2o", reward={"external": "gradient"}, max_steps=60)
    assert cfg.reward.external == "gradient"
    assert cfg.max_steps == 60
    assert cfg.uav.count == 3
