"""DAgger before PPO: the aggregated labels, β's schedule, the supervised step, a tiny run."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from test_generalist_ppo import LAYOUT, spy_teacher_horizons, tiny_ppo_run

from policies.config import GeneralistConfig
from policies.generalist_dagger import (
    CHECKPOINT_PREFIX,
    NOT_SAFE,
    Dagger,
    Labels,
    clone_update,
    dagger_beta,
    label_weights,
    safe_set_error,
)
from policies.generalist_ppo import PPONets
from sim.shield import ShieldConfig


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
        labels.add(np.stack([values, -values], axis=1), values, 2 * values)
        added += values.tolist()
    kept = sorted(labels.action[: labels.count].tolist())
    assert labels.count == min(len(added), capacity)
    assert kept == added[len(added) - labels.count :]  # the newest, each once
    np.testing.assert_array_equal(labels.obs[: labels.count, 0], labels.action[: labels.count])
    np.testing.assert_array_equal(labels.weight[: labels.count], 2 * labels.action[: labels.count])


def test_labels_refuse_rows_that_do_not_match_and_sampling_nothing():
    labels = Labels.create(4, 3)
    two, three = np.zeros(2, np.float32), np.zeros(3, np.float32)
    with pytest.raises(ValueError, match="do not match"):
        labels.add(np.zeros((2, 3), np.float32), three, three)
    with pytest.raises(ValueError, match="do not match"):
        labels.add(np.zeros((2, 2), np.float32), two, two)
    with pytest.raises(ValueError, match="do not match"):
        labels.add(np.zeros((2, 3), np.float32), two, three)
    with pytest.raises(ValueError, match="nothing to sample"):
        labels.sample(1, np.random.default_rng(0))
    labels.add(np.ones((1, 3), np.float32), np.full(1, 0.5, np.float32), np.full(1, 3, np.float32))
    obs, action, weight = labels.sample(5, np.random.default_rng(0))
    assert obs.shape == (5, 3) and np.all(action == 0.5) and np.all(weight == 3)


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
        ({"dagger_turn_weight": -1.0}, ">= 0"),
        ({"dagger_turn_weight": float("inf")}, ">= 0"),
        ({"dagger_separation_weight": -0.5}, ">= 0"),
        ({"dagger_separation_weight": float("nan")}, ">= 0"),
        ({"dagger_separation_horizon_s": -1.0}, ">= 0"),
        ({"dagger_safe_set_weight": -1.0}, ">= 0"),
        ({"dagger_safe_set_weight": float("nan")}, ">= 0"),
        ({"dagger_safe_set_weight": 4.0, "teacher": "orca-shield"}, "self-shield"),
        ({"dagger_safe_set_side": True}, "dagger_safe_set_weight > 0"),
        (
            {"dagger_safe_set_weight": 4.0, "teacher": "self-shield", "init": "generalist"},
            "dagger_fraction 1",
        ),
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


@settings(max_examples=50, deadline=None)
@given(
    taught=st.floats(-1, 1),
    goal=st.floats(-1, 1),
    kappa=st.floats(0, 50),
)
def test_a_label_weighs_more_the_further_the_teacher_turns_from_the_goal(taught, goal, kappa):
    weight = label_weights(np.array([taught, goal]), np.array([goal, goal]), kappa)
    assert weight.dtype == np.float32
    assert weight[1] == 1.0  # flying straight to the target: the base weight
    assert weight[0] == pytest.approx(1.0 + kappa * abs(taught - goal), rel=1e-6)
    assert label_weights(np.array([taught]), np.array([goal]), 0.0)[0] == 1.0


def test_the_weighted_step_is_the_plain_one_for_equal_weights_and_follows_heavy_labels():
    obs = torch.from_numpy(np.random.default_rng(1).normal(0, 1, (64, LAYOUT.size)).astype("f4"))
    teacher = torch.linspace(-1, 1, 64)
    losses = []
    for weight in (None, torch.full((64,), 3.0)):
        torch.manual_seed(0)
        nets = PPONets.create(LAYOUT, GeneralistConfig(hidden=16), "cpu")
        opt = torch.optim.Adam(nets.actor.parameters(), lr=1e-3)
        losses.append(clone_update(nets.actor, opt, obs, teacher, 1.0, weight))
    assert losses[0] == pytest.approx(losses[1], rel=1e-6)
    # every weight on one label: the step fits that label alone
    torch.manual_seed(0)
    nets = PPONets.create(LAYOUT, GeneralistConfig(hidden=16), "cpu")
    with torch.no_grad():
        alone = float((nets.actor(obs[:1]) - teacher[:1]) ** 2)
    only_first = torch.zeros(64)
    only_first[0] = 1.0
    opt = torch.optim.Adam(nets.actor.parameters(), lr=1e-3)
    assert clone_update(nets.actor, opt, obs, teacher, 1.0, only_first) == pytest.approx(alone)


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


@pytest.mark.parametrize("turn_weight", [0.0, 5.0])
def test_dagger_weighs_its_labels_by_the_runs_turn_weight(tmp_path, monkeypatch, turn_weight):
    import policies.generalist_dagger as generalist_dagger

    added: list[np.ndarray] = []
    stepped: list[torch.Tensor | None] = []
    add, step = generalist_dagger.Labels.add, generalist_dagger.clone_update

    def spied_add(self, obs, action, weight, safe=None):
        added.append(weight.copy())
        return add(self, obs, action, weight, safe)

    def spied_step(actor, opt, obs, teacher, clip, weight=None, separation=None, safe=None):
        stepped.append(weight)
        return step(actor, opt, obs, teacher, clip, weight, separation, safe)

    monkeypatch.setattr(generalist_dagger.Labels, "add", spied_add)
    monkeypatch.setattr(generalist_dagger, "clone_update", spied_step)
    tiny_ppo_run(
        tmp_path,
        teacher="orca-shield",
        dagger_fraction=0.5,
        dagger_updates=3,
        dagger_batch=16,
        dagger_turn_weight=turn_weight,
    )
    weights = np.concatenate(added)
    assert stepped and weights.size
    if turn_weight == 0:  # every label alike, the plain mean
        assert np.all(weights == 1.0) and all(w is None for w in stepped)
    else:  # 1 where the teacher flies straight for the target, up to 1 + 2κ
        assert weights.min() == 1.0 and 1.0 < weights.max() <= 1.0 + 2 * turn_weight
        assert all(w is not None and w.shape == (16,) for w in stepped)


def test_the_safe_set_error_is_the_squared_distance_to_the_nearest_safe_heading():
    sets = torch.zeros((4, 5), dtype=torch.bool)  # headings −1, −0.5, 0, 0.5, 1
    sets[0, [0, 4]] = True  # either hard turn
    sets[1, 2] = True  # straight on only
    sets[2, [3, 4]] = True
    action = torch.tensor([0.2, 0.2, 0.5, 0.0])
    error = safe_set_error(action, sets)
    expected = [0.8**2, 0.2**2, 0.0, NOT_SAFE]  # the last row: no heading passes
    np.testing.assert_allclose(error.numpy(), expected, rtol=1e-6)


def test_a_safe_set_replaces_its_rows_label_and_leaves_the_others_alone():
    obs = torch.from_numpy(np.random.default_rng(2).normal(0, 1, (8, LAYOUT.size)).astype("f4"))
    teacher = torch.linspace(-1, 1, 8)
    k = ShieldConfig().headings
    sets = torch.zeros((8, k), dtype=torch.bool)
    sets[:4, : k // 2] = True  # the first four: any turn to the right of straight on

    def loss(labels: torch.Tensor, weight: float, given: torch.Tensor | None = sets) -> float:
        torch.manual_seed(0)
        nets = PPONets.create(LAYOUT, GeneralistConfig(hidden=16), "cpu")
        opt = torch.optim.Adam(nets.actor.parameters(), lr=1e-3)
        safe = None if given is None else (given, weight)
        return clone_update(nets.actor, opt, obs, labels, 1.0, None, None, safe)

    moved = teacher.clone()
    moved[:4] = 0.9  # the rows with a set: their one label does not count
    assert loss(moved, 4.0) == pytest.approx(loss(teacher, 4.0), rel=1e-6)
    moved = teacher.clone()
    moved[4:] = 0.9  # the others': it does
    assert loss(moved, 4.0) != pytest.approx(loss(teacher, 4.0), rel=1e-3)
    # no row with a set: the plain step
    empty = torch.zeros_like(sets)
    assert loss(teacher, 4.0, empty) == pytest.approx(loss(teacher, 4.0, None), rel=1e-6)
    with torch.no_grad():
        torch.manual_seed(0)
        nets = PPONets.create(LAYOUT, GeneralistConfig(hidden=16), "cpu")
        action = nets.actor(obs)
    gap = safe_set_error(action, sets)
    plain = (action - teacher) ** 2
    for weight in (1.0, 4.0):
        want = torch.where(sets.any(-1), weight * gap, plain).mean()
        assert loss(teacher, weight) == pytest.approx(float(want), rel=1e-5)


def test_safe_sets_come_back_whole_from_the_checkpoint_and_a_setless_one_is_refused():
    cfg = GeneralistConfig(
        hidden=8,
        dagger_rows=5,
        teacher="self-shield",
        init="generalist",
        dagger_fraction=1.0,
        dagger_safe_set_weight=4.0,
    )
    nets = PPONets.create(LAYOUT, cfg, "cpu")
    dagger = Dagger.create(cfg, LAYOUT.size, nets)
    k = dagger.labels.headings
    assert k == ShieldConfig().headings
    rng = np.random.default_rng(3)
    for count in (3, 4):
        obs = rng.normal(size=(count, LAYOUT.size)).astype(np.float32)
        safe = rng.random((count, k)) < 0.3
        dagger.labels.add(obs, np.zeros(count, np.float32), np.ones(count, np.float32), safe)
        last = safe
    np.testing.assert_array_equal(dagger.labels.safe_oldest_first()[-4:], last)
    again = Dagger.create(cfg, LAYOUT.size, PPONets.create(LAYOUT, cfg, "cpu"))
    assert again.restore(dagger.state_tensors()) == 5
    np.testing.assert_array_equal(
        again.labels.safe_oldest_first(), dagger.labels.safe_oldest_first()
    )
    _, _, _, sets = again.labels.sample_sets(16, rng)
    assert sets.shape == (16, k)
    plain = Dagger.create(GeneralistConfig(hidden=8, dagger_rows=5), LAYOUT.size, nets)
    plain.labels.add(np.zeros((2, LAYOUT.size), np.float32), np.zeros(2, "f4"), np.ones(2, "f4"))
    with pytest.raises(ValueError, match="--safe-set-weight"):
        again.restore(plain.state_tensors())
    with pytest.raises(ValueError, match="safe sets"):
        again.labels.add(
            np.zeros((1, LAYOUT.size), "f4"),
            np.zeros(1, "f4"),
            np.ones(1, "f4"),
            np.zeros((1, k + 1), bool),
        )


@settings(max_examples=40, deadline=None)
@given(
    capacity=st.integers(1, 10),
    chunks=st.lists(st.integers(0, 13), min_size=1, max_size=5),
    more=st.integers(0, 13),
)
def test_the_dagger_state_comes_back_whole_from_its_checkpoint_tensors(capacity, chunks, more):
    torch.manual_seed(0)
    cfg = GeneralistConfig(hidden=8, dagger_rows=capacity)
    nets = PPONets.create(LAYOUT, cfg, "cpu")
    dagger = Dagger.create(cfg, LAYOUT.size, nets)
    rng = np.random.default_rng(capacity)
    added = 0

    def rows(count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        obs = rng.normal(size=(count, LAYOUT.size)).astype(np.float32)
        return obs, rng.uniform(-1, 1, count).astype(np.float32), np.full(count, 2.0, np.float32)

    for count in chunks:
        dagger.labels.add(*rows(count))
        added += count
    if added:  # the optimiser has moments to keep
        obs, taught, _ = dagger.labels.sample(8, rng)
        clone_update(nets.actor, dagger.opt, torch.from_numpy(obs), torch.from_numpy(taught), 1.0)
    tensors = dagger.state_tensors()
    assert all(name.startswith(CHECKPOINT_PREFIX) for name in tensors)

    again = Dagger.create(cfg, LAYOUT.size, PPONets.create(LAYOUT, cfg, "cpu"))
    assert again.restore(tensors) == min(added, capacity)
    for a, b in zip(dagger.labels.oldest_first(), again.labels.oldest_first(), strict=True):
        np.testing.assert_array_equal(a, b)
    # the same rings: the rows added next push out the same oldest ones
    extra = rows(more)
    dagger.labels.add(*extra)
    again.labels.add(*extra)
    assert again.labels.count == dagger.labels.count
    for a, b in zip(dagger.labels.oldest_first(), again.labels.oldest_first(), strict=True):
        np.testing.assert_array_equal(a, b)
    # and the optimiser's moments
    mine, theirs = dagger.opt.state_dict()["state"], again.opt.state_dict()["state"]
    assert mine.keys() == theirs.keys() and bool(mine) == (added > 0)
    for idx in mine:
        for key in mine[idx]:
            assert torch.equal(torch.as_tensor(mine[idx][key]), torch.as_tensor(theirs[idx][key]))


def test_nothing_to_restore_leaves_the_phase_fresh_and_foreign_labels_are_refused():
    cfg = GeneralistConfig(hidden=8, dagger_rows=4)
    nets = PPONets.create(LAYOUT, cfg, "cpu")
    dagger = Dagger.create(cfg, LAYOUT.size, nets)
    assert dagger.restore({}) == 0 and dagger.labels.count == 0
    other = Dagger.create(cfg, LAYOUT.size + 1, nets)
    other.labels.add(
        np.zeros((2, LAYOUT.size + 1), np.float32), np.zeros(2, np.float32), np.ones(2, np.float32)
    )
    with pytest.raises(ValueError, match="resume the run with its own settings"):
        dagger.restore(other.state_tensors())


def test_a_run_resumed_inside_its_dagger_phase_goes_on_with_its_labels(tmp_path, monkeypatch):
    from tiny_policy import tiny_suite

    import policies.generalist_ppo as generalist_ppo
    from policies.generalist_train import train_generalist
    from policies.train import load_checkpoint_tensors

    iterate = generalist_ppo.dagger_iteration

    def ctrl_c_after(iterations: int) -> None:
        """The next run is stopped by Ctrl-C once it has flown ``iterations`` iterations."""
        flown = []

        def iteration(*args):
            if len(flown) == iterations:
                raise KeyboardInterrupt
            flown.append(1)
            return iterate(*args)

        monkeypatch.setattr(generalist_ppo, "dagger_iteration", iteration)

    cfg = GeneralistConfig(
        suites=(str(tiny_suite(tmp_path)),),
        learner="ppo",
        teacher="orca-shield",
        dagger_fraction=1.0,  # DAgger the whole run
        dagger_updates=2,
        dagger_batch=16,
        agents_per_family=4,
        hidden=8,
        ppo_rollout=3,
        ppo_epochs=1,
        ppo_minibatch=8,
        minutes=0.0,
        total_iterations=4,
        eval_minutes=1e9,  # no validation
        eval_episodes=1,
        device="cpu",
    )
    out = tmp_path / "run"
    last = out / "last.safetensors"
    ctrl_c_after(2)
    with pytest.raises(KeyboardInterrupt):
        train_generalist(cfg, out)
    first = load_checkpoint_tensors(last, CHECKPOINT_PREFIX)
    assert first[f"{CHECKPOINT_PREFIX}labels.obs"].shape[0] > 0
    assert any(".opt." in name for name in first)  # the supervised steps' Adam moments

    ctrl_c_after(1)
    with pytest.raises(KeyboardInterrupt):
        train_generalist(cfg, out, resume=True)
    second = load_checkpoint_tensors(last, CHECKPOINT_PREFIX)
    # the first two iterations' labels, in their order, then the third's
    for name in ("obs", "action", "weight"):
        before, after = (t[f"{CHECKPOINT_PREFIX}labels.{name}"] for t in (first, second))
        assert after.shape[0] > before.shape[0]
        assert torch.equal(after[: before.shape[0]], before)

    # the last iteration ends the phase: the checkpoint no longer carries it
    monkeypatch.setattr(generalist_ppo, "dagger_iteration", iterate)
    assert train_generalist(cfg, out, resume=True)["iterations"] == 4
    assert not load_checkpoint_tensors(last, CHECKPOINT_PREFIX)
