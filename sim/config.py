"""Typed, frozen configuration of the simulator core.

Every default of the model lives here, once. Scenario files (``sim/scenarios/*.toml``) set the
values that differ per scenario (counts, geometry) and may override any other field; see
`sim.scenarios`. Angles are radians inside the code; scenario files write them in degrees
(keys ending in ``_deg``), converted once at load time.

Where the paper gives no number, the default is our choice; `docs/MODEL.md` gives the reason.
One module over the usual 400 lines (about 540) on purpose: every default in one place, each
with its unit and reason, is the point of it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

ExternalTerm = Literal["gradient", "level-edge"]
Formation = Literal["line", "wedge", "grid"]
TargetLayout = Literal["line", "formation"]

SWARM_FIELDS = ("all", "formation")
"""Which worlds of a mixture keep the swarm's peak (`FieldConfig.swarm_peak`): "all", or only
"formation" (the families that fly one formation)."""
TEACHERS = ("none", "orca-shield", "oracle", "self-shield")
"""What a generalist may learn from besides its reward: nothing, ORCA's actions through the
safety shield, the oracle replanned at every step, or the policy the run starts from through
the safety shield (`policies.config.GeneralistConfig.teacher`); here so that the command line
can list them without importing the training side."""
STATE_TEACHERS = ("orca-shield", "oracle")
"""The teachers that label from the simulator's state alone ("self-shield" needs the policy it
distils: `policies.generalist_train.RunBook.teach`)."""
SensorModel = Literal["exact", "adsb"]
Arrival = Literal["hover", "leave"]

EXTERNAL_TERMS: tuple[ExternalTerm, ...] = ("gradient", "level-edge")
FORMATIONS: tuple[Formation, ...] = ("line", "wedge", "grid")
TARGET_LAYOUTS: tuple[TargetLayout, ...] = ("line", "formation")
SENSOR_MODELS: tuple[SensorModel, ...] = ("exact", "adsb")
ARRIVALS: tuple[Arrival, ...] = ("hover", "leave")


class FieldValueError(ValueError):
    """A configuration field holds a bad value; ``field`` names it (for error messages)."""

    def __init__(self, field_name: str, message: str) -> None:
        super().__init__(f"{field_name}: {message}")
        self.field = field_name
        self.reason = message


def _require(ok: bool, field_name: str, message: str) -> None:
    if not ok:
        raise FieldValueError(field_name, message)


def groups_problem(groups: Sequence[int], count: int) -> str | None:
    """Why ``groups`` cannot give the swarm of each of ``count`` UAVs, or None.

    One index per UAV, integers numbering the swarms 0, 1, … without gaps (`UAVConfig.groups`,
    a mission's ``vehicle.group``).
    """
    if len(groups) != count:
        return f"must hold one swarm index per UAV ({count}), got {len(groups)}"
    integers = all(isinstance(g, int) and not isinstance(g, bool) for g in groups)
    if not integers or sorted(set(groups)) != list(range(max(groups) + 1)):
        return f"must number the swarms 0, 1, … without gaps, got {list(groups)}"
    return None


def _positive(obj: object, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        _require(math.isfinite(value) and value > 0, name, f"must be > 0, got {value!r}")


def _non_negative(obj: object, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        _require(math.isfinite(value) and value >= 0, name, f"must be >= 0, got {value!r}")


def _integer(obj: object, *names: str, minimum: int = 1) -> None:
    for name in names:
        value = getattr(obj, name)
        _require(
            isinstance(value, int) and value >= minimum,
            name,
            f"must be an integer >= {minimum}, got {value!r}",
        )


@dataclass(frozen=True)
class FieldConfig:
    """Potential field Φ = Φ_s + Σ Φ_o (paper Eq. obstaclefield, swarmfield, environmentfield)."""

    d_safe_m: float = 30.0
    """d_safe: radius of the plateau of each obstacle's field, metres (Eq. obstaclefield).

    1.5·d_col, so the field's strongest edge (at d_safe) lies outside the collision distance."""

    obstacle_range_m: float = 100.0
    """R_o: influence range of an obstacle's field, metres (Eq. obstaclefield); = sensing range."""

    swarm_range_m: float = 200.0
    """R_s: influence range of the swarm's field around p*, metres (Eq. swarmfield).

    Large enough that every UAV of the spawn formation lies inside it, so each has a contour."""

    swarm_floor_m: float = 5.0
    """Distance floor of Φ_s = v_s / max(d, floor)², metres (the paper leaves it unbounded)."""

    swarm_lead_m: float = 40.0
    """Distance of the virtual centre p* ahead of the swarm's foremost UAV, metres (p* lies on
    the line through the centroid along the swarm velocity)."""

    swarm_peak: bool = True
    """Whether Φ holds the swarms' peaks Φ_s at all. False: Φ = Σ Φ_o, a training choice for
    UAVs that fly no common formation (`GeneralistConfig.swarm_field`). Several swarms
    (`UAVConfig.groups`) each have their own peak at their own p*; see docs/MODEL.md §15, §20."""

    continuous: bool = True
    """Shift each source's field down by its value at its range (I/R²), so Φ is continuous and
    reaches 0 at R instead of jumping there; ∇Φ is unchanged. False: the paper's literal cut."""

    def __post_init__(self) -> None:
        _positive(self, "d_safe_m", "obstacle_range_m", "swarm_range_m", "swarm_floor_m")
        _non_negative(self, "swarm_lead_m")
        _require(
            self.d_safe_m < self.obstacle_range_m,
            "d_safe_m",
            f"must be < obstacle_range_m ({self.obstacle_range_m}), got {self.d_safe_m}",
        )
        _require(
            self.swarm_floor_m < self.swarm_range_m,
            "swarm_floor_m",
            f"must be < swarm_range_m ({self.swarm_range_m}), got {self.swarm_floor_m}",
        )


@dataclass(frozen=True)
class RewardConfig:
    """reMARL reward r = −f(S, Φ) + r_form·r_collide (paper Eq. reward and fitness).

    Both contour terms are non-dimensional and lie in [0, 1] per step, so the weights say how
    much each matters against the Swarming part (also in [0, 1] per step).
    """

    window_steps: int = 3
    """K: decision steps in the contour window S, including the arc of the action just taken."""

    external: ExternalTerm = "level-edge"
    """External (image) energy: "level-edge" (edge of the UAV's own level set Φ = φ_i, as in the
    active-contour method the paper builds on) or "gradient" (the paper's literal ½|∇Φ|²)."""

    quadrature_intervals: int = 4
    """Q: intervals of the trapezoid rule for the external term along each arc (5 m apart at the
    defaults, half the edge width σ). Must divide `ScenarioConfig.substeps`: the rule uses
    every (T/Q)-th sub-step point of the arc."""

    edge_width_m: float = 10.0
    """σ of the level edge exp(−s²/σ²), s the signed distance to the level set, metres."""

    w_internal: float = 1.0
    """Weight of the internal term mean((a/a_max)²) over the window (Eq. fitness, ½|S''|²)."""

    w_external: float = 1.0
    """Weight of the external term mean(e(S)) ∈ [0, 1] over the window (Eq. fitness, ½|∇Φ|²)."""

    def __post_init__(self) -> None:
        _integer(self, "window_steps", "quadrature_intervals")
        _require(
            self.external in EXTERNAL_TERMS,
            "external",
            f"must be one of {', '.join(EXTERNAL_TERMS)}, got {self.external!r}",
        )
        _positive(self, "edge_width_m")
        _non_negative(self, "w_internal", "w_external")


@dataclass(frozen=True)
class PSOConfig:
    """Contour-level separation by particle swarm optimisation (paper Eq. psocost, pso)."""

    threshold_m: float = 30.0
    """d̄_U2U: minimum distance between adjusted UAV positions, metres (Eq. psocost; the paper
    writes d_U2O, the text means UAV–UAV). 1.5·d_col, the spawn spacing guarantee."""

    particles: int = 20
    """Number of particles, each a candidate position for all N UAVs (2N numbers)."""

    iterations: int = 10
    """Cost evaluations per particle, the first on the initial particles: 200 per call by
    default. Seeded with a constructive repair, this finds smaller shifts than the authors'
    unseeded 6,000 (100 particles × 30 iterations, every particle evaluated twice) — see
    `docs/MODEL.md` — and keeps the simulator fast when many environments need it at once."""

    c1: float = 1.5
    """Cognitive acceleration coefficient c_1 (Eq. pso)."""

    c2: float = 1.5
    """Social acceleration coefficient c_2 (Eq. pso)."""

    init_noise_m: float = 2.0
    """Standard deviation of the zero-mean noise added to the current positions to start the
    particles, metres (the authors' noise had a +20 m bias)."""

    init_speed_m: float = 10.0
    """Standard deviation of the particles' zero-mean initial velocities, metres per iteration:
    the exploration radius of the first iterations (a zero start never leaves the start)."""

    def __post_init__(self) -> None:
        _positive(self, "threshold_m")
        _non_negative(self, "c1", "c2", "init_noise_m", "init_speed_m")
        _integer(self, "particles", "iterations")

    @property
    def evaluations(self) -> int:
        """Cost evaluations per call and environment."""
        return self.particles * self.iterations


@dataclass(frozen=True)
class UAVConfig:
    """The swarm: count, speed, turn limit, spawn formation and targets."""

    count: int
    """N, number of UAVs."""

    speed_m_s: float = 10.0
    """v_s, constant airspeed of every UAV, m/s."""

    max_turn_rad: float = math.pi / 4
    """a_max: largest heading change over one decision step, rad (the paper's [−π/4, π/4])."""

    formation: Formation = "wedge"
    """Spawn layout: "line" (line abreast), "wedge" (apex forward) or "grid" (rows)."""

    spacing_m: float = 40.0
    """Distance between neighbours in the spawn formation, metres (must be ≥ 1.5·d_col)."""

    rows: int = 2
    """Number of rows (across the flight direction) of the "grid" formation."""

    center_m: tuple[float, float] = (50.0, 150.0)
    """Centre of the spawn formation (x along the flight direction, y across), metres."""

    target_x_m: float = 270.0
    """x of every UAV's target; the target keeps the UAV's spawn y (a straight pre-planned line)."""

    starts_m: tuple[tuple[float, float], ...] = ()
    """Per-UAV spawn positions [x, y], metres, one per UAV; empty: the formation's slots.
    Given, they replace ``formation``, ``spacing_m``, ``rows`` and ``center_m``."""

    targets_m: tuple[tuple[float, float], ...] = ()
    """Per-UAV targets [x, y], metres, one per UAV; empty: from ``target_layout``."""

    target_layout: TargetLayout = "line"
    """Where the targets lie when ``targets_m`` is empty: "line" (the paper: every target at
    x = ``target_x_m``, on its UAV's spawn y) or "formation" (the spawn formation moved along x
    so that its centre lies at ``target_x_m``; the targets are then as far apart as the spawn
    slots, which arrival as hovering needs when slots share a y, as rows of a grid do)."""

    groups: tuple[int, ...] = ()
    """The swarm each UAV flies with, 0…G−1, one per UAV; empty: one swarm (the paper's).
    Each swarm has its own virtual centre p* (from its own starts and targets) and its own peak
    in Φ: two swarms that cross, or UAVs on unrelated routes, each keep their own formation
    reference instead of one p* between them (docs/MODEL.md §15, §20)."""

    def __post_init__(self) -> None:
        _integer(self, "count")
        problem = groups_problem(self.groups, self.count) if self.groups else None
        _require(problem is None, "groups", str(problem))
        for name in ("starts_m", "targets_m"):
            points = getattr(self, name)
            _require(
                not points or len(points) == self.count,
                name,
                f"must hold one [x, y] per UAV ({self.count}), got {len(points)}",
            )
            _require(
                all(len(p) == 2 and all(math.isfinite(v) for v in p) for p in points),
                name,
                "every entry must be a finite [x, y]",
            )
        _positive(self, "speed_m_s", "spacing_m")
        _require(
            0 < self.max_turn_rad <= math.pi / 2,
            "max_turn_rad",
            f"must be in (0, π/2], got {self.max_turn_rad!r}",
        )
        _require(
            self.formation in FORMATIONS,
            "formation",
            f"must be one of {', '.join(FORMATIONS)}, got {self.formation!r}",
        )
        _integer(self, "rows")
        _require(
            self.target_layout in TARGET_LAYOUTS,
            "target_layout",
            f"must be one of {', '.join(TARGET_LAYOUTS)}, got {self.target_layout!r}",
        )
        _require(len(self.center_m) == 2, "center_m", "must be [x, y]")
        _require(
            self.target_x_m > self.center_m[0],
            "target_x_m",
            f"must be ahead (larger x) of the spawn centre {self.center_m[0]}",
        )


@dataclass(frozen=True)
class ObstacleConfig:
    """Obstacles: count, speed, spawn line and the randomness of their approach."""

    count: int
    """M, number of obstacles."""

    speed_m_s: float = 2.5
    """v_o, obstacle speed, m/s (0 gives static obstacles)."""

    spawn_x_m: float = 240.0
    """x of the line on which obstacles spawn, metres."""

    spacing_m: float = 80.0
    """Distance between neighbouring obstacles on the spawn line, metres: with the lateral
    jitter, two obstacles leave a gap of 60–100 m, wide enough to pass between (2·d_col plus
    margin), as the middle UAVs do in the paper's Fig. 4."""

    center_y_m: float = 150.0
    """y of the centre of the obstacle spawn line, metres."""

    lateral_jitter_m: float = 10.0
    """Half-width of the uniform random shift of each obstacle's spawn y, metres."""

    heading_jitter_rad: float = math.radians(10.0)
    """Half-width of the uniform random perturbation of the heading toward the swarm, rad."""

    def __post_init__(self) -> None:
        _integer(self, "count", minimum=0)
        _non_negative(self, "speed_m_s", "spacing_m", "lateral_jitter_m", "heading_jitter_rad")
        _require(
            self.heading_jitter_rad <= math.pi,
            "heading_jitter_rad",
            f"must be <= π, got {self.heading_jitter_rad!r}",
        )


@dataclass(frozen=True)
class IntruderConfig:
    """One intruder given by its encounter with one UAV, as airspace encounter models give it.

    The geometry is what would happen if nobody turned: the UAV ``against`` flies straight to
    its target at the UAV speed, the intruder flies straight at ``speed_m_s`` on a course
    ``crossing_rad`` counter-clockwise from the UAV's (π: head-on, ±π/2: crossing, 0: same
    direction — overtaking or overtaken by speed), and the two pass ``miss_m`` apart at the
    closest point of approach (CPA), ``tcpa_s`` after the start. The parametrisation of the
    MIT Lincoln Laboratory encounter models for unmanned aircraft, in the horizontal plane.
    """

    against: int = 0
    """Index of the UAV whose encounter this is."""

    crossing_rad: float = math.pi
    """Intruder course minus the UAV's course, rad, counter-clockwise (file key crossing_deg)."""

    speed_m_s: float = 10.0
    """Intruder ground speed, m/s; 0 gives a static obstacle on (or ``miss_m`` beside) the path."""

    miss_m: float = 0.0
    """Signed horizontal miss distance at the CPA, metres: > 0 the intruder passes on the UAV's
    left (of the relative velocity; of the UAV's course for a static intruder)."""

    tcpa_s: float = 20.0
    """Time from the start of the episode to the CPA, seconds."""

    appear_s: float = 0.0
    """The intruder is hidden from sensing until this time, seconds (rounded up to whole
    decision steps): a late pop-up. It is there all along: it collides while hidden."""

    def __post_init__(self) -> None:
        _integer(self, "against", minimum=0)
        _non_negative(self, "speed_m_s", "tcpa_s", "appear_s")
        _require(math.isfinite(self.crossing_rad), "crossing_rad", "must be finite")
        _require(math.isfinite(self.miss_m), "miss_m", "must be finite")


@dataclass(frozen=True)
class SensingConfig:
    """What a UAV perceives: a forward LiDAR-like sector."""

    range_m: float = 100.0
    """Sensing range, metres."""

    aperture_rad: float = math.radians(270.0)
    """Full aperture of the sensed sector, centred on the heading, rad (2π = all around)."""

    max_obstacles: int = 4
    """m: obstacle rows in the observation (nearest first, masked when fewer are seen)."""

    observation: int = 1
    """Observation version (`sim.observation`): 1, the paper's rows (own state, swarm, the m
    nearest obstacles); 2, those plus the k nearest neighbouring UAVs, every other vehicle as
    relative position, relative velocity and distance."""

    max_neighbours: int = 0
    """k: neighbouring-UAV rows of a version-2 observation (nearest first, masked); 0 in v1."""

    def __post_init__(self) -> None:
        _positive(self, "range_m")
        _require(
            self.observation in (1, 2),
            "observation",
            f"must be 1 (the paper's rows) or 2 (with neighbours), got {self.observation!r}",
        )
        _integer(self, "max_neighbours", minimum=0)
        _require(
            self.observation == 2 or self.max_neighbours == 0,
            "max_neighbours",
            "needs observation = 2 (version 1 has no neighbour rows)",
        )
        _require(
            0 < self.aperture_rad <= 2 * math.pi,
            "aperture_rad",
            f"must be in (0, 2π], got {self.aperture_rad!r}",
        )
        _integer(self, "max_obstacles")


def _range(obj: object, *names: str, minimum: float = 0.0) -> None:
    for name in names:
        lo, hi = getattr(obj, name)
        _require(
            math.isfinite(lo) and math.isfinite(hi) and minimum <= lo <= hi,
            name,
            f"must be [low, high] with {minimum:g} <= low <= high, got {[lo, hi]!r}",
        )


@dataclass(frozen=True)
class DynamicsRandomisation:
    """Per-vehicle randomisation of the vehicle response, drawn at each episode start.

    Each UAV of each episode draws a profile from ``profiles`` (uniformly; empty: the scenario's
    ``dynamics``), then multiplies its delay, velocity time constant and acceleration cap by
    factors drawn uniformly from the ranges below. The defaults change nothing. Seeded by the
    generator of the episode start, so a run is reproducible.
    """

    profiles: tuple[str, ...] = ()
    """Vehicle profiles to draw from (shipped names or paths); empty: the scenario's one."""

    delay_scale: tuple[float, float] = (1.0, 1.0)
    """Factor range on the profile's transport delay."""

    velocity_tau_scale: tuple[float, float] = (1.0, 1.0)
    """Factor range on the profile's velocity time constant."""

    max_accel_scale: tuple[float, float] = (1.0, 1.0)
    """Factor range on the profile's acceleration cap."""

    def __post_init__(self) -> None:
        _range(self, "delay_scale")
        _range(self, "velocity_tau_scale", "max_accel_scale", minimum=1e-3)

    @property
    def randomised(self) -> bool:
        """Whether anything is drawn at all."""
        return bool(self.profiles) or any(
            lo != hi for lo, hi in (self.delay_scale, self.velocity_tau_scale, self.max_accel_scale)
        )


@dataclass(frozen=True)
class SensorConfig:
    """How the UAVs learn where the intruders and the vehicles of the swarm are.

    "exact": every position and velocity is true and current (the paper). "adsb": intruders are
    known only from ADS-B reports, each intruder reporting at its own rate with its own latency
    and accuracy, some reports lost, and tracked between reports by the runtime's extrapolation
    (`sim.sensors`); every UAV position (own and the swarm's) carries GPS noise. The ranges are
    drawn per intruder and episode.
    """

    model: SensorModel = "exact"
    """"exact" or "adsb"."""

    adsb_rate_hz: tuple[float, float] = (1.0, 2.0)
    """Report rate range, Hz: 1090ES transponders broadcast the airborne position twice a
    second, and what a receiver forwards after losses and its own decimation is 1–2 Hz."""

    adsb_latency_s: tuple[float, float] = (0.2, 1.5)
    """Age of a report when it reaches the runtime, seconds: the transponder's own latency
    plus the receiver and the telemetry link that relays it."""

    adsb_epu_m: tuple[float, float] = (10.0, 30.0)
    """95% horizontal position error (EPU) range, metres: NACp 10 (< 10 m) to NACp 9 (< 30 m),
    the classes of GNSS-equipped transponders."""

    adsb_nacv_m_s: float = 3.0
    """95% horizontal velocity error, m/s: NACv 2 (< 3 m/s)."""

    adsb_drop_probability: float = 0.1
    """Probability that a report is lost (garbled, out of range, receiver busy)."""

    adsb_error_tau_s: tuple[float, float] = (0.0, 0.0)
    """Correlation time range of an intruder's report errors, seconds, drawn per intruder:
    position and velocity errors are a first-order Gauss–Markov process, ρ = exp(−Δt/τ) between
    the reports taken, with the same σ. 0: drawn afresh for every report (the default). A real
    transponder's GNSS error wanders over minutes, so successive reports share most of it: a
    track off by a steady few metres rather than one that jumps (docs/MODEL.md §18)."""

    gps_sigma_m: float = 1.0
    """One-sigma GPS error per horizontal axis of every UAV position, metres (consumer GNSS
    with SBAS, about 1.5 m 95%), re-drawn at every decision."""

    adsb_filter: bool = False
    """Whether each ADS-B track fuses its reports in a constant-velocity Kalman filter
    (`sim.sensors.fuse`) rather than holding the newest one alone. The runtime's tracker does
    the same with the same setting (docs/MODEL.md §18, "A track filter")."""

    adsb_filter_accel_m_s2: float = 2.0
    """White acceleration σ the track filter allows for, per axis, m/s²: an aircraft at 40 m/s
    in a standard-rate turn (3°/s) accelerates 2.1 m/s² sideways. Smaller trusts straight
    flight more (smoother tracks, later in a turn); the innovation gate
    (`sim.sensors.FILTER_GATE`) restarts a track whose report the filter did not expect."""

    def __post_init__(self) -> None:
        _require(
            self.model in SENSOR_MODELS,
            "model",
            f"must be one of {', '.join(SENSOR_MODELS)}, got {self.model!r}",
        )
        _range(self, "adsb_latency_s", "adsb_epu_m", "adsb_error_tau_s")
        _range(self, "adsb_rate_hz", minimum=1e-3)
        _non_negative(self, "adsb_nacv_m_s", "gps_sigma_m", "adsb_filter_accel_m_s2")
        _require(
            0.0 <= self.adsb_drop_probability < 1.0,
            "adsb_drop_probability",
            f"must be in [0, 1), got {self.adsb_drop_probability!r}",
        )


@dataclass(frozen=True)
class ScenarioConfig:
    """A complete scenario: geometry, agents, timing, sensing, field, reward and PSO."""

    name: str
    """Scenario name, e.g. "3u2o"."""

    uav: UAVConfig
    obstacles: ObstacleConfig
    description: str = ""
    """One line for listings."""

    arena_length_m: float = 300.0
    """w: arena extent along x (the direction of flight), metres."""

    arena_width_m: float = 300.0
    """l: arena extent along y, metres."""

    dt_s: float = 2.0
    """Decision step, seconds (20 m of flight at 10 m/s)."""

    max_steps: int = 40
    """Step limit; the episode is truncated after it."""

    d_col_m: float = 20.0
    """d_col: collision distance, UAV–UAV and UAV–obstacle, metres (paper Table 2)."""

    substeps: int = 8
    """T: sub-intervals of each decision step. The swept collision checks (chord error
    ≤ L·a_max/(8T²), 3 cm at the defaults) and the trapezoid quadrature of the reward's external
    term both use the same T + 1 points of every arc."""

    sensing: SensingConfig = dataclasses.field(default_factory=SensingConfig)
    field: FieldConfig = dataclasses.field(default_factory=FieldConfig)
    reward: RewardConfig = dataclasses.field(default_factory=RewardConfig)
    pso: PSOConfig = dataclasses.field(default_factory=PSOConfig)
    arrival: Arrival = "hover"
    """What a UAV does once within d_col of its target: "hover" (it stops there and stays in
    every separation check until the episode ends, as ``fly`` holds a vehicle that arrived) or
    "leave" (the paper's rule: it leaves the episode)."""

    dynamics: str = "ideal"
    """The vehicle profile every UAV flies (`sim.vehicle`: "ideal" is the paper's arcs,
    "arducopter", "px4", ... are fitted to real autopilots), a shipped name or a file path."""

    dynamics_randomisation: DynamicsRandomisation = dataclasses.field(
        default_factory=DynamicsRandomisation
    )
    sensors: SensorConfig = dataclasses.field(default_factory=SensorConfig)
    intruders: tuple[IntruderConfig, ...] = ()
    """Obstacles placed by their encounter geometry (``[[intruders]]`` tables in a file)
    instead of the random spawn line of `ObstacleConfig`; one per obstacle."""

    def __post_init__(self) -> None:
        _positive(self, "arena_length_m", "arena_width_m", "dt_s", "d_col_m")
        _integer(self, "substeps")
        _require(
            self.substeps % self.reward.quadrature_intervals == 0,
            "reward.quadrature_intervals",
            f"must divide substeps ({self.substeps}), got {self.reward.quadrature_intervals}",
        )
        _integer(self, "max_steps")
        _require(
            self.arrival in ARRIVALS,
            "arrival",
            f"must be one of {', '.join(ARRIVALS)}, got {self.arrival!r}",
        )
        _require(
            self.uav.target_x_m <= self.arena_length_m,
            "uav.target_x_m",
            f"must lie inside the arena (<= {self.arena_length_m})",
        )
        _require(
            not self.intruders or len(self.intruders) == self.obstacles.count,
            "obstacles.count",
            f"must equal the number of [[intruders]] ({len(self.intruders)})",
        )
        for k, intruder in enumerate(self.intruders):
            _require(
                intruder.against < self.uav.count,
                f"intruders[{k}].against",
                f"must name a UAV, 0 to {self.uav.count - 1}, got {intruder.against}",
            )

    @property
    def step_length_m(self) -> float:
        """Arc length flown by a UAV in one decision step, metres (v_s·dt)."""
        return self.uav.speed_m_s * self.dt_s
