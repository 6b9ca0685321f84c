"""BenchMARL smoke test: every baseline trains a little on the simulator (needs the extra).

Needs ``pip install 'remarl-fc[baselines]'``: where BenchMARL is missing, the whole module is
skipped, with the reason. A few seconds per algorithm on one core.
"""

import csv
import json
import pickle
import sys

import numpy as np
import pytest

from policies.baseline_env import SwarmBaselineEnv
from policies.benchmarl_train import (
    ALGORITHMS,
    BaselinesNotInstalledError,
    quiet_benchmarl,
    require_benchmarl,
    train_benchmarl,
)

try:
    require_benchmarl()
except BaselinesNotInstalledError as exc:
    pytest.skip(str(exc), allow_module_level=True)

from policies.benchmarl_task import GROUP, SwarmTask, make_task  # needs the extra

BUDGET = 400


def read_curve(path):
    with path.open() as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_trains_writes_curve_and_evaluates(algorithm, tmp_path):
    summary = train_benchmarl(algorithm, "3u1o", BUDGET, 0, tmp_path, eval_episodes=5)
    assert summary["algorithm"] == algorithm
    assert summary["reward"] == "swarming"
    assert summary["n_actions"] == 11
    assert 0.0 in summary["headings_deg"]
    assert summary["env_steps"] == summary["frames"] == BUDGET
    assert summary["episodes"] == 5.0
    assert 0.0 <= summary["success_rate"] <= 1.0
    assert np.isfinite(summary["swarming_return"])
    assert json.loads((tmp_path / "summary.json").read_text())["algorithm"] == algorithm
    rows = read_curve(tmp_path / "curve.csv")
    assert list(rows[0]) == ["env_steps", "episode", "swarming_return", "success"]
    assert len(rows) == summary["train_episodes"] > 0
    steps = [int(r["env_steps"]) for r in rows]
    assert steps == sorted(steps)
    assert steps[-1] <= BUDGET
    assert [int(r["episode"]) for r in rows] == list(range(1, len(rows) + 1))
    assert {r["success"] for r in rows} <= {"0", "1"}
    returns = np.array([float(r["swarming_return"]) for r in rows])
    assert np.isfinite(returns).all()
    assert (np.abs(returns) <= 3 * 40).all()  # N agents x max_steps x |r| <= 1
    # rendering stays off: the CUDA-built torchvision from PyPI does not load beside CPU torch
    assert "torchvision" not in sys.modules


@pytest.mark.slow
def test_paper_grid_of_ten_headings(tmp_path):
    summary = train_benchmarl("mappo", "2u1o", 200, 1, tmp_path, n_actions=10, eval_episodes=2)
    assert summary["n_actions"] == 10
    assert len(summary["headings_deg"]) == 10
    assert 0.0 not in summary["headings_deg"]


@pytest.mark.slow
def test_budget_rounds_up_to_whole_batches_only(tmp_path):
    """601 steps: two batches of 304 (4 environments), not a third batch (TorchRL's rounding)."""
    summary = train_benchmarl("iql", "3u1o", 601, 0, tmp_path, eval_episodes=1)
    assert summary["frames"] == summary["env_steps"] == 608


def test_task_builds_the_torchrl_env_and_pickles():
    task = make_task("3u1o", 11)
    with quiet_benchmarl():
        env = task.get_env_fun(1, False, 0, "cpu")()
    assert task.group_map(env) == {GROUP: ["uav_0", "uav_1", "uav_2"]}
    assert env.full_action_spec[GROUP, "action"].space.n == 11
    # the global state is the adapter's: N observations / CLIP and N flags, within its bounds
    state = task.state_spec(env)["state"]
    expected = SwarmBaselineEnv("3u1o").state_space
    assert tuple(state.shape) == expected.shape == (3 * 28 + 3,)
    np.testing.assert_array_equal(state.space.low.numpy(), expected.low)
    np.testing.assert_array_equal(state.space.high.numpy(), expected.high)
    assert task.max_steps(env) == 40
    td = env.rollout(60, break_when_any_done=True)
    assert td["next", "done"][-1].all()
    assert len(td) <= 40
    assert state.is_in(td["state"][0])
    assert pickle.loads(pickle.dumps(task)) == task  # BenchMARL pickles its task
    assert type(pickle.loads(pickle.dumps(task))) is SwarmTask  # by reference, a real class
