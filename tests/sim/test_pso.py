import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.config import PSOConfig
from sim.pso import INFEASIBLE_COST, pso_separate
from sim.spawn import min_pairwise_distance


def run(positions, seed=0, **cfg):
    return pso_separate(
        np.asarray(positions, dtype=float), PSOConfig(**cfg), np.random.default_rng(seed)
    )


@pytest.mark.parametrize("seed", range(5))
def test_two_uavs_ten_metres_apart_threshold_twenty(seed):
    res = run([[[0.0, 0.0], [10.0, 0.0]]], seed=seed, threshold_m=20.0)
    assert res.feasible.item()
    assert res.min_distance_m.item() >= 20.0
    assert min_pairwise_distance(res.positions_m[0]) >= 20.0
    assert res.max_shift_m.item() == pytest.approx(5.0, rel=0.10)  # known optimum: 5 m
    assert res.cost.item() == pytest.approx(25.0, rel=0.02)


def test_known_optima_solved_independently_in_one_batched_call():
    # env 0: 2 UAVs 10 m apart along y; env 1: coincident pair needs 15 m each for 30 m;
    # env 2: already feasible.
    pos = np.array(
        [
            [[0.0, 0.0], [0.0, 10.0]],
            [[50.0, 50.0], [50.0, 50.0]],
            [[0.0, 0.0], [100.0, 0.0]],
        ]
    )
    res = run(pos, threshold_m=30.0)
    assert res.feasible.all()
    np.testing.assert_allclose(res.max_shift_m[:2], [10.0, 15.0], rtol=0.10)
    assert res.max_shift_m[2] == 0.0


def test_feasible_positions_do_not_move():
    pos = np.array([[[0.0, 0.0], [40.0, 0.0], [0.0, 40.0], [40.0, 40.0]]])
    res = run(pos, threshold_m=30.0)
    assert res.max_shift_m.item() <= 1e-9
    np.testing.assert_allclose(res.positions_m, pos, atol=1e-9)


def test_same_seed_same_result_different_seed_different_search():
    pos = [[[0.0, 0.0], [12.0, 0.0], [6.0, 8.0]]]
    a, b, c = run(pos, seed=7), run(pos, seed=7), run(pos, seed=8)
    np.testing.assert_array_equal(a.positions_m, b.positions_m)
    assert not np.array_equal(a.positions_m, c.positions_m)


def test_inactive_uavs_neither_move_nor_constrain():
    pos = np.array([[[0.0, 0.0], [5.0, 0.0], [100.0, 0.0]]])
    active = np.array([[True, False, True]])
    res = pso_separate(pos, PSOConfig(), np.random.default_rng(0), active)
    np.testing.assert_array_equal(res.positions_m[0, 1], pos[0, 1])
    assert res.max_shift_m.item() == 0.0  # the active pair is already 100 m apart


def test_single_uav_is_trivially_feasible():
    res = run([[[3.0, 4.0]]])
    assert res.feasible.item() and res.max_shift_m.item() == 0.0
    assert res.min_distance_m.item() == np.inf


def test_evaluation_count_is_reported():
    assert run([[[0.0, 0.0], [1.0, 0.0]]], particles=20, iterations=7).evaluations == 140


@settings(max_examples=25)
@given(
    n=st.integers(2, 5),
    seed=st.integers(0, 2**16),
    spread=st.floats(5.0, 60.0),
)
def test_crowded_swarms_become_feasible_without_being_made_worse(n, seed, spread):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0, spread, (1, n, 2))
    res = pso_separate(pos, PSOConfig(), rng)
    assert res.feasible.item(), "PSO did not separate a small swarm"
    assert min_pairwise_distance(res.positions_m[0]) >= 30.0 - 1e-9
    shift = np.hypot(*(res.positions_m[0] - pos[0]).T).max()
    assert shift == pytest.approx(res.max_shift_m.item())
    assert res.cost.item() < INFEASIBLE_COST


def test_close_pairs_sharing_no_uav_are_settled_by_the_certified_repair_without_a_search():
    # Two close pairs (12 m and 20 m apart, threshold 30 m) far from each other: the optimum
    # moves each pair's UAVs half its deficit apart; nothing else moves.
    pos = np.array([[[0.0, 0.0], [12.0, 0.0], [200.0, 0.0], [200.0, 20.0], [100.0, 100.0]]])
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    res = pso_separate(pos, PSOConfig(), rng)
    assert rng.bit_generator.state == state  # no search: no randomness drawn
    assert not res.searched.item() and res.feasible.item()
    assert res.max_shift_m.item() == pytest.approx(9.0, abs=0.05)  # (30 − 12) / 2
    assert min_pairwise_distance(res.positions_m[0]) >= 30.0
    np.testing.assert_array_equal(res.positions_m[0, 4], pos[0, 4])
    shift = np.hypot(*(res.positions_m[0] - pos[0]).T)
    np.testing.assert_allclose(shift[2:4], 5.0, atol=0.05)  # (30 − 20) / 2
    assert res.cost.item() == pytest.approx(30.0 + res.max_shift_m.item())


def test_a_chain_of_close_uavs_is_searched_and_beats_its_repair():
    pos = np.array([[[0.0, 0.0], [21.0, 0.0], [42.0, 0.0], [63.0, 0.0]]])
    res = run(pos)
    assert res.searched.item() and res.feasible.item()
    # The repair alone pushes the end UAVs out by the whole chain's deficit.
    assert res.max_shift_m.item() < 14.0


def test_certified_repairs_do_not_depend_on_the_rest_of_the_batch():
    # A lone close pair is settled after one sweep of the repair while a crowded swarm in the
    # same call needs many: the pair's answer is the same alone and in the batch.
    pair = [[0.0, 0.0], [12.0, 0.0], [200.0, 0.0], [300.0, 0.0], [400.0, 0.0]]
    crowd = [[0.0, 0.0], [3.0, 0.0], [6.0, 0.0], [9.0, 1.0], [12.0, 0.0]]
    far = [[0.0, 0.0], [100.0, 0.0], [200.0, 0.0], [300.0, 0.0], [400.0, 0.0]]
    batch = run([pair, crowd, pair, far] + [pair] * 3)
    alone = run([pair])
    assert not batch.searched[[0, 2, 3, 4, 5, 6]].any()
    for k in (0, 2, 4, 5, 6):
        np.testing.assert_array_equal(batch.positions_m[k], alone.positions_m[0])
        assert batch.cost[k] == alone.cost[0]
    assert batch.feasible.all()
    np.testing.assert_array_equal(batch.positions_m[3], far)


def test_inactive_uavs_are_ignored_where_others_are_separated():
    pos = np.array([[[0.0, 0.0], [0.0, 0.0], [10.0, 0.0], [5.0, 5.0]]] * 2)
    active = np.array([[True, False, True, False], [True, True, True, True]])
    res = pso_separate(pos, PSOConfig(), np.random.default_rng(0), active)
    assert res.feasible.all()
    np.testing.assert_array_equal(res.positions_m[0, [1, 3]], pos[0, [1, 3]])
    assert res.max_shift_m[0] == pytest.approx(10.0, abs=0.05)  # (30 − 10) / 2
    assert min_pairwise_distance(res.positions_m[1]) >= 30.0
