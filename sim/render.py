"""Pictures of a simulator state: the field's contours, UAVs, obstacles, targets and trails.

matplotlib is imported when a picture is drawn, not when this module is imported, and only its
object-oriented API is used (no pyplot global state), with the Agg canvas.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.config import ScenarioConfig
from sim.field import FieldSources, potential
from sim.swarm import SwarmState

RASTER_POINTS = 120
"""Field raster resolution (points per side) of a rendered frame."""


def draw_state(
    ax: Any, cfg: ScenarioConfig, state: SwarmState, env: int, trail_m: NDArray[np.float64]
) -> None:
    """Draw environment ``env`` of ``state`` on a matplotlib Axes.

    Args:
        trail_m: (T, N, 2) past UAV positions, oldest first (may be empty).
    """
    from matplotlib.colors import LogNorm

    xs = np.linspace(0.0, cfg.arena_length_m, RASTER_POINTS)
    ys = np.linspace(0.0, cfg.arena_width_m, RASTER_POINTS)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1)[None]
    src = FieldSources(
        state.obstacle_pos_m[env : env + 1],
        state.obstacle_speed_m_s[env : env + 1],
        state.centre_m[env : env + 1],
        cfg.uav.speed_m_s,
    )
    phi = potential(grid, src, cfg.field)[0]
    positive = phi[phi > 0]
    if positive.size:
        ax.imshow(
            np.where(phi > 0, phi, np.nan),
            origin="lower",
            extent=(0, cfg.arena_length_m, 0, cfg.arena_width_m),
            cmap="Blues",
            norm=LogNorm(vmin=float(np.percentile(positive, 2)), vmax=float(positive.max())),
            alpha=0.75,
        )
    n = state.pos_m.shape[1]
    colours = _colours(n)
    levels = state.levels[env]
    for k in np.argsort(levels):
        if levels[k] > 0:
            ax.contour(
                xs,
                ys,
                phi,
                levels=[levels[k]],
                colors=[colours[k]],
                linewidths=0.8,
                linestyles="--",
            )
    if len(trail_m) > 1:
        for k in range(n):
            ax.plot(trail_m[:, k, 0], trail_m[:, k, 1], color=colours[k], lw=1.6)
    target = state.target_m[env]
    ax.scatter(target[:, 0], target[:, 1], marker="x", color="0.4", s=25)
    pos, head = state.pos_m[env], state.heading_rad[env]
    alive = state.active[env] | ~state.reached[env]
    ax.scatter(
        pos[alive, 0],
        pos[alive, 1],
        marker="o",
        c=colours[alive],
        s=30,
        zorder=5,
        edgecolors="black",
        linewidths=0.6,
    )
    ax.quiver(
        pos[:, 0],
        pos[:, 1],
        np.cos(head),
        np.sin(head),
        color=colours,
        scale=30,
        width=0.005,
        zorder=6,
    )
    for ob, vel in zip(state.obstacle_pos_m[env], state.obstacle_vel_m_s[env], strict=True):
        ax.add_patch(_circle(ob, cfg.d_col_m, "tab:red"))
        ax.scatter(*ob, marker="s", color="tab:red", s=35, zorder=5)
        if np.any(vel):
            ax.quiver(*ob, *vel, color="tab:red", scale=30, width=0.005)
    ax.scatter(
        *state.centre_m[env],
        marker="o",
        facecolors="none",
        edgecolors="tab:purple",
        s=60,
        lw=1.4,
        zorder=5,
    )
    ax.set_xlim(0, cfg.arena_length_m)
    ax.set_ylim(0, cfg.arena_width_m)
    ax.set_aspect("equal")
    ax.set_xlabel("x  [m]")
    ax.set_ylabel("y  [m]")
    ax.set_title(f"{cfg.name}  step {int(state.steps[env])}")


def render_frame(
    cfg: ScenarioConfig, state: SwarmState, env: int, trail_m: NDArray[np.float64]
) -> NDArray[np.uint8]:
    """An RGB image (H, W, 3) of environment ``env``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.2, 5.2), dpi=90, layout="tight")
    canvas = FigureCanvasAgg(fig)
    draw_state(fig.add_subplot(), cfg, state, env, trail_m)
    canvas.draw()  # type: ignore[no-untyped-call]
    rgba = np.asarray(canvas.buffer_rgba())  # type: ignore[no-untyped-call]
    return rgba[..., :3].copy()


def _colours(n: int) -> NDArray[np.float64]:
    from matplotlib import colormaps

    return np.asarray(colormaps["tab10"](np.arange(n) % 10))


def _circle(centre: NDArray[np.float64], radius: float, colour: str) -> Any:
    from matplotlib.patches import Circle

    return Circle(tuple(centre), radius, fill=False, ec=colour, lw=0.8, ls=":")
