"""Load exported policy files and run them in numpy (no torch, no pickle).

A policy is resolved by zoo name (``3u2o`` → ``policies/zoo/3u2o.safetensors``) or by path.
The safetensors format holds only tensors and a JSON header: loading one never executes code.
Everything is checked before use (the format is `sim.policy_file`'s, shared with the writer), in
this order: the file is safetensors with remarl-fc metadata; the metadata fits the schema (each
bad key named); the checksum is there and matches; the tensor names, dtypes and shapes fit the
metadata and every weight is finite and within ±`sim.policy_file.WEIGHT_BOUND`. With
`Policy.check_scenario`, the scenario it is asked to fly. A file that fails any of these is a
`PolicyFileInvalid` (a `PolicyError`) whose one-line message says what to do.

Two kinds of policy run here, with one API (`Policy.act`, `Policy.q_values`): the per-agent MLPs
of the zoo (version-1 observation, exactly ``agents`` UAVs) and generalists (`Policy.generalist`:
one set network, `sim.setnet`, for any number of UAVs in `Policy.uav_range`). A generalist
brings its own observation layout (`Policy.layout`, version 2): the caller builds observations
with it (``SwarmSim.observe(state, layout=policy.layout)``), whatever the scenario's sensing.
"""

from __future__ import annotations

import functools
import importlib.util
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.errors import (
    PolicyChecksumFailed,
    PolicyError,
    PolicyFileInvalid,
    PolicySpecMismatch,
    PolicyUavRangeMismatch,
)
from sim.config import ScenarioConfig
from sim.observation import ObservationLayout
from sim.policy_file import (
    ACTOR_LAYERS,
    CHECKSUM_KEY,
    CRITIC_LAYERS,
    POLICY_SCHEMA,
    PolicyChecksumError,
    PolicyFileError,
    PolicyUnsignedError,
    network_layers,
    network_of,
    observation_layout,
    read_policy_file,
    uav_range,
    verify_policy,
)
from sim.setnet import set_actor, set_critic

__all__ = [
    "ACTOR_LAYERS",
    "CRITIC_LAYERS",
    "GENERALIST_ZOO",
    "POLICY_SCHEMA",
    "Policy",
    "PolicyChecksumFailed",
    "PolicyFileInvalid",
    "load_policy",
    "resolve",
    "zoo_dir",
    "zoo_names",
]


GENERALIST_ZOO = "generalist"
"""The zoo name of the generalist policy (`policies/zoo/generalist.safetensors`): one network
for any number of vehicles, the default policy of ``fly`` and ``demo``."""

ZOO_SUBFOLDER_NAME = re.compile(r"[A-Za-z0-9_-]+/[A-Za-z0-9_-]+")
"""A zoo name inside one of the zoo's subfolders ("robust/3u2o"): one folder, one name, no
path tricks."""


def zoo_dir() -> Path:
    """Folder of the shipped policies (located without importing the torch-based package)."""
    spec = importlib.util.find_spec("policies")
    if spec is None or not spec.submodule_search_locations:
        raise PolicyError("the policies package is not installed", source="zoo")
    return Path(next(iter(spec.submodule_search_locations))) / "zoo"


def zoo_names() -> list[str]:
    """Names of the shipped policies."""
    folder = zoo_dir()
    return sorted(p.stem for p in folder.glob("*.safetensors")) if folder.is_dir() else []


def resolve(name_or_path: str | Path) -> Path:
    """The file of a zoo name or a path; a clear error if there is none.

    A zoo name is a policy of the zoo ("3u2o") or of one of its subfolders ("robust/3u2o").
    """
    text = str(name_or_path)
    if not isinstance(name_or_path, Path) and ZOO_SUBFOLDER_NAME.fullmatch(text):
        shipped = zoo_dir() / f"{text}.safetensors"
        if shipped.is_file():
            return shipped
    if isinstance(name_or_path, Path) or text.endswith(".safetensors") or "/" in text:
        path = Path(name_or_path)
        if not path.is_file():
            raise PolicyError("no such policy file", source=text)
        return path
    path = zoo_dir() / f"{text}.safetensors"
    if not path.is_file():
        known = ", ".join(zoo_names()) or "none shipped"
        raise PolicyError(
            f"no policy of that name in the zoo (known: {known}); pass a .safetensors path",
            source=text,
        )
    return path


@dataclass(frozen=True)
class Policy:
    """A loaded policy: per-agent actor (and critic) weights and the metadata they came with.

    Attributes:
        source: where it was loaded from.
        meta: the metadata header (`policies.export`).
        actor: layer name → (weight (A, in, out), bias (A, 1, out)).
        critic: the same for the critic (may be empty).
    """

    source: str
    meta: dict[str, Any]
    actor: dict[str, tuple[NDArray[np.float32], NDArray[np.float32]]]
    critic: dict[str, tuple[NDArray[np.float32], NDArray[np.float32]]]

    @property
    def checksum(self) -> str:
        """The file's ``sha256:…`` checksum (what was verified at load; for logs)."""
        return str(self.meta.get(CHECKSUM_KEY, ""))

    def summary(self) -> dict[str, Any]:
        """What a flight's summary says of the policy it flew: name, checksum, range of N."""
        low, high = self.uav_range
        return {
            "name": self.source,
            "checksum": self.checksum,
            "generalist": self.generalist,
            "vehicles": [low, high],
        }

    @property
    def generalist(self) -> bool:
        """True for a set network over the version-2 observation (any N in `uav_range`)."""
        return network_of(self.meta) == "set"

    @property
    def uav_range(self) -> tuple[int, int]:
        """(fewest, most) UAVs the policy flies: (agents, agents) for a zoo MLP."""
        return uav_range(self.meta)

    @property
    def agents(self) -> int:
        """N, the UAVs the policy flies; for a generalist, the most it flies (`uav_range`)."""
        return self.uav_range[1] if self.generalist else int(self.meta["agents"])

    @property
    def layout(self) -> ObservationLayout:
        """The observation layout the policy expects (version 2, with k, for a generalist)."""
        return observation_layout(self.meta)

    @property
    def sees_neighbours(self) -> bool:
        """Whether its observation holds neighbouring UAVs (version 2 with k > 0).

        A zoo scenario policy sees none (the shield's track growth behind it:
        `sim.shield.track_growth_behind`).
        """
        return self.layout.max_neighbours > 0

    def _check_uavs(self, n: int) -> None:
        """Raise `PolicySpecMismatch` unless the policy flies ``n`` UAVs."""
        if not self.generalist:
            if n != self.agents:
                raise PolicySpecMismatch(self.source, "number of UAVs", self.agents, n)
            return
        low, high = self.uav_range
        if not low <= n <= high:
            raise PolicyUavRangeMismatch(self.source, (low, high), n)

    def _generalist_obs(self, obs: NDArray[np.floating[Any]]) -> NDArray[np.float32]:
        """``obs`` (..., N, D) as float32, once N and D are checked."""
        x = np.asarray(obs, dtype=np.float32)
        self._check_uavs(x.shape[-2])
        size = self.layout.size
        if x.shape[-1] != size:
            raise PolicySpecMismatch(self.source, "observation size", size, x.shape[-1])
        return x

    @functools.cached_property
    def _actor64(self) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """The actor's weights as float64, converted once (`sim.setnet` computes in float64)."""
        return {k: (w.astype(np.float64), b.astype(np.float64)) for k, (w, b) in self.actor.items()}

    @functools.cached_property
    def _critic64(self) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """The critic's weights as float64, converted once."""
        return {
            k: (w.astype(np.float64), b.astype(np.float64)) for k, (w, b) in self.critic.items()
        }

    def _weights(self, layer: tuple[NDArray[np.float32], NDArray[np.float32]], n: int) -> Any:
        w, b = layer
        if w.shape[0] == 1 and n != 1:  # shared parameters
            w, b = np.broadcast_to(w, (n, *w.shape[1:])), np.broadcast_to(b, (n, *b.shape[1:]))
        return w, b[:, 0]

    def act(self, obs: NDArray[np.floating[Any]]) -> NDArray[np.float32]:
        """Normalised actions (..., N) in [−1, 1] for flat observations (..., N, D).

        A generalist's observations are version 2 (`layout`), N any number in `uav_range`.

        Raises:
            PolicySpecMismatch: N the policy does not fly (`PolicyUavRangeMismatch` for a
                generalist), or (a generalist) observations of another size.
        """
        if self.generalist:
            return set_actor(self._actor64, self._generalist_obs(obs), self.layout)
        x = np.asarray(obs, dtype=np.float32)
        n = x.shape[-2]
        self._check_uavs(n)
        w1, b1 = self._weights(self.actor["l1"], n)
        w2, b2 = self._weights(self.actor["out"], n)
        h = np.maximum(np.einsum("...nd,ndh->...nh", x, w1) + b1, 0.0)
        out: NDArray[np.float32] = np.tanh(np.einsum("...nh,nho->...no", h, w2) + b2)[..., 0]
        return out.astype(np.float32, copy=False)

    def q_values(self, obs: NDArray[np.floating[Any]], act: NDArray[np.floating[Any]]) -> Any:
        """Critic values (..., N) of actions (..., N) at flat observations (..., N, D)."""
        if not self.critic:
            raise PolicyError("this policy file holds no critic", source=self.source)
        if self.generalist:
            return set_critic(self._critic64, self._generalist_obs(obs), act, self.layout)
        x = np.asarray(obs, dtype=np.float32)
        a = np.asarray(act, dtype=np.float32)[..., None]
        n = x.shape[-2]
        wo, bo = self._weights(self.critic["obs_l"], n)
        wa, ba = self._weights(self.critic["act_l"], n)
        w2, b2 = self._weights(self.critic["l2"], n)
        w3, b3 = self._weights(self.critic["out"], n)
        h = np.concatenate(
            [
                np.maximum(np.einsum("...nd,ndh->...nh", x, wo) + bo, 0.0),
                np.maximum(np.einsum("...nd,ndh->...nh", a, wa) + ba, 0.0),
            ],
            axis=-1,
        )
        h = np.maximum(np.einsum("...nd,ndh->...nh", h, w2) + b2, 0.0)
        return (np.einsum("...nh,nho->...no", h, w3) + b3)[..., 0]

    def check_scenario(self, cfg: ScenarioConfig) -> None:
        """Raise `PolicySpecMismatch` unless ``cfg`` matches what the policy was trained on.

        A zoo MLP: the number of UAVs, dt, speed, turn limit and the scenario's observation
        layout. A generalist: dt, speed, turn limit and N inside `uav_range`
        (`PolicyUavRangeMismatch`), not the scenario's sensing: it brings its own layout, and the
        caller builds its observations with `layout`.
        """
        self._check_uavs(cfg.uav.count)
        checks: list[tuple[str, object, object]] = [
            ("decision step dt_s", float(self.meta["dt_s"]), cfg.dt_s),
            ("UAV speed speed_m_s", float(self.meta["speed_m_s"]), cfg.uav.speed_m_s),
            ("max_turn_rad", float(self.meta["action"]["max_turn_rad"]), cfg.uav.max_turn_rad),
        ]
        if not self.generalist:
            checks.append(("observation layout", self.layout, ObservationLayout.from_scenario(cfg)))
        for field, expected, actual in checks:
            if expected != actual:
                raise PolicySpecMismatch(self.source, field, expected, actual)


def load_policy(name_or_path: str | Path) -> Policy:
    """Load and verify a policy file (zoo name or path).

    Raises:
        PolicyError: no such file or zoo name. PolicyFileInvalid: the file fails a check
            (`PolicyChecksumFailed` for a missing or wrong checksum); its message says what to do.
    """
    path = resolve(name_or_path)
    source = str(name_or_path)
    try:
        tensors, _, meta = read_policy_file(path)
        verify_policy(tensors, meta)
    except (PolicyUnsignedError, PolicyChecksumError) as exc:
        raise PolicyChecksumFailed(exc, source=source, path=str(path)) from exc
    except PolicyFileError as exc:
        raise PolicyFileInvalid(exc, source=source, path=str(path)) from exc

    def layers(prefix: str, names: tuple[str, ...]) -> dict[str, Any]:
        keys = [(f"{prefix}.{n}.weight", f"{prefix}.{n}.bias") for n in names]
        if not all(w in tensors and b in tensors for w, b in keys):
            return {}  # only the critic may be absent (verified)
        return {n: (tensors[w], tensors[b]) for n, (w, b) in zip(names, keys, strict=True)}

    actor_layers, critic_layers = network_layers(meta)
    return Policy(
        source=source,
        meta=meta,
        actor=layers("actor", actor_layers),
        critic=layers("critic", critic_layers),
    )
