"""An independent reference for predictions of the fitted response: the command stream of a
decision replayed through `sim.vehicle.respond` at 10 ms and integrated by the trapezoid rule."""

from __future__ import annotations

import numpy as np

from sim.vehicle import VehicleProfile, respond

STEP_S = 0.01
"""Sampling and integration step of the reference, seconds."""


def dense_track(
    profile: VehicleProfile,
    heading: float,
    last_turn: float,
    last_speed: float,
    turn: float,
    first: float,
    then: float,
    dt_s: float,
    horizon_s: float,
    second: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times (T,), positions (T, 2) from the origin, velocity at time 0 (2,)).

    The last decision's arc (heading − last_turn → heading at ``last_speed``) is commanded
    from −dt, starting at rest on its first heading's velocity; the coming arc (heading →
    heading + turn at ``first``) from 0; then at ``then`` from dt on the arc turning by
    ``second`` more, and its final heading from 2·dt on.
    """
    t = np.arange(-dt_s, horizon_s + STEP_S / 2, STEP_S)
    past = t < 0
    frac = np.clip(np.where(past, (t + dt_s) / dt_s, t / dt_s), 0.0, 1.0)
    course = np.where(past, heading - last_turn + last_turn * frac, heading + turn * frac)
    course = course + second * np.clip(t / dt_s - 1.0, 0.0, 1.0)
    speed = np.where(past, last_speed, np.where(t < dt_s, first, then))
    cmd = speed[:, None] * np.stack([np.cos(course), np.sin(course)], axis=-1)
    vel = respond(profile, t, cmd, cmd[0], dt_s=STEP_S)
    now = int(np.argmin(np.abs(t)))
    v = vel[now:]
    steps = 0.5 * (v[1:] + v[:-1]) * STEP_S
    pos = np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return t[now:] - t[now], pos, vel[now]
