"""Encounters sampled from named distributions: the episodes of the benchmark suite.

A *distribution* (`DISTRIBUTIONS`) says what kind of traffic an episode meets — head-on,
crossing, overtaking, being overtaken, static obstacles, late pop-ups, dense traffic, two swarms
whose paths cross, converging, diverging or random paths — and draws every number of it from
uniform ranges. A *family* (`Family`) is a distribution with a swarm size, a formation and any
range changed; `sample_family` turns it into a scenario (`ScenarioConfig`, the constants) and
B episodes (`EpisodeStart`, the arrays the simulator starts from).

Every intruder is placed by its encounter with one UAV, the parametrisation of the MIT Lincoln
Laboratory encounter models for unmanned aircraft in the horizontal plane (`IntruderConfig`):
crossing angle, speed, miss distance at the closest point of approach (CPA) if nobody turned,
and time to that point; a late pop-up is hidden until it is ``appear_range_m`` from that UAV.

Episode k of a family is drawn from its own generator, seeded with (suite seed, the family's
name, k): the same episode whatever the batch, the worker or the other families of the suite.
An intruder that would start within ``START_CLEARANCE_FACTOR``·d_col of a UAV is drawn again
from the same generator (deterministically), at most `MAX_REDRAWS` times.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from sim.arrays import FloatArray
from sim.config import Arrival, ObstacleConfig, ScenarioConfig, UAVConfig
from sim.errors import ConfigError
from sim.spawn import (
    SPAWN_SPACING_FACTOR,
    EpisodeStart,
    appear_step,
    encounter_tracks,
    formation_offsets,
    group_index,
    spawn_episodes,
)

GENERATOR_VERSION = 2
"""Bumped whenever a change here, or in a shipped scenario a family is built on, draws
different episodes (cached oracle labels depend on it). 2: the grid scenarios' targets keep the
spawn formation (``target_layout = "formation"``)."""

SUITE_ARRIVAL: Arrival = "leave"
"""The arrival rule every family is flown with: the paper's (an arrived UAV leaves the
episode). The oracle's search plans each UAV up to its arrival only; until it also plans around
vehicles hovering where they arrived, the suite keeps the rule its labels prove solvable under.
A family's ``overrides`` may still set ``arrival``."""

Formation = Literal["line", "wedge", "grid", "random"]
FORMATIONS: tuple[Formation, ...] = ("line", "wedge", "grid", "random")

Paths = Literal["formation", "swarms", "converging", "diverging", "random"]
PATHS: tuple[Paths, ...] = ("formation", "swarms", "converging", "diverging", "random")

Range = tuple[float, float]

START_CLEARANCE_FACTOR = 2.0
"""No intruder starts closer than this many d_col to a UAV (a collision on the first step
says nothing about a controller)."""

MAX_REDRAWS = 200
"""Draws of one intruder before the family is declared impossible to sample (a ConfigError)."""

MAX_DARTS = 100_000
"""Random points tried when scattering UAVs apart from each other (formation "random", paths
"random") before the family is declared impossible to sample (a ConfigError)."""

RANDOM_SIDE_FACTOR = 2.2
"""Paths "random": the square is at least this many spawn gaps times √N wide, so N points
that keep the spawn gap fit with room (random sequential packing jams near 55% cover)."""

MAX_FAN_RAD = math.radians(75.0)
"""Paths "converging"/"diverging": the largest half-angle of the fan of routes."""

MIN_FAN_RAD = math.radians(30.0)
"""Paths "converging"/"diverging": the smallest half-angle of the fan of routes."""

STEP_LIMIT_FACTOR = 2.0
"""The step limit of a generated family: this many times the steps of its longest straight
route (at least the paper's 40): room for detours, not for loitering."""

STEP_LIMIT_PROBES = 16
"""Episodes drawn to find a generated family's longest route (see `family_scenario`)."""

PAPER_STEP_LIMIT = 40
"""The paper scenarios' step limit (`ScenarioConfig.max_steps`)."""


@dataclass(frozen=True)
class Encounter:
    """A named distribution of episodes: every range is uniform, angles in degrees.

    Swarm: ``paths`` says how starts and targets are laid out — "formation" (the swarm in
    ``formation`` flies ``route_m`` straight ahead), "swarms" (two halves in formation, their
    routes crossing at ``swarm_crossing_deg`` near mid-route), "converging" (from an arc of
    radius ``route_m`` to a grid of targets around one point), "diverging" (the reverse) or
    "random" (starts and targets anywhere in a square of side ``route_m``, each route at least
    half of it). Intruders: ``intruders`` of them, each against a random UAV.
    """

    paths: Paths = "formation"
    route_m: Range = (200.0, 260.0)
    """Length of each straight route (or the spread of the layout), metres."""

    spacing_m: float = 40.0
    """Formation spacing, metres (≥ 1.5·d_col)."""

    intruders: int = 1
    crossing_deg: Range = (180.0, 180.0)
    """Intruder course minus the UAV's, degrees; ``mirror`` flips the sign half of the time."""

    mirror: bool = True
    speed_m_s: Range = (5.0, 15.0)
    miss_m: Range = (-10.0, 10.0)
    """Signed miss distance at the CPA, metres (|miss| < d_col is a collision course)."""

    tcpa_fraction: Range = (0.35, 0.7)
    """Time to the CPA as a fraction of the UAV's straight flight time to its target."""

    appear_range_m: Range | None = None
    """Late pop-up: the intruder is hidden until this far from its UAV, metres (None: seen
    from the start)."""

    swarm_crossing_deg: Range = (60.0, 120.0)
    """Angle between the two swarms' routes ("swarms"), degrees, mirrored at random."""

    swarm_offset_m: Range = (-40.0, 40.0)
    """How far ahead along its route the second swarm starts ("swarms"), metres: 0 and both
    reach the crossing point together."""

    def __post_init__(self) -> None:
        if self.paths not in PATHS:
            raise ConfigError(f"paths must be one of {', '.join(PATHS)}, got {self.paths!r}")
        for name in ("route_m", "crossing_deg", "speed_m_s", "miss_m", "tcpa_fraction"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ConfigError(f"{name} must be [low, high] with low <= high, got {[lo, hi]}")
        if self.intruders < 0:
            raise ConfigError(f"intruders must be >= 0, got {self.intruders}")
        if self.speed_m_s[0] < 0 or self.route_m[0] <= 0 or self.tcpa_fraction[0] <= 0:
            raise ConfigError("speed_m_s must be >= 0, route_m and tcpa_fraction > 0")


DISTRIBUTIONS: dict[str, Encounter] = {
    "head-on": Encounter(crossing_deg=(170.0, 190.0), mirror=False),
    "crossing": Encounter(crossing_deg=(30.0, 150.0)),
    "overtaking": Encounter(crossing_deg=(-10.0, 10.0), speed_m_s=(2.0, 5.0), mirror=False),
    "overtaken": Encounter(crossing_deg=(-10.0, 10.0), speed_m_s=(14.0, 20.0), mirror=False),
    "static": Encounter(speed_m_s=(0.0, 0.0), miss_m=(-15.0, 15.0), intruders=2),
    "pop-up": Encounter(
        crossing_deg=(90.0, 270.0), mirror=False, appear_range_m=(50.0, 90.0), miss_m=(-5.0, 5.0)
    ),
    "dense": Encounter(crossing_deg=(0.0, 360.0), mirror=False, intruders=8, speed_m_s=(0.0, 15.0)),
    "swarms": Encounter(paths="swarms", intruders=0),
    "converging": Encounter(paths="converging", intruders=0, route_m=(180.0, 240.0)),
    "diverging": Encounter(paths="diverging", intruders=0, route_m=(180.0, 240.0)),
    "random-paths": Encounter(paths="random", intruders=0, route_m=(250.0, 350.0)),
}
"""The named distributions; a family starts from one and changes what it says."""


@dataclass(frozen=True)
class Family:
    """One family of the suite: a distribution of episodes, or a scenario file's own episodes.

    Attributes:
        name: unique in its suite; seeds its episodes.
        distribution: a key of `DISTRIBUTIONS`, or "scenario" for ``scenario``'s own spawn.
        uavs: N, 1 to 50.
        formation: "line", "wedge", "grid" or "random" (paths "formation" and "swarms").
        encounter: the distribution with the family's changes (None: the distribution's own).
        scenario: a shipped scenario name or .toml path ("scenario" families; the base of the
            others' constants: speed, turn limit, d_col, sensing).
        overrides: scenario overrides per section, as in a scenario file.
        description: one line for listings.
    """

    name: str
    distribution: str
    uavs: int = 3
    formation: Formation = "wedge"
    encounter: Encounter | None = None
    scenario: str = "3u2o"
    overrides: dict[str, Any] = dataclasses.field(default_factory=dict, hash=False)
    description: str = ""

    def __post_init__(self) -> None:
        if self.distribution != "scenario" and self.distribution not in DISTRIBUTIONS:
            known = ", ".join(["scenario", *DISTRIBUTIONS])
            raise ConfigError(f"family {self.name}: unknown distribution; known: {known}")
        if self.encounter is None and self.distribution != "scenario":
            object.__setattr__(self, "encounter", DISTRIBUTIONS[self.distribution])
        if not 1 <= self.uavs <= 50:
            raise ConfigError(f"family {self.name}: uavs must be 1 to 50, got {self.uavs}")
        if self.formation not in FORMATIONS:
            raise ConfigError(
                f"family {self.name}: formation must be one of {', '.join(FORMATIONS)}"
            )

    def parameters(self) -> dict[str, Any]:
        """Everything that decides the family's episodes, JSON-ready (listings and digests)."""
        out: dict[str, Any] = {"distribution": self.distribution, "scenario": self.scenario}
        if self.overrides:
            out["overrides"] = self.overrides
        if self.encounter is not None:
            out |= {"uavs": self.uavs, "formation": self.formation}
            out |= {k: _plain(v) for k, v in dataclasses.asdict(self.encounter).items()}
        return out


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def family_scenario(family: Family) -> ScenarioConfig:
    """The scenario (constants) of a family.

    A generated family's step limit is `STEP_LIMIT_FACTOR` times the steps of the longest
    route among `STEP_LIMIT_PROBES` episodes drawn from a fixed probe seed: a property of the
    family alone, whatever the suite seed or the episodes drawn.
    """
    from sim.scenarios import load_scenario

    base = load_scenario(family.scenario, **{"arrival": SUITE_ARRIVAL, **family.overrides})
    enc = family.encounter
    if enc is None:
        return dataclasses.replace(base, name=family.name)
    cfg = dataclasses.replace(
        base,
        name=family.name,
        description=family.description,
        uav=dataclasses.replace(
            base.uav,
            count=family.uavs,
            spacing_m=enc.spacing_m,
            starts_m=(),
            targets_m=(),
            groups=swarm_groups(enc.paths, family.uavs),
        ),
        obstacles=ObstacleConfig(count=enc.intruders),
        intruders=(),
    )
    longest = 0.0
    for k in range(STEP_LIMIT_PROBES):
        start, target = _swarm(family, enc, cfg, episode_rng(0, family.name, k))
        longest = max(longest, float(np.hypot(*(target - start).T).max()))
    steps = max(PAPER_STEP_LIMIT, math.ceil(STEP_LIMIT_FACTOR * longest / cfg.step_length_m))
    return dataclasses.replace(cfg, max_steps=steps)


def swarm_groups(paths: Paths, n: int) -> tuple[int, ...]:
    """The swarm of each of N UAVs on ``paths`` (`UAVConfig.groups`).

    "swarms": the first ⌈N/2⌉ UAVs form one swarm and the others the second; "random": every
    UAV flies alone (its own virtual centre, ahead of it on its route); the other paths: one
    swarm (one formation, or a fan whose routes share a direction).
    """
    if paths == "swarms":
        return (0,) * ((n + 1) // 2) + (1,) * (n // 2) if n > 1 else ()
    if paths == "random":
        return tuple(range(n)) if n > 1 else ()
    return ()


def episode_rng(seed: int, family: str, episode: int) -> np.random.Generator:
    """The generator of one episode: (suite seed, family name, episode index)."""
    return np.random.default_rng([seed, zlib.crc32(family.encode()), episode])


def sample_family(
    family: Family, seed: int, episodes: range | list[int]
) -> tuple[ScenarioConfig, EpisodeStart]:
    """The scenario of a family and the episodes with the given indices, in that order.

    Raises:
        ConfigError: the family cannot be drawn (e.g. its intruders always start on a UAV).
    """
    cfg = family_scenario(family)
    return cfg, draw_episodes(family, cfg, seed, episodes)


def draw_episodes(
    family: Family, cfg: ScenarioConfig, seed: int, episodes: range | list[int]
) -> EpisodeStart:
    """Episodes of a family whose scenario ``cfg`` (`family_scenario`) the caller holds.

    The same episodes as `sample_family`'s; a training run draws its stream from a seed of its
    own this way, without building the scenario again for every batch.
    """
    parts = [_episode(family, cfg, episode_rng(seed, family.name, k)) for k in episodes]
    return EpisodeStart.concat(parts)


def _episode(family: Family, cfg: ScenarioConfig, rng: np.random.Generator) -> EpisodeStart:
    if family.encounter is None:
        return spawn_episodes(cfg, rng, 1)
    enc, v = family.encounter, cfg.uav.speed_m_s
    start, target = _swarm(family, enc, cfg, rng)
    m = enc.intruders
    pos, vel, appear = np.zeros((m, 2)), np.zeros((m, 2)), np.zeros(m)
    todo = np.arange(m)
    for _ in range(MAX_REDRAWS):
        if todo.size == 0:
            break
        p, w, t = _intruders(enc, cfg, start, target, todo.size, rng)
        pos[todo], vel[todo], appear[todo] = p, w, t
        gap = np.linalg.norm(pos[todo, None] - start[None], axis=-1).min(axis=-1)
        todo = todo[gap <= START_CLEARANCE_FACTOR * cfg.d_col_m]  # drawn again
    if todo.size:
        raise ConfigError(f"family {family.name}: intruders keep starting on a UAV")
    return EpisodeStart.of_swarm(
        start[None],
        target[None],
        pos[None],
        vel[None],
        appear_step(appear, cfg.dt_s)[None],
        v,
        cfg.field.swarm_lead_m,
        group_index(cfg.uav),
    )


def _uniform(rng: np.random.Generator, r: Range, size: int | None = None) -> Any:
    return rng.uniform(r[0], r[1], size)


def _slots(
    formation: Formation, n: int, spacing_m: float, min_gap_m: float, rng: np.random.Generator
) -> FloatArray:
    """(N, 2) formation offsets, centred; "random": a disc, no two closer than ``min_gap_m``."""
    if formation != "random":
        rows = max(2, round(math.sqrt(n / 2)))  # a grid about twice as wide as deep
        uav = UAVConfig(count=n, formation=formation, spacing_m=spacing_m, rows=rows)
        return formation_offsets(uav)
    radius = spacing_m * (0.6 * math.sqrt(n) + 1.0)  # disc area ≈ 3.6× the N spacing squares

    def draw() -> FloatArray:
        r, a = radius * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
        return np.array([r * math.cos(a), r * math.sin(a)])

    out = _scatter(draw, n, min_gap_m)
    centred: FloatArray = out - out.mean(axis=0)
    return centred


def _scatter(
    draw: Any, n: int, min_gap_m: float, partner: FloatArray | None = None, min_leg_m: float = 0.0
) -> FloatArray:
    """N points from ``draw()``, no two closer than ``min_gap_m`` (dart throwing).

    With ``partner`` (N, 2), point k also lies at least ``min_leg_m`` from partner k.
    """
    points: list[FloatArray] = []
    for _ in range(MAX_DARTS):
        if len(points) == n:
            return np.asarray(points)
        p = draw()
        if partner is not None and np.hypot(*(p - partner[len(points)])) < min_leg_m:
            continue
        if all(np.hypot(*(p - q)) >= min_gap_m for q in points):
            points.append(p)
    if len(points) == n:
        return np.asarray(points)
    raise ConfigError(f"cannot place {n} UAVs {min_gap_m:.0f} m apart: give them more room")


def _spread(n: int, half_angle_rad: float) -> FloatArray:
    return np.linspace(-half_angle_rad, half_angle_rad, n) if n > 1 else np.zeros(1)


def _swarm(
    family: Family, enc: Encounter, cfg: ScenarioConfig, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray]:
    """(N, 2) starts and targets of one episode."""
    n = family.uavs
    gap = SPAWN_SPACING_FACTOR * cfg.d_col_m
    route = float(_uniform(rng, enc.route_m))
    if enc.paths == "formation":
        start = _slots(family.formation, n, enc.spacing_m, gap, rng)
        return start, start + np.array([route, 0.0])
    if enc.paths == "swarms":
        sizes = np.bincount(group_index(cfg.uav))  # the swarms' sizes (`swarm_groups`)
        angle = math.radians(_uniform(rng, enc.swarm_crossing_deg)) * rng.choice([-1.0, 1.0])
        starts, targets = [], []
        lead = float(_uniform(rng, enc.swarm_offset_m))
        groups = [_slots(family.formation, int(k), enc.spacing_m, gap, rng) for k in sizes]
        # Each swarm starts clear of the other: half a route beyond both formations' reach.
        reach = max(float(np.hypot(*g.T).max()) for g in groups)
        half = max(0.5 * route, 2 * reach + gap + abs(lead))
        for slots, course, ahead in zip(groups, (0.0, angle), (0.0, lead), strict=False):
            d = np.array([math.cos(course), math.sin(course)])
            rot = np.array([[d[0], -d[1]], [d[1], d[0]]])
            starts.append(slots @ rot.T + (ahead - half) * d)
            targets.append(slots @ rot.T + (ahead + half) * d)
        return np.concatenate(starts), np.concatenate(targets)
    if enc.paths in ("converging", "diverging"):
        # A fan of routes whose neighbours start (or end) at least the spawn gap apart.
        radius, step = route, 2 * math.asin(min(1.0, gap / (2 * route)))
        if n > 1 and (n - 1) * step / 2 > MAX_FAN_RAD:
            step = 2 * MAX_FAN_RAD / (n - 1)
            radius = gap / (2 * math.sin(step / 2))
        half = max((n - 1) * step / 2, MIN_FAN_RAD)
        angles = _spread(n, half)
        arc = radius * np.stack([-np.cos(angles), np.sin(angles)], axis=-1)
        tight = _slots("grid", n, gap, gap, rng)
        tight = tight[np.argsort(tight[:, 1], kind="stable")]  # across, in the arc's order
        if enc.paths == "converging":
            return arc, tight
        return tight, arc * np.array([-1.0, 1.0])
    side = max(route, RANDOM_SIDE_FACTOR * gap * math.sqrt(n))
    spots = _scatter(lambda: rng.uniform(0.0, side, 2), n, gap)
    goals = _scatter(lambda: rng.uniform(0.0, side, 2), n, gap, spots, side / 2)
    return spots, goals


def _intruders(
    enc: Encounter,
    cfg: ScenarioConfig,
    start: FloatArray,
    target: FloatArray,
    m: int,
    rng: np.random.Generator,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``m`` intruders, each against a random UAV: positions, velocities, appear times (s)."""
    v = cfg.uav.speed_m_s
    against = rng.integers(0, len(start), m)
    delta = target[against] - start[against]
    course = np.arctan2(delta[:, 1], delta[:, 0])
    flight_s = np.hypot(delta[:, 0], delta[:, 1]) / v
    crossing = np.radians(_uniform(rng, enc.crossing_deg, m))
    if enc.mirror:
        crossing *= rng.choice([-1.0, 1.0], m)
    speed = _uniform(rng, enc.speed_m_s, m)
    miss = _uniform(rng, enc.miss_m, m)
    tcpa = _uniform(rng, enc.tcpa_fraction, m) * flight_s
    pos, vel = encounter_tracks(start[against], course, v, crossing, speed, miss, tcpa)
    appear = np.zeros(m)
    if enc.appear_range_m is not None:
        seen_at = _uniform(rng, enc.appear_range_m, m)
        closing = np.linalg.norm(v * np.stack([np.cos(course), np.sin(course)], -1) - vel, axis=-1)
        ahead = np.sqrt(np.maximum(seen_at**2 - miss**2, 0.0)) / np.maximum(closing, 1e-9)
        appear = np.maximum(tcpa - ahead, 0.0)
    return pos, vel, appear
