"""``remarl-fc suite`` and ``remarl-fc eval --suite``: the yardstick, end to end."""

import json

import numpy as np
import pytest
from tiny_policy import write_tiny_generalist

from remarl_fc.cli import main
from sim.shield import ShieldConfig

VOLATILE = {"seconds", "reaction_time_median_ms", "reaction_time_p99_ms"}


def run_json(capsys, argv):
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def steady(results):
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in results]


def test_suite_list_and_show(capsys):
    listed = run_json(capsys, ["suite", "list"])
    by_name = {s["name"]: s for s in listed["suites"]}
    assert by_name["standard"]["episodes"] == 200 and len(by_name["standard"]["families"]) >= 30
    shown = run_json(capsys, ["suite", "show", "smoke"])
    family = next(f for f in shown["families"] if f["name"] == "crossing-fast-5u")
    assert family["distribution"] == "crossing" and family["speed_m_s"] == [12.0, 20.0]
    assert family["uavs"] == 5 and family["intruders"] == 1
    assert 0.0 <= family["solvable"] <= 1.0


def test_eval_suite_is_reproducible_and_complete(capsys):
    argv = [
        "eval",
        "--suite",
        "smoke",
        "--method",
        "straight,orca",
        "--families",
        "head-on-1u,paper-3u2o,near-miss-3u",
    ]
    first = run_json(capsys, argv)
    assert [(r["method"], r["family"]) for r in first["results"]] == [
        (m, f) for m in ("straight", "orca") for f in ("head-on-1u", "paper-3u2o", "near-miss-3u")
    ]
    for r in first["results"]:
        assert r["applicable"] and r["episodes"] == 3
        for key in (
            "success_rate",
            "success_rate_solvable",
            "collision_rate_u2o",
            "collision_rate_u2u",
            "min_d_u2o_m",
            "mean_min_d_u2u_m",
            "energy_rad",
            "path_length_ratio",
            "reaction_time_median_ms",
            "solvable_episodes",
        ):
            assert key in r
    cells = {(r["method"], r["family"]): r for r in first["results"]}
    assert cells[("straight", "head-on-1u")]["success_rate"] == 0.0  # on a collision course
    assert cells[("straight", "head-on-1u")]["collision_rate_u2o"] == 1.0
    assert cells[("orca", "paper-3u2o")]["success_rate"] == 1.0
    again = run_json(capsys, argv)
    assert steady(again["results"]) == steady(first["results"])


def test_eval_suite_records_the_shield_it_flew_behind(capsys):
    argv = ["eval", "--suite", "smoke", "--method", "straight", "--families", "head-on-1u"]
    plain = run_json(capsys, argv)
    assert plain["shield_settings"]["mode"] == "off" and plain["results"][0]["shield"] == "off"
    argv += ["--shield", "on", "--shield-neighbour-horizon", "6", "--shield-margin", "2"]
    shielded = run_json(capsys, argv)
    settings = shielded["shield_settings"]
    assert settings["mode"] == "on" and shielded["results"][0]["shield"] == "on"
    assert settings["neighbour_horizon_s"] == 6.0 and settings["margin_m"] == 2.0
    base = ShieldConfig()
    assert (settings["passes"], settings["horizon_s"]) == (base.passes, base.horizon_s)


def test_policies_run_only_where_they_fit(capsys):
    out = run_json(
        capsys,
        [
            "eval",
            "--suite",
            "smoke",
            "--method",
            "zoo",
            "--policy",
            "3u2o",
            "--families",
            "paper-3u2o,head-on-1u,paper-5u2o",
        ],
    )
    cells = {(r["method"], r["family"]): r for r in out["results"]}
    assert cells[("zoo", "paper-3u2o")]["policy"] == "3u2o"
    assert cells[("zoo", "paper-5u2o")]["policy"] == "5u2o"
    assert cells[("zoo", "head-on-1u")] == {
        "family": "head-on-1u",
        "method": "zoo",
        "uavs": 1,
        "applicable": False,
        "reason": "no zoo policy for 1 UAVs",
    }
    assert cells[("policy:3u2o", "paper-3u2o")]["success_rate"] == 1.0
    refused = cells[("policy:3u2o", "paper-5u2o")]
    assert not refused["applicable"] and "number of UAVs" in refused["reason"]


def test_eval_suite_table_and_pictures(capsys, tmp_path):
    argv = [
        "eval",
        "--suite",
        "smoke",
        "--method",
        "straight,potential-field",
        "--families",
        "static-1u,crossing-3u",
        "--plot",
        str(tmp_path),
    ]
    assert main(argv) == 0
    table = capsys.readouterr().out
    assert "static-1u" in table and "potential-field" in table and "all solv" in table
    assert (tmp_path / "heatmap.png").stat().st_size > 5_000
    for method in ("straight", "potential-field"):
        for family in ("static-1u", "crossing-3u"):
            assert (tmp_path / "worst" / method / f"{family}.png").is_file()
    assert not list(tmp_path.rglob("*.part"))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["eval", "--suite", "smoke"], "--method NAME"),
        (["eval", "--suite", "smoke", "--method", "magic"], "unknown method 'magic'"),
        (
            ["eval", "--suite", "smoke", "--method", "orca", "--families", "nope"],
            "no family 'nope'",
        ),
        (["eval", "--suite", "weekly", "--method", "orca"], "unknown suite 'weekly'"),
        (["eval"], "give --policy"),
    ],
)
def test_bad_suite_requests_say_what_to_do(capsys, argv, message):
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_workers_give_the_same_results(capsys):
    argv = [
        "eval",
        "--suite",
        "smoke",
        "--method",
        "potential-field",
        "--families",
        "crossing-1u,static-5u,swarms-2x3",
    ]
    one = run_json(capsys, argv)
    two = run_json(capsys, [*argv, "--workers", "2"])
    assert steady(two["results"]) == steady(one["results"])


def test_ray_address_without_ray_says_how_to_get_it(capsys):
    try:
        import ray  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("Ray is installed: the error path is not reachable")
    argv = [
        "eval",
        "--suite",
        "smoke",
        "--method",
        "straight",
        "--families",
        "crossing-1u",
        "--ray-address",
        "127.0.0.1:6379",
    ]
    assert main(argv) == 2
    assert "pip install 'ray[default]'" in capsys.readouterr().err


def test_the_whole_smoke_suite_for_one_method(capsys):
    """CI's suite run: every smoke family, ORCA, the labels from the shipped cache."""
    out = run_json(capsys, ["eval", "--suite", "smoke", "--method", "orca"])
    from sim.suite import load_suite

    families = [f.name for f in load_suite("smoke").families]
    assert [r["family"] for r in out["results"]] == families
    assert all(r["applicable"] and r["episodes"] == 3 for r in out["results"])
    paper = [r for r in out["results"] if r["family"].startswith("paper-")]
    assert all(r["success_rate"] == 1.0 for r in paper)  # ORCA's 100 % on the paper's scenarios
    overtaken = next(r for r in out["results"] if r["family"] == "overtaken-3u")
    assert overtaken["collision_rate_u2o"] == 1.0  # hit from behind, outside its aperture


def test_a_generalist_runs_on_every_family_its_range_holds(capsys, tmp_path):
    """Its own version-2 layout on the families' version-1 scenarios; N outside: n/a."""
    path = write_tiny_generalist(tmp_path / "g.safetensors", uavs=(1, 5))
    argv = ["eval", "--suite", "smoke", "--policy", str(path)]
    out = run_json(capsys, [*argv, "--families", "head-on-1u,paper-3u2o,paper-7u1o"])
    cells = {r["family"]: r for r in out["results"]}
    for family, uavs in (("head-on-1u", 1), ("paper-3u2o", 3)):
        cell = cells[family]
        assert cell["applicable"] and cell["uavs"] == uavs and cell["episodes"] == 3
        assert cell["method"] == f"policy:{path}" and cell["policy"] == str(path)
        assert 0.0 <= cell["success_rate"] <= 1.0 and cell["reaction_time_median_ms"] > 0
    refused = cells["paper-7u1o"]
    assert not refused["applicable"]
    assert "7 UAVs here but the policy flies 1 to 5" in refused["reason"]


def test_versus_draws_an_episode_the_first_method_fails_and_the_second_flies(tmp_path):
    from remarl_fc.offline.suite import MethodSpec
    from remarl_fc.offline.suite_report import draw_versus
    from sim.suite import load_suite

    suite = load_suite("standard")
    specs = (MethodSpec("method", "straight"), MethodSpec("method", "orca"))
    out = tmp_path / "versus.png"
    found = draw_versus(suite, "crossing-3u", specs, out, episodes=6)
    assert found["episode"] is not None, found
    assert found["outcomes"]["straight"] != "success" and found["outcomes"]["orca"] == "success"
    assert found["success"]["orca"] > found["success"]["straight"]
    assert out.stat().st_size > 5_000 and not list(tmp_path.glob("*.part"))
    # the other way round no episode differs: nothing drawn, and said so
    none = draw_versus(suite, "crossing-3u", specs[::-1], tmp_path / "none.png", episodes=6)
    assert none["episode"] is None and not (tmp_path / "none.png").exists()


def test_versus_behind_the_shield_flies_both_methods_through_it(tmp_path):
    """`draw_versus(..., shield=...)`: straight flight behind the shield is not straight flight
    (the shield turns it off its collision courses), and the episode drawn, flown again alone,
    ends as it did among the others (the planner's plans do not depend on the batch)."""
    from remarl_fc.offline.suite import MethodSpec
    from remarl_fc.offline.suite_report import draw_versus
    from sim.shield import ShieldConfig
    from sim.suite import load_suite

    suite = load_suite("standard")
    specs = (MethodSpec("method", "straight"), MethodSpec("method", "orca"))
    alone = draw_versus(suite, "crossing-3u", specs, tmp_path / "alone.png", episodes=6)
    out = tmp_path / "shield.png"
    found = draw_versus(
        suite, "crossing-3u", specs, out, episodes=6, shield=ShieldConfig(mode="on")
    )
    assert found["success"]["straight"] > alone["success"]["straight"]
    assert found["episode"] is not None and found["same_as_batch"]
    assert found["outcomes"]["straight"] != "success" and found["outcomes"]["orca"] == "success"
    assert out.stat().st_size > 5_000


def test_versus_looks_only_at_solvable_episodes_when_asked(tmp_path, monkeypatch):
    """`draw_versus(..., solvable=True)` (`tools/versus.py --solvable`): an episode the oracle
    does not prove solvable is never drawn, however the methods fly it, and each method's
    success is also counted over the solvable episodes alone, as the suite counts it."""
    from remarl_fc.offline import suite_report
    from remarl_fc.offline.suite import MethodSpec
    from sim.suite import load_suite

    suite = load_suite("standard")
    specs = (MethodSpec("method", "straight"), MethodSpec("method", "orca"))
    first = suite_report.draw_versus(suite, "crossing-3u", specs, tmp_path / "a.png", episodes=6)
    k = first["episode"]
    assert k is not None and "success_solvable" not in first
    labels = np.ones(6, dtype=bool)
    labels[k] = False  # as if the oracle found no plan for the episode drawn
    monkeypatch.setattr(suite_report, "family_labels", lambda _suite, _family, n: labels[:n])
    again = suite_report.draw_versus(
        suite, "crossing-3u", specs, tmp_path / "b.png", episodes=6, solvable=True
    )
    assert again["episode"] != k
    assert again["success"] == first["success"]
    assert again["solvable_episodes"] == 5
    # the episode left out: straight flight failed it and ORCA flew it
    assert again["success_solvable"]["straight"] == pytest.approx(
        6 * first["success"]["straight"] / 5
    )
    assert again["success_solvable"]["orca"] == pytest.approx(
        (6 * first["success"]["orca"] - 1) / 5
    )


@pytest.mark.parametrize("label", ["orca", "zoo", "policy:generalist", "policy:runs/x.safetensors"])
def test_a_method_label_reads_back_as_its_spec(label):
    from remarl_fc.offline.suite import MethodSpec

    assert MethodSpec.from_label(label).label == label


def test_a_corrupt_policy_says_so_from_the_workers_too(tmp_path, capsys):
    """The checksum error raised in a worker process reaches the user whole, not as a broken
    pool (the error tree pickles: tests/remarl_fc/test_errors.py)."""
    from safetensors import safe_open
    from safetensors.numpy import load_file, save_file

    path = write_tiny_generalist(tmp_path / "g.safetensors", uavs=(1, 5))
    with safe_open(str(path), "np") as handle:
        metadata = handle.metadata()
    tensors = load_file(str(path))
    name = sorted(tensors)[0]
    tensors[name] = tensors[name] + 0.25  # changed after it was signed
    save_file(tensors, str(path), metadata=metadata)
    argv = ["eval", "--suite", "smoke", "--policy", str(path), "--families"]
    assert main([*argv, "crossing-1u,static-5u", "--workers", "2"]) == 2
    err = capsys.readouterr().err
    assert "checksum mismatch" in err and "re-export it" in err and "Traceback" not in err
