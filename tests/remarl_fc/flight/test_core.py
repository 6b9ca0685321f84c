"""The flight's sans-I/O core: plain data in, commands out; a fake clock, no sockets, no sleeps."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from remarl_fc.flight import core
from remarl_fc.flight.mission import Geofence
from remarl_fc.flight.status import (
    FLOWN,
    HOLD_ON_ENTRY,
    TRANSITIONS,
    IllegalTransition,
    Status,
    check_transition,
)

RULES = core.Rules(stale_s=1.0, dt_s=2.0)


class FakeGuidance:
    """Flies north at 10 m/s; the target is at ``target`` (reached within 1 m)."""

    def __init__(self, target=(100.0, 0.0)) -> None:
        self.target = np.array(target)

    def setpoint(self, slot, now):
        return 10.0, 0.0, 0.0

    def reached(self, slot, position_ne_m):
        return bool(np.hypot(*(position_ne_m - self.target)) < 1.0)


def tel(ne=(0.0, 0.0), *, age=0.1, external=True, height=10.0, yaw=0.5, mode=4) -> core.Telemetry:
    """Telemetry of a vehicle in GUIDED (custom_mode 4) 10 m up, fresh, unless told otherwise."""
    return core.Telemetry(ne, height, yaw, age, external, mode)  # the fields in their order


def controlled(sysid=1) -> core.Vehicle:
    return core.Vehicle(sysid, sysid - 1, status=Status.CONTROLLED)


def test_a_controlled_vehicle_gets_the_policys_setpoint():
    v, out = core.next_action(controlled(), tel(), 3.0, RULES, FakeGuidance())
    assert v.status == Status.CONTROLLED
    assert out == (core.Setpoint(1, 10.0, 0.0, 0.0, 0.0),)


def test_stale_telemetry_makes_it_lost_with_no_setpoint_and_no_hold():
    v, out = core.next_action(controlled(), tel(age=1.5), 3.0, RULES, FakeGuidance())
    assert v.status == Status.LOST
    assert out == (core.Event(1, "telemetry stale for 1.5 s: an obstacle now"),)


def test_lost_then_fresh_is_held_never_resumed():
    lost = replace(controlled(), status=Status.LOST)
    still, out = core.next_action(lost, tel(age=5.0), 3.0, RULES, FakeGuidance())
    assert (still.status, out) == (Status.LOST, ())
    back, out = core.next_action(lost, tel(age=0.2), 3.0, RULES, FakeGuidance())
    assert back.status == Status.HELD
    assert out == (core.Event(1, "telemetry back: told to hold, not resumed"), core.Hold(1))
    again, out = core.next_action(back, tel(), 3.2, RULES, FakeGuidance())
    assert (again.status, out) == (Status.HELD, (core.Setpoint(1, 0.0, 0.0, 0.0, 0.5),))
    brake = tel(external=False, mode=17)  # BRAKE confirmed
    confirmed, out = core.next_action(again, brake, 3.4, RULES, FakeGuidance())
    assert (confirmed.status, confirmed.braking, out) == (Status.HELD, False, ())


def test_untrusted_telemetry_holds_the_vehicle_instead_of_steering_it():
    t = replace(tel(), untrusted="position disagrees with its own velocity by 40 m")
    v, out = core.next_action(controlled(), t, 3.0, RULES, FakeGuidance())
    assert v.status == Status.HELD
    assert out == (
        core.Event(
            1, "telemetry untrusted (position disagrees with its own velocity by 40 m): hold"
        ),
        core.Hold(1),
    )


class BrokenGuidance(FakeGuidance):
    def setpoint(self, slot, now):
        return math.nan, 0.0, math.inf


def test_a_setpoint_that_is_not_a_number_holds_the_vehicle():
    v, out = core.next_action(controlled(), tel(), 3.0, RULES, BrokenGuidance())
    assert v.status == Status.HELD
    assert "not a number" in out[0].text and out[1] == core.Hold(1)


def test_a_lost_vehicle_is_waited_for_until_the_lost_timeout():
    lost, _ = core.next_action(controlled(2), tel(age=2.0), 10.0, RULES, FakeGuidance())
    assert lost.lost_since == 10.0
    done = {1: core.Vehicle(1, 0, status=Status.REACHED), 2: lost}
    mine = frozenset({1, 2})
    assert core.flight_goes_on(done, mine, 39.9, lost_timeout_s=30.0)
    assert not core.flight_goes_on(done, mine, 40.0, lost_timeout_s=30.0)
    flying = {**done, 1: controlled(1)}
    assert core.flight_goes_on(flying, mine, 100.0, lost_timeout_s=30.0)
    assert not core.flight_goes_on(flying, frozenset({2}), 100.0, lost_timeout_s=30.0)


def test_a_mode_the_pilot_chose_releases_it_without_a_hold():
    v, out = core.next_action(controlled(), tel(external=False, mode=5), 3.0, RULES, FakeGuidance())
    assert v.status == Status.PILOT
    assert out == (core.Event(1, "mode changed to 5 by someone else: released"),)


def test_in_a_dry_run_the_mode_is_never_taken_for_the_pilots():
    dry = replace(RULES, dry_run=True)
    v, out = core.next_action(controlled(), tel(external=False), 3.0, dry, FakeGuidance())
    assert v.status == Status.CONTROLLED
    assert isinstance(out[0], core.Setpoint)


def test_at_the_target_it_is_reached_and_held():
    v, out = core.next_action(controlled(), tel((99.5, 0.2)), 3.0, RULES, FakeGuidance())
    assert v.status == Status.REACHED
    assert out == (core.Event(1, "target reached: hold and release"), core.Hold(1))


def test_a_vehicle_told_to_hold_in_flight_is_braked_until_the_hold_mode_is_confirmed():
    """The hold is one command over a lossy link; the zero-velocity stream brakes it meanwhile
    (a lost DO_SET_MODE cost 3.5 s at 9 m/s on the mock's 10 %-loss link before this)."""
    v, _ = core.next_action(controlled(), tel((99.5, 0.2)), 3.0, RULES, FakeGuidance())
    assert v.braking
    for t in (3.1, 3.2, 5.0):  # unconfirmed: still GUIDED by its HEARTBEATs, fresh or not
        v, out = core.next_action(v, tel((95.0, 0.0), yaw=2.0, age=3.0), t, RULES, FakeGuidance())
        assert (v.status, out) == (Status.REACHED, (core.Setpoint(1, 0.0, 0.0, 0.0, 2.0),))
    v, out = core.next_action(v, tel(external=False, mode=17), 5.1, RULES, FakeGuidance())
    assert (v.status, v.braking, out) == (Status.REACHED, False, ())
    assert core.next_action(v, tel(), 5.2, RULES, FakeGuidance()) == (v, ())


def test_a_vehicle_held_before_it_flew_or_in_a_dry_run_is_never_braked():
    for before in (Status.WAITING, Status.TAKING_OFF, Status.READY):
        held, _ = core.transition(core.Vehicle(1, 0, status=before), Status.HELD, "end")
        assert not held.braking
    dry = replace(RULES, dry_run=True)
    v, _ = core.next_action(controlled(), tel((99.5, 0.2)), 3.0, dry, FakeGuidance())
    assert v.braking
    v, out = core.next_action(v, tel(), 3.1, dry, FakeGuidance())
    assert (v.braking, out) == (False, ())


def test_a_geofence_breach_within_one_step_holds_it():
    fence = Geofence(radius_m=50.0, max_alt_m=120.0)
    rules = replace(RULES, geofence=fence)
    inside, out = core.next_action(controlled(), tel((20.0, 0.0)), 3.0, rules, FakeGuidance())
    assert inside.status == Status.CONTROLLED and isinstance(out[0], core.Setpoint)
    # 35 m north + 10 m/s × 2 s = 55 m: outside the 50 m fence
    v, out = core.next_action(controlled(), tel((35.0, 0.0)), 3.0, rules, FakeGuidance())
    assert v.status == Status.HELD
    assert out == (core.Event(1, "geofence breach ahead: hold"), core.Hold(1))


@pytest.mark.parametrize("status", [s for s in Status if s not in (Status.CONTROLLED, Status.LOST)])
def test_a_vehicle_not_controlled_gets_nothing(status):
    v = core.Vehicle(1, 0, status=status)
    assert core.next_action(v, tel(), 3.0, RULES, FakeGuidance()) == (v, ())


def test_prestream_sends_zero_velocity_at_the_current_yaw():
    v = core.Vehicle(1, 0, status=Status.READY, prestream=True)
    _, out = core.next_action(v, tel(yaw=1.25), 0.0, RULES, FakeGuidance())
    assert out == (core.Setpoint(1, 0.0, 0.0, 0.0, 1.25),)
    _, out = core.next_action(v, tel(yaw=math.nan), 0.0, RULES, FakeGuidance())
    assert out == (core.Setpoint(1, 0.0, 0.0, 0.0, 0.0),)


def test_climb_goes_up_until_95_percent_of_the_height():
    v = core.Vehicle(1, 0, status=Status.TAKING_OFF, climb_target_m=10.0)
    _, low = core.next_action(v, tel(height=5.0), 0.0, RULES, FakeGuidance())
    _, high = core.next_action(v, tel(height=9.6), 0.0, RULES, FakeGuidance())
    _, unknown = core.next_action(v, tel(height=math.nan), 0.0, RULES, FakeGuidance())
    assert low[0] == core.Setpoint(1, 0.0, 0.0, -core.CLIMB_RATE_M_S, 0.5)
    assert high[0] == core.Setpoint(1, 0.0, 0.0, 0.0, 0.5)
    assert unknown[0].vd == 0.0  # no height: no climb


def test_next_actions_leaves_vehicles_without_telemetry_alone():
    fleet = {1: controlled(1), 2: controlled(2)}
    new, out = core.next_actions(fleet, {1: tel(age=3.0)}, 5.0, RULES, FakeGuidance())
    assert new[1].status == Status.LOST
    assert new[2] is fleet[2]
    assert fleet[1].status == Status.CONTROLLED  # the input is not changed
    assert [c.system_id for c in out] == [1]


def test_hold_all_holds_every_flown_vehicle_once():
    fleet = {
        1: controlled(1),
        2: core.Vehicle(2, 1, status=Status.REACHED),
        3: core.Vehicle(3, 2, status=Status.TAKING_OFF, climb_target_m=5.0),
        4: core.Vehicle(4, 3, status=Status.PILOT),
        5: controlled(5),
    }
    new, out = core.hold_all(fleet, frozenset({1, 2, 3, 4}), "exit")
    assert [s.status for s in new.values()] == [
        Status.HELD, Status.REACHED, Status.HELD, Status.PILOT, Status.CONTROLLED
    ]  # fmt: skip
    assert new[3].climb_target_m is None
    assert [c for c in out if isinstance(c, core.Hold)] == [core.Hold(1), core.Hold(3)]
    assert core.Event(1, "exit: hold") in out


def test_every_listed_transition_is_allowed_and_nothing_else():
    for old in Status:
        for new in Status:
            if new in TRANSITIONS[old]:
                check_transition(old, new)
            else:
                with pytest.raises(IllegalTransition):
                    check_transition(old, new)


def test_the_machine_has_no_way_back_to_controlled():
    for final in (Status.PILOT, Status.LOST, Status.HELD, Status.REACHED):
        reachable, frontier = set(), {final}
        while frontier:
            nxt = set().union(*(TRANSITIONS[s] for s in frontier)) - reachable
            reachable |= nxt
            frontier = nxt
        assert Status.CONTROLLED not in reachable, final


EVENTS = st.sampled_from(["tick", "stale", "pilot", "reach", "fence", "hold_all", "set"])


@settings(max_examples=300, deadline=None)
@given(
    start=st.sampled_from(list(Status)),
    events=st.lists(st.tuples(EVENTS, st.sampled_from(list(Status))), max_size=30),
)
def test_random_event_sequences_respect_the_machine(start, events):
    """Whatever happens: only allowed transitions; entering held/reached always sends a hold;
    once pilot or lost, never controlled again; pilot is never sent anything."""
    fence = Geofence(radius_m=50.0, max_alt_m=120.0)
    rules = replace(RULES, geofence=fence)
    v = core.Vehicle(1, 0, status=start)
    ever_out = start in (Status.PILOT, Status.LOST)
    for kind, target in events:
        old = v
        if kind == "set":  # any status change the shell might try
            try:
                v, out = core.transition(v, target, "try")
            except IllegalTransition:
                assert target not in TRANSITIONS[old.status]
                continue
        elif kind == "hold_all":
            fleet, out_list = core.hold_all({1: v}, frozenset({1}), "end")
            v, out = fleet[1], tuple(out_list)
        else:
            t = {
                "tick": tel(),
                "stale": tel(age=4.0),
                "pilot": tel(external=False),
                "reach": tel((100.0, 0.0)),
                "fence": tel((45.0, 0.0)),
            }[kind]
            v, out = core.next_action(v, t, 1.0, rules, FakeGuidance())
        if v.status != old.status:
            assert v.status in TRANSITIONS[old.status]
            holds = [c for c in out if isinstance(c, core.Hold)]
            assert len(holds) == (1 if v.status in HOLD_ON_ENTRY else 0)
        else:
            assert not any(isinstance(c, core.Hold) for c in out)
        if old.status == Status.PILOT:
            assert out == () or kind == "set"
        ever_out = ever_out or v.status in (Status.PILOT, Status.LOST)
        if ever_out:
            assert v.status != Status.CONTROLLED
        if old.status in FLOWN and kind == "hold_all":
            assert v.status == Status.HELD
