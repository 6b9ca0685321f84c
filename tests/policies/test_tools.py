"""The training study tools under tools/ run end to end on a few labels and write policies
that fly: a tool the test suite never runs breaks unseen when the code under it moves."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from remarl_fc.policy_io import load_policy
from sim.scenarios import load_scenario
from sim.swarm import SwarmSim

TOOLS = Path(__file__).resolve().parents[2] / "tools"


def tool(name: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``tools/<name>.py args`` on one thread, finished."""
    return subprocess.run(
        [sys.executable, str(TOOLS / f"{name}.py"), *args],
        capture_output=True,
        text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
        timeout=300,
        check=False,
    )


def run_tool(name: str, *args: str) -> dict:
    """``tools/<name>.py args --json``: its JSON result (a failure shows its output)."""
    done = tool(name, *args, "--json")
    assert done.returncode == 0, done.stdout + done.stderr
    return json.loads(done.stdout[done.stdout.index("{") :])


def flies(path: Path) -> np.ndarray:
    """The policy file at ``path`` loads and acts on a swarm it was not trained on: its actions."""
    policy = load_policy(str(path))
    cfg = load_scenario("5u2o")
    sim = SwarmSim(cfg, scored=False)
    state = sim.initial_state(np.random.default_rng(0), 1)
    actions = policy.act(sim.observe(state, layout=policy.layout).flat())
    assert actions.shape == (1, 5) and np.all(np.abs(actions) <= 1.0)
    return actions


def test_oracle_finetune_labels_with_its_teacher_and_the_anchor_and_exports(tmp_path):
    acted = {}
    for teacher in ("oracle", "orca-shield"):
        out = tmp_path / f"{teacher}.safetensors"
        result = run_tool(
            "oracle_finetune",
            *("--minutes", "0.001", "--families", "paper-2u1o", "--teacher", teacher),
            *("--out", str(out)),
        )
        assert result["teacher"] == teacher
        assert result["sweeps"] >= 1 and result["updates"] == 20 * result["sweeps"]
        assert result["oracle_families"] == ["paper-2u1o"]
        assert result["oracle_labels"] > 0 and result["anchor_labels"] > result["oracle_labels"]
        acted[teacher] = flies(out)
    # the same seed, flights and anchor: only the teacher's labels tell the two apart
    assert not np.allclose(acted["oracle"], acted["orca-shield"])


def test_oracle_finetune_refuses_families_the_mixture_lacks(tmp_path):
    out = tmp_path / "x.safetensors"
    done = tool("oracle_finetune", "--families", "no-such-*", "--out", str(out))
    assert done.returncode != 0 and "names no family of the mixture" in done.stderr
    assert not out.exists()


@pytest.mark.parametrize("turn_weight", ["0", "3"])
def test_clone_probe_fits_reports_each_family_and_exports(tmp_path, turn_weight):
    out = tmp_path / "clone.safetensors"
    result = run_tool(
        "clone_probe",
        *("--sweeps", "3", "--steps", "4", "--families", "paper-2u1o,crossing-3u"),
        *("--turn-weight", turn_weight, "--out", str(out)),
    )
    assert set(result["families"]) == {"paper-2u1o", "crossing-3u"}
    assert result["rows"] > result["held_out_rows"] > 0 and result["steps"] == 4
    assert result["turn_weight"] == float(turn_weight)
    for row in result["families"].values():
        assert np.isfinite(row["mse"]) and row["label_variance"] >= 0
    flies(out)


def test_zoo_table_prints_a_row_per_scenario_policy_and_skips_the_generalists_suite_file():
    done = tool("zoo_table")
    assert done.returncode == 0, done.stderr
    rows = [line for line in done.stdout.splitlines() if line.startswith("| ") and "%" in line]
    zoo = TOOLS.parent / "policies" / "zoo"
    scenarios = {p.name.removesuffix(".eval.json") for p in zoo.glob("*.eval.json")}
    assert len(rows) == len(scenarios - {"generalist"}) > 0


def test_bench_train_runs_each_device_and_teacher_and_refuses_an_unknown_device():
    result = run_tool(
        "bench_train", "--devices", "cpu", "--teachers", "none,orca-shield", "--minutes", "0.02"
    )
    assert set(result) == {"none-cpu", "orca-shield-cpu"}
    for row in result.values():
        assert row["transitions_per_min"] > 0 and row["updates_per_min"] > 0
        assert 0 < row["simulator_share"] < 1 and row["iterations"] >= 1
        assert row["transitions_per_min_per_cpu"] == 1.0  # the CPU run is its own reference
    done = tool("bench_train", "--devices", "gpu")
    assert done.returncode == 2 and "--devices: unknown gpu" in done.stderr


def test_bench_rollouts_flies_a_round_per_process_count_and_refuses_a_negative_one():
    result = run_tool("bench_rollouts", "--processes", "0,1", "--minutes", "0.1")
    assert set(result) == {"processes-0", "processes-1"}
    for row in result.values():
        assert row["iterations"] >= 1 and row["transitions_per_min"] > 0
        assert row["updates_per_min"] > 0 and row["wait_share"] >= 0
    assert result["processes-0"]["iterations_per_min_ratio"] == 1.0  # its own reference
    done = tool("bench_rollouts", "--processes", "-1")
    assert done.returncode == 2 and "must be >= 0" in done.stderr


def test_adsb_error_table_flies_each_variant_on_the_same_episodes(tmp_path):
    out = tmp_path / "adsb.json"
    done = tool("adsb_error_table", "--scenarios", "3u2o", "--episodes", "4", "--json", str(out))
    assert done.returncode == 0, done.stderr
    rows = [line for line in done.stdout.splitlines() if line.startswith("| ") and "%" in line]
    results = json.loads(out.read_text())
    assert len(rows) == len(results) == 12
    by_variant = {r["variant"]: r for r in results}
    assert by_variant["as flown"]["adsb"] == {}
    assert by_variant["neither error"]["adsb"] == {"adsb_epu_m": [0.0, 0.0], "adsb_nacv_m_s": 0.0}
    assert {r["seed"] for r in results} == {results[0]["seed"]}  # the same episodes in every row
    assert all(r["scenario"] == "3u2o" and r["episodes"] == 4 for r in results)
    # each variant's sensors were flown: without the errors the same episodes fly otherwise
    assert by_variant["neither error"]["energy_rad"] != by_variant["as flown"]["energy_rad"]
    assert by_variant["tracks filtered"]["track_filter"] is True
    assert not by_variant["as flown"]["track_filter"]


def test_uav_collisions_counts_what_the_suite_evaluation_counts():
    """tools/uav_collisions.py flies a family as `remarl-fc eval` does: the same UAV–UAV
    collisions, split by whether a hovering UAV was hit."""
    sys.path.insert(0, str(TOOLS))
    try:
        from uav_collisions import family_counts, real_world_counts
    finally:
        sys.path.remove(str(TOOLS))
    from remarl_fc.offline.suite import MethodSpec, run_family
    from sim.shield import ShieldConfig
    from sim.suite import load_suite

    suite = load_suite("standard")
    family = suite.family("swarms-2x3")
    episodes, uu, hovering, arriving, unsafe = family_counts("generalist", suite, family)
    row = run_family(suite, family, MethodSpec.from_label("policy:generalist"))
    assert episodes == row["episodes"] == suite.episodes
    assert uu == round(row["collision_rate_u2u"] * episodes) > 0
    assert 0 <= hovering + arriving <= uu and unsafe == 0  # no shield, nothing to pass
    # the suite's UAVs leave on arrival; in the real world they hover, and are hit (10u1o: 18
    # of the first 50 episodes' 19 UAV–UAV collisions, with the policy shipped 2026-11-29)
    episodes, uu, hovering, arriving, _ = real_world_counts("generalist", "10u1o", 50)
    assert episodes == 50 and 0 < hovering <= uu
    # behind the shield, as `remarl-fc eval --shield on` flies it, its swarm planner included
    # (dense-10u: 2 of its 200 episodes end in a UAV–UAV collision, where nothing passed)
    shield = ShieldConfig(mode="on")
    family = suite.family("dense-10u")
    episodes, uu, _, _, unsafe = family_counts("generalist", suite, family, shield)
    row = run_family(suite, family, MethodSpec.from_label("policy:generalist"), shield=shield)
    assert uu == round(row["collision_rate_u2u"] * episodes) > 0
    assert 0 < unsafe <= uu


def test_own_view_collisions_counts_the_suites_collisions_and_what_the_rows_foresaw():
    """tools/own_view_collisions.py flies the suite's episodes: the same first UAV–UAV
    collisions as `uav_collisions`, and for each colliding UAV what its own rows predicted."""
    own_view = tool_module("own_view_collisions")
    uav_collisions = tool_module("uav_collisions")
    from remarl_fc.offline.rollout import PolicyFileAct
    from remarl_fc.policy_io import load_policy
    from sim.encounters import sample_family
    from sim.suite import load_suite
    from sim.swarm import SwarmSim

    episodes, collisions, per_lag, (flown, foreseen, avoidable) = own_view.family_counts(
        "generalist", "dense-10u", 30, 4.0, 2
    )
    suite = load_suite("standard")
    cfg, batch = sample_family(suite.family("dense-10u"), suite.seed, range(30))
    sim = SwarmSim(cfg, scored=False)
    act = PolicyFileAct(load_policy("generalist"))
    start = sim.start(batch, np.random.default_rng(0))
    assert (episodes, collisions) == uav_collisions.first_collisions(act, sim, start)[:2]
    assert collisions > 0
    assert per_lag.shape == (3, 3) and per_lag[0, 0] >= 2 * collisions  # pairs at least
    assert np.all(per_lag[:, 2] <= per_lag[:, 1]) and np.all(per_lag[:, 1] <= per_lag[:, 0])
    assert per_lag[0, 1] > per_lag[0, 0] // 2  # at the collision itself, mostly foreseen
    assert 0 < avoidable <= foreseen < flown // 10  # the flagged states are rare


def tool_module(name: str):
    """tools/<name>.py as a module (tools/ is not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, TOOLS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def recipe_module():
    """tools/generalist_recipe.py as a module."""
    return tool_module("generalist_recipe")


def test_the_recipe_chains_each_round_from_the_last_export_with_flags_train_takes(tmp_path):
    from remarl_fc.cli import build_parser
    from remarl_fc.cli.learn import generalist_config

    recipe = recipe_module()
    plan = recipe.steps(tmp_path, None, 1, 13.0)
    names = ["start"] + [f"round-{k}" for k in range(1, 8)] + ["pop-ups"]
    assert [name for name, _, _ in plan] == names
    policy = None
    for number, (name, commands, made) in enumerate(plan[:-1]):
        train, export = (c[len(recipe.remarl()) :] for c in commands)
        args = build_parser().parse_args(train)
        cfg = generalist_config(args)  # every flag is one train --generalist takes, in range
        assert export == ["export", args.out, "--out", str(made)]
        if name == "start":
            assert (cfg.seed, cfg.teacher_horizon_s, cfg.minutes) == (2, 10.0, 60.0)
            assert cfg.rollout_processes == 0  # the start is the recorded run, one process
        else:
            assert args.init == str(policy)  # from the previous step's export
            assert (cfg.teacher, cfg.dagger_fraction, cfg.dagger_lr) == ("self-shield", 1.0, 3e-4)
            assert (cfg.seed, cfg.minutes, cfg.rollout_processes) == (
                recipe.ROUNDS[number - 1][0],
                13.0,
                1,
            )
            assert bool(cfg.family_weights) == (number == 5)  # the crowded round
            own_view = (cfg.dagger_separation_weight, cfg.dagger_separation_intruder_horizon_s)
            assert own_view == ((0.1, 10.0) if number == 7 else (0.0, 0.0))  # the last round
            assert cfg.dagger_separation_intruders == (number == 7)
        policy = made
    # last, the pop-up fine-tune from the last round's export, a flag set the tool takes
    (tune,) = plan[-1][1]
    assert (
        tune[1].endswith("oracle_finetune.py") and plan[-1][2] == tmp_path / "pop-ups.safetensors"
    )
    flags = tune[2:]
    assert flags[:2] == ["--policy", str(policy)] and flags[-3:] == [
        "--out",
        str(plan[-1][2]),
        "--json",
    ]
    assert " ".join(flags[2:-3]) == (
        "--families pop-up-* --teacher oracle --share 0.25 --minutes 20 --seed 22"
    )


def test_the_recipe_resumes_a_round_with_a_checkpoint_and_skips_a_made_one(tmp_path):
    start = tmp_path / "start.safetensors"
    start.write_bytes(b"")
    (tmp_path / "round-1.safetensors").write_bytes(b"")
    (tmp_path / "round-2").mkdir()
    (tmp_path / "round-2" / "last.safetensors").write_bytes(b"")
    done = tool("generalist_recipe", "--out", str(tmp_path), "--start", str(start), "--dry-run")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("round-1:") and "skipped" in lines[0]
    assert (
        lines[1] == f"$ remarl-fc train --generalist --resume --out {tmp_path / 'round-2'} --json"
    )
    assert f"--init {tmp_path / 'round-2.safetensors'}" in lines[3]  # round 3 from round 2
    assert lines[-1] == (
        f"$ OMP_NUM_THREADS=1 python tools/oracle_finetune.py --policy "
        f"{tmp_path / 'round-7.safetensors'} --families 'pop-up-*' --teacher oracle --share 0.25 "
        f"--minutes 20 --seed 22 --out {tmp_path / 'pop-ups.safetensors'} --json"
    )
    six = tool(
        "generalist_recipe",
        "--out",
        str(tmp_path),
        "--start",
        str(start),
        "--dry-run",
        "--rounds",
        "6",
    )
    assert "oracle_finetune" not in six.stdout and "round-6" in six.stdout
    assert "round-7" not in six.stdout
    missing = tool("generalist_recipe", "--out", str(tmp_path), "--start", str(tmp_path / "x"))
    assert missing.returncode == 2 and "no such policy file" in missing.stderr


def shipped_copies(tmp_path, monkeypatch):
    """`ship_generalist` with its zoo in ``tmp_path``: copies of the shipped generalist's eval
    and policy files. Returns (the module, the shipped eval file's contents)."""
    import shutil

    from remarl_fc.policy_io import zoo_dir

    ship = tool_module("ship_generalist")
    shipped = json.loads((zoo_dir() / "generalist.eval.json").read_text())
    (tmp_path / "generalist.eval.json").write_text(json.dumps(shipped))
    shutil.copy(zoo_dir() / "generalist.safetensors", tmp_path / "generalist.safetensors")
    monkeypatch.setattr(ship, "zoo_dir", lambda: tmp_path)
    return ship, shipped


def assert_same_weights(tmp_path):
    """The copy's tensors are the shipped policy's, bit for bit."""
    from safetensors.numpy import load_file

    from remarl_fc.policy_io import zoo_dir

    before = load_file(str(zoo_dir() / "generalist.safetensors"))
    after = load_file(str(tmp_path / "generalist.safetensors"))
    assert set(before) == set(after)
    assert all(before[k].tobytes() == after[k].tobytes() for k in before)


def test_reshield_rewrites_only_the_shielded_figures_and_refuses_a_changed_policy(
    tmp_path, monkeypatch
):
    """`ship_generalist.py --reshield` on copies of the shipped files, the flights stubbed:
    the shielded figures change and nothing else, in the eval file and in the figures the
    policy file carries (its weights bit for bit); an unshielded figure that does not repeat
    stops it before anything is written."""
    from remarl_fc.policy_io import load_policy, zoo_dir

    carried = load_policy(zoo_dir() / "generalist.safetensors").meta["metrics"]
    ship, shipped = shipped_copies(tmp_path, monkeypatch)

    def flown(suite, methods, workers, shield):  # every family as shipped, shielded at 0.5
        assert shield.mode == "on"
        return [
            {
                "family": name,
                "success_rate_unshielded": row["success_rate"],
                "intervention_rate": 0.25,
                "success_rate": 0.5,
                "success_rate_solvable": 0.5,
                "collision_rate_u2o": 0.125,
                "collision_rate_u2u": 0.0625,
            }
            for name, row in shipped["families"].items()
        ]

    def real(policy, episodes, suite):
        return {
            name: {**{k: r[k] for k in ship.REAL_WORLD_KEPT}, "shielded": {"success_rate": 0.75}}
            for name, r in shipped["real_world"]["scenarios"].items()
        }

    monkeypatch.setattr(ship, "evaluate_suite", flown)
    monkeypatch.setattr(ship, "real_world", real)
    summary = ship.reshield("generalist", workers=1)
    assert summary == {
        "shielded_success_rate_solvable": 0.5,
        "shielded_collision_rate_u2u": 0.0625,
        "real_world_shielded": 0.75,
    }
    again = json.loads((tmp_path / "generalist.eval.json").read_text())
    for name, row in again["families"].items():
        assert row["shielded"]["success_rate_solvable"] == 0.5
        assert row["intervention_rate"] == 0.25
        before = {k: v for k, v in shipped["families"][name].items() if k != "intervention_rate"}
        assert {k: v for k, v in row.items() if k != "intervention_rate"} | {
            "shielded": before["shielded"]
        } == before
    assert again["success_rate"] == shipped["success_rate"]
    assert again["training"] == shipped["training"]
    metrics = load_policy(tmp_path / "generalist.safetensors").meta["metrics"]
    assert metrics == carried | {"shielded_success_rate_solvable": 0.5}
    assert_same_weights(tmp_path)
    # a policy that flies differently without the shield is not the one the file records
    written = (tmp_path / "generalist.eval.json").read_text()
    signed = (tmp_path / "generalist.safetensors").read_bytes()
    monkeypatch.setattr(
        ship,
        "evaluate_suite",
        lambda *a, **k: [dict(r, success_rate_unshielded=-1.0) for r in flown(*a, **k)],
    )
    with pytest.raises(SystemExit, match="ship it again"):
        ship.reshield("generalist", workers=1)
    assert (tmp_path / "generalist.eval.json").read_text() == written
    assert (tmp_path / "generalist.safetensors").read_bytes() == signed


def test_refly_rewrites_every_figure_and_the_ones_the_policy_file_carries(tmp_path, monkeypatch):
    """`ship_generalist.py --refly` on copies of the shipped files, the flights stubbed: every
    family's figures and the means are the new flights', the training and recipe stay, and
    the policy file carries the new means with its weights bit for bit."""
    from remarl_fc.policy_io import load_policy

    ship, shipped = shipped_copies(tmp_path, monkeypatch)

    def flown(suite, methods, workers, shield):  # every family at 0.5 alone, 0.75 shielded
        row = dict.fromkeys(ship.KEPT, 1.0) | {"episodes": 200.0, "solvable_episodes": 200}
        alone = {f"{k}_unshielded": 0.5 for k in ("success_rate", "success_rate_solvable")}
        hits = {f"{k}_unshielded": 0.0625 for k in ("collision_rate_u2o", "collision_rate_u2u")}
        shielded = dict.fromkeys(ship.SHIELDED_KEPT, 0.75)
        return [
            {"family": name, **row, **alone, **hits, **shielded} for name in shipped["families"]
        ]

    def real(policy, episodes, suite):
        assert episodes == 300
        return {
            name: {"success_rate": 0.25, "collision_rate_u2o": 0.0, "collision_rate_u2u": 0.0}
            | {"episodes": 300.0, "shielded": {"success_rate": 0.5}}
            for name in shipped["real_world"]["scenarios"]
        }

    monkeypatch.setattr(ship, "evaluate_suite", flown)
    monkeypatch.setattr(ship, "real_world", real)
    metrics = ship.refly("generalist", workers=1)
    assert metrics == {
        "success_rate": 0.5,
        "success_rate_solvable": 0.5,
        "collision_rate_u2u": 0.0625,
        "shielded_success_rate_solvable": 0.75,
        "real_world_success_rate": 0.25,
    }
    again = json.loads((tmp_path / "generalist.eval.json").read_text())
    assert set(again["families"]) == set(shipped["families"])
    for row in again["families"].values():
        assert row["success_rate"] == 0.5 and row["collision_rate_u2u"] == 0.0625
        assert row["shielded"]["success_rate_solvable"] == 0.75
    assert all(r["success_rate"] == 0.25 for r in again["real_world"]["scenarios"].values())
    assert {k: again[k] for k in metrics} == metrics
    assert again["training"] == shipped["training"] and again["recipe"] == shipped["recipe"]
    assert load_policy(tmp_path / "generalist.safetensors").meta["metrics"] == metrics
    assert_same_weights(tmp_path)


def test_sighting_table_asks_the_oracle_where_each_method_stood():
    """tools/sighting_table.py: at each episode's first sighting of a late intruder, whether a
    plan exists from the state the method reached. ORCA flies its lines until it sees the
    intruder, as the oracle does, so its sighting leaves what the suite's labels say; the
    generalist strays a few metres from its lines first (32 m before its fine-tune on the
    pop-ups), and its sightings leave other episodes."""
    sighting = tool_module("sighting_table")
    from remarl_fc.offline.suite import MethodSpec, run_family
    from sim.suite import load_suite

    assert sighting.first_sighting(np.array([[0, 3], [5, 2], [0, 0]])).tolist() == [3, 2, -1]
    suite = load_suite("standard")
    family = suite.family("pop-up-3u")
    orca = sighting.family_row(suite, family, "orca", None)
    assert orca["off_line_m"] < 0.5 and orca["at_sighting"] == orca["solvable"] > 0
    mine = sighting.family_row(suite, family, "policy:generalist", None)
    row = run_family(suite, family, MethodSpec.from_label("policy:generalist"))
    assert mine["episodes"] == row["episodes"] == suite.episodes
    assert mine["success"] == round(row["success_rate"] * row["episodes"])
    assert mine["success_solvable"] == round(row["success_rate_solvable"] * mine["solvable"])
    assert 1.0 < mine["off_line_m"] < 5.0 and mine["at_sighting"] > mine["solvable"]
    assert 0 < mine["lost_no_plan"] <= mine["solvable"] - mine["success_solvable"]
    assert mine["success_at_sighting"] <= min(mine["at_sighting"], mine["success"])


def test_the_generalist_keeps_its_line_before_a_pop_up_without_knowing_it():
    """The generalist's path until a late intruder appears is the same with the intruder moved
    1,000 km away: what tools/sighting_table.py measures off the line is a prior it learned,
    not a leak of what it cannot see. Since its fine-tune on the oracle's labels of the late
    pop-ups it keeps near its line until then (3 m off after 10 s; 35 m before it)."""
    import dataclasses

    from remarl_fc.offline.rollout import PolicyFileAct, observe_for
    from remarl_fc.policy_io import load_policy
    from sim.encounters import sample_family
    from sim.suite import load_suite

    suite = load_suite("standard")
    cfg, batch = sample_family(suite.family("pop-up-1u"), suite.seed, range(20))
    away = dataclasses.replace(batch, obstacle_pos_m=batch.obstacle_pos_m + 1.0e6)
    act = PolicyFileAct(load_policy("generalist"))
    appear = batch.obstacle_appear_step[:, 0]
    late = appear >= 5
    assert late.sum() >= 10
    paths = []
    for episodes in (batch, away):
        sim = SwarmSim(cfg, scored=False)
        state, rng = sim.start(episodes, np.random.default_rng(0)), np.random.default_rng(0)
        path = [state.pos_m]
        for _ in range(5):
            state, _ = sim.step(state, act(observe_for(sim, state, act), state, cfg), rng)
            path.append(state.pos_m)
        paths.append(np.array(path))
    for e, step in enumerate(np.minimum(appear, 5)):  # the same until its intruder appears
        np.testing.assert_array_equal(paths[0][: step + 1, e], paths[1][: step + 1, e])
    assert np.abs(paths[0][5, late, :, 1]).mean() < 5.0  # near its line (y = 0) by then


def test_a_fine_tuned_policy_file_ships_with_its_base_round_and_its_own_fine_tune(
    tmp_path, monkeypatch, capsys
):
    """`ship_generalist.py TUNED.safetensors --base generalist --name tuned`, the flights
    stubbed: the eval file records the base round's training and recipe, then the fine-tune's,
    no checkpoint, the stubbed figures; the zoo copy is the tuned file's weights, bit for bit,
    carrying those figures."""
    import shutil
    import sys

    from remarl_fc.policy_io import load_policy, zoo_dir

    ship, shipped = shipped_copies(tmp_path, monkeypatch)
    tuned = tmp_path / "elsewhere" / "tuned.safetensors"
    tuned.parent.mkdir()
    shutil.copy(zoo_dir() / "generalist.safetensors", tuned)

    def flown(suite, methods, workers, shield):
        assert methods[0].name == str(tuned) and shield.mode == "on"
        return [
            {
                "family": name,
                "episodes": 200,
                "solvable_episodes": 100,
                "success_rate_unshielded": 0.5,
                "success_rate_solvable_unshielded": 0.5,
                "collision_rate_u2o_unshielded": 0.25,
                "collision_rate_u2u_unshielded": 0.125,
                "intervention_rate": 0.25,
                "success_rate": 0.75,
                "success_rate_solvable": 0.75,
                "collision_rate_u2o": 0.0,
                "collision_rate_u2u": 0.0,
            }
            for name in shipped["families"]
        ]

    monkeypatch.setattr(ship, "evaluate_suite", flown)
    monkeypatch.setattr(ship, "real_world", lambda policy, episodes, suite: {})
    argv = ["ship_generalist.py", str(tuned), "--name", "tuned", "--recipe", "a fine-tune"]
    monkeypatch.setattr(sys, "argv", [*argv, "--real-world-episodes", "0"])
    ship.main()
    report = json.loads((tmp_path / "tuned.eval.json").read_text())
    assert report["policy"] == "tuned (policies/zoo/tuned.safetensors)"
    assert report["checkpoint"] is None
    assert report["recipe"] == f"{shipped['recipe']}; then a fine-tune"
    *before, finetune = report["training"].pop("finetunes")
    assert before == shipped["training"].pop("finetunes", [])  # the base's own, kept
    assert report["training"] == shipped["training"]
    assert finetune["reward"] == load_policy(tuned).meta["reward"]
    assert report["success_rate_solvable"] == 0.5
    assert report["shielded_success_rate_solvable"] == 0.75
    assert load_policy(tmp_path / "tuned.safetensors").meta["metrics"] == {
        "success_rate": 0.5,
        "success_rate_solvable": 0.5,
        "collision_rate_u2u": 0.125,
        "shielded_success_rate_solvable": 0.75,
    }
    before = load_policy(tuned)
    after = load_policy(tmp_path / "tuned.safetensors")
    assert before.meta["checksum"] != after.meta["checksum"]  # signed again with its figures
    assert not list(tmp_path.glob("*.part"))
    from safetensors.numpy import load_file

    weights, copied = load_file(str(tuned)), load_file(str(tmp_path / "tuned.safetensors"))
    assert set(weights) == set(copied)
    assert all(weights[k].tobytes() == copied[k].tobytes() for k in weights)
    # a base the zoo does not hold is refused before anything is flown
    monkeypatch.setattr(ship, "evaluate_suite", lambda *a, **k: pytest.fail("flown"))
    monkeypatch.setattr(sys, "argv", [*argv, "--base", "nowhere"])
    with pytest.raises(SystemExit) as refused:
        ship.main()
    assert refused.value.code == 2
    assert "--base nowhere: no nowhere.eval.json in the zoo" in capsys.readouterr().err
