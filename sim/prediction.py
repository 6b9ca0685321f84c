"""Predicted motion of a UAV's candidate decisions, and closest approaches along it.

A candidate is a heading change a over the coming decision step: the UAV flies the
constant-turn-rate arc the simulator flies (sampled at `ARC_SEGMENTS` chords), then straight on
the arc's final heading until the horizon. Another vehicle's motion over the same instants
makes the relative position piecewise linear in time, whose closest approach to the origin has
a closed form per segment (`closest_approach`). Shared by the ORCA controller (`sim.orca`) and
the safety shield (`sim.shield`).
"""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from sim.arrays import FloatArray
from sim.kinematics import sinc_series

F = TypeVar("F", bound=np.floating[Any])
"""The float type of a path's coordinates (float64, or float32 where the shield saves bytes)."""

ARC_SEGMENTS = 4
"""Chords per predicted arc (the first decision step): the chord of a 5 m sub-arc turning by at
most π/16 lies within L·a_max/(8·4²) = 0.12 m of the arc at the defaults."""


TINY = 1e-12
"""Floor of lengths and squared lengths that divide, in their units (m, m/s, m², m²/s²)."""


def time_points(dt_s: float, horizon_s: float, chords: int = ARC_SEGMENTS) -> FloatArray:
    """(P,) instants of the predicted motion, seconds: the arc's ``chords`` chords, then τ."""
    arc = np.linspace(0.0, dt_s, chords + 1)
    return np.append(arc, horizon_s) if horizon_s > dt_s else arc


def displacements(
    heading_rad: FloatArray,
    turn_rad: FloatArray,
    speed_m_s: float | FloatArray,
    dt_s: float,
    horizon_s: float,
    chords: int = ARC_SEGMENTS,
) -> tuple[FloatArray, FloatArray]:
    """Own displacement (x, y), each (..., C, P), of every candidate at `time_points`.

    The arc of the first step as the simulator flies it (chord L·u·sinc(u·a/2) along
    h + u·a/2, sampled at ``chords`` chords), then straight on heading h + a at the same speed
    until τ. ``speed_m_s``: one speed, or one per candidate (broadcast to ``turn_rad``'s
    (..., C)).
    """
    u = np.linspace(0.0, 1.0, chords + 1)  # (S + 1,)
    half = 0.5 * turn_rad[..., None] * u  # (..., C, S + 1); |half| ≤ a_max/2 ≤ π/4
    chord = np.asarray(speed_m_s)[..., None] * dt_s * u * sinc_series(half)
    direction = heading_rad[..., None, None] + half
    dx, dy = chord * np.cos(direction), chord * np.sin(direction)
    if horizon_s > dt_s:
        final = heading_rad[..., None] + turn_rad  # (B, N, C)
        rest = speed_m_s * (horizon_s - dt_s)
        dx = np.concatenate([dx, (dx[..., -1] + rest * np.cos(final))[..., None]], axis=-1)
        dy = np.concatenate([dy, (dy[..., -1] + rest * np.sin(final))[..., None]], axis=-1)
    return dx, dy


def closest_approach(rx: FloatArray, ry: FloatArray) -> FloatArray:
    """Closest distance to the origin of piecewise-linear paths (..., P) → (...), closed form.

    On each segment r0 + u·Δ, u ∈ [0, 1], the closest point has u* = clip(−r0·Δ/|Δ|², 0, 1).
    """
    seg = segment_closest_sq(np.moveaxis(rx, -1, 0), np.moveaxis(ry, -1, 0))
    closest: FloatArray = np.sqrt(seg.min(axis=0))
    return closest


def segment_closest_sq(
    rx: NDArray[F], ry: NDArray[F], limit: NDArray[np.floating[Any]] | None = None
) -> NDArray[F]:
    """Squared closest distance to the origin on each segment of paths, time first.

    (P, ...) points → (P − 1, ...) segments (`closest_approach`'s closed form); with time the
    leading axis every operation runs over contiguous blocks. ``limit`` (broadcast to the
    segments, in [0, 1]): only the first that fraction of each segment counts.
    """
    x0, y0 = rx[:-1], ry[:-1]
    ddx, ddy = rx[1:] - x0, ry[1:] - y0
    dd = np.maximum(ddx * ddx + ddy * ddy, TINY)
    u = x0 * ddx
    u += y0 * ddy
    u /= dd
    np.negative(u, out=u)
    np.clip(u, 0.0, 1.0, out=u)
    if limit is not None:
        np.minimum(u, limit, out=u)
    ddx *= u
    ddx += x0
    ddy *= u
    ddy += y0
    ddx *= ddx
    ddy *= ddy
    ddx += ddy
    return ddx
