"""Could a UAV have seen its UAV–UAV collision coming, from its own observation alone?

    OMP_NUM_THREADS=1 python tools/own_view_collisions.py      # the default generalist, 3 families
    OMP_NUM_THREADS=1 python tools/own_view_collisions.py --policy FILE --families dense-10u
        [--episodes 40] [--horizon 4] [--lags 3]

Flies the first ``--episodes`` episodes of each family as ``remarl-fc eval --suite standard``
does (no shield; an episode ends at its first collision). At every decision it predicts, from
each UAV's own version-2 observation, the closest approach to each neighbour in its rows over
``--horizon`` seconds (`policies.own_view.OwnView`: its own arc for the action, each neighbour
straight on): for the action the policy chose, and for 17 actions evenly spread over [−1, 1].

For every UAV of every episode whose first collision is between UAVs, and for the decisions
0 … ``--lags`` steps before it, it counts the UAVs whose chosen action was predicted to come
within d_col of a neighbour ("foreseen"), and of those the ones for which another action was
predicted to keep d_col ("avoidable"). The last line gives the same shares over every decision
flown: how rare the states are that such a prediction flags.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from policies.config import GeneralistConfig
from policies.own_view import OwnView
from remarl_fc.offline.rollout import PolicyFileAct, observe_for
from remarl_fc.offline.suite import MethodSpec, resolve_method
from sim.encounters import sample_family
from sim.suite import load_suite
from sim.swarm import SwarmSim

GRID = np.linspace(-1.0, 1.0, 17)
"""The actions tried beside the chosen one (normalised heading changes)."""

DEFAULT_FAMILIES = "beyond-50u8o,crossing-50u,dense-10u"
"""The families where the shipped generalist's UAV–UAV collisions are (RESULTS)."""


def nearest_predicted(view: OwnView, obs: np.ndarray, action: np.ndarray) -> np.ndarray:
    """(...) the closest predicted approach to any neighbour, m, of ``action`` (...) at ``obs``."""
    with torch.no_grad():
        closest = view.closest(torch.from_numpy(obs), torch.from_numpy(action.astype(np.float32)))
    return closest.min(dim=-1).values.numpy()


def family_counts(
    policy: str, family_name: str, episodes: int, horizon_s: float, lags: int
) -> tuple[int, int, np.ndarray, tuple[int, int, int]]:
    """(episodes, first UAV–UAV collisions, per lag [UAVs, foreseen, avoidable], base rates).

    The base rates: decisions flown, foreseen, avoidable.
    """
    suite = load_suite("standard")
    family = suite.family(family_name)
    cfg, batch = sample_family(family, suite.seed, range(episodes))
    act, why = resolve_method(MethodSpec.from_label(f"policy:{policy}"), family, cfg)
    if not isinstance(act, PolicyFileAct) or act.layout is None:
        raise SystemExit(f"{policy} is not a generalist that flies {family_name}: {why}")
    view = OwnView.of(act.layout, [cfg], horizon_s, factor=GeneralistConfig().separation_factor)
    sim = SwarmSim(cfg, scored=False)
    rng = np.random.default_rng(0)
    state = sim.start(batch, rng)
    d_col = cfg.d_col_m
    history: list[tuple[np.ndarray, np.ndarray]] = []  # per step: (foreseen, avoidable) (B, N)
    flown = [0, 0, 0]
    open_ = np.ones(state.pos_m.shape[0], dtype=bool)
    events: list[tuple[int, int, np.ndarray]] = []
    for step in range(cfg.max_steps):
        obs = observe_for(sim, state, act)
        action = act(obs, state, cfg)
        chosen = nearest_predicted(view, obs, action)
        best = np.max(
            [nearest_predicted(view, obs, np.full(action.shape, a)) for a in GRID], axis=0
        )
        foreseen = chosen < d_col
        avoidable = foreseen & (best >= d_col)
        history.append((foreseen, avoidable))
        live = state.active & open_[:, None]
        flown[0] += int(live.sum())
        flown[1] += int((foreseen & live).sum())
        flown[2] += int((avoidable & live).sum())
        state, r = sim.step(state, action, rng)
        hit = open_ & r.collided_u2u.any(axis=1)
        events += [(int(b), step, np.flatnonzero(r.collided_u2u[b])) for b in np.flatnonzero(hit)]
        open_ &= ~(r.collided_u2u.any(axis=1) | r.collided_u2o.any(axis=1))
        open_ &= ~(r.terminated | r.truncated)
        if not open_.any():
            break
    per_lag = np.zeros((lags + 1, 3), dtype=np.int64)
    for b, step, uavs in events:
        for lag in range(min(lags, step) + 1):
            foreseen, avoidable = history[step - lag]
            per_lag[lag] += (len(uavs), foreseen[b, uavs].sum(), avoidable[b, uavs].sum())
    return episodes, len(events), per_lag, (flown[0], flown[1], flown[2])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--policy", default="generalist", help="a zoo name or a generalist file")
    p.add_argument("--families", default=DEFAULT_FAMILIES, help="comma-separated suite families")
    p.add_argument("--episodes", type=int, default=40, help="the first N of each family")
    p.add_argument("--horizon", type=float, default=4.0, help="seconds predicted")
    p.add_argument("--lags", type=int, default=3, help="decisions before the collision")
    args = p.parse_args()
    print("| family | episodes | UAV–UAV first | decisions before | UAVs | foreseen | avoidable |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    base = np.zeros(3, dtype=np.int64)
    for name in args.families.split(","):
        episodes, collisions, per_lag, flown = family_counts(
            args.policy, name, args.episodes, args.horizon, args.lags
        )
        base += flown
        for lag, (uavs, foreseen, avoidable) in enumerate(per_lag):
            cells = (name, episodes, collisions, lag, uavs, foreseen, avoidable)
            print("| " + " | ".join(str(c) for c in cells) + " |")
    print(
        f"every decision flown: {base[0]}; foreseen {base[1] / max(base[0], 1):.2%}, "
        f"avoidable {base[2] / max(base[0], 1):.2%}"
    )


if __name__ == "__main__":
    main()
