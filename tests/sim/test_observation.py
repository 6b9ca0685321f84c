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
        "centre_m": rng.uniform(0, 200, (b, 2)),
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
        np.array([[40.0, 0.0]]),
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
        np.zeros((1, 2)),
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
        np.zeros((1, 2)),
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
        np.zeros((1, 2)),
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
