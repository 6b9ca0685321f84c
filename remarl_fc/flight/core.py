"""The flight's decisions, without I/O: what to send to each vehicle, and when.

`next_actions` is the safety logic of a flight as a pure function. Each setpoint tick the
async shell (`remarl_fc.flight.runtime`) takes one immutable `Telemetry` snapshot per vehicle
from its tracks, calls::

    vehicles, commands = next_actions(vehicles, telemetry, now, rules, guidance)

and carries the commands out (`Setpoint` → SET_POSITION_TARGET_LOCAL_NED, `Hold` → the hold
mode, `Event` → the console and the decision log). Nothing here reads a clock, opens a socket
or sleeps: tests drive it with plain data and any ``now`` they like.

Per vehicle and tick, in this order (the first that applies wins):

1. a PX4 vehicle being prepared (`Vehicle.prestream`) or climbing (`Vehicle.climb_target_m`)
   gets a zero-velocity setpoint (climbing: `CLIMB_RATE_M_S` up until
   `TAKEOFF_DONE_FRACTION` of the height);
2. ``lost`` whose telemetry is fresh again → ``held`` (hold, never resumed);
3. a vehicle told to hold while it flew our setpoints (`Vehicle.braking`) gets zero-velocity
   setpoints until its HEARTBEATs confirm it left GUIDED / OFFBOARD: the hold is a command that
   a lossy link can lose (and its retry waits for a timeout), the setpoint stream is not;
4. anything but ``controlled`` → nothing;
5. telemetry older than `Rules.stale_s` → ``lost`` (an obstacle at its last track);
6. telemetry that contradicts itself (`Telemetry.untrusted`) → ``held`` (hold): a vehicle we
   cannot locate is not steered;
7. a mode the pilot chose, confirmed by consecutive HEARTBEATs → ``pilot`` (released, never
   fought; not in a dry run);
8. at its target → ``reached`` (hold);
9. a setpoint that is not a finite number (a broken policy) → ``held`` (hold);
10. the next setpoint would leave the geofence within one decision step → ``held`` (hold);
11. otherwise: the policy's setpoint.

Status changes go through `transition`, which allows only what `remarl_fc.flight.status`
allows, logs an `Event` for every change that has a reason to tell, and a `Hold` for every
entry into ``held`` or ``reached``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from remarl_fc.flight.mission import Geofence
from remarl_fc.flight.status import FLOWN, HOLD_ON_ENTRY, Status, check_transition
from remarl_fc.flight.tracking import VehicleTrack

CLIMB_RATE_M_S = 1.5
"""PX4 take-off climb in OFFBOARD, m/s (MPC_TKO_SPEED's default)."""

TAKEOFF_DONE_FRACTION = 0.95
"""A take-off is done at this fraction of its height."""

BRAKE_ON_HOLD = frozenset({Status.CONTROLLED, Status.LOST})
"""Statuses in which a vehicle flies our velocity setpoints (``lost``: the last one it heard):
told to hold from one of these, it is braked by zero-velocity setpoints until the hold mode is
confirmed (`Vehicle.braking`)."""


@dataclass(frozen=True)
class Telemetry:
    """What the vehicle's own telemetry says at one tick (an immutable snapshot)."""

    ne_m: tuple[float, float]
    """Position north, east of the mission origin, m."""
    height_m: float
    """Height above the origin, m (NaN before the first position)."""
    yaw_rad: float
    """Yaw, rad (NaN before the first attitude)."""
    position_age_s: float
    """Age of the latest position, s (inf before the first)."""
    external_mode: bool
    """Still in GUIDED (ArduPilot) / OFFBOARD (PX4), the mode we fly it in: False only once
    consecutive HEARTBEATs confirm another mode (`VehicleTrack.takeover_confirmed`)."""
    custom_mode: int
    """HEARTBEAT.custom_mode as last heard (for the event text)."""
    untrusted: str | None = None
    """Why the vehicle's telemetry is not believed (`VehicleTrack.untrusted`), or None."""

    @classmethod
    def of(cls, track: VehicleTrack, now: float) -> Telemetry:
        """The snapshot of ``track`` at ``now`` (flight clock, s)."""
        return cls(
            ne_m=(float(track.ne_m[0]), float(track.ne_m[1])),
            height_m=float(track.height_m),
            yaw_rad=float(track.yaw_rad),
            position_age_s=float(track.position_age_s(now)),
            external_mode=not track.takeover_confirmed(),
            custom_mode=int(track.custom_mode),
            untrusted=track.untrusted,
        )


@dataclass(frozen=True)
class Vehicle:
    """One vehicle as the flight's decisions see it (replaced, never mutated)."""

    system_id: int
    slot: int
    status: Status = Status.WAITING
    prestream: bool = False
    """PX4: stream zero-velocity setpoints (OFFBOARD needs a stream before and while
    switching to it, and leaves it after 1 s without one)."""
    climb_target_m: float | None = None
    """PX4 take-off in OFFBOARD: climb to this height."""
    lost_since: float | None = None
    """When it became ``lost`` (flight clock, s)."""
    braking: bool = False
    """Told to hold while it flew our setpoints (``controlled`` or ``lost``): stream zero
    velocity until consecutive HEARTBEATs show the hold mode (or any mode but ours)."""


@dataclass(frozen=True)
class Rules:
    """The settings the decisions depend on."""

    stale_s: float
    """Telemetry older than this marks a vehicle lost, s."""
    dt_s: float
    """Decision step, s: the geofence is checked this far ahead."""
    dry_run: bool = False
    """Nothing is sent: the mode is never ours, so no pilot takeover is inferred."""
    geofence: Geofence | None = None


class Guidance(Protocol):
    """Where the policy wants each vehicle (`remarl_fc.flight.control.SwarmController`)."""

    def setpoint(self, slot: int, now: float) -> tuple[float, float, float]:
        """(v_north m/s, v_east m/s, yaw rad) for ``slot`` at ``now``."""
        ...

    def reached(self, slot: int, position_ne_m: NDArray[np.float64]) -> bool:
        """Whether ``slot`` at ``position_ne_m`` is at its target."""
        ...


@dataclass(frozen=True)
class Setpoint:
    """Stream one velocity + yaw setpoint (NED, m/s and rad)."""

    system_id: int
    vn: float
    ve: float
    vd: float
    yaw: float


@dataclass(frozen=True)
class Hold:
    """Put the vehicle in the hold mode (the command waits for its ACK)."""

    system_id: int


@dataclass(frozen=True)
class Event:
    """Something to tell the operator and write to the decision log."""

    system_id: int
    text: str


Command = Setpoint | Hold | Event


def transition(v: Vehicle, new: Status, why: str | None) -> tuple[Vehicle, tuple[Command, ...]]:
    """``v`` in status ``new``: an `Event` saying ``why`` (if any), a `Hold` where ``new`` needs it.

    Raises:
        IllegalTransition: `remarl_fc.flight.status.TRANSITIONS` does not allow it.
    """
    check_transition(v.status, new)
    out: tuple[Command, ...] = () if why is None else (Event(v.system_id, why),)
    if new in HOLD_ON_ENTRY:
        out += (Hold(v.system_id),)
    braking = new in HOLD_ON_ENTRY and v.status in BRAKE_ON_HOLD
    return replace(v, status=new, prestream=False, climb_target_m=None, braking=braking), out


def next_action(
    v: Vehicle, tel: Telemetry, now: float, rules: Rules, guidance: Guidance
) -> tuple[Vehicle, tuple[Command, ...]]:
    """One vehicle's tick (the rules in the module docstring)."""
    if v.prestream or v.climb_target_m is not None:
        vz = 0.0
        if v.climb_target_m is not None and tel.height_m < TAKEOFF_DONE_FRACTION * v.climb_target_m:
            vz = -CLIMB_RATE_M_S
        yaw = tel.yaw_rad if math.isfinite(tel.yaw_rad) else 0.0
        return v, (Setpoint(v.system_id, 0.0, 0.0, vz, yaw),)
    fresh = tel.position_age_s <= rules.stale_s
    if v.status == Status.LOST and fresh:
        return transition(v, Status.HELD, "telemetry back: told to hold, not resumed")
    if v.braking:
        if rules.dry_run or not tel.external_mode:
            return replace(v, braking=False), ()
        yaw = tel.yaw_rad if math.isfinite(tel.yaw_rad) else 0.0
        return v, (Setpoint(v.system_id, 0.0, 0.0, 0.0, yaw),)
    if v.status != Status.CONTROLLED:
        return v, ()
    if not fresh:
        lost, out = transition(
            v, Status.LOST, f"telemetry stale for {tel.position_age_s:.1f} s: an obstacle now"
        )
        return replace(lost, lost_since=now), out
    if tel.untrusted is not None:
        return transition(v, Status.HELD, f"telemetry untrusted ({tel.untrusted}): hold")
    if not rules.dry_run and not tel.external_mode:
        return transition(
            v, Status.PILOT, f"mode changed to {tel.custom_mode} by someone else: released"
        )
    ne = np.array(tel.ne_m)
    if guidance.reached(v.slot, ne):
        return transition(v, Status.REACHED, "target reached: hold and release")
    vn, ve, yaw = guidance.setpoint(v.slot, now)
    if not all(math.isfinite(x) for x in (vn, ve, yaw)):
        return transition(
            v,
            Status.HELD,
            f"the policy gave a setpoint that is not a number ({vn}, {ve}, {yaw}): hold",
        )
    fence = rules.geofence
    if fence is not None and not fence.inside(ne + np.array([vn, ve]) * rules.dt_s, tel.height_m):
        return transition(v, Status.HELD, "geofence breach ahead: hold")
    return v, (Setpoint(v.system_id, vn, ve, 0.0, yaw),)


def next_actions(
    vehicles: Mapping[int, Vehicle],
    telemetry: Mapping[int, Telemetry],
    now: float,
    rules: Rules,
    guidance: Guidance,
) -> tuple[dict[int, Vehicle], list[Command]]:
    """Every vehicle's tick: the new vehicles (by system id) and the commands, in order.

    ``telemetry`` holds the snapshot of each vehicle this process flies; a vehicle without
    one (flown by another process) is left as it is.
    """
    new: dict[int, Vehicle] = dict(vehicles)
    commands: list[Command] = []
    for sysid, tel in telemetry.items():
        new[sysid], out = next_action(vehicles[sysid], tel, now, rules, guidance)
        commands.extend(out)
    return new, commands


def flight_goes_on(
    vehicles: Mapping[int, Vehicle], mine: frozenset[int], now: float, lost_timeout_s: float
) -> bool:
    """Whether the decision loop goes on.

    It does while a vehicle of ``mine`` is ``controlled``, or ``lost`` for less than
    ``lost_timeout_s`` (it may come back and must then be held).
    """
    for sysid in mine:
        v = vehicles[sysid]
        if v.status == Status.CONTROLLED:
            return True
        if v.status == Status.LOST and now - (v.lost_since or now) < lost_timeout_s:
            return True
    return False


def hold_all(
    vehicles: Mapping[int, Vehicle], flown: frozenset[int], reason: str
) -> tuple[dict[int, Vehicle], list[Command]]:
    """Every vehicle in ``flown`` still owned by this process (`FLOWN`) → ``held``."""
    new: dict[int, Vehicle] = dict(vehicles)
    commands: list[Command] = []
    for sysid in sorted(flown):
        if vehicles[sysid].status in FLOWN:
            new[sysid], out = transition(vehicles[sysid], Status.HELD, f"{reason}: hold")
            commands.extend(out)
    return new, commands
