"""Mission files for ``remarl-fc fly``: who flies which policy slot, where to, from which origin.

A mission is a TOML file::

    speed_m_s = 10.0          # must equal the policy's UAV speed
    dt_s = 2.0                # optional; must equal the policy's decision step

    [origin]                  # the shared local frame: north/east metres from here
    lat_deg = 47.397742
    lon_deg = 8.545594
    alt_m = 488.0             # AMSL of the ground at the origin

    [geofence]                # optional: hold a vehicle about to leave it
    radius_m = 600.0          # around the origin (and/or polygon_ne_m = [[n, e], ...])
    max_alt_m = 60.0          # above the origin

    [traffic]                 # optional: ADS-B receivers trusted beside the vehicles' own
    adsb_sources = ["200:156"]   # "SYSTEM_ID:COMPONENT_ID" of each
    epu_m = 10.0                 # optional: the reports' 95 % position error and
    nacv_m_s = 1.0               #   velocity error the track filter assumes (--track-filter on)

    [[vehicle]]
    system_id = 1
    slot = 0                  # the policy agent that flies it
    target = { north_m = 150.0, east_m = 270.0 }   # or { lat_deg = ..., lon_deg = ... }
    alt_m = 20.0              # cruise height above the origin
    group = 0                 # optional: the swarm it flies with (0, 1, …; default 0)

Vehicles of one ``group`` share a virtual centre p*, ahead of them on their common course; a
mission of two swarms whose routes cross, or of vehicles on unrelated routes, gives each its own
group (`sim.config.UAVConfig.groups`). Groups are numbered 0, 1, … without gaps.

Every error names the file and the key and says what is expected. A mission must be
consistent with itself: every target inside its own geofence, every ``alt_m`` under its ceiling.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.errors import ConfigError, PolicyError, PolicySpecMismatch
from remarl_fc.frames import GeoPoint, geodetic_to_ned, heading_to_yaw, sim_to_ne
from sim.config import ScenarioConfig, SensorConfig, groups_problem
from sim.spawn import EpisodeStart, group_index, swarm_layout, target_spacing_problem

FloatArray = NDArray[np.float64]

DEFAULT_ALT_M = 20.0
"""Cruise height above the origin when a vehicle gives none, metres."""

MAX_FILE_BYTES = 1_000_000
"""A mission file larger than this is refused unread (a mission is a few kilobytes)."""

MAX_NESTING = 8
"""Tables and arrays nested deeper than this are refused (a mission nests three deep)."""


class MissionError(ConfigError):
    """A mission file that cannot be flown.

    Attributes:
        source: the file; key: the offending key ("" for the whole file).
    """

    def __init__(self, message: str, *, source: str, key: str = "") -> None:
        where = f"{source}: {key}: " if key else f"{source}: "
        super().__init__(where + message)
        self.source, self.key = source, key


class VehicleCountMismatch(PolicySpecMismatch):
    """A mission with more or fewer vehicles than the policy flies; the message says what to do.

    Attributes:
        field: "number of vehicles". expected: the policy's N, or its (fewest, most) for a
            generalist. actual: the mission's vehicles. uav_range: (fewest, most).
    """

    def __init__(self, source: str, uav_range: tuple[int, int], vehicles: int) -> None:
        lo, hi = uav_range
        if lo == hi:
            flies = f"this policy flies {lo} vehicle{'s' * (lo != 1)}"
            fix = f"use a generalist policy (--policy generalist) or a mission of {lo}"
        else:
            flies = f"this policy flies {lo} to {hi} vehicles"
            fix = (
                f"split it into missions of at most {hi}"
                if vehicles > hi
                else f"give it at least {lo}"
            )
        what = f"{flies}; the mission has {vehicles}: {fix}"
        PolicyError.__init__(self, f"number of vehicles: {what}", source=source)
        self.field = "number of vehicles"
        self.expected = lo if lo == hi else uav_range
        self.actual = vehicles
        self.uav_range = uav_range


@dataclass(frozen=True)
class VehiclePlan:
    """One vehicle of a mission.

    Attributes:
        system_id: its MAVLink system id. slot: the policy agent index that flies it.
        target_ne_m: (2,) target, north/east metres from the origin.
        alt_m: cruise height above the origin.
        group: the swarm it flies with (its virtual centre is its swarm's).
    """

    system_id: int
    slot: int
    target_ne_m: tuple[float, float]
    alt_m: float
    group: int = 0


@dataclass(frozen=True)
class Geofence:
    """Where the swarm may fly: a circle around the origin and/or a polygon, and a ceiling."""

    radius_m: float | None = None
    polygon_ne_m: tuple[tuple[float, float], ...] | None = None
    max_alt_m: float | None = None

    def inside(self, ne_m: FloatArray, alt_m: float | None = None) -> bool:
        """Whether a point (north, east) metres from the origin is inside the fence."""
        n, e = float(ne_m[0]), float(ne_m[1])
        if self.radius_m is not None and math.hypot(n, e) > self.radius_m:
            return False
        if self.max_alt_m is not None and alt_m is not None and alt_m > self.max_alt_m:
            return False
        if self.polygon_ne_m is not None:
            inside = False
            pts = self.polygon_ne_m
            for (n1, e1), (n2, e2) in zip(pts, pts[1:] + pts[:1], strict=True):
                if (e1 > e) != (e2 > e) and n < (n2 - n1) * (e - e1) / (e2 - e1) + n1:
                    inside = not inside
            return inside
        return True


@dataclass(frozen=True)
class Mission:
    """A whole mission (see the module docstring)."""

    origin: GeoPoint
    speed_m_s: float
    vehicles: tuple[VehiclePlan, ...]
    dt_s: float | None = None
    geofence: Geofence | None = None
    source: str = "<mission>"
    adsb_sources: frozenset[tuple[int, int]] = frozenset()
    """(system id, component id) of ADS-B receivers trusted beside the vehicles' own."""
    adsb_epu_m: float | None = None
    """The 95 % position error of the ADS-B reports the track filter assumes, m (None: the
    middle of `sim.config.SensorConfig.adsb_epu_m`)."""
    adsb_nacv_m_s: float | None = None
    """The 95 % velocity error of the reports the track filter assumes, m/s (None:
    `sim.config.SensorConfig.adsb_nacv_m_s`)."""

    def sensors(self) -> SensorConfig:
        """The ADS-B model the track filter assumes for this mission (`sim.sensors.TrackNoise`)."""
        base = SensorConfig()
        epu = base.adsb_epu_m if self.adsb_epu_m is None else (self.adsb_epu_m,) * 2
        nacv = base.adsb_nacv_m_s if self.adsb_nacv_m_s is None else self.adsb_nacv_m_s
        return dataclasses.replace(base, adsb_epu_m=epu, adsb_nacv_m_s=nacv)

    def by_slot(self) -> list[VehiclePlan]:
        """The vehicles ordered by policy slot."""
        return sorted(self.vehicles, key=lambda v: v.slot)

    def targets_ne_m(self) -> FloatArray:
        """(N, 2) targets in slot order."""
        return np.array([v.target_ne_m for v in self.by_slot()], dtype=np.float64)

    def groups(self) -> tuple[int, ...]:
        """(N,) the swarm of each vehicle, in slot order."""
        return tuple(v.group for v in self.by_slot())

    def check_policy(
        self, uavs: int | tuple[int, int], speed_m_s: float, dt_s: float, d_col_m: float
    ) -> None:
        """Refuse a mission that does not fit the policy; the error names the value.

        Args:
            uavs: the vehicles the policy flies: N, or (fewest, most) (`Policy.uav_range`:
                (N, N) for a version-1 policy, (1, 50) for a generalist).

        Raises:
            VehicleCountMismatch: the mission's vehicle count is outside ``uavs`` (a
                `PolicySpecMismatch`, as is a speed or dt that differs from the policy's).
            MissionError: slots other than 0..N−1 one each; targets closer together than the
                policy's d_col plus a margin (`sim.spawn.target_spacing_problem`): arrived
                vehicles hold at their targets.
        """
        lo, hi = (uavs, uavs) if isinstance(uavs, int) else uavs
        n = len(self.vehicles)
        if not lo <= n <= hi:
            raise VehicleCountMismatch(self.source, (lo, hi), n)
        checks = [("speed_m_s", speed_m_s, self.speed_m_s)]
        if self.dt_s is not None:
            checks.append(("dt_s", dt_s, self.dt_s))
        for name, expected, actual in checks:
            if not math.isclose(float(expected), float(actual)):
                raise PolicySpecMismatch(self.source, name, expected, actual)
        slots = sorted(v.slot for v in self.vehicles)
        if slots != list(range(n)):
            raise MissionError(
                f"vehicle slots are {slots}; {n} vehicles take slots 0..{n - 1}, one each",
                source=self.source,
                key="vehicle.slot",
            )
        problem = target_spacing_problem(self.targets_ne_m(), d_col_m)
        if problem is not None:
            raise MissionError(problem, source=self.source, key="vehicle.target")

    @classmethod
    def from_scenario(
        cls,
        cfg: ScenarioConfig,
        origin: GeoPoint,
        alt_m: float = DEFAULT_ALT_M,
        *,
        episode: EpisodeStart | None = None,
    ) -> Mission:
        """The mission a scenario describes: its targets, from the arena origin, system ids 1..N.

        The mock (`remarl-fc sitl --scenario`) places vehicle i at the scenario's spawn i with
        the same origin, so this mission flies the scenario on the mock. ``episode``: the
        targets of this episode (B = 1) instead of the scenario's layout (an encounter drawn
        by `sim.encounters`, which the mock flies given the same episode).
        """
        targets_m = swarm_layout(cfg).targets_m if episode is None else episode.target_m[0]
        targets = sim_to_ne(targets_m)
        plans = tuple(
            VehiclePlan(i + 1, i, (float(t[0]), float(t[1])), alt_m, int(g))
            for i, (t, g) in enumerate(zip(targets, group_index(cfg.uav), strict=True))
        )
        return cls(origin, cfg.uav.speed_m_s, plans, cfg.dt_s, None, f"scenario {cfg.name}")


def initial_yaw_rad(mission: Mission, positions_ne_m: FloatArray) -> FloatArray:
    """(N,) NED yaw from each vehicle's position toward its target (slot order)."""
    delta = mission.targets_ne_m() - positions_ne_m
    heading = np.arctan2(delta[:, 0], delta[:, 1])  # simulator heading: atan2(north, east)
    return heading_to_yaw(heading)


def load_mission(path: str | Path) -> Mission:
    """Read and validate a mission file.

    Raises:
        MissionError: the file is missing, not TOML, or a key is missing or wrong.
    """
    p = Path(path)
    src = str(p)
    try:
        if p.stat().st_size > MAX_FILE_BYTES:
            raise MissionError(
                f"larger than {MAX_FILE_BYTES:,} bytes: not a mission file", source=src
            )
        text = p.read_bytes().decode("utf-8")
        data = tomllib.loads(text)
    except OSError as exc:
        raise MissionError(f"cannot read the file ({exc.strerror})", source=src) from exc
    except UnicodeDecodeError as exc:
        raise MissionError(
            f"not UTF-8 text (byte {exc.start}): save it as UTF-8", source=src
        ) from exc
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise MissionError(f"not valid TOML ({exc})", source=src) from exc
    _check_nesting(data, src)
    return mission_from_dict(data, source=src)


def _check_nesting(value: Any, src: str, depth: int = 0) -> None:
    if depth > MAX_NESTING:
        raise MissionError(f"nested deeper than {MAX_NESTING} levels: not a mission", source=src)
    children = (
        value.values() if isinstance(value, dict) else value if isinstance(value, list) else ()
    )
    for child in children:
        _check_nesting(child, src, depth + 1)


def _number(
    table: dict[str, Any], key: str, src: str, prefix: str, *, positive: bool = False
) -> float:
    if key not in table:
        raise MissionError("missing", source=src, key=prefix + key)
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise MissionError(f"must be a number, got {value!r}", source=src, key=prefix + key)
    if positive and value <= 0:
        raise MissionError(f"must be > 0, got {value}", source=src, key=prefix + key)
    return float(value)


def _only(table: dict[str, Any], known: set[str], src: str, prefix: str) -> None:
    """Refuse keys a table does not take: a misspelt key must not be silently ignored."""
    for key in table:
        if key not in known:
            raise MissionError(
                f"unknown key; known: {', '.join(sorted(known))}", source=src, key=prefix + key
            )


def _table(data: dict[str, Any], key: str, src: str) -> dict[str, Any]:
    value = data.get(key)
    if not isinstance(value, dict):
        raise MissionError("missing or not a table ([" + key + "])", source=src, key=key)
    return value


def mission_from_dict(data: dict[str, Any], *, source: str) -> Mission:
    """Validate parsed TOML into a `Mission` (see the module docstring)."""
    known = {
        "speed_m_s", "dt_s", "origin", "geofence", "vehicle", "policy", "description", "traffic"
    }  # fmt: skip
    for key in data:
        if key not in known:
            raise MissionError(
                f"unknown key; known: {', '.join(sorted(known))}", source=source, key=key
            )
    o = _table(data, "origin", source)
    _only(o, {"lat_deg", "lon_deg", "alt_m"}, source, "origin.")
    try:
        origin = GeoPoint(
            _number(o, "lat_deg", source, "origin."),
            _number(o, "lon_deg", source, "origin."),
            _number(o, "alt_m", source, "origin."),
        )
    except ValueError as exc:
        if isinstance(exc, MissionError):
            raise
        raise MissionError(str(exc), source=source, key="origin") from exc
    speed = _number(data, "speed_m_s", source, "", positive=True)
    dt = _number(data, "dt_s", source, "", positive=True) if "dt_s" in data else None
    raw = data.get("vehicle")
    if not isinstance(raw, list) or not raw:
        raise MissionError("give at least one [[vehicle]] table", source=source, key="vehicle")
    plans = [_vehicle(v, k, origin, source) for k, v in enumerate(raw)]
    ids = [p.system_id for p in plans]
    if len(set(ids)) != len(ids):
        raise MissionError(f"system ids repeat: {ids}", source=source, key="vehicle.system_id")
    problem = groups_problem([p.group for p in plans], len(plans))
    if problem is not None:
        raise MissionError(problem, source=source, key="vehicle.group")
    fence = _geofence(data["geofence"], source) if "geofence" in data else None
    if fence is not None:
        for k, plan in enumerate(plans):
            if not fence.inside(np.array(plan.target_ne_m)):
                raise MissionError(
                    f"target {plan.target_ne_m} m (north, east) is outside the mission's own "
                    "geofence",
                    source=source,
                    key=f"vehicle[{k}].target",
                )
            if fence.max_alt_m is not None and plan.alt_m > fence.max_alt_m:
                raise MissionError(
                    f"{plan.alt_m:g} m is above the geofence ceiling max_alt_m "
                    f"{fence.max_alt_m:g} m",
                    source=source,
                    key=f"vehicle[{k}].alt_m",
                )
    traffic = data.get("traffic", {})
    adsb = _adsb_sources(traffic, source)
    epu, nacv = (
        _number(traffic, key, source, "traffic.", positive=True) if key in traffic else None
        for key in ("epu_m", "nacv_m_s")
    )
    return Mission(origin, speed, tuple(plans), dt, fence, source, adsb, epu, nacv)


def _adsb_sources(t: Any, src: str) -> frozenset[tuple[int, int]]:
    if not isinstance(t, dict):
        raise MissionError("must be a table", source=src, key="traffic")
    _only(t, {"adsb_sources", "epu_m", "nacv_m_s"}, src, "traffic.")
    raw = t.get("adsb_sources", [])
    out: set[tuple[int, int]] = set()
    bad = MissionError(
        'must be a list of "SYSTEM_ID:COMPONENT_ID" strings, e.g. ["200:156"] (1..255 each)',
        source=src,
        key="traffic.adsb_sources",
    )
    if not isinstance(raw, list):
        raise bad
    for item in raw:
        parts = item.split(":") if isinstance(item, str) else []
        if len(parts) != 2 or not all(p.isdigit() and 1 <= int(p) <= 255 for p in parts):
            raise bad
        out.add((int(parts[0]), int(parts[1])))
    return frozenset(out)


def _vehicle(v: Any, k: int, origin: GeoPoint, src: str) -> VehiclePlan:
    prefix = f"vehicle[{k}]."
    if not isinstance(v, dict):
        raise MissionError("must be a table", source=src, key=f"vehicle[{k}]")
    _only(v, {"system_id", "slot", "target", "alt_m", "group"}, src, prefix)
    sysid = _number(v, "system_id", src, prefix)
    slot = _number(v, "slot", src, prefix)
    group = _number(v, "group", src, prefix) if "group" in v else 0.0
    if group != int(group) or group < 0:
        raise MissionError(f"must be an integer ≥ 0, got {group}", source=src, key=prefix + "group")
    if sysid != int(sysid) or not 1 <= sysid <= 255:
        raise MissionError(
            f"must be an integer 1..255, got {sysid}", source=src, key=prefix + "system_id"
        )
    if slot != int(slot) or slot < 0:
        raise MissionError(f"must be an integer ≥ 0, got {slot}", source=src, key=prefix + "slot")
    target = v.get("target")
    if not isinstance(target, dict):
        raise MissionError(
            "missing: give { north_m, east_m } or { lat_deg, lon_deg }",
            source=src,
            key=prefix + "target",
        )
    _only(target, {"north_m", "east_m", "lat_deg", "lon_deg"}, src, prefix + "target.")
    if ("north_m" in target or "east_m" in target) and ("lat_deg" in target or "lon_deg" in target):
        raise MissionError(
            "give either north_m/east_m or lat_deg/lon_deg, not both",
            source=src,
            key=prefix + "target",
        )
    if "north_m" in target or "east_m" in target:
        ne = (
            _number(target, "north_m", src, prefix + "target."),
            _number(target, "east_m", src, prefix + "target."),
        )
    else:
        lat = _number(target, "lat_deg", src, prefix + "target.")
        lon = _number(target, "lon_deg", src, prefix + "target.")
        try:
            GeoPoint(lat, lon, origin.alt_m)
        except ValueError as exc:
            raise MissionError(str(exc), source=src, key=prefix + "target") from exc
        n, e, _ = geodetic_to_ned(lat, lon, origin.alt_m, origin)
        ne = (float(n), float(e))
    alt = _number(v, "alt_m", src, prefix, positive=True) if "alt_m" in v else DEFAULT_ALT_M
    return VehiclePlan(int(sysid), int(slot), ne, alt, int(group))


def _geofence(g: Any, src: str) -> Geofence:
    if not isinstance(g, dict):
        raise MissionError("must be a table", source=src, key="geofence")
    _only(g, {"radius_m", "polygon_ne_m", "max_alt_m"}, src, "geofence.")
    radius = _number(g, "radius_m", src, "geofence.", positive=True) if "radius_m" in g else None
    ceiling = _number(g, "max_alt_m", src, "geofence.", positive=True) if "max_alt_m" in g else None
    polygon = None
    if "polygon_ne_m" in g:
        pts = g["polygon_ne_m"]
        ok = (
            isinstance(pts, list)
            and len(pts) >= 3
            and all(
                isinstance(p, list)
                and len(p) == 2
                and all(
                    isinstance(c, int | float) and not isinstance(c, bool) and math.isfinite(c)
                    for c in p
                )
                for p in pts
            )
        )
        if not ok:
            raise MissionError(
                "must be a list of at least 3 [north, east] pairs",
                source=src,
                key="geofence.polygon_ne_m",
            )
        polygon = tuple((float(p[0]), float(p[1])) for p in pts)
    if radius is None and polygon is None and ceiling is None:
        raise MissionError("give radius_m, polygon_ne_m or max_alt_m", source=src, key="geofence")
    return Geofence(radius, polygon, ceiling)
