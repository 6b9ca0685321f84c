"""`remarl-fc demo --scenario S` succeeds for every scenario with a zoo policy, on both flavours.

(Zoo policies not named after a scenario, as the generalist, fly ``demo --vehicles N``:
tests/remarl_fc/test_generalist_flight.py.)

Each flight is the demo's own (`remarl_fc.demo.fly_on_mock`: the mock's fitted vehicles, the
demo's policy), with ArduCopter's slow start skipped, run 4× faster than real time (2× from 7
vehicles on: a loaded CI machine must keep up with their 50 Hz physics and the runtime's
setpoints); the exit status is the demo's, judged on the mock's ground truth.
"""

from __future__ import annotations

import pytest

from remarl_fc.cli.fly import demo_exit_status
from remarl_fc.demo import fly_on_mock
from remarl_fc.policy_io import zoo_names
from sim.scenarios import load_scenario, scenario_names

pytestmark = [pytest.mark.asyncio, pytest.mark.network, pytest.mark.timeout(240)]


def speedup(scenario: str) -> float:
    """4× real time, 2× for swarms of 7 or more."""
    return 4.0 if load_scenario(scenario).uav.count < 7 else 2.0


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
@pytest.mark.parametrize("scenario", [n for n in zoo_names() if n in scenario_names()])
async def test_the_demo_exits_0_on_every_scenario_with_a_zoo_policy(scenario, flavour):
    flight = await fly_on_mock(
        scenario, flavour=flavour, speedup=speedup(scenario), quick_start=True
    )
    truth = flight.ground_truth
    overall = {k: v for k, v in truth.items() if k != "vehicles"}
    assert demo_exit_status(truth) == 0, overall
    assert truth["min_vehicle_intruder_m"] >= truth["d_col_m"], overall
    assert truth["min_vehicle_vehicle_m"] >= truth["d_col_m"], overall
