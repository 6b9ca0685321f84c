"""Any number of vehicles: a generalist (version-2) policy flown closed loop on the mock.

Random weights: success is not expected, only that the runtime flies any N without failing,
decides with the right shapes, and shows the vehicles to each other. The closed-loop flights
fly a stand-in with `remarl_fc.policy_io.Policy`'s generalist API (``layout``, ``generalist``,
``uav_range``, ``act``, ``check_scenario``, ``meta``) over `sim.setnet`'s numpy forward, which
records what it is shown; ``demo --vehicles N --policy PATH`` flies a tiny generalist file
(`tiny_policy.write_tiny_generalist`) through the real loader.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from remarl_fc.cli import main
from remarl_fc.demo import drawn_encounter
from remarl_fc.demo import fly_on_mock as demo_flight
from remarl_fc.errors import ConfigError, PolicySpecMismatch
from remarl_fc.flight.control import ControlSpec
from remarl_fc.flight.mission import VehicleCountMismatch
from remarl_fc.frames import sim_to_ne
from remarl_fc.policy_io import Policy, load_policy
from remarl_fc.sitl.config import SitlConfig
from remarl_fc.sitl.fleet import SitlFleet
from sim.config import ScenarioConfig
from sim.observation import ObservationLayout
from sim.scenarios import load_scenario
from sim.setnet import set_actor, set_shapes
from sim.spawn import spawn_episodes

SPEEDUP = 4.0
MAX_FLIGHT_S = 12.0
"""Seconds under control of each random-weight flight (6 decisions)."""


class StandInGeneralist:
    """A generalist policy: one random set network for every vehicle, any N from 1 to 50.

    Args:
        seed: draws the weights. straight: zero output weights (every action 0: straight to
            the targets), for flights that must end on their own.
    """

    generalist = True
    uav_range = (1, 50)
    checksum = ""  # written by no file
    summary = Policy.summary  # what a flight's summary says of it, as of a loaded file
    sees_neighbours = Policy.sees_neighbours  # the shield's track growth behind it

    def __init__(self, seed: int = 0, *, straight: bool = False, hidden: int = 8) -> None:
        self.source = f"stand-in generalist {seed}"
        self.layout = ObservationLayout(
            max_obstacles=8,
            range_m=100.0,
            aperture_rad=math.radians(270.0),
            speed_m_s=10.0,
            max_neighbours=6,
            version=2,
        )
        rng = np.random.default_rng(seed)
        self.actor = {
            name: (
                rng.normal(0.0, 0.5, (1, n_in, n_out)).astype(np.float32),
                rng.normal(0.0, 0.1, (1, 1, n_out)).astype(np.float32),
            )
            for name, (n_in, n_out) in set_shapes(hidden, critic=False).items()
        }
        if straight:
            w, b = self.actor["out"]
            self.actor["out"] = (np.zeros_like(w), np.zeros_like(b))
        self.meta: dict[str, Any] = {
            "speed_m_s": 10.0,
            "dt_s": 2.0,
            "d_col_m": 20.0,
            "action": {"max_turn_rad": math.pi / 4},
            "scenario_config": {"field": {"swarm_lead_m": 40.0}},
        }
        self.seen: list[NDArray[np.float32]] = []
        self.actions: list[NDArray[np.float32]] = []

    def act(self, obs: NDArray[np.floating[Any]]) -> NDArray[np.float32]:
        x = np.array(obs, dtype=np.float32)
        out = set_actor(self.actor, x, self.layout)
        self.seen.append(x)
        self.actions.append(out)
        return out

    def check_scenario(self, cfg: ScenarioConfig) -> None:
        lo, hi = self.uav_range
        if not lo <= cfg.uav.count <= hi:
            raise PolicySpecMismatch(self.source, "number of UAVs", self.uav_range, cfg.uav.count)


def use_policy(monkeypatch: pytest.MonkeyPatch, policy: StandInGeneralist, name: str) -> None:
    """The demo loads ``policy`` for ``name`` (any other name: the real loader)."""
    import remarl_fc.demo

    real = remarl_fc.demo.load_policy
    monkeypatch.setattr(
        remarl_fc.demo, "load_policy", lambda given: policy if given == name else real(given)
    )


def neighbour_count(layout: ObservationLayout, obs: NDArray[np.floating[Any]]) -> Any:
    """Neighbour rows in use in flat observations (..., size)."""
    return np.asarray(obs)[..., layout.blocks()["neighbour_mask"]].sum(axis=-1)


LOG_ROUNDING_M, LOG_ROUNDING_RAD = 0.05, 1e-3
"""Slack for the decision log's rounding (positions to 1 cm, headings to 1e-4 rad): a vehicle
that close to the edge of the range or the aperture may be seen either way."""


def expected_neighbours(
    layout: ObservationLayout, rows: list[dict[str, Any]]
) -> list[tuple[int, int]]:
    """Per vehicle of one decision's log rows: the fewest and most others it can see in its
    range and aperture (≤ k), the most counting those on the edge within the log's rounding."""
    flown = [r for r in rows if r["status"] in ("controlled", "reached")]
    out = []
    for r in rows:
        heading = r["heading_rad"]
        ahead = np.array([math.cos(heading), math.sin(heading)])  # simulator frame
        sure = maybe = 0
        for o in flown:
            if o is r:
                continue
            d = sim_to_ne(np.array(o["ne_m"]) - np.array(r["ne_m"]))  # (east, north) = (x, y)
            dist = float(np.hypot(*d))
            bearing = math.acos(max(-1.0, min(1.0, float(d @ ahead) / max(dist, 1e-9))))
            half = layout.aperture_rad / 2
            if dist <= layout.range_m - LOG_ROUNDING_M and bearing <= half - LOG_ROUNDING_RAD:
                sure += 1
            elif dist <= layout.range_m + LOG_ROUNDING_M and bearing <= half + LOG_ROUNDING_RAD:
                maybe += 1
        k = layout.max_neighbours
        out.append((min(sure, k), min(sure + maybe, k)))
    return out


# -- closed loop --------------------------------------------------------------------------


@pytest.mark.asyncio
@pytest.mark.network
@pytest.mark.timeout(180)
@pytest.mark.parametrize("n", [1, 4, 7])
async def test_a_generalist_flies_any_number_of_vehicles_on_the_mock(n, tmp_path, monkeypatch):
    policy = StandInGeneralist(seed=n)
    use_policy(monkeypatch, policy, "stand-in.safetensors")
    flight = await demo_flight(
        policy="stand-in.safetensors",
        vehicles=n,
        intruders=2,
        seed=n,
        speedup=SPEEDUP,
        quick_start=True,
        log_dir=tmp_path,
        fly_options={"max_flight_s": MAX_FLIGHT_S},
    )
    truth, summary = flight.ground_truth, flight.runtime
    assert len(truth["vehicles"]) == n and truth["intruders"] == 2
    assert len(summary["vehicles"]) == n
    # the flight ran its course and ended with every vehicle held or at its target
    assert summary["decisions"] >= 3
    assert {v["status"] for v in summary["vehicles"]} <= {"held", "reached"}
    assert all(v["flew"] for v in truth["vehicles"])
    # one decision per dt: (1, N, size) observations in, (1, N) actions out
    assert len(policy.seen) == summary["decisions"]
    for obs, action in zip(policy.seen, policy.actions, strict=True):
        assert obs.shape == (1, n, policy.layout.size) and action.shape == (1, n)
        assert np.isfinite(obs).all() and (np.abs(action) <= 1.0).all()
    # the decision log: each vehicle sees the others in its range and aperture, no more
    rows = [json.loads(line) for line in (tmp_path / "decisions.jsonl").read_text().splitlines()]
    decisions: dict[float, list[dict[str, Any]]] = {}
    for row in rows:
        if "action" in row:
            decisions.setdefault(row["t"], []).append(row)
    assert len(decisions) == summary["decisions"]
    seen_any = 0
    for t, step in decisions.items():
        got = [int(neighbour_count(policy.layout, np.array(r["obs"]))) for r in step]
        bounds = expected_neighbours(policy.layout, step)
        assert all(lo <= g <= hi for g, (lo, hi) in zip(got, bounds, strict=True)), (t, got, bounds)
        seen_any += sum(got)
    assert (seen_any > 0) == (n > 1)


@pytest.mark.asyncio
async def test_a_version_1_policy_refuses_another_number_of_vehicles():
    with pytest.raises(VehicleCountMismatch) as info:
        await demo_flight(policy="3u2o", vehicles=5)
    text = str(info.value)
    assert "this policy flies 3 vehicles; the mission has 5" in text
    assert "use a generalist policy (--policy generalist) or a mission of 3" in text


# -- the demo's command line --------------------------------------------------------------


@pytest.mark.network
@pytest.mark.timeout(180)
def test_demo_vehicles_with_a_generalist_file(tmp_path, capsys):
    from tiny_policy import write_tiny_generalist

    path = write_tiny_generalist(tmp_path / "g.safetensors", seed=3)
    out = tmp_path / "flight.png"
    status = main(
        ["demo", "--vehicles", "5", "--intruders", "3", "--seed", "4", "--json",
         "--policy", str(path), "--speedup", "4", "--out", str(out), "--log", str(tmp_path),
         "--summary", str(tmp_path / "truth.json")]
    )  # fmt: skip
    result = json.loads(capsys.readouterr().out)
    assert status in (0, 4)  # random weights: reaching the targets is not expected
    truth = result["ground_truth"]
    assert truth["intruders"] == 3 and truth["scenario"] == "random 5u3o"
    vehicles = json.loads((tmp_path / "truth.json").read_text())["vehicles"]
    assert len(vehicles) == 5 and all(v["flew"] for v in vehicles)
    assert result["plot"]["vehicles"] == [1, 2, 3, 4, 5]
    assert result["plot"]["intruders"] == 3 and out.stat().st_size > 10_000
    # at most the drawn episode's step limit under control (40 steps of 2 s)
    assert 5 <= result["runtime"]["decisions"] <= 41
    layout = load_policy(path).layout
    assert layout.version == 2
    rows = [json.loads(line) for line in (tmp_path / "decisions.jsonl").read_text().splitlines()]
    decided = [r for r in rows if "action" in r]
    assert len(decided) == 5 * result["runtime"]["decisions"]
    assert all(len(r["obs"]) == layout.size for r in decided)
    assert any(neighbour_count(layout, np.array(r["obs"])) for r in decided)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--vehicles", "5", "--policy", "3u2o"],
            "this policy flies 3 vehicles; the mission has 5: use a generalist policy",
        ),
        (["--vehicles", "21"], "must be 1 to 20"),
        (["--vehicles", "3", "--intruders", "9"], "must be 0 to 8"),
        (["--vehicles", "3", "--scenario", "3u2o"], "not both"),
        (["--intruders", "3"], "--intruders goes with --vehicles"),
    ],
)
def test_demo_refuses_what_it_cannot_fly(args, message, capsys):
    try:
        status = main(["demo", *args])
    except SystemExit as exc:  # argparse's own refusal
        status = int(exc.code or 0)
    assert status == 2
    assert message in capsys.readouterr().err


# -- the drawn geometry and the mock ------------------------------------------------------

SPEC = ControlSpec(speed_m_s=10.0, dt_s=2.0, max_turn_rad=math.pi / 4, lead_m=40.0, arrival_m=20.0)


def test_drawn_encounters_are_the_seeds():
    cfg, ep = drawn_encounter(7, 3, 11, SPEC)
    assert (cfg.uav.count, cfg.obstacles.count) == (7, 3)
    assert ep.start_m.shape == (1, 7, 2) and ep.obstacle_pos_m.shape == (1, 3, 2)
    assert (cfg.uav.speed_m_s, cfg.dt_s, cfg.d_col_m) == (10.0, 2.0, 20.0)
    _, again = drawn_encounter(7, 3, 11, SPEC)
    _, other = drawn_encounter(7, 3, 12, SPEC)
    np.testing.assert_array_equal(ep.start_m, again.start_m)
    np.testing.assert_array_equal(ep.obstacle_vel_m_s, again.obstacle_vel_m_s)
    assert not np.array_equal(ep.start_m, other.start_m)
    with pytest.raises(ConfigError):
        drawn_encounter(21, 2, 0, SPEC)


def test_the_mock_flies_the_episode_it_is_given():
    cfg, ep = drawn_encounter(6, 4, 1, SPEC)
    fleet = SitlFleet(SitlConfig(vehicles=6, base_port=0), scenario=cfg, episode=ep)
    np.testing.assert_allclose(fleet.frames.pos_ned_m[:, :2], sim_to_ne(ep.start_m[0]))
    assert fleet.truth.targets is not None
    np.testing.assert_allclose(fleet.truth.targets, sim_to_ne(ep.target_m[0]))
    assert fleet.traffic is not None and fleet.traffic.count == 4
    np.testing.assert_allclose(fleet.traffic.spawn_ne_m, sim_to_ne(ep.obstacle_pos_m[0]))
    np.testing.assert_allclose(fleet.traffic.vel_ne_m_s, sim_to_ne(ep.obstacle_vel_m_s[0]))


def test_a_scenarios_mock_draws_its_episode_as_the_simulator_does():
    cfg = load_scenario("5u2o")
    fleet = SitlFleet(SitlConfig(vehicles=5, base_port=0, seed=9), scenario=cfg)
    ep = spawn_episodes(cfg, np.random.default_rng(9), 1)
    np.testing.assert_allclose(fleet.frames.pos_ned_m[:, :2], sim_to_ne(ep.start_m[0]))
    assert fleet.traffic is not None
    np.testing.assert_array_equal(fleet.traffic.spawn_ne_m, sim_to_ne(ep.obstacle_pos_m[0]))
    np.testing.assert_array_equal(fleet.traffic.vel_ne_m_s, sim_to_ne(ep.obstacle_vel_m_s[0]))


def test_demo_policy_switches_to_the_shipped_generalist(tmp_path, monkeypatch):
    import remarl_fc.demo
    from remarl_fc.demo import demo_policy

    monkeypatch.setattr(remarl_fc.demo, "zoo_dir", lambda: tmp_path)
    assert demo_policy("3u2o") == "3u2o"
    (tmp_path / "robust").mkdir()
    (tmp_path / "robust" / "3u2o.safetensors").touch()
    assert demo_policy("3u2o") == "robust/3u2o"
    (tmp_path / "generalist.safetensors").touch()
    assert demo_policy("3u2o") == "generalist"  # on a scenario and on drawn vehicles alike


def test_the_stand_in_is_the_policy_api():
    """Guard: what this file assumes of a generalist is what the controller reads."""
    p = StandInGeneralist()
    obs = np.zeros((2, 3, p.layout.size), dtype=np.float32)
    assert p.act(obs).shape == (2, 3)
    spec = ControlSpec.from_policy_meta(p.meta)
    assert spec == SPEC
    assert p.summary() == {
        "name": "stand-in generalist 0",
        "checksum": "",
        "generalist": True,
        "vehicles": [1, 50],
    }
