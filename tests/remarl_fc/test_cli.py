import json

import pytest

from remarl_fc import __version__
from remarl_fc.cli import main
from sim.scenarios import scenario_names


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_version_and_help(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert __version__ in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "scenarios" in capsys.readouterr().out


def test_scenarios_json_lists_every_shipped_scenario(capsys):
    code, out, _ = run(capsys, "scenarios", "--json")
    assert code == 0
    rows = json.loads(out)["scenarios"]
    assert [r["name"] for r in rows] == scenario_names()
    three = next(r for r in rows if r["name"] == "3u2o")
    assert (three["uavs"], three["obstacles"], three["arena_m"]) == (3, 2, [300.0, 300.0])


def test_scenarios_table(capsys):
    code, out, _ = run(capsys, "scenarios")
    assert code == 0 and "50u8o" in out and "formation" in out


def test_field_draws_a_png_and_reports_levels(capsys, tmp_path):
    out_png = tmp_path / "sub" / "f.png"
    code, out, _ = run(capsys, "field", "--scenario", "3u2o", "--out", str(out_png), "--json")
    assert code == 0
    payload = json.loads(out)
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out_png.stat().st_size > 20_000
    assert not list(tmp_path.rglob("*.part"))
    assert len(payload["levels"]) == 3 and all(level > 0 for level in payload["levels"])
    assert len(payload["obstacle_m"]) == 2


def test_field_accepts_a_scenario_file(capsys, tmp_path):
    path = tmp_path / "duo.toml"
    path.write_text('[uav]\ncount = 2\nformation = "line"\n[obstacles]\ncount = 0\n')
    code, out, _ = run(capsys, "field", "--scenario", str(path), "--out", str(tmp_path / "d.png"))
    assert code == 0 and "duo" in out


def test_bad_scenario_is_a_clear_error_with_exit_2(capsys, tmp_path):
    code, out, err = run(capsys, "field", "--scenario", "9u9o", "--out", str(tmp_path / "x.png"))
    assert code == 2 and out == ""
    assert "unknown scenario" in err and "3u2o" in err
    assert not (tmp_path / "x.png").exists()


def test_bench_pso_json(capsys):
    code, out, _ = run(capsys, "bench", "pso", "--uavs", "4", "--repeats", "3", "--json")
    assert code == 0
    result = json.loads(out)
    assert result["evaluations"] == 6000
    assert result["ms_per_call"] > 0
    assert result["feasible_fraction"] == 1.0


@pytest.mark.parametrize(("scenario", "suffix"), [("3u2o", ".png"), ("10u1o", ".gif")])
def test_rollout_draws_an_episode(capsys, tmp_path, scenario, suffix):
    out = tmp_path / f"run{suffix}"
    args = ["rollout", "--scenario", scenario, "--policy", "straight", "--out", str(out)]
    code, text, _ = run(capsys, *args, "--json")
    assert code == 0
    result = json.loads(text)
    assert result["length"] >= 1
    assert result["success"] is False  # flying straight into the obstacles
    header = out.read_bytes()[:6]
    assert header in (b"\x89PNG\r\n", b"GIF89a")
    assert not list(tmp_path.glob("*.part"))


def test_rollout_refuses_other_image_types(capsys, tmp_path):
    code, _, err = run(capsys, "rollout", "--out", str(tmp_path / "run.jpg"))
    assert code == 2
    assert ".png or .gif" in err


def test_bench_sim_json(capsys):
    code, out, _ = run(
        capsys, "bench", "sim", "--scenario", "3u1o", "--batch", "8", "--seconds", "0.05", "--json"
    )
    assert code == 0
    result = json.loads(out)
    assert result["agents"] == 3
    assert result["agent_steps_per_s"] > 0
    assert result["steps"] >= 5


def train_2u1o(capsys, run_dir, options):
    """`remarl-fc train` of a 2u1o run into run_dir, with these options."""
    return run(capsys, "train", "--scenario", "2u1o", "--out", str(run_dir), *options.split())


def test_train_export_eval_round_trip(capsys, tmp_path):
    run_dir = tmp_path / "run"
    code, out, _ = train_2u1o(
        capsys, run_dir, "--steps 40 --envs 4 --eval-every 40 --eval-episodes 4 --json"
    )
    assert code == 0
    summary = json.loads(out)
    assert summary["steps"] == 40
    assert (run_dir / "config.json").is_file() and (run_dir / "best.safetensors").is_file()
    policy_file = tmp_path / "p.safetensors"
    code, out, _ = run(capsys, "export", str(run_dir), "--out", str(policy_file), "--json")
    assert code == 0
    assert json.loads(out)["agents"] == 2
    plot = tmp_path / "e.png"
    args = ["eval", "--policy", str(policy_file), "--episodes", "6", "--plot", str(plot)]
    code, out, _ = run(capsys, *args, "--json")
    assert code == 0
    result = json.loads(out)
    assert result["episodes"] == 6
    assert 0.0 <= result["success_rate"] <= 1.0
    assert result["reaction_time_median_ms"] > 0
    assert plot.read_bytes()[:4] == b"\x89PNG"


def test_eval_refuses_a_policy_for_another_scenario(capsys, tmp_path):
    run_dir = tmp_path / "run"
    train_2u1o(capsys, run_dir, "--steps 5 --envs 2 --eval-episodes 2")
    policy_file = tmp_path / "p.safetensors"
    run(capsys, "export", str(run_dir), "--out", str(policy_file))
    code, _, err = run(capsys, "eval", "--policy", str(policy_file), "--scenario", "3u2o")
    assert code == 2
    assert "number of UAVs" in err


def test_export_of_a_non_run_folder_is_a_clear_error(capsys, tmp_path):
    code, _, err = run(capsys, "export", str(tmp_path), "--out", str(tmp_path / "p.safetensors"))
    assert code == 2
    assert "not a training run folder" in err


def test_train_rejects_unknown_scenario_before_writing(capsys, tmp_path):
    code, _, err = run(capsys, "train", "--scenario", "9u9o", "--out", str(tmp_path / "r"))
    assert code == 2
    assert "unknown scenario" in err
    assert not (tmp_path / "r").exists()


def test_export_rehash_signs_an_old_policy_file(tmp_path, capsys):
    import json as _json

    from safetensors import safe_open
    from safetensors.numpy import load_file, save_file

    from remarl_fc.errors import PolicyError
    from remarl_fc.policy_io import load_policy, zoo_dir

    src = zoo_dir() / "2u1o.safetensors"
    with safe_open(str(src), "np") as f:
        meta = _json.loads(f.metadata()["remarl_policy"])
    meta.pop("checksum")
    old = tmp_path / "old.safetensors"
    save_file(load_file(str(src)), str(old), metadata={"remarl_policy": _json.dumps(meta)})
    with pytest.raises(PolicyError, match="no checksum"):
        load_policy(old)
    assert main(["export", "--rehash", str(old), "--json"]) == 0
    out = _json.loads(capsys.readouterr().out)
    assert out["written"] and out["checksum"].startswith("sha256:")
    assert load_policy(old).agents == 2
    assert main(["export"]) == 2
    assert "give the run folder and --out FILE" in capsys.readouterr().err


def test_a_reader_that_goes_away_is_not_a_traceback():
    import subprocess
    import sys as _sys

    proc = subprocess.Popen(
        [_sys.executable, "-m", "remarl_fc", "scenarios", "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    with proc.stderr:
        proc.stdout.close()  # `| head` that stopped reading
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141, err
    assert "Traceback" not in err


def test_rollout_flies_orca_and_reports_its_metrics(capsys, tmp_path):
    out = tmp_path / "x.png"
    args = ["rollout", "--scenario", "3u2o", "--policy", "orca", "--out", str(out), "--json"]
    code, text, _ = run(capsys, *args)
    assert code == 0
    result = json.loads(text)
    assert result["policy"] == "orca" and result["scenario"] == "3u2o"
    assert result["success"] is True  # ORCA goes round the obstacles (straight does not)
    assert result["collision_u2o"] is False and result["collision_u2u"] is False
    assert result["min_d_u2o_m"] >= 20.0 and result["min_d_u2u_m"] >= 20.0
    assert result["length"] >= 1 and result["energy_rad"] > 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob("*.part"))


def test_rollout_lists_orca_among_its_policies(capsys):
    with pytest.raises(SystemExit):
        main(["rollout", "--help"])
    assert "orca" in capsys.readouterr().out


def test_eval_in_the_worlds_of_real_flight(capsys):
    args = ["eval", "--policy", "3u2o", "--episodes", "4", "--json"]
    assert main([*args, "--dynamics", "px4", "--sensors", "adsb", "--arrival", "leave"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["dynamics"], out["sensors"], out["arrival"]) == ("px4", "adsb", "leave")
    assert not out["dynamics_randomised"] and not out["track_filter"]
    assert main([*args, "--sensors", "adsb", "--track-filter", "on"]) == 0
    assert json.loads(capsys.readouterr().out)["track_filter"] is True
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["dynamics"], out["sensors"], out["arrival"]) == ("ideal", "exact", "hover")
    assert out["shield_settings"]["mode"] == "off"
    assert main([*args, "--shield", "on", "--shield-neighbour-horizon", "3"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["shield"] == "on" and out["shield_settings"]["neighbour_horizon_s"] == 3.0


def test_eval_names_an_unknown_vehicle_profile_and_the_suite_refuses_world_flags(capsys):
    assert main(["eval", "--policy", "3u2o", "--episodes", "2", "--dynamics", "glider"]) == 2
    err = capsys.readouterr().err
    assert "unknown vehicle profile 'glider'" in err and "arducopter" in err
    assert main(["eval", "--suite", "smoke", "--dynamics", "px4"]) == 2
    assert "--dynamics" in capsys.readouterr().err
    assert main(["eval", "--suite", "smoke", "--track-filter", "on"]) == 2
    assert "--track-filter" in capsys.readouterr().err
