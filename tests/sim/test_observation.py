import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.observation import (
    CLIP,
    COLUMNS,
    ROW_OBSTACLES,
    ROW_SELF,
    ROW_SWARM,
    ObservationLayout,
    build_observations,
)

LAYOUT = ObservationLayout(
    max_obstacles=3, range_m=100.0, aperture_rad=np.radians(270), speed_m_s=10.0
)


def world(rng, b=2, n=4, m=5):
    return {
        "own_pos_m": rng.uniform(0, 200, (b, n, 2)),
        "own_heading_rad": rng.uniform(-np.pi, np.pi, (b, n)),
        "own_vel_m_s": rng.uniform(-10, 10, (b, n, 2)),
        "target_m": rng.uniform(0, 200, (b, n, 2)),
        "centre_m": rng.uniform(0, 200, (b, n, 2)),
        "obstacle_pos_m": rng.uniform(0, 200, (b, m, 2)),
        "obstacle_vel_m_s": rng.uniform(-3, 3, (b, m, 2)),
    }


@given(
    seed=st.integers(0, 2**31),
    angle=st.floats(-np.pi, np.pi),
    dx=st.floats(-1e4, 1e4),
    dy=st.floats(-1e4, 1e4),
)
def test_rotating_and_translating_the_world_leaves_observations_unchanged(seed, angle, dx, dy):
    w = world(np.random.default_rng(seed))
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    shift = np.array([dx, dy])
    moved = {
        "own_pos_m": w["own_pos_m"] @ rot.T + shift,
        "own_heading_rad": w["own_heading_rad"] + angle,
        "own_vel_m_s": w["own_vel_m_s"] @ rot.T,
        "target_m": w["target_m"] @ rot.T + shift,
        "centre_m": w["centre_m"] @ rot.T + shift,
        "obstacle_pos_m": w["obstacle_pos_m"] @ rot.T + shift,
        "obstacle_vel_m_s": w["obstacle_vel_m_s"] @ rot.T,
    }
    a = build_observations(LAYOUT, **w)
    b = build_observations(LAYOUT, **moved)
    np.testing.assert_allclose(a.rows, b.rows, atol=2e-4)
    np.testing.assert_array_equal(a.mask, b.mask)


def test_rows_nearest_first_within_range_and_aperture():
    own = np.zeros((1, 1, 2))
    obstacles = np.array(
        [
            [
                [60.0, 0.0],  # ahead, 60 m
                [0.0, 30.0],  # left, 30 m
                [-50.0, 0.0],  # straight behind: outside the 270° aperture
                [150.0, 0.0],  # beyond range
                [20.0, -20.0],  # right-ahead, 28 m: nearest
            ]
        ]
    )
    vel = np.zeros((1, 5, 2))
    vel[0, 0] = [-2.5, 0.0]
    obs = build_observations(
        LAYOUT,
        own,
        np.zeros((1, 1)),
        np.array([[[10.0, 0.0]]]),
        np.array([[[200.0, 0.0]]]),
        np.array([[[40.0, 0.0]]]),
        obstacles,
        vel,
    )
    rows = obs.rows[0, 0]
    np.testing.assert_array_equal(obs.mask[0, 0], [1, 1, 1])
    np.testing.assert_allclose(rows[ROW_OBSTACLES + 0, :2], [0.2, -0.2])
    np.testing.assert_allclose(rows[ROW_OBSTACLES + 1, :2], [0.0, 0.3])
    np.testing.assert_allclose(rows[ROW_OBSTACLES + 2], [0.6, 0.0, -0.25, 0.0])
    assert obs.sensed[0, 0].tolist() == [True, True, False, False, True]
    np.testing.assert_allclose(rows[ROW_SELF], [2.0, 0.0, 1.0, 0.0])
    np.testing.assert_allclose(rows[ROW_SWARM], [0.4, 0.0, 1.0, 0.0])


def test_unused_rows_are_zero_and_masked_and_flat_layout():
    own = np.zeros((1, 2, 2))
    obs = build_observations(
        LAYOUT,
        own,
        np.zeros((1, 2)),
        np.zeros((1, 2, 2)),
        np.ones((1, 2, 2)),
        np.zeros((1, 2, 2)),
        np.array([[[50.0, 0.0]]]),
        np.zeros((1, 1, 2)),
    )
    assert obs.rows.shape == (1, 2, 2 + 3, COLUMNS)
    np.testing.assert_array_equal(obs.mask[0, 0], [1, 0, 0])
    assert not obs.rows[0, 0, ROW_OBSTACLES + 1 :].any()
    flat = obs.flat()
    assert flat.shape == (1, 2, LAYOUT.size)
    assert flat.dtype == np.float32
    np.testing.assert_array_equal(flat[..., -3:], obs.mask)


def test_heading_frame_puts_a_target_to_the_left_on_positive_y():
    obs = build_observations(
        LAYOUT,
        np.zeros((1, 1, 2)),
        np.full((1, 1), np.pi / 2),
        np.array([[[0.0, 10.0]]]),
        np.array([[[-100.0, 0.0]]]),
        np.zeros((1, 1, 2)),
        np.zeros((1, 0, 2)),
        np.zeros((1, 0, 2)),
    )
    np.testing.assert_allclose(obs.rows[0, 0, ROW_SELF], [0.0, 1.0, 1.0, 0.0], atol=1e-7)


def test_far_targets_are_clipped():
    obs = build_observations(
        LAYOUT,
        np.zeros((1, 1, 2)),
        np.zeros((1, 1)),
        np.zeros((1, 1, 2)),
        np.array([[[1e6, 0.0]]]),
        np.zeros((1, 1, 2)),
        np.zeros((1, 0, 2)),
        np.zeros((1, 0, 2)),
    )
    assert obs.rows[0, 0, ROW_SELF, 0] == pytest.approx(CLIP)


def test_flat_is_a_copy_of_the_rows_then_the_mask():
    w = world(np.random.default_rng(3), b=3, n=2, m=4)
    obs = build_observations(LAYOUT, **w)
    flat = obs.flat()
    b, n = obs.rows.shape[:2]
    np.testing.assert_array_equal(flat, np.concatenate([obs.rows.reshape(b, n, -1), obs.mask], -1))
    flat[...] = 7.0
    assert not (obs.rows == 7.0).any()  # flat() hands out a new array


# ---------------------------------------------------------------------------- version 2

LAYOUT_V2 = ObservationLayout(
    max_obstacles=3,
    range_m=100.0,
    aperture_rad=np.radians(270),
    speed_m_s=10.0,
    max_neighbours=2,
    version=2,
)


def v2_rows(obs, layout=LAYOUT_V2):
    """(neighbour rows (B, N, k, 8), intruder rows (B, N, m, 5), masks) of v2 observations."""
    flat = obs.storage
    bl = layout.blocks()
    b, n = flat.shape[:2]
    nb = flat[..., bl["neighbours"]].reshape(b, n, layout.max_neighbours, 8)
    it = flat[..., bl["intruders"]].reshape(b, n, layout.max_obstacles, 5)
    return nb, it, flat[..., bl["neighbour_mask"]], flat[..., bl["intruder_mask"]]


def test_v2_layout_size_and_blocks_tile_the_vector():
    bl = LAYOUT_V2.blocks()
    assert LAYOUT_V2.size == 8 + 2 * 8 + 3 * 5 + 2 + 3
    edges = sorted((s.start, s.stop) for s in bl.values())
    assert edges[0][0] == 0 and edges[-1][1] == LAYOUT_V2.size
    assert all(a[1] == b[0] for a, b in itertools.pairwise(edges))


def test_v2_self_block_is_version_1s_rows():
    w = world(np.random.default_rng(1))
    v1 = build_observations(LAYOUT, **w)
    v2 = build_observations(LAYOUT_V2, **w)
    np.testing.assert_array_equal(v2.rows, v1.rows[:, :, :ROW_OBSTACLES])


def test_v2_neighbours_nearest_first_in_range_and_sector_never_self():
    # UAV 0 at the origin heading east; the others around it.
    pos = np.array([[[0.0, 0.0], [0.0, 30.0], [50.0, 0.0], [-40.0, 0.0], [150.0, 0.0]]])
    heading = np.array([[0.0, 0.5, 0.0, 0.0, 0.0]])
    vel = np.zeros((1, 5, 2))
    vel[0, :, 0] = 10.0
    obs = build_observations(
        LAYOUT_V2,
        pos,
        heading,
        vel,
        np.full((1, 5, 2), 300.0),
        np.zeros((1, 5, 2)),
        np.zeros((1, 0, 2)),
        np.zeros((1, 0, 2)),
        commanded_heading_rad=heading,
    )
    nb, _, nb_mask, it_mask = v2_rows(obs)
    assert nb_mask[0, 0].tolist() == [1.0, 1.0]  # 30 m left, 50 m ahead; behind and far: not
    np.testing.assert_allclose(nb[0, 0, 0, :5], [0.0, 0.3, 0.0, 0.0, 0.3], atol=1e-6)
    np.testing.assert_allclose(nb[0, 0, 1, :5], [0.5, 0.0, 0.0, 0.0, 0.5], atol=1e-6)
    np.testing.assert_allclose(nb[0, 0, 0, 5:], [np.cos(0.5), np.sin(0.5), 1.0], atol=1e-6)
    assert not it_mask.any()
    # UAV 4 (150 m out) sees nobody within range
    assert nb_mask[0, 4].tolist() == [0.0, 0.0] and not nb[0, 4].any()


def test_v2_invalid_uavs_and_unknown_headings():
    pos = np.array([[[0.0, 0.0], [20.0, 0.0], [0.0, 20.0]]])
    heading = np.zeros((1, 3))
    common = {
        "own_pos_m": pos,
        "own_heading_rad": heading,
        "own_vel_m_s": np.zeros((1, 3, 2)),
        "target_m": np.full((1, 3, 2), 300.0),
        "centre_m": np.zeros((1, 3, 2)),
        "obstacle_pos_m": np.zeros((1, 0, 2)),
        "obstacle_vel_m_s": np.zeros((1, 0, 2)),
    }
    gone = build_observations(LAYOUT_V2, **common, uav_valid=np.array([[True, False, True]]))
    nb, _, mask, _ = v2_rows(gone)
    assert mask[0, 0].tolist() == [1.0, 0.0]
    np.testing.assert_allclose(nb[0, 0, 0, :2], [0.0, 0.2], atol=1e-6)  # UAV 2, to the left
    unknown = build_observations(LAYOUT_V2, **common, heading_known=np.array([[True, False, True]]))
    nb, _, mask, _ = v2_rows(unknown)
    assert mask[0, 0].tolist() == [1.0, 1.0]
    # UAV 0's nearest (tie at 20 m: lower index first) is UAV 1, whose heading is unknown
    assert nb[0, 0, 0, 5:].tolist() == [0.0, 0.0, 0.0]
    assert nb[0, 0, 1, 7] == 1.0


def test_v2_a_single_uav_has_no_neighbours():
    w = world(np.random.default_rng(2), b=3, n=1, m=2)
    obs = build_observations(LAYOUT_V2, **w)
    nb, _, nb_mask, _ = v2_rows(obs)
    assert not nb.any() and not nb_mask.any()


@given(seed=st.integers(0, 2**31), angle=st.floats(-np.pi, np.pi))
def test_v2_rotating_the_world_and_reordering_the_uavs_leaves_each_observation_unchanged(
    seed, angle
):
    rng = np.random.default_rng(seed)
    w = world(rng, b=2, n=6, m=5)
    w["own_pos_m"] = rng.uniform(0, 120, (2, 6, 2))
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    order = rng.permutation(6)
    moved = {
        "own_pos_m": (w["own_pos_m"] @ rot.T)[:, order],
        "own_heading_rad": (w["own_heading_rad"] + angle)[:, order],
        "own_vel_m_s": (w["own_vel_m_s"] @ rot.T)[:, order],
        "target_m": (w["target_m"] @ rot.T)[:, order],
        "centre_m": (w["centre_m"] @ rot.T)[:, order],
        "obstacle_pos_m": w["obstacle_pos_m"] @ rot.T,
        "obstacle_vel_m_s": w["obstacle_vel_m_s"] @ rot.T,
    }
    a = build_observations(LAYOUT_V2, **w).storage[:, order]
    b = build_observations(LAYOUT_V2, **moved).storage
    np.testing.assert_allclose(a, b, atol=5e-4)


def crowded_world(rng, b, n, m, *, lattice):
    """A v2 world with the hard cases: exact distance ties (a lattice), coincident UAVs, equal
    headings and velocities (zero differences), intruders in and out of range."""
    w = world(rng, b=b, n=n, m=m)
    if lattice:
        w["own_pos_m"] = rng.integers(-5, 6, (b, n, 2)) * 20.0
        w["obstacle_pos_m"] = rng.integers(-5, 6, (b, m, 2)) * 20.0
    else:
        w["own_pos_m"] = rng.uniform(-120, 120, (b, n, 2))
    if n > 1:
        w["own_pos_m"][0, 1] = w["own_pos_m"][0, 0]  # coincident
        w["own_heading_rad"][1] = w["own_heading_rad"][1, 0]  # one heading
        w["own_vel_m_s"][1] = w["own_vel_m_s"][1, 0]
    return w


@pytest.mark.parametrize("lattice", [False, True])
@pytest.mark.parametrize(
    ("n", "m", "k", "intruder_rows", "aperture"),
    [
        (5, 1, 6, 8, np.radians(270)),  # the bench's real world: every other UAV kept
        (6, 4, 2, 3, 2 * np.pi),  # fewer rows than candidates, all around
        (4, 3, 3, 5, np.radians(120)),
        (2, 2, 1, 1, np.radians(270)),
    ],
)
def test_v2_placed_rows_are_the_sorted_rows_of_the_direct_formula(
    monkeypatch, lattice, n, m, k, intruder_rows, aperture
):
    """Every UAV's rows placed by rank (`_place_rows`) hold the numbers of sorting each UAV's
    vehicles and computing the rows kept (the direct formula, `_sorted_order`), ties included;
    rows that hold no vehicle are +0."""
    import sim.observation as observation

    layout = ObservationLayout(intruder_rows, 100.0, aperture, 10.0, k, 2)
    rng = np.random.default_rng(n * 31 + m + lattice)
    for trial in range(6):
        w = crowded_world(rng, 16, n, m, lattice=lattice)
        extra = {
            "obstacle_valid": rng.random((16, m)) < 0.8,
            "uav_valid": rng.random((16, n)) < 0.8 if trial % 2 else None,
            "heading_known": rng.random((16, n)) < 0.7 if trial % 3 == 2 else None,
        }
        if trial % 3 == 1:
            extra["commanded_heading_rad"] = w["own_heading_rad"] + rng.normal(0, 0.3, (16, n))
        placed = build_observations(layout, **w, **extra)
        monkeypatch.setattr(observation, "RANK_CANDIDATES_MAX", -1)  # sort every block
        sorted_ = build_observations(layout, **w, **extra)
        monkeypatch.undo()
        np.testing.assert_array_equal(placed.storage, sorted_.storage)  # −0 == +0
        np.testing.assert_array_equal(placed.sensed, sorted_.sensed)
        nb, it, nb_mask, it_mask = v2_rows(placed, layout)
        for rows, mask in ((nb, nb_mask), (it, it_mask)):
            empty = rows[mask == 0.0]
            assert not np.signbit(empty).any() and not empty.any()


def test_v2_many_uavs_sort_each_uavs_neighbours_first():
    """Above `RANK_CANDIDATES_MAX` candidates the rows kept are sorted out first; either way
    the nearest seen are kept, nearest first."""
    from sim.observation import RANK_CANDIDATES_MAX

    n = RANK_CANDIDATES_MAX + 3
    layout = ObservationLayout(2, 100.0, 2 * np.pi, 10.0, 3, 2)
    rng = np.random.default_rng(4)
    w = world(rng, b=3, n=n, m=RANK_CANDIDATES_MAX + 2)
    w["own_pos_m"] = rng.uniform(-60, 60, (3, n, 2))
    obs = build_observations(layout, **w)
    nb, _, nb_mask, it_mask = v2_rows(obs, layout)
    gaps = np.linalg.norm(w["own_pos_m"][:, None] - w["own_pos_m"][:, :, None], axis=-1)
    gaps[:, np.arange(n), np.arange(n)] = np.inf
    nearest = np.sort(np.where(gaps <= 100.0, gaps, np.inf), axis=-1)[..., :3]
    np.testing.assert_allclose(nb[..., 4], np.where(nb_mask > 0, nearest / 100.0, 0.0), atol=1e-6)
    assert it_mask.shape[-1] == 2


def test_v2_other_swarms_uavs_are_intruder_rows_not_neighbours():
    """Two swarms: a UAV's neighbour rows hold its own swarm's UAVs only; the other swarm's are
    intruder rows, nearest first among the intruders, with their velocity; ``sensed`` keeps the
    intruders alone."""
    w = {
        "own_pos_m": np.array([[[0.0, 0.0], [30.0, 0.0], [0.0, 20.0]]]),
        "own_heading_rad": np.array([[0.0, np.pi, -0.5 * np.pi]]),  # each sees the others
        "own_vel_m_s": np.array([[[10.0, 0.0], [-10.0, 0.0], [0.0, -10.0]]]),
        "target_m": np.full((1, 3, 2), 500.0),
        "centre_m": np.zeros((1, 3, 2)),
        "obstacle_pos_m": np.array([[[50.0, 0.0]]]),
        "obstacle_vel_m_s": np.zeros((1, 1, 2)),
    }
    obs = build_observations(LAYOUT_V2, **w, uav_group=np.array([0, 0, 1]))
    nb, it, nb_mask, it_mask = v2_rows(obs)
    assert nb_mask[0].tolist() == [[1, 0], [1, 0], [0, 0]]
    np.testing.assert_allclose(nb[0, 0, 0, :5], [0.3, 0.0, -2.0, 0.0, 0.3], atol=1e-6)
    # UAV 0: the other swarm's UAV 20 m to its left, then the intruder 50 m ahead
    assert it_mask[0, 0].tolist() == [1, 1, 0]
    np.testing.assert_allclose(it[0, 0, 0], [0.0, 0.2, -1.0, -1.0, 0.2], atol=1e-6)
    np.testing.assert_allclose(it[0, 0, 1], [0.5, 0.0, -1.0, 0.0, 0.5], atol=1e-6)
    # UAV 2, alone in its swarm: both UAVs of the other one and the intruder, nearest first
    assert it_mask[0, 2].tolist() == [1, 1, 1]
    np.testing.assert_allclose(
        it[0, 2, :, 4], [0.2, np.hypot(30, 20) / 100, np.hypot(50, 20) / 100]
    )
    assert obs.sensed.shape == (1, 3, 1)
    assert obs.sensed[0, :, 0].tolist() == [True, False, True]  # behind UAV 1: not sensed


def test_v2_one_swarm_named_is_the_observation_without_groups():
    w = world(np.random.default_rng(5), b=3, n=5, m=4)
    plain = build_observations(LAYOUT_V2, **w)
    named = build_observations(LAYOUT_V2, **w, uav_group=np.zeros(5, dtype=np.int64))
    np.testing.assert_array_equal(plain.storage, named.storage)
    np.testing.assert_array_equal(plain.sensed, named.sensed)


@given(seed=st.integers(0, 2**31))
def test_v2_each_swarm_sees_itself_alone_and_the_other_swarms_as_intruders(seed):
    """With several swarms, a UAV's observation is the one-swarm observation of its own swarm,
    the present UAVs of the others appended to the intruders; UAVs flying alone count as one
    swarm among themselves."""
    rng = np.random.default_rng(seed)
    b, n, m = 2, 9, 3
    w = world(rng, b=b, n=n, m=m)
    w["own_pos_m"] = rng.uniform(-150, 150, (b, n, 2))
    groups = np.array([0, 0, 0, 1, 1, 2, 3, 4, 4])  # swarm 2 and 3 fly alone
    valid = rng.random((b, n)) < 0.8
    layout = ObservationLayout(4, 200.0, np.radians(270), 10.0, 3, 2)
    built = build_observations(layout, **w, uav_valid=valid, uav_group=groups)
    for swarm in ([0, 1, 2], [3, 4], [5, 6], [7, 8]):
        mine = np.isin(np.arange(n), swarm)
        alone = build_observations(
            layout,
            **{k: w[k][:, mine] for k in ("own_pos_m", "own_heading_rad", "own_vel_m_s")},
            target_m=w["target_m"][:, mine],
            centre_m=w["centre_m"][:, mine],
            obstacle_pos_m=np.concatenate([w["obstacle_pos_m"], w["own_pos_m"][:, ~mine]], 1),
            obstacle_vel_m_s=np.concatenate([w["obstacle_vel_m_s"], w["own_vel_m_s"][:, ~mine]], 1),
            obstacle_valid=np.concatenate([np.ones((b, m), bool), valid[:, ~mine]], 1),
            uav_valid=valid[:, mine],
        )
        np.testing.assert_array_equal(built.storage[:, mine], alone.storage)
        np.testing.assert_array_equal(built.sensed[:, mine], alone.sensed[..., :m])
