"""A tiny in-process training run: learning must happen, and the run must be resumable."""

import json

import numpy as np
import pytest

pytest.importorskip("torch", reason="needs the train extra: pip install 'remarl-fc[train]'")

from policies.config import DDPGConfig, TrainConfig
from policies.export import export_policy
from policies.train import policy_actions
from remarl_fc.errors import PolicyError, PolicySpecMismatch
from remarl_fc.policy_io import load_policy
from sim.evaluation import run_episodes, summarize
from sim.scenarios import load_scenario

SCENARIO = {"obstacles": {"speed_m_s": 0.0, "spawn_x_m": 160.0}}


@pytest.fixture(scope="module")
def static_2u1o(tmp_path_factory):
    path = tmp_path_factory.mktemp("scen") / "static2.toml"
    path.write_text(
        '[uav]\ncount = 2\nformation = "line"\n'
        "[obstacles]\ncount = 1\nspeed_m_s = 0.0\nspawn_x_m = 160.0\n"
    )
    return str(path)


@pytest.fixture(scope="module")
def trained(tmp_path_factory, static_2u1o):
    from policies.train import train

    out = tmp_path_factory.mktemp("run")
    cfg = TrainConfig(
        scenario=static_2u1o,
        num_envs=16,
        total_steps=900,
        eval_every=450,
        eval_episodes=50,
        seed=1,
        ddpg=DDPGConfig(warmup_steps=800),
    )
    summary = train(cfg, out)
    return out, summary


@pytest.mark.slow  # the module's `trained` run: about 40 s on one core
def test_learning_happens(trained, static_2u1o):
    out, summary = trained
    evals = [json.loads(line) for line in (out / "evals.jsonl").read_text().splitlines()]
    assert len(evals) == 2
    # Before training, flying (near-)straight hits the static obstacle in the middle.
    before = summarize(
        run_episodes(lambda o: np.zeros(o.shape[:-1], np.float32), static_2u1o, 50, 7)
    )
    assert before["success_rate"] < 0.1
    assert summary["best_success"] > before["success_rate"] + 0.5


@pytest.mark.slow  # the module's `trained` run: about 40 s on one core
def test_export_load_and_numpy_matches_torch(trained, tmp_path, static_2u1o):
    import torch

    from policies.ddpg import DDPGNets
    from policies.train import load_checkpoint

    out, _ = trained
    path = tmp_path / "p.safetensors"
    meta = export_policy(out, path, metrics={"success_rate": 1.0})
    policy = load_policy(path)
    assert policy.agents == 2 and meta["metrics"]["success_rate"] == 1.0
    policy.check_scenario(load_scenario(static_2u1o))
    nets = DDPGNets.create(2, policy.layout.size, DDPGConfig())
    load_checkpoint(out / "best.safetensors", nets)
    obs = np.random.default_rng(0).normal(size=(64, 2, policy.layout.size)).astype(np.float32)
    torch_actions = policy_actions(nets, obs, shared=False)
    np.testing.assert_allclose(policy.act(obs), torch_actions, atol=1e-5)
    with torch.no_grad():
        q_torch = (
            nets.critic(
                torch.from_numpy(obs.swapaxes(0, 1).copy()),
                torch.from_numpy(torch_actions.T.copy()),
            )
            .numpy()
            .T
        )
    np.testing.assert_allclose(policy.q_values(obs, torch_actions), q_torch, atol=1e-4)


@pytest.mark.slow  # the module's `trained` run: about 40 s on one core
def test_resume_continues_from_the_checkpoint(trained, tmp_path, static_2u1o):
    import shutil

    from policies.train import train

    out, _ = trained
    copy = tmp_path / "run"
    shutil.copytree(out, copy)
    more = TrainConfig(
        scenario=static_2u1o, num_envs=16, total_steps=950, eval_every=475, eval_episodes=10, seed=1
    )
    resumed = train(more, copy, resume=True)
    assert resumed["steps"] == 950  # started from step 900, not from 0


@pytest.mark.slow  # the module's `trained` run: about 40 s on one core
def test_bad_policy_files_are_clear_errors(tmp_path, trained):
    with pytest.raises(PolicyError, match="no such policy file"):
        load_policy(tmp_path / "absent.safetensors")
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"\x00" * 64)
    with pytest.raises(PolicyError, match="not a readable safetensors"):
        load_policy(junk)
    from safetensors.numpy import save_file

    other = tmp_path / "other.safetensors"
    save_file({"x": np.zeros(3, np.float32)}, str(other))
    with pytest.raises(PolicyError, match="not a remarl-fc policy"):
        load_policy(other)
    with pytest.raises(PolicyError, match="zoo"):
        load_policy("no-such-policy")
    out, _ = trained
    path = tmp_path / "p.safetensors"
    export_policy(out, path)
    policy = load_policy(path)
    with pytest.raises(PolicySpecMismatch, match="number of UAVs"):
        policy.check_scenario(load_scenario("3u2o"))
    with pytest.raises(PolicySpecMismatch):
        policy.act(np.zeros((3, policy.layout.size), np.float32))


def test_a_checkpoint_keeps_extra_run_state_apart_from_the_networks(tmp_path):
    import torch

    from policies.ddpg import DDPGNets
    from policies.train import load_checkpoint, load_checkpoint_tensors, save_checkpoint

    torch.manual_seed(0)
    nets = DDPGNets.create(2, 9, DDPGConfig())
    path = tmp_path / "last.safetensors"
    extra = {"labels.rows": torch.arange(6.0).reshape(3, 2)}
    save_checkpoint(path, nets, {"iteration": 7}, extra)
    assert load_checkpoint(path, DDPGNets.create(2, 9, DDPGConfig())) == {"iteration": 7}
    kept = load_checkpoint_tensors(path, "labels.")
    assert kept.keys() == extra.keys() and torch.equal(kept["labels.rows"], extra["labels.rows"])
    assert load_checkpoint_tensors(path, "nothing.") == {}
    # a name a network or optimiser owns is refused, and nothing is written
    path.unlink()
    owner = next(iter(nets.modules()))
    with pytest.raises(ValueError, match="collides with the networks'"):
        save_checkpoint(path, nets, {}, {f"{owner}.weight": torch.zeros(1)})
    assert not path.exists()
