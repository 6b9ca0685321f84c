"""The mock's pieces without sockets: airframes, setpoint rules, ground truth, faults."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from remarl_fc.frames import GeoPoint
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import TYPE_MASK_VELOCITY_YAW, MavFrame, TypeMask
from remarl_fc.sitl.channel import Counters
from remarl_fc.sitl.config import SitlConfig, VehicleModelConfig
from remarl_fc.sitl.faults import Faults, Window, parse_glitch, parse_pilot_switch, parse_window
from remarl_fc.sitl.groundtruth import GroundTruth, write_json_atomic
from remarl_fc.sitl.setpoints import parse_setpoint
from remarl_fc.sitl.vehicle import Airframes, Guidance, YawMode, step
from sim.vehicle import DelayLine, VehicleProfile, load_profile

REAL_T90_S = json.loads(
    (Path(__file__).resolve().parents[2] / "data" / "sitl" / "derived.json").read_text()
)
HOME = GeoPoint(47.0, 8.0, 500.0)


def flying(n: int = 1) -> Airframes:
    a = Airframes.on_ground(np.zeros((n, 3)), np.zeros(n))
    a.pos_ned_m[:, 2] = -20.0
    a.landed[:] = False
    for i in range(n):
        a.set_hold(i)
    return a


ARDUCOPTER = load_profile("arducopter")


def run(
    a: Airframes,
    seconds: float,
    cfg: VehicleModelConfig | None = None,
    profile: VehicleProfile = ARDUCOPTER,
    delay: DelayLine | None = None,
) -> None:
    cfg = cfg or VehicleModelConfig()
    rng = np.random.default_rng(0)
    for _ in range(round(seconds * 50)):
        step(a, cfg, 0.02, rng, profile, delay)


def test_velocity_step_response_matches_arducopter_sitl():
    """The mock flies the fitted ArduCopter profile: a 0 → 5 m/s step reaches 90 % after
    2.33 s on real ArduCopter SITL (tests/data/sitl/derived.json); the mock within 0.4 s (the
    model has no jerk limit: from a standing start real ArduCopter is slower for 0.5 s)."""
    a = flying()
    a.guidance[0] = Guidance.VELOCITY
    a.vel_target_m_s[0] = [3.0, 4.0, 0.0]
    delay = DelayLine(ARDUCOPTER.delay_s, 0.02)
    t90 = None
    for k in range(300):
        run(a, 0.02, delay=delay)
        if t90 is None and np.linalg.norm(a.vel_ned_m_s[0]) >= 0.9 * 5.0:
            t90 = (k + 1) * 0.02
    real = REAL_T90_S["ardupilot"]["a_speed_steps"]["0->5"]["t90_s"]
    assert t90 is not None and abs(t90 - real) <= 0.4
    np.testing.assert_allclose(a.vel_ned_m_s[0], [3.0, 4.0, 0.0], atol=1e-2)


def test_acceleration_and_yaw_rate_are_limited():
    cfg = VehicleModelConfig()
    a = flying()
    a.guidance[0] = Guidance.VELOCITY
    a.vel_target_m_s[0] = [15.0, 0.0, 0.0]
    a.yaw_mode[0] = YawMode.ANGLE
    a.yaw_target_rad[0] = math.radians(170)
    prev_v, prev_yaw = a.vel_ned_m_s[0].copy(), a.yaw_rad[0]
    for _ in range(100):
        run(a, 0.02, cfg)
        dv = np.linalg.norm(a.vel_ned_m_s[0] - prev_v) / 0.02
        dyaw = abs(a.yaw_rad[0] - prev_yaw) / 0.02
        assert dv <= ARDUCOPTER.max_accel_m_s2 + 1e-6
        assert dyaw <= ARDUCOPTER.max_yaw_rate_rad_s + 1e-6
        prev_v, prev_yaw = a.vel_ned_m_s[0].copy(), a.yaw_rad[0]


def test_climb_lands_and_idle_on_the_ground():
    a = Airframes.on_ground(np.zeros((2, 3)), np.zeros(2))
    a.set_hold(0)
    a.guidance[0] = Guidance.CLIMB
    a.pos_target_ned_m[0, 2] = -10.0
    a.climb_m_s[0] = 2.5
    run(a, 10.0)
    assert a.height_m()[0] == pytest.approx(10.0, abs=0.2) and not a.landed[0]
    assert a.landed[1] and a.height_m()[1] == 0.0  # idle: never moves
    a.guidance[0] = Guidance.LAND
    a.fast_descent_m_s[0] = a.slow_descent_m_s[0] = 1.5
    run(a, 12.0)
    assert a.landed[0] and a.height_m()[0] == 0.0


def test_travel_yaw_faces_the_velocity():
    a = flying()
    a.guidance[0] = Guidance.VELOCITY
    a.vel_target_m_s[0] = [0.0, -5.0, 0.0]
    a.yaw_mode[0] = YawMode.TRAVEL
    run(a, 6.0)
    assert math.degrees(a.yaw_rad[0]) == pytest.approx(-90.0, abs=1.0)


def msg(**kw):
    f = Codec(255, 190).factory
    fields = {"time_boot_ms": 0, "target_system": 1, "target_component": 1}
    fields |= {"coordinate_frame": 1, "type_mask": TYPE_MASK_VELOCITY_YAW}
    fields |= {"x": 0.0, "y": 0.0, "z": 0.0, "vx": 1.0, "vy": 2.0, "vz": 0.0}
    fields |= {"afx": 0.0, "afy": 0.0, "afz": 0.0, "yaw": 0.5, "yaw_rate": 0.0}
    fields.update(kw)
    return f.set_position_target_local_ned_encode(*fields.values())


def parse(m, flavour="ardupilot", yaw=0.0):
    return parse_setpoint(
        m, flavour=flavour, origin=HOME, home_ned_m=np.array([10.0, 0.0, 0.0]),
        pos_ned_m=np.array([10.0, 5.0, -20.0]), yaw_rad=yaw,
    )  # fmt: skip


def test_setpoint_rules_per_flavour():
    sp = parse(msg())
    assert sp.valid and sp.yaw_rad == 0.5 and sp.pos_ned_m is None
    np.testing.assert_allclose(sp.vel_ned_m_s, [1.0, 2.0, 0.0])
    trap = msg(type_mask=TYPE_MASK_VELOCITY_YAW | TypeMask.VZ_IGNORE)
    assert not parse(trap).valid  # ArduCopter: a single ignore bit invalidates
    px4 = parse(trap, "px4")
    assert px4.valid and math.isnan(px4.vel_ned_m_s[2])  # PX4: that axis holds
    assert parse(msg(coordinate_frame=MavFrame.LOCAL_OFFSET_NED)).valid
    assert not parse(msg(coordinate_frame=MavFrame.LOCAL_OFFSET_NED), "px4").valid
    assert not parse(msg(vx=math.nan)).valid
    assert not parse(msg(vx=2000.0)).valid
    nothing = msg(type_mask=0x0FFF & ~TypeMask.YAW_IGNORE)
    assert not parse(nothing).valid


def test_body_frame_rotates_velocity_and_yaw_is_relative_on_ardupilot():
    sp = parse(
        msg(coordinate_frame=MavFrame.BODY_OFFSET_NED, vx=2.0, vy=0.0, yaw=0.1), yaw=math.pi / 2
    )
    np.testing.assert_allclose(sp.vel_ned_m_s, [0.0, 2.0, 0.0], atol=1e-12)
    assert sp.yaw_rad == pytest.approx(math.pi / 2 + 0.1)


def test_local_ned_positions_are_from_the_vehicles_home():
    mask = int(TypeMask.VX_IGNORE | TypeMask.VY_IGNORE | TypeMask.VZ_IGNORE) | 0x1C0 | 0xC00
    sp = parse(msg(type_mask=mask, x=1.0, y=2.0, z=-3.0))
    np.testing.assert_allclose(sp.pos_ned_m, [11.0, 2.0, -3.0])


def test_ground_truth_catches_a_crossing_between_samples(tmp_path):
    truth = GroundTruth(2, 1, d_col_m=5.0, targets_ne_m=np.array([[100.0, 0.0], [0.0, 0.0]]))
    far = np.array([[0.0, 0.0, -10.0]])
    truth.record(0.0, np.array([[-50.0, 1.0, -10.0], [50.0, -1.0, -10.0]]), far + 500)
    truth.record(1.0, np.array([[50.0, 1.0, -10.0], [-50.0, -1.0, -10.0]]), far + 500)
    assert truth.min_uu[0] == pytest.approx(2.0)  # they passed 2 m apart mid-interval
    assert truth.collisions_uu[0] == 1
    truth.record(2.0, np.array([[99.0, 0.0, -10.0], [-60.0, -1.0, -10.0]]), far + 500)
    assert truth.collisions_uu[0] == 1  # one encounter, one collision
    assert truth.reached().tolist() == [True, False]
    out = tmp_path / "s" / "summary.json"
    write_json_atomic(out, {"overall": truth.overall(), "v0": truth.vehicle_summary(0)})
    assert '"collisions_vehicle_vehicle": 1' in out.read_text()
    assert [p.name for p in out.parent.iterdir()] == ["summary.json"]  # no temp file left


@pytest.mark.parametrize(
    ("parser", "text", "expected"),
    [
        (parse_window, "all:1:2", SimpleNamespace(vehicle=None, start_s=1.0, end_s=2.0)),
        (parse_pilot_switch, "2:30:LOITER", SimpleNamespace(vehicle=2, at_s=30.0, mode="LOITER")),
    ],
)
def test_fault_specs(parser, text, expected):
    got = parser(text)
    for key, value in vars(expected).items():
        assert getattr(got, key) == value
    assert parse_glitch("0:1:2:30").offset_m == 30.0


def test_faults_on_one_vehicle_or_all():
    faults = Faults()
    faults.cut_link(1, 10.0, 5.0)
    faults.drop_heartbeats(None, 0.0, 1.0)
    assert faults.link_cuts == [Window(1, 10.0, 15.0)]
    assert [faults.link_down(v, 12.0) for v in range(3)] == [False, True, False]
    assert not faults.link_down(1, 15.0)  # the end is open
    assert all(faults.heartbeat_muted(v, 0.5) for v in range(3))
    assert [parse_pilot_switch("all:1:LOITER").targets(v) for v in range(2)] == [True, True]
    assert [parse_pilot_switch("1:1:LOITER").targets(v) for v in range(2)] == [False, True]


def test_ignored_setpoints_are_the_total_of_their_reasons():
    counters = Counters()
    counters.ignored_reasons.update({"not in GUIDED": 2, "on the ground": 1})
    assert counters.setpoints_ignored == counters.as_dict()["setpoints_ignored"] == 3


@pytest.mark.parametrize("text", ["1:2", "x:1:2", "0:5:1", "0:a:b", "-1:0:1"])
def test_bad_fault_specs_say_what_is_expected(text):
    with pytest.raises(ValueError, match=r"VEHICLE|vehicle|window|seconds|negative"):
        parse_window(text)


def test_config_validation():
    with pytest.raises(ValueError, match="flavour"):
        SitlConfig(flavour="inav")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="ports"):
        SitlConfig(vehicles=200, base_port=65000)
    assert SitlConfig(vehicles=3).port(2) == 14570
    assert SitlConfig(vehicles=3, flavour="px4").port(2) == 18572


@pytest.mark.parametrize(
    ("profile", "flavour", "expected"),
    [
        ("responsive", "ardupilot", "responsive"),
        ("flavour", "ardupilot", "arducopter"),
        ("flavour", "px4", "px4"),
        ("px4-sluggish", "ardupilot", "px4-sluggish"),
    ],
)
def test_the_mock_flies_the_simulator_s_vehicle_profiles(profile, flavour, expected):
    from remarl_fc.sitl.fleet import SitlFleet

    cfg = SitlConfig(
        vehicles=1, flavour=flavour, base_port=0, model=VehicleModelConfig(profile=profile)
    )
    fleet = SitlFleet(cfg)
    assert fleet.vehicle_profile == load_profile(expected)
    assert fleet._delay.steps == round(fleet.vehicle_profile.delay_s * cfg.physics_hz)


def test_the_fitted_delay_holds_the_command_back():
    a = flying()
    delay = DelayLine(ARDUCOPTER.delay_s, 0.02)
    run(a, 0.5, delay=delay)  # hovering: the line fills with zero commands
    a.guidance[0] = Guidance.VELOCITY
    a.vel_target_m_s[0] = [5.0, 0.0, 0.0]
    run(a, 0.30, delay=delay)  # inside the 0.33 s delay: nothing yet
    assert np.linalg.norm(a.vel_ned_m_s[0]) == 0.0
    run(a, 0.1, delay=delay)
    assert np.linalg.norm(a.vel_ned_m_s[0]) > 0.0
