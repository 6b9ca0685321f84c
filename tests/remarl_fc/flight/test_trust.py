"""The source gate: a vehicle is the autopilot that answered the handshake, nobody else."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from remarl_fc.flight.trust import MAX_ALARMS, SourceGate, Verdict
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import MavAutopilot, MavCmd, MavComponent, MavResult, MavState

OWN = (255, 191)
HERE = ("127.0.0.1", 14551)
THERE = ("127.0.0.1", 40000)


def frame(codec: Codec, msg):
    (out,) = Codec(255, 191).decode(codec.encode(msg), "x")
    return out


def heartbeat(sysid=2, comp=1, autopilot=MavAutopilot.ARDUPILOTMEGA):
    c = Codec(sysid, comp)
    return frame(c, c.factory.heartbeat_encode(2, autopilot, 0, 0, MavState.ACTIVE))


def position(sysid=2, comp=1):
    c = Codec(sysid, comp)
    return frame(c, c.factory.global_position_int_encode(0, 1, 1, 0, 0, 0, 0, 0, 0))


def ack(sysid=2, target=OWN):
    c = Codec(sysid, 1)
    msg = c.factory.command_ack_encode(MavCmd.COMPONENT_ARM_DISARM, MavResult.DENIED, 0, 0, *target)
    return frame(c, msg)


def adsb(sysid=2, comp=MavComponent.ADSB):
    c = Codec(sysid, comp)
    msg = c.factory.adsb_vehicle_encode(1, 1, 1, 1, 0, 0, 0, 0, b"X", 14, 0, 1, 0)
    return frame(c, msg)


def bound_gate() -> SourceGate:
    gate = SourceGate(frozenset({1, 2, 3}), OWN)
    got = gate.admit(0, HERE, heartbeat())
    assert got.verdict == Verdict.VEHICLE and got.bound
    return gate


def test_the_first_autopilot_heartbeat_binds_and_nothing_before_it_passes():
    gate = SourceGate(frozenset({2}), OWN)
    assert gate.admit(0, HERE, position()).verdict == Verdict.DROP  # before the handshake
    assert gate.admit(0, HERE, heartbeat(comp=191)).verdict == Verdict.DROP  # not the autopilot
    assert gate.admit(0, HERE, heartbeat(autopilot=MavAutopilot.INVALID)).verdict == Verdict.DROP
    assert 2 not in gate.bound
    got = gate.admit(0, HERE, heartbeat())
    assert got.bound and str(gate.bound[2]) == "link 0 127.0.0.1:14551 component 1"
    assert gate.admit(0, HERE, position()).verdict == Verdict.VEHICLE
    assert not gate.admit(0, HERE, heartbeat()).bound  # binds once


def test_another_address_link_or_component_is_dropped_with_one_alarm_per_source():
    gate = bound_gate()
    first = gate.admit(0, THERE, position())
    assert first.verdict == Verdict.DROP and first.alarm is not None
    assert "127.0.0.1:40000" in first.alarm and "bound to link 0 127.0.0.1:14551" in first.alarm
    again = gate.admit(0, THERE, position())
    assert again.verdict == Verdict.DROP and again.alarm is None  # counted, not re-alarmed
    assert gate.admit(1, HERE, position()).alarm is not None  # same address, other link
    assert gate.admit(0, HERE, position(comp=2)).alarm is not None  # other component
    assert gate.foreign[2] == 4
    assert len(gate.alarms) == 3


def test_a_heartbeat_from_another_source_is_an_identity_claim():
    gate = bound_gate()
    assert gate.admit(0, THERE, heartbeat()).identity_claim
    assert not gate.admit(0, THERE, position()).identity_claim


def test_the_autopilot_type_cannot_change():
    gate = bound_gate()
    got = gate.admit(0, HERE, heartbeat(autopilot=MavAutopilot.PX4))
    assert got.verdict == Verdict.DROP and "autopilot type changed" in (got.alarm or "")


def test_acks_must_be_addressed_to_us():
    gate = bound_gate()
    assert gate.admit(0, HERE, ack(target=OWN)).verdict == Verdict.VEHICLE
    assert gate.admit(0, HERE, ack(target=(0, 0))).verdict == Verdict.VEHICLE  # legacy: unset
    other = gate.admit(0, HERE, ack(target=(254, 190)))
    assert other.verdict == Verdict.DROP and other.reason == "COMMAND_ACK addressed to someone else"


def test_adsb_only_from_a_bound_vehicle_or_a_named_receiver():
    gate = SourceGate(frozenset({2}), OWN, adsb_sources=frozenset({(200, 156)}))
    assert gate.admit(0, HERE, adsb()).verdict == Verdict.DROP  # vehicle 2 not bound yet
    gate.admit(0, HERE, heartbeat())
    assert gate.admit(0, HERE, adsb(comp=MavComponent.ADSB)).verdict == Verdict.TRAFFIC
    assert gate.admit(0, HERE, adsb(comp=1)).verdict == Verdict.TRAFFIC
    assert gate.admit(0, THERE, adsb()).verdict == Verdict.DROP  # its id, another address
    assert gate.admit(0, THERE, adsb(sysid=200)).verdict == Verdict.TRAFFIC  # named
    assert gate.admit(0, THERE, adsb(sysid=201)).verdict == Verdict.DROP
    assert gate.dropped["sender not in the mission"] == 1


def test_alarms_are_capped_under_a_flood_of_sources():
    gate = bound_gate()
    for port in range(1000, 1000 + 3 * MAX_ALARMS):
        gate.admit(0, ("10.0.0.9", port), position())
    assert len(gate.alarms) == MAX_ALARMS
    assert gate.alarms_not_kept == 2 * MAX_ALARMS
    assert gate.summary()["foreign_frames"] == {"2": 3 * MAX_ALARMS}


@settings(max_examples=200, deadline=None)
@given(
    events=st.lists(
        st.tuples(
            st.integers(0, 1),  # link
            st.sampled_from([HERE, THERE]),
            st.sampled_from(["heartbeat", "position", "ack", "adsb", "hb_px4"]),
            st.integers(1, 4),  # system id (4 is not in the mission)
        ),
        max_size=40,
    )
)
def test_once_bound_only_the_bound_source_ever_passes_as_the_vehicle(events):
    gate = SourceGate(frozenset({1, 2, 3}), OWN)
    build = {
        "heartbeat": lambda s: heartbeat(s),
        "position": lambda s: position(s),
        "ack": lambda s: ack(s),
        "adsb": lambda s: adsb(s),
        "hb_px4": lambda s: heartbeat(s, autopilot=MavAutopilot.PX4),
    }
    for link, address, kind, sysid in events:
        before = dict(gate.bound)
        got = gate.admit(link, address, build[kind](sysid))
        if sysid == 4:
            assert got.verdict == Verdict.DROP
        if got.verdict == Verdict.VEHICLE and sysid in before:
            source = before[sysid]
            assert (source.link, source.address) == (link, f"{address[0]}:{address[1]}")
        assert all(gate.bound[k] == v for k, v in before.items())  # a binding never moves
