"""`FlyConfig` refuses settings that contradict the mission or the link's security."""

from __future__ import annotations

import dataclasses

import pytest

from remarl_fc.flight.config import FlyConfig
from remarl_fc.flight.mission import Geofence, Mission
from remarl_fc.mavlink.codec import SigningConfig
from remarl_fc.sitl.config import DEFAULT_HOME
from sim.scenarios import load_scenario

MISSION = dataclasses.replace(
    Mission.from_scenario(load_scenario("3u2o"), DEFAULT_HOME, 20.0),
    geofence=Geofence(radius_m=600.0, max_alt_m=60.0),
)
URL = ("udpin:127.0.0.1:14550",)


def test_a_take_off_above_the_ceiling_is_refused():
    FlyConfig(URL, MISSION, takeoff_m=60.0)
    with pytest.raises(ValueError, match=r"take-off height 500 m is above .* max_alt_m 60 m"):
        FlyConfig(URL, MISSION, takeoff_m=500.0)


def test_require_signing_without_a_key_is_refused():
    with pytest.raises(ValueError, match="--require-signing: give the link's key"):
        FlyConfig(URL, MISSION, require_signing=True)
    FlyConfig(URL, MISSION, require_signing=True, signing=SigningConfig(b"k" * 32))


def test_the_lost_timeout_must_be_positive():
    with pytest.raises(ValueError, match="lost timeout"):
        FlyConfig(URL, MISSION, lost_timeout_s=0.0)
