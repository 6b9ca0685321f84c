"""The BenchMARL adapter, without BenchMARL: agents stay, discrete headings, Swarming reward."""

import csv
import math
import subprocess
import sys

import numpy as np
import pytest
from gymnasium import spaces

from policies.baseline_env import EpisodeLog, SwarmBaselineEnv
from policies.benchmarl_train import INSTALL_HINT, BaselinesNotInstalledError, train_benchmarl
from policies.common import heading_actions
from sim.env import SwarmParallelEnv, agent_spaces, make_vector_env
from sim.errors import ConfigError
from sim.observation import CLIP
from sim.scenarios import load_scenario

NO_OBSTACLES = {"obstacles": {"count": 0}}  # 3u1o without its obstacle: uav_0 arrives first
STRAIGHT = 5  # index of 0 in the default 11 headings


def fly_straight(env):
    """Run one episode straight ahead; returns the per-step (obs, rewards, term, trunc, infos)."""
    steps = []
    while env.agents:
        steps.append(env.step(dict.fromkeys(env.agents, STRAIGHT)))
    return steps


def test_is_the_parallel_env_with_discrete_headings_and_the_swarming_reward():
    env = SwarmBaselineEnv("3u1o")
    assert isinstance(env, SwarmParallelEnv)
    assert env._vec.reward_mode == "swarming"
    np.testing.assert_array_equal(env.headings, heading_actions(11))


def test_spaces():
    env = SwarmBaselineEnv("3u1o", n_actions=10)
    obs_space, _ = agent_spaces(load_scenario("3u1o"))
    assert env.possible_agents == ["uav_0", "uav_1", "uav_2"]
    for agent in env.possible_agents:
        assert env.action_space(agent) == spaces.Discrete(10)
        assert env.observation_space(agent) == obs_space
    d = obs_space.shape[0]
    assert env.state_space.shape == (3 * d + 3,)
    assert env.state_space.dtype == np.float32


def test_arrived_agents_stay_with_done_flag_and_zero_reward():
    log = EpisodeLog()
    env = SwarmBaselineEnv("3u1o", log=log, **NO_OBSTACLES)
    obs, infos = env.reset(seed=0)
    assert set(obs) == set(infos) == set(env.agents) == set(env.possible_agents)
    steps = fly_straight(env)
    everyone = set(env.possible_agents)
    for obs, rew, term, trunc, infos in steps:
        assert set(obs) == set(rew) == set(term) == set(trunc) == set(infos) == everyone
    first_done = {a: next(t for t, s in enumerate(steps) if s[2][a]) for a in everyone}
    early = min(first_done, key=first_done.get)
    t_arrive = first_done[early]
    assert t_arrive < len(steps) - 1, "one UAV must arrive before the episode ends"
    # the arrival step itself is paid; afterwards: done, zero reward, zero observation
    assert steps[t_arrive][1][early] != 0.0
    assert steps[t_arrive][4][early]["arrived"]
    for obs, rew, term, trunc, _ in steps[t_arrive + 1 :]:
        assert term[early]
        assert not trunc[early]
        assert rew[early] == 0.0
        assert not obs[early].any()
    # the others fly on, not done, until the episode ends
    for _, _, term, _, _ in steps[t_arrive:-1]:
        assert not all(term.values())
    last = steps[-1]
    assert all(last[2].values())  # everyone arrived: all terminated
    assert env.agents == []
    assert env.last_episode["success"]
    assert log.env_steps == len(steps)
    assert len(log.rows) == 1
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})


def test_state_scales_and_zeroes_departed_agents_and_flags_the_flying():
    env = SwarmBaselineEnv("3u1o", **NO_OBSTACLES)
    env.reset(seed=0)
    state = env.state()
    d = env.observation_space("uav_0").shape[0]
    np.testing.assert_array_equal(state[-3:], [1.0, 1.0, 1.0])
    while True:
        obs, _, term, _, _ = env.step(dict.fromkeys(env.agents, STRAIGHT))
        if any(term.values()):
            break
    state = env.state()
    flags = state[-3:]
    for i, agent in enumerate(env.possible_agents):
        assert flags[i] == (0.0 if term[agent] else 1.0)
        np.testing.assert_allclose(state[i * d : (i + 1) * d], obs[agent] / CLIP)
    assert env.state_space.contains(state)


def test_state_is_comas_global_state():
    import torch

    from policies.coma import global_state

    env = SwarmBaselineEnv("3u1o", **NO_OBSTACLES)
    env.reset(seed=3)
    d = env.observation_space("uav_0").shape[0]
    vec = make_vector_env("3u1o", 1, **NO_OBSTACLES)
    raw, info = vec.reset(seed=3)
    for _ in range(11):
        expect = global_state(torch.from_numpy(raw[0]), torch.from_numpy(info["active"][0]))
        expect[: 3 * d] /= CLIP  # observations scaled into [-1, 1]; the flags as they are
        np.testing.assert_allclose(env.state(), expect.numpy(), atol=1e-6)
        assert np.abs(env.state()).max() <= 1.0
        if not env.agents:
            break
        env.step(dict.fromkeys(env.agents, STRAIGHT))
        raw, _, _, _, info = vec.step(np.zeros((1, 3), np.float32))


@pytest.mark.parametrize("n_actions", [10, 11])
def test_actions_map_to_normalised_heading_changes(n_actions):
    """Discrete index k flies exactly as the continuous action heading_actions(n)[k]."""
    headings = heading_actions(n_actions)
    rng = np.random.default_rng(7)
    env = SwarmBaselineEnv("3u1o", n_actions=n_actions)
    vec = make_vector_env("3u1o", 1, reward="swarming")
    obs, _ = env.reset(seed=11)
    vec_obs, _ = vec.reset(seed=11)
    np.testing.assert_array_equal(np.stack([obs[a] for a in env.possible_agents]), vec_obs[0])
    while env.agents:
        picks = rng.integers(0, n_actions, 3)
        obs, rew, *_ = env.step(dict(zip(env.possible_agents, picks, strict=True)))
        result = vec.step_without_reset(headings[picks][None])
        flying = vec.state.active[0]
        np.testing.assert_array_equal(
            np.stack([obs[a] for a in env.possible_agents]),
            result.obs.flat()[0] * flying[:, None],
        )
        np.testing.assert_allclose([rew[a] for a in env.possible_agents], result.reward.swarming[0])
    env.reset(seed=0)
    with pytest.raises(ValueError, match="Discrete"):
        env.step({"uav_0": n_actions})


def test_reward_is_swarming_and_curve_is_the_simulators_episode_metrics(tmp_path):
    log = EpisodeLog(tmp_path / "curve.csv")
    log.start()
    env = SwarmBaselineEnv("3u1o", log=log)
    vec = make_vector_env("3u1o", 1, reward="remarl")
    rng = np.random.default_rng(0)
    paid = []
    for episode in range(3):
        env.reset(seed=episode)
        vec.reset(seed=episode)
        total = 0.0
        while env.agents:
            picks = rng.integers(0, 11, 3)
            _, rew, _, _, infos = env.step(dict(zip(env.possible_agents, picks, strict=True)))
            result = vec.step_without_reset(heading_actions()[picks][None])
            swarming = np.where(result.acted[0], result.reward.swarming[0], 0.0)
            np.testing.assert_allclose([rew[a] for a in env.possible_agents], swarming)
            assert [infos[a]["swarming"] for a in env.possible_agents] == [
                rew[a] for a in env.possible_agents
            ]
            total += sum(rew.values())
        paid.append(total)
    assert not np.allclose(result.reward.total[0], result.reward.swarming[0])  # not the reMARL one
    with (tmp_path / "curve.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["env_steps", "episode", "swarming_return", "success"]
    assert [int(r["episode"]) for r in rows] == [1, 2, 3]
    assert int(rows[-1]["env_steps"]) == log.env_steps
    assert np.diff([int(r["env_steps"]) for r in rows]).min() > 0
    for row, total in zip(rows, paid, strict=True):
        assert math.isclose(float(row["swarming_return"]), total, rel_tol=1e-6, abs_tol=1e-6)
        assert row["success"] in ("0", "1")


def test_missing_benchmarl_says_how_to_install(monkeypatch, tmp_path):
    for name in ("benchmarl", "benchmarl.experiment", "torchrl.envs.libs.pettingzoo"):
        monkeypatch.setitem(sys.modules, name, None)  # import raises ImportError
    with pytest.raises(BaselinesNotInstalledError, match=r"pip install 'remarl-fc\[baselines\]'"):
        train_benchmarl("mappo", "3u1o", 100, 0, tmp_path)
    assert issubclass(BaselinesNotInstalledError, ConfigError)
    assert INSTALL_HINT == "pip install 'remarl-fc[baselines]'"


def test_bad_arguments_are_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="unknown BenchMARL algorithm"):
        train_benchmarl("coma", "3u1o", 100, 0, tmp_path)
    with pytest.raises(ConfigError, match="budget_steps"):
        train_benchmarl("iql", "3u1o", 0, 0, tmp_path)
    with pytest.raises(ConfigError, match="n_actions"):
        train_benchmarl("iql", "3u1o", 100, 0, tmp_path, n_actions=1)


def test_modules_import_without_benchmarl_and_the_task_says_what_is_missing():
    code = (
        "import sys\n"
        "sys.modules['benchmarl'] = None\n"
        "sys.modules['torchrl'] = None\n"
        "import policies.baseline_env, policies.benchmarl_train, policies.compare\n"
        "assert 'tensordict' not in sys.modules\n"
        "from policies.benchmarl_train import BaselinesNotInstalledError\n"
        "try:\n"
        "    import policies.benchmarl_task\n"
        "except BaselinesNotInstalledError as exc:\n"
        "    assert 'remarl-fc[baselines]' in str(exc), exc\n"
        "else:\n"
        "    raise SystemExit('policies.benchmarl_task imported without BenchMARL')\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
