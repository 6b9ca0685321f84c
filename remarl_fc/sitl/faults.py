"""Faults the mock can inject.

A lossy, late link; cut links; silent heartbeats; GPS glitches; a pilot taking the mode switch.

Times are simulated seconds since the fleet started. A `vehicle` of None means every vehicle.
Use the `Faults` methods from Python, or the `remarl-fc sitl` flags (`parse_window` and friends
read their ``V:START:END`` syntax).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Targeted:
    """A fault on one vehicle (its index) or on every vehicle (None)."""

    vehicle: int | None

    def targets(self, vehicle: int) -> bool:
        """Whether the fault is on ``vehicle`` (an index)."""
        return self.vehicle is None or self.vehicle == vehicle


@dataclass(frozen=True)
class Window(Targeted):
    """A time window [start_s, end_s) on one vehicle (index) or all (None)."""

    start_s: float
    end_s: float

    def __post_init__(self) -> None:
        if not self.end_s > self.start_s >= 0:
            raise ValueError(f"window {self.start_s}..{self.end_s} s must have 0 ≤ start < end")

    @classmethod
    def lasting(cls, vehicle: int | None, start_s: float, duration_s: float) -> Window:
        """The window [start_s, start_s + duration_s) on ``vehicle``."""
        return cls(vehicle, start_s, start_s + duration_s)

    def covers(self, vehicle: int, now_s: float) -> bool:
        """Whether the window applies to ``vehicle`` at ``now_s``."""
        return self.targets(vehicle) and self.start_s <= now_s < self.end_s


@dataclass(frozen=True)
class GpsGlitch:
    """Reported positions of a vehicle jump by ``offset_m`` north (then return) in a window."""

    window: Window
    offset_m: float


@dataclass(frozen=True)
class PilotSwitch(Targeted):
    """At ``at_s`` the pilot switches vehicle ``vehicle`` (None: all) to ``mode``."""

    at_s: float
    mode: str


@dataclass
class Faults:
    """Every fault of a fleet; mutate it while the fleet runs to inject faults live.

    Attributes:
        loss: probability that a datagram (either way) is dropped, 0..1.
        latency_s: one-way delay added to every datagram, simulated seconds.
        jitter_s: uniform extra delay 0..jitter_s per datagram.
        link_cuts, heartbeat_dropouts: windows with no traffic / no HEARTBEAT.
        gps_glitches: jumps of the reported position (EKF flags GPS_GLITCHING meanwhile).
        pilot_switches: mode changes by "the pilot", applied once each.
    """

    loss: float = 0.0
    latency_s: float = 0.0
    jitter_s: float = 0.0
    link_cuts: list[Window] = field(default_factory=list)
    heartbeat_dropouts: list[Window] = field(default_factory=list)
    gps_glitches: list[GpsGlitch] = field(default_factory=list)
    pilot_switches: list[PilotSwitch] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not 0.0 <= self.loss <= 1.0:
            raise ValueError(f"loss must be a probability 0..1, not {self.loss}")
        if self.latency_s < 0 or self.jitter_s < 0:
            raise ValueError("latency and jitter must be ≥ 0 s")

    def cut_link(self, vehicle: int | None, start_s: float, duration_s: float) -> None:
        """No datagram to or from ``vehicle`` during [start_s, start_s + duration_s)."""
        self.link_cuts.append(Window.lasting(vehicle, start_s, duration_s))

    def drop_heartbeats(self, vehicle: int | None, start_s: float, duration_s: float) -> None:
        """``vehicle`` sends no HEARTBEAT during the window (other messages still flow)."""
        self.heartbeat_dropouts.append(Window.lasting(vehicle, start_s, duration_s))

    def glitch_gps(
        self, vehicle: int | None, start_s: float, duration_s: float, offset_m: float
    ) -> None:
        """Reported position jumps ``offset_m`` north during the window."""
        self.gps_glitches.append(GpsGlitch(Window.lasting(vehicle, start_s, duration_s), offset_m))

    def switch_mode(self, vehicle: int | None, at_s: float, mode: str) -> None:
        """The pilot takes ``vehicle`` into ``mode`` at ``at_s``."""
        self.pilot_switches.append(PilotSwitch(vehicle, at_s, mode))

    def link_down(self, vehicle: int, now_s: float) -> bool:
        """Whether ``vehicle``'s link is cut now."""
        return any(w.covers(vehicle, now_s) for w in self.link_cuts)

    def heartbeat_muted(self, vehicle: int, now_s: float) -> bool:
        """Whether ``vehicle``'s HEARTBEATs are being dropped now."""
        return any(w.covers(vehicle, now_s) for w in self.heartbeat_dropouts)

    def gps_offset_m(self, vehicle: int, now_s: float) -> float | None:
        """North offset of ``vehicle``'s reported position now, or None when not glitching."""
        for g in self.gps_glitches:
            if g.window.covers(vehicle, now_s):
                return g.offset_m
        return None

    def drop(self, rng: np.random.Generator) -> bool:
        """Draw whether one datagram is lost."""
        return self.loss > 0 and bool(rng.random() < self.loss)

    def delay_s(self, rng: np.random.Generator) -> float:
        """Draw one datagram's delay, simulated seconds."""
        if self.jitter_s > 0:
            return self.latency_s + float(rng.uniform(0.0, self.jitter_s))
        return self.latency_s


def _vehicle(text: str) -> int | None:
    if text.lower() == "all":
        return None
    try:
        v = int(text)
    except ValueError as exc:
        raise ValueError(f"vehicle {text!r} is not an index (0, 1, …) or 'all'") from exc
    if v < 0:
        raise ValueError(f"vehicle index {v} is negative")
    return v


def _numbers(parts: list[str], spec: str, what: str) -> list[float]:
    try:
        return [float(p) for p in parts]
    except ValueError as exc:
        raise ValueError(f"{spec!r}: {what}") from exc


def parse_window(spec: str) -> Window:
    """``V:START:END`` (vehicle index or ``all``, simulated seconds) → `Window`.

    >>> parse_window("1:10:15")
    Window(vehicle=1, start_s=10.0, end_s=15.0)
    """
    parts = spec.split(":")
    if len(parts) != 3:
        raise ValueError(f"{spec!r} is not VEHICLE:START_S:END_S (e.g. 0:10:15 or all:5:6)")
    start, end = _numbers(parts[1:], spec, "START and END are seconds")
    return Window(_vehicle(parts[0]), start, end)


def parse_glitch(spec: str) -> GpsGlitch:
    """``V:START:END:METRES`` → `GpsGlitch`."""
    head, _, metres = spec.rpartition(":")
    if not head:
        raise ValueError(f"{spec!r} is not VEHICLE:START_S:END_S:METRES (e.g. 0:20:25:30)")
    (offset,) = _numbers([metres], spec, "METRES is a number")
    return GpsGlitch(parse_window(head), offset)


def parse_pilot_switch(spec: str) -> PilotSwitch:
    """``V:AT_S:MODE`` → `PilotSwitch` (e.g. ``0:30:LOITER``)."""
    parts = spec.split(":")
    if len(parts) != 3 or not parts[2]:
        raise ValueError(f"{spec!r} is not VEHICLE:AT_S:MODE (e.g. 0:30:LOITER)")
    (at,) = _numbers([parts[1]], spec, "AT_S is seconds")
    return PilotSwitch(_vehicle(parts[0]), at, parts[2])
