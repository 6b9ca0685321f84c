"""Suite files: loading, errors that name the key, derived suites, and the label cache."""

import shutil
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from sim.encounters import DISTRIBUTIONS
from sim.errors import ConfigError
from sim.scenarios import scenario_names
from sim.suite import cached_labels, family_digest, load_suite, store_labels, suite_names


def test_shipped_suites():
    assert {"standard", "smoke"} <= set(suite_names())
    standard = load_suite("standard")
    assert len(standard.families) >= 30 and standard.episodes == 200
    names = {f.name for f in standard.families}
    paper = {f.scenario for f in standard.families if f.distribution == "scenario"}
    assert set(scenario_names()) <= paper  # the paper's eight, 20u4o and 50u8o
    kinds = {f.distribution for f in standard.families}
    assert set(DISTRIBUTIONS) <= kinds
    assert {f.formation for f in standard.families if f.encounter} >= {
        "line",
        "wedge",
        "grid",
        "random",
    }
    assert max(f.uavs for f in standard.families) == 50 and "head-on-1u" in names


def test_smoke_is_the_first_episodes_of_standard():
    smoke, standard = load_suite("smoke"), load_suite("standard")
    assert smoke.families == standard.families and smoke.seed == standard.seed
    assert smoke.episodes < standard.episodes
    assert smoke.labels_path == standard.labels_path


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "mine.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('name = "x"\n', "needs [[family]]"),
        (
            '[[family]]\nname = "a"\ndistribution = "head-on"\nspeed = [1, 2]\n',
            "unknown key 'speed'",
        ),
        ('[[family]]\nname = "a"\ndistribution = "tailgate"\n', "unknown distribution"),
        (
            '[[family]]\nname = "a"\ndistribution = "scenario"\nmiss_m = [0, 1]\n',
            "needs a distribution",
        ),
        ('[[family]]\nname = "a"\ndistribution = "head-on"\nmiss_m = [3, 1]\n', "low <= high"),
        (
            '[[family]]\nname = "a"\ndistribution = "head-on"\n'
            '[[family]]\nname = "a"\ndistribution = "static"\n',
            "unique",
        ),
        ("[[family\n", "not valid TOML"),
        (
            'colour = "red"\n[[family]]\nname = "a"\ndistribution = "static"\n',
            "unknown key 'colour'",
        ),
    ],
)
def test_bad_suite_files_say_what_is_wrong(tmp_path, text, message):
    with pytest.raises(ConfigError, match=message.replace("[", r"\[")):
        load_suite(_write(tmp_path, text))


def test_unknown_suite_lists_the_shipped_ones():
    with pytest.raises(
        ConfigError, match="unknown suite 'nightly'; shipped: generalist-extra, smoke, standard"
    ):
        load_suite("nightly")


def test_family_changes_apply_on_the_named_distribution(tmp_path):
    s = load_suite(
        _write(
            tmp_path,
            '[[family]]\nname = "fast"\ndistribution = "crossing"\n'
            "uavs = 4\nspeed_m_s = [12, 20]\n",
        )
    )
    enc = s.families[0].encounter
    assert enc.speed_m_s == (12, 20)
    assert enc.crossing_deg == DISTRIBUTIONS["crossing"].crossing_deg


def test_label_cache_round_trip_and_invalidation(tmp_path):
    path = _write(tmp_path, '[[family]]\nname = "a"\ndistribution = "head-on"\n')
    suite = load_suite(path)
    family = suite.families[0]
    assert cached_labels(suite, family, 4) is None
    store_labels(suite, family, np.array([True, False, True, True]))
    assert cached_labels(suite, family, 3).tolist() == [True, False, True]
    assert cached_labels(suite, family, 5) is None  # more than cached
    # The same name with other parameters: a different digest, the labels no longer apply.
    path.write_text('[[family]]\nname = "a"\ndistribution = "head-on"\nmiss_m = [0, 1]\n')
    changed = load_suite(path)
    assert family_digest(changed, changed.families[0]) != family_digest(suite, family)
    assert cached_labels(changed, changed.families[0], 3) is None
    (tmp_path / "mine.labels.json").write_text("{not json")
    assert cached_labels(suite, family, 3) is None  # a damaged cache is never trusted


def test_shipped_standard_labels_cover_every_family(tmp_path):
    suite = load_suite("standard")
    missing = [f.name for f in suite.families if cached_labels(suite, f, suite.episodes) is None]
    assert missing == []


def test_a_copied_suite_file_uses_its_own_cache(tmp_path):
    src = Path(str(resources.files("sim").joinpath("suites", "standard.toml")))
    copy = tmp_path / "copy.toml"
    shutil.copy(src, copy)
    mine = load_suite(copy)
    assert mine.labels_path == tmp_path / "copy.labels.json"
    assert cached_labels(mine, mine.families[0], 1) is None


def test_smoke_oracle_plans_pass_the_swept_check_and_match_the_cached_labels():
    """CI's oracle check: on every smoke episode, re-plan, fly the plans in the simulator (its
    swept collision check), and compare with the labels the suite ships."""
    from sim.encounters import sample_family
    from sim.oracle import plan_episodes
    from sim.swarm import SwarmSim

    suite = load_suite("smoke")
    for family in suite.families:
        cfg, batch = sample_family(family, suite.seed, range(suite.episodes))
        plans = plan_episodes(cfg, batch)
        sim = SwarmSim(cfg, scored=False)
        rng = np.random.default_rng(0)
        state = sim.start(batch, rng)
        success = np.zeros(batch.num_envs, dtype=bool)
        for t in range(cfg.max_steps):
            state, result = sim.step(state, plans.actions[:, t], rng)
            success |= result.success
        closest = np.minimum(state.stats.min_u2o_m, state.stats.min_u2u_m)
        assert (closest[plans.solvable] >= cfg.d_col_m).all(), family.name
        assert state.reached[plans.solvable].all(), family.name
        assert np.array_equal(success, plans.solvable), family.name
        assert np.array_equal(plans.solvable, cached_labels(suite, family, suite.episodes)), (
            family.name
        )


def test_paper_scenarios_are_the_paper_families_scenarios_in_order():
    suite = load_suite("standard")
    expected = ["2u1o", "3u1o", "3u2o", "5u1o", "5u2o", "7u1o", "7u2o", "10u1o"]
    assert suite.paper_scenarios() == expected
    assert all(suite.family(f"paper-{name}").scenario == name for name in expected)
