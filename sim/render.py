"""Pictures of a simulator state: the field's contours, UAVs, obstacles, targets and trails.

`draw_state` draws one environment of a `SwarmState` (the ``rgb_array`` frames of `sim.env`,
`remarl-fc rollout`, `remarl-fc eval --plot`); the ``draw_*`` helpers it is made of are the
one drawing code of every scenario picture (`remarl-fc field` draws with them too), each
taking its style as keyword arguments passed on to matplotlib.

matplotlib is imported when a picture is drawn, not when this module is imported, and only its
object-oriented API is used (no pyplot global state), with the Agg canvas.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, FloatArray
from sim.config import ScenarioConfig
from sim.field import FieldSources, potential
from sim.state import SwarmState

RASTER_POINTS = 120
"""Field raster resolution (points per side) of a rendered frame."""

OBSTACLE_COLOUR = "tab:red"
"""Colour of the obstacles, their velocity arrows and collision circles."""


def uav_colours(n: int) -> FloatArray:
    """(N, 4) RGBA colours of N UAVs (matplotlib's tab10 cycle), the same in every picture."""
    from matplotlib import colormaps

    return np.asarray(colormaps["tab10"](np.arange(n) % 10))


def draw_log_image(
    ax: Any,
    values: FloatArray,
    extent: tuple[float, float, float, float],
    *,
    cmap: str,
    low_percentile: float,
    **style: Any,
) -> Any:
    """A field raster (Y, X) on a log colour scale, blank where it is not positive.

    The scale runs from the ``low_percentile`` of the positive values to their maximum.

    Returns:
        The image (for a colour bar), or None when no value is positive (nothing drawn).
    """
    from matplotlib.colors import LogNorm

    positive = values[values > 0]
    if not positive.size:
        return None
    return ax.imshow(
        np.where(values > 0, values, np.nan),
        origin="lower",
        extent=extent,
        cmap=cmap,
        norm=LogNorm(
            vmin=float(np.percentile(positive, low_percentile)), vmax=float(positive.max())
        ),
        **style,
    )


def draw_contours(
    ax: Any,
    xs_m: FloatArray,
    ys_m: FloatArray,
    phi: FloatArray,
    levels: FloatArray,
    colours: FloatArray,
    **style: Any,
) -> None:
    """Each UAV's own contour Φ = φ_i of the raster ``phi`` (Y, X), in the given order.

    Levels that are not positive (no contour) are skipped.
    """
    for level, colour in zip(levels, colours, strict=True):
        if level > 0:
            ax.contour(xs_m, ys_m, phi, levels=[level], colors=[colour], **style)


def draw_targets(ax: Any, targets_m: FloatArray, *, colour: str, size: float, **style: Any) -> None:
    """The UAVs' targets (N, 2) as crosses."""
    ax.scatter(targets_m[:, 0], targets_m[:, 1], marker="x", color=colour, s=size, **style)


def draw_uavs(
    ax: Any, pos_m: FloatArray, colours: FloatArray, *, marker: str, size: float, **style: Any
) -> None:
    """UAVs (N, 2) as markers in their colours, edged in black."""
    ax.scatter(
        pos_m[:, 0], pos_m[:, 1], marker=marker, c=colours, s=size, edgecolors="black", **style
    )


def draw_headings(
    ax: Any,
    pos_m: FloatArray,
    heading_rad: FloatArray,
    colours: FloatArray,
    *,
    scale: float,
    width: float,
    **style: Any,
) -> None:
    """A unit arrow along each UAV's heading (N,) from its position (N, 2)."""
    ax.quiver(
        pos_m[:, 0],
        pos_m[:, 1],
        np.cos(heading_rad),
        np.sin(heading_rad),
        color=colours,
        scale=scale,
        width=width,
        **style,
    )


def draw_obstacles(ax: Any, pos_m: FloatArray, *, size: float, **style: Any) -> None:
    """Obstacles (M, 2) as red squares."""
    ax.scatter(
        pos_m[:, 0], pos_m[:, 1], marker="s", color=OBSTACLE_COLOUR, s=size, zorder=5, **style
    )


def draw_velocities(
    ax: Any, pos_m: FloatArray, vel_m_s: FloatArray, *, scale: float, width: float
) -> None:
    """The obstacles' velocity arrows (M, 2) from their positions (M, 2)."""
    ax.quiver(
        pos_m[:, 0],
        pos_m[:, 1],
        vel_m_s[:, 0],
        vel_m_s[:, 1],
        color=OBSTACLE_COLOUR,
        scale=scale,
        width=width,
    )


def draw_centre(
    ax: Any, centre_m: FloatArray, *, colour: str, size: float, lw: float, **style: Any
) -> None:
    """The virtual centres p*, one per swarm (G, 2), as open circles."""
    ax.scatter(
        centre_m[:, 0],
        centre_m[:, 1],
        marker="o",
        facecolors="none",
        edgecolors=colour,
        s=size,
        lw=lw,
        zorder=5,
        **style,
    )


def draw_state(
    ax: Any, cfg: ScenarioConfig, state: SwarmState, env: int, trail_m: NDArray[np.float64]
) -> None:
    """Draw environment ``env`` of ``state`` on a matplotlib Axes.

    Args:
        trail_m: (T, N, 2) past UAV positions, oldest first (may be empty).
    """
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
    extent = (0.0, cfg.arena_length_m, 0.0, cfg.arena_width_m)
    draw_log_image(ax, phi, extent, cmap="Blues", low_percentile=2, alpha=0.75)
    n = state.pos_m.shape[1]
    colours = uav_colours(n)
    order = np.argsort(state.levels[env])
    draw_contours(
        ax, xs, ys, phi, state.levels[env][order], colours[order], linewidths=0.8, linestyles="--"
    )
    if len(trail_m) > 1:
        for k in range(n):
            ax.plot(trail_m[:, k, 0], trail_m[:, k, 1], color=colours[k], lw=1.6)
    draw_targets(ax, state.target_m[env], colour="0.4", size=25)
    pos, head = state.pos_m[env], state.heading_rad[env]
    alive: BoolArray = state.active[env] | ~state.reached[env]
    draw_uavs(ax, pos[alive], colours[alive], marker="o", size=30, zorder=5, linewidths=0.6)
    draw_headings(ax, pos, head, colours, scale=30, width=0.005, zorder=6)
    for ob, vel in zip(state.obstacle_pos_m[env], state.obstacle_vel_m_s[env], strict=True):
        ax.add_patch(_circle(ob, cfg.d_col_m, OBSTACLE_COLOUR))
        draw_obstacles(ax, ob[None], size=35)
        if np.any(vel):
            draw_velocities(ax, ob[None], vel[None], scale=30, width=0.005)
    draw_centre(ax, state.centre_m[env], colour="tab:purple", size=60, lw=1.4)
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


def _circle(centre: NDArray[np.float64], radius: float, colour: str) -> Any:
    from matplotlib.patches import Circle

    return Circle(tuple(centre), radius, fill=False, ec=colour, lw=0.8, ls=":")
