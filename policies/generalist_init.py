"""Start a generalist run from a policy file (`GeneralistConfig.init`).

A shipped generalist (`policies/zoo/generalist.safetensors`) or any exported one holds the
actor and, for PPO, the value network as its critic (`policies.export.export_generalist`): the
``state_dict`` of each `policies.generalist.SetNet` under ``actor.`` and ``critic.``. This
module reads such a file back into a run's networks. The file is verified as the flight path
verifies it (`sim.policy_file.verify_policy`: schema, checksum, shapes, finite weights), and it
must see what the run's worlds show: the same version-2 observation (range, aperture, rows),
hidden width and pooling, else the weights would read other columns than they learned.

What it is for: the "self-shield" teacher (`policies.generalist_train.RunBook.teach`), which
distils the policy a run starts from, flown behind the safety shield, back into it.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import torch

from policies.config import GeneralistConfig
from policies.generalist import SetNet
from sim.errors import ConfigError
from sim.observation import ObservationLayout
from sim.policy_file import PolicyFileError, read_policy_file, verify_policy
from sim.policy_metadata import network_of, observation_layout, pooling_of


def init_path(name: str) -> Path:
    """The file of ``init``: a zoo name or a path to an exported file.

    A zoo name is one at the zoo's top ("generalist") or in one of its subfolders
    ("robust/generalist"), as ``eval --policy`` takes it.

    Raises:
        ConfigError: no such file.
    """
    shipped = Path(__file__).parent / "zoo" / f"{name}.safetensors"
    if ZOO_NAME.fullmatch(name) and shipped.is_file():
        return shipped
    path = Path(name) if "/" in name or name.endswith(".safetensors") else shipped
    if not path.is_file():
        raise ConfigError(
            f"train --generalist --init {name}: no such policy file ({path}); name a zoo "
            "policy (generalist, robust/generalist) or an exported .safetensors file"
        )
    return path


ZOO_NAME = re.compile(r"[A-Za-z0-9_-]+(/[A-Za-z0-9_-]+)?")
"""A zoo name, at the zoo's top or in one of its subfolders: one folder at most, no path
tricks (``remarl_fc.policy_io.resolve`` reads the same names)."""

INIT_FILE = "init.safetensors"
"""The copy of ``init`` a run folder keeps: a resumed run starts from what it started from,
even if the zoo's file of that name was replaced since (by the run's own result, say)."""


def keep_init(cfg: GeneralistConfig, out_dir: Path, *, resume: bool) -> Path:
    """The run's copy of ``cfg.init`` in ``out_dir`` (made now unless resuming with one).

    Raises:
        ConfigError: no such file.
    """
    kept = out_dir / INIT_FILE
    if resume and kept.is_file():
        return kept
    partial = kept.with_suffix(".partial")
    shutil.copyfile(init_path(cfg.init), partial)
    partial.replace(kept)  # whole or not at all
    return kept


def init_states(
    cfg: GeneralistConfig, layout: ObservationLayout, path: Path
) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """(actor, critic) ``state_dict``s of the policy file ``path`` (the run's ``init``).

    The critic is empty if the file has none.

    Raises:
        ConfigError: the file fails verification, is not a generalist, or sees, thinks or pools
            otherwise than the run (each named, with what to pass).
    """
    where = f"train --generalist --init {cfg.init}"
    tensors, meta = _generalist_file(path, where)
    theirs = observation_layout(meta)
    clash = [
        f"{name} {getattr(theirs, name)!r} (the run's: {getattr(layout, name)!r})"
        for name in ("max_neighbours", "max_obstacles", "range_m", "aperture_rad", "speed_m_s")
        if getattr(theirs, name) != getattr(layout, name)
    ]
    if int(meta["hidden"]) != cfg.hidden:
        clash.append(f"hidden {meta['hidden']} (the run's: {cfg.hidden})")
    if pooling_of(meta) != cfg.pooling:
        clash.append(f"pooling {pooling_of(meta)!r} (the run's: {cfg.pooling!r})")
    if clash or theirs != layout:
        detail = "; ".join(clash) or f"observation {theirs} (the run's: {layout})"
        raise ConfigError(
            f"{where}: the policy does not see what the run shows: {detail}. Pass the run "
            "the policy's settings (--sensing-range, --sensing-aperture, --max-neighbours, "
            "--pooling)"
        )

    return _prefixed(tensors, "actor"), _prefixed(tensors, "critic")


def load_actor(name: str) -> SetNet:
    """The actor of policy file ``name`` (`init_path`: a path or a zoo name) as a torch `SetNet`.

    Verified as `init_states` verifies it; its own observation, width and pooling.

    Raises:
        ConfigError: no such file, or not a valid generalist policy file.
    """
    path = init_path(name)
    tensors, meta = _generalist_file(path, name)
    actor = SetNet(observation_layout(meta), int(meta["hidden"]), False, pooling_of(meta))
    actor.load_state_dict(_prefixed(tensors, "actor"))
    return actor


def _generalist_file(path: Path, where: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """(tensors, metadata) of the verified generalist policy file ``path``.

    Raises:
        ConfigError: it fails verification, or is a per-slot zoo policy (``where`` leads).
    """
    try:
        tensors, _, meta = read_policy_file(path)
        meta = verify_policy(tensors, meta)
    except PolicyFileError as exc:
        raise ConfigError(f"{where}: {path} is not a valid policy file: {exc}") from exc
    if network_of(meta) != "set":
        raise ConfigError(f"{where}: {path} is a per-slot zoo policy, not a generalist")
    return tensors, meta


def _prefixed(tensors: dict[str, Any], prefix: str) -> dict[str, torch.Tensor]:
    """The float32 tensors named ``prefix``.…, without the prefix: a network's ``state_dict``."""
    return {
        key[len(prefix) + 1 :]: torch.from_numpy(np.array(value, dtype=np.float32))
        for key, value in tensors.items()
        if key.startswith(f"{prefix}.")
    }
