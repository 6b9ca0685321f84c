"""The policy file format: metadata schema, checksum and weight checks (numpy and stdlib only).

This module lives in `sim` because both ends of the format need it and neither may import the
other's package: the writer, `policies.export` (torch side), may not import `remarl_fc`, and the
loader, `remarl_fc.policy_io` (the flight path), may not import `policies` or torch. Both import
`sim`, so the one definition of what a valid policy file is lives here.

A policy file is safetensors: float32 tensors ``actor.*`` (and optionally ``critic.*``) with a
leading agent dimension (1 when parameters are shared), and one JSON string under the header key
``remarl_policy`` (`METADATA_KEY`): the metadata of `metadata_problems`. Its ``checksum``
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
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, get_args, get_origin, get_type_hints

import numpy as np
from numpy.typing import NDArray

from sim.config import FieldValueError, ScenarioConfig
from sim.errors import RemarlError
from sim.observation import CLIP, COLUMNS, ROW_OBSTACLES

POLICY_SCHEMA = 1
"""Version of the policy file layout this module describes (the metadata's ``schema``)."""

METADATA_KEY = "remarl_policy"
"""Key of the safetensors header entry that holds the JSON metadata."""

CHECKSUM_KEY = "checksum"
"""Metadata key of the checksum, ``"sha256:<64 hex digits>"``; excluded from what it hashes."""

CHECKSUM_PREFIX = "sha256:"
"""The algorithm tag of `CHECKSUM_KEY` values."""

CHECKSUM_DOMAIN = b"remarl-fc policy checksum v1\n"
"""First bytes hashed, so that the digest of a policy file can be no other format's digest."""

WEIGHT_BOUND = 1e4
"""Largest |weight| a policy file may hold.

Trained weights here are O(1) (the zoo's largest is about 7, in a critic); a float32 with one
flipped exponent bit is 1e30 or more (or inf, or NaN), and a diverged training run gives values
far above 1e4 long before it gives infinities. So the bound is four orders of magnitude above
anything a healthy run writes and still catches what a bit flip or a divergence does."""

MAX_METADATA_DEPTH = 16
"""Deepest nesting of JSON objects and arrays accepted in the metadata (the writer's is 3)."""

ACTOR_LAYERS = ("l1", "out")
"""Layers of the actor: ``actor.<layer>.weight`` and ``.bias`` (all required)."""

CRITIC_LAYERS = ("obs_l", "act_l", "l2", "out")
"""Layers of the critic: ``critic.<layer>.weight`` and ``.bias`` (all of them, or none)."""

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
"""Top-level metadata keys every policy file has; with `CHECKSUM_KEY`, the only ones allowed (an
unknown key is a problem: it is what a damaged key name looks like)."""

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
"""Keys of ``observation`` (all required)."""

ACTION_KEYS = ("normalised_bound", "max_turn_rad")
"""Keys of ``action`` (all required)."""

TRAINING_KEYS = ("commit", "steps", "seed")
"""Keys of ``training`` (all required). ``metrics`` is free-form (finite numbers)."""

_HEX64 = re.compile(r"[0-9a-f]{64}")
_SCENARIO_NAME = re.compile(r"[^/\\\x00-\x1f\x7f]{1,255}")
_MAX_LISTED = 4


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a policy file.

    Attributes:
        key: the dotted metadata key (``observation.size``), the tensor name
            (``actor.l1.weight``), or ``file`` / ``checksum``.
        message: what is expected, and what was found.
    """

    key: str
    message: str

    def __post_init__(self) -> None:  # names come from the file: keep messages one clean line
        object.__setattr__(self, "key", _printable(self.key, 80))
        object.__setattr__(self, "message", _printable(self.message, 400))

    def __str__(self) -> str:
        return f"{self.key}: {self.message}"


class PolicyFileError(RemarlError, ValueError):
    """A policy file breaks the format; ``problems`` name each key or tensor at fault.

    Attributes:
        problems: what is wrong, one `Problem` per key or tensor.
        key: the key of the first problem.
    """

    kind: ClassVar[str] = "invalid"
    summary: ClassVar[str] = "invalid policy file"
    advice: ClassVar[str] = "re-export it with remarl-fc export"

    def __init__(self, problems: Iterable[Problem]) -> None:
        self.problems = tuple(problems)
        self.key = self.problems[0].key if self.problems else ""
        super().__init__(self.describe())

    def details(self) -> str:
        """The problems, on one line (the first few, then how many more)."""
        shown = "; ".join(str(p) for p in self.problems[:_MAX_LISTED])
        more = len(self.problems) - _MAX_LISTED
        return shown + (f"; and {more} more" if more > 0 else "")

    def describe(self, path: str = "FILE") -> str:
        """One line: what is wrong and what to do (``path`` fills the advice's file name)."""
        return f"{self.summary} ({self.details()}): {self.advice.replace('FILE', path)}"


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


class PolicyUnsignedError(PolicyFileError):
    """The file has no checksum: it was written before policy files carried one."""

    kind = "unsigned"
    summary = "no checksum"
    advice = (
        "if you trust the file, add one with `python -m policies.export --rehash FILE` "
        "(or re-export it with remarl-fc export)"
    )

    def describe(self, path: str = "FILE") -> str:
        """One line: what is wrong and what to do."""
        return (
            "no checksum: written by a remarl-fc older than policy checksums; "
            + self.advice.replace("FILE", path)
        )


class PolicyChecksumError(PolicyFileError):
    """The checksum does not match the contents: the file changed after it was written.

    Attributes:
        expected: the checksum the file carries. actual: the checksum of its contents.
    """

    kind = "checksum"
    summary = "corrupt"
    advice = "re-export it or restore the file"

    def __init__(self, expected: str, actual: str) -> None:
        self.expected, self.actual = expected, actual
        super().__init__([Problem(CHECKSUM_KEY, f"file says {expected}, contents give {actual}")])

    def describe(self, path: str = "FILE") -> str:
        """One line: what is wrong and what to do."""
        return (
            f"corrupt: checksum mismatch (the file says {_short(self.expected)}, its contents "
            f"hash to {_short(self.actual)}); {self.advice}"
        )


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


def _printable(text: str, limit: int) -> str:
    """``text`` with control characters escaped, cut to ``limit`` characters."""
    if not text.isprintable():
        text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _short(checksum: str) -> str:
    return checksum[: len(CHECKSUM_PREFIX) + 16] + "…" if len(checksum) > 40 else repr(checksum)


def _show(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


# ---------------------------------------------------------------------------------- metadata


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
            [Problem(METADATA_KEY, f"metadata is not valid JSON ({_show(str(exc))})")]
        ) from exc
    if not isinstance(meta, dict):
        raise PolicySchemaError(
            [Problem(METADATA_KEY, f"must be a JSON object, got {type(meta).__name__}")]
        )
    return meta


class _Checker:
    """Collects `Problem` items while reading typed values out of nested dicts."""

    def __init__(self) -> None:
        self.problems: list[Problem] = []

    def add(self, key: str, message: str) -> None:
        if all(p.key != key for p in self.problems):  # the first problem of a key says enough
            self.problems.append(Problem(key, message))

    def get(self, d: Mapping[str, Any], key: str, prefix: str, expected: str) -> Any:
        if key not in d:
            self.add(prefix + key, f"required key is missing (expected {expected})")
            return None
        return d[key]

    def obj(self, d: Mapping[str, Any], key: str, prefix: str = "") -> dict[str, Any] | None:
        value = self.get(d, key, prefix, "an object")
        if key in d and not isinstance(value, dict):
            self.add(prefix + key, f"must be an object, got {_show(value)}")
        return value if isinstance(value, dict) else None

    def integer(
        self, d: Mapping[str, Any], key: str, prefix: str = "", *, minimum: int | None = 1
    ) -> int | None:
        expected = "an integer" if minimum is None else f"an integer >= {minimum}"
        value = self.get(d, key, prefix, expected)
        if key not in d:
            return None
        too_small = minimum is not None and isinstance(value, int) and value < minimum
        if isinstance(value, bool) or not isinstance(value, int) or too_small:
            self.add(prefix + key, f"must be {expected}, got {_show(value)}")
            return None
        return value

    def number(
        self,
        d: Mapping[str, Any],
        key: str,
        prefix: str = "",
        *,
        high: float = math.inf,
    ) -> float | None:
        expected = "a finite number > 0" if high == math.inf else f"a number in (0, {high:.6g}]"
        value = self.get(d, key, prefix, expected)
        if key not in d:
            return None
        ok = not isinstance(value, bool) and isinstance(value, int | float)
        ok = ok and math.isfinite(value) and 0 < value <= high
        if not ok:
            self.add(prefix + key, f"must be {expected}, got {_show(value)}")
            return None
        return float(value)

    def string(self, d: Mapping[str, Any], key: str, prefix: str = "") -> str | None:
        value = self.get(d, key, prefix, "a string")
        if key not in d:
            return None
        if not isinstance(value, str) or not value:
            self.add(prefix + key, f"must be a non-empty string, got {_show(value)}")
            return None
        return value

    def boolean(self, d: Mapping[str, Any], key: str, prefix: str = "") -> bool | None:
        value = self.get(d, key, prefix, "true or false")
        if key not in d:
            return None
        if not isinstance(value, bool):
            self.add(prefix + key, f"must be true or false, got {_show(value)}")
            return None
        return value

    def known(self, d: Mapping[str, Any], keys: Iterable[str], prefix: str = "") -> None:
        allowed = set(keys)
        for key in d:
            if key not in allowed:
                self.add(prefix + key, f"unknown key (known: {', '.join(sorted(allowed))})")

    def equal(self, key: str, value: object, expected: object, what: str) -> None:
        if value is not None and expected is not None and value != expected:
            self.add(key, f"must equal {what} ({_show(expected)}), got {_show(value)}")


def _walk(meta: Mapping[str, Any], check: _Checker) -> bool:
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


def _convert(value: Any, hint: Any, key: str, check: _Checker) -> tuple[bool, Any]:
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
    elif get_origin(hint) is tuple:
        args = get_args(hint)
        expected = f"a list of {len(args)} numbers"
        ok = isinstance(value, list | tuple) and len(value) == len(args)
        if ok:
            items = [_convert(v, a, key, _Checker()) for v, a in zip(value, args, strict=True)]
            ok, value = all(o for o, _ in items), tuple(v for _, v in items)
    else:  # pragma: no cover - every ScenarioConfig field is one of the above
        ok, expected = False, str(hint)
    if not ok:
        check.add(key, f"must be {expected}, got {_show(value)}")
    return ok, value


_FIELDS: dict[type[Any], tuple[dict[str, Any], dict[str, dataclasses.Field[Any]]]] = {}


def _fields(cls: type[Any]) -> tuple[dict[str, Any], dict[str, dataclasses.Field[Any]]]:
    """Type hints and fields of a config dataclass (resolving hints is slow: once per class)."""
    if cls not in _FIELDS:
        _FIELDS[cls] = get_type_hints(cls), {f.name: f for f in dataclasses.fields(cls)}
    return _FIELDS[cls]


def _build(cls: type[Any], raw: Any, prefix: str, check: _Checker) -> Any:
    """The config dataclass ``cls`` from its `dataclasses.asdict` form, or None (problems noted)."""
    if not isinstance(raw, dict):
        check.add(prefix.rstrip("."), f"must be an object, got {_show(raw)}")
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
    check = _Checker()
    cfg = _build(ScenarioConfig, meta.get("scenario_config"), "scenario_config.", check)
    if check.problems or not isinstance(cfg, ScenarioConfig):
        raise PolicySchemaError(check.problems or [Problem("scenario_config", "is missing")])
    return cfg


def scenario_hash(config: Mapping[str, Any]) -> str:
    """The ``scenario_hash`` the writer stores: SHA-256 of the sorted-key JSON of the config."""
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()


def metadata_problems(meta: object) -> list[Problem]:
    """Everything wrong with a policy's metadata; empty when it is valid.

    The schema (`POLICY_SCHEMA` 1; ranges as the simulator's config enforces them):

    - ``schema``: 1. ``scenario``: the scenario's name (1–255 characters, no path separator
      or control character).
    - ``scenario_config``: the `ScenarioConfig` as `dataclasses.asdict` writes it; it must build
      one (every key known, typed and in range). ``scenario_hash``: `scenario_hash` of it.
    - ``agents``: integer >= 1, = ``scenario_config.uav.count``. ``shared``: bool.
      ``hidden``: integer >= 1 (units of every hidden layer).
    - ``observation``: ``max_obstacles`` integer >= 1, ``range_m`` > 0, ``aperture_rad`` in
      (0, 2π], ``speed_m_s`` > 0 (all equal to the scenario's), ``rows`` = 2 + max_obstacles,
      ``columns`` = `COLUMNS`, ``size`` = rows·columns + max_obstacles, ``clip`` = `CLIP`,
      ``frame`` a string.
    - ``action``: ``normalised_bound`` 1.0, ``max_turn_rad`` in (0, π/2] (= the scenario's).
    - ``dt_s``, ``speed_m_s``, ``d_col_m``: finite > 0, equal to the scenario's.
    - ``reward``: a string. ``training``: ``commit`` string, ``steps`` integer >= 0, ``seed``
      integer. ``metrics``: an object.
    - ``checksum`` (optional here, required by `check_checksum`): ``sha256:`` + 64 hex digits.
    - no other keys (except in ``metrics``); every number finite; nesting at most
      `MAX_METADATA_DEPTH`.
    """
    check = _Checker()
    if not isinstance(meta, dict):
        return [Problem(METADATA_KEY, f"must be a JSON object, got {type(meta).__name__}")]
    if not _walk(meta, check):
        return check.problems
    if "schema" not in meta:
        check.add("schema", f"required key is missing (expected {POLICY_SCHEMA})")
    elif meta["schema"] != POLICY_SCHEMA or isinstance(meta["schema"], bool):
        check.add(
            "schema",
            f"this remarl-fc reads policy schema {POLICY_SCHEMA}, the file has "
            f"{_show(meta['schema'])} (use the remarl-fc that wrote it)",
        )
        return check.problems
    check.known(meta, (*REQUIRED_KEYS, CHECKSUM_KEY))
    name = check.string(meta, "scenario")
    if name is not None and not _SCENARIO_NAME.fullmatch(name):
        check.add("scenario", f"must be a scenario name (no '/'), got {_show(name)}")
    cfg, cfg_raw = None, check.obj(meta, "scenario_config")
    if cfg_raw is not None:
        cfg = _build(ScenarioConfig, cfg_raw, "scenario_config.", check)
    digest = check.string(meta, "scenario_hash")
    if digest is not None and not _HEX64.fullmatch(digest):
        check.add("scenario_hash", f"must be 64 lowercase hex digits, got {_show(digest)}")
    elif cfg is not None and digest is not None:
        recorded = meta["scenario_config"]
        if digest != scenario_hash(recorded):
            check.add("scenario_hash", "does not match scenario_config (SHA-256 of its JSON)")
    agents = check.integer(meta, "agents")
    check.boolean(meta, "shared")
    check.integer(meta, "hidden")
    dt_s, speed, d_col = (check.number(meta, k) for k in ("dt_s", "speed_m_s", "d_col_m"))
    check.string(meta, "reward")
    obs = check.obj(meta, "observation")
    layout: dict[str, Any] = {}
    if obs is not None:
        p = "observation."
        check.known(obs, OBSERVATION_KEYS, p)
        m = check.integer(obs, "max_obstacles", p)
        layout["range_m"] = check.number(obs, "range_m", p)
        layout["aperture_rad"] = check.number(obs, "aperture_rad", p, high=2 * math.pi)
        layout["speed_m_s"] = check.number(obs, "speed_m_s", p)
        rows, columns, size = (check.integer(obs, k, p) for k in ("rows", "columns", "size"))
        check.equal(p + "columns", columns, COLUMNS, "the observation's columns")
        if m is not None:
            layout["max_obstacles"] = m
            check.equal(p + "rows", rows, ROW_OBSTACLES + m, "2 + max_obstacles")
            check.equal(p + "size", size, (ROW_OBSTACLES + m) * COLUMNS + m, "rows·4 + m")
        clip = check.number(obs, "clip", p)
        check.equal(p + "clip", clip, CLIP, "the clip of sim.observation")
        check.string(obs, "frame", p)
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
            check.add(CHECKSUM_KEY, f"must be 'sha256:' + 64 hex digits, got {_show(value)}")
    if isinstance(cfg, ScenarioConfig):
        of = "scenario_config"
        check.equal("scenario", name, cfg.name, f"{of}.name")
        check.equal("agents", agents, cfg.uav.count, f"{of}.uav.count")
        check.equal("dt_s", dt_s, cfg.dt_s, f"{of}.dt_s")
        check.equal("speed_m_s", speed, cfg.uav.speed_m_s, f"{of}.uav.speed_m_s")
        check.equal("d_col_m", d_col, cfg.d_col_m, f"{of}.d_col_m")
        check.equal("action.max_turn_rad", turn, cfg.uav.max_turn_rad, f"{of}.uav.max_turn_rad")
        s = cfg.sensing
        for key, want, what in (
            ("max_obstacles", s.max_obstacles, "sensing.max_obstacles"),
            ("range_m", s.range_m, "sensing.range_m"),
            ("aperture_rad", s.aperture_rad, "sensing.aperture_rad"),
            ("speed_m_s", cfg.uav.speed_m_s, "uav.speed_m_s"),
        ):
            check.equal(f"observation.{key}", layout.get(key), want, f"{of}.{what}")
    return check.problems


def check_metadata(meta: object) -> dict[str, Any]:
    """``meta`` if it is valid metadata (`metadata_problems`); else raise `PolicySchemaError`."""
    problems = metadata_problems(meta)
    if problems:
        raise PolicySchemaError(problems)
    assert isinstance(meta, dict)
    return meta


# ---------------------------------------------------------------------------------- checksum


def canonical_json(value: object) -> bytes:
    """Canonical JSON bytes: sorted keys, no whitespace, ASCII, no NaN (raises ValueError)."""
    return json.dumps(
        value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False
    ).encode("ascii")


def policy_checksum(tensors: Mapping[str, NDArray[Any]], meta: Mapping[str, Any]) -> str:
    """``"sha256:<hex>"`` of a policy's tensors and metadata (the metadata's checksum excluded).

    SHA-256 over `CHECKSUM_DOMAIN`, then for each tensor in sorted name order a record
    ``len(h) h len(d) d`` (lengths as 8-byte little-endian) where ``h`` is the canonical JSON
    ``{"dtype": "<f4", "name": ..., "shape": [...]}`` (numpy dtype string, little-endian) and ``d``
    the raw little-endian bytes in C order; then the record ``len(m) m`` of the canonical JSON
    `canonical_json` of the metadata without `CHECKSUM_KEY`.
    """
    h = hashlib.sha256(CHECKSUM_DOMAIN)

    def record(data: bytes | memoryview) -> None:
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)

    for name in sorted(tensors):
        arr = np.asarray(tensors[name])
        arr = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<"))
        record(canonical_json({"dtype": arr.dtype.str, "name": name, "shape": list(arr.shape)}))
        record(arr.reshape(-1).view(np.uint8).data)
    record(canonical_json({k: v for k, v in meta.items() if k != CHECKSUM_KEY}))
    return CHECKSUM_PREFIX + h.hexdigest()


def check_checksum(tensors: Mapping[str, NDArray[Any]], meta: Mapping[str, Any]) -> None:
    """Raise `PolicyUnsignedError` without a checksum, `PolicyChecksumError` on a mismatch."""
    if CHECKSUM_KEY not in meta:
        raise PolicyUnsignedError([Problem(CHECKSUM_KEY, "missing")])
    actual = policy_checksum(tensors, meta)
    if meta[CHECKSUM_KEY] != actual:
        raise PolicyChecksumError(str(meta[CHECKSUM_KEY]), actual)


# ----------------------------------------------------------------------------------- tensors


def expected_shapes(meta: Mapping[str, Any]) -> dict[str, tuple[int, ...]]:
    """Tensor name → shape that valid metadata implies (actor and critic)."""
    a = 1 if meta["shared"] else int(meta["agents"])
    d, h = int(meta["observation"]["size"]), int(meta["hidden"])
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
    problems = [
        Problem(name, "unexpected tensor (this remarl-fc reads actor.* and critic.* only)")
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
    "POLICY_SCHEMA",
    "WEIGHT_BOUND",
    "PolicyChecksumError",
    "PolicyFileError",
    "PolicyFormatError",
    "PolicySchemaError",
    "PolicyTensorError",
    "PolicyUnsignedError",
    "PolicyWeightsError",
    "Problem",
    "check_checksum",
    "check_metadata",
    "check_tensors",
    "metadata_problems",
    "parse_metadata",
    "policy_checksum",
    "scenario_config",
    "sign_policy",
    "verify_policy",
]
