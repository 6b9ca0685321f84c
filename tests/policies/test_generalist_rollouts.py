"""DAgger's rollouts flown in processes of their own while the learner learns."""

from __future__ import annotations

import dataclasses
import itertools
import os

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from tiny_policy import tiny_run_cfg

from policies.generalist_dagger import fly_dagger
from policies.generalist_ppo import PPONets
from policies.generalist_rollouts import RolloutFleet, split_worlds
from policies.generalist_train import RunBook, make_worlds, teach, train_generalist
from policies.train import load_checkpoint
from sim.errors import WorkerFailed


@given(uavs=st.lists(st.integers(1, 200), min_size=1, max_size=40), parts=st.integers(1, 6))
def test_the_worlds_split_into_contiguous_runs_of_about_equal_uavs(uavs, parts):
    runs = split_worlds(uavs, parts)
    assert len(runs) == min(parts, len(uavs))
    assert runs[0][0] == 0 and runs[-1][1] == len(uavs)
    assert all(first < stop for first, stop in runs)  # none empty
    assert all(a[1] == b[0] for a, b in itertools.pairwise(runs))  # contiguous
    # a run holds more than its share only by its last world
    share = sum(uavs) / len(runs)
    assert all(sum(uavs[first : stop - 1]) <= share + 1e-9 for first, stop in runs)


def self_shield_book(tmp_path, start, **changes) -> RunBook:
    cfg = tiny_run_cfg(
        tmp_path, init=str(start), teacher="self-shield", dagger_fraction=1.0, **changes
    )
    return RunBook.open(cfg, tmp_path / "run", PPONets.create, resume=False)


def test_a_process_flies_what_this_one_would_with_the_same_weights_and_stream(
    tmp_path, start_policy
):
    book = self_shield_book(tmp_path, start_policy)
    cfg = book.cfg
    with RolloutFleet(book, 2) as fleet:
        assert len(fleet.runs) == 2
        first = fleet.fly(lambda: 0.5)
        second = fleet.fly(lambda: 0.25)  # asked for with the first, before any learning
    assert first.beta == 0.5 and second.beta == 0.5

    # the same rollouts flown here: each run of worlds from the start, its own stream
    worlds = make_worlds(cfg, book.layout, np.random.default_rng([cfg.seed, 1]))
    expected = []
    for index, (lo, hi) in enumerate(fleet.runs):
        mine = worlds[lo:hi]
        for number in range(2):
            rng = np.random.default_rng([cfg.seed, 2, index, number])
            expected.append(
                fly_dagger(
                    mine,
                    book.nets.actor,
                    lambda ws: teach(ws, cfg, book.anchor, "cpu"),
                    0.5,
                    cfg,
                    book.goal_value,
                    rng,
                    "cpu",
                )
            )
    # per process: its first rollout, then its second
    here = [expected[0:2], expected[2:4]]
    for number, got in enumerate((first, second)):
        rows = [row for part in here for row in part[number].flown]
        assert len(got.flown) == len(worlds)
        for mine, theirs in zip(got.flown, rows, strict=True):
            for a, b in zip(mine, theirs, strict=True):
                np.testing.assert_array_equal(a[0].obs, b[0].obs)
                np.testing.assert_array_equal(a[0].reward, b[0].reward)
                np.testing.assert_array_equal(a[1], b[1])  # the actions flown
                np.testing.assert_array_equal(a[3], b[3])  # the teacher's labels
        assert got.transitions == sum(part[number].transitions for part in here)
        assert got.drawn == [n for part in here for n in part[number].drawn]


def test_a_run_with_a_rollout_process_learns_counts_and_resumes(
    tmp_path, start_policy, monkeypatch
):
    import policies.generalist_ppo as generalist_ppo

    flown = []  # the rollouts the run learned from came from its processes

    class Counted(RolloutFleet):
        def fly(self, beta):
            flown.append(len(self.procs))
            return super().fly(beta)

    monkeypatch.setattr(generalist_ppo, "RolloutFleet", Counted)
    book = self_shield_book(tmp_path, start_policy)
    cfg = dataclasses.replace(book.cfg, rollout_processes=1, total_iterations=3)
    out = tmp_path / "fleet"
    summary = train_generalist(cfg, out)
    assert summary["iterations"] == 3 and summary["transitions"] > 0
    assert flown == [1, 1, 1]
    nets = PPONets.create(book.layout, cfg, "cpu")
    meta = load_checkpoint(out / "last.safetensors", nets)
    assert meta["iteration"] == 3 and meta["updates"] == 3 * cfg.dagger_updates
    # the episodes the process drew are the run's: a resumed run draws after them
    assert sum(meta["drawn"].values()) >= sum(w.envs for w in book.worlds)
    again = train_generalist(dataclasses.replace(cfg, total_iterations=4), out, resume=True)
    assert again["iterations"] == 4


def test_a_failed_or_killed_process_is_a_clear_error_and_nothing_is_left_running(
    tmp_path, start_policy
):
    book = self_shield_book(tmp_path, start_policy)
    threads = torch.get_num_threads()
    with RolloutFleet(book, 1) as fleet:
        # the learner leaves the rollout process its core, and takes its threads back after
        assert torch.get_num_threads() <= max(1, (os.cpu_count() or 1) - 1)
        fleet.conns[0].send(("not", "a request"))  # what no learner sends
        with pytest.raises(WorkerFailed, match="failed: ValueError"):
            fleet._receive(0, fleet.conns[0])
    assert not fleet.procs[0].is_alive()
    with RolloutFleet(book, 1) as fleet:
        fleet.procs[0].kill()
        with pytest.raises(WorkerFailed, match="stopped"):
            fleet.fly(lambda: 1.0)
    assert not fleet.procs[0].is_alive()
    assert torch.get_num_threads() == threads


def test_rollout_processes_are_refused_where_there_is_no_dagger_phase(tmp_path, capsys):
    from remarl_fc.cli import main

    code = main(
        [
            "train",
            "--generalist",
            "--teacher",
            "none",
            "--rollout-processes",
            "1",
            "--out",
            str(tmp_path / "r"),
        ]
    )
    assert code == 2
    assert "drop --rollout-processes" in capsys.readouterr().err
    with pytest.raises(ValueError, match="rollout_processes: must be >= 0"):
        tiny_run_cfg(tmp_path, rollout_processes=-1)


def test_a_resumed_run_may_take_other_rollout_processes():
    from policies.config import GeneralistConfig, resumed_config

    stored = dataclasses.asdict(GeneralistConfig())
    stored["suites"] = list(stored["suites"])
    assert resumed_config(stored, rollout_processes=1).rollout_processes == 1
    assert resumed_config(stored).rollout_processes == 0
