"""`remarl-fc demo --scenario S` succeeds for every scenario with a zoo policy: flown by the
demo's default, the generalist, on both flavours, and by the scenario's own zoo policy.

(The generalist on drawn encounters, ``demo --vehicles N``:
tests/remarl_fc/test_generalist_flight.py.)

Each flight is the demo's own (`remarl_fc.demo.fly_on_mock`: the mock's fitted vehicles), with
ArduCopter's slow start skipped, run 4× faster than real time (2× from 7 vehicles on: a loaded
CI machine must keep up with their 50 Hz physics and the runtime's setpoints); the exit status
is the demo's, judged on the mock's ground truth. The scenario policies fly the ArduPilot
flavour only: the PX4 flavour's flights are the generalist's.
"""

from __future__ import annotations

import pytest

from remarl_fc.cli.fly import demo_exit_status
from remarl_fc.demo import demo_policy, fly_on_mock, scenario_policy
from remarl_fc.policy_io import zoo_names
from sim.scenarios import load_scenario, scenario_names

pytestmark = [pytest.mark.asyncio, pytest.mark.network, pytest.mark.timeout(240)]


SCENARIOS = [n for n in zoo_names() if n in scenario_names()]
"""Every scenario with a zoo policy of its own."""


def speedup(scenario: str) -> float:
    """4× real time, 2× for swarms of 7 or more."""
    return 4.0 if load_scenario(scenario).uav.count < 7 else 2.0


FLIGHTS = [
    *[(scenario, flavour, None) for flavour in ("ardupilot", "px4") for scenario in SCENARIOS],
    *[(scenario, "ardupilot", scenario_policy(scenario)) for scenario in SCENARIOS],
]
"""(scenario, flavour, policy): None is the demo's default."""


@pytest.mark.parametrize(("scenario", "flavour", "policy"), FLIGHTS)
async def test_the_demo_exits_0_on_every_scenario_with_a_zoo_policy(scenario, flavour, policy):
    flight = await fly_on_mock(
        scenario, policy, flavour=flavour, speedup=speedup(scenario), quick_start=True
    )
    truth = flight.ground_truth
    overall = {k: v for k, v in truth.items() if k != "vehicles"}
    assert flight.runtime["policy"]["name"] == (policy or demo_policy(scenario))
    assert demo_exit_status(truth) == 0, overall
    assert truth["min_vehicle_intruder_m"] >= truth["d_col_m"], overall
    assert truth["min_vehicle_vehicle_m"] >= truth["d_col_m"], overall
