"""Closed-loop flights: the runtime flies the shipped policies on the mock fleet.

Every assertion about safety reads the mock's ground truth (what really happened), not the
runtime's own account. The mock and the runtime run 4× faster than real time together.
"""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any

import pytest

from remarl_fc.demo import MockFlight
from remarl_fc.demo import fly_on_mock as demo_flight
from remarl_fc.flight.status import Status
from remarl_fc.mavlink.consts import CopterMode
from remarl_fc.sitl.faults import Faults


def fly_on_mock(*args: Any, **kwargs: Any) -> Coroutine[Any, Any, MockFlight]:
    """The demo's flight with ArduCopter's slow start skipped: these tests are about the flight
    (the start itself: tests/remarl_fc/sitl/test_sitl_start.py)."""
    return demo_flight(*args, quick_start=True, **kwargs)


pytestmark = [pytest.mark.asyncio, pytest.mark.network, pytest.mark.timeout(180)]

SPEEDUP = 4.0


def assert_safe_and_arrived(truth: dict, reached: int | None = None) -> None:
    assert truth["collisions_vehicle_intruder"] == 0
    assert truth["collisions_vehicle_vehicle"] == 0
    assert truth["min_vehicle_intruder_m"] >= truth["d_col_m"]
    assert truth["min_vehicle_vehicle_m"] >= truth["d_col_m"]
    n = len(truth["vehicles"]) if reached is None else reached
    assert truth["reached_targets"] == n


async def flown_for(fleet, runtime, seconds: float) -> None:
    """Wait until the mock's own clock has run ``seconds`` further (not a wall-clock sleep)."""
    t_end = fleet.now_s() + seconds
    await runtime.commands.wait_until(
        f"{seconds:g} s of flight", lambda: fleet.now_s() >= t_end, 120
    )


async def until_controlled(runtime) -> float:
    await runtime.commands.wait_until(
        "control", lambda: all(s == Status.CONTROLLED for s in runtime.statuses()), 120
    )
    return runtime.clock.now()


@pytest.mark.parametrize(
    ("scenario", "flavour"), [("3u2o", "ardupilot"), ("5u2o", "ardupilot"), ("3u2o", "px4")]
)
async def test_shipped_policy_flies_the_mock_to_every_target(scenario, flavour, tmp_path):
    flight = await fly_on_mock(scenario, flavour=flavour, speedup=SPEEDUP, log_dir=tmp_path)
    truth = flight.ground_truth
    assert truth["intruders"] == 2
    assert_safe_and_arrived(truth)
    assert all(v["status"] == "reached" for v in flight.runtime["vehicles"])
    assert all(v["link"]["bad_frames"] == 0 for v in truth["vehicles"])
    # the vehicles were commanded with 2503 setpoints only after take-off, and held at the end
    hold = CopterMode.BRAKE if flavour == "ardupilot" else 0x03040000
    assert all(v["custom_mode"] == hold for v in truth["vehicles"])
    assert (tmp_path / "flight.tlog").stat().st_size > 0
    assert (tmp_path / "decisions.jsonl").read_text().count('"action"') >= 3 * 10
    # the failsafe parameters were read and judged before arming
    events = [e for _, e in flight.runtime["vehicles"][0]["events"]]
    # (every one the mock serves has real firmware's default value)
    if flavour == "ardupilot":
        read = "GUID_TIMEOUT=3, FS_GCS_ENABLE=0, AVD_ENABLE=0, AVD_F_ACTION=1, FENCE_ENABLE=0"
    else:
        read = "COM_OF_LOSS_T=1, COM_OBL_RC_ACT=0, NAV_DLL_ACT=0, COM_RC_IN_MODE=3, GF_ACTION=2"
        assert any(e.startswith("parameter warning: COM_OBL_RC_ACT 0 (Position)") for e in events)
    assert f"parameters: {read}" in events
    assert not any(e.startswith("parameters not read") for e in events)


async def test_lossy_late_link_still_no_collision():
    faults = Faults(loss=0.10, latency_s=0.200)
    flight = await fly_on_mock("3u2o", speedup=SPEEDUP, faults=faults)
    assert_safe_and_arrived(flight.ground_truth)
    assert sum(v["link"]["dropped_in"] for v in flight.ground_truth["vehicles"]) > 0


async def test_filtered_tracks_fly_the_lossy_late_link_without_collision():
    """`fly --track-filter on`: the ADS-B reports from the mock are fused into tracks."""
    seen: dict[str, bool] = {}

    async def watch(fleet, runtime) -> None:
        await until_controlled(runtime)
        await flown_for(fleet, runtime, 4.0)
        tracks = list(runtime.traffic.tracks.values())
        seen["fused"] = bool(tracks) and all(v.cov is not None for v in tracks)

    faults = Faults(loss=0.10, latency_s=0.200)
    flight = await fly_on_mock(
        "3u2o", speedup=SPEEDUP, faults=faults, during=watch, fly_options={"track_filter": True}
    )
    assert_safe_and_arrived(flight.ground_truth)
    assert seen["fused"]
    assert flight.runtime["traffic"]["filtered"] is True


async def test_link_cut_is_detected_within_a_second_and_the_vehicle_is_held():
    seen: dict[str, float] = {}

    async def cut(fleet, runtime) -> None:
        await until_controlled(runtime)
        await flown_for(fleet, runtime, 4.0)
        seen["cut_at"] = runtime.clock.now()
        fleet.faults.cut_link(1, fleet.now_s(), 5.0)  # vehicle 2 (index 1)

    # The robust 3u2o policy, trained on fitted vehicles: with the mock's fitted ArduCopter
    # response the ideal-trained zoo policy passes 8.1 m from an intruder in this flight while
    # vehicle 2 holds (measured), the robust one 22.2 m (docs/RESULTS.md).
    flight = await fly_on_mock("3u2o", "robust/3u2o", speedup=SPEEDUP, during=cut)
    v2 = next(v for v in flight.runtime["vehicles"] if v["system_id"] == 2)
    lost = [t for t, e in v2["events"] if e.startswith("telemetry stale")]
    assert lost, v2["events"]
    assert lost[0] - seen["cut_at"] <= 1.0 + 0.3  # stale_s + one setpoint tick + jitter
    assert v2["status"] == "held"
    assert any("told to hold" in e for _, e in v2["events"])
    truth = flight.ground_truth
    assert truth["collisions_vehicle_intruder"] == 0 and truth["collisions_vehicle_vehicle"] == 0
    others = [v for v in flight.runtime["vehicles"] if v["system_id"] != 2]
    assert all(v["status"] == "reached" for v in others)
    assert truth["vehicles"][1]["custom_mode"] == CopterMode.BRAKE


async def test_a_vehicle_that_stays_lost_ends_the_flight_after_the_lost_timeout():
    async def cut(fleet, runtime) -> None:
        await until_controlled(runtime)
        fleet.faults.cut_link(1, fleet.now_s(), 10_000.0)  # vehicle 2 never comes back

    flight = await fly_on_mock(
        "3u2o", speedup=SPEEDUP, during=cut, fly_options={"lost_timeout_s": 5.0}
    )
    v2 = next(v for v in flight.runtime["vehicles"] if v["system_id"] == 2)
    assert v2["status"] == "lost"
    (given_up,) = [t for t, e in v2["events"] if "still lost after the lost timeout (5 s)" in e]
    last_reach = max(
        t for v in flight.runtime["vehicles"] for t, e in v["events"] if "target reached" in e
    )
    assert given_up <= last_reach + 5.0 + 2.5  # the timeout, plus one decision step
    assert flight.runtime["reached"] == [1, 3]
    assert flight.runtime["decisions"] < 40  # not run on to --max-flight


async def test_a_mode_the_pilot_takes_is_never_fought():
    marks: dict[str, int] = {}

    async def pilot(fleet, runtime) -> None:
        await until_controlled(runtime)
        await flown_for(fleet, runtime, 3.0)
        fleet.faults.switch_mode(0, fleet.now_s(), "LOITER")
        # released once two HEARTBEATs in a row say LOITER (one could be forged)
        await runtime.commands.wait_until(
            "the takeover", lambda: runtime.status(1).value == "pilot", 30
        )
        await flown_for(fleet, runtime, 0.5)  # a setpoint already in flight has landed
        marks["sent"] = fleet.vehicles[0].counters.setpoints_received
        marks["modes"] = fleet.vehicles[0].counters.commands["DO_SET_MODE"]

    flight = await fly_on_mock("3u2o", speedup=SPEEDUP, during=pilot)
    v1 = flight.runtime["vehicles"][0]
    assert v1["status"] == "pilot"
    truth = flight.ground_truth["vehicles"][0]
    assert truth["custom_mode"] == CopterMode.LOITER  # still the pilot's mode at the end
    assert truth["setpoints_received"] == marks["sent"]  # nothing more was sent to it
    assert truth["commands"]["DO_SET_MODE"] == marks["modes"]


async def test_cancellation_leaves_every_vehicle_holding():
    """Ctrl-C cancels the flight's task (asyncio.run does that): every vehicle must hold."""
    box = {}
    flying = asyncio.Event()

    async def watch(fleet, runtime) -> None:
        box["fleet"] = fleet
        await until_controlled(runtime)
        await flown_for(fleet, runtime, 3.0)
        flying.set()
        await asyncio.Event().wait()

    task = asyncio.create_task(fly_on_mock("3u2o", speedup=SPEEDUP, during=watch))
    await asyncio.wait_for(flying.wait(), 120)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    truth = box["fleet"].summary()
    assert all(v["custom_mode"] == CopterMode.BRAKE for v in truth["vehicles"])
    assert all(v["armed"] and not v["landed"] for v in truth["vehicles"])


async def test_dry_run_sends_no_command_and_no_setpoint(tmp_path):
    flight = await fly_on_mock(
        "3u2o",
        speedup=SPEEDUP,
        log_dir=tmp_path,
        fly_options={"dry_run": True, "max_flight_s": 6.0},
    )
    truth = flight.ground_truth["vehicles"]
    assert all(v["setpoints_received"] == 0 for v in truth)
    assert all(set(v["commands"]) == {"SET_MESSAGE_INTERVAL"} for v in truth)
    assert all(not v["armed"] and v["landed"] for v in truth)
    assert flight.runtime["decisions"] >= 3
    assert '"setpoint"' in (tmp_path / "decisions.jsonl").read_text()


async def test_one_link_per_vehicle_ardupilot_sitl_style():
    flight = await fly_on_mock("3u2o", speedup=SPEEDUP, link_per_vehicle=True)
    assert_safe_and_arrived(flight.ground_truth)


async def test_over_tcp_ardupilot_sitl_serial_ports():
    flight = await fly_on_mock("3u2o", speedup=SPEEDUP, tcp=True)
    assert_safe_and_arrived(flight.ground_truth)
    assert all(v["link"]["bad_frames"] == 0 for v in flight.ground_truth["vehicles"])


async def test_geofence_breach_ahead_holds_the_vehicle():
    from remarl_fc.flight.mission import Geofence

    # the targets lie 270 m east of the origin: a 230 m fence stops everyone before them
    flight = await fly_on_mock("3u2o", speedup=SPEEDUP, geofence=Geofence(radius_m=230.0))
    for v in flight.runtime["vehicles"]:
        assert v["status"] == "held"
        assert any("geofence" in e for _, e in v["events"])
    for v in flight.ground_truth["vehicles"]:
        assert v["custom_mode"] == CopterMode.BRAKE
        n, e = v["track_t_n_e_up_m"][-1][1:3]
        assert (n * n + e * e) ** 0.5 < 235.0


async def test_arming_refusal_carries_the_autopilots_reason():
    from remarl_fc.errors import CommandRejected
    from remarl_fc.mavlink.consts import MavCmd, MavResult

    async def arm_too_early(fleet, runtime) -> None:
        member = runtime.members[0]
        await runtime.commands.wait_until(
            "heartbeat", lambda: member.track.autopilot is not None, 30
        )
        with pytest.raises(CommandRejected) as info:
            await runtime.commands.command(member, MavCmd.COMPONENT_ARM_DISARM, 1)
        assert info.value.result == MavResult.FAILED
        assert "PreArm: Need Position Estimate" in info.value.reason
        assert "PreArm" in str(info.value)
        raise Checked  # done: end the flight here

    with pytest.raises(ExceptionGroup) as info:
        await fly_on_mock("3u2o", speedup=SPEEDUP, during=arm_too_early)
    assert info.value.subgroup(Checked) is not None


class Checked(Exception):
    """Ends a flight once a test has seen what it wanted."""


async def test_signed_flight_on_px4():
    import os

    flight = await fly_on_mock("3u2o", flavour="px4", speedup=SPEEDUP, signing_key=os.urandom(32))
    assert_safe_and_arrived(flight.ground_truth)
    assert all(v["link"]["rejected_unsigned"] == 0 for v in flight.ground_truth["vehicles"])


async def test_a_setpoint_timeout_shorter_than_the_stream_stops_the_flight_before_arming():
    from remarl_fc.errors import UnsafeParameters
    from remarl_fc.sitl.config import Px4Params

    box = {}

    async def keep(fleet, runtime) -> None:
        box["fleet"] = fleet
        await asyncio.Event().wait()

    short = {"px4": Px4Params(com_of_loss_t_s=0.15)}  # under two 10 Hz setpoint periods
    with pytest.raises(ExceptionGroup) as info:
        await fly_on_mock("3u2o", flavour="px4", speedup=SPEEDUP, during=keep, sitl_options=short)
    (error,) = info.value.subgroup(UnsafeParameters).exceptions  # one vehicle is enough
    assert "COM_OF_LOSS_T 0.15 s is under two setpoint periods (0.2 s)" in str(error)
    assert "--no-param-check" in str(error)
    truth = box["fleet"].summary()["vehicles"]
    assert all(not v["armed"] and v["landed"] for v in truth)
    assert all("COMPONENT_ARM_DISARM" not in v["commands"] for v in truth)


async def test_no_param_check_reads_no_parameter():
    flight = await fly_on_mock(
        "3u2o",
        speedup=SPEEDUP,
        fly_options={"check_params": False, "dry_run": True, "max_flight_s": 2.0},
    )
    assert all(v["params_unknown"] == {} for v in flight.ground_truth["vehicles"])
    events = [e for v in flight.runtime["vehicles"] for _, e in v["events"]]
    assert not any(e.startswith("parameter") for e in events)
