"""DAgger before PPO: the aggregated labels, β's schedule, the supervised step, a tiny run."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from test_generalist_ppo import LAYOUT, spy_teacher_horizons, tiny_ppo_run

from policies.config import GeneralistConfig
from policies.generalist_dagger import Labels, clone_update, dagger_beta
from policies.generalist_ppo import PPONets


@settings(max_examples=50, deadline=None)
@given(
    capacity=st.integers(1, 12),
    chunks=st.lists(st.integers(0, 15), min_size=1, max_size=6),
)
def test_labels_keep_the_newest_rows_up_to_their_capacity(capacity, chunks):
    labels = Labels.create(capacity, 2)
    added: list[float] = []
    for rows in chunks:
        values = np.arange(len(added), len(added) + rows, dtype=np.float32)
        labels.add(np.stack([values, -values], axis=1), values)
        added += values.tolist()
    kept = sorted(labels.action[: labels.count].tolist())
    assert labels.count == min(len(added), capacity)
    assert kept == added[len(added) - labels.count :]  # the newest, each once
    np.testing.assert_array_equal(labels.obs[: labels.count, 0], labels.action[: labels.count])


def test_labels_refuse_rows_that_do_not_match_and_sampling_nothing():
    labels = Labels.create(4, 3)
    with pytest.raises(ValueError, match="do not match"):
        labels.add(np.zeros((2, 3), np.float32), np.zeros(3, np.float32))
    with pytest.raises(ValueError, match="do not match"):
        labels.add(np.zeros((2, 2), np.float32), np.zeros(2, np.float32))
    with pytest.raises(ValueError, match="nothing to sample"):
        labels.sample(1, np.random.default_rng(0))
    labels.add(np.ones((1, 3), np.float32), np.full(1, 0.5, np.float32))
    obs, action = labels.sample(5, np.random.default_rng(0))
    assert obs.shape == (5, 3) and np.all(action == 0.5)


def test_beta_falls_from_its_start_to_zero_over_half_the_phase():
    cfg = GeneralistConfig(teacher="orca-shield", dagger_fraction=0.4, dagger_beta=0.8)
    assert dagger_beta(cfg, 0.0) == pytest.approx(0.8)
    assert dagger_beta(cfg, 0.1) == pytest.approx(0.4)
    assert dagger_beta(cfg, 0.2) == 0.0 and dagger_beta(cfg, 0.9) == 0.0
    no_phase = GeneralistConfig(dagger_fraction=0.0)
    assert dagger_beta(no_phase, 0.0) == 0.0  # no phase, no teacher flying
    assert dagger_beta(GeneralistConfig(teacher="none"), 0.0) == 0.0  # no teacher, no phase


def test_dagger_applies_only_to_ppo_with_a_teacher():
    assert GeneralistConfig().dagger_share() == 0.5  # the shipped recipe
    assert GeneralistConfig(teacher="none").dagger_share() == 0.0
    assert GeneralistConfig(learner="td3").dagger_share() == 0.0


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"dagger_fraction": 1.5, "teacher": "orca-shield"}, r"in \[0, 1\]"),
        ({"dagger_beta": 1.5}, r"in \[0, 1\]"),
        ({"dagger_batch": 0}, ">= 1"),
        ({"dagger_lr": 0.0}, "> 0"),
    ],
)
def test_bad_dagger_settings_are_refused_by_name(changes, message):
    with pytest.raises(ValueError, match=f"dagger_.*{message}"):
        GeneralistConfig(**changes)


def test_supervised_steps_fit_the_actor_to_the_labels():
    torch.manual_seed(0)
    cfg = GeneralistConfig(hidden=16)
    nets = PPONets.create(LAYOUT, cfg, "cpu")
    rng = np.random.default_rng(0)
    obs = torch.from_numpy(rng.normal(0, 1, (256, LAYOUT.size)).astype(np.float32))
    teacher = torch.tanh(obs[:, 0] - obs[:, 1])  # something the self block carries
    value_before = [p.detach().clone() for p in nets.value.parameters()]
    opt = torch.optim.Adam(nets.actor.parameters(), lr=cfg.dagger_lr)
    first = clone_update(nets.actor, opt, obs, teacher, cfg.grad_clip)
    for _ in range(300):
        last = clone_update(nets.actor, opt, obs, teacher, cfg.grad_clip)
    assert last < 0.25 * first
    # only the actor learns from the labels
    for before, after in zip(value_before, nets.value.parameters(), strict=True):
        assert torch.equal(before, after)


@pytest.mark.parametrize("teacher", ["orca-shield", "oracle"])
def test_a_tiny_run_clones_first_then_goes_on_with_ppo(tmp_path, teacher, monkeypatch):
    import policies.generalist_train as generalist_train

    asked = []  # the configured teacher is the one that labels
    plan = generalist_train.oracle_actions
    monkeypatch.setattr(generalist_train, "oracle_actions", lambda *a: asked.append(1) or plan(*a))
    horizons = spy_teacher_horizons(monkeypatch)
    summary, seen = tiny_ppo_run(
        tmp_path,
        teacher=teacher,
        dagger_fraction=0.5,
        dagger_updates=3,
        dagger_batch=16,
        teacher_horizon_s=14,
    )
    assert set(horizons) <= {14}  # ORCA (the oracle's fallback too) looks as far as the run says
    assert horizons or teacher == "oracle"
    # a row is logged for each iteration once an episode has ended: DAgger's iterations (the
    # first two of three: under half the budget), then PPO's
    phases = ["dagger" if "charts/dagger_beta" in row else "ppo" for row in seen]
    assert "dagger" in phases and phases[-1] == "ppo"
    assert phases == sorted(phases)  # every DAgger row before every PPO row
    dagger = [row for row in seen if "charts/dagger_beta" in row]
    assert all(row["losses/clone"] > 0 and row["charts/dagger_labels"] > 0 for row in dagger)
    assert dagger[-1]["iteration"] <= 2
    assert summary["teacher"] == teacher
    assert bool(asked) == (teacher == "oracle")
