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
every entry is dimensionless. p* is the UAV's own swarm's virtual centre (one swarm in the
paper; `UAVConfig.groups` gives several, each with its own).

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
the other UAVs of the UAV's own swarm still present (``uav_valid``), never the UAV itself; the
UAVs of other swarms (``uav_group``) are intruder rows (`OTHER_SWARMS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

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
    uav_group: IntArray | None = None,
) -> Observations:
    """Build every UAV's observation from plain arrays.

    Args:
        layout: rows and scales.
        own_pos_m: (B, N, 2) positions; own_heading_rad: (B, N); own_vel_m_s: (B, N, 2).
        target_m: (B, N, 2) each UAV's target.
        centre_m: (B, N, 2) each UAV's virtual centre p*, its swarm's (the one p* of the swarm
            in the paper; `UAVConfig.groups` gives several).
        obstacle_pos_m, obstacle_vel_m_s: (B, M, 2).
        obstacle_valid: (B, M) False for obstacle slots that hold nothing.
        heading_cos_sin: cos and sin of ``own_heading_rad``, where the caller has them (None:
            computed).
        uav_valid: (B, N) version 2: the UAVs that are neighbours to the others (present in the
            episode, position known); None: all of them.
        commanded_heading_rad: (B, N) version 2: the heading each UAV is commanded to fly (the
            neighbours' Δψ); None: ``own_heading_rad``.
        heading_known: (B, N) version 2: whose commanded heading the others know; None: all.
        uav_group: (N,) version 2: the swarm each UAV flies with (`UAVConfig.groups`); a UAV's
            neighbours are its own swarm's, and the other swarms' UAVs are among its intruder
            rows (`OTHER_SWARMS`). None: one swarm.

    Returns:
        `Observations` (rows, mask, sensed).
    """
    if centre_m.shape != own_pos_m.shape:
        raise ValueError(
            f"centre_m is {centre_m.shape}: give each UAV's virtual centre, {own_pos_m.shape}"
        )
    common = (
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
    )
    if layout.version == 2:
        swarms = None if uav_group is None else _formations(np.asarray(uav_group))
        if swarms is None or len(np.unique(swarms)) < 2:
            return _build_v2(*common, uav_valid, commanded_heading_rad, heading_known)
        return _build_v2_swarms(common, uav_valid, commanded_heading_rad, heading_known, swarms)
    b, n, _ = own_pos_m.shape
    # One flat float32 array holds every observation; rows and mask are views of it.
    storage = np.zeros((b, n, layout.size), dtype=np.float32)
    sensed = _build_v1(*common, storage)
    rows = storage[..., : layout.rows * COLUMNS].reshape(b, n, layout.rows, COLUMNS)
    mask = storage[..., layout.rows * COLUMNS :]
    return Observations(rows, mask, sensed, storage)


OTHER_SWARMS = "intruders"
"""What a UAV of one swarm sees of another swarm's UAVs (version 2, `UAVConfig.groups`): rows
among the intruders, nearest first with them, not neighbours. As neighbours, flying their own
formation to their own targets, they drew UAVs after them: the generalist, seeing two crossing
swarms as one, left its own in 53 of the 55 episodes two lines of five lost, flying with the
other line for hundreds of metres; as intruders it flew 96 % of them (docs/MODEL.md §19)."""


def _formations(group: IntArray) -> IntArray:
    """Each UAV's swarm for `OTHER_SWARMS`, the UAVs that fly alone (a swarm of one) as one.

    A UAV alone has no formation of its own to be drawn from: the others stay its neighbours,
    as they stay each other's (random paths: 97.5 % of the suite's episodes that way, 94 % with
    every other UAV an intruder row).
    """
    sizes = np.bincount(group)
    out: IntArray = np.where(sizes[group] > 1, group, -1)
    return out


def _build_v2_swarms(
    common: tuple[Any, ...],
    uav_valid: BoolArray | None,
    commanded_heading_rad: FloatArray | None,
    heading_known: BoolArray | None,
    uav_group: IntArray,
) -> Observations:
    """`_build_v2` for several swarms (`OTHER_SWARMS`): built once per swarm, for its UAVs.

    ``common``: `build_observations`' arguments up to ``heading_cos_sin``, in its order. Each
    pass observes one swarm's UAVs alone, so their neighbours are each other; the other
    swarms' UAVs that are present join the intruders (after them, so that ``sensed`` keeps
    its M obstacles). A loop over the swarms, a few at most, each pass batched over every
    environment and UAV of it.
    """
    layout, own_pos_m, own_heading_rad, own_vel_m_s, target_m, centre_m = common[:6]
    obstacle_pos_m, obstacle_vel_m_s, obstacle_valid, heading_cos_sin = common[6:]
    b, n, _ = own_pos_m.shape
    group = np.asarray(uav_group)
    present = np.ones((b, n), dtype=bool) if uav_valid is None else np.asarray(uav_valid, bool)
    seen = np.ones(obstacle_pos_m.shape[:2], bool) if obstacle_valid is None else obstacle_valid
    if heading_cos_sin is None:
        heading_cos_sin = np.cos(own_heading_rad), np.sin(own_heading_rad)
    storage = np.zeros((b, n, layout.size), dtype=np.float32)
    sensed = np.zeros((b, n, obstacle_pos_m.shape[1]), dtype=bool)
    for g in np.unique(group):
        mine = group == g
        built = _build_v2(
            layout,
            own_pos_m[:, mine],
            own_heading_rad[:, mine],
            own_vel_m_s[:, mine],
            target_m[:, mine],
            centre_m[:, mine],
            np.concatenate([obstacle_pos_m, own_pos_m[:, ~mine]], axis=1),
            np.concatenate([obstacle_vel_m_s, own_vel_m_s[:, ~mine]], axis=1),
            np.concatenate([seen, present[:, ~mine]], axis=1),
            (heading_cos_sin[0][:, mine], heading_cos_sin[1][:, mine]),
            present[:, mine],
            None if commanded_heading_rad is None else commanded_heading_rad[:, mine],
            None if heading_known is None else heading_known[:, mine],
        )
        assert built.storage is not None  # `_build_v2` builds one flat array
        storage[:, mine] = built.storage
        sensed[:, mine] = built.sensed[..., : obstacle_pos_m.shape[1]]
    rows = storage[..., layout.blocks()["self"]].reshape(b, n, ROW_OBSTACLES, COLUMNS)
    mask = storage[..., layout.blocks()["neighbour_mask"].start :]
    return Observations(rows, mask, sensed, storage)


def _build_v1(
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
    storage: NDArray[np.float32],
) -> BoolArray:
    """Write a version-1 observation into the first entries of ``storage`` (B, N, ≥ size).

    ``storage`` holds zeros (rows and mask entries left empty stay so). Version 2 writes its
    self block this way (a layout of no obstacle rows: rows 0 and 1 alone).

    Returns:
        sensed (B, N, M).
    """
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
        np.subtract(centre_m[..., k], own_pos_m[..., k], out=w[ROW_SWARM, 0])  # to p*
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

    flat = storage.reshape(b * n, storage.shape[-1])
    mask = flat[:, layout.rows * COLUMNS :].reshape(b, n, -1)
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
    flat_rows = flat[:, : used * COLUMNS].reshape(b * n, -1, 2)
    for xy, w in enumerate((wx, wy)):
        np.copyto(flat_rows[..., xy], w.reshape(used * 2, b * n).T, casting="same_kind")
    return sensed


RANK_CANDIDATES_MAX = 16
"""Candidates per UAV (K: neighbours, intruders) up to which a version-2 block computes every
UAV's row of every candidate and places each by counting the seen candidates nearer than it
(`_place_rows`: K² comparisons, with the batch innermost); above it, each UAV's nearest are
sorted first and only the rows kept are computed (`_intruder_rows_sorted`,
`_neighbour_rows_sorted`). With 6 neighbour rows kept, 1,024 environments of 6 UAVs take 0.6 of
the sort's time, 256 of 17 UAVs 0.9, 256 of 25 UAVs 1.1."""

RANK_AT_ONCE_MAX = 8
"""Candidates up to which `_place_rows` makes all K² comparisons in one (N, K, K, B) pass; above
it, one (N, K, B) pass per candidate (the temporary grows as K²)."""


def _nearest(key: FloatArray, keep: int) -> IntArray:
    """Indices (..., keep) of the ``keep`` smallest of ``key`` (..., K), smallest first.

    ``key`` is the distance of a seen vehicle, +inf for the others. Ties between equal keys go
    to whichever index the partial sort (`np.argpartition`) leaves first: the order this
    function has always given, kept exactly by `_place_rows`.
    """
    if keep < key.shape[-1]:
        part = np.argpartition(key, keep - 1, axis=-1)[..., :keep]
        order: IntArray = np.take_along_axis(
            part, np.argsort(np.take_along_axis(key, part, axis=-1), axis=-1, kind="stable"), -1
        )
        return order
    full: IntArray = np.argsort(key, axis=-1, kind="stable")
    return full


def _row_entries(
    layout: ObservationLayout,
    rel: FloatArray,
    dist: FloatArray,
    cos_h: FloatArray,
    sin_h: FloatArray,
    sector: float | None,
    columns: int,
) -> tuple[FloatArray, BoolArray]:
    """Every candidate's row entries and whether the UAV sees it.

    Args:
        rel: (4, N, K, B) Δx, Δy, Δv_x, Δv_y (the candidate's minus the UAV's, world frame).
        dist: (N, K, B). cos_h, sin_h: (N, 1, B) the observing UAV's heading.
        sector: cos(½ aperture), None for all around.

    Returns:
        (columns, N, K, B) entries, the first five Δx, Δy, Δv_x, Δv_y in the heading frame and
        the distance, scaled (velocities clipped; the positions and distances of seen vehicles
        are within ±1 and need no clip), the others left to the caller; and seen (N, K, B):
        within the range and the sector.
    """
    cols = np.empty((columns, *dist.shape))
    # All four rotated entries at once: cos·(rx, ry, rvx, rvy) and sin·(…), then
    # ahead = cos·u + sin·v and left = cos·v − sin·u on the (position, velocity) pairs.
    with_cos = np.multiply(cos_h, rel)
    with_sin = np.multiply(sin_h, rel)
    rotated = cols[:4]
    np.add(with_cos[0::2], with_sin[1::2], out=rotated[0::2])  # ahead: Δx', Δv_x'
    np.subtract(with_cos[1::2], with_sin[0::2], out=rotated[1::2])  # left: Δy', Δv_y'
    seen = dist <= layout.range_m
    if sector is not None:  # inside the sector: cos(bearing) ≥ cos(½ aperture); the bearing's
        seen &= rotated[0] >= dist * sector  # cosine times the distance is Δx' (rx·cos + ry·sin)
    rotated *= np.array([1.0 / layout.range_m] * 2 + [1.0 / layout.speed_m_s] * 2)[
        :, None, None, None
    ]
    velocity = cols[2:4]
    np.maximum(velocity, -CLIP, out=velocity)  # np.clip's numbers without its Python wrapper
    np.minimum(velocity, CLIP, out=velocity)
    np.multiply(dist, 1.0 / layout.range_m, out=cols[4])
    return cols, seen


def _intruder_rows(
    layout: ObservationLayout,
    own_pos_m: FloatArray,
    own_vel_m_s: FloatArray,
    obstacle_pos_m: FloatArray,
    obstacle_vel_m_s: FloatArray,
    obstacle_valid: BoolArray | None,
    cos_t: FloatArray,
    sin_t: FloatArray,
    sector: float | None,
    storage: NDArray[np.float32],
) -> BoolArray:
    """Write the intruder rows and their mask entries of a version-2 observation.

    Every UAV's row of every intruder is computed ((N, M, B) arrays, the batch innermost), then
    placed among that UAV's rows (`_place_rows`). ``cos_t``, ``sin_t``: (N, B).

    Returns:
        sensed (B, N, M): the intruders each UAV senses.
    """
    b, n, _ = own_pos_m.shape
    m_total = obstacle_pos_m.shape[1]
    blocks = layout.blocks()
    rel = np.empty((4, n, m_total, b))  # rx, ry, rvx, rvy: the intruder's minus the UAV's
    for q, (theirs, mine) in enumerate(
        ((obstacle_pos_m, own_pos_m), (obstacle_vel_m_s, own_vel_m_s))
    ):
        for xy in range(2):
            np.subtract(theirs[..., xy].T[None], mine[..., xy].T[:, None], out=rel[2 * q + xy])
    dist = np.hypot(rel[0], rel[1])
    cols, seen = _row_entries(
        layout, rel, dist, cos_t[:, None], sin_t[:, None], sector, INTRUDER_COLUMNS
    )
    if obstacle_valid is not None:
        seen &= obstacle_valid.T[None]
    key = np.where(seen, dist, np.inf)
    column = np.broadcast_to(np.arange(m_total), (n, m_total))
    m = layout.max_obstacles
    count = _place_rows(cols, key, seen, column, m_total, storage, blocks["intruders"], m)
    _write_mask(storage, blocks["intruder_mask"].start, count, min(m, m_total))
    sensed: BoolArray = np.ascontiguousarray(seen.transpose(2, 0, 1))
    return sensed


def _neighbour_tables(n: int) -> tuple[IntArray, IntArray, IntArray, IntArray, IntArray]:
    """Index tables of the neighbour rows of N UAVs: row r = i·(N − 1) + c, UAV i's c-th other.

    Returns:
        others (N, N − 1): the other UAV j of each row; first, second (P,): the pairs i < j in
        `np.triu_indices` order; pair (N·(N − 1),): the pair of each row; mirror
        (N·(N − 1),): the pair seen the row's way in stacked [i < j; j < i] arrays, P + pair
        where j < i. (Python lists first: a fraction of numpy's cost at these sizes.)
    """
    pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
    number = {ab: q for q, ab in enumerate(pairs)}
    rows = [(i, j) for i in range(n) for j in range(n) if j != i]
    pair = [number[(i, j) if i < j else (j, i)] for i, j in rows]
    mirror = [q + len(pairs) * (j < i) for q, (i, j) in zip(pair, rows, strict=True)]
    return (
        np.array([j for _, j in rows], dtype=np.intp).reshape(n, n - 1),
        np.array([a for a, _ in pairs], dtype=np.intp),
        np.array([b for _, b in pairs], dtype=np.intp),
        np.array(pair, dtype=np.intp),
        np.array(mirror, dtype=np.intp),
    )


def _neighbour_rows(
    layout: ObservationLayout,
    own_pos_m: FloatArray,
    own_heading_rad: FloatArray,
    own_vel_m_s: FloatArray,
    cos_t: FloatArray,
    sin_t: FloatArray,
    sector: float | None,
    uav_valid: BoolArray | None,
    commanded_heading_rad: FloatArray | None,
    heading_known: BoolArray | None,
    storage: NDArray[np.float32],
) -> None:
    """Write the neighbour rows and their mask entries of a version-2 observation.

    Every entry is computed once per ordered pair of UAVs ("i sees j": (N, N − 1, B) arrays,
    the batch innermost), before anyone's rows are chosen; each pair's row then goes to its
    place, the number of neighbours the observer sees nearer (`_place_rows`). The
    differences are the direct formula's subtractions in both directions (x_j − x_i and
    x_i − x_j: a negation would turn a +0 into −0); the distance is symmetric (hypot of |Δx|,
    |Δy|), and so is the cos of Δψ (the sin is odd) where the commanded headings are the UAVs'
    own: one hypot, cos and sin per pair.
    """
    b, n, _ = own_pos_m.shape
    blocks = layout.blocks()
    k = layout.max_neighbours
    keep = min(k, n - 1)
    others, first, second, pair, mirror = _neighbour_tables(n)
    p, c_ = len(first), n - 1
    flat_others = others.reshape(-1)
    # Per-UAV quantities (kind, N, B); the other's of each row, (kind, N, N − 1, B).
    own = np.stack(
        [own_pos_m[..., 0].T, own_pos_m[..., 1].T, own_vel_m_s[..., 0].T, own_vel_m_s[..., 1].T]
    )
    rel = own.take(flat_others, axis=1).reshape(4, n, c_, b)
    rel -= own[:, :, None]  # rx, ry, rvx, rvy: the other's minus the observer's
    flat_rx, flat_ry = rel[0].reshape(n * c_, b), rel[1].reshape(n * c_, b)
    ahead_rows = (first * (n - 1) + second - 1).astype(np.intp)  # the row of each i < j
    dist = np.hypot(flat_rx.take(ahead_rows, axis=0), flat_ry.take(ahead_rows, axis=0))
    dist = dist.take(pair, axis=0).reshape(n, c_, b)
    cols, seen = _row_entries(
        layout, rel, dist, cos_t[:, None], sin_t[:, None], sector, NEIGHBOUR_COLUMNS
    )
    if uav_valid is not None:
        seen &= uav_valid.T.take(flat_others, axis=0).reshape(n, c_, b)
    # Δψ: the other's commanded heading minus the observer's own heading.
    heading_t = own_heading_rad.T
    if commanded_heading_rad is None or commanded_heading_rad is own_heading_rad:
        turn = heading_t.take(second, axis=0) - heading_t.take(first, axis=0)  # i sees j
        back = heading_t.take(first, axis=0) - heading_t.take(second, axis=0)  # j sees i
        trig = np.empty((2, 2 * p, b))
        np.cos(turn, out=trig[0, :p])
        np.sin(turn, out=trig[1, :p])
        np.negative(trig[1, :p], out=trig[1, p:])
        np.copyto(trig[1, p:], back, where=back == 0.0)  # sin(±0) = ±0, its sign
        # "clip" (the indices are valid): `take` buffers an ``out`` in its default mode
        trig[0, :p].take(pair, axis=0, out=cols[5].reshape(n * c_, b), mode="clip")
        trig[1].take(mirror, axis=0, out=cols[6].reshape(n * c_, b), mode="clip")
    else:
        relative = commanded_heading_rad.T.take(flat_others, axis=0).reshape(n, c_, b)
        relative -= heading_t[:, None]
        np.cos(relative, out=cols[5])
        np.sin(relative, out=cols[6])
    if heading_known is None:
        cols[7] = 1.0
    else:
        known = heading_known.T.take(flat_others, axis=0).reshape(n, c_, b)
        cols[5:7] *= known  # cos and sin times "known", as the direct formula
        cols[7] = known

    key = np.where(seen, dist, np.inf)
    column = others  # the column of each row's UAV in `_nearest`'s (N, N) keys
    count = _place_rows(cols, key, seen, column, n, storage, blocks["neighbours"], k)
    _write_mask(storage, blocks["neighbour_mask"].start, count, keep)


def _write_mask(storage: NDArray[np.float32], start: int, count: IntArray, keep: int) -> None:
    """Write mask entries ``start`` + s, s < keep: 1 where row s holds a vehicle.

    The vehicles fill the first ``count`` (N, B) rows of each UAV.
    """
    filled = np.ascontiguousarray(count.T)  # (B, N)
    for slot in range(keep):
        np.copyto(storage[..., start + slot], filled > slot)


def _place_rows(
    cols: FloatArray,
    key: FloatArray,
    seen: BoolArray,
    column: IntArray,
    width: int,
    storage: NDArray[np.float32],
    block: slice,
    rows: int,
) -> IntArray:
    """Write each UAV's rows of its nearest seen vehicles into ``storage[..., block]``.

    Args:
        cols: (C, N, K, B) the C entries of the row of each of every UAV's K candidates.
        key: (N, K, B) the candidates' distances, +inf where not seen; seen: (N, K, B).
        column: (N, K) each candidate's column in the (…, width) keys `_nearest` sorts (the
            direct formula's: a neighbour's is its UAV, the observer's own column +inf).
        block: (B, N, rows·C) entries of ``storage`` (zeros); the first min(rows, K) rows are
            written, +0 where no vehicle.

    Returns:
        (N, B) the vehicles each UAV sees (they fill its first rows, up to ``rows``).

    A candidate's row is the number of seen candidates nearer than it: no sort where keys
    differ. Where two seen candidates of a UAV tie (exact coincidence), that UAV's rows are
    ordered by `_nearest` itself, so that ties go where they always went.
    """
    columns, n, kk, b = cols.shape
    keep = min(rows, kk)
    dest = storage[..., block].reshape(b, n, rows, columns)
    if kk == 1:  # a single candidate (5u1o's intruder): its row is the first, where seen
        np.copyto(cols, 0.0, where=~seen[None])
        for col in range(columns):  # column by column: numpy's 2-D transposition is quick
            dest[:, :, 0, col] = cols[col, :, 0].T
        one: IntArray = seen[:, 0].astype(np.int64)
        return one
    # Every candidate's row as one item of C float32 (numpy moves them whole).
    item = np.dtype((np.void, columns * 4))
    rows_t = np.empty((n, kk, b, columns), dtype=np.float32)
    np.copyto(rows_t, cols.transpose(1, 2, 3, 0), casting="same_kind")
    placed = np.zeros((b, n, keep + 1, columns), dtype=np.float32)  # row keep: not kept
    count: IntArray = np.add.reduce(seen, axis=1, dtype=np.int64)  # (N, B)
    # rank[i, j] = Σ_l [key[i, l] < key[i, j]]: every comparison in one pass where the
    # (N, K, K, B) comparisons are few, one pass per candidate l otherwise
    if kk <= RANK_AT_ONCE_MAX:
        rank = np.add.reduce(np.less(key[:, None], key[:, :, None]), axis=2, dtype=np.uint8)
    else:
        rank = np.zeros((n, kk, b), dtype=np.uint8)
        nearer = np.empty((n, kk, b), dtype=bool)
        for other in range(kk):
            np.less(key[:, other : other + 1], key, out=nearer)
            rank += nearer
    slot = np.where(seen, rank, np.uint8(keep))  # placed's row keep: not kept
    if keep < kk:
        np.minimum(slot, keep, out=slot)
    target = (np.arange(b) * n)[None, None] + np.arange(n)[:, None, None]
    target *= keep + 1
    target = target + slot  # (N, K, B) the row of placed of each candidate
    np.put(placed.view(item).reshape(-1), target, rows_t.view(item).reshape(-1))
    # Without ties the seen candidates' ranks are 0, 1, …, count − 1, and every unseen one's
    # is count: the total says so (ties are rare: the UAVs of a tie are found only then).
    unseen = kk - count
    unseen *= count
    expected = count * (count - 1)
    expected //= 2
    expected += unseen
    if np.add.reduce(rank, axis=None, dtype=np.int64) != np.add.reduce(expected, axis=None):
        uav, env = np.nonzero(np.add.reduce(rank, axis=1, dtype=np.int64) != expected)
        where = np.full((n, width), kk, dtype=np.intp)  # column → candidate (kk: none)
        where[np.arange(n)[:, None], column] = np.arange(kk)
        full = np.full((len(uav), width), np.inf)
        full[np.arange(len(uav))[:, None], column[uav]] = key[uav, :, env]
        order = _nearest(full, keep)  # (rows, keep) columns, nearest first
        place = where[uav[:, None], order]  # their candidates (kk: the observer itself)
        real = place < kk
        np.minimum(place, kk - 1, out=place)
        taken = seen[uav[:, None], place, env[:, None]] & real
        values = rows_t[uav[:, None], place, env[:, None]]  # (rows, keep, C)
        values[~taken] = 0.0
        placed[env, uav, :keep] = values
    dest[:, :, :keep] = placed[:, :, :keep]
    return count


def _sorted_order(dist: FloatArray, seen: BoolArray, keep: int) -> tuple[IntArray, BoolArray]:
    """The ``keep`` nearest seen vehicles: indices (B, N, keep), nearest first, and seen.

    `_nearest` on the (B, N, K) distances of the seen vehicles; rows past the seen ones hold
    unseen vehicles (seen False).
    """
    order = _nearest(np.where(seen, dist, np.inf), keep)
    return order, np.take_along_axis(seen, order, axis=-1)


def _sorted_rows(
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
    """(B, N, K, 5) Δx, Δy, Δv_x, Δv_y, distance of chosen vehicles.

    Heading frame, scaled, clipped; inputs (B, N, K) in the world frame; rows not ``chosen``
    are zero.
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


def _intruder_rows_sorted(
    layout: ObservationLayout,
    own_pos_m: FloatArray,
    own_vel_m_s: FloatArray,
    obstacle_pos_m: FloatArray,
    obstacle_vel_m_s: FloatArray,
    obstacle_valid: BoolArray | None,
    cos_h: FloatArray,
    sin_h: FloatArray,
    storage: NDArray[np.float32],
) -> BoolArray:
    """`_intruder_rows` for many intruders: each UAV's nearest sorted first, then computed.

    Where far fewer rows are kept than there are intruders, computing every UAV's row of every
    intruder first (as `_intruder_rows` does) costs more than the sort it saves.
    """
    b, n, _ = own_pos_m.shape
    blocks = layout.blocks()
    m = layout.max_obstacles
    rx = obstacle_pos_m[:, None, :, 0] - own_pos_m[:, :, None, 0]  # (B, N, M)
    ry = obstacle_pos_m[:, None, :, 1] - own_pos_m[:, :, None, 1]
    dist = np.hypot(rx, ry)
    sensed = _in_sector(layout, rx, ry, dist, cos_h, sin_h)
    if obstacle_valid is not None:
        sensed &= obstacle_valid[:, None]
    keep = min(m, obstacle_pos_m.shape[1])
    order, chosen = _sorted_order(dist, sensed, keep)
    envs = np.arange(b)[:, None, None]
    rvx = obstacle_vel_m_s[envs, order, 0] - own_vel_m_s[..., None, 0]
    rvy = obstacle_vel_m_s[envs, order, 1] - own_vel_m_s[..., None, 1]
    take = [np.take_along_axis(a, order, axis=-1) for a in (rx, ry, dist)]
    rows = _sorted_rows(layout, take[0], take[1], rvx, rvy, take[2], cos_h, sin_h, chosen)
    block = storage[..., blocks["intruders"]].reshape(b, n, m, INTRUDER_COLUMNS)
    block[:, :, :keep] = rows
    start = blocks["intruder_mask"].start
    storage[..., start : start + keep] = chosen
    return sensed


def _neighbour_rows_sorted(
    layout: ObservationLayout,
    own_pos_m: FloatArray,
    own_heading_rad: FloatArray,
    own_vel_m_s: FloatArray,
    cos_h: FloatArray,
    sin_h: FloatArray,
    uav_valid: BoolArray | None,
    commanded_heading_rad: FloatArray | None,
    heading_known: BoolArray | None,
    storage: NDArray[np.float32],
) -> None:
    """`_neighbour_rows` for many UAVs: each UAV's nearest sorted first, then computed.

    Where far fewer rows are kept than there are other UAVs, computing every pair's row first
    (as `_neighbour_rows` does) costs more than the sort it saves.
    """
    b, n, _ = own_pos_m.shape
    blocks = layout.blocks()
    k = layout.max_neighbours
    rx = own_pos_m[:, None, :, 0] - own_pos_m[:, :, None, 0]  # (B, N, N): j − i
    ry = own_pos_m[:, None, :, 1] - own_pos_m[:, :, None, 1]
    dist = np.hypot(rx, ry)
    seen = _in_sector(layout, rx, ry, dist, cos_h, sin_h)
    seen &= ~np.eye(n, dtype=bool)
    if uav_valid is not None:
        seen &= uav_valid[:, None, :]
    keep = min(k, n - 1)
    order, chosen = _sorted_order(dist, seen, keep)
    envs = np.arange(b)[:, None, None]
    rvx = own_vel_m_s[envs, order, 0] - own_vel_m_s[..., None, 0]
    rvy = own_vel_m_s[envs, order, 1] - own_vel_m_s[..., None, 1]
    take = [np.take_along_axis(a, order, axis=-1) for a in (rx, ry, dist)]
    rows = _sorted_rows(layout, take[0], take[1], rvx, rvy, take[2], cos_h, sin_h, chosen)
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
    start = blocks["neighbour_mask"].start
    storage[..., start : start + keep] = chosen


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
    """`build_observations` for a version-2 layout (the module docstring's table).

    It runs at every step of a version-2 scenario, so it is built lean: every UAV's row of every
    candidate vehicle is computed at once, with the batch innermost ((N, K, B) arrays), then
    placed among the UAV's rows by how many seen candidates are nearer (`_place_rows`); with
    many candidates, each UAV's nearest are sorted out first (`RANK_CANDIDATES_MAX`). Every
    entry is the number of the direct formula (the same operations on the same operands); a
    row that holds no vehicle is zero.
    """
    b, n, _ = own_pos_m.shape
    if heading_cos_sin is None:
        heading_cos_sin = np.cos(own_heading_rad), np.sin(own_heading_rad)
    cos_h, sin_h = heading_cos_sin
    blocks = layout.blocks()
    k, m = layout.max_neighbours, layout.max_obstacles
    storage = np.zeros((b, n, layout.size), dtype=np.float32)
    # The self block: version 1's rows 0 and 1, written in place by version 1's builder.
    _build_v1(
        ObservationLayout(0, layout.range_m, layout.aperture_rad, layout.speed_m_s),
        own_pos_m,
        own_heading_rad,
        own_vel_m_s,
        target_m,
        centre_m,
        np.zeros((b, 0, 2)),
        np.zeros((b, 0, 2)),
        None,
        heading_cos_sin,
        storage,
    )
    sector = math.cos(0.5 * layout.aperture_rad) if layout.aperture_rad < 2 * math.pi else None
    cos_t, sin_t = cos_h.T, sin_h.T  # (N, B): the batch innermost

    num_obstacles = obstacle_pos_m.shape[1]
    sensed = np.zeros((b, n, num_obstacles), dtype=bool)
    if num_obstacles > RANK_CANDIDATES_MAX and m:
        sensed = _intruder_rows_sorted(
            layout,
            own_pos_m,
            own_vel_m_s,
            obstacle_pos_m,
            obstacle_vel_m_s,
            obstacle_valid,
            cos_h,
            sin_h,
            storage,
        )
    elif num_obstacles and m:
        sensed = _intruder_rows(
            layout,
            own_pos_m,
            own_vel_m_s,
            obstacle_pos_m,
            obstacle_vel_m_s,
            obstacle_valid,
            cos_t,
            sin_t,
            sector,
            storage,
        )

    if n - 1 > RANK_CANDIDATES_MAX and k:
        _neighbour_rows_sorted(
            layout,
            own_pos_m,
            own_heading_rad,
            own_vel_m_s,
            cos_h,
            sin_h,
            uav_valid,
            commanded_heading_rad,
            heading_known,
            storage,
        )
    elif n > 1 and k:
        _neighbour_rows(
            layout,
            own_pos_m,
            own_heading_rad,
            own_vel_m_s,
            cos_t,
            sin_t,
            sector,
            uav_valid,
            commanded_heading_rad,
            heading_known,
            storage,
        )
    self_rows = storage[..., blocks["self"]].reshape(b, n, ROW_OBSTACLES, COLUMNS)
    mask = storage[..., blocks["neighbour_mask"].start :]
    return Observations(self_rows, mask, sensed, storage)
