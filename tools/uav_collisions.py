"""Where a policy's UAV–UAV collisions happen on the suite: in flight, or against a UAV that hovers.

    OMP_NUM_THREADS=1 python tools/uav_collisions.py                     # the default generalist
    OMP_NUM_THREADS=1 python tools/uav_collisions.py --policy FILE --families dense-10u,swarms-2x5

Each family's episodes are flown as ``remarl-fc eval --suite standard`` flies them (no shield;
an episode ends at its first collision). For every episode whose first collision is between
two UAVs, it tells whether one of them had already arrived and hovered at its target
(``arrival = "hover"``), or arrived during that step. A minute for the whole suite on one core.
"""

from __future__ import annotations

import argparse

import numpy as np

from remarl_fc.offline.rollout import observe_for
from remarl_fc.offline.suite import MethodSpec, resolve_method
from sim.encounters import sample_family
from sim.suite import load_suite
from sim.swarm import SwarmSim


def family_counts(policy: str, family_name: str, suite_name: str) -> tuple[int, int, int, int]:
    """(episodes, first collisions UAV–UAV, of them with a hovering UAV, with one arriving)."""
    suite = load_suite(suite_name)
    family = suite.family(family_name)
    cfg, batch = sample_family(family, suite.seed, range(suite.episodes))
    act, why = resolve_method(MethodSpec.from_label(f"policy:{policy}"), family, cfg)
    if act is None:
        raise SystemExit(f"{policy} cannot fly {family_name}: {why}")
    sim = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(0)
    state = sim.start(batch, rng)
    episodes = state.pos_m.shape[0]
    open_ = np.ones(episodes, dtype=bool)  # no collision and not over yet
    uu = hovering = arriving = 0
    for _ in range(cfg.max_steps):
        before = state.reached.copy()
        action = act(observe_for(sim, state, act), state, cfg)
        assert not isinstance(action, tuple)  # a policy file chooses headings, not speeds
        state, r = sim.step(state, action, rng)
        hit = open_ & r.collided_u2u.any(axis=1)
        uu += int(hit.sum())
        hov = hit & (r.collided_u2u & before).any(axis=1)
        hovering += int(hov.sum())
        arriving += int((hit & ~hov & (r.collided_u2u & r.arrived).any(axis=1)).sum())
        open_ &= ~(r.collided_u2u.any(axis=1) | r.collided_u2o.any(axis=1))
        open_ &= ~(r.terminated | r.truncated)
        if not open_.any():
            break
    return episodes, uu, hovering, arriving


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--policy", default="generalist", help="a zoo name or a policy file")
    p.add_argument("--suite", default="standard")
    p.add_argument("--families", default="", help="comma-separated; default: every family")
    args = p.parse_args()
    suite = load_suite(args.suite)
    names = args.families.split(",") if args.families else [f.name for f in suite.families]
    print("| family | episodes | UAV–UAV first | with a hovering UAV | with one arriving |")
    print("|---|---:|---:|---:|---:|")
    total = np.zeros(4, dtype=np.int64)
    for name in names:
        counts = family_counts(args.policy, name, args.suite)
        total += counts
        if counts[1]:
            print(f"| {name} | " + " | ".join(str(c) for c in counts) + " |", flush=True)
    print("| **all** | " + " | ".join(str(int(c)) for c in total) + " |")


if __name__ == "__main__":
    main()
