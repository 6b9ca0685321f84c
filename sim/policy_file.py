"""The policy file format: metadata schema, checksum and weight checks (numpy; safetensors to read).

This module lives in `sim` because both ends of the format need it and neither may import the
other's package: the writer, `policies.export` (torch side), may not import `remarl_fc`, and the
loader, `remarl_fc.policy_io` (the flight path), may not import `policies` or torch. Both import
`sim`, so the one definition of what a valid policy file is lives here.

A policy file is safetensors: float32 tensors ``actor.*`` (and optionally ``critic.*``) with a
leading agent dimension (1 when parameters are shared), and one JSON string under the header key
``remarl_policy`` (`METADATA_KEY`): the metadata of `metadata_problems`. The metadata's
``network`` says which layers there are: "mlp" (`ACTOR_LAYERS`, `CRITIC_LAYERS`; what a
schema-1 file implies) or "set" (`sim.setnet.SET_LAYERS` for both, shapes from
`sim.setnet.set_shapes`, leading dimension 1: one network for any number of UAVs; with the
query layers where its ``pooling`` is "max-attention"). Its ``checksum``
(`CHECKSUM_KEY`) is ``"sha256:"`` and the hex digest of `policy_checksum`: SHA-256 over every
tensor (name, dtype, shape, raw bytes, in sorted name order) and over the canonical JSON of the
metadata without the checksum, so any change to a weight or a metadata value shows.

Checks, in the order a loader applies them (`verify_policy`):

1. `check_metadata`: required keys, their types and ranges, the scenario they describe
   (``scenario_config`` must build a `ScenarioConfig`) and its agreement with the other keys;
2. `check_checksum`: the file is signed (`PolicyUnsignedError`) and the signature matches
   (`PolicyChecksumError`);
3. `check_tensors`: the tensor names, dtypes and shapes the metadata implies, every weight
   finite and within ±`WEIGHT_BOUND`.

Every failure is a `PolicyFileError` (a `ValueError`) whose `Problem` items each name the key or
tensor and say what is expected; `remarl_fc.policy_io` turns them into `PolicyError` subclasses.

This module is the format's face: it holds the tensor checks, reads, verifies and signs whole
files, and every public name of the format is importable from it. The rest lives by concern, each
with the errors it raises: `sim.policy_metadata` (the metadata schema), `sim.policy_checksum`
(what the checksum hashes), `sim.policy_problems` (`Problem`, the `Checker`, `PolicyFileError`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.policy_checksum import (
    CHECKSUM_KEY,
    PolicyChecksumError,
    PolicyUnsignedError,
    check_checksum,
    policy_checksum,
)
from sim.policy_metadata import (
    METADATA_KEY,
    NETWORKS,
    POLICY_SCHEMA,
    POLICY_SCHEMAS,
    REQUIRED_KEYS,
    SCHEMA_2_KEYS,
    PolicyFormatError,
    PolicySchemaError,
    build_metadata,
    check_metadata,
    metadata_problems,
    network_of,
    observation_layout,
    parse_metadata,
    pooling_of,
    scenario_config,
    scenario_hash,
    uav_range,
)
from sim.policy_problems import PolicyFileError, Problem
from sim.setnet import SET_LAYERS, set_layers, set_shapes

WEIGHT_BOUND = 1e4
"""Largest |weight| a policy file may hold.

Trained weights here are O(1) (the zoo's largest is about 7, in a critic); a float32 with one
flipped exponent bit is 1e30 or more (or inf, or NaN), and a diverged training run gives values
far above 1e4 long before it gives infinities. So the bound is four orders of magnitude above
anything a healthy run writes and still catches what a bit flip or a divergence does."""

ACTOR_LAYERS = ("l1", "out")
"""Layers of the actor: ``actor.<layer>.weight`` and ``.bias`` (all required)."""

CRITIC_LAYERS = ("obs_l", "act_l", "l2", "out")
"""Layers of the critic: ``critic.<layer>.weight`` and ``.bias`` (all of them, or none)."""


# ----------------------------------------------------------------------------------- tensors


class PolicyTensorError(PolicyFileError):
    """A tensor is missing, unexpected, of the wrong dtype or shape, or holds bad weights."""

    kind = "tensors"
    summary = "bad tensors"


class PolicyWeightsError(PolicyTensorError):
    """A weight is NaN or infinite, or beyond ±`WEIGHT_BOUND`."""

    kind = "weights"
    summary = "bad weights"
    advice = (
        "the training run diverged or the file was damaged before it was signed: export another "
        "checkpoint (remarl-fc export --checkpoint) or retrain"
    )


def network_layers(meta: Mapping[str, Any]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(actor layers, critic layers) of valid metadata's ``network``."""
    if network_of(meta) == "set":
        layers = set_layers(pooling_of(meta))
        return layers, layers
    return ACTOR_LAYERS, CRITIC_LAYERS


def expected_shapes(meta: Mapping[str, Any]) -> dict[str, tuple[int, ...]]:
    """Tensor name → shape that valid metadata implies (actor and critic)."""
    h = int(meta["hidden"])
    if network_of(meta) == "set":
        a = 1
        pooling = pooling_of(meta)
        layers = {f"actor.{k}": v for k, v in set_shapes(h, False, pooling).items()}
        layers |= {f"critic.{k}": v for k, v in set_shapes(h, True, pooling).items()}
    else:
        a = 1 if meta["shared"] else int(meta["agents"])
        d = int(meta["observation"]["size"])
        layers = {
            "actor.l1": (d, h),
            "actor.out": (h, 1),
            "critic.obs_l": (d, h),
            "critic.act_l": (1, h),
            "critic.l2": (2 * h, h),
            "critic.out": (h, 1),
        }
    shapes: dict[str, tuple[int, ...]] = {}
    for layer, (n_in, n_out) in layers.items():
        shapes[f"{layer}.weight"] = (a, n_in, n_out)
        shapes[f"{layer}.bias"] = (a, 1, n_out)
    return shapes


def tensor_problems(tensors: Mapping[str, NDArray[Any]], meta: Mapping[str, Any]) -> list[Problem]:
    """Missing, unexpected, non-float32 or misshapen tensors (``meta`` must be valid)."""
    shapes = expected_shapes(meta)
    layers = ", ".join(dict.fromkeys(n.split(".")[1] for n in shapes))
    problems = [
        Problem(
            name,
            f"unexpected tensor (a {network_of(meta)} policy holds actor.* and critic.* of the "
            f"layers {layers})",
        )
        for name in sorted(set(tensors) - set(shapes))
    ]
    critic = [n for n in shapes if n.startswith("critic.")]
    has_critic = any(n in tensors for n in critic)
    for name, shape in shapes.items():
        if name not in tensors:
            if name.startswith("actor.") or has_critic:
                problems.append(Problem(name, "missing tensor"))
            continue
        arr = tensors[name]
        if arr.dtype != np.float32:
            problems.append(Problem(name, f"must be float32, got {arr.dtype}"))
        elif tuple(arr.shape) != shape:
            problems.append(Problem(name, f"has shape {tuple(arr.shape)}, metadata says {shape}"))
    return problems


def weight_problems(tensors: Mapping[str, NDArray[Any]]) -> list[Problem]:
    """Tensors holding NaN, ±inf or a value beyond ±`WEIGHT_BOUND` (floating tensors only)."""
    problems = []
    for name in sorted(tensors):
        arr = tensors[name]
        if arr.size == 0 or not np.issubdtype(arr.dtype, np.floating):
            continue
        lo, hi = arr.min(), arr.max()  # NaN propagates, and fails both comparisons
        if lo >= -WEIGHT_BOUND and hi <= WEIGHT_BOUND:
            continue
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        if bad:
            problems.append(Problem(name, f"{bad} non-finite value(s) (NaN or inf)"))
        else:
            peak = float(np.abs(arr).max())
            problems.append(
                Problem(
                    name,
                    f"|w| reaches {peak:.3g}, beyond the bound {WEIGHT_BOUND:g} (trained weights "
                    "are O(1); a flipped exponent bit gives 1e30 or more)",
                )
            )
    return problems


def check_tensors(tensors: Mapping[str, NDArray[Any]], meta: Mapping[str, Any]) -> None:
    """Raise `PolicyTensorError` (layout) or `PolicyWeightsError` (values); ``meta`` valid."""
    problems = tensor_problems(tensors, meta)
    if problems:
        raise PolicyTensorError(problems)
    problems = weight_problems(tensors)
    if problems:
        raise PolicyWeightsError(problems)


# ------------------------------------------------------------------------------ whole files


def read_policy_file(
    path: Path | str,
) -> tuple[dict[str, NDArray[Any]], dict[str, str], dict[str, Any]]:
    """(tensors, safetensors header metadata, parsed policy metadata) of a file, unverified.

    The safetensors format holds only tensors and a JSON header: reading one never runs code.

    Raises:
        PolicyFormatError: not a safetensors file, or no remarl-fc metadata in it.
    """
    from safetensors import safe_open

    try:
        with safe_open(str(path), framework="numpy") as f:
            header = dict(f.metadata() or {})
            tensors = {k: f.get_tensor(k) for k in f.keys()}  # noqa: SIM118 - not a dict
    except Exception as exc:  # whatever a damaged file makes the parser raise
        text = " ".join(str(exc).split())[:160] or type(exc).__name__
        raise PolicyFormatError(
            [Problem("file", f"not a readable safetensors file: {text}")]
        ) from exc
    return tensors, header, parse_metadata(header)


def verify_policy(tensors: Mapping[str, NDArray[Any]], meta: object) -> dict[str, Any]:
    """Check a policy's metadata, checksum and tensors, in that order; returns the metadata.

    Raises:
        PolicySchemaError, PolicyUnsignedError, PolicyChecksumError, PolicyTensorError,
        PolicyWeightsError: the first check that fails.
    """
    valid = check_metadata(meta)
    check_checksum(tensors, valid)
    check_tensors(tensors, valid)
    return valid


def sign_policy(tensors: Mapping[str, NDArray[Any]], meta: Mapping[str, Any]) -> dict[str, Any]:
    """``meta`` as the loader will read it, with its checksum (last key), once checked.

    The metadata goes through JSON first (tuples become lists), so what is checked and signed
    is exactly what the file will hold.

    Raises:
        PolicySchemaError, PolicyTensorError, PolicyWeightsError: a file the loader would refuse.
    """
    try:
        unsigned = json.loads(json.dumps({k: v for k, v in meta.items() if k != CHECKSUM_KEY}))
    except (TypeError, ValueError) as exc:
        raise PolicySchemaError([Problem(METADATA_KEY, f"not JSON ({exc})")]) from exc
    check_metadata(unsigned)
    check_tensors(tensors, unsigned)
    return {**unsigned, CHECKSUM_KEY: policy_checksum(tensors, unsigned)}


__all__ = [
    "ACTOR_LAYERS",
    "CHECKSUM_KEY",
    "CRITIC_LAYERS",
    "METADATA_KEY",
    "NETWORKS",
    "POLICY_SCHEMA",
    "POLICY_SCHEMAS",
    "REQUIRED_KEYS",
    "SCHEMA_2_KEYS",
    "SET_LAYERS",
    "WEIGHT_BOUND",
    "PolicyChecksumError",
    "PolicyFileError",
    "PolicyFormatError",
    "PolicySchemaError",
    "PolicyTensorError",
    "PolicyUnsignedError",
    "PolicyWeightsError",
    "Problem",
    "build_metadata",
    "check_checksum",
    "check_metadata",
    "check_tensors",
    "expected_shapes",
    "metadata_problems",
    "network_layers",
    "network_of",
    "observation_layout",
    "parse_metadata",
    "policy_checksum",
    "pooling_of",
    "read_policy_file",
    "scenario_config",
    "scenario_hash",
    "sign_policy",
    "tensor_problems",
    "uav_range",
    "verify_policy",
    "weight_problems",
]
