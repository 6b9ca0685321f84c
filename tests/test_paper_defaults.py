"""The defaults are the paper's values (SPEC §3); a change here is a change of the model."""

import math

import numpy as np
import pytest

from sim.config import PSOConfig, RewardConfig
from sim.contour import ArcWindow
from sim.scenarios import load_scenario, scenario_names

PAPER = ["2u1o", "3u1o", "5u1o", "7u1o", "10u1o", "3u2o", "5u2o", "7u2o"]


@pytest.mark.parametrize("name", PAPER)
def test_paper_geometry(name):
    cfg = load_scenario(name)
    assert (cfg.arena_length_m, cfg.arena_width_m) == (300.0, 300.0)
    assert cfg.uav.speed_m_s == 10.0
    assert cfg.dt_s == 2.0
    assert cfg.step_length_m == 20.0
    assert cfg.obstacles.speed_m_s == 2.5
    assert cfg.d_col_m == 20.0
    assert cfg.sensing.range_m == 100.0
    assert cfg.uav.max_turn_rad == pytest.approx(math.pi / 4)


@pytest.mark.parametrize("name", scenario_names())
def test_every_scenario_keeps_speeds_and_timing(name):
    cfg = load_scenario(name)
    assert cfg.step_length_m == 20.0
    assert cfg.obstacles.speed_m_s * cfg.dt_s == 5.0


def test_pso_threshold_and_budget():
    pso = PSOConfig()
    assert pso.threshold_m == 1.5 * 20.0
    assert pso.evaluations == 200


def test_reward_window_includes_the_new_arc_and_default_external_term():
    reward = RewardConfig()
    assert reward.window_steps == 3  # K = 3 decision steps, 60 m (docs/MODEL.md)
    assert reward.window_steps * load_scenario("3u2o").step_length_m == 60.0
    # the window of a step holds the arc of the action just taken, newest last
    window = ArcWindow.empty(1, 1, reward.window_steps)
    window = window.push(np.array([[0.3]]), np.array([[0.5]]), np.array([[True]]))
    np.testing.assert_array_equal(window.turn_rad[0, 0], [0.0, 0.0, 0.3])
    np.testing.assert_array_equal(window.valid[0, 0], [False, False, True])
    assert reward.external == "level-edge"
