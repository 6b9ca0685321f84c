"""The one evaluation-seed scheme, and the episode runner every method is scored with."""

import numpy as np
import pytest

from sim.evaluation import (
    EVALUATION_SEED_BASES,
    RUN_SEED_STRIDE,
    evaluation_seed,
    run_episodes,
    summarize,
)


def test_published_evaluations_keep_their_seeds():
    """These seeds are behind published figures: the zoo's .eval.json, docs/RESULTS.md."""
    assert evaluation_seed() == 2_000_000  # remarl-fc eval
    assert [evaluation_seed(s) for s in range(3)] == [2_000_000, 2_001_000, 2_002_000]  # compare
    assert evaluation_seed(suite="zoo") == 5_000_000
    assert evaluation_seed(suite="ablation") == 7_000_000
    assert evaluation_seed(suite="training", offset=450) == 1_000_453


def test_suites_never_share_a_seed_and_never_meet_training_seeds():
    runs = range(100)
    seen: dict[int, str] = {}
    for suite in EVALUATION_SEED_BASES:
        offsets = range(0, 200_000, 500) if suite == "training" else [0]
        seeds = {evaluation_seed(r, suite=suite, offset=o) for r in runs for o in offsets}
        clash = seeds & set(seen)
        assert not clash, (suite, [seen[s] for s in sorted(clash)[:3]])
        seen.update(dict.fromkeys(seeds, suite))
    training = {r + step for r in runs for step in range(0, 200_000, 500)}  # resumed runs
    assert not training & set(seen)
    assert RUN_SEED_STRIDE * max(runs) < min(EVALUATION_SEED_BASES.values())


def test_run_episodes_counts_every_episode_once_in_order():
    rows = run_episodes(lambda o: np.zeros(o.shape[:2], np.float32), "2u1o", 7, seed=3, num_envs=3)
    assert len(rows) == 7
    again = run_episodes(lambda o: np.zeros(o.shape[:2], np.float32), "2u1o", 7, seed=3, num_envs=3)
    assert summarize(rows) == pytest.approx(summarize(again), nan_ok=True)
