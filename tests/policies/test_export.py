"""The exporter signs what it writes, never writes a file the loader would refuse, and rehashes
files written before checksums (tensors bit for bit, metadata unchanged); generalists too."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from safetensors import safe_open
from safetensors.numpy import load_file, save_file
from tiny_policy import (
    generalist_scenario,
    tiny_generalist_meta,
    tiny_generalist_tensors,
    tiny_meta,
    tiny_tensors,
)

from policies.export import Rehash, rehash_policy, remeasure_policy, write_policy
from remarl_fc.policy_io import PolicyChecksumFailed, load_policy
from sim.observation import ObservationLayout
from sim.policy_file import (
    CHECKSUM_KEY,
    METADATA_KEY,
    PolicyChecksumError,
    PolicyFormatError,
    PolicySchemaError,
    PolicyTensorError,
    PolicyWeightsError,
    policy_checksum,
)
from sim.scenarios import load_scenario
from sim.setnet import SET_LAYERS, set_actor


def write_old(path: Path, tensors: dict[str, np.ndarray], meta: dict[str, Any], **header: str):
    """A policy file as the exporter wrote it before checksums."""
    save_file(tensors, str(path), metadata={**header, METADATA_KEY: json.dumps(meta)})
    return path


def header_of(path: Path) -> dict[str, str]:
    with safe_open(str(path), framework="numpy") as f:
        return dict(f.metadata())


@pytest.fixture
def old_file(tmp_path):
    meta = tiny_meta()
    tensors = tiny_tensors(meta)
    return write_old(tmp_path / "old.safetensors", tensors, meta), tensors, meta


# ------------------------------------------------------------------------------------- rehash


def test_rehash_adds_a_checksum_and_changes_nothing_else(old_file):
    path, tensors, _ = old_file
    before = header_of(path)[METADATA_KEY]
    with pytest.raises(PolicyChecksumFailed, match="older"):
        load_policy(path)
    result = rehash_policy(path)
    assert result.written and result.checksum.startswith("sha256:")
    policy = load_policy(path)
    assert policy.checksum == result.checksum
    new = load_file(str(path))
    assert set(new) == set(tensors)
    for name, arr in tensors.items():
        assert new[name].dtype == arr.dtype and new[name].shape == arr.shape
        assert new[name].tobytes() == arr.tobytes()
    after = json.loads(header_of(path)[METADATA_KEY])
    assert after.pop(CHECKSUM_KEY) == result.checksum
    assert after == json.loads(before) and list(after) == list(json.loads(before))
    assert not path.with_name(path.name + ".part").exists()


def test_rehash_of_a_signed_file_does_nothing(old_file):
    path, _, _ = old_file
    first = rehash_policy(path)
    raw = path.read_bytes()
    assert rehash_policy(path) == Rehash(first.checksum, written=False)
    assert path.read_bytes() == raw


def test_rehash_keeps_other_header_entries(tmp_path):
    meta = tiny_meta()
    path = write_old(tmp_path / "h.safetensors", tiny_tensors(meta), meta, note="kept")
    rehash_policy(path)
    assert header_of(path)["note"] == "kept"
    load_policy(path)


def test_remeasure_replaces_the_figures_and_keeps_the_weights(old_file):
    """A policy flown again: its metrics are the new ones (NaN as null), signed; the tensors
    bit for bit and every other metadata entry as they were; a damaged file is refused."""
    path, tensors, _ = old_file
    rehash_policy(path)
    before = json.loads(header_of(path)[METADATA_KEY])
    signed = remeasure_policy(path, {"success_rate": 0.9, "real_world_success_rate": math.nan})
    policy = load_policy(path)
    assert policy.checksum == signed[CHECKSUM_KEY] != before[CHECKSUM_KEY]
    assert policy.meta["metrics"] == {"success_rate": 0.9, "real_world_success_rate": None}
    new = load_file(str(path))
    assert all(new[name].tobytes() == arr.tobytes() for name, arr in tensors.items())
    after = json.loads(header_of(path)[METADATA_KEY])
    for key in set(before) - {CHECKSUM_KEY, "metrics"}:
        assert after[key] == before[key]
    damaged = {k: v.copy() for k, v in tensors.items()}
    damaged["actor.l1.weight"].flat[0] += 1.0
    save_file(damaged, str(path), metadata={METADATA_KEY: json.dumps(after)})
    raw = path.read_bytes()
    with pytest.raises(PolicyChecksumError, match="checksum mismatch"):
        remeasure_policy(path, {"success_rate": 1.0})
    assert path.read_bytes() == raw


def test_rehash_refuses_a_damaged_file_unless_forced(old_file):
    path, tensors, _ = old_file
    rehash_policy(path)
    signed = json.loads(header_of(path)[METADATA_KEY])
    damaged = {k: v.copy() for k, v in tensors.items()}
    damaged["actor.l1.weight"].flat[0] += 1.0
    save_file(damaged, str(path), metadata={METADATA_KEY: json.dumps(signed)})
    raw = path.read_bytes()
    with pytest.raises(PolicyChecksumError, match="checksum mismatch"):
        rehash_policy(path)
    assert path.read_bytes() == raw
    assert rehash_policy(path, force=True).written
    assert load_policy(path).checksum == policy_checksum(damaged, signed)


@pytest.mark.parametrize("value", [math.nan, 1e30])
def test_rehash_refuses_bad_weights_and_leaves_the_file(tmp_path, value):
    meta = tiny_meta()
    tensors = tiny_tensors(meta)
    tensors["critic.l2.weight"].flat[3] = value
    path = write_old(tmp_path / "nan.safetensors", tensors, meta)
    raw = path.read_bytes()
    with pytest.raises(PolicyWeightsError, match=r"critic\.l2\.weight"):
        rehash_policy(path)
    assert path.read_bytes() == raw
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nan.safetensors"]


def test_rehash_refuses_bad_metadata_and_garbage(tmp_path):
    meta = tiny_meta()
    meta["agents"] = "three"
    path = write_old(tmp_path / "m.safetensors", tiny_tensors(tiny_meta()), meta)
    with pytest.raises(PolicySchemaError, match="agents"):
        rehash_policy(path)
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"\x00" * 64)
    with pytest.raises(PolicyFormatError, match="not a policy file"):
        rehash_policy(junk)


def run_module(*args: str) -> subprocess.CompletedProcess[str]:
    """``python -m policies.export ...`` with torch made unimportable."""
    code = (
        "import sys, importlib.abc, runpy\n"
        "class Block(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name == 'torch' or name.startswith('torch.'):\n"
        "            raise ImportError('torch blocked')\n"
        "sys.meta_path.insert(0, Block())\n"
        f"sys.argv = ['policies.export', *{list(args)!r}]\n"
        "runpy.run_module('policies.export', run_name='__main__')\n"
    )
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )


def test_python_m_policies_export_rehash_works_without_torch(tmp_path, old_file):
    path, _, _ = old_file
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"junk")
    done = run_module("--rehash", str(path))
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"{path}: checksum added (sha256:")
    load_policy(path)
    again = run_module("--rehash", str(path), str(junk))
    assert again.returncode == 2
    assert "already has a valid checksum" in again.stdout
    lines = again.stderr.strip().splitlines()
    assert len(lines) == 1 and "not a policy file" in lines[0] and str(junk) in lines[0]


# ---------------------------------------------------------------------------------- writing


def test_write_policy_round_trip_keeps_the_checksum_valid(tmp_path):
    meta = tiny_meta()  # tuples (uav.center_m), as dataclasses.asdict gives them
    tensors = tiny_tensors(meta)
    out = tmp_path / "sub" / "p.safetensors"
    written = write_policy(out, tensors, meta)
    policy = load_policy(out)
    assert policy.meta == written and written[CHECKSUM_KEY] == policy.checksum
    assert policy_checksum(load_file(str(out)), policy.meta) == policy.checksum
    assert [p.name for p in out.parent.iterdir()] == ["p.safetensors"]


@pytest.mark.parametrize(
    ("change", "error"),
    [
        ("nan", PolicyWeightsError),
        ("huge", PolicyWeightsError),
        ("hidden", PolicySchemaError),
        ("nan-metric", PolicySchemaError),
        ("shape", PolicyTensorError),
    ],
)
def test_write_policy_never_writes_what_the_loader_refuses(tmp_path, change, error):
    meta = tiny_meta()
    tensors = tiny_tensors(meta)
    if change == "nan":
        tensors["actor.out.weight"].flat[0] = np.nan
    elif change == "huge":
        tensors["actor.out.weight"].flat[0] = 1e30
    elif change == "hidden":
        meta["hidden"] = None
    elif change == "nan-metric":
        meta["metrics"]["success_rate"] = math.nan
    else:
        tensors["actor.l1.weight"] = tensors["actor.l1.weight"][:, :, :3].copy()
    out = tmp_path / "p.safetensors"
    out.write_bytes(b"previous")
    with pytest.raises(error):
        write_policy(out, tensors, meta)
    assert out.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["p.safetensors"]


# ------------------------------------------------------------------------ export (with torch)


def make_run(tmp_path: Path, *, poison: bool = False) -> Path:
    """A training run folder (config.json, best.safetensors) with untrained small networks."""
    torch = pytest.importorskip("torch", reason="needs the train extra")
    from policies.config import DDPGConfig, TrainConfig
    from policies.ddpg import DDPGNets
    from policies.train import save_checkpoint

    run = tmp_path / "run"
    run.mkdir()
    cfg = TrainConfig(scenario="2u1o", seed=3, ddpg=DDPGConfig(hidden=8))
    (run / "config.json").write_text(
        json.dumps({"train": dataclasses.asdict(cfg), "scenario": "2u1o"})
    )
    torch.manual_seed(0)
    size = ObservationLayout.from_scenario(load_scenario("2u1o")).size
    nets = DDPGNets.create(2, size, cfg.ddpg)
    if poison:
        with torch.no_grad():
            next(nets.critic.parameters()).view(-1)[0] = float("nan")
    save_checkpoint(run / "best.safetensors", nets, {"step": 7})
    return run


def test_export_load_round_trip(tmp_path):
    run = make_run(tmp_path)
    from policies.config import DDPGConfig
    from policies.ddpg import DDPGNets
    from policies.export import export_policy
    from policies.train import load_checkpoint, policy_actions

    out = tmp_path / "p.safetensors"
    meta = export_policy(run, out, metrics={"success_rate": 0.25, "min_d_u2o_m": math.nan})
    assert meta["metrics"] == {"success_rate": 0.25, "min_d_u2o_m": None}
    policy = load_policy(out)
    assert policy.meta == meta and policy.checksum == meta[CHECKSUM_KEY]
    assert policy.meta["training"]["steps"] == 7 and policy.meta["hidden"] == 8
    nets = DDPGNets.create(2, policy.layout.size, DDPGConfig(hidden=8))
    load_checkpoint(run / "best.safetensors", nets)
    obs = np.random.default_rng(0).normal(size=(16, 2, policy.layout.size)).astype(np.float32)
    np.testing.assert_allclose(policy.act(obs), policy_actions(nets, obs, shared=False), atol=1e-6)


def test_export_refuses_a_diverged_run(tmp_path):
    run = make_run(tmp_path, poison=True)
    from policies.export import export_policy

    out = tmp_path / "p.safetensors"
    with pytest.raises(PolicyWeightsError, match="non-finite") as info:
        export_policy(run, out)
    assert info.value.key.startswith("critic.")
    assert not out.exists() and not out.with_name(out.name + ".part").exists()


# ------------------------------------------------------------------------------ generalists


def generalist_states(hidden: int = 8, seed: int = 0) -> tuple[dict[str, Any], dict[str, Any]]:
    """An actor's and a critic's state dicts (``<layer>.weight`` / ``.bias``), in numpy."""
    tensors = tiny_generalist_tensors(tiny_generalist_meta(hidden=hidden), seed)
    split = {
        net: {k.split(".", 1)[1]: v for k, v in tensors.items() if k.startswith(net + ".")}
        for net in ("actor", "critic")
    }
    return split["actor"], split["critic"]


def export_tiny_generalist(out: Path, actor, critic, **changes: Any) -> dict[str, Any]:
    from policies.export import export_generalist

    args: dict[str, Any] = {
        "base_cfg": generalist_scenario(),
        "hidden": 8,
        "uav_range": (1, 50),
        "reward": "remarl",
        "training": {"steps": 12, "seed": 4},
        "metrics": {"success_rate": 0.75, "min_d_u2o_m": math.nan},
        **changes,
    }
    return export_generalist(out, actor, critic, **args)


def test_export_generalist_writes_a_signed_file_that_acts_like_its_weights(tmp_path):
    actor, critic = generalist_states()
    out = tmp_path / "sub" / "g.safetensors"
    meta = export_tiny_generalist(out, actor, critic)
    assert meta["schema"] == 2 and meta["network"] == "set" and meta["uavs"] == [1, 50]
    assert meta["metrics"] == {"success_rate": 0.75, "min_d_u2o_m": None}
    assert meta["training"]["steps"] == 12 and meta["training"]["commit"]
    policy = load_policy(out)
    assert policy.meta == meta and policy.generalist and policy.uav_range == (1, 50)
    assert [p.name for p in out.parent.iterdir()] == ["g.safetensors"]
    obs = np.random.default_rng(0).normal(size=(4, 9, policy.layout.size)).astype(np.float32)
    params = {n: (actor[f"{n}.weight"], actor[f"{n}.bias"]) for n in SET_LAYERS}
    np.testing.assert_array_equal(policy.act(obs), set_actor(params, obs, policy.layout))
    assert policy.q_values(obs, policy.act(obs)).shape == (4, 9)


def test_export_generalist_takes_torch_tensors_and_no_critic(tmp_path):
    torch = pytest.importorskip("torch", reason="needs the train extra")
    actor, _ = generalist_states()
    from_numpy = export_tiny_generalist(tmp_path / "n.safetensors", actor, None)
    from_torch = export_tiny_generalist(
        tmp_path / "t.safetensors",
        {k: torch.from_numpy(v.copy()).requires_grad_() for k, v in actor.items()},
        None,
    )
    assert from_torch[CHECKSUM_KEY] == from_numpy[CHECKSUM_KEY]
    assert load_policy(tmp_path / "t.safetensors").critic == {}


@pytest.mark.parametrize(
    ("changes", "error", "key"),
    [
        ({"base_cfg": "v1"}, PolicySchemaError, "network"),
        ({"uav_range": (4, 50)}, PolicySchemaError, "uavs"),
        ({"hidden": 16}, PolicyTensorError, "actor.self.weight"),
    ],
)
def test_export_generalist_never_writes_what_the_loader_refuses(tmp_path, changes, error, key):
    if changes.get("base_cfg") == "v1":
        changes = {"base_cfg": load_scenario("3u2o")}  # observation version 1
    actor, critic = generalist_states()
    out = tmp_path / "g.safetensors"
    out.write_bytes(b"previous")
    with pytest.raises(error) as info:
        export_tiny_generalist(out, actor, critic, **changes)
    assert info.value.key == key
    assert out.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["g.safetensors"]
