"""Synthetic policies for the exporter's and the loader's tests: the metadata `policies.export`
builds (tuples and all, before JSON) and random weights of the shapes it implies, in numpy."""

from __future__ import annotations

from typing import Any

import numpy as np

from sim.policy_file import build_metadata, expected_shapes
from sim.scenarios import load_scenario


def tiny_meta(scenario: str = "2u1o", *, hidden: int = 4, shared: bool = False) -> dict[str, Any]:
    """Unsigned metadata of a ``hidden``-unit policy for ``scenario``."""
    return build_metadata(
        load_scenario(scenario),
        shared=shared,
        hidden=hidden,
        reward="remarl",
        training={"commit": "abc1234", "steps": 100, "seed": 0},
        metrics={"success_rate": 0.5, "train_env_steps": None},
    )


def tiny_tensors(meta: dict[str, Any], seed: int = 0) -> dict[str, np.ndarray]:
    """Actor and critic weights drawn from N(0, 0.5²), as the metadata's shapes say."""
    rng = np.random.default_rng(seed)
    return {
        name: rng.normal(0, 0.5, shape).astype(np.float32)
        for name, shape in expected_shapes(meta).items()
    }
