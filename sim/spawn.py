"""Initial layouts: UAV formations, targets, obstacles and the swarm's virtual centre.

Coordinates are the simulator's: x along the direction of flight (east), y across it (north),
headings counter-clockwise from +x, metres and radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.arrays import FloatArray
from sim.config import ObstacleConfig, ScenarioConfig, UAVConfig
from sim.field import FieldSources
from sim.kinematics import heading_velocity

SPAWN_SPACING_FACTOR = 1.5
"""Minimum spawn distance between two UAVs, in units of d_col (SPEC §3)."""

WEDGE_ARM_ANGLE_RAD = math.radians(60.0)
"""Angle between each arm of the "wedge" formation and the −x axis (arms trail the apex)."""


@dataclass(frozen=True)
class SwarmLayout:
    """Where the swarm starts and where it goes (no batch dimension: it is the same in every env).

    Attributes:
        positions_m: (N, 2) spawn positions.
        headings_rad: (N,) initial headings, toward each UAV's target.
        targets_m: (N, 2) targets, on each UAV's straight pre-planned line.
        velocity_m_s: (2,) the swarm's initial (pre-planned) velocity, v_s along the mean heading.
        centre_m: (2,) initial virtual centre p*: on the line through the centroid along the
            swarm velocity, `FieldConfig.swarm_lead_m` ahead of the foremost UAV.
    """

    positions_m: FloatArray
    headings_rad: FloatArray
    targets_m: FloatArray
    velocity_m_s: FloatArray
    centre_m: FloatArray


def formation_offsets(uav: UAVConfig) -> FloatArray:
    """Offsets of the N formation slots from the formation centre, metres: (N, 2).

    The centroid of the offsets is 0 for "line" and "grid"; the "wedge" is centred on the
    midpoint between its apex and its last row.

    >>> formation_offsets(UAVConfig(count=3, formation="line", spacing_m=30.0)).tolist()
    [[0.0, -30.0], [0.0, 0.0], [0.0, 30.0]]
    """
    n, s = uav.count, uav.spacing_m
    if uav.formation == "line":
        y = (np.arange(n) - (n - 1) / 2) * s
        return np.stack([np.zeros(n), y], axis=-1)
    if uav.formation == "grid":
        rows = min(uav.rows, n)
        per_row = math.ceil(n / rows)
        k = np.arange(n)
        row, col = k // per_row, k % per_row
        # Staggered rows: each row behind the previous one, shifted by half a spacing.
        x = -(row - (rows - 1) / 2) * s * math.sqrt(3) / 2
        y = col * s + np.where(row % 2 == 1, s / 2, 0.0)
        grid: FloatArray = np.stack([x, y], axis=-1)
        centred: FloatArray = grid - grid.mean(axis=0)
        return centred
    # wedge: apex first, then alternately left/right, each rank one spacing further back.
    k = np.arange(n)
    rank = (k + 1) // 2
    side = np.where(k % 2 == 1, 1.0, -1.0)
    back = -rank * s * math.cos(WEDGE_ARM_ANGLE_RAD)
    across = side * rank * s * math.sin(WEDGE_ARM_ANGLE_RAD)
    back = back - (back.max() + back.min()) / 2
    return np.stack([back, across], axis=-1)


def swarm_layout(cfg: ScenarioConfig) -> SwarmLayout:
    """Spawn positions, headings, targets and virtual centre of a scenario's swarm."""
    centre = np.asarray(cfg.uav.center_m, dtype=np.float64)
    positions = centre + formation_offsets(cfg.uav)
    targets = np.stack([np.full(cfg.uav.count, cfg.uav.target_x_m), positions[:, 1]], axis=-1)
    delta = targets - positions
    headings = np.arctan2(delta[:, 1], delta[:, 0])
    velocity, virtual_centre = virtual_centre_and_velocity(
        positions, targets, cfg.uav.speed_m_s, cfg.field.swarm_lead_m
    )
    return SwarmLayout(positions, headings, targets, velocity, virtual_centre)


def virtual_centre_and_velocity(
    positions_m: FloatArray, targets_m: FloatArray, speed_m_s: float, lead_m: float
) -> tuple[FloatArray, FloatArray]:
    """The swarm's pre-planned velocity v_s and virtual centre p* for UAVs at ``positions_m``.

    v_s has the UAV speed along the mean of the directions to the targets; p* lies on the line
    through the centroid along v_s, ``lead_m`` ahead of the foremost UAV.

    Args:
        positions_m, targets_m: (N, 2).

    Returns:
        (velocity (2,), centre (2,)).

    >>> v, c = virtual_centre_and_velocity(np.array([[0.0, 0.0], [0.0, 10.0]]),
    ...                                    np.array([[100.0, 0.0], [100.0, 10.0]]), 10.0, 50.0)
    >>> v.tolist(), c.tolist()
    ([10.0, 0.0], [50.0, 5.0])
    """
    delta = targets_m - positions_m
    headings = np.arctan2(delta[:, 1], delta[:, 0])
    mean_dir = np.array([np.cos(headings).mean(), np.sin(headings).mean()])
    mean_dir /= np.linalg.norm(mean_dir)
    centroid = positions_m.mean(axis=0)
    front = float(((positions_m - centroid) @ mean_dir).max())  # the foremost UAV, along v
    return speed_m_s * mean_dir, centroid + (front + lead_m) * mean_dir


def min_pairwise_distance(points_m: FloatArray) -> float:
    """Smallest distance between two of the points (N, 2); +inf for fewer than two.

    >>> min_pairwise_distance(np.array([[0.0, 0.0], [3.0, 4.0], [10.0, 0.0]]))
    5.0
    """
    if len(points_m) < 2:
        return math.inf
    diff = points_m[:, None, :] - points_m[None, :, :]
    dist = np.hypot(diff[..., 0], diff[..., 1])
    iu = np.triu_indices(len(points_m), k=1)
    return float(dist[iu].min())


def obstacle_nominal_positions(obstacles: ObstacleConfig) -> FloatArray:
    """Obstacle spawn positions without jitter, evenly spaced on the spawn line: (M, 2)."""
    m = obstacles.count
    y = obstacles.center_y_m + (np.arange(m) - (m - 1) / 2) * obstacles.spacing_m
    return np.stack([np.full(m, obstacles.spawn_x_m), y], axis=-1)


def spawn_obstacles(
    cfg: ScenarioConfig, rng: np.random.Generator, num_envs: int
) -> tuple[FloatArray, FloatArray]:
    """Random obstacle spawns for a batch of environments.

    Each obstacle starts on the spawn line (nominal y plus a uniform lateral jitter) and heads
    toward the swarm's spawn centroid, perturbed by a uniform heading jitter.

    Returns:
        (positions_m (B, M, 2), velocities_m_s (B, M, 2)).
    """
    o = cfg.obstacles
    nominal = obstacle_nominal_positions(o)  # (M, 2)
    jitter = rng.uniform(-o.lateral_jitter_m, o.lateral_jitter_m, size=(num_envs, o.count))
    pos = np.broadcast_to(nominal, (num_envs, o.count, 2)).copy()
    pos[..., 1] += jitter
    aim = swarm_layout(cfg).positions_m.mean(axis=0)  # (2,)
    to_swarm = aim - pos  # (B, M, 2)
    heading = np.arctan2(to_swarm[..., 1], to_swarm[..., 0])
    heading += rng.uniform(-o.heading_jitter_rad, o.heading_jitter_rad, size=heading.shape)
    return pos, heading_velocity(heading, o.speed_m_s)  # (B, M, 2) each


def initial_sources(
    cfg: ScenarioConfig, rng: np.random.Generator, num_envs: int
) -> tuple[FieldSources, FloatArray]:
    """Field sources at the start of an episode, and the obstacle velocities (B, M, 2)."""
    pos, vel = spawn_obstacles(cfg, rng, num_envs)
    centre = np.broadcast_to(swarm_layout(cfg).centre_m, (num_envs, 2)).copy()
    speed = np.full((num_envs, cfg.obstacles.count), cfg.obstacles.speed_m_s)
    return FieldSources(pos, speed, centre, cfg.uav.speed_m_s), vel
