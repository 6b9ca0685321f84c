"""The runtime assurance shield: the policy proposes, a simple checked rule keeps separation.

A Simplex-style monitor around any controller (a learned policy, the potential field, ORCA):
for every UAV at every decision it predicts, over a look-ahead ``horizon_s``,

* its own motion under each candidate decision — a heading change over the coming step flown
  as the simulator flies it (the ideal vehicle: the constant-turn-rate arc, then straight on
  its final heading, `sim.prediction`; a vehicle flown with a fitted autopilot response:
  that command stream through the response, from its velocity now and after its last
  command, `sim.dynamics.predict_response`), at full speed and, where the vehicle can slow
  down (a multirotor), at lower speeds down to a hover for the coming step, on at the cruise
  speed after it;
* every intruder it knows of, straight at constant velocity from its track, with a position
  uncertainty that grows with the age of the report and the time predicted ahead
  (``track_growth_m_s``; a tracked intruder over the shorter ``track_horizon_s``);
* every neighbouring UAV of the swarm on its committed arc: the decision the swarm's controller
  proposes for it this step (the swarm shares its decisions), at its commanded speed (0 while
  it hovers where it arrived), flown as its own candidates are (with its response, if any);

and computes, in closed form per piecewise-linear segment, each candidate's closest approach to
each of them (the "bands" of detect-and-avoid systems such as NASA's DAIDALUS, over the
candidates a turn-limited UAV can fly). The policy's action passes when its closest approach
stays ≥ d_col + ``margin_m`` (plus the intruder's uncertainty) over the horizon; otherwise the
shield flies the passing heading change nearest to the proposed one at full speed, then (where
the vehicle can slow down) the fastest slower speed with a passing heading, nearest first; then,
where no intruder is a track, a full turn held over this step and the next (`_escape`); when
nothing passes, the least dangerous candidate, of one step or held (`_rank`: it avoids a
collision predicted in the coming step first, then one with an intruder within the neighbour
look-ahead, then one with a neighbour in it; then the largest clearance, the closest approach
minus what is required). Last, a UAV whose decision points more than ``return_deg`` away from
its target turns back towards it where that passes (`_homeward`): safe is not enough, a UAV
that paces an intruder away from its target never arrives. A UAV boxed in by its own swarm
(nothing passes, but a heading clears every intruder) gets room: its neighbours decide again
with it held to that heading (``give_way``, `_give_way`). Beyond one decision, where some UAV
has nothing that passes, its swarm may fly a centralised plan for a few steps
(``plan_steps``: the swarm planner, `sim.oracle.oracle_actions`, applied by the offline
evaluation, which keeps the memory a plan held over steps needs).
Nothing after a UAV reaches its target (its distance over the cruise speed, at least the coming
step) is checked: it leaves, or hovers where nothing of the swarm is headed; a
straight line past the target would see conflicts the UAV never flies into.

Modes: "off" (the proposal is flown, nothing computed), "monitor" (computed and recorded, never
changes the proposal), "on". Everything is batched over (B environments, N UAVs, K candidates,
J threats, P time points) in numpy, with no Python loop over UAVs, candidates or threats.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, Float32Array, FloatArray, IntArray
from sim.config import ScenarioConfig
from sim.dynamics import PREDICTED_STEPS, Motion, predict_response
from sim.kinematics import sinc_series, wrap_angle
from sim.prediction import F, displacements, segment_closest_sq
from sim.sensors import picture
from sim.state import SwarmState
from sim.vehicle import load_profile

ShieldMode = Literal["off", "monitor", "on"]
SHIELD_MODES: tuple[ShieldMode, ...] = ("off", "monitor", "on")
NeighbourArcs = Literal["proposals", "straight"]
NEIGHBOUR_ARCS: tuple[NeighbourArcs, ...] = ("proposals", "straight")
VehicleModel = Literal["fitted", "ideal"]
VEHICLE_MODELS: tuple[VehicleModel, ...] = ("fitted", "ideal")


BLIND_TRACK_GROWTH_M_S = 0.5
"""`ShieldConfig.track_growth_m_s` behind a policy blind to its neighbours (observation version
1: the zoo's scenario policies), m/s. Flown one process per vehicle over the swarm bus, such a
policy swerves wider round an intruder at 1.5 m/s and into its neighbours' lanes, which it does
not see: its 3u2o vehicles met in two of three CI flights, in three of three with today's
shield, and in none at 0.5 (docs/MODEL.md §21)."""


def track_growth_behind(sees_neighbours: bool) -> float:
    """The default `ShieldConfig.track_growth_m_s` behind a policy, m/s.

    ``sees_neighbours``: its observation has neighbour rows; else `BLIND_TRACK_GROWTH_M_S`.
    """
    return ShieldConfig.track_growth_m_s if sees_neighbours else BLIND_TRACK_GROWTH_M_S


GIVE_WAY_ROUNDS = 2
"""Boxed-in UAVs of one environment that `ShieldConfig.give_way` tries, one after the other
(each later one with the earlier ones' headings held)."""

ESCAPE_STEPS_MAX = 4
"""The most decision steps `ShieldConfig.escape_steps` may hold the full turn for: four full
turns of the paper's a_max (45°) turn the UAV around."""


@dataclass(frozen=True)
class ShieldConfig:
    """Settings of the shield (`remarl-fc eval/fly --shield`, ``--shield-horizon``, ...)."""

    mode: ShieldMode = "off"
    """"off", "monitor" (record what the shield would do, never change the action) or "on"."""

    horizon_s: float = 25.0
    """Look-ahead of the checks against exactly sensed intruders, seconds (12.5 decision steps
    at the paper's 2 s; tracked ones: ``track_horizon_s``). A candidate that passes over a
    short look-ahead may only have pushed the conflict past it, and a few steps later nothing
    the turn-limited UAV can fly passes. Measured behind the generalist on the standard suite
    (200 episodes a family, two passes), 10 → 15 → 20 → 25 → 30 s: mean success 92.8 → 93.4 →
    93.8 → 94.0 → 94.0 %, 50u8o 55 → 62 → 69 → 72 → 71 %, 20u4o 94 → 97 → 98 → 98 → 98.5 %, no
    family lower (docs/MODEL.md §21)."""

    track_horizon_s: float = 10.0
    """Look-ahead of the checks against tracked intruders (a report of some age: ADS-B), seconds,
    at most ``horizon_s``. A track's required clearance grows with the time predicted ahead
    (``track_growth_m_s``), and 25 s ahead of one it asked more than the vehicles could give:
    behind the zoo policies on the mock (ADS-B traffic, fitted ArduCopters) the 7u2o demo and
    the three-process 3u2o flight over the bus met intruders at 25 s and flew clean at 10 s; in
    the simulated real world `robust/3u2o` behind the shield flew 3u2o at 79 % at 10 s and 66 %
    at 25 s (300 episodes; 61–64 % either way while the shield predicted the ideal arc;
    docs/MODEL.md §21). The simulator's exact sensing has no tracks: ``horizon_s`` applies."""

    neighbour_horizon_s: float = 4.0
    """Look-ahead of the checks against the swarm's own UAVs, seconds (2 decision steps): they
    re-plan together every step, so their arcs are not held straight for long. Measured on the
    paper scenarios behind the zoo policies (60 episodes each): at 10 s the shield intervened
    in 22% of 10u1o's decisions and cost 12% of its success; at 6 s, 4% and nothing. Behind
    the generalist on the standard suite (two passes), 2 / 3 / 4 / 6 / 8 s: UAV–UAV collisions
    in 2.2 / 0.76 / 0.67 / 1.07 / 1.2 % of the episodes, 50u8o 80 / 84 / 90 / 85 / 82 %; see
    docs/MODEL.md §21."""

    margin_m: float = 1.0
    """Required clearance beyond d_col, metres: covers the chord error of the predicted arcs
    (0.25 m, `CHORDS`). Measured behind the zoo policies on the paper
    scenarios (100 episodes each): 2.5 m cost 3u2o 2% of its success and 5u2o 1%, 1 m cost
    nothing (docs/MODEL.md). Raise it on real vehicles by their tracking error
    (``--shield-margin``)."""

    headings: int = 21
    """Candidate heading changes, evenly spaced over [−a_max, a_max] (odd: 0 included), besides
    the proposed one: 4.5° apart at the paper's a_max = 45°. 15 (6.4° apart) cost a sixth
    less time and 1% of 3u2o's and of 5u2o's success behind the zoo policies (100 episodes)."""

    slow_fractions: tuple[float, ...] = (0.5, 0.0)
    """Speeds tried after every full-speed candidate failed, as fractions of the cruise speed,
    fastest first (0: hover); only where the vehicle can slow down."""

    track_growth_m_s: float = 1.5
    """Growth of an intruder's position uncertainty per second of report age and of prediction,
    m/s, added to the required clearance, for tracked intruders (a report of some age: ADS-B);
    an exactly sensed one (age 0) is certain. Behind a policy blind to its neighbours (a zoo
    policy, observation version 1) `fly`, `demo` and `eval` keep `BLIND_TRACK_GROWTH_M_S`
    instead (`track_growth_behind`). Measured behind the default generalist in the simulated
    real world (fitted ArduCopters, ADS-B; its eight paper scenarios, 300 episodes each),
    0.5 → 1.5 m/s: 88.5 → 91.4 % as flown (UAV–intruder collisions 6.8 → 1.5 % of the
    episodes), 72.5 → 85.5 % with ADS-B errors that wander as GNSS errors do (correlated over
    60 s); the generalist over the swarm bus flew clean either way (docs/MODEL.md §21)."""

    neighbours: int = 8
    """Nearest other UAVs each UAV checks its candidates against."""

    passes: int = 2
    """Decisions per step: each pass after the first checks every candidate against the
    neighbours' proposals and also against what the earlier passes decided for them. One pass
    checks against the proposals alone, and two UAVs that both turn away from each other's
    proposal may turn into each other. Measured behind the generalist on eight crowded
    families (200 episodes each): two passes took UAV–UAV collisions from 4.5 to 0 % of 20u4o's
    episodes, 28 to 4.5 % of 50u8o's, 3.5 to 1 % of two lines of five; a third pass changed
    nothing measurable (docs/MODEL.md §21)."""

    neighbour_arcs: NeighbourArcs = "proposals"
    """What each UAV expects of its neighbours: "proposals" (the arcs the swarm's controller
    proposes for them this step, and with ``passes`` > 1 what the earlier passes decided: the
    swarm shares its decisions) or "straight" (each flies on at its heading and speed: what one
    UAV's own observation tells it, `policies.own_view`). "straight" makes every decision a
    function of what that UAV sees, so that a student can copy it (a DAgger teacher:
    ``remarl-fc train --generalist --teacher self-shield --teacher-neighbours straight``); it
    makes one pass, whatever ``passes`` says."""

    vehicle_model: VehicleModel = "fitted"
    """How the UAVs' motion is predicted where the simulator flies them with a fitted autopilot
    response (``--dynamics``, `sim.dynamics`): "fitted" (every candidate and every neighbour's
    arc flown with the vehicle's response, from its velocity now and after its last command:
    `sim.dynamics.predict_response`; `fly` predicts each vehicle with its autopilot's fitted
    profile, docs/FLYING.md) or "ideal" (the arcs as commanded). Ideal vehicles fly their arcs
    exactly either way; a UAV hovering where it arrived is held where it is either
    way (predicting its braking too cost the real world's 10u1o 5 points). Measured behind the
    default generalist (docs/MODEL.md §21): fifty fitted ArduCopters in 50u8o 61.5 → 79.5 %
    (UAV–UAV collisions 27 → 16 % of the episodes), fifty PX4s 75.5 → 85.5 %; the real world's
    eight paper scenarios 82.6 → 86.5 %."""

    escape_steps: int = 2
    """Decision steps a UAV may hold the full turn for where no candidate of one step passes,
    then straight on (1: the one-step candidates alone). A one-step candidate turns at most
    a_max and then flies straight: an intruder that needs a wider turn leaves nothing that
    passes, though turning fully now and again at the next decision clears it. Measured behind
    the generalist on the standard suite (docs/MODEL.md §21), 1 → 2 → 3 steps: mean success
    95.5 → 96.0 → 95.8 %, UAV–UAV collisions in 0.67 → 0.53 → 0.74 % of the episodes, dense-10u
    65 → 72 → 74 %, 50u8o 90 → 91 → 83 %. Where none of them passes either, the least
    dangerous competes with the one-step candidates for the fallback: at two steps 96.06 %,
    UAV–UAV collisions in 0.47 % of the episodes. A vehicle flown with its fitted response holds its
    turn for two steps at most (its response is predicted exactly over two). None is held
    against an ADS-B track, whose position errors the check does not model: held there, they
    cost the real world's eight paper scenarios 0.5 and 0.8 points on two draws."""

    return_deg: float = 60.0
    """Return to course: a UAV whose decided heading (the proposal, or what the shield chose)
    lies more than this from the bearing to its target, degrees, turns back towards the target
    instead where that passes the check: full turns at a_max until it points at the target,
    then straight on, or where that does not pass the long way round; checked like any
    candidate over the look-ahead; only the first step is flown (180: never). A vehicle flown
    with its fitted response turns back over two steps at most (its response is predicted
    exactly over two), the short way or else the long way round, then holds its heading
    (the long way too since 2026-12-01, late: the real world 87.45 → 88.75 %, docs/MODEL.md
    §21). A UAV that hovers where it arrived
    is kept clear of over the whole look-ahead. Why: a policy may pace an intruder that flies
    its way between it and its target, hundreds of metres past the target, until the episode
    runs out of time; nothing is unsafe, so nothing else in the shield intervenes. Measured
    behind the generalist on the standard suite (docs/MODEL.md §21): mean success 96.8 %
    without (UAV–UAV collisions in 37 episodes of 7,600), 98.7 % at 60° (34 episodes); with
    the turn back checked against the swarm over 4 s, 98.4 % at 60° and at 90° (36 episodes
    each), 98.5 % at 30° (43). In the real world (fitted ArduCopters, ADS-B) 86.6 → 87.4 %."""

    return_neighbour_horizon_s: float = 12.0
    """Look-ahead of the turn back's check against the swarm's own UAVs, seconds (every other
    candidate: ``neighbour_horizon_s``). The turn back overrides a decision that passed, and
    a loop checked over 4 s against the neighbours' arcs can turn into a neighbour just past
    them. Measured behind the generalist on the standard suite (docs/MODEL.md §21), 4 → 8 →
    12 → 25 s: mean success 98.42 → 98.58 → 98.67 → 98.61 %, UAV–UAV collisions in 36 → 35
    → 34 → 34 episodes of 7,600, crossing-50u 83 → 86.5 → 86.5 → 86 %, two lines of five
    96 → 97 → 100 → 99.5 %."""

    fly_out: bool = True
    """Fly out of a circle round the target: a UAV whose target lies so near the centre of its
    tightest turn towards it that turning on circles the target without ever coming within
    d_col, and whose decision turns that way, flies straight on for the step instead, where
    that passes the check like any candidate; from one step further on, the turn reaches the
    target. At the paper's defaults (20 m a step, 45° a step: a circle of 25.5 m radius) a
    target within 5.5 m of that circle's centre is circled 20–31 m away until the episode runs
    out. Why: the policy now and then circles its target so; nothing is unsafe, and the turn
    back (``return_deg``) turns the short way, which is the circle. Only where the UAVs fly
    their arcs exactly (no fitted response predicted): a fitted vehicle turns later and wider
    than the circle, and may well reach a target the circle does not; flown out there, the
    own-separation generalist met more intruders in the real world (7u1o 96.3 → 93.3 %).
    Measured behind the generalist on the standard suite (docs/MODEL.md §21), with the turn
    back's exact rule for the ideal vehicle (`_reachable`): mean success 99.20 → 99.32 %,
    crossing-50u 91.0 → 93.5 % (its five time-outs gone), crossing-20u 98 → 99 %, dense-10u
    96.4 → 96.9 %, no family lower, UAV–UAV collisions level (16 episodes of 7,600)."""

    plan_steps: int = 8
    """The swarm planner, the last resort: where some UAV of an environment has nothing that
    passes (not one heading, speed, held turn), every UAV of that environment flies the
    oracle's plan instead of its controller's (`sim.oracle.oracle_actions`: a centralised
    prioritised search over the known intruders' straight futures and the swarm's own plans,
    from where the swarm stands, replanned at every step) for this many decision steps, the
    step it was stuck included (0: never). The check decides for each UAV against its
    neighbours' arcs of one step; in a crowd that leaves a UAV boxed in between its neighbours
    and an intruder, where only the neighbours moving too makes room. Only in the simulator's
    exact world (every intruder known exactly, the vehicles flying their arcs exactly: the
    plan is checked by flying it there, `sim.oracle`); not against ADS-B tracks, a fitted
    response or GPS errors, where its plan would not be exact, and not in `fly`. A plan found
    is held while the swarm flies it: where the search from a later step finds none, the held
    plan's next step is flown, until an intruder appears. Applied by the offline evaluation
    (`remarl_fc.offline.shielding.Shielded`); `shield` itself decides one step and keeps no
    memory. Measured behind the generalist on the standard suite (docs/MODEL.md §21)."""

    give_way: int = 6
    """Give way to a boxed-in UAV: where a UAV has nothing that passes (not one heading,
    speed or held turn) but some heading of one step clears the intruders, its neighbours make
    room. Up to this many of those headings, nearest its proposal first, are tried: the UAV
    committed to the heading, every other UAV of its environment decides again against it (the
    whole check, ``passes`` and all), and the first heading with which the UAV then passes
    against what its neighbours fly, and no UAV that had a passing candidate loses it, is
    flown with the neighbours' new decisions (0: never). A joint decision of one step, made
    with the check's own prediction (a fitted response, tracked intruders), so `fly` carries
    it too; `GIVE_WAY_ROUNDS` boxed-in UAVs of an environment at most, one after the other.
    Where the swarm planner runs (``plan_steps``, the exact world) it comes first, and giving
    way only where it finds no plan. Measured behind the default generalist on the standard
    suite (docs/MODEL.md §21): without the planner, as `fly` carries the shield, 98.90 →
    98.99 %, UAV–UAV collisions in 45 → 41 episodes of 7,600, crossing-50u 86.6 → 87.9 %,
    no family lower; with it 99.57 → 99.59 % (crossing-50u 95.5 → 96.2 %); in dense-10u it
    freed 93 of the 126 boxed-in decisions that had a heading clear of the intruders (of 322
    with nothing that passed). 6 and 22 headings free the same."""

    @property
    def return_rad(self) -> float:
        """``return_deg`` in radians."""
        return math.radians(self.return_deg)

    def __post_init__(self) -> None:
        if not 0.0 < self.return_deg <= 180.0:
            raise ValueError(f"shield return_deg must be in (0, 180], got {self.return_deg!r}")
        horizon = self.return_neighbour_horizon_s
        if not (math.isfinite(horizon) and horizon > 0):
            raise ValueError(
                f"shield return_neighbour_horizon_s must be a finite number > 0, got {horizon!r}"
            )
        if self.vehicle_model not in VEHICLE_MODELS:
            raise ValueError(
                f"shield vehicle_model must be one of {', '.join(VEHICLE_MODELS)}, "
                f"got {self.vehicle_model!r}"
            )
        if self.mode not in SHIELD_MODES:
            raise ValueError(f"shield mode must be one of {', '.join(SHIELD_MODES)}")
        if self.neighbour_arcs not in NEIGHBOUR_ARCS:
            raise ValueError(
                f"shield neighbour_arcs must be one of {', '.join(NEIGHBOUR_ARCS)}, "
                f"got {self.neighbour_arcs!r}"
            )
        for name in (
            "horizon_s",
            "track_horizon_s",
            "neighbour_horizon_s",
            "track_growth_m_s",
            "margin_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"shield {name} must be a finite number >= 0, got {value!r}")
        if self.horizon_s <= 0 or self.track_horizon_s <= 0:
            raise ValueError("shield horizon_s and track_horizon_s must be > 0")
        if self.headings < 3 or self.headings % 2 == 0:
            raise ValueError(f"shield headings must be odd and >= 3, got {self.headings}")
        if any(not 0.0 <= f < 1.0 for f in self.slow_fractions):
            raise ValueError("shield slow_fractions must be in [0, 1)")
        if self.neighbours < 0:
            raise ValueError("shield neighbours must be >= 0")
        if self.passes < 1:
            raise ValueError(f"shield passes must be >= 1, got {self.passes}")
        if self.plan_steps < 0:
            raise ValueError(f"shield plan_steps must be >= 0, got {self.plan_steps}")
        if self.give_way < 0:
            raise ValueError(f"shield give_way must be >= 0, got {self.give_way}")
        if not 1 <= self.escape_steps <= ESCAPE_STEPS_MAX:
            raise ValueError(
                f"shield escape_steps must be 1 to {ESCAPE_STEPS_MAX}, got {self.escape_steps}"
            )


@dataclass(frozen=True)
class ShieldDecision:
    """What the shield decided for every UAV, (B, N) each.

    Attributes:
        action: the normalised heading change to fly (the proposal where the shield let it
            pass, or in monitor mode).
        speed_m_s: the speed to fly it at (the cruise speed unless the shield slowed down).
        intervened: the proposal did not pass (in monitor mode: the shield would have changed
            it) — deciding UAVs only.
        safe_exists: some candidate passes.
        proposed_cpa_m: predicted closest approach of the proposal to any threat (+inf: none).
        flown_cpa_m: the same for the decision flown (what the shield would fly, in monitor
            mode).
        shield_action, shield_speed_m_s: what the shield would fly (= action and speed_m_s when
            on).
        safe_headings: (B, N, K) of the UAVs whose proposal did not pass, which of the
            `ShieldConfig.headings` candidates (`candidate_grid`) pass at the cruise speed;
            all False for the others (their proposal passed, or the shield is off). The set a
            teacher's label is one point of (`policies.generalist_dagger`, safe sets).
    """

    action: NDArray[np.float32]
    speed_m_s: FloatArray
    intervened: BoolArray
    safe_exists: BoolArray
    proposed_cpa_m: FloatArray
    flown_cpa_m: FloatArray
    shield_action: NDArray[np.float32]
    shield_speed_m_s: FloatArray
    safe_headings: BoolArray


def candidate_grid(headings: int) -> FloatArray:
    """(K,) the shield's candidate heading changes, normalised to [−1, 1], evenly spaced."""
    return np.linspace(-1.0, 1.0, headings)


def nearest_candidate(heading: FloatArray | Float32Array, headings: int) -> IntArray:
    """(...) the index of the candidate (`candidate_grid` of ``headings``) nearest ``heading``.

    ``heading`` (...): normalised heading changes in [−1, 1]; ties go to the lower index.
    """
    offset = np.asarray(heading, dtype=np.float64)[..., None] - candidate_grid(headings)
    nearest: IntArray = np.abs(offset).argmin(axis=-1)
    return nearest


def passing_side(safe: BoolArray, heading: FloatArray | Float32Array) -> BoolArray:
    """(..., K) the run of ``safe``'s passing candidates that holds ``heading``.

    ``safe`` (..., K): which of the candidates (`candidate_grid`) pass, as
    `ShieldDecision.safe_headings`; ``heading`` (...): a normalised heading change, the
    shield's choice among them. Kept: the candidates that pass with no failing one between
    them and the candidate nearest ``heading`` — the side of the threats the shield turned
    to, where passing headings lie on both. All False where that candidate itself fails.
    """
    k = safe.shape[-1]
    index = np.arange(k)
    at = nearest_candidate(heading, k)[..., None]  # (..., 1) the candidate chosen
    fails = ~safe
    below = np.where(fails & (index < at), index, -1).max(axis=-1, keepdims=True)
    above = np.where(fails & (index > at), index, k).min(axis=-1, keepdims=True)
    holds = np.take_along_axis(safe, at, axis=-1)
    kept: BoolArray = safe & (index > below) & (index < above) & holds
    return kept


@dataclass(frozen=True)
class Threats:
    """What one decision knows of the other vehicles.

    Attributes:
        intruder_pos_m, intruder_vel_m_s: (B, M, 2) intruders at the decision time.
        intruder_known: (B, M) the intruders known at all (a track, or sensed).
        intruder_age_s: (B, M) age of each intruder's report, seconds (0 for exact sensing).
    """

    intruder_pos_m: FloatArray
    intruder_vel_m_s: FloatArray
    intruder_known: BoolArray
    intruder_age_s: FloatArray

    @property
    def tracked(self) -> BoolArray:
        """(B, M) intruders known from a report of some age (ADS-B tracks), not sensed exactly.

        They are checked over ``track_horizon_s``, their clearance growing with
        ``track_growth_m_s``.
        """
        out: BoolArray = self.intruder_known & (self.intruder_age_s > 0)
        return out


@dataclass(frozen=True)
class Swarm:
    """The swarm at one decision, (B, N) per UAV.

    Attributes:
        pos_m: (B, N, 2) positions. heading_rad: commanded headings. target_m: (B, N, 2).
        deciding: the UAVs this decision is for (flying). present: the UAVs the others must
        keep clear of: flying (deciding, or decided elsewhere: a peer process's vehicle in
        `fly`), or hovering where they arrived (not deciding, at speed 0). speed_m_s: each
        UAV's speed along its committed arc (0 while hovering). motion: (B, N) each UAV's
        velocity, last command and fitted response, where its motion is predicted with the response
        (`ShieldConfig.vehicle_model` "fitted"); None: every UAV flies its arcs exactly.
    """

    pos_m: FloatArray
    heading_rad: FloatArray
    target_m: FloatArray
    deciding: BoolArray
    present: BoolArray
    speed_m_s: FloatArray
    motion: Motion | None = None


@dataclass(frozen=True)
class Vehicle:
    """The constants of the swarm's vehicles.

    Attributes:
        d_col_m: collision distance. dt_s: decision step. max_turn_rad: heading change of a
        full action. cruise_m_s: full speed. can_slow: the vehicle may fly slower, down to a
        hover (a multirotor).
    """

    d_col_m: float
    dt_s: float
    max_turn_rad: float
    cruise_m_s: float
    can_slow: bool = True


def shield(
    cfg: ShieldConfig,
    vehicle: Vehicle,
    swarm: Swarm,
    threats: Threats,
    proposed: NDArray[np.floating],
) -> ShieldDecision:
    """Check the proposed actions (B, N) and decide what to fly (the module docstring).

    ``cfg.passes`` passes: each after the first keeps every UAV clear of its neighbours'
    proposals and of what the earlier passes decided for those it changed. With
    ``cfg.neighbour_arcs`` "straight", one pass against neighbours flying straight on.
    """
    prop = np.clip(np.asarray(proposed, dtype=np.float64), -1.0, 1.0)
    b, n = prop.shape
    full = np.full((b, n), vehicle.cruise_m_s)
    if cfg.mode == "off":
        inf = np.full((b, n), np.inf)
        no = np.zeros((b, n), dtype=bool)
        act = prop.astype(np.float32)
        none = np.zeros((b, n, cfg.headings), dtype=bool)
        return ShieldDecision(act, full, no, ~no, inf, inf, act, full, none)
    everyone = np.ones((b, n), dtype=bool)
    if cfg.neighbour_arcs == "straight":  # what each UAV sees: its neighbours flying on
        arcs = [Commitment(np.zeros_like(prop), swarm.speed_m_s, everyone)]
        return _decide(cfg, vehicle, swarm, threats, prop, arcs)
    arcs = [Commitment(prop, swarm.speed_m_s, everyone)]
    decision = _decide(cfg, vehicle, swarm, threats, prop, arcs)
    for _ in range(cfg.passes - 1):
        # compared in float32, the decision's own precision: a passing float64 proposal comes
        # back rounded, and is no change
        turn = decision.shield_action
        first = np.where(swarm.deciding, decision.shield_speed_m_s, swarm.speed_m_s)
        changed = swarm.deciding & ((turn != prop.astype(np.float32)) | (first != swarm.speed_m_s))
        if not changed.any():
            break
        arcs.append(Commitment(turn.astype(np.float64), first, changed))
        earlier, decision = decision, _decide(cfg, vehicle, swarm, threats, prop, arcs)
        # where nothing passes every arc but something passed the earlier ones, the earlier
        # decision stands: a pass never gives up a decision that keeps clear of the proposals
        keep = ~decision.safe_exists & earlier.safe_exists
        if keep.any():
            decision = ShieldDecision(
                **{
                    f.name: np.where(
                        keep if f.name != "safe_headings" else keep[..., None],
                        getattr(earlier, f.name),
                        getattr(decision, f.name),
                    )
                    for f in dataclasses.fields(ShieldDecision)
                }
            )
    if cfg.give_way:
        decision = _give_way(cfg, vehicle, swarm, threats, prop, decision)
    return decision


def _of_envs(obj: Any, envs: NDArray[np.intp]) -> Any:
    """A `Swarm`, `Threats` or `ShieldDecision` of the environments ``envs`` (E,) alone."""
    picked = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if value is not None:
            picked[f.name] = value.of(envs) if isinstance(value, Motion) else value[envs]
    return dataclasses.replace(obj, **picked)


def give_way(
    cfg: ShieldConfig,
    vehicle: Vehicle,
    swarm: Swarm,
    threats: Threats,
    proposed: NDArray[np.floating],
    decision: ShieldDecision,
    envs: NDArray[np.intp],
) -> ShieldDecision:
    """Giving way (`ShieldConfig.give_way`) in the environments ``envs`` (E,) alone.

    ``decision``: `shield`'s without giving way, (B, N) each; returns theirs with it, (E, N)
    each, as `shield` with ``cfg`` would decide them: the environments are independent. For a
    caller that gives way only where it needs to (`remarl_fc.offline.shielding.Shielded`, where
    its swarm planner found no plan).
    """
    return _give_way(
        cfg,
        vehicle,
        _of_envs(swarm, envs),
        _of_envs(threats, envs),
        np.clip(np.asarray(proposed, dtype=np.float64)[envs], -1.0, 1.0),
        _of_envs(decision, envs),
    )


def _give_way(
    cfg: ShieldConfig,
    vehicle: Vehicle,
    swarm: Swarm,
    threats: Threats,
    prop: FloatArray,
    decision: ShieldDecision,
) -> ShieldDecision:
    """``decision`` with the neighbours of boxed-in UAVs making room (`ShieldConfig.give_way`).

    Batched over every (environment, heading) tried; the environments where no heading works
    keep ``decision``.
    """
    inner = dataclasses.replace(cfg, mode="on", give_way=0)
    # whether a fixed heading passes: the plain check of one pass, nothing substituted
    check = dataclasses.replace(inner, passes=1, return_deg=180.0, fly_out=False, escape_steps=1)
    b, n = prop.shape
    fixed = np.zeros((b, n), dtype=bool)
    held = prop.copy()  # the proposals, the fixed UAVs' headings in their place
    tried = np.zeros((b, n), dtype=bool)
    grid = candidate_grid(cfg.headings)
    out = {f.name: getattr(decision, f.name).copy() for f in dataclasses.fields(ShieldDecision)}
    for _ in range(GIVE_WAY_ROUNDS):
        stuck = swarm.deciding & ~out["safe_exists"] & ~tried
        envs = np.flatnonzero(stuck.any(axis=-1))
        if not envs.size:
            break
        e = len(envs)
        rows = np.arange(e)
        who = stuck[envs].argmax(axis=-1)  # (E,) the first boxed-in UAV of each
        tried[envs, who] = True
        base = held[envs]
        # 1. its headings of one step clear of the intruders alone (no neighbour present)
        one = np.zeros((e, n), dtype=bool)
        one[rows, who] = True
        alone = dataclasses.replace(_of_envs(swarm, envs), deciding=one, present=one)
        sub_threats = _of_envs(threats, envs)
        lone = _decide(
            check, vehicle, alone, sub_threats, base, [Commitment(base, alone.speed_m_s, one)]
        )
        own = base[rows, who]
        values = np.concatenate([np.broadcast_to(grid, (e, len(grid))), own[:, None]], axis=1)
        clear = np.concatenate(
            [lone.safe_headings[rows, who], ~lone.intervened[rows, who][:, None]], axis=1
        )
        near = np.where(clear, np.abs(values - own[:, None]), np.inf)
        order = np.argsort(near, axis=1, kind="stable")[:, : cfg.give_way]  # (E, C)
        pe, pc = np.nonzero(np.isfinite(np.take_along_axis(near, order, axis=1)))
        if not pe.size:
            continue
        # 2. each (environment, heading): the UAV fixed on it, the others decide again
        hyp = envs[pe]
        r = np.arange(len(pe))
        h_swarm = _of_envs(swarm, hyp)
        h_threats = _of_envs(threats, hyp)
        h_prop = base[pe].copy()
        h_prop[r, who[pe]] = np.take_along_axis(values, order, axis=1)[pe, pc]
        h_fixed = fixed[hyp].copy()
        h_fixed[r, who[pe]] = True
        deciding = h_swarm.deciding & ~h_fixed
        again = shield(
            inner, vehicle, dataclasses.replace(h_swarm, deciding=deciding), h_threats, h_prop
        )
        act = np.where(deciding, again.shield_action, h_prop)
        first = np.where(deciding, again.shield_speed_m_s, h_swarm.speed_m_s)
        # 3. every fixed UAV's heading against what the others now fly
        flown = act.astype(np.float64)
        final = _decide(
            check,
            vehicle,
            dataclasses.replace(h_swarm, deciding=h_fixed & h_swarm.deciding),
            h_threats,
            flown,
            [Commitment(flown, first, np.ones_like(h_fixed))],
        )
        passes = ~np.logical_or.reduce(final.intervened & h_fixed, axis=-1)
        lost = deciding & out["safe_exists"][hyp] & ~again.safe_exists
        good = passes & ~np.logical_or.reduce(lost, axis=-1)
        # the first good heading of each environment, in the order tried (pe, pc row-major)
        ks = np.flatnonzero(good)
        ks = ks[np.unique(pe[ks], return_index=True)[1]]
        env, fix = hyp[ks], h_fixed[ks]
        mine = fix & ~fixed[env]
        out["action"][env] = out["shield_action"][env] = act[ks]
        out["speed_m_s"][env] = out["shield_speed_m_s"][env] = first[ks]
        out["safe_exists"][env] = fix | again.safe_exists[ks]
        out["intervened"][env] = np.where(
            fix, act[ks] != prop[env].astype(np.float32), again.intervened[ks]
        )
        out["flown_cpa_m"][env] = np.where(fix, final.proposed_cpa_m[ks], again.flown_cpa_m[ks])
        out["safe_headings"][env] = np.where(
            mine[..., None], out["safe_headings"][env], again.safe_headings[ks]
        )
        held[env] = np.where(fix, act[ks], held[env])
        fixed[env] = fix
    if cfg.mode == "monitor":
        out["action"] = prop.astype(np.float32)
        out["speed_m_s"] = np.full((b, n), vehicle.cruise_m_s)
    return ShieldDecision(**out)


@dataclass(frozen=True)
class Commitment:
    """One arc every UAV may fly this step, which its neighbours keep clear of, (B, N) each.

    Attributes:
        action: its heading change. first_m_s: its speed over the coming step (its committed
        speed after it). only: the UAVs for which it is a new arc to check; for the others it
        repeats one already checked and adds no pair.
    """

    action: FloatArray
    first_m_s: FloatArray
    only: BoolArray


def _decide(
    cfg: ShieldConfig,
    vehicle: Vehicle,
    swarm: Swarm,
    threats: Threats,
    prop: FloatArray,
    arcs: list[Commitment],
) -> ShieldDecision:
    """One pass of `shield`: ``prop`` checked against the intruders and the neighbours' arcs."""
    b, n = prop.shape
    cruise = vehicle.cruise_m_s
    full = np.full((b, n), cruise)
    dt, horizon = vehicle.dt_s, max(cfg.horizon_s, vehicle.dt_s)
    # tracked intruders are checked over their own, shorter look-ahead (a cut where it ends)
    tracked = bool(threats.tracked.any())
    cuts = (cfg.neighbour_horizon_s, cfg.track_horizon_s) if tracked else (cfg.neighbour_horizon_s,)
    motion = swarm.motion
    if motion is not None:  # the end of the steps the response is flown exactly: a knot
        cuts = (*cuts, PREDICTED_STEPS * dt)
    base_cuts = cuts
    if cfg.escape_steps > 1:  # the chords of the turns held after the coming step (`_escape`)
        cuts = (*cuts, *_knots(dt, cfg.escape_steps))
    times, split = _times(dt, horizon, cuts)  # (P,)
    later = times[CHORDS + 1 :]  # the instants after the coming step
    a_max = vehicle.max_turn_rad
    deciding = swarm.deciding
    # Every UAV's proposal at 1 m/s, (B, N, 1, P): its own first candidate; and each arc its
    # neighbours check against (at its speed), the proposal itself first unless they expect it
    # to fly straight on (`ShieldConfig.neighbour_arcs`). With the fitted response, each arc
    # as the vehicle flies it instead (`sim.dynamics.predict_response`).
    if motion is None:
        committed = _unit_arcs(swarm, prop, vehicle, horizon, split)
        theirs = [
            _committed_path(
                committed
                if arc.action is prop
                else _unit_arcs(swarm, arc.action, vehicle, horizon, split),
                arc,
                swarm,
            )
            for arc in arcs
        ]
    else:  # one prediction for all of them: the proposal at full speed, then each arc
        mine_now, *theirs = _responses(swarm, motion, vehicle, prop, full, arcs, later)
    paths = _threat_paths(
        cfg,
        vehicle,
        swarm,
        threats,
        list(zip(arcs, theirs, strict=True)),
        times,
        required_m(cfg, vehicle),
    )

    # 1. The proposal of every UAV at full speed: most pass, and their decision is made.
    if motion is None:
        unit_x, unit_y = (d.reshape(-1, b * n, 1) for d in _time_first(committed))
        at = np.float32(cruise)
        own = (_flown(unit_x, at, cruise), _flown(unit_y, at, cruise))  # (P, B·N, 1)
    else:
        own = (
            np.ascontiguousarray(mine_now[0], dtype=np.float32).reshape(-1, b * n, 1),
            np.ascontiguousarray(mine_now[1], dtype=np.float32).reshape(-1, b * n, 1),
        )
    clear, cpa, rank = _clearance(own, paths.owner, paths, (b, n), vehicle.d_col_m)
    proposed_cpa = cpa[..., 0]
    fails = deciding & (clear[..., 0] < 0.0)
    turn, speed, flown_cpa = prop.copy(), full.copy(), proposed_cpa.copy()
    found = ~fails
    safe_headings = np.zeros((b, n, cfg.headings), dtype=bool)
    if fails.any():
        # 2. The failing UAVs' bands: every heading change at full speed, then slower ones.
        grid = np.broadcast_to(candidate_grid(cfg.headings), (b, n, cfg.headings))
        speeds = [cruise]
        if vehicle.can_slow:
            speeds += [f * cruise for f in cfg.slow_fractions]
        if motion is None:  # (P, F, K): the F failing UAVs' candidates only
            unit_x, unit_y = _unit_candidates(swarm, fails, grid[fails], vehicle, horizon, split)
        else:  # every speed's candidates in one prediction, (P, F, speeds · K)
            k = cfg.headings
            cand_x, cand_y = _time_first(
                predict_response(
                    swarm.heading_rad[fails],
                    np.tile(grid[fails] * a_max, len(speeds)),
                    np.repeat(speeds, k),
                    cruise,
                    motion.of(fails),
                    dt,
                    CHORDS,
                    later,
                )
            )
        row = np.cumsum(fails.reshape(-1)) - 1  # each failing UAV's place among them
        best = rank[..., 0].copy()  # the fallback's rank so far (`_rank`)
        fallback = (prop.copy(), full.copy(), proposed_cpa.copy())
        # fastest first, each batched over every UAV, heading and threat
        for i, v in enumerate(speeds):
            todo = fails & ~found
            if not todo.any():
                break
            mine = paths.of(todo)
            if motion is None:
                at = np.float32(v)
                flown = (_flown(unit_x, at, cruise), _flown(unit_y, at, cruise))
            else:
                flown = (cand_x[..., i * k : (i + 1) * k], cand_y[..., i * k : (i + 1) * k])
            c, d, u = _clearance(flown, row[mine.owner], mine, (b, n), vehicle.d_col_m)
            ok = (c >= 0.0) & todo[..., None]
            if v == cruise:
                safe_headings = ok
            pick = np.where(ok, np.abs(grid - prop[..., None]), np.inf).argmin(axis=-1)
            now = ok.any(axis=-1)
            turn = np.where(now, _at(grid, pick), turn)
            flown_cpa = np.where(now, _at(d, pick), flown_cpa)
            speed = np.where(now, v, speed)
            found = found | now
            top = u.argmax(axis=-1)
            better = todo & ~now & (_at(u, top) > best)
            best = np.where(better, _at(u, top), best)
            fallback = (
                np.where(better, _at(grid, top), fallback[0]),
                np.where(better, v, fallback[1]),
                np.where(better, _at(d, top), fallback[2]),
            )
        # held turns only where every intruder is known exactly: against ADS-B tracks, whose
        # position errors the check does not model, they cost the real world (docs/MODEL.md §21)
        todo = fails & ~found & ~np.logical_or.reduce(threats.tracked, axis=-1)[:, None]
        if cfg.escape_steps > 1 and todo.any():
            # 3. A full turn held over the next decisions, for the UAVs still without one.
            held = _escape(cfg, vehicle, swarm, prop, todo, paths, times)
            turn = np.where(held.passes, held.first, turn)
            flown_cpa = np.where(held.passes, held.cpa_m, flown_cpa)
            found = found | held.passes
            # where none passes either, the least dangerous of them competes for the fallback
            better = todo & ~held.passes & (held.top_rank > best)
            fallback = (
                np.where(better, held.top_first, fallback[0]),
                np.where(better, cruise, fallback[1]),
                np.where(better, held.top_cpa_m, fallback[2]),
            )
        # 4. Nothing passes: the least dangerous (`_rank`), of one step or held.
        turn = np.where(found, turn, fallback[0])
        speed = np.where(found, speed, fallback[1])
        flown_cpa = np.where(found, flown_cpa, fallback[2])

    # 5. A UAV that would fly away from its target while a turn back towards it passes: that
    # turn (`_homeward`).
    homed = np.zeros((b, n), dtype=bool)
    if cfg.return_deg < 180.0:
        after = swarm.heading_rad + turn * a_max
        away = deciding & found & (speed == cruise) & (_off_course(swarm, after) > cfg.return_rad)
        if away.any():
            home = _homeward(cfg, vehicle, swarm, threats, arcs, away, base_cuts)
            homed = home.passes
            turn = np.where(homed, home.first, turn)
            flown_cpa = np.where(homed, home.cpa_m, flown_cpa)

    # 6. A UAV circling a target its tightest turn never reaches, while flying straight on
    # passes: straight on (`_fly_out`).
    out = np.zeros((b, n), dtype=bool)
    if cfg.fly_out and motion is None:  # the circle is the ideal vehicle's, flown exactly
        circling = deciding & found & (speed == cruise) & ~homed & _circling(swarm, vehicle, turn)
        if circling.any():
            out, cpa = _fly_out(cfg, vehicle, swarm, paths, circling, split)
            turn = np.where(out, 0.0, turn)
            flown_cpa = np.where(out, cpa, flown_cpa)

    shield_action = turn.astype(np.float32)
    if cfg.mode == "monitor":
        act, flown_speed = prop.astype(np.float32), full
    else:
        act, flown_speed = shield_action, speed
    return ShieldDecision(
        action=act,
        speed_m_s=flown_speed,
        intervened=fails | homed | out,
        safe_exists=found,
        proposed_cpa_m=np.where(deciding, proposed_cpa, np.inf),
        flown_cpa_m=np.where(deciding, flown_cpa, np.inf),
        shield_action=shield_action,
        shield_speed_m_s=speed,
        safe_headings=safe_headings,
    )


@dataclass(frozen=True)
class HeldTurns:
    """What `_escape` found for the UAVs it tried, (B, N) each.

    Attributes:
        passes: a plan passes. first: the first step of the one flown (±1, normalised).
        cpa_m: its predicted closest approach. top_rank, top_first, top_cpa_m: where none
        passes, the least dangerous plan (`_rank`): its rank, first step and closest approach,
        which compete with the one-step candidates for the fallback.
    """

    passes: BoolArray
    first: FloatArray
    cpa_m: FloatArray
    top_rank: FloatArray
    top_first: FloatArray
    top_cpa_m: FloatArray


def _escape(
    cfg: ShieldConfig,
    vehicle: Vehicle,
    swarm: Swarm,
    prop: FloatArray,
    todo: BoolArray,
    paths: ThreatPaths,
    times: FloatArray,
) -> HeldTurns:
    """Full turns held over 2 … ``cfg.escape_steps`` steps for the UAVs ``todo`` (B, N).

    Each such plan turns by a_max at this decision and at the next ones, then flies straight
    on: a turn wider than one step gives, which the one-step candidates cannot see. The fewest
    steps that pass first; among the two sides, the one nearer the proposal. Only its first
    step is flown: the next decision checks again, and its neighbours keep clear of that step
    then straight on, as of any other decision (they re-plan every step; keeping clear of the
    whole turn changed nothing measurable, docs/MODEL.md §21). Where none passes, the least
    dangerous plan competes for the fallback with the one-step candidates, by `_rank`.
    """
    b, n = prop.shape
    motion = swarm.motion
    # a fitted vehicle's plans: as far as its response is flown exactly (`PREDICTED_STEPS`)
    longest = cfg.escape_steps if motion is None else min(cfg.escape_steps, PREDICTED_STEPS)
    held = np.arange(2, longest + 1)  # (H,) steps of each plan's turn
    side = np.array([-1.0, 1.0])
    firsts = np.tile(side, len(held))  # (C,) = (H · 2,)
    steps = np.repeat(held, len(side))
    turns = np.where(np.arange(longest) < steps[:, None], firsts[:, None], 0.0)
    turns *= vehicle.max_turn_rad  # (C, S) each plan's turn per step
    start = swarm.heading_rad[todo]  # (F,)
    flown = _plans_flown(vehicle, start, turns, None if motion is None else motion.of(todo), times)
    row = np.cumsum(todo.reshape(-1)) - 1  # each UAV's place among them
    mine = paths.of(todo)
    clear, cpa, rank = _clearance(
        (flown[0], flown[1]), row[mine.owner], mine, (b, n), vehicle.d_col_m
    )
    ok = (clear >= 0.0) & todo[..., None]
    order = steps + 0.25 * np.abs(firsts - prop[..., None])  # (B, N, C); |offset| ≤ 2
    pick = np.where(ok, order, np.inf).argmin(axis=-1)
    top = rank.argmax(axis=-1)
    return HeldTurns(
        passes=np.logical_or.reduce(ok, axis=-1),
        first=firsts[pick],
        cpa_m=_at(cpa, pick),
        top_rank=_at(rank, top),
        top_first=firsts[top],
        top_cpa_m=_at(cpa, top),
    )


@dataclass(frozen=True)
class Homeward:
    """What `_homeward` found, (B, N) each.

    Attributes:
        passes: the turn back towards the target passes. first: its first step (normalised).
        cpa_m: its predicted closest approach.
    """

    passes: BoolArray
    first: FloatArray
    cpa_m: FloatArray


def _to_target(swarm: Swarm, heading_rad: FloatArray) -> FloatArray:
    """(B, N) each UAV's bearing to its target less ``heading_rad``, (−π, π] (> 0: left)."""
    gap = swarm.target_m - swarm.pos_m
    out: FloatArray = wrap_angle(np.arctan2(gap[..., 1], gap[..., 0]) - heading_rad)
    return out


def _off_course(swarm: Swarm, heading_rad: FloatArray) -> FloatArray:
    """(B, N) how far ``heading_rad`` lies from each UAV's bearing to its target, [0, π]."""
    out: FloatArray = np.abs(_to_target(swarm, heading_rad))
    return out


def _reachable(swarm: Swarm, vehicle: Vehicle, side: FloatArray) -> BoolArray:
    """(B, N) the UAVs whose tightest turn to ``side`` is taken to reach their target.

    ``side`` (B, N): +1 to the left, −1 to the right. Turning on at a_max flies a circle (at the
    paper's defaults, 10 m/s and 45° a step of 2 s, 25.5 m radius). Flown exactly (the ideal
    vehicle), it comes within d_col of every target but those within radius − d_col of its
    centre (`_out_of_reach`): the UAV has to fly out first (`_fly_out`). A vehicle flown with
    its fitted response turns later and wider than that circle, so for it a target anywhere
    inside the circle counts as out of reach (measured: the exact rule for it too raised the
    real world's UAV–UAV collisions, docs/MODEL.md §21, "Flying out of a circle").
    """
    if swarm.motion is None:
        return ~_out_of_reach(swarm, vehicle, side)
    radius = vehicle.cruise_m_s * vehicle.dt_s / vehicle.max_turn_rad
    out: BoolArray = _from_centre(swarm, side, radius) >= radius
    return out


def _out_of_reach(swarm: Swarm, vehicle: Vehicle, side: FloatArray) -> BoolArray:
    """(B, N) the UAVs whose tightest turn to ``side`` never comes within d_col of their target.

    Turning on at a_max flies a circle; where the target lies within radius − d_col of its
    centre (5.5 m at the paper's defaults: 20 m a step and 45°, a circle of 25.5 m radius), the
    circle stays more than d_col from it: the UAV circles it until it flies out (`_fly_out`).
    Never where the radius is d_col or less.
    """
    radius = vehicle.cruise_m_s * vehicle.dt_s / vehicle.max_turn_rad
    out: BoolArray = _from_centre(swarm, side, radius) < radius - vehicle.d_col_m
    return out


def _from_centre(swarm: Swarm, side: FloatArray, radius_m: float) -> FloatArray:
    """(B, N) each UAV's target's distance from the centre of a turn, metres.

    The turn of ``radius_m`` to ``side`` (B, N): +1 to the left, −1 to the right.
    """
    gap = swarm.target_m - swarm.pos_m
    h = swarm.heading_rad
    cx = gap[..., 0] + radius_m * side * np.sin(h)
    cy = gap[..., 1] - radius_m * side * np.cos(h)
    out: FloatArray = np.hypot(cx, cy)
    return out


def _circling(swarm: Swarm, vehicle: Vehicle, turn: FloatArray) -> BoolArray:
    """(B, N) the UAVs that turn towards a target their tightest turn cannot reach.

    Their decided ``turn`` (normalised) turns towards the target, which their tightest turn
    that way circles without reaching (`_out_of_reach`).
    """
    side = np.where(_to_target(swarm, swarm.heading_rad) < 0.0, -1.0, 1.0)
    out: BoolArray = (turn * side > 0.0) & _out_of_reach(swarm, vehicle, side)
    return out


def _fly_out(
    cfg: ShieldConfig,
    vehicle: Vehicle,
    swarm: Swarm,
    paths: ThreatPaths,
    circling: BoolArray,
    split: list[float],
) -> tuple[BoolArray, FloatArray]:
    """Straight on at the cruise speed for the UAVs ``circling`` (B, N), checked.

    Flown exactly, as the ideal vehicle flies (`_decide` calls it for no other), and checked
    like any one-step candidate against the intruders and the neighbours' arcs (``paths``, as
    `_decide` built them; ``split``: its cuts of the straight part, `_times`). Returns
    (passes, closest approach), (B, N) each.
    """
    b, n = circling.shape
    straight = np.zeros((int(circling.sum()), 1))
    horizon = max(cfg.horizon_s, vehicle.dt_s)
    unit_x, unit_y = _unit_candidates(swarm, circling, straight, vehicle, horizon, split)
    at, cruise = np.float32(vehicle.cruise_m_s), vehicle.cruise_m_s
    flown = (_flown(unit_x, at, cruise), _flown(unit_y, at, cruise))  # (P, F, 1)
    mine = paths.of(circling)
    row = np.cumsum(circling.reshape(-1)) - 1  # each UAV's place among them
    clear, cpa, _ = _clearance(flown, row[mine.owner], mine, (b, n), vehicle.d_col_m)
    return circling & (clear[..., 0] >= 0.0), cpa[..., 0]


def _unit_candidates(
    swarm: Swarm,
    uavs: BoolArray,
    actions: FloatArray,
    vehicle: Vehicle,
    horizon_s: float,
    split: list[float],
) -> tuple[Float32Array, Float32Array]:
    """(x, y), each (P, F, K): the F UAVs ``uavs``' one-step candidates at 1 m/s, time first.

    ``actions`` (F, K) normalised heading changes, each an arc over the coming step then
    straight on to ``horizon_s``, exact at the points of `_times` (``split``: its cuts).
    """
    return _time_first(
        _at_times(
            displacements(
                swarm.heading_rad[uavs],
                actions * vehicle.max_turn_rad,
                1.0,
                vehicle.dt_s,
                horizon_s,
                CHORDS,
            ),
            split,
        )
    )


def _homeward(
    cfg: ShieldConfig,
    vehicle: Vehicle,
    swarm: Swarm,
    threats: Threats,
    arcs: list[Commitment],
    away: BoolArray,
    cuts: tuple[float, ...],
) -> Homeward:
    """The turn back towards the target of the UAVs ``away`` (B, N), checked.

    Full turns at a_max towards the bearing to the target, the last one the rest of the angle,
    then straight on, exact at a knot in the middle and at the end of every step of the turn
    (`_turns`); where that does not pass, the long way round, turning away first (an intruder
    alongside, between the UAV and its target, may leave no room to turn towards it, and all
    the room to loop the other way behind it). A vehicle flown with its fitted response: the
    first two steps of either way through its response, then its final heading held
    (`sim.dynamics.predict_response`). Checked like any candidate: against the intruders over
    the look-ahead and the neighbours' arcs over theirs (``arcs``, flown as `_decide` flies
    them); ``cuts``: `_decide`'s, but for the held turns' knots.
    """
    b, n = away.shape
    a_max, dt = vehicle.max_turn_rad, vehicle.dt_s
    horizon = max(cfg.horizon_s, dt)
    motion = swarm.motion
    error = _to_target(swarm, swarm.heading_rad)  # (B, N)
    side = np.where(error < 0.0, -1.0, 1.0)  # the short way
    # (B, N, 2): the short way, the long way
    reach = np.stack([_reachable(swarm, vehicle, side), _reachable(swarm, vehicle, -side)], -1)
    away = away & np.logical_or.reduce(reach, axis=-1)
    if not away.any():
        none = np.zeros((b, n), dtype=bool)
        return Homeward(none, np.zeros((b, n)), np.full((b, n), np.inf))
    start = swarm.heading_rad[away]  # (F,)
    short = np.abs(error[away])
    signs = np.stack([side[away], -side[away]], axis=-1)  # (F, 2): the short way, the long
    angles = np.stack([short, 2.0 * np.pi - short], axis=-1)
    steps = max(2, math.ceil(float(angles.max()) / a_max - 1e-9))
    if motion is not None:  # its response is predicted exactly over two steps
        steps = PREDICTED_STEPS
    turns = signs[..., None] * np.clip(
        angles[..., None] - a_max * np.arange(steps), 0.0, a_max
    )  # (F, 2, S)
    # checked against the neighbours for longer than other candidates: it overrides a decision
    # that passed, so it must not hand a neighbour a conflict just past their 4 s
    cfg = dataclasses.replace(cfg, neighbour_horizon_s=cfg.return_neighbour_horizon_s)
    times, split = _times(dt, horizon, (*cuts, cfg.return_neighbour_horizon_s, *_knots(dt, steps)))
    if motion is None:
        theirs = [
            _committed_path(_unit_arcs(swarm, a.action, vehicle, horizon, split), a, swarm)
            for a in arcs
        ]
    else:
        theirs = _responses(swarm, motion, vehicle, None, None, arcs, times[CHORDS + 1 :])
    committed = list(zip(arcs, theirs, strict=True))
    flown = _plans_flown(vehicle, start, turns, None if motion is None else motion.of(away), times)
    # a UAV hovering where it arrived is kept clear of over the whole look-ahead, as a static
    # intruder: the turn back heads where the swarm's targets are, and it stays there. One
    # that flies, decided elsewhere (a peer process's, `fly` over the swarm bus), is a
    # neighbour on its arc like any other
    parked = swarm.present & ~swarm.deciding & (swarm.speed_m_s == 0.0)
    mine = dataclasses.replace(swarm, deciding=away, present=swarm.present & ~parked)
    if parked.any():
        threats = Threats(
            np.concatenate([threats.intruder_pos_m, swarm.pos_m], axis=1),
            np.concatenate([threats.intruder_vel_m_s, np.zeros_like(swarm.pos_m)], axis=1),
            np.concatenate([threats.intruder_known, parked], axis=1),
            np.concatenate([threats.intruder_age_s, np.zeros(parked.shape)], axis=1),
        )
    paths = _threat_paths(cfg, vehicle, mine, threats, committed, times, required_m(cfg, vehicle))
    row = np.cumsum(away.reshape(-1)) - 1  # each UAV's place among them
    clear, cpa, _ = _clearance(
        flown, row[paths.owner], paths, (b, n), vehicle.d_col_m, ranked=False
    )
    ok = (clear >= 0.0) & reach & away[..., None]  # (B, N, 2)
    pick = np.where(ok[..., 0], 0, 1)  # the short way first
    first = np.zeros((b, n, 2))
    first[away] = turns[..., 0] / a_max
    return Homeward(np.logical_or.reduce(ok, axis=-1), _at(first, pick), _at(cpa, pick))


def _unit_arcs(
    swarm: Swarm, action: FloatArray, vehicle: Vehicle, horizon_s: float, split: list[float]
) -> tuple[FloatArray, FloatArray]:
    """(x, y), each (B, N, 1, P): every UAV's arc of ``action`` (B, N), then straight on.

    ``action`` normalised; at 1 m/s, at the points of `_times` (``split``: its cuts in the
    straight part).
    """
    return _at_times(
        displacements(
            swarm.heading_rad,
            action[..., None] * vehicle.max_turn_rad,
            1.0,
            vehicle.dt_s,
            horizon_s,
            CHORDS,
        ),
        split,
    )


def _responses(
    swarm: Swarm,
    motion: Motion,
    vehicle: Vehicle,
    action: FloatArray | None,
    first_m_s: FloatArray | None,
    arcs: list[Commitment],
    later_s: FloatArray,
) -> list[tuple[FloatArray, FloatArray]]:
    """Arcs flown through every UAV's fitted response, in one prediction: (x, y), each (P, B, N).

    ``action`` at ``first_m_s`` then the cruise speed first, where given (a UAV's own
    candidate), then each of ``arcs`` at its speeds (what the neighbours keep clear of).
    """
    cruise = np.full(swarm.heading_rad.shape, vehicle.cruise_m_s)
    own = [] if action is None or first_m_s is None else [(action, first_m_s, cruise)]
    each: list[tuple[FloatArray, FloatArray, FloatArray]] = [
        *own,
        *((a.action, a.first_m_s, swarm.speed_m_s) for a in arcs),
    ]
    px, py = predict_response(
        swarm.heading_rad,
        np.stack([e[0] for e in each], axis=-1) * vehicle.max_turn_rad,
        np.stack([e[1] for e in each], axis=-1),
        np.stack([e[2] for e in each], axis=-1),
        motion,
        vehicle.dt_s,
        CHORDS,
        later_s,
    )  # (B, N, arcs, P)
    return [
        (np.moveaxis(px[..., k, :], -1, 0), np.moveaxis(py[..., k, :], -1, 0))
        for k in range(len(each))
    ]


def _plans_flown(
    vehicle: Vehicle,
    start: FloatArray,
    turns: FloatArray,
    motion: Motion | None,
    times: FloatArray,
) -> tuple[Float32Array, Float32Array]:
    """(P, F, C) displacements of plans turning by ``turns`` (…, C, S ≥ 2) a step, then straight.

    ``start`` (F,): the headings of the UAVs flying them. The ideal vehicle flies them exactly
    (`_turns`, at ``times``); a fitted one (``motion``: those UAVs') through its response over
    the first two steps, then its final heading held (`sim.dynamics.predict_response`).
    """
    if motion is None:
        z = _turns(start[:, None], turns, vehicle.dt_s, times) * vehicle.cruise_m_s
        return _time_first((z.real, z.imag))
    wide = np.broadcast_to(turns, (len(start), *turns.shape[-2:]))
    return _time_first(
        predict_response(
            start,
            wide[..., 0],
            vehicle.cruise_m_s,
            vehicle.cruise_m_s,
            motion,
            vehicle.dt_s,
            CHORDS,
            times[CHORDS + 1 :],
            second_rad=wide[..., 1],
        )
    )


def _knots(dt_s: float, steps: int) -> tuple[float, ...]:
    """The chords' ends of the steps after the coming one, of a plan turning over ``steps``."""
    return tuple(dt_s * (1 + i / CHORDS) for i in range(1, CHORDS * (steps - 1) + 1))


def _turns(
    heading: FloatArray, turns: FloatArray, dt_s: float, times: FloatArray
) -> NDArray[np.complex128]:
    """(..., P) complex displacements at 1 m/s: per-step ``turns`` (..., S), then straight.

    Each step a constant-turn-rate arc (its chord as `sim.prediction.displacements` computes
    it), as the simulator flies the ideal vehicle; exact at ``times`` (P,). ``heading``
    broadcasts against ``turns[..., 0]``; every turn at most a_max ≤ π/2 a step.
    """
    s = turns.shape[-1]
    zeros = np.zeros((*turns.shape[:-1], 1))
    h = np.asarray(heading)[..., None] + np.concatenate([zeros, np.cumsum(turns, -1)], -1)
    rate = np.broadcast_to(np.concatenate([turns, zeros], axis=-1), h.shape)  # per step
    half = 0.5 * rate[..., :s]
    step = dt_s * sinc_series(half) * np.exp(1j * (h[..., :s] + half))  # each whole step
    ends = np.concatenate([np.zeros((*h.shape[:-1], 1)), np.cumsum(step, axis=-1)], axis=-1)
    j = np.minimum((times / dt_s + 1e-9).astype(np.intp), s)  # (P,) the step each time is in
    into = times - j * dt_s
    half_in = 0.5 * rate[..., j] * into / dt_s
    out: NDArray[np.complex128] = ends[..., j] + into * sinc_series(half_in) * np.exp(
        1j * (h[..., j] + half_in)
    )
    return out


CHORDS = 2
"""Chords of the predicted arc (half `sim.prediction`'s): the chord of a 10 m arc turning by
at most π/8 lies within L·a_max/(8·2²) = 0.25 m of it at the defaults, inside the margin;
half the segments of ORCA's four."""


def _times(
    dt_s: float, horizon_s: float, cuts: tuple[float, ...]
) -> tuple[FloatArray, list[float]]:
    """The time points of every check, and where the cuts split the straight part.

    The arc's chords, then each cut (the neighbour horizon, the track horizon) that lies inside
    the straight part, in order, then the horizon; the cuts kept as fractions of the straight
    part.
    """
    arc = [i * (dt_s / CHORDS) for i in range(CHORDS)] + [dt_s]  # `time_points`'s values
    if horizon_s <= dt_s:
        return np.array(arc), []
    inner = sorted({c for c in cuts if dt_s < c < horizon_s})
    fractions = [(c - dt_s) / (horizon_s - dt_s) for c in inner]
    return np.array([*arc, *inner, horizon_s]), fractions


def _at_times(
    xy: tuple[FloatArray, FloatArray], fractions: list[float]
) -> tuple[FloatArray, FloatArray]:
    """`sim.prediction.displacements` (..., P) at the points of `_times`.

    The cuts inserted: the straight part is linear in time, so they are interpolated exactly.
    """
    if not fractions:
        return xy
    out = []
    for d in xy:
        cut = [d[..., -2] + f * (d[..., -1] - d[..., -2]) for f in fractions]
        out.append(np.concatenate([d[..., :-1], np.stack(cut, axis=-1), d[..., -1:]], axis=-1))
    return out[0], out[1]


def _committed_path(
    unit: tuple[FloatArray, FloatArray], arc: Commitment, swarm: Swarm
) -> tuple[FloatArray, FloatArray]:
    """A committed arc's (P, B, N) displacements as flown, from its 1 m/s ones (B, N, 1, P).

    The coming step at the arc's own speed, then on at the committed speed.
    """
    x, y = (
        _flown(np.moveaxis(d[..., 0, :], -1, 0), arc.first_m_s[None], swarm.speed_m_s[None])
        for d in unit
    )  # (P, B, N)
    return x, y


def _time_first(xy: tuple[FloatArray, FloatArray]) -> tuple[Float32Array, Float32Array]:
    """Displacements (..., K, P) as C-contiguous float32 (P, ..., K).

    Time first, so that every segment operation runs over contiguous blocks (an elementwise
    result keeps its input's memory order: a moved axis alone would leave time innermost).
    float32: relative positions of a few hundred metres keep 0.1 mm, and the segment
    arithmetic, most of the shield's time, moves half the bytes.
    """
    x, y = (np.ascontiguousarray(np.moveaxis(d, -1, 0), dtype=np.float32) for d in xy)
    return x, y


def _checked(times: FloatArray, until_s: float | FloatArray) -> BoolArray:
    """The segments that start before ``until_s``, (P − 1, 1, 1) or against its shape.

    ``until_s``: a look-ahead, one per threat where an array; past it nothing is required.
    """
    until = np.asarray(until_s)
    starts = times[:-1].reshape(-1, *([1] * max(until.ndim, 2)))
    out: BoolArray = starts < until - 1e-9
    return out


def required_m(cfg: ShieldConfig, vehicle: Vehicle) -> float:
    """The separation every check requires before uncertainty: d_col + margin, metres."""
    return vehicle.d_col_m + cfg.margin_m


def _at(values: FloatArray, index: NDArray[np.intp]) -> FloatArray:
    """values[..., index] for (B, N, K) values and (B, N) indices."""
    out: FloatArray = np.take_along_axis(values, index[..., None], -1)[..., 0]
    return out


def _clearance(
    flown: tuple[Float32Array, Float32Array],
    row: NDArray[np.intp],
    paths: ThreatPaths,
    swarm_shape: tuple[int, int],
    d_col_m: float,
    ranked: bool = True,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(clearance, closest approach, rank), each (B, N, K), of the candidates at one speed.

    ``flown`` (x, y), each (P, R, K) (`_time_first`): the candidates' displacements at that
    speed; ``row`` (S,): the row of each pair's UAV. Clearance:
    the smallest (distance − required) over every threat and segment; +inf with no threat
    (and the closest approach +inf too). Rank: `_rank`, what the fallback flies the highest of
    when nothing passes (+inf, not computed, unless ``ranked``).
    """
    b, n = swarm_shape
    k = flown[0].shape[-1]
    clearance = np.full((b, n, k), np.inf)
    cpa_sq = np.full((b, n, k), np.inf)
    rank = np.full((b, n, k), np.inf)
    if not len(paths.owner):
        return clearance, np.sqrt(cpa_sq), rank
    # Time first from here on: every segment operation runs over contiguous blocks.
    rx = flown[0][:, row]  # (P, S, K), contiguous float32
    rx += paths.rel_x[..., None]
    ry = flown[1][:, row]
    ry += paths.rel_y[..., None]
    seg = segment_closest_sq(rx, ry, paths.reach[..., None])
    seg[paths.after] = np.inf  # segments that start after the arrival
    pair_cpa = seg.min(axis=0)  # (S, K)
    np.sqrt(seg, out=seg)
    seg -= paths.need[..., None]
    pair_clear = seg.min(axis=0)
    # Per UAV: the worst pair (the pairs come grouped by owner, in order).
    starts = paths.starts
    owners = paths.owner[starts]
    worst = np.minimum.reduceat(pair_clear, starts, axis=0)  # (owners, K)
    clearance.reshape(b * n, k)[owners] = worst
    cpa_sq.reshape(b * n, k)[owners] = np.minimum.reduceat(pair_cpa, starts, axis=0)
    # The rank, for the UAVs none of whose candidates passes (the fallback's only): from their
    # pairs' near segments (the rest weigh nothing), a predicted collision being closer than
    # d_col itself (not the margin, not a track's uncertainty), weighed by how sure and how
    # near it is.
    hopeless = (worst < 0.0).all(axis=-1)
    if ranked and hopeless.any():
        pairs = np.repeat(hopeless, np.diff(np.append(starts, len(paths.owner))))
        near = len(paths.severity)
        mine = seg[:near, pairs]  # (Q, S', K) clearances
        distance = mine + paths.need[:near, pairs, None]
        danger = np.where(distance < d_col_m, paths.severity[:, pairs, None], np.uint8(0))
        firsts = _group_starts(paths.owner[pairs])
        rank.reshape(b * n, k)[owners[hopeless]] = _rank(
            worst[hopeless],
            np.minimum.reduceat(mine.min(axis=0), firsts, axis=0),
            np.maximum.reduceat(danger.max(axis=0), firsts, axis=0),
        )
    return clearance, np.sqrt(cpa_sq), rank


COLLISION_NOW, COLLISION_INTRUDER_SOON, COLLISION_NEIGHBOUR_SOON = 3, 2, 1
"""How much a collision predicted in a segment weighs in the fallback's `_rank` (0: none, or
beyond the neighbour look-ahead): in the coming step, which is flown whatever the next
decisions do, most; with an intruder within the neighbour look-ahead (it flies on straight, as
predicted), less; with a neighbour in it (it decides again next step, and keeps clear too),
least."""

RANK_TIER_M = 1e6
"""Weight of one level of `_rank`'s danger, metres of clearance: more than any clearance a check
can see (a few kilometres), so the danger decides and the metres break ties."""


def _rank(clearance: FloatArray, near_clear: FloatArray, danger: NDArray[np.uint8]) -> FloatArray:
    """The fallback's rank of candidates, (R, K) (higher: flown first when nothing passes).

    ``danger``: the heaviest predicted collision of each candidate (`COLLISION_NOW`, ...; 0:
    none within the neighbour look-ahead). Lower danger first; among equals, the largest
    clearance over the segments that can weigh (within the neighbour look-ahead) where some
    collision is predicted there, else over the whole look-ahead, as the shield did before.
    The largest clearance alone traded a collision with a neighbour in the coming step for more
    room from an intruder twenty seconds away, which the coming decisions can still turn from
    (docs/MODEL.md §21).
    """
    hit = danger > 0
    metres = np.clip(np.where(hit, near_clear, clearance), -RANK_TIER_M / 4, RANK_TIER_M / 4)
    out: FloatArray = metres - danger * RANK_TIER_M
    return out


def _flown(unit: NDArray[F], first_m_s: Any, then_m_s: Any) -> NDArray[F]:
    """Displacements (P, ...) of arcs flown at ``first_m_s``, then ``then_m_s``, from 1 m/s ones.

    The arc at the first speed over the coming step, then on at the second: a candidate slowed
    down (or stopped) holds for one step and the next decision goes on at the cruise speed, so
    a stop never hides a conflict beyond the horizon by standing in an intruder's way; a
    neighbour's committed arc goes on at its committed speed. Speeds: scalars (of ``unit``'s
    float type, to keep it) or arrays broadcast against ``unit[0]``.
    """
    out: NDArray[F] = unit * first_m_s
    if not np.array_equal(first_m_s, then_m_s):
        end = CHORDS  # the arc's last point, at dt; the straight part's follow
        out[end + 1 :] = out[end] + (unit[end + 1 :] - unit[end]) * then_m_s
    return out


@dataclass(frozen=True)
class ThreatPaths:
    """Every (UAV, threat) pair to check, and the threat's predicted path relative to it.

    Attributes:
        owner: (S,) b·N + i of each pair's UAV, non-decreasing. starts: where each owner's
        pairs start. rel_x, rel_y: (P, S) the UAV's position now minus the threat's at each
        time point. need: (P − 1, S) the distance each segment requires. reach: (P − 1, S)
        the fraction of each segment flown before the UAV reaches its target (float32).
        after: (P − 1, S) the segments that start after it: not checked. severity: (Q, S)
        the weight of a collision predicted in each of the Q near segments (`_severity`).
    """

    owner: NDArray[np.intp]
    starts: NDArray[np.intp]
    rel_x: FloatArray
    rel_y: FloatArray
    need: FloatArray
    reach: Float32Array
    after: BoolArray
    severity: NDArray[np.uint8]

    @staticmethod
    def grouped(
        owner: NDArray[np.intp],
        rel_x: FloatArray,
        rel_y: FloatArray,
        need: FloatArray,
        reach: Float32Array,
        after: BoolArray,
        severity: NDArray[np.uint8],
    ) -> ThreatPaths:
        """The pairs (sorted by owner) with the start of each owner's group."""
        return ThreatPaths(owner, _group_starts(owner), rel_x, rel_y, need, reach, after, severity)

    def of(self, uavs: BoolArray) -> ThreatPaths:
        """The pairs of the UAVs selected by ``uavs`` (B, N) alone."""
        keep = uavs.reshape(-1)[self.owner]
        return ThreatPaths.grouped(
            self.owner[keep],
            self.rel_x[:, keep],
            self.rel_y[:, keep],
            self.need[:, keep],
            self.reach[:, keep],
            self.after[:, keep],
            self.severity[:, keep],
        )


def _group_starts(owner: NDArray[np.intp]) -> NDArray[np.intp]:
    """Where each run of equal owners starts in ``owner`` (sorted): `np.minimum.reduceat`'s."""
    starts = np.flatnonzero(owner[1:] != owner[:-1]) + 1
    out: NDArray[np.intp] = np.concatenate([np.zeros(min(len(owner), 1), dtype=np.intp), starts])
    return out


def _threat_paths(
    cfg: ShieldConfig,
    vehicle: Vehicle,
    swarm: Swarm,
    threats: Threats,
    committed: list[tuple[Commitment, tuple[FloatArray, FloatArray]]],
    times: FloatArray,
    required: float,
) -> ThreatPaths:
    """The (UAV, threat) pairs that can come within the required distance, and their paths.

    ``committed``: the neighbours' arcs, each with its (P, B, N) displacements as flown
    (`_committed_path`, `sim.dynamics.predict_response`); the first is every UAV's proposal.
    Sorted by UAV. Most of the N·M and N·N pairs are far apart: gathered away, they cost
    nothing.
    """
    b, n = swarm.heading_rad.shape
    horizon = float(times[-1])
    deciding = swarm.deciding
    p = len(times)
    # Every threat of an environment, (P, B, T): its M intruders, then its N UAVs; each UAV's
    # slots (B, N, M + J) name which of them it checks (its J nearest UAVs): the pairs are
    # the slots that count, gathered in (environment, UAV, slot) order (sorted by UAV).
    xs, ys, needs, slots, masks = [], [], [], [], []
    m = threats.intruder_pos_m.shape[1]
    if m:  # intruders: straight at constant velocity; the requirement grows with uncertainty
        q, w = threats.intruder_pos_m, threats.intruder_vel_m_s
        rel = swarm.pos_m[:, :, None] - q[:, None]  # (B, N, M, 2)
        dist = np.hypot(rel[..., 0], rel[..., 1])
        speed = np.hypot(w[..., 0], w[..., 1])  # (B, M)
        age = threats.intruder_age_s
        tracked = threats.tracked  # the unknown are masked out below either way
        ahead_s = np.where(tracked, min(cfg.track_horizon_s, horizon), horizon)  # (B, M)
        grow = np.where(tracked, cfg.track_growth_m_s, 0.0) * (age + ahead_s)
        reach = (vehicle.cruise_m_s + speed + cfg.track_growth_m_s) * ahead_s + required + grow
        masks.append(
            deciding[..., None] & threats.intruder_known[:, None] & (dist <= reach[:, None])
        )
        slots.append(np.broadcast_to(np.arange(m), (b, n, m)))
        t = times[:, None, None]
        xs.append(q[..., 0] + w[..., 0] * t)
        ys.append(q[..., 1] + w[..., 1] * t)
        # a report's error grows with its age and with the time predicted ahead; exact
        # sensing (age 0, the simulator's paper world) has none; past the track horizon
        # nothing is required of a tracked intruder (−inf: never binding)
        growth = np.where(tracked, cfg.track_growth_m_s, 0.0) * (age + times[1:, None, None])
        beyond = tracked & ~_checked(times, ahead_s)
        needs.append(np.where(beyond, -np.inf, required + growth))
    others = min(cfg.neighbours, n - 1)
    if others > 0:  # the nearest present UAVs within reach, on their committed arcs
        rel = swarm.pos_m[:, :, None] - swarm.pos_m[:, None]  # (B, N, N, 2)
        dist = np.hypot(rel[..., 0], rel[..., 1])
        dist[:, np.arange(n), np.arange(n)] = np.inf
        dist = np.where(swarm.present[:, None, :] & deciding[..., None], dist, np.inf)
        both = 2.0 * vehicle.cruise_m_s * horizon + required  # two UAVs closing head-on
        idx = np.argpartition(dist, others - 1, axis=-1)[..., :others]  # (B, N, J)
        near = np.take_along_axis(dist, idx, -1) <= both
        # past the neighbour horizon nothing is required (−inf: never binding)
        ahead = _checked(times, cfg.neighbour_horizon_s)[:, 0, 0]
        need = np.broadcast_to(np.where(ahead, required, -np.inf)[:, None, None], (p - 1, b, n))
        for k, (arc, path) in enumerate(committed):  # threats M + k·N + j: arc k of UAV j
            counts = np.take_along_axis(np.broadcast_to(arc.only[:, None], dist.shape), idx, -1)
            masks.append(near & counts)
            slots.append(m + k * n + idx)
            for out, flown, at in ((xs, path[0], 0), (ys, path[1], 1)):
                out.append(swarm.pos_m[None, ..., at] + flown)
            needs.append(need)
    if not masks:
        empty = np.zeros((p, 0))
        return ThreatPaths.grouped(
            np.zeros(0, dtype=np.intp),
            empty,
            empty,
            empty[1:],
            empty[1:].astype(np.float32),
            np.zeros((p - 1, 0), dtype=bool),
            _severity(times, vehicle.dt_s, cfg.neighbour_horizon_s, np.zeros(0, dtype=bool)),
        )
    env, uav, slot = np.nonzero(np.concatenate(masks, axis=-1))
    threat = np.concatenate(slots, axis=-1)[env, uav, slot]
    # Nothing after a UAV reaches its target is checked: each segment ends there at the
    # latest (the whole coming step is always checked: the UAV flies it).
    gap = swarm.target_m - swarm.pos_m
    to_go = np.maximum(np.hypot(gap[..., 0], gap[..., 1]) / vehicle.cruise_m_s, vehicle.dt_s)
    to_go = to_go[env, uav]  # (S,)
    start, end = times[:-1, None], times[1:, None]
    return ThreatPaths.grouped(
        env * n + uav,
        (swarm.pos_m[env, uav, 0] - np.concatenate(xs, axis=-1)[:, env, threat]).astype(np.float32),
        (swarm.pos_m[env, uav, 1] - np.concatenate(ys, axis=-1)[:, env, threat]).astype(np.float32),
        np.concatenate(needs, axis=-1)[:, env, threat],
        np.clip((to_go - start) / (end - start), 0.0, 1.0).astype(np.float32),
        start >= to_go,
        _severity(times, vehicle.dt_s, cfg.neighbour_horizon_s, threat >= m),
    )


def _severity(
    times: FloatArray, dt_s: float, soon_s: float, neighbour: BoolArray
) -> NDArray[np.uint8]:
    """(Q, S) the weight of a collision predicted in each near segment of each pair (`_rank`).

    The near segments: the Q first, those that start within ``soon_s`` (the neighbour
    look-ahead), at least the coming step's; a collision predicted after them weighs nothing.
    ``neighbour`` (S,): the pair's threat is a UAV of the swarm (else an intruder).
    """
    start = times[:-1, None]
    start = start[: max(CHORDS, int(np.count_nonzero(start < soon_s - 1e-9)))]
    soon = np.where(neighbour, COLLISION_NEIGHBOUR_SOON, COLLISION_INTRUDER_SOON)
    out: NDArray[np.uint8] = np.where(start < dt_s - 1e-9, COLLISION_NOW, soon).astype(np.uint8)
    return out


def vehicle_of(cfg: ScenarioConfig) -> Vehicle:
    """The shield's view of a scenario's vehicles (slowing down where every profile hovers)."""
    names = cfg.dynamics_randomisation.profiles or (cfg.dynamics,)
    return Vehicle(
        d_col_m=cfg.d_col_m,
        dt_s=cfg.dt_s,
        max_turn_rad=cfg.uav.max_turn_rad,
        cruise_m_s=cfg.uav.speed_m_s,
        can_slow=all(load_profile(name).can_hover for name in names),
    )


def shield_state(
    shield_cfg: ShieldConfig,
    cfg: ScenarioConfig,
    state: SwarmState,
    proposed: NDArray[np.floating],
    vehicle: Vehicle | None = None,
) -> ShieldDecision:
    """`shield` on a simulator state: what each UAV knows (exact or ADS-B) and the swarm's plan.

    Intruders are what the UAVs know of them: the exact obstacles that are visible, or the
    ADS-B tracks' picture (`sim.sensors.picture`, its reports' age); neighbours are the other
    UAVs still present (hovering ones at speed 0), on their proposed arcs (`shield_inputs`).
    """
    swarm, threats = shield_inputs(shield_cfg, cfg, state)
    return shield(shield_cfg, vehicle or vehicle_of(cfg), swarm, threats, proposed)


def shield_inputs(
    shield_cfg: ShieldConfig, cfg: ScenarioConfig, state: SwarmState
) -> tuple[Swarm, Threats]:
    """What `shield_state` checks a simulator state's proposals against: (swarm, threats)."""
    now = (state.steps * cfg.dt_s).astype(np.float64)[:, None]
    if state.tracks is None:
        pos, vel, known = state.obstacle_pos_m, state.obstacle_vel_m_s, state.obstacle_visible
        age = np.zeros(known.shape)
    else:
        pos, vel, known = picture(state.tracks, now)
        age = np.where(known, now - state.tracks.t_valid_s, 0.0)
        pos, vel = np.where(known[..., None], pos, 0.0), np.where(known[..., None], vel, 0.0)
    hovering = state.hovering(cfg.arrival)
    response = state.response
    motion = None
    if response is not None and shield_cfg.vehicle_model == "fitted":
        # A vehicle that hovers where it arrived is checked where it is, as the ideal one: its
        # braking, predicted too, cost the real world's 10u1o 5 points (docs/MODEL.md §21)
        parked = hovering[..., None]
        motion = Motion(
            np.where(parked, 0.0, state.vel_m_s),
            state.last_turn_rad,
            np.where(hovering, 0.0, state.speed_m_s),
            response.delay_s,
            response.tau_s,
            response.accel_m_s2,
        )
    swarm = Swarm(
        pos_m=state.pos_m + state.gps_error_m,
        heading_rad=state.heading_rad,
        target_m=state.target_m,
        deciding=state.active,
        present=state.active | hovering,
        speed_m_s=np.where(hovering, 0.0, state.speed_m_s),
        motion=motion,
    )
    return swarm, Threats(pos, vel, known, age)
