import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test, parallel_seed_test

from sim.env import ENV_ID, make_env, make_parallel_env, make_vector_env, register
from sim.heuristics import potential_field_actions, straight_actions
from sim.scenarios import scenario_names

SCENARIOS = scenario_names()


@pytest.mark.parametrize("name", SCENARIOS)
def test_pettingzoo_parallel_api(name):
    parallel_api_test(make_parallel_env(name), num_cycles=60)


@pytest.mark.parametrize("name", SCENARIOS)
def test_pettingzoo_seed(name):
    parallel_seed_test(lambda: make_parallel_env(name))


@pytest.mark.parametrize("name", SCENARIOS)
def test_gymnasium_check_env(name):
    check_env(make_env(name), skip_render_check=True)


@pytest.mark.parametrize("name", SCENARIOS)
def test_vector_env_determinism_and_spaces(name):
    def rollout(seed):
        env = make_vector_env(name, 4)
        obs, _ = env.reset(seed=seed)
        act_rng = np.random.default_rng(0)
        out = [np.concatenate([obs.ravel(), env.state.obstacle_pos_m.ravel()])]
        for _ in range(8):
            obs, rew, term, trunc, _ = env.step(act_rng.uniform(-1, 1, (4, env.num_agents)))
            assert env.observation_space.contains(obs)
            assert rew.shape == (4, env.num_agents)
            assert term.shape == trunc.shape == (4,)
            out.append(np.concatenate([obs.ravel(), env.state.obstacle_pos_m.ravel()]))
        return np.array(out)

    a, b = rollout(3), rollout(3)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, rollout(4))  # obstacles spawn differently


def test_vector_env_autoresets_in_the_same_step_with_final_obs_and_metrics():
    env = make_vector_env("3u2o", 8)
    obs, _ = env.reset(seed=0)
    ended = 0
    for _ in range(40):
        obs, _, term, trunc, info = env.step(straight_actions(obs))
        done = term | trunc
        if done.any():
            ended += done.sum()
            np.testing.assert_array_equal(info["_final_obs"], done)
            assert not np.array_equal(info["final_obs"][done], obs[done])
            assert info["active"][done].all()  # the new episodes start with everyone active
            assert len(info["episode"]["success"]) == done.sum()
            assert (env.state.steps[done] == 0).all()
    assert ended >= 8
    assert env.metadata["autoreset_mode"].name == "SAME_STEP"


def test_vector_env_pays_remarl_or_swarming_reward():
    pays = {}
    for mode in ("remarl", "swarming"):
        env = make_vector_env("3u2o", 2, reward=mode)
        env.reset(seed=1)
        _, rew, _, _, info = env.step(np.full((2, 3), 0.5))
        pays[mode] = (rew, info)
    np.testing.assert_allclose(pays["swarming"][0], pays["swarming"][1]["swarming"], rtol=1e-6)
    r, info = pays["remarl"]
    np.testing.assert_allclose(r, info["swarming"] + info["contour"], rtol=1e-5)


def test_registered_id_and_bad_arguments():
    register()
    import gymnasium

    env = gymnasium.make(ENV_ID, scenario="2u1o")
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape
    with pytest.raises(ValueError, match="reward"):
        make_vector_env("3u2o", 2, reward="team")
    with pytest.raises(ValueError, match="num_envs"):
        make_vector_env("3u2o", 0)


def test_rgb_render():
    env = make_vector_env("3u2o", 1, render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    env.step(straight_actions(obs))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.std() > 10  # not a blank image


def success_rate(policy, episodes=64):
    env = make_vector_env("2u1o", 32, obstacles={"speed_m_s": 0.0, "spawn_x_m": 160.0})
    obs, _ = env.reset(seed=7)
    results = []
    while len(results) < episodes:
        obs, _, _, _, info = env.step(policy(obs, env))
        if "episode" in info:
            results.extend(info["episode"]["success"])
    return np.mean(results)


def test_potential_field_oracle_beats_flying_straight_on_2u1o_static():
    straight = success_rate(lambda obs, env: straight_actions(obs))
    field = success_rate(
        lambda obs, env: potential_field_actions(
            obs, env.cfg.sensing.max_obstacles, env.cfg.uav.max_turn_rad
        )
    )
    assert field >= 0.9
    assert field > straight + 0.5


def test_reset_mask_restarts_only_the_selected_environments():
    env = make_vector_env("3u2o", 3)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.full((3, 3), 0.2, np.float32))
    before = env.state.pos_m.copy()
    obs, _ = env.reset(options={"reset_mask": np.array([False, True, False])})
    np.testing.assert_array_equal(env.state.steps, [3, 0, 3])
    np.testing.assert_array_equal(env.state.pos_m[[0, 2]], before[[0, 2]])
    assert obs.shape == (3, 3, env.obs_layout_size)
