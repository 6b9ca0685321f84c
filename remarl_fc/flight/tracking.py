"""What the runtime knows about each vehicle: latest values, monotonic stamps.

`VehicleTrack.update` takes one decoded MAVLink message from the vehicle's autopilot and its
monotonic receive time; nothing here does I/O. Telemetry is converted once, at this boundary,
into the mission's local frame (north/east metres from the mission origin, height above the
origin) through `remarl_fc.frames`. Values that cannot be true — NaN, a position without a fix
(lat = lon = 0), a jump faster than `MAX_SPEED_M_S` — are dropped and counted, never used.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.frames import GeoPoint, cdeg_to_yaw, from_deg_e7, geodetic_to_ned
from remarl_fc.mavlink.consts import (
    CopterMode,
    EkfFlag,
    MavAutopilot,
    MavModeFlag,
    MsgId,
    Px4MainMode,
    px4_mode_parts,
)

FloatArray = NDArray[np.float64]

MAX_SPEED_M_S = 100.0
"""Telemetry implying a faster vehicle (reported or between two fixes) is rejected."""

EKF_POSITION_OK = EkfFlag.VELOCITY_HORIZ | EkfFlag.POS_HORIZ_ABS
"""EKF flags a controller needs before taking control (ArduPilot), with CONST_POS_MODE clear."""

STATUSTEXT_KEPT = 20
"""Recent STATUSTEXTs kept per vehicle (refusal reasons)."""

STATUSTEXT_MAX_CHARS = 50
"""STATUSTEXT.text is 50 characters on the wire (chunked texts are not reassembled)."""

TAKEOVER_CONFIRM_HEARTBEATS = 2
"""Consecutive HEARTBEATs in a mode that is not ours before a pilot takeover is believed (one
forged or corrupted HEARTBEAT must not release a vehicle)."""

DEAD_RECKONING_TAU_S = 10.0
"""Time constant with which the dead-reckoned position (integrated reported velocity) is pulled
toward the reported fixes, s: a position stream drifting at r m/s against its own velocity
shows a disagreement of about r·τ."""

DEAD_RECKONING_MAX_GAP_S = 5.0
"""Fixes further apart than this on the vehicle's clock restart the dead reckoning, s."""

DISAGREEMENT_UNTRUSTED_M = 15.0
"""A fix this far from the dead-reckoned position makes the vehicle's telemetry untrusted, m
(a real autopilot's position and velocity come from one estimator and agree to about 1 m)."""

REJECTIONS_UNTRUSTED = 10
"""This many positions rejected within `REJECTIONS_WINDOW_S` make the telemetry untrusted
(two streams interleaved on one source: each rejects the other's fixes)."""

REJECTIONS_WINDOW_S = 3.0
"""Window for `REJECTIONS_UNTRUSTED`, s."""

HEARTBEATS_UNTRUSTED = 20
"""This many HEARTBEATs within `HEARTBEAT_WINDOW_S` make the telemetry untrusted: an
autopilot sends one a second per link, so a sustained faster stream means a second sender on
the vehicle's own source (whose HEARTBEATs could otherwise fake a pilot takeover). Counted by
arrival time, so it is set high: a link that delivers a backlog after a stall bursts a few,
and a vehicle silent for 20 s is lost long before."""

HEARTBEAT_WINDOW_S = 2.0
"""Window for `HEARTBEATS_UNTRUSTED`, s."""


NO_FIX = "no fix (lat = lon = 0)"
"""The rejection of a position sent before the GPS has a fix: normal while booting, not an
anomaly of the link."""


def printable(text: str) -> str:
    r"""``text`` safe to print: control and other non-printable characters become ``?``.

    >>> printable("PreArm: \x1b[2Jok")
    'PreArm: ?[2Jok'
    """
    return "".join(c if c.isprintable() else "?" for c in text[:STATUSTEXT_MAX_CHARS])


@dataclass
class VehicleTrack:
    """The latest state of one vehicle, in the mission frame, with monotonic stamps (s).

    Attributes:
        system_id: the vehicle. origin: the mission origin.
        autopilot: HEARTBEAT.autopilot (3 ArduPilot, 12 PX4) once heard, else None.
        custom_mode, base_mode, system_status: from the last HEARTBEAT; t_heartbeat its time.
        ne_m: (2,) north/east from the origin; height_m above the origin; vel_ned_m_s (3,);
            t_position: time of the last accepted position.
        yaw_rad: from ATTITUDE (or the GLOBAL_POSITION_INT heading); t_yaw.
        ekf_flags: last EKF_STATUS_REPORT flags (ArduPilot), or None.
        landed_state: EXTENDED_SYS_STATE.landed_state, or None.
        rejected: counts of telemetry dropped as impossible, by reason.
        seen: counts of messages received, by type name.
        texts: recent (time, severity, text) STATUSTEXTs, made printable.
        other_mode_heartbeats: consecutive HEARTBEATs in a mode that is not the external one.
        dr_ne_m: the dead-reckoned position (reported velocity integrated, pulled toward the
            fixes with `DEAD_RECKONING_TAU_S`); disagreement_m: the last fix's distance from it.
        untrusted: why the telemetry is no longer believed (sticky), or None.
    """

    system_id: int
    origin: GeoPoint
    autopilot: int | None = None
    custom_mode: int = 0
    base_mode: int = 0
    system_status: int = 0
    t_heartbeat: float = -math.inf
    ne_m: FloatArray = field(default_factory=lambda: np.full(2, np.nan))
    height_m: float = math.nan
    vel_ned_m_s: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    t_position: float = -math.inf
    yaw_rad: float = math.nan
    t_yaw: float = -math.inf
    ekf_flags: int | None = None
    landed_state: int | None = None
    rejected: Counter[str] = field(default_factory=Counter)
    seen: Counter[str] = field(default_factory=Counter)
    texts: deque[tuple[float, int, str]] = field(
        default_factory=lambda: deque(maxlen=STATUSTEXT_KEPT)
    )
    other_mode_heartbeats: int = 0
    dr_ne_m: FloatArray = field(default_factory=lambda: np.full(2, np.nan))
    t_fix_vehicle_s: float = -math.inf
    disagreement_m: float = 0.0
    untrusted: str | None = None
    _rejections: deque[float] = field(
        default_factory=lambda: deque(maxlen=REJECTIONS_UNTRUSTED), repr=False
    )
    _heartbeats: deque[float] = field(
        default_factory=lambda: deque(maxlen=HEARTBEATS_UNTRUSTED), repr=False
    )

    # -- derived ------------------------------------------------------------------------

    @property
    def armed(self) -> bool:
        """HEARTBEAT says armed."""
        return bool(self.base_mode & MavModeFlag.SAFETY_ARMED)

    @property
    def is_px4(self) -> bool:
        """The autopilot is PX4 (else ArduPilot conventions apply)."""
        return self.autopilot == MavAutopilot.PX4

    def in_external_control_mode(self) -> bool:
        """GUIDED (ArduPilot) or OFFBOARD (PX4), per the last HEARTBEAT."""
        if self.is_px4:
            return px4_mode_parts(self.custom_mode)[0] == Px4MainMode.OFFBOARD
        return self.custom_mode == CopterMode.GUIDED

    def takeover_confirmed(self) -> bool:
        """`TAKEOVER_CONFIRM_HEARTBEATS` HEARTBEATs in a row say the mode is not ours."""
        return self.other_mode_heartbeats >= TAKEOVER_CONFIRM_HEARTBEATS

    def position_age_s(self, now: float) -> float:
        """Seconds since the last accepted position."""
        return now - self.t_position

    def position_ok(self) -> bool:
        """A position has been received and, on ArduPilot, the EKF reports an absolute one."""
        if not math.isfinite(self.t_position):
            return False
        if self.is_px4 or self.ekf_flags is None:
            return self.is_px4
        flags = self.ekf_flags
        return flags & EKF_POSITION_OK == EKF_POSITION_OK and not flags & EkfFlag.CONST_POS_MODE

    def last_text(self, since: float) -> str:
        """The most recent STATUSTEXT received at or after ``since`` ("" if none)."""
        for t, _, text in reversed(self.texts):
            if t >= since:
                return text
        return ""

    # -- updates ------------------------------------------------------------------------

    def update(self, msg: Any, now: float) -> None:
        """Take one message from this vehicle's autopilot."""
        mid = msg.get_msgId()
        self.seen[msg.get_type()] += 1
        if mid == MsgId.HEARTBEAT:
            if msg.autopilot == MavAutopilot.INVALID:
                return  # another GCS or a companion, not the autopilot
            self.autopilot = msg.autopilot
            self.custom_mode, self.base_mode = msg.custom_mode, msg.base_mode
            self.system_status, self.t_heartbeat = msg.system_status, now
            ours = self.in_external_control_mode()
            self.other_mode_heartbeats = 0 if ours else self.other_mode_heartbeats + 1
            self._heartbeats.append(now)
            beats = self._heartbeats
            if (
                self.untrusted is None
                and len(beats) == HEARTBEATS_UNTRUSTED
                and now - beats[0] < HEARTBEAT_WINDOW_S
            ):
                self.untrusted = (
                    f"{HEARTBEATS_UNTRUSTED} HEARTBEATs within {HEARTBEAT_WINDOW_S:g} s: "
                    "more than one sender on its source"
                )
        elif mid == MsgId.GLOBAL_POSITION_INT:
            self._position(msg, now)
        elif mid == MsgId.ATTITUDE:
            if math.isfinite(msg.yaw) and abs(msg.yaw) <= 2 * math.pi:
                self.yaw_rad, self.t_yaw = float(msg.yaw), now
            else:
                self.rejected["attitude not a number"] += 1
        elif mid == MsgId.EKF_STATUS_REPORT:
            self.ekf_flags = int(msg.flags)
        elif mid == MsgId.EXTENDED_SYS_STATE:
            self.landed_state = int(msg.landed_state)
        elif mid == MsgId.STATUSTEXT:
            self.texts.append((now, int(msg.severity), printable(str(msg.text))))

    def _reject(self, reason: str, now: float) -> None:
        self.rejected[reason] += 1
        self._rejections.append(now)
        if (
            self.untrusted is None
            and len(self._rejections) == REJECTIONS_UNTRUSTED
            and now - self._rejections[0] <= REJECTIONS_WINDOW_S
        ):
            self.untrusted = (
                f"{REJECTIONS_UNTRUSTED} positions rejected within {REJECTIONS_WINDOW_S:g} s"
            )

    def _dead_reckon(self, ne: FloatArray, vel: FloatArray, t_vehicle_s: float) -> None:
        """Compare the fix with the integrated velocity history; flag a disagreement.

        Time is the vehicle's own (GLOBAL_POSITION_INT.time_boot_ms), not the arrival time: a
        link that delivers a backlog in one burst must not look like a position that outran its
        velocity. A clock that goes back or jumps (a reboot) restarts the dead reckoning.
        """
        dt = t_vehicle_s - self.t_fix_vehicle_s
        self.t_fix_vehicle_s = t_vehicle_s
        if not 0.0 < dt <= DEAD_RECKONING_MAX_GAP_S or not np.isfinite(self.dr_ne_m).all():
            self.dr_ne_m = ne.copy()
            return
        predicted = self.dr_ne_m + 0.5 * (self.vel_ned_m_s[:2] + vel[:2]) * dt
        self.disagreement_m = float(np.linalg.norm(ne - predicted))
        pull = 1.0 - math.exp(-dt / DEAD_RECKONING_TAU_S)
        self.dr_ne_m = predicted + pull * (ne - predicted)
        if self.untrusted is None and self.disagreement_m > DISAGREEMENT_UNTRUSTED_M:
            self.untrusted = (
                f"position disagrees with its own velocity by {self.disagreement_m:.0f} m"
            )

    def _position(self, msg: Any, now: float) -> None:
        if msg.lat == 0 and msg.lon == 0:
            self.rejected[NO_FIX] += 1
            return
        vel = np.array([msg.vx, msg.vy, msg.vz], dtype=np.float64) / 100.0
        if np.linalg.norm(vel) > MAX_SPEED_M_S or not (-90e7 <= msg.lat <= 90e7):
            self.rejected["impossible position or velocity"] += 1
            return
        n, e, d = geodetic_to_ned(
            from_deg_e7(msg.lat), from_deg_e7(msg.lon), msg.alt / 1000.0, self.origin
        )
        ne = np.array([float(n), float(e)])
        t_vehicle = int(msg.time_boot_ms) / 1000.0
        if math.isfinite(self.t_position):
            # the longer of the time between arrivals and on the vehicle's clock: a backlog
            # delivered in one burst arrives at once but was flown over seconds
            dt_vehicle = t_vehicle - self.t_fix_vehicle_s
            flown = dt_vehicle if 0.0 < dt_vehicle <= DEAD_RECKONING_MAX_GAP_S else 0.0
            elapsed = max(now - self.t_position, flown)
            if float(np.linalg.norm(ne - self.ne_m)) > MAX_SPEED_M_S * elapsed + 5.0:
                self._reject("position jump", now)
                return
        self._dead_reckon(ne, vel, t_vehicle)
        self.ne_m, self.height_m, self.vel_ned_m_s = ne, -float(d), vel
        self.t_position = now
        if msg.hdg != 65535 and not math.isfinite(self.t_yaw):
            self.yaw_rad = float(cdeg_to_yaw(msg.hdg))
