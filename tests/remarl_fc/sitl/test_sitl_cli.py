"""``remarl-fc sitl`` and ``remarl-fc bench sitl`` from the command line (in-process)."""

from __future__ import annotations

import json

import pytest

from remarl_fc.cli import main

pytestmark = [pytest.mark.network, pytest.mark.timeout(120)]


def test_sitl_scenario_runs_and_writes_the_ground_truth(tmp_path, capsys):
    out = tmp_path / "summary.json"
    args = ["sitl", "--scenario", "3u2o", "--base-port", "0", "--speedup", "50"]
    status = main([*args, "--timeout", "4", "--summary", str(out), "--json"])
    assert status == 0
    printed = json.loads(capsys.readouterr().out)
    written = json.loads(out.read_text())
    assert printed == written
    assert written["scenario"] == "3u2o" and written["intruders"] == 2
    assert len(written["vehicles"]) == 3
    assert written["simulated_s"] == pytest.approx(4.0, abs=0.05)
    v = written["vehicles"][0]
    assert v["system_id"] == 1 and v["reached_target"] is False and v["collisions"] == 0
    assert set(v["min_distance_to_intruder_m"]) == {"OBST0000", "OBST0001"}
    assert v["track_t_n_e_up_m"][0][3] == 0.0  # on the ground


def test_until_done_times_out_with_status_3(tmp_path):
    args = ["sitl", "--vehicles", "2", "--base-port", "0", "--speedup", "50"]
    assert main([*args, "--until-done", "--timeout", "2", "--json"]) == 3


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--cut-link", "1:2"], "VEHICLE:START_S:END_S"),
        (["--out", "nowhere"], "HOST:PORT"),
        (["--home", "1,2"], "LAT,LON,ALT"),
        (["--scenario", "3u2o", "--vehicles", "2"], "not allowed with"),
        (["--param", "RTL_ALT"], "NAME=VALUE"),
        (["--param", "RTL_ALT=high"], "NAME=VALUE"),
    ],
)
def test_bad_options_exit_2_with_a_clear_message(extra, message, capsys):
    with pytest.raises(SystemExit) as info:
        main(["sitl", "--base-port", "0", *extra])
    assert info.value.code == 2
    assert message in capsys.readouterr().err


def test_bad_signing_key_and_scenario_exit_2(tmp_path, capsys):
    assert main(["sitl", "--signing-key", str(tmp_path / "missing")]) == 2
    assert "cannot read the key file" in capsys.readouterr().err
    assert main(["sitl", "--scenario", "9u9o"]) == 2
    assert "3u2o" in capsys.readouterr().err  # lists the known scenarios


def test_params_at_start_reach_the_vehicles(tmp_path, capsys):
    out = tmp_path / "summary.json"
    args = ["sitl", "--flavour", "px4", "--vehicles", "2", "--base-port", "0", "--speedup", "50"]
    params = ["--param", "com_obl_rc_act=5", "--param", "MIS_TAKEOFF_ALT=7.5"]
    assert main([*args, *params, "--timeout", "1", "--summary", str(out)]) == 0
    for v in json.loads(out.read_text())["vehicles"]:
        assert v["params"]["COM_OBL_RC_ACT"] == 5 and v["params"]["MIS_TAKEOFF_ALT"] == 7.5
        assert v["params"]["COM_OF_LOSS_T"] == 1.0  # the others keep their defaults
        assert v["params_set"] == {}  # nobody set one over MAVLink


@pytest.mark.parametrize(
    ("flavour", "param", "message"),
    [
        ("ardupilot", "FS_THR_ENABLE=1", "not modelled here; this flavour serves AVD_ENABLE"),
        ("ardupilot", "FS_GCS_ENABLE=1", "FS_GCS_ENABLE=1 not modelled: use 0"),
        ("px4", "RTL_ALT=2500", "COM_DISARM_LAND"),  # ArduPilot's name on PX4
        ("ardupilot", "LAND_SPEED=0", "LAND_SPEED=0 outside"),
        ("px4", "COM_OBL_RC_ACT=6", "not modelled: use 0,3,4,5"),
    ],
)
def test_bad_params_exit_2_naming_what_is_served(flavour, param, message, capsys):
    assert main(["sitl", "--flavour", flavour, "--base-port", "0", "--param", param]) == 2
    assert message in capsys.readouterr().err


def test_tcp_refuses_out_and_serves_tcp(capsys):
    assert main(["sitl", "--tcp", "--out", "127.0.0.1:14540"]) == 2
    assert "--out is for UDP" in capsys.readouterr().err
    args = ["sitl", "--tcp", "--vehicles", "2", "--base-port", "0", "--timeout", "0.5"]
    assert main([*args, "--speedup", "10"]) == 0
    out = capsys.readouterr().out
    assert out.count("(ardupilot): tcp 127.0.0.1:") == 2


def test_busy_port_is_a_clear_error(capsys):
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        assert main(["sitl", "--base-port", str(port), "--timeout", "1"]) == 2
    assert "cannot bind" in capsys.readouterr().err


def test_bench_sitl_json(capsys):
    args = ["bench", "sitl", "--vehicles", "5", "--seconds", "1", "--speedup", "5", "--json"]
    assert main(args) == 0
    result = json.loads(capsys.readouterr().out)
    pos = result["messages"]["GLOBAL_POSITION_INT"]
    assert pos["requested_hz"] == 10.0 and pos["mean_hz"] > 5.0
    assert result["cpu_s_per_simulated_s"] > 0
