"""A generalist run started from a policy file, and the "self-shield" teacher it enables."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_policy import tiny_run_cfg as tiny_cfg

from policies.config import GeneralistConfig
from policies.generalist_dagger import label_of
from policies.generalist_init import INIT_FILE
from policies.generalist_ppo import PPONets
from policies.generalist_train import (
    TEACHER_TRACK_GROWTH_M_S,
    RunBook,
    shielded,
    train_generalist,
)
from policies.train import load_checkpoint
from remarl_fc.policy_io import load_policy
from sim.errors import ConfigError
from sim.shield import ShieldConfig, passing_side, shield_state


def test_a_run_from_a_policy_file_starts_from_its_actor_and_value_network(tmp_path, start_policy):
    cfg = tiny_cfg(tmp_path, init=str(start_policy), dagger_updates=0, total_iterations=1)
    book = RunBook.open(cfg, tmp_path / "run", PPONets.create, resume=False)
    policy = load_policy(str(start_policy))
    obs = np.random.default_rng(0).normal(size=(7, book.layout.size)).astype(np.float32)
    with torch.no_grad():
        ours = book.nets.actor(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(ours, policy.act(obs), atol=1e-5)
    critic = {k: torch.from_numpy(np.asarray(w)) for k, (w, _) in policy.critic.items()}
    for name, weight in critic.items():
        assert torch.equal(getattr(book.nets.value, name).weight, weight)
    assert (tmp_path / "run" / INIT_FILE).read_bytes() == start_policy.read_bytes()


def test_the_self_shield_teacher_is_the_start_policy_through_the_shield(tmp_path, start_policy):
    cfg = tiny_cfg(tmp_path, init=str(start_policy), teacher="self-shield", dagger_fraction=1.0)
    book = RunBook.open(cfg, tmp_path / "run", PPONets.create, resume=False)
    policy = load_policy(str(start_policy))
    with torch.no_grad():  # the student moves; the teacher's proposals stay the start's
        for p in book.nets.actor.parameters():
            p.add_(0.5)
    for world in book.worlds:
        proposed = policy.act(world.obs).astype(np.float32)
        expected = shielded(world.state, world.cfg, proposed)
        np.testing.assert_allclose(book.teach([world])[0], expected, atol=1e-5)


def safe_set_book(out, start_policy, side: bool) -> RunBook:
    """A self-shield run's book with safe sets at weight 4, cut to a side or not."""
    cfg = tiny_cfg(
        out.parent,
        init=str(start_policy),
        teacher="self-shield",
        dagger_fraction=1.0,
        dagger_safe_set_weight=4.0,
        dagger_safe_set_side=side,
    )
    return RunBook.open(cfg, out, PPONets.create, resume=False)


@pytest.mark.parametrize("side", [False, True])
def test_with_safe_sets_the_self_shield_teacher_gives_each_label_its_set(
    tmp_path, start_policy, side
):
    book = safe_set_book(tmp_path / "run", start_policy, side)
    policy = load_policy(str(start_policy))
    k = ShieldConfig().headings
    for world in book.worlds:
        proposed = policy.act(world.obs).astype(np.float32)
        (taught,) = book.teach([world])
        assert taught.shape == (*proposed.shape, 1 + k)
        np.testing.assert_allclose(
            label_of(taught), shielded(world.state, world.cfg, proposed), atol=1e-5
        )
        teachers = ShieldConfig(mode="on", track_growth_m_s=TEACHER_TRACK_GROWTH_M_S)
        decision = shield_state(teachers, world.cfg, world.state, proposed, world.teacher_vehicle)
        want = decision.safe_headings
        if side:
            want = passing_side(want, decision.action)
        np.testing.assert_array_equal(taught[..., 1:] > 0.5, want)


def test_the_side_option_cuts_every_set_through_passing_side(tmp_path, start_policy, monkeypatch):
    """Where the shield intervenes nowhere the test above cannot tell the cut was made: a cut
    that keeps every heading shows each set went through it, and only with the option."""
    import policies.generalist_train as generalist_train

    monkeypatch.setattr(generalist_train, "passing_side", lambda safe, heading: safe | True)
    for side in (False, True):
        book = safe_set_book(tmp_path / f"run-{side}", start_policy, side)
        for world in book.worlds:
            (taught,) = book.teach([world])
            assert (taught[..., 1:] > 0.5).all() == side


@pytest.mark.parametrize(("neighbours", "mark"), [("proposals", 7.0), ("straight", 9.0)])
def test_the_self_shield_labels_go_through_the_shield(
    tmp_path, start_policy, monkeypatch, neighbours, mark
):
    """Where the shield would turn nothing, the test above cannot tell it was asked: a shield
    that marks what it returns shows every label passed through it, with the neighbours'
    expected arcs the run asks for (``teacher_neighbours``)."""
    import policies.generalist_train as generalist_train

    def marking(state, cfg, proposed, vehicle, arcs):
        return proposed + {"proposals": 7.0, "straight": 9.0}[arcs]

    monkeypatch.setattr(generalist_train, "shielded", marking)
    cfg = tiny_cfg(
        tmp_path,
        init=str(start_policy),
        teacher="self-shield",
        dagger_fraction=1.0,
        teacher_neighbours=neighbours,
    )
    book = RunBook.open(cfg, tmp_path / "run", PPONets.create, resume=False)
    policy = load_policy(str(start_policy))
    for world in book.worlds:
        np.testing.assert_allclose(book.teach([world])[0], policy.act(world.obs) + mark, atol=1e-5)


def test_a_self_shield_run_learns_resumes_and_keeps_its_start(tmp_path, start_policy):
    own = tmp_path / "mine.safetensors"  # a copy the test may destroy
    own.write_bytes(start_policy.read_bytes())
    cfg = tiny_cfg(tmp_path, init=str(own), teacher="self-shield", dagger_fraction=1.0)
    out = tmp_path / "run"
    summary = train_generalist(cfg, out)
    assert summary["iterations"] == 2 and summary["teacher"] == "self-shield"
    first = load_policy(str(own))
    trained = PPONets.create(first.layout, cfg, "cpu")
    load_checkpoint(out / "last.safetensors", trained)
    moved = [
        not torch.equal(getattr(trained.actor, name).weight, torch.from_numpy(np.asarray(w)))
        for name, (w, _) in first.actor.items()
    ]
    assert any(moved)  # DAgger stepped the actor away from its start toward the labels
    own.write_bytes(b"not a policy any more")  # the run kept its own copy
    again = train_generalist(dataclasses.replace(cfg, total_iterations=3), out, resume=True)
    assert again["iterations"] == 3


def test_the_state_teachers_refuse_self_shield_which_needs_its_policy():
    from policies.generalist_train import teacher_plan

    with pytest.raises(ValueError, match=r"RunBook\.teach"):
        teacher_plan(None, None, "self-shield")


def test_the_self_shield_teacher_needs_a_policy_to_start_from():
    with pytest.raises(ValueError, match="init"):
        GeneralistConfig(teacher="self-shield")
    with pytest.raises(ValueError, match="init: the ppo learner only"):
        GeneralistConfig(teacher="self-shield", init="generalist", learner="td3")


def test_a_start_that_sees_otherwise_than_the_run_is_refused_with_what_to_pass(
    tmp_path, start_policy
):
    cfg = tiny_cfg(tmp_path, init=str(start_policy), max_neighbours=3)
    with pytest.raises(ConfigError, match=r"max_neighbours 6 \(the run's: 3\).*--max-neighbours"):
        RunBook.open(cfg, tmp_path / "run", PPONets.create, resume=False)


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("missing.safetensors", None, "no such policy file"),
        ("corrupt.safetensors", b"\x00garbage", "not a valid policy file"),
        ("3u2o", None, "per-slot zoo policy"),
    ],
)
def test_a_bad_start_is_a_clear_error(tmp_path, name, content, match):
    if content is not None:
        (tmp_path / name).write_bytes(content)
    init = str(tmp_path / name) if name.endswith(".safetensors") else name
    cfg = tiny_cfg(tmp_path, init=init)
    with pytest.raises(ConfigError, match=match):
        RunBook.open(cfg, tmp_path / "run", PPONets.create, resume=False)


@pytest.mark.parametrize("name", ["generalist", "robust/generalist"])
def test_a_start_is_named_as_eval_names_a_zoo_policy(name):
    import policies
    from policies.generalist_init import init_path

    shipped = Path(policies.__file__).parent / "zoo" / f"{name}.safetensors"
    assert init_path(name).resolve() == shipped.resolve()
    with pytest.raises(ConfigError, match=r"robust/generalist\) or an exported"):
        init_path("robust/none")


@pytest.mark.parametrize("fraction", [1.0, 0.5])
def test_the_dagger_phase_warms_the_critic_only_where_ppo_follows(tmp_path, start_policy, fraction):
    from policies.generalist_dagger import Dagger, dagger_iteration

    cfg = tiny_cfg(
        tmp_path, init=str(start_policy), teacher="self-shield", dagger_fraction=fraction
    )
    book = RunBook.open(cfg, tmp_path / "run", PPONets.create, resume=False)
    before = [p.detach().clone() for p in book.nets.value.parameters()]
    scalars = dagger_iteration(book, Dagger.create(cfg, book.layout.size, book.nets), [])
    after = list(book.nets.value.parameters())
    moved = any(not torch.equal(a, b) for a, b in zip(after, before, strict=True))
    assert moved == cfg.ppo_follows() == (fraction < 1)
    assert ("losses/value" in scalars) == moved and scalars["losses/clone"] > 0


def test_the_self_shield_teacher_labels_the_worlds_together_as_each_alone(tmp_path, start_policy):
    """One batch of the anchor's proposals for every world (`teach`), the same labels."""
    cfg = tiny_cfg(tmp_path, init=str(start_policy), teacher="self-shield", dagger_fraction=1.0)
    book = RunBook.open(cfg, tmp_path / "run", PPONets.create, resume=False)
    assert len(book.worlds) > 1
    together = book.teach(book.worlds)
    for world, labels in zip(book.worlds, together, strict=True):
        np.testing.assert_allclose(labels, book.teach([world])[0], atol=1e-5)


def test_load_actor_gives_the_files_actor_and_refuses_a_per_slot_policy():
    from policies.generalist_init import load_actor

    actor = load_actor("generalist")
    policy = load_policy("generalist")
    obs = np.random.default_rng(0).normal(size=(9, policy.layout.size)).astype(np.float32)
    with torch.no_grad():
        ours = actor(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(ours, policy.act(obs), atol=1e-5)
    with pytest.raises(ConfigError, match="per-slot"):
        load_actor("3u2o")
