"""``remarl-fc fly`` and ``plot-flight`` end to end: the mock in another process, real UDP."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from remarl_fc.cli import main
from remarl_fc.demo import free_udp_port
from sim.shield import ShieldConfig

pytestmark = [pytest.mark.network, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "docs" / "examples" / "mission-3u2o.toml"


def test_fly_the_example_mission_on_a_mock_in_another_process(tmp_path, capsys):
    port = free_udp_port()
    truth_file = tmp_path / "truth.json"
    mock = subprocess.Popen(
        [sys.executable, "-m", "remarl_fc", "sitl", "--quick-start", "--scenario", "3u2o",
         "--base-port", "0", "--out", f"127.0.0.1:{port}", "--speedup", "4", "--timeout", "200",
         "--summary", str(truth_file), "--json"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )  # fmt: skip
    try:  # no --policy: the shipped generalist, fly's default
        status = main(
            ["fly", "--connection", f"udpin:127.0.0.1:{port}",
             "--mission", str(MISSION), "--takeoff", "--log", str(tmp_path / "log"),
             "--speedup", "4", "--json"]
        )  # fmt: skip
    finally:
        mock.send_signal(signal.SIGINT)
        _, err = mock.communicate(timeout=30)
    summary = json.loads(capsys.readouterr().out)
    assert status == 0, summary
    assert summary["policy"]["name"] == "generalist", summary["policy"]
    assert [v["status"] for v in summary["vehicles"]] == ["reached"] * 3
    truth = json.loads(truth_file.read_text())
    assert truth["collisions_vehicle_intruder"] == 0 == truth["collisions_vehicle_vehicle"]
    assert truth["reached_targets"] == 3, err
    assert (
        main(["plot-flight", str(tmp_path / "log"), "--out", str(tmp_path / "f.png"), "--json"])
        == 0
    )
    plot = json.loads(capsys.readouterr().out)
    assert plot["vehicles"] == [1, 2, 3] and plot["intruders"] == 2
    assert plot["min_distance_to_intruder_m"] >= truth["d_col_m"] - 1.0
    assert (tmp_path / "f.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--policy", "5u2o", "--mission", str(MISSION)],
            "number of vehicles: this policy flies 5 vehicles; the mission has 3: use a "
            "generalist policy (--policy generalist) or a mission of 5",
        ),
        (["--policy", "3u2o", "--mission", "missing.toml"], "cannot read the file"),
        (["--policy", "nope", "--mission", str(MISSION)], "nope"),
        (["--policy", "3u2o", "--mission", str(MISSION), "--setpoint-hz", "2"], "10 Hz"),
        (
            ["--mission", str(MISSION), "--vehicle-profile", "bogus"],
            "unknown vehicle profile 'bogus'; shipped: arducopter",
        ),
    ],
)
def test_fly_refuses_what_cannot_be_flown(args, message, capsys):
    assert main(["fly", "--connection", "udpin:127.0.0.1:0", *args]) == 2
    assert message in capsys.readouterr().err


def test_fly_takes_any_mission_size_in_a_generalists_range(tmp_path, capsys):
    from tiny_policy import write_tiny_generalist

    args = ["fly", "--connection", "bogus", "--mission", str(MISSION), "--policy"]
    anyone = write_tiny_generalist(tmp_path / "g.safetensors")
    assert main([*args, str(anyone)]) == 2
    assert "udpin:HOST:PORT" in capsys.readouterr().err  # refused later: the mission fits
    four = write_tiny_generalist(tmp_path / "g4.safetensors", scenario="5u2o", uavs=(4, 50))
    assert main([*args, str(four)]) == 2
    err = capsys.readouterr().err
    assert "this policy flies 4 to 50 vehicles; the mission has 3: give it at least 4" in err


def test_bad_connection_and_bad_log_folder(capsys, tmp_path):
    args = ["fly", "--connection", "bogus", "--policy", "3u2o", "--mission", str(MISSION)]
    assert main(args) == 2
    assert "udpin:HOST:PORT" in capsys.readouterr().err
    assert main(["plot-flight", str(tmp_path)]) == 2
    assert "not a flight log folder" in capsys.readouterr().err


def test_demo_command(tmp_path, capsys):
    out = tmp_path / "flight.png"
    args = ["demo", "--speedup", "4", "--out", str(out), "--summary", str(tmp_path / "t.json")]
    assert main([*args, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["ground_truth"]["reached_targets"] == 3
    assert result["plot"]["intruders"] == 2 and out.stat().st_size > 10_000
    assert json.loads((tmp_path / "t.json").read_text())["finished"] is True
    # the generalist sees its neighbours: the shield's default track growth behind it
    settings = result["runtime"]["shield_settings"]
    assert settings["mode"] == "on"
    assert settings["track_growth_m_s"] == ShieldConfig().track_growth_m_s


def test_demo_with_noisy_adsb_and_filtered_tracks(tmp_path, capsys):
    args = ["demo", "--speedup", "4", "--out", str(tmp_path / "f.png"), "--json"]
    assert main([*args, "--adsb-noise", "--track-filter", "on"]) in (0, 4)
    result = json.loads(capsys.readouterr().out)
    assert result["ground_truth"]["adsb_noise"] is True
    assert result["runtime"]["traffic"]["filtered"] is True


def test_the_summary_names_the_policy_flown():
    from remarl_fc.cli.fly import policy_line
    from remarl_fc.policy_io import load_policy

    shipped = load_policy("generalist").summary()
    assert shipped["name"] == "generalist" and shipped["generalist"] is True
    assert shipped["checksum"].startswith("sha256:") and shipped["vehicles"] == [1, 50]
    line = policy_line(shipped)
    assert line.startswith("policy generalist (1 to 50 vehicles, sha256:") and line.endswith(")")
    scenario = load_policy("3u2o").summary()
    assert scenario["vehicles"] == [3, 3] and scenario["generalist"] is False
    assert policy_line(scenario).startswith("policy 3u2o (3 vehicles, sha256:")
    assert "no checksum" in policy_line({**scenario, "checksum": ""})
