"""The swarm controller: telemetry snapshot → policy decision → constant-rate arcs → setpoints.

Pure and clock-free: every method takes the time. Once per decision step dt the controller
builds every controlled vehicle's observation with the simulator's own builder
(`sim.observation.build_observations`), asks the policy for heading changes, and starts each
vehicle on the arc the simulator would fly: heading h(t) = h₀ + a·(t − t₀)/dt at constant
speed. Between decisions `setpoint` samples that arc as a NED velocity and yaw (what
SET_POSITION_TARGET_LOCAL_NED with type_mask 2503 carries).

A version-2 policy (a generalist: any number of vehicles) also sees the swarm's own vehicles
as neighbours (`SwarmPicture`, from `swarm_picture`): those under control or holding at their
targets, where their telemetry places them; the controller knows the headings it commands
and flies its vehicles at the arcs' velocities, as the simulator's UAVs fly theirs. A version-1
policy sees only its own rows, as it was trained.

Behind the policy stands the safety shield (`sim.shield.shield`, the one implementation the
simulator and the offline evaluation use too), when the controller is given one
(``SwarmController(..., shield=ShieldConfig(mode="on"))``): every decision, the policy's
heading changes are checked against the obstacles (ADS-B intruders, each with its report's
age, and vehicles no longer flown) and the swarm's committed arcs, and the shield's heading
change and speed replace a proposal that would come within d_col + margin ("on"; "monitor"
only records what it would do).

The frames are the simulator's (x east, y north, heading counter-clockwise from east); the
mission's north/east metres and NED yaw are converted in `remarl_fc.frames` only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from remarl_fc.flight.config import Member
from remarl_fc.flight.status import NEIGHBOUR, OBSTACLE, Status
from remarl_fc.flight.traffic import TrafficPicture
from remarl_fc.frames import heading_to_yaw, ne_to_sim, sim_to_ne
from sim.dynamics import Motion, brake, response_values
from sim.kinematics import heading_velocity
from sim.observation import ObservationLayout, build_observations
from sim.sensors import extrapolate
from sim.shield import ShieldConfig, ShieldDecision, Threats, shield
from sim.shield import Swarm as ShieldSwarm
from sim.shield import Vehicle as ShieldVehicle
from sim.spawn import virtual_centre_and_velocity
from sim.vehicle import VehicleProfile

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

MULTIROTOR_CAN_SLOW = True
"""The vehicles `fly` flies can slow down and hover (ArduPilot and PX4 multirotors in
GUIDED/OFFBOARD follow a zero velocity setpoint): the shield may slow them down."""

MIN_REPORT_AGE_S = 1e-3
"""The least age the shield is given for an obstacle, s. In flight every obstacle is a report
(an ADS-B track, a vehicle's last telemetry), never the simulator's exact sensing, which the
shield tells by an age of 0 and trusts without uncertainty."""

MOVING_M_S = 0.1
"""A vehicle not on this controller's arcs (a peer's) slower than this has no heading from its
velocity: the shield keeps the controller's."""


class PolicyLike(Protocol):
    """What the controller needs of a policy (`remarl_fc.policy_io.Policy`)."""

    @property
    def layout(self) -> ObservationLayout:
        """Observation rows and scales."""
        ...

    def act(self, obs: NDArray[np.floating[Any]]) -> NDArray[np.float32]:
        """(..., N, size) observations → (..., N) actions in [−1, 1]."""
        ...


class FlownPolicy(PolicyLike, Protocol):
    """What the runtime needs of a policy: the controller's, and what its summary says of it."""

    def summary(self) -> dict[str, Any]:
        """Name, checksum, generalist or not, range of N (`remarl_fc.policy_io.Policy.summary`)."""
        ...


@dataclass(frozen=True)
class ControlSpec:
    """Constants of the controlled swarm, from the policy file.

    Attributes:
        speed_m_s: the constant flight speed. dt_s: the decision step. max_turn_rad: the
        heading change of a full action. lead_m: how far ahead of the swarm the virtual centre
        lies (`FieldConfig.swarm_lead_m`). arrival_m: distance to a target that counts as
        reached (d_col, as in the simulator).
    """

    speed_m_s: float
    dt_s: float
    max_turn_rad: float
    lead_m: float
    arrival_m: float

    @classmethod
    def from_policy_meta(cls, meta: dict[str, Any]) -> ControlSpec:
        """Read the constants out of a policy file's metadata."""
        return cls(
            speed_m_s=float(meta["speed_m_s"]),
            dt_s=float(meta["dt_s"]),
            max_turn_rad=float(meta["action"]["max_turn_rad"]),
            lead_m=float(meta["scenario_config"]["field"]["swarm_lead_m"]),
            arrival_m=float(meta["d_col_m"]),
        )

    def shield_vehicle(self) -> ShieldVehicle:
        """The shield's view of the vehicles (`sim.shield.Vehicle`).

        The policy's d_col, step, turn bound and speed; multirotors that can slow down
        (`MULTIROTOR_CAN_SLOW`).
        """
        return ShieldVehicle(
            d_col_m=self.arrival_m,
            dt_s=self.dt_s,
            max_turn_rad=self.max_turn_rad,
            cruise_m_s=self.speed_m_s,
            can_slow=MULTIROTOR_CAN_SLOW,
        )


@dataclass(frozen=True)
class SwarmPicture:
    """The swarm's own vehicles as a version-2 policy's neighbour rows show them (slot order).

    Attributes:
        present: (N,) neighbours to the others: position known, and under control or holding
            at their targets (`remarl_fc.flight.status.NEIGHBOUR`). The others are not (a
            lost, held or pilot-flown vehicle is an obstacle: `obstacle_picture`).
        on_arc: (N,) flying this controller's arcs (its own vehicles under control): their
            velocity is the arc's heading × the arc's speed.
        heading_known: (N,) whose commanded heading the others know (this controller's own,
            and a peer's whose arc the bus carried).
        vel_ne_m_s: (N, 2) each vehicle's velocity from its telemetry: a peer process's
            vehicles move at it; 0 for one holding at its target; NaN where unknown (a
            vehicle on an arc then moves at the arc's velocity). The shield's prediction of
            a fitted vehicle on an arc starts from it (`SwarmController.use_profiles`).
    """

    present: BoolArray
    on_arc: BoolArray
    heading_known: BoolArray
    vel_ne_m_s: FloatArray
    peer_arc: BoolArray | None = None
    """(N,) a peer process's vehicles whose arc the bus carried (`SwarmController.follow`):
    they fly that arc, their commanded heading known; None: none."""

    @classmethod
    def everyone(cls, n: int) -> SwarmPicture:
        """All N vehicles under this controller's control."""
        yes = np.ones(n, dtype=bool)
        return cls(yes, yes.copy(), yes.copy(), np.full((n, 2), np.nan))


@dataclass(frozen=True)
class Decision:
    """One decision of the swarm (for the log).

    Attributes:
        t: decision time. obs: (N, size) observations. action: (N,) in [−1, 1], flown (the
        shield's where it replaced the policy's). turn_rad: (N,) heading change over the
        coming step. heading_rad: (N,) at t. positions_ne_m: (N, 2) as used.
        obstacles_ne_m: (M, 2) as used. speed_m_s: (N,) the speed commanded along the coming
        arc. proposed_action: (N,) the policy's. flown: (N,) the vehicles this decision flies
        (on this controller's arcs, position known): the ones the shield checked.
        shield: the shield's decision, (1, N) arrays (`sim.shield.ShieldDecision`); None when
        the shield is off.
    """

    t: float
    obs: NDArray[np.float32]
    action: NDArray[np.float32]
    turn_rad: FloatArray
    heading_rad: FloatArray
    positions_ne_m: FloatArray
    obstacles_ne_m: FloatArray
    speed_m_s: FloatArray
    proposed_action: NDArray[np.float32]
    flown: BoolArray
    shield: ShieldDecision | None


class SwarmController:
    """Flies N vehicles (policy slots 0..N−1) toward their targets.

    Args:
        policy: the policy (numpy inference).
        spec: speed, dt, turn bound, virtual-centre lead, arrival distance.
        targets_ne_m: (N, 2) targets, north/east metres in the mission frame.
        shield: the safety shield behind the policy (default: `ShieldConfig`'s, off).
        groups: (N,) the swarm each vehicle flies with, 0…G−1 (each swarm has its own virtual
            centre, as `UAVConfig.groups` in the simulator); None: one swarm.
    """

    def __init__(
        self,
        policy: PolicyLike,
        spec: ControlSpec,
        targets_ne_m: FloatArray,
        *,
        shield: ShieldConfig | None = None,
        groups: Sequence[int] | None = None,
    ) -> None:
        self.policy, self.spec = policy, spec
        self.shield = shield if shield is not None else ShieldConfig()
        self.shield_vehicle = spec.shield_vehicle()
        self.targets_xy = ne_to_sim(np.asarray(targets_ne_m, dtype=np.float64))
        n = len(self.targets_xy)
        self.n = n
        self.groups = np.zeros(n, dtype=np.int64) if groups is None else np.asarray(groups)
        self.h0 = np.zeros(n)
        self.turn = np.zeros(n)
        self.t0 = np.zeros(n)
        self.speed_m_s = np.full(n, spec.speed_m_s)
        self.response: FloatArray | None = None
        """(N, 3) each vehicle's delay (s), velocity time constant (s) and acceleration cap
        (m/s²) for the shield's prediction (`use_profiles`); None: the arcs as commanded."""
        self.centre0 = np.zeros((int(self.groups.max(initial=0)) + 1, 2))
        self.swarm_vel = np.zeros_like(self.centre0)
        self.t_start = 0.0
        self.started = False

    def start(self, positions_ne_m: FloatArray, now: float) -> None:
        """Fix each swarm's virtual centre and velocity, and head each vehicle to its target."""
        pos = ne_to_sim(np.asarray(positions_ne_m, dtype=np.float64))
        delta = self.targets_xy - pos
        self.h0 = np.arctan2(delta[:, 1], delta[:, 0])
        self.turn[:] = 0.0
        self.t0[:] = now
        self.swarm_vel, self.centre0 = virtual_centre_and_velocity(
            pos, self.targets_xy, self.spec.speed_m_s, self.spec.lead_m, self.groups
        )
        self.t_start = now
        self.started = True

    def use_profiles(self, profiles: Sequence[VehicleProfile]) -> None:
        """Predict each vehicle (slot order) with this fitted response behind the shield.

        With ``ShieldConfig.vehicle_model`` "fitted" the shield flies every candidate of a
        vehicle on this controller's arcs with its profile's response, from its telemetry's
        velocity and after its current arc (`sim.dynamics.predict_response`), as the
        simulator's shield does; an ideal profile is the arc as commanded. A peer's vehicle
        flies the rest of the arc the bus carried (`follow`), or else straight on at its
        velocity.
        """
        if len(profiles) != self.n:
            raise ValueError(f"{len(profiles)} vehicle profiles for {self.n} vehicles")
        ideal = all(p.ideal for p in profiles)
        self.response = None if ideal else np.array([response_values(p) for p in profiles])

    def heading_at(self, now: float) -> FloatArray:
        """(N,) heading on each vehicle's current arc (straight on after the arc's end)."""
        frac = np.clip((now - self.t0) / self.spec.dt_s, 0.0, 1.0)
        heading: FloatArray = self.h0 + self.turn * frac
        return heading

    def arc(self, slot: int, now: float) -> tuple[float, float, float, float]:
        """Vehicle ``slot``'s arc as the swarm bus carries it (`VehicleState.arc`).

        Its course at the start (rad clockwise from north), its turn (clockwise), its speed,
        and how long ago it started (s).
        """
        course = float(heading_to_yaw(self.h0[slot]))
        turn, speed = -float(self.turn[slot]), float(self.speed_m_s[slot])
        return course, turn, speed, max(0.0, now - float(self.t0[slot]))

    def follow(self, slot: int, arc: tuple[float, float, float, float]) -> None:
        """Vehicle ``slot`` (a peer process's) flies ``arc``.

        ``arc``: (heading at its start, turn, speed, start time) in this controller's frame and
        clock (`Member.remote_arc`).
        """
        self.h0[slot], self.turn[slot], self.speed_m_s[slot], self.t0[slot] = arc

    def centre_at(self, now: float) -> FloatArray:
        """(N, 2) each vehicle's virtual centre p* (its swarm's), moving with the swarm."""
        out: FloatArray = (self.centre0 + self.swarm_vel * (now - self.t_start))[self.groups]
        return out

    def decide(
        self,
        now: float,
        positions_ne_m: FloatArray,
        obstacles_ne_m: FloatArray,
        obstacle_vel_ne_m_s: FloatArray,
        speed_m_s: FloatArray | None = None,
        *,
        swarm: SwarmPicture | None = None,
        obstacle_age_s: FloatArray | None = None,
    ) -> Decision:
        """Decide every vehicle's next arc: the policy's, through the shield.

        Args:
            now: decision time (s, the controller's clock).
            positions_ne_m: (N, 2) current positions (rows of vehicles not flown are ignored).
            obstacles_ne_m, obstacle_vel_ne_m_s: (M, 2) intruders and vehicles that are not
                (or no longer) members of the swarm, predicted to ``now``.
            speed_m_s: (N,) speeds to fly the coming arcs at, clipped to [0, the policy's
                speed] (a multirotor can slow down and stop); None: the policy's speed.
            swarm: which vehicles are neighbours and how they move (see `SwarmPicture`);
                None: every vehicle with a known position, all on their arcs. A version-1
                policy does not see it; the shield does (it decides for the vehicles on this
                controller's arcs, and keeps them clear of every neighbour).
            obstacle_age_s: (M,) age of each obstacle's report (now − its time), which widens
                the shield's required clearance; None: 0, exactly known (as the simulator's
                sensing: `obstacle_picture` gives every report's).

        With the shield on, the shield's heading change replaces the policy's where the
        policy's would not keep clear, and the speed is the lower of ``speed_m_s`` and the
        shield's (which checks every candidate at the policy's speed first).
        """
        layout = self.policy.layout
        heading = self.heading_at(now)
        raw = ne_to_sim(np.asarray(positions_ne_m, dtype=np.float64))
        known: BoolArray = np.asarray(np.isfinite(raw).all(axis=-1))
        pos = np.where(np.isfinite(raw), raw, 0.0)
        vel = heading_velocity(heading, self.spec.speed_m_s)
        obs_xy = ne_to_sim(np.asarray(obstacles_ne_m, dtype=np.float64).reshape(-1, 2))
        obs_v = ne_to_sim(np.asarray(obstacle_vel_ne_m_s, dtype=np.float64).reshape(-1, 2))
        sw = SwarmPicture.everyone(self.n) if swarm is None else swarm
        neighbours: dict[str, Any] = {}
        if layout.version == 2:
            arc = heading_velocity(heading, self.speed_m_s[:, None])
            told = ne_to_sim(np.nan_to_num(np.asarray(sw.vel_ne_m_s, dtype=np.float64)))
            vel = np.where(np.asarray(sw.on_arc)[:, None], arc, told)
            neighbours = {
                "uav_valid": (np.asarray(sw.present, dtype=bool) & known)[None],
                "commanded_heading_rad": heading[None],
                "heading_known": np.asarray(sw.heading_known, dtype=bool)[None],
                "uav_group": self.groups,  # other swarms' vehicles are intruder rows
            }
        built = build_observations(
            layout,
            pos[None],
            heading[None],
            vel[None],
            self.targets_xy[None],
            self.centre_at(now)[None],
            obs_xy[None],
            obs_v[None],
            **neighbours,
        )
        flat = built.flat()
        proposed = np.clip(self.policy.act(flat)[0], -1.0, 1.0).astype(np.float32)
        cruise = self.spec.speed_m_s
        wanted = np.full(self.n, cruise) if speed_m_s is None else np.asarray(speed_m_s, float)
        speed = np.clip(np.nan_to_num(wanted, nan=0.0), 0.0, cruise)
        flown = np.asarray(sw.on_arc, dtype=bool) & known
        peer = np.zeros(self.n, dtype=bool) if sw.peer_arc is None else np.asarray(sw.peer_arc)
        action, checked = proposed, None
        if self.shield.mode != "off":
            age = np.zeros(len(obs_xy)) if obstacle_age_s is None else obstacle_age_s
            obstacles = (obs_xy, obs_v, np.asarray(age, dtype=np.float64).reshape(-1))
            checked = self._shield(
                now, pos, heading, speed, proposed, flown, known, sw, peer, obstacles
            )
            action = np.where(flown, checked.action[0], proposed).astype(np.float32)
            speed = np.where(flown, np.minimum(speed, checked.speed_m_s[0]), speed)
        turn = action.astype(np.float64) * self.spec.max_turn_rad
        # a peer's vehicle keeps the arc its own process commands (until the bus says more)
        self.h0 = np.where(peer, self.h0, heading)
        self.turn = np.where(peer, self.turn, turn)
        self.t0 = np.where(peer, self.t0, now)
        self.speed_m_s = np.where(peer, self.speed_m_s, speed)
        return Decision(
            now,
            flat[0],
            action,
            turn,
            heading,
            np.asarray(positions_ne_m),
            sim_to_ne(obs_xy),
            self.speed_m_s.copy(),
            proposed,
            flown,
            checked,
        )

    def _shield(
        self,
        now: float,
        pos: FloatArray,
        heading: FloatArray,
        speed: FloatArray,
        proposed: NDArray[np.float32],
        flown: BoolArray,
        known: BoolArray,
        sw: SwarmPicture,
        peer: BoolArray,
        obstacles: tuple[FloatArray, FloatArray, FloatArray],
    ) -> ShieldDecision:
        """`sim.shield.shield` on this decision (simulator frame, B = 1).

        It decides for the vehicles flown here (``flown``) and keeps them clear of the
        obstacles (each report's age widening the clearance) and of the swarm's present
        vehicles: those flown here on their proposed arcs at their commanded speeds (as the
        simulator's adapter `sim.shield.shield_state` does); a peer's vehicle on the rest of
        the arc its process commands (``peer``: the bus carried it) — the turn it has left,
        over the coming step — or else straight on at its telemetry's velocity; one holding
        at its target at rest.
        """
        on_arc = np.asarray(sw.on_arc, dtype=bool)
        told = ne_to_sim(np.nan_to_num(np.asarray(sw.vel_ne_m_s, dtype=np.float64)))
        told_speed = np.hypot(told[:, 0], told[:, 1])
        moving = ~on_arc & ~peer & (told_speed > MOVING_M_S)
        course = np.where(moving, np.arctan2(told[:, 1], told[:, 0]), heading)
        frac = np.clip((now - self.t0) / self.spec.dt_s, 0.0, 1.0)
        left = np.where(peer, self.turn * (1.0 - frac) / self.spec.max_turn_rad, 0.0)
        left = np.clip(left, -1.0, 1.0)  # an action: a bus arc may turn more than ours
        own = on_arc | peer  # flying a known arc
        motion = None
        if self.response is not None and self.shield.vehicle_model == "fitted":
            # on an arc: from its telemetry's velocity (the arc's where unknown), after the arc
            # in force now; a peer's on a known arc after the turn it has left; any other
            # (or one at rest) flies on at its velocity, its command
            raw = ne_to_sim(np.asarray(sw.vel_ne_m_s, dtype=np.float64))
            arc = heading_velocity(heading, self.speed_m_s[:, None])
            now_vel = np.where(np.isfinite(raw), raw, np.where(own[:, None], arc, 0.0))
            motion = Motion(
                now_vel[None],
                np.where(on_arc, self.turn, left * self.spec.max_turn_rad)[None],
                np.where(own, self.speed_m_s, told_speed)[None],
                self.response[None, :, 0],
                self.response[None, :, 1],
                self.response[None, :, 2],
            )
        swarm = ShieldSwarm(
            pos_m=pos[None],
            heading_rad=course[None],
            target_m=self.targets_xy[None],
            deciding=flown[None],
            present=(np.asarray(sw.present, dtype=bool) & known)[None],
            speed_m_s=np.where(on_arc, speed, np.where(peer, self.speed_m_s, told_speed))[None],
            motion=motion,
        )
        obs_xy, obs_v, ages = obstacles
        threats = Threats(
            intruder_pos_m=obs_xy[None],
            intruder_vel_m_s=np.nan_to_num(obs_v)[None],  # no velocity reported: at rest
            intruder_known=np.asarray(np.isfinite(obs_xy).all(axis=-1))[None],
            intruder_age_s=np.maximum(ages, 0.0)[None],
        )
        committed = np.where(on_arc, proposed, left)
        return shield(self.shield, self.shield_vehicle, swarm, threats, committed[None])

    def setpoint(self, slot: int, now: float) -> tuple[float, float, float]:
        """(north m/s, east m/s, yaw rad) of vehicle ``slot`` on its arc now."""
        h = float(self.heading_at(now)[slot])
        v = float(self.speed_m_s[slot])
        return v * math.sin(h), v * math.cos(h), float(heading_to_yaw(h))

    def reached(self, slot: int, position_ne_m: FloatArray) -> bool:
        """Within the arrival distance of its target (horizontal)."""
        xy = ne_to_sim(np.asarray(position_ne_m, dtype=np.float64))
        return bool(np.hypot(*(xy - self.targets_xy[slot])) < self.spec.arrival_m)


def swarm_picture(rows: Sequence[tuple[Member, Status]]) -> SwarmPicture:
    """The `SwarmPicture` of the mission's vehicles (``rows`` in slot order).

    Neighbours: under control or holding at their targets, with a known position. This
    process's own vehicles under control fly its arcs, and their headings are known; a peer
    process's vehicles move as their telemetry says, on the arc their process published where
    the bus carried it (their headings then known, else unknown); a vehicle holding at its
    target is at rest.
    """
    present, on_arc, known, vel, peer = [], [], [], [], []
    for m, status in rows:
        flying = status == Status.CONTROLLED
        present.append(status in NEIGHBOUR and math.isfinite(m.track.t_position))
        on_arc.append(m.local and flying)
        peer.append(not m.local and flying and m.remote_arc is not None)
        known.append((m.local and status in NEIGHBOUR) or peer[-1])
        vel.append(m.track.vel_ned_m_s[:2] if flying else np.zeros(2))
    return SwarmPicture(
        np.array(present, dtype=bool),
        np.array(on_arc, dtype=bool),
        np.array(known, dtype=bool),
        np.array(vel, dtype=np.float64).reshape(-1, 2),
        np.array(peer, dtype=bool),
    )


TOLD_TO_HOLD = frozenset({Status.HELD, Status.REACHED})
"""Statuses of a vehicle told to hold (the hold mode, zero-velocity setpoints): it brakes to
rest and keeps its place (`whereabouts`)."""

_TOLD_TO_HOLD_SAID = frozenset(s.value for s in TOLD_TO_HOLD)


def told_to_hold(member: Member, status: Status) -> bool:
    """Whether the vehicle was told to hold.

    This process's word for its own; for a peer's, the last status its own process published
    (a peer silent since is ``lost`` here, and still holding).
    """
    if member.local:
        return status in TOLD_TO_HOLD
    return member.remote_said in _TOLD_TO_HOLD_SAID


@dataclass(frozen=True)
class Whereabouts:
    """Where the mission's vehicles are now, from their last tracks (slot order).

    Attributes:
        ne_m, vel_ne_m_s: (N, 2) positions and velocities (NaN: no position yet).
        age_s: (N,) how long each has moved unobserved: now − its last position, or, for a
            vehicle told to hold, as long of that as it was predicted still moving.
    """

    ne_m: FloatArray
    vel_ne_m_s: FloatArray
    age_s: FloatArray


def whereabouts(
    rows: Sequence[tuple[Member, Status]], responses: FloatArray, now: float
) -> Whereabouts:
    """Every vehicle's track predicted to ``now``.

    ``responses`` (N, 3): each one's fitted (delay, time constant, acceleration cap)
    (`sim.dynamics.response_values`).

    A vehicle still flying is extrapolated at its velocity (a lost one flies its last setpoint).
    One told to hold (`told_to_hold`) brakes to rest and keeps its place (`sim.dynamics.brake`):
    a peer whose process ended while its vehicle braked is where that vehicle stopped, not
    flying on at its last velocity; its uncertainty stops growing once it is at rest.
    """
    tracks = [m.track for m, _ in rows]
    ne = np.array([t.ne_m for t in tracks], dtype=np.float64).reshape(-1, 2)
    vel = np.array([t.vel_ned_m_s[:2] for t in tracks], dtype=np.float64).reshape(-1, 2)
    t_pos = np.array([t.t_position for t in tracks], dtype=np.float64)
    pos = extrapolate(ne, vel, t_pos, now)  # at its velocity, never backwards
    age = np.nan_to_num(np.maximum(now - t_pos, 0.0))  # no position yet: its NaN stays
    holding = np.array([told_to_hold(m, s) for m, s in rows], dtype=bool)
    if holding.any():
        r = np.asarray(responses, dtype=np.float64)[holding]
        stop = brake(vel[holding], r[:, 0], r[:, 1], r[:, 2], age[holding])
        pos[holding] = ne[holding] + stop.disp_m
        vel[holding], age[holding] = stop.vel_m_s, stop.moving_s
    return Whereabouts(pos, vel, age)


@dataclass(frozen=True)
class Obstacles:
    """What the policy and the shield must avoid, north/east, predicted to the decision time.

    Attributes:
        ne_m, vel_ne_m_s: (M, 2) positions and velocities.
        age_s: (M,) age of each one's report: now − the ADS-B report's time, or now − the
            last position of a vehicle no longer flown; at least `MIN_REPORT_AGE_S`.
    """

    ne_m: FloatArray
    vel_ne_m_s: FloatArray
    age_s: FloatArray


def obstacle_picture(
    traffic: TrafficPicture,
    rows: Sequence[tuple[Member, Status]],
    where: Whereabouts,
    now: float,
    band_m: float,
) -> Obstacles:
    """Every obstacle the policy must avoid.

    The ADS-B intruders within ±``band_m`` of the swarm's mean height (nearest the swarm centre
    first, capped by the picture), and the vehicles no longer flown by the policy (`OBSTACLE`:
    lost, held, pilot) where ``where`` (`whereabouts`) puts them now.
    """
    tracks = [m.track for m, _ in rows]
    known = [t.ne_m for t in tracks if math.isfinite(t.t_position)]
    heights = [t.height_m for t in tracks if math.isfinite(t.height_m)]
    centre = np.mean(known, axis=0) if known else None
    height = float(np.mean(heights)) if heights else 0.0
    pos, vel, age = [], [], []
    for intr in traffic.current(now, height, band_m, near_ne_m=centre):
        pos.append(intr.predicted_ne_m(now))
        vel.append(intr.vel_ne_m_s)
        age.append(max(MIN_REPORT_AGE_S, now - intr.t))
    for k, (m, status) in enumerate(rows):
        if status in OBSTACLE and math.isfinite(m.track.t_position):
            pos.append(where.ne_m[k])
            vel.append(where.vel_ne_m_s[k])
            age.append(max(MIN_REPORT_AGE_S, float(where.age_s[k])))
    if not pos:
        return Obstacles(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
    return Obstacles(np.array(pos), np.array(vel), np.array(age))
