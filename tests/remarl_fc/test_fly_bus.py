"""One `fly` process per vehicle over a real mosquitto, against the mock in its own process."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from remarl_fc.demo import free_udp_port
from remarl_fc.policy_io import load_policy
from sim.observation import NEIGHBOUR_COLUMNS
from sim.shield import BLIND_TRACK_GROWTH_M_S, ShieldConfig

pytestmark = [pytest.mark.network, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "docs" / "examples" / "mission-3u2o.toml"
CLI = [sys.executable, "-m", "remarl_fc"]


def consecutive_udp_ports(n: int) -> int:
    """A first port such that it and the next n − 1 are free now."""
    for _ in range(50):
        first = free_udp_port()
        if all(_free(first + k) for k in range(n)):
            return first
    raise RuntimeError("no run of free UDP ports")


def _free(port: int) -> bool:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def wait_for_logs(logs, done, what: str, timeout_s: float = 120.0) -> None:
    """Poll the fly processes' decision logs until ``done(k, text)`` holds for each log k."""
    deadline = time.monotonic() + timeout_s
    pending = list(enumerate(logs))
    while pending:
        pending = [(k, p) for k, p in pending if not (p.exists() and done(k, p.read_text()))]
        if pending and time.monotonic() > deadline:
            raise AssertionError(f"{what}: not seen in {pending} after {timeout_s:g} s")
        time.sleep(0.05)


def fly_swarm(
    tmp_path: Path, broker, speedup: float, outage=None, policy: str = "3u2o"
) -> tuple[list, dict]:
    """Three fly processes, one mock; returns (their summaries, the mock's ground truth)."""
    port = consecutive_udp_ports(3)
    truth = tmp_path / "truth.json"
    mock = subprocess.Popen(
        [*CLI, "sitl", "--quick-start", "--scenario", "3u2o", "--base-port", "0",
         "--out", f"127.0.0.1:{port}", "--out-step", "1", "--speedup", str(speedup),
         "--timeout", "600", "--summary", str(truth), "--json"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    flyers = [
        subprocess.Popen(
            [
                *CLI,
                "fly",
                "--connection",
                f"udpin:127.0.0.1:{port + i}",
                "--policy",
                policy,
                "--mission",
                str(MISSION),
                "--takeoff",
                "20",
                "--vehicle",
                str(i + 1),
                "--bus",
                broker.url,
                "--swarm",
                "ci",
                "--speedup",
                str(speedup),
                "--json",
                "--log",
                str(tmp_path / f"log{i + 1}"),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        for i in range(3)
    ]
    try:
        if outage is not None:
            outage(broker)
        outs = [p.communicate(timeout=240) for p in flyers]
    finally:
        for p in flyers:
            if p.poll() is None:
                p.kill()
                p.communicate()
        mock.send_signal(signal.SIGINT)
        mock.communicate(timeout=30)
    summaries = []
    for p, (out, err) in zip(flyers, outs, strict=True):
        assert p.returncode == 0, err.decode()[-3000:]
        summaries.append(json.loads(out))
    return summaries, json.loads(truth.read_text())


@pytest.mark.parametrize("policy", ["3u2o", "generalist"])
def test_three_processes_fly_the_swarm_over_mqtt(tmp_path, mosquitto, policy):
    summaries, truth = fly_swarm(tmp_path, mosquitto, speedup=4.0, policy=policy)
    for k, s in enumerate(summaries):
        mine = [v for v in s["vehicles"] if v["local"]]
        assert [v["system_id"] for v in mine] == [k + 1]
        assert mine[0]["status"] == "reached"
        assert s["bus"]["accepted"] > 50  # it heard its peers
        assert not s["bus"]["rejected"]
    assert truth["reached_targets"] == 3
    assert truth["collisions_vehicle_intruder"] == 0 == truth["collisions_vehicle_vehicle"]
    assert truth["min_vehicle_intruder_m"] >= truth["d_col_m"]
    # the track growth follows what the policy sees: the zoo's 3u2o is blind to its neighbours
    growth = BLIND_TRACK_GROWTH_M_S if policy == "3u2o" else ShieldConfig().track_growth_m_s
    assert all(s["shield_settings"]["track_growth_m_s"] == growth for s in summaries)
    if policy == "generalist":  # its neighbour rows: the peers' headings, from their arcs
        assert peers_headings_known(tmp_path / "log1" / "decisions.jsonl")


def peers_headings_known(log: Path) -> bool:
    """Whether vehicle 1's first decision sees a neighbour and knows each one's heading (its
    neighbours are all other processes' vehicles: known only from the arcs on the bus)."""
    layout = load_policy("generalist").layout
    blocks = layout.blocks()
    for line in log.read_text().splitlines():
        row = json.loads(line)
        if "obs" not in row or row["system_id"] != 1:
            continue
        obs = np.array(row["obs"], dtype=np.float32)
        mask = obs[blocks["neighbour_mask"]] > 0
        rows = obs[blocks["neighbours"]].reshape(layout.max_neighbours, NEIGHBOUR_COLUMNS)
        return bool(mask.any() and (rows[mask, -1] == 1.0).all())
    raise AssertionError(f"no decision of vehicle 1 in {log}")


def test_broker_outage_mid_flight(tmp_path, mosquitto):
    speedup = 4.0

    def outage(broker) -> None:
        logs = [tmp_path / f"log{i}" / "decisions.jsonl" for i in (1, 2, 3)]
        wait_for_logs(logs, lambda k, text: '"under control"' in text, "every vehicle controlled")
        rows = [log.read_text().count('"action"') for log in logs]
        broker.stop()
        # three decisions (6 s of flight) in every process without a broker
        wait_for_logs(logs, lambda k, text: text.count('"action"') >= rows[k] + 3 * 3, "decisions")
        broker.start()

    summaries, truth = fly_swarm(tmp_path, mosquitto, speedup=speedup, outage=outage)
    assert all(s["bus"]["reconnects"] >= 1 for s in summaries)
    assert truth["collisions_vehicle_intruder"] == 0 == truth["collisions_vehicle_vehicle"]
    assert truth["reached_targets"] == 3
