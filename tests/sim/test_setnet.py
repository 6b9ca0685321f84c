"""The set network's attention pooling (`sim.setnet.attend`), numpy: what its weights mean."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.setnet import ATTENTION_HEADS, attend

H = 4 * ATTENTION_HEADS


def encodings(seed: int, rows: int, lead: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Non-negative encodings (lead, rows, H) and a 0/1 mask keeping at least one row each."""
    rng = np.random.default_rng(seed)
    mask = (rng.random((lead, rows)) < 0.6).astype(np.float64)
    mask[:, 0] = 1.0
    e = rng.gamma(2.0, 1.0, (lead, rows, H)) * mask[..., None]
    return e, mask


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rows=st.integers(1, 8))
def test_a_zero_query_is_the_mean_of_the_kept_rows(seed, rows):
    e, mask = encodings(seed, rows)
    pooled = attend(e, mask, np.zeros((len(e), H)))
    np.testing.assert_allclose(pooled, e.sum(axis=1) / mask.sum(axis=1, keepdims=True))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rows=st.integers(2, 8), row=st.integers(0, 7))
def test_a_query_that_points_at_one_row_reads_that_row(seed, rows, row):
    e, mask = encodings(seed, rows)
    row %= rows
    mask[:, row] = 1.0
    e[:, row] = 0.0
    e[:, row, ::2] = 100.0  # far above the others' (gamma) channels; every head sees them
    query = np.zeros((len(e), H))
    query[:, ::2] = 10.0
    np.testing.assert_allclose(attend(e, mask, query), e[:, row], rtol=1e-9, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rows=st.integers(1, 8))
def test_weights_are_a_convex_mix_per_head_and_masked_rows_do_not_count(seed, rows):
    e, mask = encodings(seed, rows)
    rng = np.random.default_rng(seed + 1)
    query = rng.normal(0, 3, (len(e), H))
    pooled = attend(e, mask, query)
    kept = np.where(mask[..., None] > 0, e, np.nan)
    assert np.all(pooled <= np.nanmax(kept, axis=1) + 1e-9)
    assert np.all(pooled >= np.nanmin(kept, axis=1) - 1e-9)
    junk = e + (1 - mask[..., None]) * rng.normal(0, 50, e.shape)
    np.testing.assert_allclose(attend(junk, mask, query), pooled, rtol=1e-13)
    order = rng.permutation(rows)
    np.testing.assert_allclose(attend(e[:, order], mask[:, order], query), pooled, rtol=1e-13)


def test_no_kept_row_pools_to_zero():
    e = np.ones((2, 3, H))
    assert np.all(attend(e * 0, np.zeros((2, 3)), np.ones((2, H))) == 0.0)
