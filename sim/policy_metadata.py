"""The metadata of a policy file: its keys, what each may hold, and how it is checked and built.

The metadata is one JSON object under the safetensors header key ``remarl_policy``
(`METADATA_KEY`); `metadata_problems` documents every key. Two schemas are read: 1, the zoo's
MLPs over the version-1 observation for exactly ``agents`` UAVs, and 2, which adds ``network``
("mlp" or "set"), ``uavs`` (the range of swarm sizes it flies) and ``observation.version``
(a version-2 observation describes its blocks: k, m and the entries per row). `network_of`,
`uav_range` and `observation_layout` read them, with schema 1's implied values.

`build_metadata` writes the metadata of a policy trained on a scenario (`policies.export`),
`check_metadata` and `scenario_config` read it back (`remarl_fc.policy_io`, through
`sim.policy_file.verify_policy`). A header without readable metadata is a `PolicyFormatError`;
metadata that breaks the schema, a `PolicySchemaError`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
import typing
from collections.abc import Mapping
from typing import Any, get_args, get_origin, get_type_hints

from sim.config import FieldValueError, ScenarioConfig
from sim.observation import (
    CLIP,
    COLUMNS,
    INTRUDER_COLUMNS,
    NEIGHBOUR_COLUMNS,
    ROW_OBSTACLES,
    SELF_SIZE,
    ObservationLayout,
)
from sim.policy_checksum import CHECKSUM_KEY, CHECKSUM_PREFIX
from sim.policy_problems import Checker, PolicyFileError, Problem, show
from sim.setnet import ATTENTION_HEADS, POOLINGS

POLICY_SCHEMA = 2
"""Newest version of the policy file layout (the metadata's ``schema``).

`build_metadata` writes the lowest schema that describes a policy: 1 for an MLP over the
version-1 observation (every zoo file), 2 for a set network (a generalist). Every schema of
`POLICY_SCHEMAS` is read."""

POLICY_SCHEMAS = (1, 2)
"""The schemas this module reads: 1 (the MLP files), 2 (adds ``network`` and ``uavs``)."""

NETWORKS = ("mlp", "set")
"""``network`` kinds: "mlp" (per-agent or shared MLP over a version-1 observation; what a
schema-1 file implies) and "set" (`sim.setnet`, one network for any number of UAVs)."""

METADATA_KEY = "remarl_policy"
"""Key of the safetensors header entry that holds the JSON metadata."""

MAX_METADATA_DEPTH = 16
"""Deepest nesting of JSON objects and arrays accepted in the metadata (the writer's is 3)."""

REQUIRED_KEYS = (
    "schema",
    "scenario",
    "scenario_config",
    "scenario_hash",
    "agents",
    "shared",
    "hidden",
    "observation",
    "action",
    "dt_s",
    "speed_m_s",
    "d_col_m",
    "reward",
    "training",
    "metrics",
)
"""Top-level metadata keys every policy file has; with `CHECKSUM_KEY` (and in schema 2
`SCHEMA_2_KEYS`), the only ones allowed (an unknown key is a problem: it is what a damaged key
name looks like)."""

SCHEMA_2_KEYS = ("network", "uavs")
"""Top-level keys schema 2 adds (required there, unknown in schema 1)."""

SCHEMA_2_OPTIONAL_KEYS = ("pooling",)
"""Top-level keys schema 2 may hold: ``pooling`` (a set network's, `sim.setnet.POOLINGS`;
absent: "max-mean", what every set network before it was)."""

OBSERVATION_KEYS = (
    "max_obstacles",
    "range_m",
    "aperture_rad",
    "speed_m_s",
    "size",
    "rows",
    "columns",
    "clip",
    "frame",
)
"""Keys of a version-1 ``observation`` (all required; schema 2 adds ``version``)."""

OBSERVATION_V2_KEYS = (
    "version",
    "max_obstacles",
    "max_neighbours",
    "range_m",
    "aperture_rad",
    "speed_m_s",
    "size",
    "self_size",
    "neighbour_size",
    "intruder_size",
    "clip",
    "frame",
)
"""Keys of a version-2 ``observation`` (all required): block sizes instead of rows/columns."""

FRAME = "heading (x ahead, y left); positions / range_m, velocities / speed_m_s"
"""The ``observation.frame`` the writer stores (informative)."""

ACTION_KEYS = ("normalised_bound", "max_turn_rad")
"""Keys of ``action`` (all required)."""

TRAINING_KEYS = ("commit", "steps", "seed")
"""Keys of ``training`` (all required). ``metrics`` is free-form (finite numbers)."""

_HEX64 = re.compile(r"[0-9a-f]{64}")
_SCENARIO_NAME = re.compile(r"[^/\\\x00-\x1f\x7f]{1,255}")


class PolicyFormatError(PolicyFileError):
    """Not a safetensors file, or no (parseable) remarl-fc metadata in it."""

    kind = "format"
    summary = "not a policy file"

    def details(self) -> str:
        """The problems' messages (the key adds nothing here)."""
        return "; ".join(p.message for p in self.problems)


class PolicySchemaError(PolicyFileError):
    """The metadata misses a key, or holds a value of the wrong type or out of range."""

    kind = "schema"
    summary = "bad policy metadata"


def parse_metadata(header: Mapping[str, str] | None) -> dict[str, Any]:
    """The metadata dict of a safetensors header (its ``__metadata__`` strings).

    Raises:
        PolicyFormatError: no `METADATA_KEY` entry, or one that is not a JSON object.
    """
    text = (header or {}).get(METADATA_KEY)
    if not isinstance(text, str):
        raise PolicyFormatError(
            [Problem("file", f"not a remarl-fc policy: no {METADATA_KEY} metadata")]
        )
    try:
        meta = json.loads(text)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, too many digits, too deep
        raise PolicyFormatError(
            [Problem(METADATA_KEY, f"metadata is not valid JSON ({show(str(exc))})")]
        ) from exc
    if not isinstance(meta, dict):
        raise PolicySchemaError(
            [Problem(METADATA_KEY, f"must be a JSON object, got {type(meta).__name__}")]
        )
    return meta


def _walk(meta: Mapping[str, Any], check: Checker) -> bool:
    """Flag non-finite numbers and nesting beyond `MAX_METADATA_DEPTH`; False if too deep."""
    stack: list[tuple[str, Any, int]] = [("", meta, 0)]
    while stack:
        key, value, depth = stack.pop()
        if depth > MAX_METADATA_DEPTH:
            check.add(key or METADATA_KEY, f"nests deeper than {MAX_METADATA_DEPTH} levels")
            return False
        if isinstance(value, float) and not math.isfinite(value):
            check.add(key, f"must be a finite number, got {value!r}")
        elif isinstance(value, dict):
            stack.extend((f"{key}.{k}" if key else k, v, depth + 1) for k, v in value.items())
        elif isinstance(value, list | tuple):
            stack.extend((f"{key}[{i}]", v, depth + 1) for i, v in enumerate(value))
    return True


def _convert(value: Any, hint: Any, key: str, check: Checker) -> tuple[bool, Any]:
    """(ok, value) for a JSON value read into a config field of type ``hint``."""
    if hint is bool:
        ok = isinstance(value, bool)
        expected = "true or false"
    elif hint is float:
        ok = not isinstance(value, bool) and isinstance(value, int | float)
        ok, value, expected = ok and math.isfinite(value), float(value) if ok else value, "a number"
    elif hint is int:
        ok = not isinstance(value, bool) and isinstance(value, int)
        expected = "an integer"
    elif hint is str:
        ok, expected = isinstance(value, str), "a string"
    elif get_origin(hint) is typing.Literal:
        choices = get_args(hint)
        ok, expected = value in choices and isinstance(value, str), f"one of {', '.join(choices)}"
    elif get_origin(hint) is tuple and get_args(hint)[-1:] == (Ellipsis,):
        return _convert_list(value, get_args(hint)[0], key, check)
    elif get_origin(hint) is tuple:
        args = get_args(hint)
        expected = f"a list of {len(args)} numbers"
        ok = isinstance(value, list | tuple) and len(value) == len(args)
        if ok:
            items = [_convert(v, a, key, Checker()) for v, a in zip(value, args, strict=True)]
            ok, value = all(o for o, _ in items), tuple(v for _, v in items)
    else:  # pragma: no cover - every ScenarioConfig field is one of the above
        ok, expected = False, str(hint)
    if not ok:
        check.add(key, f"must be {expected}, got {show(value)}")
    return ok, value


def _convert_list(value: Any, item: Any, key: str, check: Checker) -> tuple[bool, Any]:
    """(ok, tuple) for a list of any length (per-UAV points, ``[[intruders]]`` tables)."""
    if not isinstance(value, list | tuple):
        check.add(key, f"must be a list, got {show(value)}")
        return False, value
    if isinstance(item, type) and dataclasses.is_dataclass(item):
        built = [_build(item, v, f"{key}[{k}].", check) for k, v in enumerate(value)]
        return all(b is not None for b in built), tuple(built)
    items = [_convert(v, item, f"{key}[{k}]", check) for k, v in enumerate(value)]
    return all(ok for ok, _ in items), tuple(v for _, v in items)


_FIELDS: dict[type[Any], tuple[dict[str, Any], dict[str, dataclasses.Field[Any]]]] = {}


def _fields(cls: type[Any]) -> tuple[dict[str, Any], dict[str, dataclasses.Field[Any]]]:
    """Type hints and fields of a config dataclass (resolving hints is slow: once per class)."""
    if cls not in _FIELDS:
        _FIELDS[cls] = get_type_hints(cls), {f.name: f for f in dataclasses.fields(cls)}
    return _FIELDS[cls]


def _build(cls: type[Any], raw: Any, prefix: str, check: Checker) -> Any:
    """The config dataclass ``cls`` from its `dataclasses.asdict` form, or None (problems noted)."""
    if not isinstance(raw, dict):
        check.add(prefix.rstrip("."), f"must be an object, got {show(raw)}")
        return None
    hints, fields = _fields(cls)
    kwargs: dict[str, Any] = {}
    ok = True
    for key, value in raw.items():
        if key not in fields:
            check.add(prefix + key, f"unknown key (known: {', '.join(sorted(fields))})")
            ok = False
            continue
        hint = hints[key]
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            kwargs[key] = _build(hint, value, f"{prefix}{key}.", check)
            ok = ok and kwargs[key] is not None
        else:
            good, kwargs[key] = _convert(value, hint, prefix + key, check)
            ok = ok and good
    for name, spec in fields.items():
        required = (
            spec.default is dataclasses.MISSING and spec.default_factory is dataclasses.MISSING
        )
        if name not in raw and required:
            check.add(prefix + name, "required key is missing")
            ok = False
    if not ok:
        return None
    try:
        return cls(**kwargs)
    except FieldValueError as exc:  # a dotted field is relative to the ScenarioConfig
        root = prefix.split(".", 1)[0] + "."
        check.add((root if "." in exc.field else prefix) + exc.field, exc.reason)
        return None


def scenario_config(meta: Mapping[str, Any]) -> ScenarioConfig:
    """The `ScenarioConfig` of a policy's ``scenario_config`` (`dataclasses.asdict` form).

    Raises:
        PolicySchemaError: naming the key that is missing, unknown, mistyped or out of range.
    """
    check = Checker()
    cfg = _build(ScenarioConfig, meta.get("scenario_config"), "scenario_config.", check)
    if check.problems or not isinstance(cfg, ScenarioConfig):
        raise PolicySchemaError(check.problems or [Problem("scenario_config", "is missing")])
    return cfg


def scenario_hash(config: Mapping[str, Any]) -> str:
    """The ``scenario_hash`` the writer stores: SHA-256 of the sorted-key JSON of the config."""
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()


def observation_metadata(layout: ObservationLayout, *, versioned: bool) -> dict[str, Any]:
    """The ``observation`` metadata of a layout (keys: `metadata_problems`).

    Args:
        versioned: write ``version`` (schema 2; a schema-1 file's observation has none).
    """
    common = {
        "max_obstacles": layout.max_obstacles,
        "range_m": layout.range_m,
        "aperture_rad": layout.aperture_rad,
        "speed_m_s": layout.speed_m_s,
    }
    if layout.version == 1:
        return {
            **({"version": 1} if versioned else {}),
            **common,
            "size": layout.size,
            "rows": layout.rows,
            "columns": COLUMNS,
            "clip": CLIP,
            "frame": FRAME,
        }
    return {
        "version": layout.version,
        **common,
        "max_neighbours": layout.max_neighbours,
        "size": layout.size,
        "self_size": SELF_SIZE,
        "neighbour_size": NEIGHBOUR_COLUMNS,
        "intruder_size": INTRUDER_COLUMNS,
        "clip": CLIP,
        "frame": FRAME,
    }


def build_metadata(
    cfg: ScenarioConfig,
    *,
    shared: bool,
    hidden: int,
    reward: str,
    training: Mapping[str, Any],
    metrics: Mapping[str, Any],
    network: str = "mlp",
    uavs: tuple[int, int] | None = None,
    pooling: str = "max-mean",
) -> dict[str, Any]:
    """The unsigned metadata of a policy trained on ``cfg`` (its keys: `metadata_problems`).

    An MLP over the version-1 observation gets schema 1 (the metadata every zoo file has);
    anything else schema 2, with ``network`` and ``uavs``.

    Args:
        shared: one set of parameters for every agent. hidden: units of every hidden layer.
        reward: the reward it was trained on. training: ``commit``, ``steps`` and ``seed``.
        metrics: evaluation figures (finite numbers or null).
        network: "mlp" or "set" (`NETWORKS`); the observation is the scenario's
            (``[sensing] observation``: a set network needs version 2).
        uavs: (fewest, most) UAVs the policy flies (None: exactly ``cfg.uav.count``).
        pooling: a set network's pooling (`sim.setnet.POOLINGS`); written only when it is not
            the default "max-mean", so files of the default stay as they were.
    """
    layout = ObservationLayout.from_scenario(cfg)
    schema = 1 if network == "mlp" and layout.version == 1 else 2
    scenario = dataclasses.asdict(cfg)
    meta: dict[str, Any] = {
        "schema": schema,
        "scenario": cfg.name,
        "scenario_config": scenario,
        "scenario_hash": scenario_hash(scenario),
        "agents": cfg.uav.count,
    }
    if schema >= 2:
        low, high = uavs if uavs is not None else (cfg.uav.count, cfg.uav.count)
        meta["network"] = network
        meta["uavs"] = [int(low), int(high)]
        if pooling != "max-mean":
            meta["pooling"] = pooling
    return {
        **meta,
        "shared": shared,
        "hidden": hidden,
        "observation": observation_metadata(layout, versioned=schema >= 2),
        "action": {"normalised_bound": 1.0, "max_turn_rad": cfg.uav.max_turn_rad},
        "dt_s": cfg.dt_s,
        "speed_m_s": cfg.uav.speed_m_s,
        "d_col_m": cfg.d_col_m,
        "reward": reward,
        "training": dict(training),
        "metrics": dict(metrics),
    }


def pooling_of(meta: Mapping[str, Any]) -> str:
    """The ``pooling`` of valid metadata of a set network ("max-mean" where absent)."""
    return str(meta.get("pooling", "max-mean"))


def network_of(meta: Mapping[str, Any]) -> str:
    """The ``network`` of valid metadata: "mlp" (implied by schema 1) or "set"."""
    return str(meta.get("network", "mlp"))


def uav_range(meta: Mapping[str, Any]) -> tuple[int, int]:
    """(fewest, most) UAVs a policy of valid metadata flies (schema 1: exactly ``agents``)."""
    if "uavs" in meta:
        low, high = meta["uavs"]
        return int(low), int(high)
    return int(meta["agents"]), int(meta["agents"])


def observation_layout(meta: Mapping[str, Any]) -> ObservationLayout:
    """The `ObservationLayout` of valid metadata's ``observation`` (version 1 where none)."""
    o = meta["observation"]
    return ObservationLayout(
        int(o["max_obstacles"]),
        float(o["range_m"]),
        float(o["aperture_rad"]),
        float(o["speed_m_s"]),
        int(o.get("max_neighbours", 0)),
        int(o.get("version", 1)),
    )


def _schema(meta: Mapping[str, Any], check: Checker) -> int | None:
    """The schema of the metadata (1 where missing, noted); None for one this module can't read."""
    readable = " or ".join(str(s) for s in POLICY_SCHEMAS)
    if "schema" not in meta:
        check.add("schema", f"required key is missing (expected {readable})")
        return 1
    value = meta["schema"]
    if type(value) is not int or value not in POLICY_SCHEMAS:
        check.add(
            "schema",
            f"this remarl-fc reads policy schema {readable}, the file has {show(value)} "
            "(use the remarl-fc that wrote it)",
        )
        return None
    return value


def _uavs(meta: Mapping[str, Any], check: Checker) -> tuple[int, int] | None:
    """``uavs`` as (fewest, most): two integers, 1 <= fewest <= most; else None (noted)."""
    value = check.get(meta, "uavs", "", "[fewest, most]")
    if "uavs" not in meta:
        return None
    ok = isinstance(value, list) and len(value) == 2
    ok = ok and all(type(v) is int and v >= 1 for v in value) and value[0] <= value[1]
    if not ok:
        check.add(
            "uavs", f"must be [fewest, most], integers with 1 <= fewest <= most, got {show(value)}"
        )
        return None
    return int(value[0]), int(value[1])


def _observation(obs: Mapping[str, Any], schema: int, check: Checker) -> dict[str, Any]:
    """Check ``observation``; returns the layout fields it read (``version`` among them)."""
    p = "observation."
    layout: dict[str, Any] = {"version": 1}
    if schema >= 2:
        version = check.integer(obs, "version", p)
        if version is not None and version not in (1, 2):
            check.add(p + "version", f"must be 1 or 2 (sim.observation), got {show(version)}")
            version = None
        if version is None:
            return {}
        layout["version"] = version
    v2 = layout["version"] == 2
    keys = (
        OBSERVATION_V2_KEYS if v2 else (*OBSERVATION_KEYS, *(("version",) if schema >= 2 else ()))
    )
    check.known(obs, keys, p)
    m = check.integer(obs, "max_obstacles", p)
    layout["range_m"] = check.number(obs, "range_m", p)
    layout["aperture_rad"] = check.number(obs, "aperture_rad", p, high=2 * math.pi)
    layout["speed_m_s"] = check.number(obs, "speed_m_s", p)
    size = check.integer(obs, "size", p)
    if v2:
        k = check.integer(obs, "max_neighbours", p, minimum=0)
        for key, want in (
            ("self_size", SELF_SIZE),
            ("neighbour_size", NEIGHBOUR_COLUMNS),
            ("intruder_size", INTRUDER_COLUMNS),
        ):
            check.equal(p + key, check.integer(obs, key, p), want, f"sim.observation's {key}")
        if m is not None and k is not None:
            layout["max_neighbours"] = k
            want = ObservationLayout(m, 1.0, 1.0, 1.0, k, 2).size
            check.equal(p + "size", size, want, "8 + 9·max_neighbours + 6·max_obstacles")
    else:
        rows, columns = (check.integer(obs, k, p) for k in ("rows", "columns"))
        check.equal(p + "columns", columns, COLUMNS, "the observation's columns")
        if m is not None:
            check.equal(p + "rows", rows, ROW_OBSTACLES + m, "2 + max_obstacles")
            check.equal(p + "size", size, (ROW_OBSTACLES + m) * COLUMNS + m, "rows·4 + m")
    if m is not None:
        layout["max_obstacles"] = m
    clip = check.number(obs, "clip", p)
    check.equal(p + "clip", clip, CLIP, "the clip of sim.observation")
    check.string(obs, "frame", p)
    return layout


def metadata_problems(meta: object) -> list[Problem]:
    """Everything wrong with a policy's metadata; empty when it is valid.

    The schemas (`POLICY_SCHEMAS`: 1 and 2; ranges as the simulator's config enforces them):

    - ``schema``: 1 (an MLP over the version-1 observation: every zoo file) or 2 (adds
      ``network`` and ``uavs``, and ``observation.version``). ``scenario``: the scenario's name
      (1–255 characters, no path separator or control character).
    - ``scenario_config``: the `ScenarioConfig` as `dataclasses.asdict` writes it; it must build
      one (every key known, typed and in range). ``scenario_hash``: `scenario_hash` of it. For a
      generalist, the scenario it was trained or exported with (its ``sensing`` describes the
      version-2 observation); it flies others (`uavs`).
    - ``agents``: integer >= 1, = ``scenario_config.uav.count``. ``shared``: bool (true for a set
      network). ``hidden``: integer >= 1 (units of every hidden layer).
    - ``network`` (schema 2 only; schema 1 implies "mlp"): "mlp" (tensors `expected_shapes`'s
      per-agent MLP, observation version 1) or "set" (`sim.setnet`, observation version 2).
    - ``uavs`` (schema 2 only; schema 1 implies [agents, agents]): [fewest, most], integers
      with 1 <= fewest <= most: the numbers of UAVs the policy flies; [agents, agents] for an
      MLP, a range holding ``agents`` for a set network.
    - ``pooling`` (schema 2, optional, set networks only): one of `sim.setnet.POOLINGS`
      (absent: "max-mean"); "max-attention" needs ``hidden`` divisible by
      `sim.setnet.ATTENTION_HEADS`.
    - ``observation``, version 1: ``max_obstacles`` integer >= 1, ``range_m`` > 0,
      ``aperture_rad`` in (0, 2π], ``speed_m_s`` > 0 (all equal to the scenario's),
      ``rows`` = 2 + max_obstacles, ``columns`` = `COLUMNS`, ``size`` = rows·columns +
      max_obstacles, ``clip`` = `CLIP`, ``frame`` a string; in schema 2 also ``version`` = 1.
    - ``observation``, version 2 (schema 2): ``version`` = 2, ``max_obstacles`` (m) integer >= 1,
      ``max_neighbours`` (k) integer >= 0, ``range_m``, ``aperture_rad``, ``speed_m_s`` (all
      equal to the scenario's), ``size`` = `SELF_SIZE` + 9k + 6m (`ObservationLayout.size`),
      ``self_size`` = `SELF_SIZE`, ``neighbour_size`` = `NEIGHBOUR_COLUMNS`, ``intruder_size`` =
      `INTRUDER_COLUMNS` (entries of the self block and per neighbour and intruder row),
      ``clip`` = `CLIP`, ``frame`` a string. ``version`` equals the scenario's
      ``sensing.observation`` (1 in schema 1), ``max_neighbours`` its ``sensing.max_neighbours``.
    - ``action``: ``normalised_bound`` 1.0, ``max_turn_rad`` in (0, π/2] (= the scenario's).
    - ``dt_s``, ``speed_m_s``, ``d_col_m``: finite > 0, equal to the scenario's.
    - ``reward``: a string. ``training``: ``commit`` string, ``steps`` integer >= 0, ``seed``
      integer. ``metrics``: an object.
    - ``checksum`` (optional here, required by `check_checksum`): ``sha256:`` + 64 hex digits.
    - no other keys (except in ``metrics``); every number finite; nesting at most
      `MAX_METADATA_DEPTH`.
    """
    check = Checker()
    if not isinstance(meta, dict):
        return [Problem(METADATA_KEY, f"must be a JSON object, got {type(meta).__name__}")]
    if not _walk(meta, check):
        return check.problems
    schema = _schema(meta, check)
    if schema is None:
        return check.problems
    later = (*SCHEMA_2_KEYS, *SCHEMA_2_OPTIONAL_KEYS) if schema >= 2 else ()
    check.known(meta, (*REQUIRED_KEYS, *later, CHECKSUM_KEY))
    name = check.string(meta, "scenario")
    if name is not None and not _SCENARIO_NAME.fullmatch(name):
        check.add("scenario", f"must be a scenario name (no '/'), got {show(name)}")
    cfg, cfg_raw = None, check.obj(meta, "scenario_config")
    if cfg_raw is not None:
        cfg = _build(ScenarioConfig, cfg_raw, "scenario_config.", check)
    digest = check.string(meta, "scenario_hash")
    if digest is not None and not _HEX64.fullmatch(digest):
        check.add("scenario_hash", f"must be 64 lowercase hex digits, got {show(digest)}")
    elif cfg is not None and digest is not None:
        recorded = meta["scenario_config"]
        if digest != scenario_hash(recorded):
            check.add("scenario_hash", "does not match scenario_config (SHA-256 of its JSON)")
    agents = check.integer(meta, "agents")
    shared = check.boolean(meta, "shared")
    check.integer(meta, "hidden")
    dt_s, speed, d_col = (check.number(meta, k) for k in ("dt_s", "speed_m_s", "d_col_m"))
    check.string(meta, "reward")
    obs = check.obj(meta, "observation")
    layout = _observation(obs, schema, check) if obs is not None else {}
    if schema >= 2:
        network = check.choice(meta, "network", NETWORKS)
        uavs = _uavs(meta, check)
        version = layout.get("version")
        if (
            network is not None
            and version is not None
            and version != (2 if network == "set" else 1)
        ):
            check.add(
                "network",
                f"a {network} network reads observation version {2 if network == 'set' else 1}, "
                f"the observation is version {version} (the scenario's [sensing] observation)",
            )
        if "pooling" in meta:
            pooling = check.choice(meta, "pooling", POOLINGS)
            if pooling is not None and network is not None and network != "set":
                check.add("pooling", f"only a set network pools, this is a {network} network")
            hidden = meta.get("hidden")
            if pooling == "max-attention" and isinstance(hidden, int) and hidden % ATTENTION_HEADS:
                check.add("hidden", f"must be divisible by {ATTENTION_HEADS} (attention heads)")
        if network == "set" and shared is False:
            check.add("shared", "must be true for a set network (one network for every UAV)")
        if network is not None and uavs is not None and agents is not None:
            low, high = uavs
            if network == "mlp" and uavs != (agents, agents):
                check.add("uavs", f"must be [agents, agents] for an mlp, got {show(list(uavs))}")
            elif not low <= agents <= high:
                check.add("uavs", f"must hold agents ({agents}), got {show(list(uavs))}")
    act = check.obj(meta, "action")
    turn = None
    if act is not None:
        check.known(act, ACTION_KEYS, "action.")
        bound = check.number(act, "normalised_bound", "action.")
        check.equal("action.normalised_bound", bound, 1.0, "the tanh output bound")
        turn = check.number(act, "max_turn_rad", "action.", high=math.pi / 2)
    training = check.obj(meta, "training")
    if training is not None:
        check.known(training, TRAINING_KEYS, "training.")
        check.string(training, "commit", "training.")
        check.integer(training, "steps", "training.", minimum=0)
        check.integer(training, "seed", "training.", minimum=None)
    check.obj(meta, "metrics")
    if CHECKSUM_KEY in meta:
        value = meta[CHECKSUM_KEY]
        if not (
            isinstance(value, str)
            and value.startswith(CHECKSUM_PREFIX)
            and _HEX64.fullmatch(value[len(CHECKSUM_PREFIX) :])
        ):
            check.add(CHECKSUM_KEY, f"must be 'sha256:' + 64 hex digits, got {show(value)}")
    if isinstance(cfg, ScenarioConfig):
        _agrees_with_scenario(check, cfg, schema, layout, name, agents, dt_s, speed, d_col, turn)
    return check.problems


def _agrees_with_scenario(
    check: Checker,
    cfg: ScenarioConfig,
    schema: int,
    layout: Mapping[str, Any],
    name: str | None,
    agents: int | None,
    dt_s: float | None,
    speed: float | None,
    d_col: float | None,
    turn: float | None,
) -> None:
    """Note every metadata value that differs from the scenario's (``scenario_config``)."""
    of = "scenario_config"
    check.equal("scenario", name, cfg.name, f"{of}.name")
    check.equal("agents", agents, cfg.uav.count, f"{of}.uav.count")
    check.equal("dt_s", dt_s, cfg.dt_s, f"{of}.dt_s")
    check.equal("speed_m_s", speed, cfg.uav.speed_m_s, f"{of}.uav.speed_m_s")
    check.equal("d_col_m", d_col, cfg.d_col_m, f"{of}.d_col_m")
    check.equal("action.max_turn_rad", turn, cfg.uav.max_turn_rad, f"{of}.uav.max_turn_rad")
    s = cfg.sensing
    if schema == 1:
        check.equal(
            f"{of}.sensing.observation",
            s.observation,
            1,
            "1 (schema 1 is the version-1 observation)",
        )
    for key, want, what in (
        ("version", s.observation, "sensing.observation"),
        ("max_obstacles", s.max_obstacles, "sensing.max_obstacles"),
        ("max_neighbours", s.max_neighbours, "sensing.max_neighbours"),
        ("range_m", s.range_m, "sensing.range_m"),
        ("aperture_rad", s.aperture_rad, "sensing.aperture_rad"),
        ("speed_m_s", cfg.uav.speed_m_s, "uav.speed_m_s"),
    ):
        if schema >= 2 or key != "version":
            check.equal(f"observation.{key}", layout.get(key), want, f"{of}.{what}")


def check_metadata(meta: object) -> dict[str, Any]:
    """``meta`` if it is valid metadata (`metadata_problems`); else raise `PolicySchemaError`."""
    problems = metadata_problems(meta)
    if problems:
        raise PolicySchemaError(problems)
    assert isinstance(meta, dict)
    return meta
