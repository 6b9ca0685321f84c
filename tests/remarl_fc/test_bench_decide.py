"""The decision benchmark runs, times every part and its reference workload, numpy only."""

from __future__ import annotations

import numpy as np
import pytest

from remarl_fc.bench.decide import bench_decide, reference_workload


@pytest.mark.parametrize("policy", [None, "generalist"])
def test_the_decision_benchmark_times_each_part_and_a_reference_beside_it(policy):
    result = bench_decide("5u2o", samples=30, policy_name=policy)
    assert (result["uavs"], result["intruders"], result["samples"]) == (5, 2, 30)
    for part in ("decision", "observe", "act", "shield", "shielded_decision", "reference"):
        assert 0 < result[f"{part}_median_ms"] <= result[f"{part}_p99_ms"]
    ratio = result["decision_median_ms"] / result["reference_median_ms"]
    assert result["decision_per_reference"] == pytest.approx(ratio)
    assert result["most_intruders_in_one_observation"] <= result["max_obstacles"]
    assert 0.0 <= result["shield_intervention_rate"] <= 1.0


def test_the_reference_workload_is_the_same_work_every_time():
    first, again = reference_workload(3)(), reference_workload(3)()
    assert isinstance(first, np.ndarray) and first.shape == (400, 64)
    np.testing.assert_array_equal(first, again)
    assert (first >= 0).all() and first.any()  # ReLU'd, and not all zero
