"""The active-contour cost f(S, Φ) of a trajectory window S (paper Eq. fitness).

    f(S) = ∫ ½|S''(ρ)|² dρ − ∫ ½|∇Φ(S(ρ))|² dρ        (ρ: arc length)

S is the UAV's last K decision steps, each a constant-turn-rate arc (`sim.kinematics`), the
newest being the arc of the action just taken. Both integrals are made non-dimensional so each
lies in [0, 1] per step:

* internal: on an arc of length L that turns by a, |S''| = κ = a/L, so ∫½κ² dρ = ½a²/L exactly
  (no quadrature). Dividing by its largest value ½a_max²/L and averaging over the K arcs gives
  mean_k (a_k / a_max)².
* external: mean over the window, in arc length, of an edge density e(q) ∈ [0, 1]:

  - ``"gradient"``: e = min(|∇Φ|/g_ref, 1)², the paper's literal ½|∇Φ|² scaled by the peak
    gradient g_ref = 2·v_s/d_safe³ of an obstacle's field (`sim.field.peak_gradient`);
  - ``"level-edge"``: e = exp(−s²/σ²) with s = (Φ(q) − φ_i)/|∇Φ(q)| the first-order signed
    distance from q to the UAV's own level set Φ = φ_i: an analytic, smoothed edge map of the
    field cut at the UAV's level, as in the active-contour method the paper builds on.

Quadrature of the external term: composite trapezoid rule in arc length on Q + 1 equally spaced
points of each arc (`RewardConfig.quadrature_intervals`; they are a subset of the T + 1 points of
the swept collision checks), error O((L/Q)²) for a smooth integrand.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, FloatArray
from sim.config import FieldConfig, RewardConfig
from sim.field import FieldSources, peak_gradient, potential_and_gradient_xy

PAIRWISE_BLOCK = 8
"""numpy sums a run of fewer numbers than this left to right (`_sum_last` matches it)."""

GRADIENT_FLOOR = 1e-12
"""|∇Φ| below this, in 1/(m²·s), counts as a flat field: no level-set edge there."""


@dataclass(frozen=True)
class ArcWindow:
    """The contour window S of every UAV: its last K arcs, oldest first, newest last.

    Each arc is scored once, when it is flown, against the field of that moment (the field moves
    with the obstacles and the virtual centre: what matters is whether the UAV followed its
    contour while it flew the arc, not where that contour has gone since).

    Attributes:
        turn_rad: (B, N, K) heading change over each arc.
        external: (B, N, K) arc-length mean of the edge density e along each arc, in [0, 1].
        valid: (B, N, K) False for arcs before the episode started (not yet flown).
    """

    turn_rad: FloatArray
    external: FloatArray
    valid: BoolArray

    @classmethod
    def empty(cls, num_envs: int, num_uavs: int, window_steps: int) -> ArcWindow:
        """A window with no arc flown yet, (B, N, K)."""
        shape = (num_envs, num_uavs, window_steps)
        return cls(np.zeros(shape), np.zeros(shape), np.zeros(shape, dtype=bool))

    def push(self, turn_rad: FloatArray, external: FloatArray, flown: BoolArray) -> ArcWindow:
        """The window after one more step: the oldest arc drops out, the new arc comes last.

        Args:
            turn_rad: (B, N) heading change of the arc just flown.
            external: (B, N) its edge score (`arc_external`).
            flown: (B, N) False for UAVs that did not fly this step (masked out); their
                windows are left unchanged.
        """
        return ArcWindow(
            turn_rad=_shifted(self.turn_rad, turn_rad, flown),
            external=_shifted(self.external, external, flown),
            valid=_shifted(self.valid, flown, flown),
        )

    def reset(self, mask: BoolArray) -> ArcWindow:
        """The window with the environments selected by ``mask`` (B,) emptied."""
        keep = ~mask[:, None, None]
        return ArcWindow(self.turn_rad * keep, self.external * keep, self.valid & keep)


def _shifted(old: NDArray[Any], new: NDArray[Any], flown: BoolArray) -> NDArray[Any]:
    """``old`` (B, N, K) shifted one arc to the left with ``new`` (B, N) last, where ``flown``.

    Slot by slot on (B, N) slices: a selection over the whole window would broadcast ``flown``
    along its short last axis, which numpy runs one K-long row at a time.
    """
    out = np.empty_like(old)
    for k in range(old.shape[-1] - 1):
        np.copyto(out[..., k], np.where(flown, old[..., k + 1], old[..., k]))
    np.copyto(out[..., -1], np.where(flown, new, old[..., -1]))
    return out


def _sum_last(a: NDArray[Any]) -> NDArray[Any]:
    """``a.sum(axis=-1)``, bit for bit, for a short last axis: added slice by slice.

    numpy adds fewer than 8 numbers left to right (pairwise beyond), and runs a reduction over
    a short last axis one row at a time; the slices are whole (B, N) arrays.
    """
    k = a.shape[-1]
    if k == 0 or k >= PAIRWISE_BLOCK:
        total: NDArray[Any] = a.sum(axis=-1)
        return total
    out = a[..., 0].copy()
    for i in range(1, k):
        out += a[..., i]
    return out


@dataclass(frozen=True)
class ContourTerms:
    """The two non-dimensional terms of f, each in [0, 1]: f = w_int·internal − w_ext·external.

    Attributes:
        internal: (B, N) mean_k (a_k/a_max)² over the valid arcs of the window.
        external: (B, N) mean edge density e over the valid arcs of the window.
    """

    internal: FloatArray
    external: FloatArray


def arc_bending_energy(turn_rad: FloatArray, length_m: float) -> FloatArray:
    """∫ ½|S''|² dρ over one arc, in 1/m: ½a²/L (closed form).

    >>> float(arc_bending_energy(np.array(np.pi / 4), 20.0).round(6))
    0.015421
    """
    return 0.5 * np.square(turn_rad) / length_m


def trapezoid_weights(intervals: int) -> FloatArray:
    """Weights of the composite trapezoid rule on intervals + 1 equally spaced points (sum 1).

    >>> trapezoid_weights(4).tolist()
    [0.125, 0.25, 0.25, 0.25, 0.125]
    """
    w = np.full(intervals + 1, 1.0 / intervals)
    w[[0, -1]] *= 0.5
    return w


def external_density_xy(
    x_m: FloatArray,
    y_m: FloatArray,
    levels: FloatArray | None,
    src: FieldSources,
    field_cfg: FieldConfig,
    reward_cfg: RewardConfig,
) -> FloatArray:
    """Edge density e(q) ∈ [0, 1] at points given by coordinates x, y (each (B, *P)).

    Args:
        levels: φ_i broadcastable to (B, *P), required by "level-edge".

    Returns:
        (B, *P) densities.
    """
    phi, gx, gy = potential_and_gradient_xy(x_m, y_m, src, field_cfg)
    gx *= gx
    gy *= gy
    gx += gy
    gnorm = np.sqrt(gx, out=gx)
    if reward_cfg.external == "gradient":
        return np.square(np.minimum(gnorm / peak_gradient(field_cfg, src.swarm_speed_m_s), 1.0))
    if levels is None:
        raise ValueError('the "level-edge" external term needs the UAVs\' contour levels')
    has_edge = gnorm > GRADIENT_FLOOR
    # signed = (Φ − φ_i)/(|∇Φ|·σ), with |∇Φ| replaced by 1 where there is no edge: adding 1 to a
    # product below GRADIENT_FLOOR·σ gives exactly 1 in any float, as np.where would.
    den = gnorm
    den *= reward_cfg.edge_width_m
    den += ~has_edge
    signed = phi - levels
    signed /= den
    signed *= signed
    np.negative(signed, out=signed)
    dens = np.exp(signed, out=signed)
    dens *= has_edge
    return dens


def external_density(
    points_m: FloatArray,
    levels: FloatArray | None,
    src: FieldSources,
    field_cfg: FieldConfig,
    reward_cfg: RewardConfig,
) -> FloatArray:
    """`external_density_xy` at points given as one array ``points_m`` (B, *P, 2)."""
    return external_density_xy(
        points_m[..., 0], points_m[..., 1], levels, src, field_cfg, reward_cfg
    )


def arc_external(
    points_m: FloatArray,
    levels: FloatArray,
    src: FieldSources,
    field_cfg: FieldConfig,
    reward_cfg: RewardConfig,
) -> FloatArray:
    """Arc-length mean of the edge density along each arc (trapezoid rule): (B, N) in [0, 1].

    Args:
        points_m: (B, N, T + 1, 2) equally spaced points of each arc, ends included
            (`sim.kinematics.arc_points` at `sim.metrics.substep_fractions`).
        levels: (B, N) each UAV's contour level φ_i (ignored by the "gradient" term).
    """
    return arc_external_xy(points_m[..., 0], points_m[..., 1], levels, src, field_cfg, reward_cfg)


def arc_external_xy(
    x_m: FloatArray,
    y_m: FloatArray,
    levels: FloatArray,
    src: FieldSources,
    field_cfg: FieldConfig,
    reward_cfg: RewardConfig,
) -> FloatArray:
    """`arc_external` on the coordinates of the arc points, each (B, N, T + 1)."""
    dens = external_density_xy(x_m, y_m, levels[..., None], src, field_cfg, reward_cfg)
    # The trapezoid rule as one matrix–vector product on (B·N, T + 1) rows, in float64.
    rows = dens.reshape(-1, dens.shape[-1]).astype(np.float64)
    mean: FloatArray = (rows @ trapezoid_weights(x_m.shape[-1] - 1)).reshape(dens.shape[:-1])
    return mean


def window_terms(window: ArcWindow, max_turn_rad: float) -> ContourTerms:
    """Internal and external terms of f(S, Φ) over each UAV's window: (B, N) each.

    The internal term is exact for arcs (see the module docstring); both are means over the
    valid arcs of the window, so a window that is not full yet is not penalised for its length.
    """
    valid = window.valid
    count = np.maximum(_sum_last(valid.astype(np.int64)), 1)  # (B, N)
    internal = _sum_last(np.where(valid, np.square(window.turn_rad / max_turn_rad), 0.0))
    external = _sum_last(np.where(valid, window.external, 0.0))
    internal /= count
    external /= count
    return ContourTerms(internal=internal, external=external)
