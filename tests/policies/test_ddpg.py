import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="needs the train extra: pip install 'remarl-fc[train]'")

from policies.buffer import ReplayBuffer  # noqa: E402 - after the skip
from policies.config import DDPGConfig, TrainConfig  # noqa: E402
from policies.ddpg import Actor, Critic, DDPGNets, ddpg_update, soft_update  # noqa: E402


def test_networks_are_the_papers_and_agents_are_independent():
    torch.manual_seed(0)
    actor, critic = Actor(3, 28, 256), Critic(3, 28, 256)
    obs = torch.randn(3, 5, 28)
    a = actor(obs)
    assert a.shape == (3, 5)
    assert (a.abs() <= 1).all()
    assert critic(obs, a).shape == (3, 5)
    assert actor.l1.weight.shape == (3, 28, 256)
    assert critic.l2.weight.shape == (3, 512, 256)
    # Changing agent 0's weights leaves agents 1 and 2 untouched.
    before = actor(obs).detach()
    with torch.no_grad():
        actor.l1.weight[0] += 1.0
    after = actor(obs).detach()
    assert not torch.allclose(before[0], after[0])
    assert torch.equal(before[1:], after[1:])


def test_soft_update_moves_targets_by_tau():
    src, dst = Actor(1, 4, 8), Actor(1, 4, 8)
    with torch.no_grad():
        for p in src.parameters():
            p.fill_(1.0)
        for p in dst.parameters():
            p.fill_(0.0)
    soft_update(dst, src, 0.25)
    assert all(torch.allclose(p, torch.full_like(p, 0.25)) for p in dst.parameters())


def test_critic_learns_a_constant_reward_and_terminal_values():
    """With terminal transitions the critic target is r + γ·terminal_value: it must fit it."""
    torch.manual_seed(0)
    cfg = DDPGConfig(hidden=32, critic_lr=3e-3, actor_lr=1e-4, tau=0.05)
    nets = DDPGNets.create(2, 6, cfg)
    buf = ReplayBuffer(512, 2, 6)
    rng = np.random.default_rng(0)
    for _ in range(4):
        obs = rng.normal(size=(64, 2, 6)).astype(np.float32)
        act = rng.uniform(-1, 1, (64, 2)).astype(np.float32)
        buf.add(
            obs,
            act,
            np.ones((64, 2), np.float32),
            obs,
            np.ones((64, 2), bool),
            np.full((64, 2), 10.0, np.float32),
            np.ones((64, 2), bool),
        )
    for _ in range(400):
        stats = ddpg_update(nets, buf.sample(64, rng, shared=False), cfg)
    assert stats["values/q_mean"] == pytest.approx(1.0 + cfg.gamma * 10.0, rel=0.05)


def test_masked_transitions_do_not_count():
    cfg = DDPGConfig(hidden=16)
    buf = ReplayBuffer(16, 2, 3)
    obs = np.zeros((4, 2, 3), np.float32)
    buf.add(
        obs,
        np.zeros((4, 2), np.float32),
        np.full((4, 2), 5.0, np.float32),
        obs,
        np.zeros((4, 2), bool),
        np.zeros((4, 2), np.float32),
        np.array([[True, False]] * 4),
    )
    batch = buf.sample(8, np.random.default_rng(0), shared=False)
    assert batch.weight.shape == (2, 8)
    assert batch.weight[0].eq(1).all() and batch.weight[1].eq(0).all()
    shared = buf.sample(8, np.random.default_rng(0), shared=True)
    assert shared.obs.shape == (1, 16, 3)
    DDPGNets.create(1, 3, cfg)  # shared networks build for one "agent"


def test_configs_validate():
    with pytest.raises(ValueError, match="gamma"):
        DDPGConfig(gamma=1.0)
    with pytest.raises(ValueError, match="reward"):
        TrainConfig(reward="team")
