"""Figures: the potential field of a scenario (the paper's field figure).

matplotlib is imported inside the functions, with the non-interactive Agg backend, so that
importing this module costs nothing and needs no display.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sim.arrays import FloatArray
from sim.config import ScenarioConfig
from sim.field import potential_and_gradient
from sim.render import (
    draw_centre,
    draw_contours,
    draw_headings,
    draw_log_image,
    draw_obstacles,
    draw_targets,
    draw_uavs,
    draw_velocities,
    uav_colours,
)
from sim.reward import assign_contour_levels
from sim.spawn import initial_sources, swarm_layout

GRID_STEP_M = 1.5
"""Resolution of the field raster, metres."""


@dataclass(frozen=True)
class FieldSnapshot:
    """A scenario's initial state with its field raster, ready to draw (no batch dimension).

    Attributes:
        xs_m, ys_m: raster axes; phi and grad_norm are (len(ys), len(xs)).
        uav_m: (N, 2) UAV positions; adjusted_m: the PSO-adjusted positions (N, 2).
        levels: (N,) contour levels φ_i; headings_rad: (N,); targets_m: (N, 2).
        obstacle_m, obstacle_vel_m_s: (M, 2); centre_m: (G, 2) each swarm's virtual centre p*.
    """

    xs_m: FloatArray
    ys_m: FloatArray
    phi: FloatArray
    grad_norm: FloatArray
    uav_m: FloatArray
    adjusted_m: FloatArray
    levels: FloatArray
    headings_rad: FloatArray
    targets_m: FloatArray
    obstacle_m: FloatArray
    obstacle_vel_m_s: FloatArray
    centre_m: FloatArray


def field_snapshot(cfg: ScenarioConfig, seed: int) -> FieldSnapshot:
    """Initial state of one episode of the scenario, its contour levels and its field raster."""
    rng = np.random.default_rng(seed)
    layout = swarm_layout(cfg)
    src, vel = initial_sources(cfg, rng, num_envs=1)
    levels, pso = assign_contour_levels(layout.positions_m[None], src, cfg.field, cfg.pso, rng)
    xs = np.arange(0.0, cfg.arena_length_m + GRID_STEP_M / 2, GRID_STEP_M)
    ys = np.arange(0.0, cfg.arena_width_m + GRID_STEP_M / 2, GRID_STEP_M)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1)[None]  # (1, Y, X, 2)
    phi, grad = potential_and_gradient(grid, src, cfg.field)
    return FieldSnapshot(
        xs_m=xs,
        ys_m=ys,
        phi=phi[0],
        grad_norm=np.hypot(grad[0, ..., 0], grad[0, ..., 1]),
        uav_m=layout.positions_m,
        adjusted_m=pso.positions_m[0],
        levels=levels[0],
        headings_rad=layout.headings_rad,
        targets_m=layout.targets_m,
        obstacle_m=src.obstacle_pos_m[0],
        obstacle_vel_m_s=vel[0],
        centre_m=src.centre_m[0],
    )


def draw_field(cfg: ScenarioConfig, out: Path, seed: int = 0) -> FieldSnapshot:
    """Draw Φ and |∇Φ| of the scenario's initial state with the UAVs' contours to ``out``.

    Left: Φ (log colour scale) with each UAV's own contour Φ = φ_i; right: |∇Φ|, whose ridge
    at d_safe around each obstacle is where the "gradient" external term pays most.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    snap = field_snapshot(cfg, seed)
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.6), constrained_layout=True)
    extent = (snap.xs_m[0], snap.xs_m[-1], snap.ys_m[0], snap.ys_m[-1])
    panels: list[tuple[Any, FloatArray, str, str]] = [
        (axes[0], snap.phi, "Φ  [1/(m·s)]", "potential field Φ and the UAVs' contours"),
        (axes[1], snap.grad_norm, "|∇Φ|  [1/(m²·s)]", "field gradient |∇Φ| (edges)"),
    ]
    colours = uav_colours(len(snap.uav_m))
    for ax, img, label, title in panels:
        mesh = draw_log_image(ax, img, extent, cmap="viridis", low_percentile=1)
        if mesh is not None:
            fig.colorbar(mesh, ax=ax, label=label, shrink=0.85)
        _draw_agents(ax, snap, colours, with_contours=ax is axes[0])
        ax.set_title(f"{cfg.name}: {title}")
        ax.set_xlabel("x  [m]  (direction of flight)")
        ax.set_ylabel("y  [m]")
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.set_aspect("equal")
    axes[0].legend(loc="upper left", fontsize=7, framealpha=0.85)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".part")
    fig.savefig(tmp, dpi=110, format=out.suffix.lstrip(".") or "png")
    plt.close(fig)
    tmp.replace(out)
    return snap


def _draw_agents(ax: Any, snap: FieldSnapshot, colours: FloatArray, *, with_contours: bool) -> None:
    if with_contours:
        draw_contours(ax, snap.xs_m, snap.ys_m, snap.phi, snap.levels, colours, linewidths=1.4)
    for (x0, y0), (x1, y1) in zip(snap.uav_m, snap.targets_m, strict=True):
        ax.plot([x0, x1], [y0, y1], ls=":", color="0.85", lw=0.8)
    draw_targets(ax, snap.targets_m, colour="0.85", size=30, label="targets")
    draw_uavs(ax, snap.uav_m, colours, marker="^", size=80, zorder=6, label="UAVs")
    draw_headings(ax, snap.uav_m, snap.headings_rad, colours, scale=25, width=0.004)
    draw_obstacles(ax, snap.obstacle_m, size=70, edgecolors="white", label="obstacles")
    if len(snap.obstacle_m):
        draw_velocities(ax, snap.obstacle_m, snap.obstacle_vel_m_s, scale=25, width=0.004)
    draw_centre(ax, snap.centre_m, colour="white", size=90, lw=1.5, label="virtual centre p*")
