"""Initial layouts: UAV formations, targets, obstacles and the swarm's virtual centre.

Coordinates are the simulator's: x along the direction of flight (east), y across it (north),
headings counter-clockwise from +x, metres and radians.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, FloatArray, IntArray
from sim.config import ObstacleConfig, ScenarioConfig, UAVConfig
from sim.field import FieldSources
from sim.kinematics import heading_velocity

SPAWN_SPACING_FACTOR = 1.5
"""Minimum spawn distance between two UAVs, in units of d_col (SPEC §3)."""

TARGET_SPACING_FACTOR = SPAWN_SPACING_FACTOR
"""Minimum distance between two UAVs' targets, in units of d_col: d_col plus a half-d_col
margin, as for the spawn. A UAV that arrives stops and hovers near its target until the
episode (or the flight) ends, and the others must keep d_col from it."""

DEGENERATE_DIRECTION = 1e-6
"""Below this length the mean of the UAVs' unit directions to their targets has no direction."""

WEDGE_ARM_ANGLE_RAD = math.radians(60.0)
"""Angle between each arm of the "wedge" formation and the −x axis (arms trail the apex)."""


@dataclass(frozen=True)
class SwarmLayout:
    """Where the swarm starts and where it goes (no batch dimension: it is the same in every env).

    Attributes:
        positions_m: (N, 2) spawn positions.
        headings_rad: (N,) initial headings, toward each UAV's target.
        targets_m: (N, 2) targets, on each UAV's straight pre-planned line.
        velocity_m_s: (G, 2) each swarm's initial (pre-planned) velocity, v_s along its mean
            heading (G = 1 but for `UAVConfig.groups`).
        centre_m: (G, 2) each swarm's initial virtual centre p*: on the line through its
            centroid along its velocity, `FieldConfig.swarm_lead_m` ahead of its foremost UAV.
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
    """Spawn positions, headings, targets and virtual centre of a scenario's swarm.

    Per-UAV ``starts_m``/``targets_m`` of the scenario win over the formation and target line.
    """
    uav = cfg.uav
    if uav.starts_m:
        positions = np.asarray(uav.starts_m, dtype=np.float64)
    else:
        positions = np.asarray(uav.center_m, dtype=np.float64) + formation_offsets(uav)
    if uav.targets_m:
        targets = np.asarray(uav.targets_m, dtype=np.float64)
    elif uav.target_layout == "formation":
        centre_x = float(positions[:, 0].mean()) if uav.starts_m else uav.center_m[0]
        targets = positions + np.array([uav.target_x_m - centre_x, 0.0])
    else:
        targets = np.stack([np.full(uav.count, uav.target_x_m), positions[:, 1]], axis=-1)
    delta = targets - positions
    headings = np.arctan2(delta[:, 1], delta[:, 0])
    velocity, virtual_centre = virtual_centre_and_velocity(
        positions, targets, cfg.uav.speed_m_s, cfg.field.swarm_lead_m, group_index(cfg.uav)
    )
    return SwarmLayout(positions, headings, targets, velocity, virtual_centre)


def virtual_centre_and_velocity(
    positions_m: FloatArray,
    targets_m: FloatArray,
    speed_m_s: float,
    lead_m: float,
    groups: IntArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Each swarm's pre-planned velocity v_s and virtual centre p* for UAVs at ``positions_m``.

    A swarm's v_s has the UAV speed along the mean of its UAVs' directions to their targets; its
    p* lies on the line through its centroid along v_s, ``lead_m`` ahead of its foremost UAV.
    Where the directions cancel (UAVs flying apart or toward each other), v_s points from the
    centroid of the starts to the centroid of the targets, and along +x if those coincide too.

    Args:
        positions_m, targets_m: (..., N, 2), any batch dimensions first.
        groups: (N,) the swarm of each UAV, 0…G−1 (`UAVConfig.groups`); None: one swarm.

    Returns:
        (velocity (..., G, 2), centre (..., G, 2)).

    >>> v, c = virtual_centre_and_velocity(np.array([[0.0, 0.0], [0.0, 10.0]]),
    ...                                    np.array([[100.0, 0.0], [100.0, 10.0]]), 10.0, 50.0)
    >>> v.tolist(), c.tolist()
    ([[10.0, 0.0]], [[50.0, 5.0]])
    """
    n = positions_m.shape[-2]
    index = np.zeros(n, dtype=np.int64) if groups is None else np.asarray(groups)
    member = (index[None, :] == np.arange(int(index.max()) + 1)[:, None]).astype(np.float64)
    size = member.sum(axis=-1)  # (G,)

    def group_mean(values: FloatArray) -> FloatArray:  # (..., N) → (..., G)
        mean: FloatArray = values @ member.T / size
        return mean

    delta = targets_m - positions_m
    headings = np.arctan2(delta[..., 1], delta[..., 0])
    mean_dir = np.stack([group_mean(np.cos(headings)), group_mean(np.sin(headings))], axis=-1)
    norm = np.linalg.norm(mean_dir, axis=-1, keepdims=True)
    start = np.stack([group_mean(positions_m[..., 0]), group_mean(positions_m[..., 1])], -1)
    if (norm < DEGENERATE_DIRECTION).any():
        end = np.stack([group_mean(targets_m[..., 0]), group_mean(targets_m[..., 1])], -1)
        overall = end - start
        fallback = np.where(
            np.linalg.norm(overall, axis=-1, keepdims=True) > DEGENERATE_DIRECTION,
            overall,
            np.array([1.0, 0.0]),
        )
        mean_dir = np.where(norm < DEGENERATE_DIRECTION, fallback, mean_dir)
        norm = np.linalg.norm(mean_dir, axis=-1, keepdims=True)
    mean_dir = mean_dir / norm  # (..., G, 2)
    # The foremost UAV of each swarm, along its v: (..., G, N) projections, others at −∞.
    ahead = np.einsum("...ni,...gi->...gn", positions_m, mean_dir)
    ahead -= np.einsum("...gi,...gi->...g", start, mean_dir)[..., None]
    front = np.where(member > 0, ahead, -np.inf).max(axis=-1)
    return speed_m_s * mean_dir, start + (front[..., None] + lead_m) * mean_dir


def group_index(uav: UAVConfig) -> IntArray:
    """(N,) the swarm of each UAV (`UAVConfig.groups`; all 0 for one swarm)."""
    return np.asarray(uav.groups or (0,) * uav.count, dtype=np.int64)


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
    cfg: ScenarioConfig,
    rng: np.random.Generator,
    num_envs: int,
    layout: SwarmLayout | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Random obstacle spawns for a batch of environments.

    Each obstacle starts on the spawn line (nominal y plus a uniform lateral jitter) and heads
    toward the swarm's spawn centroid, perturbed by a uniform heading jitter. ``layout``: the
    scenario's `swarm_layout`, where the caller keeps it (None: computed).

    Returns:
        (positions_m (B, M, 2), velocities_m_s (B, M, 2)).
    """
    o = cfg.obstacles
    nominal = obstacle_nominal_positions(o)  # (M, 2)
    jitter = rng.uniform(-o.lateral_jitter_m, o.lateral_jitter_m, size=(num_envs, o.count))
    pos = np.broadcast_to(nominal, (num_envs, o.count, 2)).copy()
    pos[..., 1] += jitter
    if layout is None:
        layout = swarm_layout(cfg)
    aim = layout.positions_m.mean(axis=0)  # (2,)
    to_swarm = aim - pos  # (B, M, 2)
    heading = np.arctan2(to_swarm[..., 1], to_swarm[..., 0])
    heading += rng.uniform(-o.heading_jitter_rad, o.heading_jitter_rad, size=heading.shape)
    return pos, heading_velocity(heading, o.speed_m_s)  # (B, M, 2) each


@dataclass(frozen=True)
class EpisodeStart:
    """Where B episodes begin: everything that differs between episodes, drawn up front.

    The simulator starts episodes from it (`sim.swarm.SwarmSim.start`); a scenario draws one
    with `spawn_episodes`, the encounter generator (`sim.encounters`) with its own
    distributions. UAVs start heading for their targets.

    Attributes:
        start_m, target_m: (B, N, 2) spawn positions and targets.
        centre_m, swarm_vel_m_s: (B, G, 2) each swarm's virtual centre p* and its constant
            velocity (G = 1 but for `UAVConfig.groups`).
        obstacle_pos_m, obstacle_vel_m_s: (B, M, 2) obstacle positions and velocities.
        obstacle_appear_step: (B, M) the decision step from which each obstacle can be sensed
            (0: from the start).
        heading_rad: (B, N) initial headings; None: every UAV heads for its target (a restart
            in mid-flight, as the oracle's, gives them).
    """

    start_m: FloatArray
    target_m: FloatArray
    centre_m: FloatArray
    swarm_vel_m_s: FloatArray
    obstacle_pos_m: FloatArray
    obstacle_vel_m_s: FloatArray
    obstacle_appear_step: IntArray
    heading_rad: FloatArray | None = None

    @property
    def num_envs(self) -> int:
        """B."""
        return int(self.start_m.shape[0])

    def check(self, cfg: ScenarioConfig) -> None:
        """Raise ValueError unless these are episodes of ``cfg``'s N UAVs and M obstacles."""
        b, n, m = self.num_envs, cfg.uav.count, cfg.obstacles.count
        if self.start_m.shape != (b, n, 2) or self.obstacle_pos_m.shape != (b, m, 2):
            raise ValueError(
                f"episodes of {self.start_m.shape[1]} UAVs and "
                f"{self.obstacle_pos_m.shape[1]} obstacles for a scenario of {n} and {m}"
            )

    def headings(self) -> FloatArray:
        """(B, N) initial headings: given, or toward each UAV's target."""
        if self.heading_rad is not None:
            return self.heading_rad
        delta = self.target_m - self.start_m
        heading: FloatArray = np.arctan2(delta[..., 1], delta[..., 0])
        return heading

    def take(self, envs: IntArray | BoolArray | slice) -> EpisodeStart:
        """The episodes selected by ``envs`` (indices, a (B,) mask or a slice)."""
        fields: dict[str, Any] = {
            f.name: None if (v := getattr(self, f.name)) is None else v[envs]
            for f in dataclasses.fields(self)
        }
        return EpisodeStart(**fields)

    @classmethod
    def concat(cls, parts: list[EpisodeStart]) -> EpisodeStart:
        """The episodes of ``parts``, in order (same N and M; all or none with headings)."""
        given = [p.heading_rad is not None for p in parts]
        if any(given) and not all(given):
            parts = [dataclasses.replace(p, heading_rad=p.headings()) for p in parts]
        fields: dict[str, Any] = {
            f.name: None
            if getattr(parts[0], f.name) is None
            else np.concatenate([getattr(p, f.name) for p in parts])
            for f in dataclasses.fields(cls)
        }
        return cls(**fields)

    @classmethod
    def of_swarm(
        cls,
        start_m: FloatArray,
        target_m: FloatArray,
        obstacle_pos_m: FloatArray,
        obstacle_vel_m_s: FloatArray,
        obstacle_appear_step: IntArray,
        speed_m_s: float,
        lead_m: float,
        groups: IntArray | None = None,
    ) -> EpisodeStart:
        """Episodes whose virtual centres and swarm velocities follow from starts and targets.

        ``groups``: the swarm of each UAV (`virtual_centre_and_velocity`).
        """
        vel, centre = virtual_centre_and_velocity(start_m, target_m, speed_m_s, lead_m, groups)
        return cls(
            start_m,
            target_m,
            centre,
            vel,
            obstacle_pos_m,
            obstacle_vel_m_s,
            obstacle_appear_step,
        )


def encounter_tracks(
    own_start_m: FloatArray,
    own_course_rad: FloatArray,
    own_speed_m_s: float,
    crossing_rad: FloatArray,
    speed_m_s: FloatArray,
    miss_m: FloatArray,
    tcpa_s: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Intruder start positions and velocities from encounter geometry (`IntruderConfig`).

    All arguments broadcast together (any shape (...)); positions (..., 2). The UAV flies
    straight from ``own_start_m`` (..., 2) on ``own_course_rad``; at ``tcpa_s`` the intruder
    is ``miss_m`` to the left of the relative velocity (UAV minus intruder; of the UAV's course
    when that vanishes, as for a static intruder overtaken at its own speed).

    >>> p, v = encounter_tracks(np.zeros(2), np.array(0.0), 10.0, np.array(np.pi),
    ...                         np.array(10.0), np.array(0.0), np.array(10.0))
    >>> (np.round(p, 6) + 0.0).tolist(), (np.round(v, 6) + 0.0).tolist()  # head-on, 200 m ahead
    ([200.0, 0.0], [-10.0, 0.0])
    """
    own_vel = heading_velocity(own_course_rad, own_speed_m_s)
    vel = heading_velocity(own_course_rad + crossing_rad, np.asarray(speed_m_s)[..., None])
    rel = own_vel - vel
    rel_norm = np.linalg.norm(rel, axis=-1, keepdims=True)
    course = heading_velocity(own_course_rad, 1.0)
    along = np.where(rel_norm > DEGENERATE_DIRECTION, rel / np.maximum(rel_norm, 1e-300), course)
    left = np.stack([-along[..., 1], along[..., 0]], axis=-1)
    tcpa = np.asarray(tcpa_s)[..., None]
    at_cpa = own_start_m + own_vel * tcpa + np.asarray(miss_m)[..., None] * left
    return at_cpa - vel * tcpa, vel


def appear_step(appear_s: NDArray[Any], dt_s: float) -> IntArray:
    """The decision step from which an intruder hidden until ``appear_s`` can be sensed."""
    steps: IntArray = np.ceil(np.asarray(appear_s) / dt_s - 1e-9).astype(np.int64)
    return steps


def spawn_episodes(
    cfg: ScenarioConfig,
    rng: np.random.Generator,
    num_envs: int,
    layout: SwarmLayout | None = None,
) -> EpisodeStart:
    """B episodes of a scenario: its swarm layout and its obstacles.

    Obstacles come from the ``[[intruders]]`` geometry, or else are drawn on the spawn line
    (`spawn_obstacles`, the only use of ``rng``). ``layout``: the scenario's `swarm_layout`,
    where the caller keeps it (None: computed).
    """
    if layout is None:
        layout = swarm_layout(cfg)
    b, n, m = num_envs, cfg.uav.count, cfg.obstacles.count
    if cfg.intruders:
        pos, vel, appear = _intruder_spawn(cfg, layout)
        obs_pos, obs_vel = (np.broadcast_to(a, (b, m, 2)).copy() for a in (pos, vel))
        obs_appear = np.broadcast_to(appear, (b, m)).copy()
    else:
        obs_pos, obs_vel = spawn_obstacles(cfg, rng, b, layout)
        obs_appear = np.zeros((b, m), dtype=np.int64)
    return EpisodeStart(
        start_m=np.broadcast_to(layout.positions_m, (b, n, 2)).copy(),
        target_m=np.broadcast_to(layout.targets_m, (b, n, 2)).copy(),
        centre_m=np.broadcast_to(layout.centre_m, (b, *layout.centre_m.shape)).copy(),
        swarm_vel_m_s=np.broadcast_to(layout.velocity_m_s, (b, *layout.velocity_m_s.shape)).copy(),
        obstacle_pos_m=obs_pos,
        obstacle_vel_m_s=obs_vel,
        obstacle_appear_step=obs_appear,
    )


def _intruder_spawn(
    cfg: ScenarioConfig, layout: SwarmLayout
) -> tuple[FloatArray, FloatArray, IntArray]:
    def column(name: str) -> FloatArray:
        return np.array([getattr(i, name) for i in cfg.intruders], dtype=np.float64)

    own = np.array([i.against for i in cfg.intruders])
    pos, vel = encounter_tracks(
        layout.positions_m[own],
        layout.headings_rad[own],
        cfg.uav.speed_m_s,
        column("crossing_rad"),
        column("speed_m_s"),
        column("miss_m"),
        column("tcpa_s"),
    )
    return pos, vel, appear_step(column("appear_s"), cfg.dt_s)


def initial_sources(
    cfg: ScenarioConfig, rng: np.random.Generator, num_envs: int
) -> tuple[FieldSources, FloatArray]:
    """Field sources at the start of an episode, and the obstacle velocities (B, M, 2)."""
    ep = spawn_episodes(cfg, rng, num_envs)
    return FieldSources(
        ep.obstacle_pos_m,
        obstacle_speeds(ep.obstacle_vel_m_s),
        ep.centre_m,
        cfg.uav.speed_m_s,
        ep.obstacle_appear_step <= 0,
    ), ep.obstacle_vel_m_s


def obstacle_speeds(velocity_m_s: FloatArray) -> FloatArray:
    """|v_o| of every obstacle, (B, M), from velocities (B, M, 2)."""
    speed: FloatArray = np.hypot(velocity_m_s[..., 0], velocity_m_s[..., 1])
    return speed


def target_spacing_problem(targets_m: FloatArray, d_col_m: float) -> str | None:
    """Why the targets (N, 2) are too close for vehicles that hover at them, or None.

    Two targets must lie `TARGET_SPACING_FACTOR`·d_col apart: vehicles that arrive hover there
    while the others still fly, and every separation counts until the end.
    """
    targets = np.asarray(targets_m, dtype=np.float64).reshape(-1, 2)
    if len(targets) < 2:
        return None
    gaps = np.hypot(*(targets[:, None] - targets[None]).transpose(2, 0, 1))
    gaps[np.diag_indices(len(targets))] = np.inf
    i, j = np.unravel_index(int(np.argmin(gaps)), gaps.shape)
    need = TARGET_SPACING_FACTOR * d_col_m
    if gaps[i, j] >= need:
        return None
    return (
        f"the targets of vehicles {min(i, j)} and {max(i, j)} are {gaps[i, j]:.1f} m apart, below "
        f"{TARGET_SPACING_FACTOR}·d_col = {need:.1f} m: vehicles that arrive hover at their "
        "targets and must keep d_col from each other; move the targets apart"
    )
