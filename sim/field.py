"""The potential field Φ and its analytic gradient.

Paper Eq. obstaclefield, swarmfield and environmentfield.

Obstacles and the swarm's virtual centre p* are peaks (one p* per swarm where a scenario flies
several, `UAVConfig.groups`: Φ_s is then the sum of their peaks)::

    Φ_o(q) = I_o / d_safe²   for |q − p_o| ≤ d_safe         I_o = max(v_o, v_s)
           = I_o / |q − p_o|²  for d_safe < |q − p_o| ≤ R_o
           = 0                beyond R_o
    Φ_s(q) = v_s / max(|q − p*|, d_floor)²  for |q − p*| ≤ R_s, 0 beyond
    Φ(q)   = Φ_s(q) + Σ_o Φ_o(q)

With ``FieldConfig.continuous`` (the default) each source's field is lowered by its value at
its range, I/R_o² or v_s/R_s², inside that range: Φ is then continuous and falls to 0 at R
instead of jumping there (a jump is a spurious contour, a ring that has nothing to do with an
obstacle's shape); ∇Φ is the same either way.

Units: Φ in 1/(m·s) (a speed over an area), ∇Φ in 1/(m²·s). Every function takes points of
shape (B, *P, 2) — any number of points per environment — and sources batched on B.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.arrays import BoolArray, FloatArray
from sim.config import FieldConfig

GRADIENT_EXPONENT = 2.0
"""Exponent of the inverse-square law of Eq. obstaclefield/swarmfield (|∇(1/d²)| = 2/d³)."""


@dataclass(frozen=True)
class FieldSources:
    """The sources of Φ in a batch of B environments.

    Attributes:
        obstacle_pos_m: (B, M, 2) obstacle positions.
        obstacle_speed_m_s: (B, M) obstacle speeds v_o (0 for static obstacles).
        centre_m: (B, G, 2) each swarm's virtual centre p* (G = 1 but for `UAVConfig.groups`).
        swarm_speed_m_s: v_s, the swarm's speed.
        obstacle_mask: (B, M) True where an obstacle exists (None: all exist).
    """

    obstacle_pos_m: FloatArray
    obstacle_speed_m_s: FloatArray
    centre_m: FloatArray
    swarm_speed_m_s: float
    obstacle_mask: BoolArray | None = None

    def __post_init__(self) -> None:
        if self.centre_m.ndim != 3 or self.centre_m.shape[-1] != 2:
            raise ValueError(f"centre_m is {self.centre_m.shape}: give (B, G, 2), a p* per swarm")

    @property
    def num_envs(self) -> int:
        """B, the batch size."""
        return int(self.centre_m.shape[0])

    def intensity(self) -> FloatArray:
        """I_o = max(v_o, v_s) per obstacle, (B, M); 0 for masked-out obstacles."""
        inten = np.maximum(self.obstacle_speed_m_s, self.swarm_speed_m_s)
        if self.obstacle_mask is not None:
            inten = np.where(self.obstacle_mask, inten, 0.0)
        return inten


def _expand(source: FloatArray, points_ndim: int) -> FloatArray:
    """Reshape per-env (B,) or (B, M) arrays to broadcast against (B, *P[, M]) point arrays."""
    return source.reshape(source.shape[:1] + (1,) * (points_ndim - 1) + source.shape[1:])


def _inverse_square(
    d2: FloatArray,
    intensity: FloatArray | float,
    plateau_m: float,
    range_m: float,
    shift: bool,
    gradient: bool = True,
) -> tuple[FloatArray, FloatArray | None]:
    """I/max(d, plateau)² inside the range (lowered by I/R² if ``shift``) and its gradient factor.

    Computed in place on as few temporaries as the formula allows (the same operations, in the
    same order, as the formula reads).

    Returns:
        (phi, coef) with ∇ = coef·(q − p): coef = −2I/d⁴ on the slope, 0 on the plateau and
        outside the range; None unless ``gradient``.
    """
    inside = d2 <= range_m**2
    inv = np.maximum(d2, plateau_m**2)
    np.divide(1.0, inv, out=inv)
    phi = inv - 1.0 / range_m**2 if shift else inv * 1.0
    phi *= intensity
    phi *= inside
    if not gradient:
        return phi, None
    slope = d2 > plateau_m**2
    slope &= inside
    coef = inv
    coef *= inv
    coef *= -GRADIENT_EXPONENT * intensity
    coef *= slope
    return phi, coef


def obstacle_terms(
    points_m: FloatArray, src: FieldSources, cfg: FieldConfig
) -> tuple[FloatArray, FloatArray]:
    """Each obstacle's Φ_o and ∇Φ_o at the points.

    Args:
        points_m: (B, *P, 2).

    Returns:
        (phi (B, *P, M), grad (B, *P, M, 2)).
    """
    nd = points_m.ndim - 1
    diff = points_m[..., None, :] - _expand(src.obstacle_pos_m, nd)  # (B, *P, M, 2)
    d2 = np.einsum("...i,...i->...", diff, diff)  # (B, *P, M)
    phi, coef = _inverse_square(
        d2, _expand(src.intensity(), nd), cfg.d_safe_m, cfg.obstacle_range_m, cfg.continuous
    )
    assert coef is not None
    return phi, coef[..., None] * diff


def swarm_intensity(src: FieldSources, cfg: FieldConfig) -> float:
    """The intensity v_s of the swarm's peak Φ_s; 0 where the field has none (``swarm_peak``)."""
    return src.swarm_speed_m_s if cfg.swarm_peak else 0.0


def swarm_term(
    points_m: FloatArray, src: FieldSources, cfg: FieldConfig
) -> tuple[FloatArray, FloatArray]:
    """The swarms' Φ_s and ∇Φ_s at the points: (phi (B, *P), grad (B, *P, 2))."""
    nd = points_m.ndim - 1
    phi_sum, grad_sum = np.zeros(points_m.shape[:-1]), np.zeros(points_m.shape)
    for g in range(src.centre_m.shape[1]):
        diff = points_m - _expand(src.centre_m[:, g], nd)  # (B, *P, 2)
        d2 = np.einsum("...i,...i->...", diff, diff)
        phi, coef = _inverse_square(
            d2, swarm_intensity(src, cfg), cfg.swarm_floor_m, cfg.swarm_range_m, cfg.continuous
        )
        assert coef is not None
        phi_sum += phi
        grad_sum += coef[..., None] * diff
    return phi_sum, grad_sum


def potential_and_gradient_xy(
    x_m: FloatArray, y_m: FloatArray, src: FieldSources, cfg: FieldConfig
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Φ and the two components of ∇Φ at points given by their coordinates, each (B, *P).

    The same field as `potential_and_gradient`, on contiguous component arrays (faster).
    """
    phi, grad = _field_xy(x_m, y_m, src, cfg, gradient=True)
    assert grad is not None
    return phi, grad[0], grad[1]


def _field_xy(
    x_m: FloatArray, y_m: FloatArray, src: FieldSources, cfg: FieldConfig, gradient: bool
) -> tuple[FloatArray, tuple[FloatArray, FloatArray] | None]:
    """Φ, and (∂Φ/∂x, ∂Φ/∂y) if ``gradient``, at points given by their coordinates (B, *P).

    Computed in the points' dtype (float32 is faster). One obstacle at a time on (B, *P)
    arrays: a trailing obstacle axis would make numpy reduce it one short row at a time. The
    obstacles' terms are added up first, left to right, then to the swarm's: numpy's own order
    for fewer than 8 obstacles, so the sums are the same as over an obstacle axis.
    """
    nd, dt = x_m.ndim, x_m.dtype
    centres = src.centre_m.astype(dt, copy=False)
    for g in range(centres.shape[1]):  # one swarm but for `UAVConfig.groups`
        dx = x_m - _expand(centres[:, g, 0], nd)
        dy = y_m - _expand(centres[:, g, 1], nd)
        d2 = dx * dx
        d2 += dy * dy
        phi_g, coef = _inverse_square(
            d2,
            swarm_intensity(src, cfg),
            cfg.swarm_floor_m,
            cfg.swarm_range_m,
            cfg.continuous,
            gradient,
        )
        grad_g = None
        if coef is not None:
            dx *= coef
            dy *= coef
            grad_g = (dx, dy)
        if g == 0:
            phi, grad = phi_g, grad_g
            continue
        phi += phi_g
        if grad is not None and grad_g is not None:
            gx, gy = grad
            gx += grad_g[0]
            gy += grad_g[1]
    num_obstacles = src.obstacle_pos_m.shape[1]
    if not num_obstacles:
        return phi, grad
    obstacles = src.obstacle_pos_m.astype(dt, copy=False)
    intensity = src.intensity().astype(dt, copy=False)
    sums: list[FloatArray] = []
    for k in range(num_obstacles):
        ox = x_m - _expand(obstacles[:, k, 0], nd)  # (B, *P)
        oy = y_m - _expand(obstacles[:, k, 1], nd)
        d2 = ox * ox
        d2 += oy * oy
        phi_o, coef_o = _inverse_square(
            d2,
            _expand(intensity[:, k], nd),
            cfg.d_safe_m,
            cfg.obstacle_range_m,
            cfg.continuous,
            gradient,
        )
        terms = [phi_o]
        if coef_o is not None:
            ox *= coef_o
            oy *= coef_o
            terms += [ox, oy]
        if k == 0:
            sums = terms
        else:
            for total, term in zip(sums, terms, strict=True):
                total += term
    phi += sums[0]
    if grad is not None:
        gx, gy = grad
        gx += sums[1]
        gy += sums[2]
    return phi, grad


def potential_and_gradient(
    points_m: FloatArray, src: FieldSources, cfg: FieldConfig
) -> tuple[FloatArray, FloatArray]:
    """Φ and ∇Φ at the points (Eq. environmentfield): (phi (B, *P), grad (B, *P, 2))."""
    phi, gx, gy = potential_and_gradient_xy(points_m[..., 0], points_m[..., 1], src, cfg)
    return phi, np.stack([gx, gy], axis=-1)


def potential(points_m: FloatArray, src: FieldSources, cfg: FieldConfig) -> FloatArray:
    """Φ at the points: (B, *P) (the gradient is not computed)."""
    return _field_xy(points_m[..., 0], points_m[..., 1], src, cfg, gradient=False)[0]


def peak_gradient(cfg: FieldConfig, swarm_speed_m_s: float) -> float:
    """|∇Φ_o| just outside d_safe of an obstacle slower than the swarm: 2·v_s/d_safe³, 1/(m²·s).

    The external term of the reward divides |∇Φ| by it to be non-dimensional.

    >>> round(peak_gradient(FieldConfig(d_safe_m=10.0), 10.0), 6)
    0.02
    """
    return GRADIENT_EXPONENT * swarm_speed_m_s / cfg.d_safe_m**3
