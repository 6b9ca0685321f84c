"""The discrete heading set and the learning-curve file every method shares."""

import doctest

import numpy as np
import pytest

import policies.common
from policies.common import CURVE_COLUMNS, CurveWriter, heading_actions, read_curve
from sim.errors import ConfigError
from sim.kinematics import scale_action


def test_default_heading_set_holds_straight_ahead_nine_degrees_apart():
    eleven = heading_actions()
    assert eleven.dtype == np.float32
    assert eleven.shape == (11,)
    assert eleven[0] == -1.0 and eleven[-1] == 1.0
    assert eleven[5] == 0.0  # straight ahead, in the middle
    np.testing.assert_allclose(np.diff(eleven) * 45.0, 9.0, rtol=1e-5)
    np.testing.assert_array_equal(eleven, -eleven[::-1])  # symmetric: no side preferred


def test_the_papers_literal_grid_of_ten_has_no_straight_ahead():
    ten = heading_actions(10)
    np.testing.assert_array_equal(ten, np.linspace(-1, 1, 10).astype(np.float32))
    assert 0.0 not in ten
    np.testing.assert_allclose(np.diff(ten) * 45.0, 10.0, rtol=1e-5)  # 10° apart
    np.testing.assert_allclose(ten * 45.0, [-45, -35, -25, -15, -5, 5, 15, 25, 35, 45], atol=1e-5)


@pytest.mark.parametrize("n", [2, 3, 10, 11, 21])
def test_headings_are_normalised_actions_that_span_the_turn_limit(n):
    """The set is in the simulator's action units: its ends turn by exactly ±a_max."""
    headings = heading_actions(n)
    assert len(headings) == n
    np.testing.assert_allclose(scale_action(headings.astype(np.float64), np.pi / 4)[[0, -1]],
                               [-np.pi / 4, np.pi / 4])  # fmt: skip


@pytest.mark.parametrize("bad", [1, 0, -3, 2.5, True, "11"])
def test_a_bad_heading_count_is_a_config_error(bad):
    with pytest.raises(ConfigError, match="n_actions"):
        heading_actions(bad)


def test_curve_writer_writes_the_shared_columns_and_numbers_episodes(tmp_path):
    path = tmp_path / "curve.csv"
    curve = CurveWriter(path)
    curve.add(16, 12.345678901234567, False)
    curve.add(np.int64(32), np.float64(-0.5), np.bool_(True))
    lines = path.read_text().splitlines()
    assert lines == [",".join(CURVE_COLUMNS), "16,1,12.345678901234567,0", "32,2,-0.5,1"]
    np.testing.assert_array_equal(read_curve(path), [[16, 12.345678901234567, 0], [32, -0.5, 1]])


def test_curve_writer_resumes_numbering_after_the_last_row(tmp_path):
    path = tmp_path / "curve.csv"
    first = CurveWriter(path)
    for k in range(3):
        first.add(10 * (k + 1), float(k), k == 2)
    again = CurveWriter(path, resume=True)
    assert again.episodes == 3
    again.add(40, 4.0, True)
    assert path.read_text().splitlines()[-1] == "40,4,4.0,1"
    fresh = CurveWriter(path)  # not resuming: a new file
    assert fresh.episodes == 0
    assert path.read_text().splitlines() == [",".join(CURVE_COLUMNS)]
    assert read_curve(path).shape == (0, 3)


def test_module_doctests():
    result = doctest.testmod(policies.common)
    assert result.attempted >= 2
    assert result.failed == 0
