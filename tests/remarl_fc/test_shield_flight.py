"""The safety shield in `fly` and `demo`: the controller's wiring of `sim.shield`, the records
of the runtime (decision log, tlog STATUSTEXT, summary), the settings, and a closed-loop flight
on the mock where a policy that ignores traffic would hit an intruder.

The stand-in policy of the flights, `GoToTarget`, turns toward its target at the largest turn
it may and never looks at traffic: on the demo's drawn crossings (`demo --vehicles 1
--intruders 1`), every one of which puts the intruder on the vehicle's route, it flies into
the intruder unless the shield turns it away.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from remarl_fc.cli import main
from remarl_fc.cli.fly import FLY_SHIELD_MODE, _fly_text
from remarl_fc.demo import fly_on_mock
from remarl_fc.flight.config import FLY_SHIELD, FlyConfig
from remarl_fc.flight.control import (
    MIN_REPORT_AGE_S,
    ControlSpec,
    SwarmController,
    SwarmPicture,
    obstacle_picture,
    whereabouts,
)
from remarl_fc.flight.flightlog import read_tlog
from remarl_fc.flight.mission import Mission, VehiclePlan
from remarl_fc.flight.runtime import SwarmRuntime
from remarl_fc.flight.shielding import Check, ShieldTally, checks_of, summary_line, yaw_deg
from remarl_fc.flight.status import Status
from remarl_fc.flight.tracking import STATUSTEXT_MAX_CHARS
from remarl_fc.flight.traffic import TrafficPicture
from remarl_fc.frames import GeoPoint, ne_to_sim, sim_to_ne
from remarl_fc.mavlink.consts import MsgId, Severity
from remarl_fc.policy_io import Policy
from remarl_fc.sitl.config import DEFAULT_HOME
from remarl_fc.sitl.traffic import Traffic
from sim.config import ScenarioConfig
from sim.dynamics import response_values
from sim.observation import ObservationLayout
from sim.scenarios import load_scenario
from sim.shield import BLIND_TRACK_GROWTH_M_S, ShieldConfig, shield_state
from sim.swarm import SwarmSim
from sim.vehicle import load_profile

SPEC = ControlSpec(speed_m_s=10.0, dt_s=2.0, max_turn_rad=math.pi / 4, lead_m=40.0, arrival_m=20.0)
LAYOUT = ObservationLayout(
    max_obstacles=8,
    range_m=100.0,
    aperture_rad=math.radians(270.0),
    speed_m_s=10.0,
    max_neighbours=6,
    version=2,
)
CRUISE_ALT_M = 20.0


class GoToTarget:
    """A generalist-shaped policy that turns toward its target and ignores every other vehicle.

    The first two entries of an observation are the target in the vehicle's heading frame (x
    ahead, y to the left), so the action is the bearing to the target over the turn bound.
    """

    generalist = True
    uav_range = (1, 50)
    source = "go-to-target stand-in"
    checksum = ""  # written by no file
    summary = Policy.summary  # what a flight's summary says of it, as of a loaded file

    def __init__(self) -> None:
        self.layout = LAYOUT
        self.meta: dict[str, Any] = {
            "speed_m_s": SPEC.speed_m_s,
            "dt_s": SPEC.dt_s,
            "d_col_m": SPEC.arrival_m,
            "action": {"max_turn_rad": SPEC.max_turn_rad},
            "scenario_config": {"field": {"swarm_lead_m": SPEC.lead_m}},
        }

    def act(self, obs: NDArray[np.floating[Any]]) -> NDArray[np.float32]:
        o = np.asarray(obs, dtype=np.float64)
        bearing = np.arctan2(o[..., 1], o[..., 0])
        return np.clip(bearing / SPEC.max_turn_rad, -1.0, 1.0).astype(np.float32)

    def check_scenario(self, cfg: ScenarioConfig) -> None:
        """Any number of vehicles."""


# -- the controller ------------------------------------------------------------------------

HEAD_ON = (np.array([[0.0, 150.0]]), np.array([[0.0, -10.0]]))
"""An intruder 150 m east of a vehicle at the origin, flying west at 10 m/s (north/east)."""


def head_on_controller(mode: str, growth: float | None = None) -> SwarmController:
    """One vehicle at the origin, its target 400 m east: straight at `HEAD_ON`'s intruder.

    ``growth``: the shield's track growth (None: its default).
    """
    shield = ShieldConfig(mode=mode)
    if growth is not None:
        shield = replace(shield, track_growth_m_s=growth)
    c = SwarmController(GoToTarget(), SPEC, np.array([[0.0, 400.0]]), shield=shield)
    c.start(np.zeros((1, 2)), 0.0)
    return c


def test_the_shield_turns_a_vehicle_away_from_an_intruder_ahead():
    c = head_on_controller("on")
    d = c.decide(0.0, np.zeros((1, 2)), *HEAD_ON, obstacle_age_s=np.zeros(1))
    assert d.shield is not None and d.flown.tolist() == [True]
    assert d.proposed_action[0] == 0.0  # the policy flies on, straight at it
    assert d.shield.intervened[0, 0] and d.shield.safe_exists[0, 0]
    assert d.action[0] != 0.0 and d.turn_rad[0] == pytest.approx(d.action[0] * SPEC.max_turn_rad)
    assert d.shield.proposed_cpa_m[0, 0] < SPEC.arrival_m < d.shield.flown_cpa_m[0, 0]
    # the arc flown is the shield's
    assert c.turn[0] == d.turn_rad[0] and c.speed_m_s[0] == d.speed_m_s[0]


def test_in_monitor_mode_the_proposal_is_flown_and_the_shields_choice_recorded():
    c = head_on_controller("monitor")
    d = c.decide(0.0, np.zeros((1, 2)), *HEAD_ON)
    assert d.shield is not None and d.shield.intervened[0, 0]
    assert d.action[0] == d.proposed_action[0] == 0.0 and c.turn[0] == 0.0
    assert d.speed_m_s[0] == SPEC.speed_m_s
    assert d.shield.shield_action[0, 0] != 0.0


def test_off_computes_nothing():
    c = head_on_controller("off")
    d = c.decide(0.0, np.zeros((1, 2)), *HEAD_ON)
    assert d.shield is None and d.action[0] == d.proposed_action[0] == 0.0


@pytest.mark.parametrize("growth", [ShieldConfig().track_growth_m_s, BLIND_TRACK_GROWTH_M_S])
def test_an_old_report_widens_the_clearance_the_shield_keeps(growth):
    """An intruder passing abeam in 7.5 s, 1 m more than d_col + margin + the uncertainty of a
    fresh report over the track look-ahead (21 + G × 10 + 1 m: 37 m at the default growth G
    of 1.5 m/s, 27 m behind a policy blind to its neighbours; a segment of the prediction
    requires what its end does, and 7.5 s lies in the last, to 10 s): clear of it; a 10 s old
    report adds G × 10 s more, and the shield acts."""
    cfg = ShieldConfig()
    abeam = SPEC.arrival_m + cfg.margin_m + growth * cfg.track_horizon_s + 1.0
    passing = (np.array([[abeam, 150.0]]), np.array([[0.0, -10.0]]))
    decided = []
    for age in (MIN_REPORT_AGE_S, 10.0):
        c = head_on_controller("on", growth)
        decided.append(c.decide(0.0, np.zeros((1, 2)), *passing, obstacle_age_s=np.array([age])))
    fresh, old = decided
    assert fresh.shield is not None and old.shield is not None
    assert not fresh.shield.intervened[0, 0] and old.shield.intervened[0, 0]


def test_only_the_vehicles_flown_here_are_decided_and_the_others_are_kept_clear_of():
    """Vehicle 0 flies here; vehicle 1 (a peer's, 60 m ahead flying west at 10 m/s straight at
    it per its telemetry) is not decided for, but the shield keeps vehicle 0 clear of it."""
    c = SwarmController(
        GoToTarget(), SPEC, np.array([[0.0, 400.0], [0.0, -400.0]]), shield=ShieldConfig("on")
    )
    positions = np.array([[0.0, 0.0], [0.0, 60.0]])
    c.start(positions, 0.0)
    peer = SwarmPicture(
        present=np.array([True, True]),
        on_arc=np.array([True, False]),
        heading_known=np.array([True, False]),
        vel_ne_m_s=np.array([[0.0, 0.0], [0.0, -10.0]]),
    )
    d = c.decide(0.0, positions, np.zeros((0, 2)), np.zeros((0, 2)), swarm=peer)
    assert d.shield is not None and d.flown.tolist() == [True, False]
    assert d.shield.intervened[0].tolist() == [True, False]
    assert d.action[1] == d.proposed_action[1]


def test_the_controller_shields_as_the_simulator_adapter_does():
    """Given a simulator state, the controller's shield decides what `shield_state` decides.

    3u2o flown toward the targets, traffic ignored, until the shield first intervenes; there
    the controller, on the simulator's headings, positions and visible obstacles, proposes the
    same actions and shields them the same way.
    """
    cfg = load_scenario("3u2o")
    sim = SwarmSim(cfg)
    rng = np.random.default_rng(0)
    state = sim.initial_state(rng, 1)
    policy = GoToTarget()
    policy.layout = sim.obs_layout  # the scenario's observation, version 1
    spec = replace(SPEC, lead_m=cfg.field.swarm_lead_m)
    shield = ShieldConfig(mode="on")
    for _ in range(cfg.max_steps):
        proposed = policy.act(sim.observe(state).flat())
        expected = shield_state(shield, cfg, state, proposed, spec.shield_vehicle())
        if expected.intervened.any():
            break
        state, _ = sim.step(state, proposed, rng)
    assert expected.intervened.any() and state.active.all()
    now = float(state.steps[0]) * cfg.dt_s
    c = SwarmController(policy, spec, sim_to_ne(state.target_m[0]), shield=shield)
    c.start(sim_to_ne(state.pos_m[0]), 0.0)
    c.h0, c.t0[:] = state.heading_rad[0].copy(), now
    visible = state.obstacle_visible[0]
    d = c.decide(
        now,
        sim_to_ne(state.pos_m[0] + state.gps_error_m[0]),
        sim_to_ne(state.obstacle_pos_m[0][visible]),
        sim_to_ne(state.obstacle_vel_m_s[0][visible]),
    )
    assert d.shield is not None
    np.testing.assert_allclose(d.proposed_action, proposed[0], atol=1e-6)
    np.testing.assert_array_equal(d.shield.intervened, expected.intervened)
    np.testing.assert_allclose(d.action, expected.action[0], atol=1e-6)
    np.testing.assert_allclose(d.speed_m_s, expected.speed_m_s[0])
    np.testing.assert_allclose(d.shield.proposed_cpa_m, expected.proposed_cpa_m, rtol=1e-6)
    np.testing.assert_allclose(d.shield.flown_cpa_m, expected.flown_cpa_m, rtol=1e-6)


def test_with_fitted_vehicles_the_controller_predicts_as_the_simulator_does():
    """3u2o flown by fitted ArduCopters, each vehicle then still turning out of a hard turn
    the other way: the controller told the vehicles' profile, their telemetry's
    velocities and the arcs in force decides the same; told nothing of the profile, or with
    ``vehicle_model`` "ideal", it predicts the arcs as commanded, as the simulator's adapter
    then does."""
    cfg = load_scenario("3u2o", dynamics="arducopter")
    sim = SwarmSim(cfg)
    rng = np.random.default_rng(0)
    state = sim.initial_state(rng, 1)
    policy = GoToTarget()
    policy.layout = sim.obs_layout
    spec = replace(SPEC, lead_m=cfg.field.swarm_lead_m)
    shield = ShieldConfig(mode="on")
    for _ in range(3):
        state, _ = sim.step(state, policy.act(sim.observe(state).flat()), rng)
    # each vehicle still turning out of a hard turn the other way, 25° off its new heading
    last = np.array([[0.6, -0.6, 0.6]])
    tilt = np.exp(1j * np.deg2rad(25.0) * np.sign(last[0]))
    v = (state.vel_m_s[0, :, 0] + 1j * state.vel_m_s[0, :, 1]) * tilt
    state = replace(state, vel_m_s=np.stack([v.real, v.imag], axis=-1)[None], last_turn_rad=last)
    proposed = policy.act(sim.observe(state).flat())
    expected = shield_state(shield, cfg, state, proposed, spec.shield_vehicle())
    now = float(state.steps[0]) * cfg.dt_s
    visible = state.obstacle_visible[0]
    picture = SwarmPicture.everyone(3)
    picture = replace(picture, vel_ne_m_s=sim_to_ne(state.vel_m_s[0]))

    def decide(controller_shield: ShieldConfig, profiles: bool) -> Any:
        c = SwarmController(policy, spec, sim_to_ne(state.target_m[0]), shield=controller_shield)
        c.start(sim_to_ne(state.pos_m[0]), 0.0)
        c.h0, c.t0[:] = state.heading_rad[0].copy(), now
        c.turn, c.speed_m_s = state.last_turn_rad[0].copy(), state.speed_m_s[0].copy()
        c.h0 = c.h0 - c.turn  # the arc in force ends on the state's heading
        c.t0[:] = now - cfg.dt_s
        if profiles:
            c.use_profiles([load_profile("arducopter")] * 3)
        return c.decide(
            now,
            sim_to_ne(state.pos_m[0] + state.gps_error_m[0]),
            sim_to_ne(state.obstacle_pos_m[0][visible]),
            sim_to_ne(state.obstacle_vel_m_s[0][visible]),
            swarm=picture,
        )

    d = decide(shield, profiles=True)
    assert d.shield is not None
    np.testing.assert_array_equal(d.shield.intervened, expected.intervened)
    np.testing.assert_allclose(d.action, expected.action[0], atol=1e-6)
    np.testing.assert_allclose(d.speed_m_s, expected.speed_m_s[0])
    np.testing.assert_allclose(d.shield.proposed_cpa_m, expected.proposed_cpa_m, rtol=1e-5)
    ideal = replace(shield, vehicle_model="ideal")
    arcs = shield_state(ideal, cfg, state, proposed, spec.shield_vehicle())
    for told in (decide(shield, profiles=False), decide(ideal, profiles=True)):
        assert told.shield is not None
        np.testing.assert_allclose(told.shield.proposed_cpa_m, arcs.proposed_cpa_m, rtol=1e-5)
    assert not np.allclose(arcs.proposed_cpa_m, expected.proposed_cpa_m)
    assert np.isfinite(expected.proposed_cpa_m).any()


def test_the_obstacle_picture_gives_each_reports_age():
    origin = GeoPoint(47.0, 8.0, 500.0)
    traffic = TrafficPicture(origin)
    intruders = Traffic(ne_to_sim(HEAD_ON[0]), ne_to_sim(HEAD_ON[1]), CRUISE_ALT_M, start_s=0.0)
    from remarl_fc.mavlink.codec import Codec

    (msg,) = intruders.reports(Codec(1, 1).factory, origin, 0.0)
    msg.tslc = 2  # the receiver last heard it 2 s before
    assert traffic.update(msg, 10.0, source=(1, 1))
    mission = Mission(origin, 10.0, (VehiclePlan(1, 0, (0.0, 400.0), CRUISE_ALT_M),))
    runtime = SwarmRuntime(FlyConfig(("udpin:127.0.0.1:0",), mission), GoToTarget(), SPEC)
    m = runtime.members[0]
    m.track.ne_m, m.track.height_m, m.track.t_position = np.zeros(2), CRUISE_ALT_M, 10.0
    rows = [(m, Status.CONTROLLED)]
    response = np.array([response_values(load_profile("arducopter"))])
    seen = obstacle_picture(traffic, rows, whereabouts(rows, response, 11.0), 11.0, 50.0)
    np.testing.assert_allclose(seen.age_s, [3.0])
    np.testing.assert_allclose(seen.ne_m, HEAD_ON[0] + 3.0 * HEAD_ON[1], atol=0.5)


# -- the records ---------------------------------------------------------------------------


def check(**changes: Any) -> Check:
    base = Check(
        t=12.0, system_id=3, mode="on", intervened=True, safe_exists=True, proposed_deg=90.0,
        flown_deg=135.0, shield_deg=135.0, flown_speed_m_s=10.0, shield_speed_m_s=10.0,
        proposed_cpa_m=12.4, flown_cpa_m=25.2, shield_cpa_m=25.2, proposed_action=0.0,
    )  # fmt: skip
    return replace(base, **changes)


def test_statustexts_are_short_and_say_would_in_monitor_mode():
    assert check().text(10.0) == "SHIELD v3 hdg 090->135 cpa 12->25m"
    assert check().severity() == Severity.NOTICE
    monitor = check(mode="monitor", flown_deg=90.0, flown_cpa_m=12.4)
    assert monitor.text(10.0) == "SHIELD would v3 hdg 090->135 cpa 12->25m"
    worst = check(
        mode="monitor", system_id=255, safe_exists=False, shield_speed_m_s=0.0,
        proposed_cpa_m=1e6, shield_cpa_m=math.inf,
    )  # fmt: skip
    assert worst.text(10.0) == "SHIELD would v255 hdg 090->135 0m/s cpa 9999->-m!"
    assert len(worst.text(10.0)) <= STATUSTEXT_MAX_CHARS and worst.severity() == Severity.WARNING
    assert "would turn" in monitor.console() and "turned" in check().console()


def test_log_fields_are_json_with_no_infinity():
    fields = check(flown_cpa_m=math.inf, shield_cpa_m=math.inf).fields()
    assert json.loads(json.dumps(fields)) == fields
    assert fields["flown_cpa_m"] is None and fields["proposed_cpa_m"] == 12.4
    assert fields["proposed_heading_deg"] == 90.0 and fields["flown_heading_deg"] == 135.0


def test_yaw_degrees_follow_the_ned_convention():
    assert yaw_deg(0.0) == 90.0  # east
    assert yaw_deg(math.pi / 2) == 0.0  # north
    assert yaw_deg(-math.pi / 2) == 180.0
    assert yaw_deg(math.pi) == 270.0


def test_the_tally_counts_per_vehicle_decision():
    tally = ShieldTally("on")
    tally.add([check(), check(system_id=4, intervened=False)])
    tally.add([check(safe_exists=False), check(system_id=4, intervened=False)])
    got = tally.summary([3, 4])
    assert got == {
        "mode": "on", "decisions": 4, "interventions": 2, "intervention_rate": 0.5,
        "no_safe_option": 1, "by_vehicle": {"3": 2, "4": 0},
    }  # fmt: skip
    assert summary_line(got) == (
        "shield on: intervened in 2 of 4 vehicle decisions (vehicle 3: 2); "
        "1 with no candidate clear"
    )
    assert ShieldTally("off").summary([3]) == {"mode": "off"}


def test_checks_are_the_flown_vehicles_only():
    c = head_on_controller("monitor")
    d = c.decide(0.0, np.zeros((1, 2)), *HEAD_ON)
    (one,) = checks_of(d, [7], SPEC.max_turn_rad, "monitor")
    assert one.system_id == 7 and one.intervened and one.proposed_deg == one.flown_deg == 90.0
    assert one.flown_cpa_m == one.proposed_cpa_m < SPEC.arrival_m < one.shield_cpa_m
    assert checks_of(head_on_controller("off").decide(0.0, np.zeros((1, 2)), *HEAD_ON), [7],
                     SPEC.max_turn_rad, "off") == []  # fmt: skip


# -- the runtime's records -----------------------------------------------------------------


async def decide_head_on(mode: str, log_dir: Path) -> dict[str, Any]:
    """Three decisions of a runtime (dry run, no vehicle) flying one vehicle straight at an
    ADS-B intruder; returns its summary, decision rows and our STATUSTEXTs in the tlog."""
    origin = DEFAULT_HOME
    mission = Mission(origin, 10.0, (VehiclePlan(1, 0, (0.0, 400.0), CRUISE_ALT_M),), 2.0)
    cfg = FlyConfig(
        ("udpin:127.0.0.1:0",), mission, dry_run=True, log_dir=log_dir,
        shield=ShieldConfig(mode=mode),
    )  # fmt: skip
    printed: list[str] = []
    runtime = SwarmRuntime(cfg, GoToTarget(), SPEC, on_status=printed.append)
    intruders = Traffic(ne_to_sim(HEAD_ON[0]), ne_to_sim(HEAD_ON[1]), CRUISE_ALT_M, start_s=0.0)
    async with runtime:
        m = runtime.members[0]
        runtime.vehicles[1] = replace(runtime.vehicles[1], status=Status.CONTROLLED)
        runtime.controller.start(np.zeros((1, 2)), 0.0)
        for k in range(3):
            now = 2.0 * k
            m.track.ne_m = np.array([0.0, 10.0 * now])
            m.track.height_m, m.track.t_position = CRUISE_ALT_M, now
            m.track.vel_ned_m_s = np.array([0.0, 10.0, 0.0])
            for msg in intruders.reports(runtime.codec.factory, origin, now):
                assert runtime.traffic.update(msg, now, source=(1, 1))
            runtime.decide(now)
    rows = [json.loads(x) for x in (log_dir / "decisions.jsonl").read_text().splitlines()[1:]]
    texts = [
        (int(msg.severity), msg.text)
        for _, msg in read_tlog(log_dir / "flight.tlog")
        if msg.get_msgId() == MsgId.STATUSTEXT and msg.get_srcSystem() == cfg.system_id
    ]
    return {
        "summary": runtime.summary(),
        "rows": [r for r in rows if "action" in r],
        "texts": texts,
        "printed": printed,
    }


@pytest.mark.asyncio
async def test_the_runtime_records_every_intervention(tmp_path):
    got = await decide_head_on("on", tmp_path)
    rows, shield = got["rows"], got["summary"]["shield"]
    assert len(rows) == 3 and all("shield" in r for r in rows)
    hit = [r for r in rows if r["shield"]["intervened"]]
    assert hit, rows
    first = hit[0]["shield"]
    assert first["mode"] == "on" and first["proposed_heading_deg"] == 90.0
    assert first["flown_heading_deg"] != 90.0 == first["proposed_heading_deg"]
    assert first["flown_heading_deg"] == first["shield_heading_deg"]
    assert first["proposed_cpa_m"] < 20.0 < first["flown_cpa_m"]
    assert hit[0]["action"] == pytest.approx(hit[0]["turn_rad"] / SPEC.max_turn_rad, abs=1e-3)
    assert shield["mode"] == "on" and shield["decisions"] == 3
    assert shield["interventions"] == len(hit) == shield["by_vehicle"]["1"]
    assert len(got["texts"]) == len(hit)
    severity, text = got["texts"][0]
    assert text.startswith("SHIELD v1 hdg 090->") and severity == Severity.NOTICE
    assert len(text) <= STATUSTEXT_MAX_CHARS
    assert any("shield turned heading 090.0 ->" in line for line in got["printed"])
    assert "shield on: intervened in" in _fly_text(got["summary"])


@pytest.mark.asyncio
async def test_in_monitor_mode_the_runtime_records_what_the_shield_would_do(tmp_path):
    got = await decide_head_on("monitor", tmp_path)
    rows, shield = got["rows"], got["summary"]["shield"]
    hit = [r for r in rows if r["shield"]["intervened"]]
    assert hit and shield["mode"] == "monitor" and shield["interventions"] == len(hit)
    for r in rows:  # the proposal is flown: the policy flies on east, straight at it
        assert r["shield"]["flown_heading_deg"] == r["shield"]["proposed_heading_deg"] == 90.0
        assert r["action"] == 0.0
    assert hit[0]["shield"]["shield_heading_deg"] != 90.0
    assert all(text.startswith("SHIELD would v1 ") for _, text in got["texts"])
    assert len(got["texts"]) == len(hit)
    assert "would have intervened" in _fly_text(got["summary"])


@pytest.mark.asyncio
async def test_with_the_shield_off_nothing_is_computed_or_logged(tmp_path):
    got = await decide_head_on("off", tmp_path)
    assert len(got["rows"]) == 3 and not any("shield" in r for r in got["rows"])
    assert got["texts"] == [] and got["summary"]["shield"] == {"mode": "off"}
    assert not any("shield" in line for line in got["printed"])


# -- the settings --------------------------------------------------------------------------


def test_fly_and_demo_default_to_the_shield_on():
    assert FLY_SHIELD_MODE == FLY_SHIELD.mode == "on"
    mission = Mission(GeoPoint(47.0, 8.0, 500.0), 10.0, (VehiclePlan(1, 0, (0.0, 1.0), 20.0),))
    assert FlyConfig(("udpin:127.0.0.1:0",), mission).shield == FLY_SHIELD
    assert FLY_SHIELD.horizon_s == ShieldConfig().horizon_s  # one default of each setting


@pytest.mark.parametrize("command", ["fly", "demo"])
def test_bad_shield_settings_are_refused(command, capsys):
    base = ["fly", "--connection", "udpin:127.0.0.1:0", "--policy", "3u2o", "--mission",
            "docs/examples/mission-3u2o.toml"] if command == "fly" else ["demo"]  # fmt: skip
    assert main([*base, "--shield-horizon", "-1"]) == 2
    assert "--shield" in capsys.readouterr().err
    assert main([*base, "--shield-neighbour-horizon", "nan"]) == 2
    assert "neighbour_horizon_s" in capsys.readouterr().err
    assert main([*base, "--shield-track-growth", "-1"]) == 2
    assert "track_growth_m_s" in capsys.readouterr().err
    assert main([*base, "--shield-passes", "0"]) == 2
    assert "passes must be >= 1" in capsys.readouterr().err
    assert main([*base, "--shield-escape-steps", "5"]) == 2
    assert "escape_steps must be 1 to 4" in capsys.readouterr().err
    assert main([*base, "--shield-return", "0"]) == 2
    assert "return_deg must be in (0, 180]" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*base, "--shield", "sometimes"])
    with pytest.raises(SystemExit):
        main([*base, "--shield-neighbours", "guess"])
    with pytest.raises(SystemExit):
        main([*base, "--shield-fly-out", "sometimes"])


def test_the_shield_flags_build_its_config():
    from remarl_fc.cli import build_parser
    from remarl_fc.cli.common import shield_from_args

    args = build_parser().parse_args(["demo", "--shield-neighbours", "straight"])
    assert shield_from_args(args).neighbour_arcs == "straight"
    for command in ("demo", "eval"):
        args = build_parser().parse_args([command, "--shield-neighbour-horizon", "6"])
        assert shield_from_args(args).neighbour_horizon_s == 6.0
        args = build_parser().parse_args([command, "--shield-track-growth", "0.7"])
        assert shield_from_args(args).track_growth_m_s == 0.7
        assert shield_from_args(args, sees_neighbours=False).track_growth_m_s == 0.7
        args = build_parser().parse_args([command])
        assert shield_from_args(args).track_growth_m_s == ShieldConfig().track_growth_m_s
        blind = shield_from_args(args, sees_neighbours=False)
        assert blind.track_growth_m_s == BLIND_TRACK_GROWTH_M_S
        args = build_parser().parse_args([command, "--shield-escape-steps", "1"])
        assert shield_from_args(args).escape_steps == 1
        args = build_parser().parse_args([command, "--shield-return", "180"])
        assert shield_from_args(args).return_deg == 180.0
        args = build_parser().parse_args([command, "--shield-fly-out", "off"])
        assert shield_from_args(args).fly_out is False
    assert shield_from_args(build_parser().parse_args(["demo"])) == ShieldConfig(mode="on")
    # the swarm planner: the simulator's evaluation alone applies it, and alone offers the flag
    args = build_parser().parse_args(["eval", "--shield-plan-steps", "0"])
    assert shield_from_args(args).plan_steps == 0
    assert shield_from_args(build_parser().parse_args(["eval"])).plan_steps == 8


@pytest.mark.parametrize("command", ["fly", "demo"])
def test_fly_and_demo_offer_no_swarm_planner(command, capsys):
    from remarl_fc.cli import build_parser

    base = ["fly", "--connection", "udpin:127.0.0.1:0", "--policy", "3u2o", "--mission",
            "docs/examples/mission-3u2o.toml"] if command == "fly" else ["demo"]  # fmt: skip
    build_parser().parse_args(base)
    with pytest.raises(SystemExit):
        build_parser().parse_args([*base, "--shield-plan-steps", "0"])
    assert "unrecognized arguments: --shield-plan-steps" in capsys.readouterr().err


def test_a_negative_plan_steps_is_refused(capsys):
    assert main(["eval", "--policy", "3u2o", "--shield", "on", "--shield-plan-steps", "-1"]) == 2
    assert "plan_steps must be >= 0" in capsys.readouterr().err


# -- closed loop on the mock ---------------------------------------------------------------

SEED = 9
"""`demo --vehicles 1 --intruders 1 --seed 9`: flown straight, the intruder passes 0.5 m from
the vehicle's route (the drawn crossing's geometry)."""


def use_go_to_target(monkeypatch: pytest.MonkeyPatch) -> None:
    import remarl_fc.demo

    real = remarl_fc.demo.load_policy
    monkeypatch.setattr(
        remarl_fc.demo, "load_policy", lambda name: GoToTarget() if name == "go" else real(name)
    )


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.timeout(180)
async def test_a_policy_that_ignores_traffic_keeps_separation_behind_the_shield(monkeypatch):
    """Against the mock's ground truth: without the shield the vehicle flies through the
    intruder (closer than d_col); with it, it stays d_col clear and still reaches its target."""
    use_go_to_target(monkeypatch)
    flights = {}
    for mode in ("off", "on"):
        flights[mode] = await fly_on_mock(
            policy="go", vehicles=1, intruders=1, seed=SEED, speedup=4.0, quick_start=True,
            shield=ShieldConfig(mode=mode),
        )  # fmt: skip
    off, on = flights["off"].ground_truth, flights["on"].ground_truth
    assert off["collisions_vehicle_intruder"] >= 1, off
    assert off["min_vehicle_intruder_m"] < off["d_col_m"]
    assert on["collisions_vehicle_intruder"] == 0, on
    assert on["min_vehicle_intruder_m"] >= on["d_col_m"], on
    assert on["reached_targets"] == 1
    shield = flights["on"].runtime["shield"]
    assert shield["mode"] == "on" and shield["by_vehicle"]["1"] == shield["interventions"] >= 1
    assert flights["off"].runtime["shield"] == {"mode": "off"}
    # the mock's ArduPilot answered: the shield predicted the vehicle with ArduCopter's fit

    def said(flight: Any) -> list[str]:
        return [text for v in flight.runtime["vehicles"] for _, text in v["events"]]

    assert "the shield predicts it with the arducopter response" in said(flights["on"])
    assert not any("predicts" in text for text in said(flights["off"]))
