"""Export a trained swarm to one self-describing, checksummed policy file (safetensors, no pickle).

Tensors: the actors (``actor.*``) — all inference needs — and the critics (``critic.*``) for
Q-value plots, each with a leading agent dimension (1 when parameters are shared). Metadata
(``remarl_policy``, JSON): schema version, scenario and its units, observation layout and scales,
action bound, dt, speed, agent count, sharing, network size, training commit, metrics, and the
checksum over all of it (`sim.policy_file`, the format shared with the loader
`remarl_fc.policy_io`). A file is checked against that format before it is written, and written
atomically, so the exporter never leaves a file the loader would refuse.

`export_generalist` writes a generalist (a set network, `sim.setnet`, over the version-2
observation, for any number of UAVs in a range: schema 2) from its actor's and critic's state
dicts.

`remeasure_policy` replaces the figures a shipped file carries, where it was flown again.

Files written before checksums existed get one with `rehash_policy`, or from the shell::

    python -m policies.export --rehash FILE [FILE ...]

This module imports torch only inside `export_policy`, so rehashing (and `export_generalist`
from numpy arrays) works without it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from policies.config import DDPGConfig
from sim.config import ScenarioConfig
from sim.errors import RemarlError
from sim.observation import ObservationLayout
from sim.policy_file import (
    CHECKSUM_KEY,
    METADATA_KEY,
    POLICY_SCHEMA,
    PolicyFileError,
    build_metadata,
    read_policy_file,
    sign_policy,
    verify_policy,
)
from sim.scenarios import load_scenario

__all__ = [
    "POLICY_SCHEMA",
    "Rehash",
    "export_generalist",
    "export_policy",
    "read_policy_file",
    "rehash_policy",
    "write_policy",
]


def _commit() -> str:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
            cwd=Path(__file__).resolve().parent,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() or "unknown"


def export_policy(
    run_dir: Path, out: Path, *, checkpoint: str = "best", metrics: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Write ``out`` from a training run folder; returns the metadata written.

    Args:
        run_dir: the ``--out`` folder of ``remarl-fc train``.
        checkpoint: "best" or "last".
        metrics: evaluation figures to embed (e.g. the eval JSON of the shipped policy).
    """
    from policies.ddpg import DDPGNets
    from policies.train import load_checkpoint

    config = json.loads((run_dir / "config.json").read_text())
    train_cfg = config["train"]
    cfg = load_scenario(train_cfg["scenario"])
    ddpg = DDPGConfig(**train_cfg["ddpg"])
    layout = ObservationLayout.from_scenario(cfg)
    agents = 1 if ddpg.shared else cfg.uav.count
    nets = DDPGNets.create(agents, layout.size, ddpg)
    meta_ckpt = load_checkpoint(run_dir / f"{checkpoint}.safetensors", nets)
    tensors = {
        **_prefixed("actor", nets.actor.state_dict()),
        **_prefixed("critic", nets.critic.state_dict()),
    }
    meta = build_metadata(
        cfg,
        shared=ddpg.shared,
        hidden=ddpg.hidden,
        reward=train_cfg["reward"],
        training={"commit": _commit(), "steps": meta_ckpt["step"], "seed": train_cfg["seed"]},
        metrics=_finite_or_null(metrics or {}),
    )
    return write_policy(out, tensors, meta)


def export_generalist(
    out: Path,
    actor_state: Mapping[str, Any],
    critic_state: Mapping[str, Any] | None,
    *,
    base_cfg: ScenarioConfig,
    hidden: int,
    uav_range: tuple[int, int],
    reward: str,
    training: Mapping[str, Any],
    metrics: Mapping[str, Any] | None = None,
    pooling: str = "max-mean",
) -> dict[str, Any]:
    """Write a signed generalist file ``out`` (atomically); returns the metadata written.

    Args:
        actor_state, critic_state: ``state_dict()`` of `policies.generalist.SetNet` (torch
            tensors) or numpy arrays: ``<layer>.weight`` (1, in, out), ``<layer>.bias``
            (1, 1, out) for each of `sim.setnet.set_layers` of ``pooling``; no critic: None.
        base_cfg: the scenario it was trained (or is published) with; its ``sensing`` is the
            version-2 observation the policy reads (``observation = 2``, ``max_neighbours``),
            its ``uav.count`` inside ``uav_range``.
        hidden: units of every hidden layer. uav_range: (fewest, most) UAVs it flies.
        reward: the reward it was trained on. training: ``steps`` and ``seed`` (and
            ``commit``: this checkout's where absent). metrics: evaluation figures.
        pooling: the set networks' pooling (`sim.setnet.POOLINGS`).

    Raises:
        PolicyFileError: the metadata or tensors are not a valid generalist (nothing written),
            e.g. a base scenario of observation version 1, or weights of other shapes.
    """
    tensors = _prefixed("actor", actor_state)
    if critic_state is not None:
        tensors |= _prefixed("critic", critic_state)
    meta = build_metadata(
        base_cfg,
        shared=True,
        hidden=hidden,
        reward=reward,
        training={"commit": _commit(), **training},
        metrics=_finite_or_null(metrics or {}),
        network="set",
        uavs=uav_range,
        pooling=pooling,
    )
    return write_policy(out, tensors, meta)


def _prefixed(prefix: str, state: Mapping[str, Any]) -> dict[str, NDArray[np.float32]]:
    """``prefix.<key>`` → float32 C-ordered numpy array, from torch tensors or arrays."""
    out = {}
    for key, value in state.items():
        if hasattr(value, "detach"):  # a torch tensor (torch itself not imported here)
            value = value.detach().cpu().float().numpy()
        out[f"{prefix}.{key}"] = np.ascontiguousarray(value, dtype=np.float32)
    return out


def _finite_or_null(value: Any) -> Any:
    """``value`` with NaN and infinities replaced by None (JSON null).

    Metrics are informative, and a policy file's metadata holds finite numbers only.
    """
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_null(v) for v in value]
    return value


def write_policy(
    out: Path,
    tensors: Mapping[str, NDArray[Any]],
    meta: Mapping[str, Any],
    *,
    header: Mapping[str, str] | None = None,
) -> dict[str, Any]:
    """Sign ``meta`` and write the policy file ``out`` atomically; returns the metadata written.

    The file is checked before it is written (`sim.policy_file.sign_policy`) and read back and
    verified before it replaces ``out``, so ``out`` is either the old file or a valid new one.

    Args:
        header: other safetensors header entries to keep (strings).

    Raises:
        PolicyFileError: the metadata or the tensors are not a valid policy (nothing written).
    """
    from safetensors.numpy import save

    signed = sign_policy(tensors, meta)
    data = save(dict(tensors), metadata={**(header or {}), METADATA_KEY: json.dumps(signed)})
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".part")
    try:
        with tmp.open("wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        back, _, back_meta = read_policy_file(tmp)
        verify_policy(back, back_meta)
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)
    return signed


@dataclasses.dataclass(frozen=True)
class Rehash:
    """What `rehash_policy` did.

    Attributes:
        checksum: the file's checksum now. written: False when it already had a valid one.
    """

    checksum: str
    written: bool


def rehash_policy(path: Path | str, *, force: bool = False) -> Rehash:
    """Add a checksum to a policy file written before checksums existed, in place.

    The tensors are written back bit for bit and the other metadata unchanged; the file must
    pass every other check of the loader (schema, tensors, finite in-range weights). A file that
    already has a valid checksum is left alone.

    Args:
        force: also re-sign a file whose checksum does not match its contents. Only for a file
            you changed on purpose: a mismatch otherwise means the file is damaged.

    Raises:
        PolicyFileError: not a policy file, invalid metadata or weights, or (without ``force``)
            a checksum that does not match.
    """
    path = Path(path)
    tensors, header, meta = read_policy_file(path)
    if CHECKSUM_KEY in meta:
        try:
            verify_policy(tensors, meta)
            return Rehash(str(meta[CHECKSUM_KEY]), written=False)
        except PolicyFileError as exc:
            if exc.kind != "checksum" or not force:
                raise
    signed = write_policy(path, tensors, meta, header=header)
    return Rehash(str(signed[CHECKSUM_KEY]), written=True)


def remeasure_policy(path: Path | str, metrics: Mapping[str, Any]) -> dict[str, Any]:
    """Replace the evaluation figures a policy file carries (``metrics``), in place.

    For a policy flown again where the simulator changed what it shows a policy, not the
    policy: the tensors are written back bit for bit and the rest of the metadata unchanged,
    signed anew; the file must pass every check of the loader first.

    Raises:
        PolicyFileError: not a policy file, or its metadata or weights are invalid.
    """
    path = Path(path)
    tensors, header, meta = read_policy_file(path)
    verify_policy(tensors, meta)
    return write_policy(
        path, tensors, {**meta, "metrics": _finite_or_null(dict(metrics))}, header=header
    )


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m policies.export --rehash FILE ...``; returns the exit status (2 on errors)."""
    parser = argparse.ArgumentParser(
        prog="python -m policies.export",
        description="Add a checksum to policy files written before policy files carried one "
        "(export new ones with remarl-fc export).",
    )
    parser.add_argument(
        "--rehash",
        nargs="+",
        metavar="FILE",
        required=True,
        help="policy files to checksum in place (tensors and metadata unchanged)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="also re-sign a file whose checksum does not match (only if you changed it on "
        "purpose: otherwise the file is damaged)",
    )
    args = parser.parse_args(argv)
    status = 0
    for name in args.rehash:
        try:
            result = rehash_policy(Path(name), force=args.force)
        except PolicyFileError as exc:
            print(f"{parser.prog}: error: {name}: {exc.describe(name)}", file=sys.stderr)
            status = 2
        except RemarlError as exc:
            print(f"{parser.prog}: error: {name}: {exc}", file=sys.stderr)
            status = 2
        else:
            done = "checksum added" if result.written else "already has a valid checksum"
            print(f"{name}: {done} ({result.checksum})")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
