"""The observation builder: one function for the simulator, the SITL mock and the flight runtime.

Each UAV sees a (2 + m) × 4 array (the paper's minimum observation) and a mask of m obstacle rows,
everything relative to the UAV and rotated into its heading frame (x' ahead, y' to the left), so
a policy trained flying east works flying north over any origin:

| Row | Columns 0, 1                       | Columns 2, 3                           |
|-----|------------------------------------|----------------------------------------|
| 0   | (target − own position) / range    | own velocity / UAV speed               |
| 1   | (p* − own position) / range        | pre-planned velocity v̄ / UAV speed     |
| 2.. | (obstacle − own position) / range  | obstacle velocity / UAV speed          |

Obstacle rows hold the m nearest obstacles inside the sensing range and aperture, nearest first;
rows beyond those are zero and their mask entry is 0. Entries are clipped to ±`CLIP`. Units:
positions are divided by the sensing range (m / m), velocities by the UAV speed (m/s / m/s), so
every entry is dimensionless.

Version 2 (``[sensing] observation = 2``, the generalist policies) adds the swarm's other UAVs
and describes every other vehicle by what a set encoder needs, one row each, so a policy can
take any number of them in any order. The flat observation, in this order:

| Block              | Entries per row                                                   |
|--------------------|-------------------------------------------------------------------|
| self (`SELF_SIZE`) | rows 0 and 1 of version 1, flattened                              |
| k neighbours       | Δx, Δy, Δv_x, Δv_y, distance, cos Δψ, sin Δψ, ψ known (8)         |
| m intruders        | Δx, Δy, Δv_x, Δv_y, distance (5)                                  |
| k + m mask entries | 1 for a row that holds a vehicle                                  |

Δ is the other vehicle's minus the UAV's own (position, velocity), in the UAV's heading frame;
Δψ is the other UAV's commanded heading minus the UAV's own (its cos and sin are 0, and "ψ
known" 0, where the heading is not known, e.g. a vehicle commanded by someone else). Rows hold
the nearest vehicles inside the sensing range and aperture, nearest first; the neighbours are
the other UAVs still present (``uav_valid``), never the UAV itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, FloatArray, IntArray
from sim.config import ScenarioConfig

ROW_SELF = 0
"""Row of the UAV's own properties."""
ROW_SWARM = 1
"""Row of the swarm's properties."""
ROW_OBSTACLES = 2
"""First obstacle row."""
COLUMNS = 4
"""Entries per row: (x, y, v_x, v_y) in the UAV's heading frame."""
SELF_SIZE = ROW_OBSTACLES * COLUMNS
"""Entries of the self block of a version-2 observation (version 1's rows 0 and 1)."""
NEIGHBOUR_COLUMNS = 8
"""Entries per neighbour row (v2): Δx, Δy, Δv_x, Δv_y, distance, cos Δψ, sin Δψ, ψ known."""
INTRUDER_COLUMNS = 5
"""Entries per intruder row (v2): Δx, Δy, Δv_x, Δv_y, distance."""
CLIP = 10.0
"""Every entry is clipped to [−CLIP, CLIP]: 1 km at a 100 m sensing range, or 10× the UAV
speed; only targets and virtual centres far outside any arena reach it."""


@dataclass(frozen=True)
class ObservationLayout:
    """Shape and scales of the observation; exported with every policy.

    Attributes:
        max_obstacles: m, obstacle (intruder) rows.
        range_m: sensing range; also the scale of positions.
        aperture_rad: full sensed sector, centred on the heading.
        speed_m_s: the UAV speed; the scale of velocities.
        max_neighbours: k, neighbouring-UAV rows (version 2 only).
        version: 1 (the paper's rows) or 2 (with neighbours: see the module docstring).
    """

    max_obstacles: int
    range_m: float
    aperture_rad: float
    speed_m_s: float
    max_neighbours: int = 0
    version: int = 1

    @classmethod
    def from_scenario(cls, cfg: ScenarioConfig) -> ObservationLayout:
        """The layout of a scenario's observations."""
        s = cfg.sensing
        return cls(
            s.max_obstacles,
            s.range_m,
            s.aperture_rad,
            cfg.uav.speed_m_s,
            s.max_neighbours,
            s.observation,
        )

    @property
    def rows(self) -> int:
        """2 + m (version 1's rows; in version 2, the rows of the same width: the self block)."""
        return ROW_OBSTACLES + (self.max_obstacles if self.version == 1 else 0)

    @property
    def size(self) -> int:
        """Length of the flat observation.

        Version 1: (2 + m)·4 entries, then the m mask entries. Version 2: the self block, k
        neighbour rows, m intruder rows, then the k + m mask entries.
        """
        if self.version == 1:
            return self.rows * COLUMNS + self.max_obstacles
        k, m = self.max_neighbours, self.max_obstacles
        return SELF_SIZE + k * (NEIGHBOUR_COLUMNS + 1) + m * (INTRUDER_COLUMNS + 1)

    def blocks(self) -> dict[str, slice]:
        """Version 2: where each block lies in the flat observation.

        Keys: self, neighbours, intruders, neighbour_mask, intruder_mask.
        """
        k, m = self.max_neighbours, self.max_obstacles
        edges = [SELF_SIZE, k * NEIGHBOUR_COLUMNS, m * INTRUDER_COLUMNS, k, m]
        names = ("self", "neighbours", "intruders", "neighbour_mask", "intruder_mask")
        out, start = {}, 0
        for name, width in zip(names, edges, strict=True):
            out[name] = slice(start, start + width)
            start += width
        return out


@dataclass(frozen=True)
class Observations:
    """Observations of B×N UAVs.

    Attributes:
        rows: (B, N, 2 + m, 4) float32.
        mask: (B, N, m) float32, 1 for a sensed obstacle row.
        sensed: (B, N, M) bool, which obstacles each UAV senses (before the top-m cut).
    """

    rows: NDArray[np.float32]
    mask: NDArray[np.float32]
    sensed: BoolArray
    storage: NDArray[np.float32] | None = field(default=None, repr=False, compare=False)
    """(B, N, (2 + m)·4 + m) where ``rows`` and ``mask`` are views of one flat array (as
    `build_observations` makes them), so `flat` copies it instead of concatenating; None
    otherwise."""

    def flat(self) -> NDArray[np.float32]:
        """(B, N, (2 + m)·4 + m): the rows, flattened, then the mask (a new array)."""
        if self.storage is not None:
            return self.storage.copy()
        b, n = self.rows.shape[:2]
        return np.concatenate([self.rows.reshape(b, n, -1), self.mask], axis=-1)

    def flat_shared(self) -> NDArray[np.float32]:
        """`flat`'s numbers, without its copy where there is a flat array.

        Returns ``storage`` itself (writing to it writes to ``rows`` and ``mask``) where there
        is one, a new array otherwise.
        """
        return self.flat() if self.storage is None else self.storage


def build_observations(
    layout: ObservationLayout,
    own_pos_m: FloatArray,
    own_heading_rad: FloatArray,
    own_vel_m_s: FloatArray,
    target_m: FloatArray,
    centre_m: FloatArray,
    obstacle_pos_m: FloatArray,
    obstacle_vel_m_s: FloatArray,
    obstacle_valid: BoolArray | None = None,
    heading_cos_sin: tuple[FloatArray, FloatArray] | None = None,
    *,
    uav_valid: BoolArray | None = None,
    commanded_heading_rad: FloatArray | None = None,
    heading_known: BoolArray | None = None,
) -> Observations:
    """Build every UAV's observation from plain arrays.

    Args:
        layout: rows and scales.
        own_pos_m: (B, N, 2) positions; own_heading_rad: (B, N); own_vel_m_s: (B, N, 2).
        target_m: (B, N, 2) each UAV's target.
        centre_m: (B, 2) the virtual centre p*.
        obstacle_pos_m, obstacle_vel_m_s: (B, M, 2).
        obstacle_valid: (B, M) False for obstacle slots that hold nothing.
        heading_cos_sin: cos and sin of ``own_heading_rad``, where the caller has them (None:
            computed).
        uav_valid: (B, N) version 2: the UAVs that are neighbours to the others (present in the
            episode, position known); None: all of them.
        commanded_heading_rad: (B, N) version 2: the heading each UAV is commanded to fly (the
            neighbours' Δψ); None: ``own_heading_rad``.
        heading_known: (B, N) version 2: whose commanded heading the others know; None: all.

    Returns:
        `Observations` (rows, mask, sensed).
    """
    if layout.version == 2:
        return _build_v2(
            layout,
            own_pos_m,
            own_heading_rad,
            own_vel_m_s,
            target_m,
            centre_m,
            obstacle_pos_m,
            obstacle_vel_m_s,
            obstacle_valid,
            heading_cos_sin,
            uav_valid,
            commanded_heading_rad,
            heading_known,
        )
    b, n, _ = own_pos_m.shape
    m, num_obstacles = layout.max_obstacles, obstacle_pos_m.shape[1]
    # World-frame vectors first, as x and y arrays (rows, kind, B, N) with kind 0 = position-
    # like and 1 = velocity-like: one rotation and one scaling at the end serve every row, and
    # (B, N) innermost keeps numpy's inner loops long.
    keep = min(m, num_obstacles)
    used = ROW_OBSTACLES + keep  # rows below are empty: not computed
    wx = np.empty((used, 2, b, n))
    wy = np.empty((used, 2, b, n))
    for w, k in ((wx, 0), (wy, 1)):
        np.subtract(target_m[..., k], own_pos_m[..., k], out=w[ROW_SELF, 0])  # to the target
        w[ROW_SELF, 1] = own_vel_m_s[..., k]
        np.subtract(centre_m[:, None, k], own_pos_m[..., k], out=w[ROW_SWARM, 0])  # to p*
    tx, ty = wx[ROW_SELF, 0], wy[ROW_SELF, 0]
    dist_t = tx * tx
    dist_t += ty * ty
    np.sqrt(dist_t, out=dist_t)
    vbar = layout.speed_m_s / np.where(dist_t > 0, dist_t, np.inf)
    np.multiply(tx, vbar, out=wx[ROW_SWARM, 1])  # pre-planned velocity v̄
    np.multiply(ty, vbar, out=wy[ROW_SWARM, 1])
    if heading_cos_sin is None:
        heading_cos_sin = np.cos(own_heading_rad), np.sin(own_heading_rad)
    cos_h, sin_h = heading_cos_sin  # (B, N)

    # One flat float32 array holds every observation; rows and mask are views of it.
    storage = np.zeros((b, n, layout.size), dtype=np.float32)
    rows = storage[..., : layout.rows * COLUMNS].reshape(b, n, layout.rows, COLUMNS)
    mask = storage[..., layout.rows * COLUMNS :]
    sensed = np.zeros((b, n, num_obstacles), dtype=bool)
    if num_obstacles:
        rx = obstacle_pos_m[:, None, :, 0] - own_pos_m[:, :, None, 0]  # (B, N, M), world frame
        ry = obstacle_pos_m[:, None, :, 1] - own_pos_m[:, :, None, 1]
        dist = np.sqrt(rx * rx + ry * ry)
        sensed = dist <= layout.range_m
        if layout.aperture_rad < 2 * math.pi:  # inside the sector: cos(bearing) ≥ cos(½ aperture)
            ahead = rx * cos_h[..., None] + ry * sin_h[..., None]
            sensed &= ahead >= dist * math.cos(0.5 * layout.aperture_rad)
        if obstacle_valid is not None:
            sensed &= obstacle_valid[:, None]
        rows_k = slice(ROW_OBSTACLES, used)
        if num_obstacles == 1:
            chosen = sensed
            picked = (rx, ry, obstacle_vel_m_s[:, None, :, 0], obstacle_vel_m_s[:, None, :, 1])
        else:
            order = np.argsort(np.where(sensed, dist, np.inf), axis=-1, kind="stable")[..., :keep]
            chosen = np.take_along_axis(sensed, order, axis=-1)  # (B, N, keep)
            envs = np.arange(b)[:, None, None]
            picked = (
                np.take_along_axis(rx, order, axis=-1),
                np.take_along_axis(ry, order, axis=-1),
                obstacle_vel_m_s[envs, order, 0],
                obstacle_vel_m_s[envs, order, 1],
            )
        front = chosen.transpose(2, 0, 1).astype(np.float64)  # (keep, B, N): 1 or 0
        for (w, kind), value in zip(((wx, 0), (wy, 0), (wx, 1), (wy, 1)), picked, strict=True):
            np.multiply(value.transpose(2, 0, 1), front, out=w[rows_k, kind])
        mask[..., :keep] = chosen

    scale = np.array([1.0 / layout.range_m, 1.0 / layout.speed_m_s])[:, None, None]  # per kind
    # Rotate in place, every row at once: x' ahead = (cos·x + sin·y)·scale, y' to the left =
    # (cos·y − sin·x)·scale.
    sin_y = np.multiply(sin_h, wy)
    sin_x = np.multiply(sin_h, wx)
    wx *= cos_h
    wx += sin_y
    wy *= cos_h
    wy -= sin_x
    for w in (wx, wy):
        w *= scale
        np.maximum(w, -CLIP, out=w)  # np.clip's numbers without its Python wrapper
        np.minimum(w, CLIP, out=w)
    # Transposing casts into the flat layout: (rows·kind, B·N) → (B·N, rows·kind), x' then y'.
    flat_rows = storage.reshape(b * n, layout.size)[:, : used * COLUMNS].reshape(b * n, -1, 2)
    for xy, w in enumerate((wx, wy)):
        np.copyto(flat_rows[..., xy], w.reshape(used * 2, b * n).T, casting="same_kind")
    return Observations(rows, mask, sensed, storage)


def _in_sector(
    layout: ObservationLayout,
    rx: FloatArray,
    ry: FloatArray,
    dist: FloatArray,
    cos_h: FloatArray,
    sin_h: FloatArray,
) -> BoolArray:
    """(B, N, K) vehicles at (rx, ry) (world frame, relative) inside range and aperture."""
    seen: BoolArray = dist <= layout.range_m
    if layout.aperture_rad < 2 * math.pi:
        ahead = rx * cos_h[..., None] + ry * sin_h[..., None]
        seen &= ahead >= dist * math.cos(0.5 * layout.aperture_rad)
    return seen


def _nearest(dist: FloatArray, seen: BoolArray, keep: int) -> tuple[IntArray, BoolArray]:
    """The ``keep`` nearest seen vehicles: indices (B, N, keep), nearest first, and seen.

    Ties go to the lower index; rows past the seen ones hold unseen vehicles (seen False).
    """
    key = np.where(seen, dist, np.inf)
    if keep < key.shape[-1]:
        part = np.argpartition(key, keep - 1, axis=-1)[..., :keep]
        order = np.take_along_axis(
            part, np.argsort(np.take_along_axis(key, part, axis=-1), axis=-1, kind="stable"), -1
        )
    else:
        order = np.argsort(key, axis=-1, kind="stable")
    return order, np.take_along_axis(seen, order, axis=-1)


def _relative_rows(
    layout: ObservationLayout,
    rx: FloatArray,
    ry: FloatArray,
    rvx: FloatArray,
    rvy: FloatArray,
    dist: FloatArray,
    cos_h: FloatArray,
    sin_h: FloatArray,
    chosen: BoolArray,
) -> FloatArray:
    """(B, N, K, 5) Δx, Δy, Δv_x, Δv_y, distance: heading frame, scaled, clipped.

    Inputs (B, N, K) in the world frame; rows not ``chosen`` are zero.
    """
    c, s_ = cos_h[..., None], sin_h[..., None]
    pos_scale, vel_scale = 1.0 / layout.range_m, 1.0 / layout.speed_m_s
    out = np.stack(
        [
            (c * rx + s_ * ry) * pos_scale,
            (c * ry - s_ * rx) * pos_scale,
            (c * rvx + s_ * rvy) * vel_scale,
            (c * rvy - s_ * rvx) * vel_scale,
            dist * pos_scale,
        ],
        axis=-1,
    )
    np.clip(out, -CLIP, CLIP, out=out)
    out *= chosen[..., None]
    return out


def _build_v2(
    layout: ObservationLayout,
    own_pos_m: FloatArray,
    own_heading_rad: FloatArray,
    own_vel_m_s: FloatArray,
    target_m: FloatArray,
    centre_m: FloatArray,
    obstacle_pos_m: FloatArray,
    obstacle_vel_m_s: FloatArray,
    obstacle_valid: BoolArray | None,
    heading_cos_sin: tuple[FloatArray, FloatArray] | None,
    uav_valid: BoolArray | None,
    commanded_heading_rad: FloatArray | None,
    heading_known: BoolArray | None,
) -> Observations:
    """`build_observations` for a version-2 layout (the module docstring's table)."""
    b, n, _ = own_pos_m.shape
    if heading_cos_sin is None:
        heading_cos_sin = np.cos(own_heading_rad), np.sin(own_heading_rad)
    cos_h, sin_h = heading_cos_sin
    blocks = layout.blocks()
    k, m = layout.max_neighbours, layout.max_obstacles
    storage = np.zeros((b, n, layout.size), dtype=np.float32)
    # The self block: version 1's rows 0 and 1, from version 1's builder.
    own = build_observations(
        ObservationLayout(0, layout.range_m, layout.aperture_rad, layout.speed_m_s),
        own_pos_m,
        own_heading_rad,
        own_vel_m_s,
        target_m,
        centre_m,
        np.zeros((b, 0, 2)),
        np.zeros((b, 0, 2)),
        heading_cos_sin=heading_cos_sin,
    )
    storage[..., blocks["self"]] = own.storage

    num_obstacles = obstacle_pos_m.shape[1]
    sensed = np.zeros((b, n, num_obstacles), dtype=bool)
    if num_obstacles and m:
        rx = obstacle_pos_m[:, None, :, 0] - own_pos_m[:, :, None, 0]  # (B, N, M)
        ry = obstacle_pos_m[:, None, :, 1] - own_pos_m[:, :, None, 1]
        dist = np.hypot(rx, ry)
        sensed = _in_sector(layout, rx, ry, dist, cos_h, sin_h)
        if obstacle_valid is not None:
            sensed &= obstacle_valid[:, None]
        keep = min(m, num_obstacles)
        order, chosen = _nearest(dist, sensed, keep)
        envs = np.arange(b)[:, None, None]
        rvx = obstacle_vel_m_s[envs, order, 0] - own_vel_m_s[..., None, 0]
        rvy = obstacle_vel_m_s[envs, order, 1] - own_vel_m_s[..., None, 1]
        take = [np.take_along_axis(a, order, axis=-1) for a in (rx, ry, dist)]
        rows = _relative_rows(layout, take[0], take[1], rvx, rvy, take[2], cos_h, sin_h, chosen)
        block = storage[..., blocks["intruders"]].reshape(b, n, m, INTRUDER_COLUMNS)
        block[:, :, :keep] = rows
        storage[..., blocks["intruder_mask"].start : blocks["intruder_mask"].start + keep] = chosen

    if n > 1 and k:
        rx = own_pos_m[:, None, :, 0] - own_pos_m[:, :, None, 0]  # (B, N, N): j − i
        ry = own_pos_m[:, None, :, 1] - own_pos_m[:, :, None, 1]
        dist = np.hypot(rx, ry)
        seen = _in_sector(layout, rx, ry, dist, cos_h, sin_h)
        seen &= ~np.eye(n, dtype=bool)
        if uav_valid is not None:
            seen &= uav_valid[:, None, :]
        keep = min(k, n - 1)
        order, chosen = _nearest(dist, seen, keep)
        envs = np.arange(b)[:, None, None]
        rvx = own_vel_m_s[envs, order, 0] - own_vel_m_s[..., None, 0]
        rvy = own_vel_m_s[envs, order, 1] - own_vel_m_s[..., None, 1]
        take = [np.take_along_axis(a, order, axis=-1) for a in (rx, ry, dist)]
        rows = _relative_rows(layout, take[0], take[1], rvx, rvy, take[2], cos_h, sin_h, chosen)
        commanded = own_heading_rad if commanded_heading_rad is None else commanded_heading_rad
        relative = commanded[envs, order] - own_heading_rad[..., None]
        known = chosen.copy()
        if heading_known is not None:
            known &= heading_known[envs, order]
        block = storage[..., blocks["neighbours"]].reshape(b, n, k, NEIGHBOUR_COLUMNS)
        block[:, :, :keep, :INTRUDER_COLUMNS] = rows
        block[:, :, :keep, 5] = np.cos(relative) * known
        block[:, :, :keep, 6] = np.sin(relative) * known
        block[:, :, :keep, 7] = known
        storage[..., blocks["neighbour_mask"].start : blocks["neighbour_mask"].start + keep] = (
            chosen
        )
    self_rows = storage[..., blocks["self"]].reshape(b, n, ROW_OBSTACLES, COLUMNS)
    mask = storage[..., blocks["neighbour_mask"].start :]
    return Observations(self_rows, mask, sensed, storage)
