"""What a UAV's own observation says its action does to its separation: a differentiable penalty.

From a version-2 observation alone (its own velocity and its neighbour rows, `sim.observation`)
and a normalised action a, the UAV's motion over the coming ``horizon_s`` is predicted as the
simulator flies it — the constant-turn-rate arc of the step, then straight on, as
`sim.prediction.displacements` — and each visible neighbour's as a straight line at its current
velocity (the rows hold no future command). The closest approach d to each neighbour on that
piecewise-linear relative path (`sim.prediction.closest_approach`'s closed form, here in torch so
that it has a gradient in a) is charged

    ((f·d_col − d) / ((f − 1)·d_col))₊²

per neighbour row the mask keeps: 0 beyond f·d_col, 1 at d_col, and growing below it, so that a
predicted collision never stops pushing. f is the reward's ``separation_factor`` (1.5, the PSO
threshold and spawn spacing, `GeneralistConfig`).

Why (docs/MODEL.md §20, "A penalty the student can see"): the distilled students' UAV–UAV
collisions in the crowded families are foreseeable from the colliding UAV's own rows one step
before (29 of 35 UAVs in 40 episodes of 50u8o) and, for about half of those, an action exists
that the same prediction keeps clear. A squared error to the teacher's labels averages those
few states away; this term charges them by name. It reads nothing the UAV does not see.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from sim.config import ScenarioConfig
from sim.errors import ConfigError
from sim.observation import (
    COLUMNS,
    INTRUDER_COLUMNS,
    NEIGHBOUR_COLUMNS,
    ROW_SELF,
    ObservationLayout,
)
from sim.prediction import ARC_SEGMENTS, time_points


@dataclass(frozen=True)
class OwnView:
    """How to read a version-2 observation's neighbours and predict one's own arc.

    Attributes:
        layout: the observations' layout (version 2). dt_s: the decision step, s. max_turn_rad:
            a_max, the heading change of a normalised action of 1 over one step. d_col_m:
            collision distance, m. horizon_s: how far ahead the paths are predicted, s
            (≥ dt_s). intruder_horizon_s: the same for the intruder rows (≥ dt_s; `of` sets
            it to ``horizon_s`` unless asked otherwise). factor: f, where the penalty starts,
            in d_col. reciprocal: each
            neighbour is predicted to turn as the UAV itself does, from its own course (a
            formation turning together keeps its spacing), rather than to fly straight on.
            intruders: the intruder rows are charged too (each straight on at its velocity,
            as ADS-B traffic is predicted everywhere), after the neighbours. intruder_scale:
            the intruder rows' share of the penalty against the neighbour rows' 1.
    """

    layout: ObservationLayout
    dt_s: float
    max_turn_rad: float
    d_col_m: float
    horizon_s: float
    intruder_horizon_s: float
    factor: float
    reciprocal: bool = False
    intruders: bool = False
    intruder_scale: float = 1.0

    @classmethod
    def of(
        cls,
        layout: ObservationLayout,
        scenarios: list[ScenarioConfig],
        horizon_s: float,
        factor: float,
        reciprocal: bool = False,
        intruders: bool = False,
        intruder_horizon_s: float = 0.0,
        intruder_scale: float = 1.0,
    ) -> OwnView:
        """The view of ``layout`` over worlds that share one decision step, turn limit and d_col.

        ``intruder_horizon_s`` 0: the intruders are predicted over ``horizon_s`` too.

        Raises:
            ConfigError: the layout is not version 2, or the worlds' kinematics differ.
        """
        if layout.version != 2:
            raise ConfigError(
                "the own-view separation penalty reads neighbour rows: it needs observation "
                "version 2"
            )
        kinds = {(c.dt_s, c.uav.max_turn_rad, c.d_col_m) for c in scenarios}
        if len(kinds) != 1:
            raise ConfigError(
                "the own-view separation penalty needs one decision step, turn limit and d_col "
                f"across the training worlds, got {sorted(kinds)}: set dagger_separation_weight "
                "to 0 for this mixture"
            )
        ((dt_s, max_turn_rad, d_col_m),) = kinds
        return cls(
            layout=layout,
            dt_s=dt_s,
            max_turn_rad=max_turn_rad,
            d_col_m=d_col_m,
            horizon_s=max(horizon_s, dt_s),
            intruder_horizon_s=max(intruder_horizon_s or horizon_s, dt_s),
            factor=factor,
            reciprocal=reciprocal,
            intruders=intruders,
            intruder_scale=intruder_scale,
        )

    def time_points(
        self, device: torch.device | str = "cpu", horizon_s: float | None = None
    ) -> torch.Tensor:
        """(P,) the instants of the prediction, s: `sim.prediction.time_points`, as a tensor.

        Over ``horizon_s``, by default the view's ``horizon_s``.
        """
        horizon = self.horizon_s if horizon_s is None else horizon_s
        return torch.from_numpy(time_points(self.dt_s, horizon)).to(device)

    def closest(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(..., k [+ m]) predicted closest approach, m, to each row (masked rows: inf).

        The neighbour rows, then the intruder rows where the view charges them.
        ``obs`` (..., D) flat version-2 observations, ``action`` (...,) normalised actions.
        Computed in float64 and returned in ``obs``'s dtype.
        """
        return self._closest(obs, action).to(obs.dtype)

    def _closest(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """`closest` in float64."""
        lay = self.layout
        blocks = lay.blocks()
        x = obs.to(torch.float64)
        a = action.to(torch.float64)
        own_v = x[..., ROW_SELF * COLUMNS + 2 : ROW_SELF * COLUMNS + 4] * lay.speed_m_s
        speed = torch.linalg.vector_norm(own_v, dim=-1)  # (...)
        turn = a * self.max_turn_rad  # (...)

        sets = [("neighbours", "neighbour_mask", lay.max_neighbours, NEIGHBOUR_COLUMNS)]
        horizons = [self.horizon_s]
        if self.intruders:
            sets.append(("intruders", "intruder_mask", lay.max_obstacles, INTRUDER_COLUMNS))
            horizons.append(self.intruder_horizon_s)
        # the UAV's own path in its heading frame (ψ = 0), (..., 1, P), and its instants (P,):
        # once per look-ahead
        own = {}
        for horizon in set(horizons):
            ox, oy = self._path(torch.zeros_like(speed), speed, turn, horizon)
            own[horizon] = (ox[..., None, :], oy[..., None, :], self.time_points(x.device, horizon))
        out = []
        for (rows_name, mask_name, count, width), horizon in zip(sets, horizons, strict=True):
            ox, oy, t = own[horizon]
            rows = x[..., blocks[rows_name]].unflatten(-1, (count, width))
            kept = x[..., blocks[mask_name]] > 0.5
            px, py = rows[..., 0] * lay.range_m, rows[..., 1] * lay.range_m  # (..., R)
            vx = own_v[..., 0:1] + rows[..., 2] * lay.speed_m_s
            vy = own_v[..., 1:2] + rows[..., 3] * lay.speed_m_s
            if self.reciprocal and rows_name == "neighbours":  # turning as the UAV does
                heading = torch.atan2(vy, vx)
                nx, ny = self._path(heading, torch.hypot(vx, vy), turn[..., None], horizon)
            else:  # straight on at its velocity
                nx, ny = vx[..., None] * t, vy[..., None] * t
            d = segment_closest(px[..., None] + nx - ox, py[..., None] + ny - oy)  # (..., R)
            out.append(torch.where(kept, d, torch.full_like(d, math.inf)))
        return torch.cat(out, dim=-1)

    def _path(
        self, heading: torch.Tensor, speed: torch.Tensor, turn: torch.Tensor, horizon_s: float
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Displacements (x, y), each (..., P), of vehicles turning by ``turn`` over the step.

        ``heading``, ``speed`` and ``turn`` broadcast to (...). As the simulator flies it: the
        arc's chords, then straight on the arc's final heading until the horizon.
        """
        u = torch.linspace(0.0, 1.0, ARC_SEGMENTS + 1, dtype=torch.float64, device=speed.device)
        half = 0.5 * turn[..., None] * u  # (..., S + 1)
        chord = speed[..., None] * self.dt_s * u * torch.sinc(half / math.pi)
        direction = heading[..., None] + half
        x, y = chord * torch.cos(direction), chord * torch.sin(direction)
        if horizon_s > self.dt_s:
            final = heading + turn
            rest = speed * (horizon_s - self.dt_s)
            x = torch.cat([x, (x[..., -1] + rest * torch.cos(final))[..., None]], dim=-1)
            y = torch.cat([y, (y[..., -1] + rest * torch.sin(final))[..., None]], dim=-1)
        return x, y

    def penalty(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(...) the penalty of ``action`` at ``obs``: Σ over the kept rows it reads (module doc).

        Summed in float64 (the order of the rows moves it by float64 rounding only), returned
        in ``obs``'s dtype.
        """
        d = self._closest(obs, action)
        scale = (self.factor - 1.0) * self.d_col_m
        excess = torch.relu((self.factor * self.d_col_m - d) / scale) ** 2
        k = self.layout.max_neighbours  # the neighbour rows first, then the intruders'
        total = excess[..., :k].sum(dim=-1) + self.intruder_scale * excess[..., k:].sum(dim=-1)
        return total.to(obs.dtype)


def segment_closest(rx: torch.Tensor, ry: torch.Tensor) -> torch.Tensor:
    """(...) closest distance to the origin of piecewise-linear paths (..., P), closed form.

    On each segment r0 + u·Δ the closest point has u* = clip(−r0·Δ/|Δ|², 0, 1), as
    `sim.prediction.segment_closest_sq`; differentiable wherever the minimum is unique.
    """
    x0, y0 = rx[..., :-1], ry[..., :-1]
    dx, dy = rx[..., 1:] - x0, ry[..., 1:] - y0
    span = (dx * dx + dy * dy).clamp_min(1e-12)
    u = (-(x0 * dx + y0 * dy) / span).clamp(0.0, 1.0)
    cx, cy = x0 + u * dx, y0 + u * dy
    closest_sq = (cx * cx + cy * cy).amin(dim=-1)
    return torch.sqrt(closest_sq.clamp_min(1e-12))
