"""Synthetic policies for the exporter's and the loader's tests: the metadata `policies.export`
builds (tuples and all, before JSON) and random weights of the shapes it implies, in numpy.

Zoo-like MLPs (`tiny_meta`, `tiny_tensors`) and generalists (`tiny_generalist_meta`,
`tiny_generalist_tensors`, `write_tiny_generalist`: a set network over the version-2
observation, k = 6 neighbour and m = 8 intruder rows, for 1 to 50 UAVs)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np

from policies.config import GeneralistConfig
from sim.config import ScenarioConfig
from sim.policy_file import METADATA_KEY, build_metadata, expected_shapes, sign_policy
from sim.scenarios import load_scenario

TRAINING = {"commit": "abc1234", "steps": 100, "seed": 0}
METRICS = {"success_rate": 0.5, "train_env_steps": None}


def tiny_meta(scenario: str = "2u1o", *, hidden: int = 4, shared: bool = False) -> dict[str, Any]:
    """Unsigned metadata of a ``hidden``-unit policy for ``scenario``."""
    return build_metadata(
        load_scenario(scenario),
        shared=shared,
        hidden=hidden,
        reward="remarl",
        training=TRAINING,
        metrics=METRICS,
    )


def tiny_tensors(meta: dict[str, Any], seed: int = 0) -> dict[str, np.ndarray]:
    """Actor and critic weights drawn from N(0, 0.5²), as the metadata's shapes say."""
    rng = np.random.default_rng(seed)
    return {
        name: rng.normal(0, 0.5, shape).astype(np.float32)
        for name, shape in expected_shapes(meta).items()
    }


def generalist_scenario(
    scenario: str = "3u2o", *, k: int = 6, m: int = 8, **overrides: Any
) -> ScenarioConfig:
    """``scenario`` with the version-2 observation of k neighbour and m intruder rows."""
    sensing = {"observation": 2, "max_neighbours": k, "max_obstacles": m}
    return load_scenario(scenario, sensing=sensing, **overrides)


def tiny_generalist_meta(
    scenario: str = "3u2o",
    *,
    hidden: int = 8,
    k: int = 6,
    m: int = 8,
    uavs: tuple[int, int] = (1, 50),
    pooling: str = "max-mean",
) -> dict[str, Any]:
    """Unsigned metadata of a ``hidden``-unit generalist (schema 2, network "set")."""
    return build_metadata(
        generalist_scenario(scenario, k=k, m=m),
        shared=True,
        hidden=hidden,
        reward="remarl",
        training=TRAINING,
        metrics=METRICS,
        network="set",
        uavs=uavs,
        pooling=pooling,
    )


def tiny_generalist_tensors(
    meta: dict[str, Any], seed: int = 0, *, critic: bool = True
) -> dict[str, np.ndarray]:
    """A generalist's random weights (`tiny_tensors`), without ``critic.*`` if ``critic`` False."""
    tensors = tiny_tensors(meta, seed)
    return {n: t for n, t in tensors.items() if critic or n.startswith("actor.")}


def write_tiny_generalist(
    path: Path, *, seed: int = 0, critic: bool = True, **meta_args: Any
) -> Path:
    """A signed tiny generalist file at ``path`` (`tiny_generalist_meta`'s arguments)."""
    from safetensors.numpy import save_file

    meta = tiny_generalist_meta(**meta_args)
    tensors = tiny_generalist_tensors(meta, seed, critic=critic)
    signed = sign_policy(tensors, meta)
    save_file(tensors, str(path), metadata={METADATA_KEY: json.dumps(signed)})
    return path


def changed_tensors(tensors: dict[str, np.ndarray], change: str) -> dict[str, np.ndarray]:
    """A copy of ``tensors`` with one change, ``"VERB NAME"``: drop it, add it (zeros), make it
    float64, reshape it (3 outputs), give it 3 members (leading dimension) or a NaN."""
    out = {k: v.copy() for k, v in tensors.items()}
    verb, name = change.split()
    if verb == "drop":
        del out[name]
    elif verb == "add":
        out[name] = np.zeros((1, 4, 4), np.float32)
    elif verb == "float64":
        out[name] = out[name].astype(np.float64)
    elif verb == "reshape":
        out[name] = np.zeros((*out[name].shape[:-1], 3), np.float32)
    elif verb == "members":
        out[name] = np.repeat(out[name], 3, axis=0)
    elif verb == "nan":
        out[name].flat[-1] = np.nan
    else:
        raise ValueError(f"unknown change {change!r}")
    return out


DELETE = object()
"""`mutate`'s value that deletes the key."""


def mutate(meta: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    """A deep copy with ``path`` (dotted) set to ``value``, or deleted for `DELETE`."""
    out = copy.deepcopy(meta)
    *parents, last = path.split(".")
    node = out
    for p in parents:
        node = node[p]
    if value is DELETE:
        del node[last]
    else:
        node[last] = value
    return out


TINY_SUITE = """
name = "tiny"
episodes = 2

[[family]]
name = "crossing-2u"
distribution = "crossing"
uavs = 2
formation = "line"

[[family]]
name = "paper-2u1o"
distribution = "scenario"
scenario = "2u1o"
"""
"""Two families of two UAVs: the mixture of the generalist trainers' tiny runs."""


def tiny_suite(folder: Path) -> Path:
    """`TINY_SUITE` written to ``folder``/tiny.toml."""
    path = folder / "tiny.toml"
    path.write_text(TINY_SUITE)
    return path


def tiny_run_cfg(tmp_path: Path, **changes: Any) -> GeneralistConfig:
    """A 2-iteration PPO run of the tiny suite (from scratch unless ``changes`` say otherwise)."""
    settings = {
        "suites": (str(tiny_suite(tmp_path)),),
        "learner": "ppo",
        "agents_per_family": 4,
        "hidden": 8,
        "ppo_rollout": 3,
        "ppo_epochs": 1,
        "ppo_minibatch": 8,
        "dagger_updates": 2,
        "dagger_batch": 16,
        "minutes": 0.0,
        "total_iterations": 2,
        "eval_minutes": 1e6,
        "eval_episodes": 2,
        "real_share": 0.5,
        "device": "cpu",
        "teacher": "none",
        **changes,
    }
    return GeneralistConfig(**settings)
