"""Where a policy's UAV–UAV collisions happen on the suite: in flight, or against a UAV that hovers.

    OMP_NUM_THREADS=1 python tools/uav_collisions.py                     # the default generalist
    OMP_NUM_THREADS=1 python tools/uav_collisions.py --policy FILE --families dense-10u,swarms-2x5
    OMP_NUM_THREADS=1 python tools/uav_collisions.py --real-world        # the 8 paper scenarios
    OMP_NUM_THREADS=1 python tools/uav_collisions.py --shield            # behind the shield

``--real-world`` flies the suite's paper scenarios in the world of RESULTS "The generalist in
the real world" (`REAL_WORLD_FLOWN`: ``remarl-fc eval --scenario S --dynamics arducopter
--sensors adsb --arrival hover``; 300 episodes each, drawn from seed 0, not the evaluation's,
no shield): there an arrived vehicle brakes with the fitted response and may stop past the
edge of its arrival circle.

Each family's episodes are flown as ``remarl-fc eval --suite standard`` flies them (no shield;
an episode ends at its first collision). For every episode whose first collision is between
two UAVs, it tells whether one of them had already arrived and hovered at its target
(``arrival = "hover"``), or arrived during that step. A minute for the whole suite on one core.

``--shield`` flies behind the safety shield at its defaults (``remarl-fc eval --shield on``, its
swarm planner included, `remarl_fc.offline.shielding.Shielded`) and adds a column: the
collisions where, for one of the two UAVs at least, no candidate passed the shield's check at
that decision (it flew its fallback, the least dangerous candidate, or the swarm planner's
plan). Where both had one that passed, a neighbour flew other than the arc it was checked
against.
"""

from __future__ import annotations

import argparse

import numpy as np

from remarl_fc.offline.evaluate import REAL_WORLD_FLOWN, evaluation_scenario, world_overrides
from remarl_fc.offline.rollout import PolicyFileAct, observe_for
from remarl_fc.offline.shielding import Shielded
from remarl_fc.offline.suite import Act, MethodSpec, resolve_method
from remarl_fc.policy_io import load_policy
from sim.encounters import Family, sample_family
from sim.shield import ShieldConfig, track_growth_behind
from sim.state import SwarmState
from sim.suite import Suite, load_suite
from sim.swarm import SwarmSim

Counts = tuple[int, int, int, int, int]
"""(episodes, first collisions UAV–UAV, of them with a hovering UAV, with one arriving, with a
UAV for which nothing passed the shield: 0 without it)."""


def first_collisions(
    act: Act, sim: SwarmSim, state: SwarmState, shield: ShieldConfig | None = None
) -> Counts:
    """`Counts` of the episodes of ``state`` flown to their first collision or end."""
    cfg = sim.cfg
    rng = np.random.default_rng(0)
    shielded = Shielded(act, shield) if shield is not None else None  # as the suite flies it
    episodes = state.pos_m.shape[0]
    open_ = np.ones(episodes, dtype=bool)  # no collision and not over yet
    uu = hovering = arriving = unsafe = 0
    for _ in range(cfg.max_steps):
        before = state.reached.copy()
        obs = observe_for(sim, state, act)
        speeds, passed = None, np.ones(state.active.shape, dtype=bool)
        if shielded is not None:
            action, speeds = shielded(obs, state, cfg)
            assert shielded.last is not None
            passed = shielded.last.safe_exists | ~state.active
        else:
            proposed = act(obs, state, cfg)
            assert not isinstance(proposed, tuple)  # a policy file chooses headings, not speeds
            action = proposed
        state, r = sim.step(state, action, rng, speeds_m_s=speeds)
        hit = open_ & r.collided_u2u.any(axis=1)
        uu += int(hit.sum())
        hov = hit & (r.collided_u2u & before).any(axis=1)
        hovering += int(hov.sum())
        arriving += int((hit & ~hov & (r.collided_u2u & r.arrived).any(axis=1)).sum())
        unsafe += int((hit & (r.collided_u2u & ~passed).any(axis=1)).sum())
        open_ &= ~(r.collided_u2u.any(axis=1) | r.collided_u2o.any(axis=1))
        open_ &= ~(r.terminated | r.truncated)
        if not open_.any():
            break
    return episodes, uu, hovering, arriving, unsafe


def family_counts(
    policy: str, suite: Suite, family: Family, shield: ShieldConfig | None = None
) -> Counts:
    """`first_collisions` of one suite family's episodes."""
    cfg, batch = sample_family(family, suite.seed, range(suite.episodes))
    act, why = resolve_method(MethodSpec.from_label(f"policy:{policy}"), family, cfg)
    if act is None:
        raise SystemExit(f"{policy} cannot fly {family.name}: {why}")
    sim = SwarmSim(cfg, scored=False)
    return first_collisions(act, sim, sim.start(batch, np.random.default_rng(0)), shield)


def real_world_counts(
    policy: str, scenario: str, episodes: int, shield: ShieldConfig | None = None
) -> Counts:
    """`first_collisions` of a scenario's episodes in the real world (fitted ArduCopter, ADS-B)."""
    loaded = load_policy(policy)
    cfg = evaluation_scenario(loaded, scenario, world_overrides(*REAL_WORLD_FLOWN))
    sim = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(0)
    return first_collisions(PolicyFileAct(loaded), sim, sim.initial_state(rng, episodes), shield)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--policy", default="generalist", help="a zoo name or a policy file")
    p.add_argument("--suite", default="standard")
    p.add_argument("--families", default="", help="comma-separated; default: every family")
    p.add_argument("--real-world", action="store_true", help="the 8 paper scenarios, real world")
    p.add_argument("--episodes", type=int, default=300, help="per scenario (--real-world)")
    p.add_argument("--shield", action="store_true", help="behind the shield (its defaults)")
    args = p.parse_args()
    suite = load_suite(args.suite)
    growth = track_growth_behind(load_policy(args.policy).sees_neighbours)
    shield = ShieldConfig(mode="on", track_growth_m_s=growth) if args.shield else None
    if args.real_world:  # the paper scenarios, as tools/ship_generalist.py flies them
        names = suite.paper_scenarios()
    else:
        names = args.families.split(",") if args.families else [f.name for f in suite.families]
    columns = 5 if shield else 4
    head = "| family | episodes | UAV–UAV first | with a hovering UAV | with one arriving |"
    print(head + (" where nothing passed the shield |" if shield else ""))
    print("|---|" + "---:|" * columns)
    total = np.zeros(columns, dtype=np.int64)
    for name in names:
        counts = (
            real_world_counts(args.policy, name, args.episodes, shield)
            if args.real_world
            else family_counts(args.policy, suite, suite.family(name), shield)
        )[:columns]
        total += counts
        if counts[1]:
            print(f"| {name} | " + " | ".join(str(c) for c in counts) + " |", flush=True)
    print("| **all** | " + " | ".join(str(int(c)) for c in total) + " |")


if __name__ == "__main__":
    main()
