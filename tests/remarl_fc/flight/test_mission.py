"""Mission files: parsing, every error path, policy checks, scenarios and geofences."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from remarl_fc.errors import ConfigError, PolicySpecMismatch
from remarl_fc.flight.mission import (
    DEFAULT_ALT_M,
    Geofence,
    Mission,
    MissionError,
    VehicleCountMismatch,
    VehiclePlan,
    initial_yaw_rad,
    load_mission,
)
from remarl_fc.frames import GeoPoint, ned_to_geodetic, sim_to_ne
from remarl_fc.sitl.config import DEFAULT_HOME
from sim.encounters import Family, sample_family
from sim.scenarios import load_scenario
from sim.spawn import swarm_layout

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = ROOT / "docs" / "examples" / "mission-3u2o.toml"

ORIGIN = GeoPoint(47.397742, 8.545594, 488.0)
TARGET_LAT, TARGET_LON, _ = ned_to_geodetic(-80.0, 120.0, 0.0, ORIGIN)

VALID = f"""
description = "two vehicles"
speed_m_s = 10.0
dt_s = 2.0

[origin]
lat_deg = 47.397742
lon_deg = 8.545594
alt_m = 488.0

[geofence]
radius_m = 600.0
max_alt_m = 60.0

[[vehicle]]
system_id = 7
slot = 1
target = {{ north_m = 150.0, east_m = 270.0 }}
alt_m = 25.0

[[vehicle]]
system_id = 3
slot = 0
target = {{ lat_deg = {float(TARGET_LAT)!r}, lon_deg = {float(TARGET_LON)!r} }}
"""


def write(tmp_path: Path, text: str, name: str = "mission.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def replace(old: str, new: str, text: str = VALID) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def load_error(tmp_path: Path, text: str) -> MissionError:
    path = write(tmp_path, text)
    with pytest.raises(MissionError) as info:
        load_mission(path)
    assert isinstance(info.value, ConfigError)
    assert info.value.source == str(path)
    assert str(path) in str(info.value)
    return info.value


# -- a valid file ---------------------------------------------------------------------------


def test_valid_mission_north_east_and_lat_lon_targets(tmp_path):
    path = write(tmp_path, VALID)
    m = load_mission(path)
    assert m.source == str(path)
    assert m.origin == ORIGIN
    assert m.speed_m_s == 10.0 and m.dt_s == 2.0
    assert m.geofence == Geofence(radius_m=600.0, polygon_ne_m=None, max_alt_m=60.0)
    first, second = m.vehicles  # file order is kept
    assert first == VehiclePlan(7, 1, (150.0, 270.0), 25.0)
    assert second.system_id == 3 and second.slot == 0
    assert second.alt_m == DEFAULT_ALT_M  # no alt_m: the default cruise height
    np.testing.assert_allclose(second.target_ne_m, (-80.0, 120.0), atol=1e-6)
    # by slot: slot 0 (system 3) first
    assert [v.system_id for v in m.by_slot()] == [3, 7]
    np.testing.assert_allclose(m.targets_ne_m(), [[-80.0, 120.0], [150.0, 270.0]], atol=1e-6)
    assert m.targets_ne_m().dtype == np.float64


def test_path_may_be_a_string_and_dt_and_geofence_are_optional(tmp_path):
    text = replace("dt_s = 2.0\n", "")
    text = replace("[geofence]\nradius_m = 600.0\nmax_alt_m = 60.0\n", "", text)
    m = load_mission(str(write(tmp_path, text)))
    assert m.dt_s is None and m.geofence is None


def test_integers_are_accepted_as_numbers(tmp_path):
    m = load_mission(write(tmp_path, replace("speed_m_s = 10.0", "speed_m_s = 10")))
    assert m.speed_m_s == 10.0 and isinstance(m.speed_m_s, float)


def test_polygon_geofence_is_read(tmp_path):
    text = replace(
        "radius_m = 600.0", "polygon_ne_m = [[-100, -100], [400, -100], [400, 400], [-100, 400]]"
    )
    fence = load_mission(write(tmp_path, text)).geofence
    assert fence is not None and fence.radius_m is None and fence.max_alt_m == 60.0
    assert fence.polygon_ne_m == (
        (-100.0, -100.0),
        (400.0, -100.0),
        (400.0, 400.0),
        (-100.0, 400.0),
    )


def test_initial_yaw_points_each_vehicle_at_its_target(tmp_path):
    m = load_mission(write(tmp_path, VALID))
    # slot order: slot 0 target (-80, 120), slot 1 target (150, 270)
    positions = np.array([[-80.0, 0.0], [0.0, 270.0]])  # due west of / due south of the target
    yaw = initial_yaw_rad(m, positions)
    np.testing.assert_allclose(yaw, [math.pi / 2, 0.0], atol=1e-8)  # east, north


# -- every error names the key --------------------------------------------------------------


@pytest.mark.parametrize(
    ("old", "new", "key", "words"),
    [
        (
            "[origin]\nlat_deg = 47.397742\nlon_deg = 8.545594\nalt_m = 488.0\n",
            "",
            "origin",
            "table",
        ),
        ("lat_deg = 47.397742\n", "", "origin.lat_deg", "missing"),
        ("lon_deg = 8.545594\n", "", "origin.lon_deg", "missing"),
        ("alt_m = 488.0\n", "", "origin.alt_m", "missing"),
        ("lat_deg = 47.397742", 'lat_deg = "north"', "origin.lat_deg", "number"),
        ("lat_deg = 47.397742", "lat_deg = 95.0", "origin", "latitude"),
        ("lon_deg = 8.545594", "lon_deg = 190.0", "origin", "longitude"),
        ("alt_m = 488.0", "alt_m = nan", "origin.alt_m", "number"),
        ("alt_m = 488.0", "alt_m = true", "origin.alt_m", "number"),
        ("alt_m = 488.0", "alt_m = 488.0\naltitude = 1", "origin.altitude", "unknown"),
        ("speed_m_s = 10.0\n", "", "speed_m_s", "missing"),
        ("speed_m_s = 10.0", 'speed_m_s = "fast"', "speed_m_s", "number"),
        ("speed_m_s = 10.0", "speed_m_s = inf", "speed_m_s", "number"),
        ("speed_m_s = 10.0", "speed_m_s = 0.0", "speed_m_s", "> 0"),
        ("dt_s = 2.0", "dt_s = -2.0", "dt_s", "> 0"),
        ("dt_s = 2.0", "dt_s = [2.0]", "dt_s", "number"),
        ("dt_s = 2.0", "dt_s = 2.0\nspeed = 3", "speed", "unknown key"),
        ("system_id = 7", "sytem_id = 7", "vehicle[0].sytem_id", "unknown key"),
        ("system_id = 7\n", "", "vehicle[0].system_id", "missing"),
        ("system_id = 7", "system_id = 0", "vehicle[0].system_id", "1..255"),
        ("system_id = 7", "system_id = 256", "vehicle[0].system_id", "1..255"),
        ("system_id = 7", "system_id = 7.5", "vehicle[0].system_id", "integer"),
        ("system_id = 3", "system_id = 7", "vehicle.system_id", "repeat"),
        ("slot = 1\n", "", "vehicle[0].slot", "missing"),
        ("slot = 1", "slot = -1", "vehicle[0].slot", "≥ 0"),
        ("slot = 1", "slot = 0.5", "vehicle[0].slot", "integer"),
        ("alt_m = 25.0", "alt_m = 0.0", "vehicle[0].alt_m", "> 0"),
        ("alt_m = 25.0", "alt_m = 25.0\ngroup = -1", "vehicle[0].group", "≥ 0"),
        ("alt_m = 25.0", "alt_m = 25.0\ngroup = 0.5", "vehicle[0].group", "integer"),
        ("alt_m = 25.0", "alt_m = 25.0\ngroup = 2", "vehicle.group", "without gaps"),
        ("alt_m = 25.0", "alt = 25.0", "vehicle[0].alt", "unknown key"),
        ("target = { north_m = 150.0, east_m = 270.0 }\n", "", "vehicle[0].target", "missing"),
        ("target = { north_m = 150.0, east_m = 270.0 }", "target = 5", "vehicle[0].target", "give"),
        ("north_m = 150.0, ", "", "vehicle[0].target.north_m", "missing"),
        (", east_m = 270.0", "", "vehicle[0].target.east_m", "missing"),
        ("east_m = 270.0", 'east_m = "far"', "vehicle[0].target.east_m", "number"),
        ("east_m = 270.0", "east_m = 270.0, up_m = 3", "vehicle[0].target.up_m", "unknown key"),
        ("east_m = 270.0", "east_m = 270.0, lat_deg = 47.0", "vehicle[0].target", "not both"),
        (", lon_deg = ", ", lon = ", "vehicle[1].target.lon", "unknown key"),
        ("max_alt_m = 60.0", "max_alt = 60.0", "geofence.max_alt", "unknown key"),
        ("max_alt_m = 60.0", "max_alt_m = -1.0", "geofence.max_alt_m", "> 0"),
        ("radius_m = 600.0", "radius_m = 0", "geofence.radius_m", "> 0"),
        ("[geofence]\nradius_m = 600.0\nmax_alt_m = 60.0\n", "geofence = 3\n", "geofence", "table"),
    ],
)
def test_errors_name_the_key(tmp_path, old, new, key, words):
    if new.startswith("geofence = "):  # a top-level key must come before the first table
        text = replace("[geofence]\nradius_m = 600.0\nmax_alt_m = 60.0\n", "")
        text = new + text
    else:
        text = replace(old, new)
    err = load_error(tmp_path, text)
    assert err.key == key
    assert f": {key}: " in str(err)
    assert words in str(err)


def test_lat_lon_target_outside_the_globe_is_refused(tmp_path):
    text = VALID.replace(f"lat_deg = {float(TARGET_LAT)!r}", "lat_deg = 91.0")
    err = load_error(tmp_path, text)
    assert err.key == "vehicle[1].target" and "latitude" in str(err)


def test_unknown_top_level_key_lists_the_known_ones(tmp_path):
    err = load_error(tmp_path, "speeed_m_s = 10.0\n" + VALID)
    assert err.key == "speeed_m_s"
    assert "known: description, dt_s, geofence, origin, policy, speed_m_s, traffic, vehicle" in str(
        err
    )


@pytest.mark.parametrize("vehicles", ["", "vehicle = []\n", "vehicle = 3\n"])
def test_no_vehicle_is_an_error(tmp_path, vehicles):
    head = VALID.split("[[vehicle]]")[0]
    text = vehicles + head  # top-level keys before the tables
    err = load_error(tmp_path, text)
    assert err.key == "vehicle" and "at least one" in str(err)


def test_vehicle_that_is_not_a_table(tmp_path):
    head = VALID.split("[[vehicle]]")[0]
    err = load_error(tmp_path, "vehicle = [1, 2]\n" + head)
    assert err.key == "vehicle[0]" and "table" in str(err)


def test_duplicate_system_ids_are_listed(tmp_path):
    err = load_error(tmp_path, replace("system_id = 3", "system_id = 7"))
    assert err.key == "vehicle.system_id"
    assert "[7, 7]" in str(err)


@pytest.mark.parametrize(
    "polygon",
    [
        "[[0, 0], [1, 1]]",  # fewer than 3 points
        "[[0, 0], [1, 1], [2]]",  # not a pair
        "[[0, 0], [1, 1], [2, 3, 4]]",
        '[[0, 0], [1, 1], ["a", 2]]',  # not numbers
        "[[0, 0], [1, 1], [true, 2]]",
        "[[0, 0], [1, 1], [nan, 2]]",
        "[[0, 0], [1, 1], [inf, 2]]",
        "[0, 1, 2]",
        '"square"',
    ],
)
def test_bad_geofence_polygon(tmp_path, polygon):
    err = load_error(tmp_path, replace("radius_m = 600.0", f"polygon_ne_m = {polygon}"))
    assert err.key == "geofence.polygon_ne_m"
    assert "at least 3 [north, east] pairs" in str(err)


def test_empty_geofence_is_an_error(tmp_path):
    text = replace("[geofence]\nradius_m = 600.0\nmax_alt_m = 60.0\n", "[geofence]\n")
    err = load_error(tmp_path, text)
    assert err.key == "geofence" and "radius_m, polygon_ne_m or max_alt_m" in str(err)


def test_not_toml(tmp_path):
    err = load_error(tmp_path, "speed_m_s = = 10\n[origin\n")
    assert err.key == "" and "not valid TOML" in str(err)


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere" / "mission.toml"
    with pytest.raises(MissionError) as info:
        load_mission(path)
    assert str(path) in str(info.value)
    assert "cannot read the file" in str(info.value)
    assert info.value.key == ""


def test_a_folder_is_not_a_mission(tmp_path):
    with pytest.raises(MissionError, match="cannot read the file"):
        load_mission(tmp_path)


def test_a_target_outside_the_missions_own_fence_is_refused(tmp_path):
    text = replace("north_m = 150.0, east_m = 270.0", "north_m = 650.0, east_m = 0.0")
    error = load_error(tmp_path, text)
    assert error.key == "vehicle[0].target" and "outside the mission's own geofence" in str(error)


def test_a_cruise_height_above_the_ceiling_is_refused(tmp_path):
    error = load_error(tmp_path, replace("alt_m = 25.0", "alt_m = 500.0"))
    assert error.key == "vehicle[0].alt_m"
    assert "above the geofence ceiling max_alt_m 60 m" in str(error)


def test_a_file_that_is_not_utf8_is_one_clear_error(tmp_path):
    path = tmp_path / "mission.toml"
    path.write_bytes(VALID.encode() + b"\n# caf\xe9\n")
    with pytest.raises(MissionError, match=r"not UTF-8 text \(byte \d+\): save it as UTF-8"):
        load_mission(path)


def test_absurd_nesting_is_refused(tmp_path):
    deep = "x = " + "[" * 200 + "]" * 200 + "\n"
    error = load_error(tmp_path, deep + VALID)
    assert "nested deeper than" in str(error) or "not valid TOML" in str(error)
    deeper = "x = " + "[" * 5000 + "]" * 5000 + "\n"
    load_error(tmp_path, deeper + VALID)  # the TOML parser's recursion limit: still one error


def test_a_huge_file_is_refused_unread(tmp_path):
    path = tmp_path / "mission.toml"
    path.write_text(VALID + "#" * 2_000_000, encoding="utf-8")
    with pytest.raises(MissionError, match="not a mission file"):
        load_mission(path)


def test_trusted_adsb_sources(tmp_path):
    path = write(tmp_path, VALID + '\n[traffic]\nadsb_sources = ["200:156", "201:1"]\n')
    assert load_mission(path).adsb_sources == frozenset({(200, 156), (201, 1)})
    for bad in ('["200"]', '["0:156"]', '["a:b"]', "200", '["200:156:1"]'):
        error = load_error(tmp_path, VALID + f"\n[traffic]\nadsb_sources = {bad}\n")
        assert error.key == "traffic.adsb_sources"


def test_the_track_filters_report_noise_comes_from_the_mission(tmp_path):
    from sim.config import SensorConfig
    from sim.sensors import TrackNoise

    default = load_mission(write(tmp_path, VALID))
    assert default.sensors() == SensorConfig()  # none given: the simulator's
    path = write(tmp_path, VALID + "\n[traffic]\nepu_m = 5.0\nnacv_m_s = 1.0\n")
    mission = load_mission(path)
    assert (mission.adsb_epu_m, mission.adsb_nacv_m_s) == (5.0, 1.0)
    assert mission.sensors().adsb_epu_m == (5.0, 5.0)
    assert TrackNoise.of(mission.sensors()).pos_var_m2 < TrackNoise.of(SensorConfig()).pos_var_m2
    for bad in ("0", "-3", '"ten"', "nan"):
        error = load_error(tmp_path, VALID + f"\n[traffic]\nepu_m = {bad}\n")
        assert error.key == "traffic.epu_m"
    assert load_error(tmp_path, VALID + "\n[traffic]\nnacv = 1\n").key == "traffic.nacv"


def test_mission_error_is_a_value_error():
    err = MissionError("bad", source="m.toml", key="speed_m_s")
    assert isinstance(err, ValueError)
    assert str(err) == "m.toml: speed_m_s: bad"
    assert str(MissionError("bad", source="m.toml")) == "m.toml: bad"


# -- check_policy ---------------------------------------------------------------------------


def test_check_policy_accepts_a_fitting_policy(tmp_path):
    load_mission(write(tmp_path, VALID)).check_policy(2, 10.0, 2.0, 20.0)


@pytest.mark.parametrize(
    ("agents", "speed", "dt", "field", "expected", "actual"),
    [
        (3, 10.0, 2.0, "number of vehicles", 3, 2),
        (2, 12.0, 2.0, "speed_m_s", 12.0, 10.0),
        (2, 10.0, 1.0, "dt_s", 1.0, 2.0),
    ],
)
def test_check_policy_names_the_conflicting_value(
    tmp_path, agents, speed, dt, field, expected, actual
):
    m = load_mission(write(tmp_path, VALID))
    with pytest.raises(PolicySpecMismatch) as info:
        m.check_policy(agents, speed, dt, 20.0)
    err = info.value
    assert err.field == field and err.expected == expected and err.actual == actual
    assert err.source == m.source
    assert field in str(err) and repr(expected) in str(err) and repr(actual) in str(err)


def test_check_policy_without_dt_does_not_check_dt(tmp_path):
    m = load_mission(write(tmp_path, replace("dt_s = 2.0\n", "")))
    m.check_policy(2, 10.0, 0.5, 20.0)


def test_a_policy_for_another_number_of_vehicles_says_what_to_do(tmp_path):
    m = load_mission(write(tmp_path, VALID))
    with pytest.raises(VehicleCountMismatch) as info:
        m.check_policy((3, 3), 10.0, 2.0, 20.0)
    err = info.value
    assert isinstance(err, PolicySpecMismatch)
    assert (err.field, err.expected, err.actual) == ("number of vehicles", 3, 2)
    assert "this policy flies 3 vehicles; the mission has 2" in str(err)
    assert "use a generalist policy (--policy generalist) or a mission of 3" in str(err)


@pytest.mark.parametrize("uavs", [(1, 50), (2, 2), (2, 8)])
def test_check_policy_takes_any_count_inside_the_policys_range(tmp_path, uavs):
    load_mission(write(tmp_path, VALID)).check_policy(uavs, 10.0, 2.0, 20.0)


@pytest.mark.parametrize(
    ("uavs", "fix"), [((3, 50), "give it at least 3"), ((1, 1), "a mission of 1")]
)
def test_check_policy_refuses_a_count_outside_the_range(tmp_path, uavs, fix):
    with pytest.raises(VehicleCountMismatch) as info:
        load_mission(write(tmp_path, VALID)).check_policy(uavs, 10.0, 2.0, 20.0)
    assert fix in str(info.value) and info.value.uav_range == uavs


def test_too_many_vehicles_for_a_generalist(tmp_path):
    err = VehicleCountMismatch("m.toml", (1, 50), 60)
    assert str(err) == (
        "m.toml: number of vehicles: this policy flies 1 to 50 vehicles; the mission has 60: "
        "split it into missions of at most 50"
    )
    assert err.expected == (1, 50) and err.actual == 60


@pytest.mark.parametrize(("first", "second"), [(0, 0), (1, 2), (1, 1)])
def test_check_policy_refuses_bad_slots(tmp_path, first, second):
    text = replace("system_id = 7\nslot = 1", f"system_id = 7\nslot = {first}")
    text = replace("system_id = 3\nslot = 0", f"system_id = 3\nslot = {second}", text)
    m = load_mission(write(tmp_path, text))
    with pytest.raises(MissionError) as info:
        m.check_policy(2, 10.0, 2.0, 20.0)
    assert info.value.key == "vehicle.slot"
    assert "0..1" in str(info.value)
    assert not isinstance(info.value, PolicySpecMismatch)


# -- scenarios ------------------------------------------------------------------------------


def test_from_scenario_3u2o():
    cfg = load_scenario("3u2o")
    m = Mission.from_scenario(cfg, ORIGIN)
    layout = swarm_layout(cfg)
    assert m.origin == ORIGIN and m.speed_m_s == cfg.uav.speed_m_s and m.dt_s == cfg.dt_s
    assert m.geofence is None and "3u2o" in m.source
    assert [(v.system_id, v.slot, v.alt_m) for v in m.vehicles] == [
        (1, 0, DEFAULT_ALT_M),
        (2, 1, DEFAULT_ALT_M),
        (3, 2, DEFAULT_ALT_M),
    ]
    # sim frame: x east, y north → north = y, east = x
    expected = np.stack([layout.targets_m[:, 1], layout.targets_m[:, 0]], axis=-1)
    np.testing.assert_array_equal(m.targets_ne_m(), expected)
    np.testing.assert_array_equal(m.targets_ne_m(), sim_to_ne(layout.targets_m))
    assert np.all(m.targets_ne_m()[:, 1] == cfg.uav.target_x_m)  # every target 270 m east
    m.check_policy(cfg.uav.count, cfg.uav.speed_m_s, cfg.dt_s, cfg.d_col_m)


def test_from_scenario_with_a_drawn_episode_flies_its_targets():
    family = Family("drawn", "crossing", uavs=6, formation="random")
    cfg, episode = sample_family(family, 3, [0])
    m = Mission.from_scenario(cfg, ORIGIN, episode=episode)
    assert [v.slot for v in m.by_slot()] == list(range(6))
    np.testing.assert_array_equal(m.targets_ne_m(), sim_to_ne(episode.target_m[0]))
    m.check_policy((1, 50), cfg.uav.speed_m_s, cfg.dt_s, cfg.d_col_m)


def test_vehicles_fly_in_their_groups(tmp_path):
    m = load_mission(write(tmp_path, replace("alt_m = 25.0", "alt_m = 25.0\ngroup = 1")))
    assert m.by_slot()[1].group == 1 and m.by_slot()[0].group == 0  # the default
    assert m.groups() == (0, 1)
    assert load_mission(write(tmp_path, VALID)).groups() == (0, 0)


def test_from_scenario_keeps_the_families_swarms():
    cfg, episode = sample_family(Family("two", "swarms", uavs=5), 0, [0])
    m = Mission.from_scenario(cfg, ORIGIN, episode=episode)
    assert m.groups() == cfg.uav.groups == (0, 0, 0, 1, 1)


def test_from_scenario_alt_and_initial_yaw():
    cfg = load_scenario("3u2o")
    m = Mission.from_scenario(cfg, ORIGIN, alt_m=35.0)
    assert {v.alt_m for v in m.vehicles} == {35.0}
    spawn = sim_to_ne(swarm_layout(cfg).positions_m)
    # targets are straight east of each spawn: NED yaw π/2
    np.testing.assert_allclose(initial_yaw_rad(m, spawn), math.pi / 2)


def test_example_mission_file_is_the_3u2o_scenario():
    example = load_mission(EXAMPLE)
    scenario = Mission.from_scenario(load_scenario("3u2o"), DEFAULT_HOME)
    assert example.origin == DEFAULT_HOME == scenario.origin
    assert example.speed_m_s == scenario.speed_m_s and example.dt_s == scenario.dt_s
    assert [(v.system_id, v.slot, v.alt_m) for v in example.by_slot()] == [
        (v.system_id, v.slot, v.alt_m) for v in scenario.by_slot()
    ]
    np.testing.assert_allclose(example.targets_ne_m(), scenario.targets_ne_m(), atol=0.01)
    assert example.geofence == Geofence(radius_m=600.0, polygon_ne_m=None, max_alt_m=60.0)
    example.check_policy(3, 10.0, 2.0, 20.0)
    # the whole flight (spawns and targets, at cruise height) lies inside the fence
    fence = example.geofence
    assert fence is not None
    for ne in [
        *sim_to_ne(swarm_layout(load_scenario("3u2o")).positions_m),
        *example.targets_ne_m(),
    ]:
        assert fence.inside(ne, 20.0)


# -- geofence -------------------------------------------------------------------------------


def test_circle_fence():
    fence = Geofence(radius_m=100.0)
    assert fence.inside(np.array([0.0, 0.0]))
    assert fence.inside(np.array([60.0, -80.0]))  # exactly on the circle: inside
    assert not fence.inside(np.array([60.0, -80.1]))
    assert not fence.inside(np.array([-100.0, 1.0]))
    assert fence.inside(np.array([0.0, 99.0]), alt_m=1e6)  # no ceiling


def test_ceiling():
    fence = Geofence(max_alt_m=60.0)
    assert fence.inside(np.array([1e5, -1e5]))  # no horizontal limit
    assert fence.inside(np.array([0.0, 0.0]), 60.0)
    assert not fence.inside(np.array([0.0, 0.0]), 60.5)
    assert fence.inside(np.array([0.0, 0.0]), None)  # height unknown: not judged
    both = Geofence(radius_m=10.0, max_alt_m=5.0)
    assert not both.inside(np.array([20.0, 0.0]), 1.0)
    assert not both.inside(np.array([1.0, 0.0]), 6.0)
    assert both.inside(np.array([1.0, 0.0]), 4.0)


SQUARE = ((0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (0.0, 100.0))
# An "L" (concave): the square minus its north-east quarter (n > 50 and e > 50).
ELL = ((0.0, 0.0), (100.0, 0.0), (100.0, 50.0), (50.0, 50.0), (50.0, 100.0), (0.0, 100.0))


@pytest.mark.parametrize(
    ("polygon", "point", "inside"),
    [
        (SQUARE, (50.0, 50.0), True),
        (SQUARE, (1.0, 99.0), True),
        (SQUARE, (-1.0, 50.0), False),
        (SQUARE, (50.0, 101.0), False),
        (SQUARE, (150.0, 150.0), False),
        (ELL, (25.0, 25.0), True),
        (ELL, (75.0, 25.0), True),  # the northern arm
        (ELL, (25.0, 75.0), True),  # the eastern arm
        (ELL, (75.0, 75.0), False),  # the notch
        (ELL, (99.0, 51.0), False),
        (ELL, (51.0, 99.0), False),
        (ELL, (49.0, 99.0), True),
        (ELL, (-5.0, 25.0), False),
    ],
)
def test_polygon_fence(polygon, point, inside):
    assert Geofence(polygon_ne_m=polygon).inside(np.array(point)) is inside
    # the vertex order (clockwise or counter-clockwise) does not matter
    assert Geofence(polygon_ne_m=polygon[::-1]).inside(np.array(point)) is inside


def test_polygon_and_circle_both_apply():
    fence = Geofence(radius_m=60.0, polygon_ne_m=SQUARE)
    assert fence.inside(np.array([30.0, 30.0]))
    assert not fence.inside(np.array([-10.0, 10.0]))  # in the circle, outside the square
    assert not fence.inside(np.array([90.0, 90.0]))  # in the square, outside the circle


@given(st.floats(-200.0, 200.0), st.floats(-200.0, 200.0))
def test_polygon_fence_matches_a_rectangle(n, e):
    rect = ((-50.0, -120.0), (80.0, -120.0), (80.0, 30.0), (-50.0, 30.0))
    expected = -50.0 < n < 80.0 and -120.0 < e < 30.0
    on_edge = n in (-50.0, 80.0) or e in (-120.0, 30.0)
    if not on_edge:
        assert Geofence(polygon_ne_m=rect).inside(np.array([n, e])) is expected


def test_check_policy_refuses_targets_closer_than_d_col_plus_margin(tmp_path):
    m = load_mission(write(tmp_path, VALID))
    gap = float(np.hypot(*(m.targets_ne_m()[0] - m.targets_ne_m()[1])))
    m.check_policy(2, 10.0, 2.0, gap / 1.5)  # exactly at the margin: accepted
    with pytest.raises(MissionError) as info:
        m.check_policy(2, 10.0, 2.0, gap / 1.4)
    assert info.value.key == "vehicle.target"
    assert "apart" in str(info.value) and "hover" in str(info.value)
