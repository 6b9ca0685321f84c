"""Constant-turn-rate kinematics: one decision step is a circular arc (or a straight segment).

A UAV at position p with heading h that changes its heading by a over a step of arc length
L = v·dt flies the arc of curvature κ = a/L; the chord of that arc has length L·sinc(a/2) and
points along h + a/2. This form has no division by a, so straight flight (a = 0) needs no
special case. Headings are counter-clockwise from +x, radians.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import FloatArray

SINC_SERIES_BELOW = 1e-3
"""|x| below which sin(x)/x is evaluated as 1 − x²/6 (error < 1e-13)."""


def scale_action(action: FloatArray, max_turn_rad: float) -> FloatArray:
    """Map normalised actions in [−1, 1] to heading changes in [−a_max, a_max], radians.

    The only place where actions are scaled; values outside [−1, 1] are clipped.

    >>> scale_action(np.array([-2.0, 0.5]), np.pi / 4).round(4).tolist()
    [-0.7854, 0.3927]
    """
    # np.clip's numbers without its Python wrapper
    scaled: FloatArray = np.minimum(np.maximum(action, -1.0), 1.0) * max_turn_rad
    return scaled


def heading_velocity(heading_rad: NDArray[Any], speed_m_s: float | NDArray[Any]) -> FloatArray:
    """Velocity (..., 2) of flight at ``speed_m_s`` along ``heading_rad`` (...), m/s.

    The velocity every UAV and obstacle has in the simulator, and the one the flight runtime
    gives the observation builder.

    >>> heading_velocity(np.array([0.0, np.pi / 2]), 10.0).round(6).tolist()
    [[10.0, 0.0], [0.0, 10.0]]
    """
    velocity: FloatArray = speed_m_s * np.stack([np.cos(heading_rad), np.sin(heading_rad)], axis=-1)
    return velocity


def wrap_angle(angle_rad: FloatArray) -> FloatArray:
    """Wrap angles to [−π, π).

    >>> wrap_angle(np.array([3 * np.pi / 2, -np.pi])).round(4).tolist()
    [-1.5708, -3.1416]
    """
    return (angle_rad + np.pi) % (2 * np.pi) - np.pi


def sinc(x: FloatArray) -> FloatArray:
    """sin(x)/x, with 1 at 0 and a 3-term series below |x| = 1e-3 (numpy's sinc is slower)."""
    small = np.abs(x) < SINC_SERIES_BELOW
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 - x * x / 6.0, np.sin(safe) / safe)


SINC_SERIES_MAX = math.pi / 4
"""Largest |x| for `sinc_series` (a heading change of π/2 over one arc, the config's limit)."""


def sinc_series(x: NDArray[Any]) -> NDArray[Any]:
    """sin(x)/x for |x| ≤ π/4 by its Taylor series to x⁸ (error < 3e-9): no division, no branch.

    >>> float(abs(sinc_series(np.array(0.7)) - np.sin(0.7) / 0.7)) < 3e-9
    True
    """
    x2 = x * x
    series: NDArray[Any] = 1.0 + x2 * (-1 / 6 + x2 * (1 / 120 + x2 * (-1 / 5040 + x2 / 362880)))
    return series


def arc_points_xy(
    start_m: FloatArray,
    heading_rad: FloatArray,
    turn_rad: FloatArray,
    length_m: float | FloatArray,
    fractions: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """X and y (each (..., Q)) of the points at the given fractions of arc length.

    The same as `arc_points`, as two contiguous component arrays (faster to work with);
    ``length_m`` may also be an array (...,) of per-arc lengths (0 keeps a UAV in place).
    """
    u = np.asarray(fractions, dtype=np.float64)
    half = (0.5 * u) * turn_rad[..., None]  # (..., Q)
    chord = (np.asarray(length_m)[..., None] * u) * sinc(half)  # (..., Q)
    direction = heading_rad[..., None] + half
    x = start_m[..., 0, None] + chord * np.cos(direction)
    y = start_m[..., 1, None] + chord * np.sin(direction)
    return x, y


def arc_points(
    start_m: FloatArray,
    heading_rad: FloatArray,
    turn_rad: FloatArray,
    length_m: float,
    fractions: FloatArray,
) -> FloatArray:
    """Points at the given fractions of arc length along each arc.

    Args:
        start_m: (..., 2) start of each arc.
        heading_rad: (...,) heading at the start.
        turn_rad: (...,) heading change over the whole arc.
        length_m: arc length L.
        fractions: (Q,) values in [0, 1].

    Returns:
        (..., Q, 2) points.
    """
    return np.stack(arc_points_xy(start_m, heading_rad, turn_rad, length_m, fractions), axis=-1)


def arc_step(
    start_m: FloatArray, heading_rad: FloatArray, turn_rad: FloatArray, length_m: float
) -> tuple[FloatArray, FloatArray]:
    """End position (..., 2) and end heading (...,) of each arc; headings are wrapped."""
    end = arc_points(start_m, heading_rad, turn_rad, length_m, np.ones(1))[..., 0, :]
    return end, wrap_angle(heading_rad + turn_rad)


def straight_points(
    start_m: FloatArray, velocity_m_s: FloatArray, dt_s: float, fractions: FloatArray
) -> FloatArray:
    """Points of straight, constant-velocity motion at fractions of a step: (..., Q, 2)."""
    u = np.asarray(fractions, dtype=np.float64)
    return start_m[..., None, :] + (dt_s * u)[:, None] * velocity_m_s[..., None, :]
