"""The multirotor's response to velocity and yaw setpoints, fitted to real autopilots.

A vehicle flown through MAVLink velocity setpoints (what ``fly`` sends) does not turn on a
perfect arc the moment a heading is decided, as the paper's simulator assumes (profile
"ideal"). It follows its command late and smoothly: after a transport delay, its horizontal
velocity tracks the commanded one to first order with a time constant, and its acceleration is
capped; its yaw tracks the commanded yaw to first order with a rate cap. The parameters of each
autopilot are fitted by least squares to traces of real firmware in SITL flown with our own
setpoints (`tools/fit_vehicle.py`, figures in ``docs/MODEL.md`` §16), and shipped as data
(``sim/vehicles/*.toml``).

Batched like the simulator: velocities (..., 2), any batch dimensions first; one step updates
every vehicle at once. Units: metres, seconds, radians; yaw counter-clockwise from +x in the
simulator's frame (the trace tools convert from NED).
"""

from __future__ import annotations

import csv
import math
from collections import deque
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import FloatArray
from sim.datafiles import read_toml, shipped_names
from sim.errors import ConfigError
from sim.kinematics import wrap_angle


@dataclass(frozen=True)
class VehicleProfile:
    """How one kind of vehicle answers velocity and yaw setpoints.

    ``ideal`` is the paper's model (no lag, any acceleration): velocity equals the command.
    """

    name: str
    description: str = ""
    ideal: bool = False
    """True: the command is flown exactly and at once (the simulator's arcs)."""

    delay_s: float = 0.0
    """Transport delay between a setpoint and the start of the response, seconds."""

    velocity_tau_s: float = 0.5
    """Time constant of the first-order horizontal velocity tracking, seconds."""

    max_accel_m_s2: float = 5.0
    """Cap on the norm of the horizontal acceleration, m/s²."""

    yaw_tau_s: float = 0.35
    """Time constant of the first-order yaw tracking, seconds."""

    max_yaw_rate_rad_s: float = math.radians(60.0)
    """Cap on the yaw rate, rad/s (file key max_yaw_rate_deg_s)."""

    can_hover: bool = True
    """The vehicle can slow down and stop in the air (a multirotor); the paper's ideal UAV flies
    at its constant speed (the safety shield only turns it)."""

    fit_rms_m_s: float = 0.0
    """RMS horizontal velocity error of the fit on its traces, m/s (a record, not a setting)."""

    fitted_on: tuple[str, ...] = ()
    """The trace files the parameters were fitted to (a record)."""

    def __post_init__(self) -> None:
        for name in ("velocity_tau_s", "max_accel_m_s2", "yaw_tau_s", "max_yaw_rate_rad_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"vehicle profile {self.name}: {name} must be > 0, got {value}")
        if not (math.isfinite(self.delay_s) and self.delay_s >= 0):
            raise ConfigError(f"vehicle profile {self.name}: delay_s must be >= 0")


def profile_names() -> list[str]:
    """The vehicle profiles shipped with the package."""
    return shipped_names("vehicles")


def load_profile(name_or_path: str | Path) -> VehicleProfile:
    """A shipped profile by name ("ideal", "arducopter", "px4", ...) or a profile file by path.

    Raises:
        ConfigError: unknown name, unreadable file, unknown key or bad value.
    """
    data, path = read_toml("vehicles", name_or_path, "vehicle profile")
    known = {f.name for f in fields(VehicleProfile)} - {"max_yaw_rate_rad_s"}
    kwargs: dict[str, Any] = {"name": path.stem}
    for key, value in data.items():
        if key == "max_yaw_rate_deg_s":
            kwargs["max_yaw_rate_rad_s"] = math.radians(float(value))
        elif key in known:
            kwargs[key] = tuple(value) if isinstance(value, list) else value
        else:
            raise ConfigError(f"{path}: unknown key {key!r}; allowed: {', '.join(sorted(known))}")
    return VehicleProfile(**kwargs)


def track_velocity(
    velocity_m_s: FloatArray, command_m_s: FloatArray, profile: VehicleProfile, dt_s: float
) -> FloatArray:
    """The horizontal velocity after ``dt_s`` of first-order, acceleration-capped tracking.

    Args:
        velocity_m_s: (..., 2) current velocities.
        command_m_s: (..., 2) the commands in force (already delayed by the caller).

    The update is exact for the uncapped first-order response over ``dt_s`` (exponential
    decay of the error); when the acceleration it needs exceeds the cap, the velocity moves
    toward the command by at most ``max_accel_m_s2``·dt.
    """
    if profile.ideal:
        return command_m_s.copy()
    velocity = velocity_m_s[..., 0] + 1j * velocity_m_s[..., 1]
    command = command_m_s[..., 0] + 1j * command_m_s[..., 1]
    fraction = closing_fraction(profile.velocity_tau_s, dt_s)
    new = approach(velocity, command, fraction, profile.max_accel_m_s2 * dt_s)
    return np.stack([new.real, new.imag], axis=-1)


def closing_fraction(tau_s: float | FloatArray, dt_s: float) -> FloatArray:
    """The share of a velocity error a first-order response closes in ``dt_s``: 1 − e^(−dt/τ)."""
    fraction: FloatArray = -np.expm1(-dt_s / np.asarray(tau_s, dtype=np.float64))
    return fraction


def approach(
    velocity: NDArray[np.complex128],
    command: NDArray[np.complex128],
    fraction: float | FloatArray | NDArray[np.complex128],
    cap_m_s: float | FloatArray,
    out: NDArray[np.complex128] | None = None,
) -> NDArray[np.complex128]:
    """One step of the response, on horizontal velocities as complex numbers (x + iy).

    The one implementation of the model: the velocity closes ``fraction`` of its error to the
    command (`closing_fraction`: exact for a first-order response over the step), by at most
    ``cap_m_s`` (the acceleration cap times the step). Any shapes that broadcast; ``out``: where
    to put the new velocity, of the shape of the velocity error (None: a new array or number).
    ``fraction`` may come cast to complex already (the same numbers: the product casts it).
    """
    step = (command - velocity) * fraction
    norm = np.abs(step)
    if out is None:  # numbers or arrays of any shape
        new: NDArray[np.complex128] = velocity + step * np.minimum(
            1.0, cap_m_s / np.maximum(norm, 1e-300)
        )
        return new
    # the simulator's hot loop: the same operations, in place on the step's own arrays
    np.maximum(norm, 1e-300, out=norm)
    limit = np.divide(cap_m_s, norm)
    np.minimum(1.0, limit, out=limit)
    np.multiply(step, limit, out=step)
    return np.add(velocity, step, out=out)


def track_yaw(
    yaw_rad: FloatArray, command_rad: FloatArray, profile: VehicleProfile, dt_s: float
) -> FloatArray:
    """The yaw after ``dt_s`` of first-order, rate-capped tracking of ``command_rad`` (...)."""
    if profile.ideal:
        return command_rad.copy()
    error = wrap_angle(command_rad - yaw_rad)
    step = error * -math.expm1(-dt_s / profile.yaw_tau_s)
    cap = profile.max_yaw_rate_rad_s * dt_s
    new: FloatArray = wrap_angle(yaw_rad + np.clip(step, -cap, cap))
    return new


def respond(
    profile: VehicleProfile,
    times_s: FloatArray,
    command_m_s: FloatArray,
    velocity0_m_s: FloatArray,
    dt_s: float = 0.01,
) -> FloatArray:
    """Replay a recorded command sequence: the model's velocity at each of ``times_s``.

    Args:
        times_s: (T,) increasing sample times; the command ``command_m_s`` (T, 2) holds from its
            sample until the next (zero-order hold, as setpoints do), delayed by the profile's
            ``delay_s``.
        velocity0_m_s: (2,) the velocity at ``times_s[0]``.
        dt_s: integration step.

    Returns:
        (T, 2) velocities at the sample times (the commands themselves for the ideal profile).
    """
    if profile.ideal:
        return np.asarray(command_m_s, dtype=np.float64).copy()
    grid = np.arange(times_s[0], times_s[-1] + dt_s, dt_s)
    held = np.searchsorted(times_s, grid - profile.delay_s, side="right") - 1
    cmd = np.where((held >= 0)[:, None], command_m_s[np.maximum(held, 0)], command_m_s[0])
    vel = np.empty((len(grid), 2))
    v = np.asarray(velocity0_m_s, dtype=np.float64)
    for k in range(len(grid)):
        vel[k] = v
        v = track_velocity(v, cmd[k], profile, dt_s)
    out = np.empty((len(times_s), 2))
    for axis in range(2):
        out[:, axis] = np.interp(times_s, grid, vel[:, axis])
    return out


class DelayLine:
    """Commands delayed by a whole number of fixed steps: what a vehicle acts on now.

    The caller owns it and steps at a fixed ``dt_s`` (the mock's physics rate); the delay is
    rounded to whole steps (0.33 s at 50 Hz: 16 steps, 0.32 s). Until it has filled, the first
    command pushed is what comes out.
    """

    def __init__(self, delay_s: float, dt_s: float) -> None:
        self.steps = max(0, round(delay_s / dt_s))
        self._queue: deque[FloatArray] = deque(maxlen=self.steps + 1)

    def push(self, command: FloatArray) -> FloatArray:
        """Add this step's command; the one from ``steps`` steps ago comes back."""
        if self.steps == 0:
            return command
        self._queue.append(command.copy())
        return self._queue[0]


@dataclass(frozen=True)
class Trace:
    """A recorded response of real firmware to our setpoints (one CSV of the SITL traces).

    North/east velocities; yaws counter-clockwise in radians (the files' NED degrees
    converted), not unwrapped. Attributes are (T,) or (T, 2) arrays, one row per sample.
    """

    times_s: FloatArray
    command_m_s: FloatArray
    velocity_m_s: FloatArray
    command_yaw_rad: FloatArray
    yaw_rad: FloatArray


def read_trace(path: Path) -> Trace:
    """Read one trace file.

    Columns t_s, cmd_vn_m_s, cmd_ve_m_s, vn_m_s, ve_m_s, cmd_yaw_deg, yaw_deg, as the README of
    the traces describes them.
    """
    with path.open(encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    col = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    return Trace(
        times_s=col["t_s"],
        command_m_s=np.stack([col["cmd_vn_m_s"], col["cmd_ve_m_s"]], axis=-1),
        velocity_m_s=np.stack([col["vn_m_s"], col["ve_m_s"]], axis=-1),
        command_yaw_rad=-np.radians(col["cmd_yaw_deg"]),  # NED clockwise → counter-clockwise
        yaw_rad=-np.radians(col["yaw_deg"]),
    )
