"""Scenarios as data: TOML files under ``sim/scenarios/``, resolved by name or path.

A scenario file sets what differs from the defaults of `sim.config`; every key it writes is
checked against the dataclass field of the same name (angles are written in degrees, with keys
ending in ``_deg``; they are stored in radians, in the field ending in ``_rad``). A typo'd key,
a wrong type or an out-of-range value is a `ScenarioError` that names the file and the key.

Example file::

    description = "3 UAVs, 2 obstacles (paper, Table 2)"

    [uav]
    count = 3
    formation = "wedge"

    [obstacles]
    count = 2

Per-UAV starts and targets (``[uav] starts_m``, ``targets_m``: lists of [x, y]) replace the
formation and the target line; ``[[intruders]]`` tables place the obstacles by their
encounter geometry (`sim.config.IntruderConfig`) instead of the random spawn line::

    [uav]
    count = 1
    starts_m = [[50.0, 150.0]]
    targets_m = [[270.0, 150.0]]

    [[intruders]]         # head-on, passing 5 m to the left, 12 s from the start
    crossing_deg = 180
    speed_m_s = 10.0
    miss_m = 5.0
    tcpa_s = 12.0
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from importlib import resources
from pathlib import Path
from typing import Any, get_args, get_origin, get_type_hints

import numpy as np

from sim.config import FieldValueError, IntruderConfig, ScenarioConfig
from sim.dynamics import longest_delay_s
from sim.errors import ConfigError, ScenarioError
from sim.spawn import (
    SPAWN_SPACING_FACTOR,
    group_index,
    min_pairwise_distance,
    swarm_layout,
    target_spacing_problem,
)
from sim.vehicle import load_profile

SECTIONS: dict[str, type[Any]] = {
    name: hint
    for name, hint in get_type_hints(ScenarioConfig).items()
    if isinstance(hint, type) and dataclasses.is_dataclass(hint)
}
"""Scenario file sections and the dataclass each one fills: the dataclass fields of
`ScenarioConfig` (``uav``, ``obstacles``, ``sensing``, ``field``, ``reward``, ``pso``)."""

_RAD, _DEG = "_rad", "_deg"


REAL_WORLD: dict[str, Any] = {
    "dynamics": "arducopter",
    "dynamics_randomisation": {
        "profiles": ["arducopter", "px4"],
        "delay_scale": [0.7, 1.5],
        "velocity_tau_scale": [0.8, 1.5],
        "max_accel_scale": [0.8, 1.25],
    },
    "sensors": {"model": "adsb"},
}
"""Scenario overrides of the world as flown (`load_scenario(name, **REAL_WORLD)`): each UAV
ArduCopter's or PX4's fitted response (`sim.vehicle`), scaled per parameter by factors drawn per
episode, intruders through ADS-B, GPS noise. What the robust and generalist policies train on
(``policies/zoo/robust/3u2o.toml`` spells it out) and ``bench sim``'s "real" world. Only read:
callers copy it."""


def scenario_names() -> list[str]:
    """Names of the scenarios shipped with the package, sorted by UAV then obstacle count."""
    names = [
        p.name.removesuffix(".toml")
        for p in resources.files("sim").joinpath("scenarios").iterdir()
        if p.name.endswith(".toml")
    ]
    return sorted(names, key=_natural_key)


def _natural_key(name: str) -> tuple[int, int, str]:
    head, _, tail = name.partition("u")
    try:
        return (int(head), int(tail.rstrip("o")), name)
    except ValueError:
        return (10**9, 0, name)


def load_scenario(name_or_path: str | Path, **overrides: Any) -> ScenarioConfig:
    """Resolve a scenario by shipped name (e.g. "3u2o") or by the path of a TOML file.

    Args:
        name_or_path: a shipped scenario name, or a path to a ``.toml`` file.
        **overrides: values that replace the file's, as nested dicts per section
            (``reward={"external": "gradient"}``) or top-level keys (``max_steps=60``).

    Raises:
        ScenarioError: unknown name, unreadable file, bad key, type or value.
    """
    text, source, name = _read(name_or_path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"not valid TOML ({exc})", source=source) from exc
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    return scenario_from_dict(data, name=name, source=source)


def _read(name_or_path: str | Path) -> tuple[str, str, str]:
    text_name = str(name_or_path)
    looks_like_path = (
        isinstance(name_or_path, Path) or text_name.endswith(".toml") or "/" in text_name
    )
    if looks_like_path:
        path = Path(name_or_path)
        try:
            return path.read_text(encoding="utf-8"), str(path), path.stem
        except OSError as exc:
            raise ScenarioError(
                f"cannot read scenario file ({exc.strerror or exc})", source=str(path)
            ) from exc
    known = scenario_names()
    if text_name.lower() not in known:
        raise ScenarioError(
            f"unknown scenario; known scenarios: {', '.join(known)} "
            "(or pass the path of a .toml file)",
            source=text_name,
        )
    res = resources.files("sim").joinpath("scenarios").joinpath(f"{text_name.lower()}.toml")
    return res.read_text(encoding="utf-8"), f"scenario {text_name.lower()}", text_name.lower()


def scenario_from_dict(data: dict[str, Any], *, name: str, source: str) -> ScenarioConfig:
    """Build and validate a `ScenarioConfig` from parsed TOML (see module docstring)."""
    data = dict(data)
    intruders = _intruders(data.pop("intruders", []), source)
    if intruders and isinstance(data.get("obstacles", {}), dict):
        data["obstacles"] = {"count": len(intruders), **data.get("obstacles", {})}
    sections: dict[str, Any] = {"intruders": intruders}
    for section, cls in SECTIONS.items():
        raw = data.pop(section, {})
        if not isinstance(raw, dict):
            raise ScenarioError("must be a table ([section])", source=source, key=section)
        sections[section] = _build(cls, raw, prefix=f"{section}.", source=source)
    top: ScenarioConfig = _build(
        ScenarioConfig,
        {"name": data.pop("name", name), **data},
        prefix="",
        source=source,
        skip={*SECTIONS, "intruders"},
        extra=sections,
    )
    _check_geometry(top, source)
    _check_dynamics(top, source)
    return top


def _check_dynamics(cfg: ScenarioConfig, source: str) -> None:
    named = [("dynamics", cfg.dynamics)]
    named += [("dynamics_randomisation.profiles", p) for p in cfg.dynamics_randomisation.profiles]
    for key, name in named:
        try:
            load_profile(name)
        except ConfigError as exc:
            raise ScenarioError(str(exc), source=source, key=key) from exc
    if longest_delay_s(cfg) >= cfg.dt_s:
        raise ScenarioError(
            f"the longest vehicle delay it can draw, {longest_delay_s(cfg):.2f} s, reaches the "
            f"decision step dt_s = {cfg.dt_s} s; lower it",
            source=source,
            key="dynamics_randomisation.delay_scale",
        )


def _intruders(raw: Any, source: str) -> tuple[IntruderConfig, ...]:
    if not isinstance(raw, list) or not all(isinstance(t, dict) for t in raw):
        raise ScenarioError(
            "must be an array of tables ([[intruders]])", source=source, key="intruders"
        )
    return tuple(
        _build(IntruderConfig, t, prefix=f"intruders[{k}].", source=source)
        for k, t in enumerate(raw)
    )


def _build(
    cls: type[Any],
    raw: dict[str, Any],
    *,
    prefix: str,
    source: str,
    skip: set[str] | None = None,
    extra: dict[str, Any] | None = None,
) -> Any:
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name not in (skip or set())}
    kwargs: dict[str, Any] = dict(extra or {})
    for key, value in raw.items():
        fname = key[: -len(_DEG)] + _RAD if key.endswith(_DEG) else key
        if fname not in fields or key.endswith(_RAD):
            allowed = sorted(_file_key(f) for f in fields)
            raise ScenarioError(
                f"unknown key; allowed here: {', '.join(allowed)}", source=source, key=prefix + key
            )
        kwargs[fname] = _convert(value, hints[fname], source=source, key=prefix + key)
        if key.endswith(_DEG):
            kwargs[fname] = math.radians(kwargs[fname])
    missing = [
        f
        for f, spec in fields.items()
        if f not in kwargs
        and spec.default is dataclasses.MISSING
        and spec.default_factory is dataclasses.MISSING
    ]
    if missing:
        raise ScenarioError("required key is missing", source=source, key=prefix + missing[0])
    try:
        return cls(**kwargs)
    except FieldValueError as exc:
        key = exc.field if "." in exc.field else prefix + _file_key(exc.field)
        raise ScenarioError(exc.reason, source=source, key=key) from exc


def _file_key(field_name: str) -> str:
    return field_name[: -len(_RAD)] + _DEG if field_name.endswith(_RAD) else field_name


def _convert(value: Any, hint: Any, *, source: str, key: str) -> Any:
    origin = get_origin(hint)
    if hint is bool:
        if not isinstance(value, bool):
            raise ScenarioError(f"must be true or false, got {value!r}", source=source, key=key)
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ScenarioError(f"must be a number, got {value!r}", source=source, key=key)
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(f"must be an integer, got {value!r}", source=source, key=key)
        return value
    if hint is str or origin is typing.Literal:
        if not isinstance(value, str):
            raise ScenarioError(f"must be a string, got {value!r}", source=source, key=key)
        return value
    if origin is tuple and get_args(hint)[-1:] == (Ellipsis,):
        if not isinstance(value, list):
            raise ScenarioError(f"must be a list, got {value!r}", source=source, key=key)
        item = get_args(hint)[0]
        return tuple(
            _convert(v, item, source=source, key=f"{key}[{k}]") for k, v in enumerate(value)
        )
    if origin is tuple:
        args = get_args(hint)
        if not isinstance(value, list) or len(value) != len(args):
            raise ScenarioError(
                f"must be a list of {len(args)} numbers, got {value!r}", source=source, key=key
            )
        return tuple(
            _convert(v, a, source=source, key=key) for v, a in zip(value, args, strict=True)
        )
    if isinstance(hint, types.UnionType):  # pragma: no cover - no optional fields yet
        return value
    raise ScenarioError(f"cannot be set from a scenario file ({hint})", source=source, key=key)


def _check_geometry(cfg: ScenarioConfig, source: str) -> None:
    layout = swarm_layout(cfg)
    need = SPAWN_SPACING_FACTOR * cfg.d_col_m
    closest = min_pairwise_distance(layout.positions_m)
    if closest < need:
        raise ScenarioError(
            f"UAVs spawn {closest:.1f} m apart, below {SPAWN_SPACING_FACTOR}·d_col = {need:.1f} m; "
            "raise uav.spacing_m or change uav.formation",
            source=source,
            key="uav.spacing_m",
        )
    problem = target_spacing_problem(layout.targets_m, cfg.d_col_m)
    if problem is not None:
        key = "uav.targets_m" if cfg.uav.targets_m else "uav.target_layout"
        hint = "" if cfg.uav.targets_m else ' (target_layout = "formation" keeps the spawn spacing)'
        raise ScenarioError(problem + hint, source=source, key=key)
    pos = layout.positions_m
    inside = (
        (pos[:, 0] >= 0)
        & (pos[:, 0] <= cfg.arena_length_m)
        & (pos[:, 1] >= 0)
        & (pos[:, 1] <= cfg.arena_width_m)
    )
    if not inside.all():
        raise ScenarioError(
            "the spawn formation does not fit in the arena; move uav.center_m, reduce "
            "uav.spacing_m or enlarge arena_length_m/arena_width_m",
            source=source,
            key="uav.center_m",
        )
    own_centre = layout.centre_m[group_index(cfg.uav)]  # (N, 2): each UAV's swarm's p*
    reach = float(np.hypot(*(layout.positions_m - own_centre).T).max())
    if reach >= cfg.field.swarm_range_m:
        raise ScenarioError(
            f"a UAV spawns {reach:.0f} m from its virtual centre, outside the swarm field "
            f"(R_s = {cfg.field.swarm_range_m:.0f} m), so it has no contour; raise "
            "field.swarm_range_m",
            source=source,
            key="field.swarm_range_m",
        )
    o = cfg.obstacles
    half = (o.count - 1) / 2 * o.spacing_m + o.lateral_jitter_m
    if (
        o.count
        and not cfg.intruders
        and not (
            0 <= o.spawn_x_m <= cfg.arena_length_m
            and o.center_y_m - half >= 0
            and o.center_y_m + half <= cfg.arena_width_m
        )
    ):
        raise ScenarioError(
            "obstacles can spawn outside the arena; move obstacles.spawn_x_m/center_y_m or "
            "reduce obstacles.spacing_m/lateral_jitter_m",
            source=source,
            key="obstacles.spawn_x_m",
        )
