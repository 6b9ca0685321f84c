"""`remarl-fc bench sim`: each part's share of a step, from a profile, summing to 1."""

import json

import pytest

from remarl_fc.bench.sim import PARTS, _own_part, bench_sim, format_parts, shares_of_profile
from remarl_fc.cli import main


def entry(own, callers=None):
    """A pstats row: (calls, primitive calls, own time, cumulative time, callers)."""
    callers = callers or {}
    return (1, 1, own, own + sum(c[3] for c in callers.values()), callers)


FLY = ("/repo/sim/transition.py", 70, "fly")
AVOID = ("/repo/sim/transition.py", 330, "begin_avoidance")
HELPER = ("/repo/sim/field.py", 10, "potential")
STEP = ("/repo/sim/swarm.py", 160, "step")
LOOP = ("/repo/tools/x.py", 1, "loop")


@pytest.mark.parametrize(
    ("key", "part"),
    [
        (FLY, "flight"),
        (AVOID, "avoidance"),
        (("/a/sim/transition.py", 1, "closest_approaches"), "swept"),
        (("/a/sim/observation.py", 1, "build_observations"), "observation"),
        (("/a/sim/spawn.py", 1, "spawn_episodes"), "reset"),
        (("/a/sim/dynamics.py", 1, "fly_response"), "dynamics"),
        (("/a/sim/sensors.py", 1, "anything_new"), "sensors"),
        (HELPER, None),
        (LOOP, None),
    ],
)
def test_functions_map_to_parts_by_module_and_name(key, part):
    assert _own_part(key, lambda k: k[2]) == part


def test_helpers_split_over_their_callers_and_the_rest_is_other():
    raw = {
        LOOP: entry(0.5),
        STEP: entry(1.0, {LOOP: (1, 1, 1.0, 9.5)}),
        FLY: entry(2.0, {STEP: (1, 1, 2.0, 3.0)}),
        AVOID: entry(1.0, {STEP: (1, 1, 1.0, 4.0)}),
        # 4 s in a helper: 1 s of it under fly, 3 s under begin_avoidance.
        HELPER: entry(4.0, {FLY: (1, 1, 1.0, 1.0), AVOID: (1, 1, 3.0, 3.0)}),
    }
    shares = shares_of_profile(raw)
    assert set(shares) == set(PARTS)
    assert sum(shares.values()) == pytest.approx(1.0)
    total = 8.5
    assert shares["flight"] == pytest.approx(3.0 / total)
    assert shares["avoidance"] == pytest.approx(4.0 / total)
    assert shares["other"] == pytest.approx(1.5 / total)


def test_bench_sim_reports_parts_summing_to_one_and_measures_without_the_profiler():
    result = bench_sim("3u1o", 8, seconds=0.05)
    parts = result["parts"]
    assert set(parts) == set(PARTS)
    assert sum(parts.values()) == pytest.approx(1.0)
    assert all(v >= 0.0 for v in parts.values())
    assert parts["flight"] > 0 and parts["swept"] > 0 and parts["observation"] > 0
    assert result["agent_steps_per_s"] > 0
    assert "flight" in format_parts(parts)
    assert "parts" not in bench_sim("3u1o", 8, seconds=0.02, parts=False)


def test_bench_sim_cli_prints_the_shares(capsys):
    code = main(["bench", "sim", "--scenario", "3u1o", "--batch", "8", "--seconds", "0.05"])
    out = capsys.readouterr().out
    assert code == 0
    assert "agent-steps/s" in out and "share of a step" in out and "flight" in out
    code = main(
        ["bench", "sim", "--scenario", "3u1o", "--batch", "8", "--seconds", "0.02", "--json"]
    )
    result = json.loads(capsys.readouterr().out)
    assert code == 0 and sum(result["parts"].values()) == pytest.approx(1.0)
