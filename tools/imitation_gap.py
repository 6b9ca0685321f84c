"""How far is a generalist from its teacher on the states it flies itself? Per family, measured.

    OMP_NUM_THREADS=1 python tools/imitation_gap.py --policy FILE \\
        [--families beyond-50u8o,beyond-20u4o,...] [--episodes 10] [--teacher-horizon 20]

Flies the policy over a family's first ``--episodes`` suite episodes and, at every decision,
asks the "orca-shield" teacher (`policies.generalist_train.orca_shield_actions`, sensing as the
policy does: its layout's range and aperture) what it would do from the same state — the
labels DAgger trains on. Prints per family: the labels (UAV decisions of UAVs still flying),
the mean squared gap between the policy's action and the label, the labels' variance and the
share of it the policy explains (R² = 1 − gap / variance), and the mean |action| of each: a
policy that turns less than its teacher shows it there.
"""

from __future__ import annotations

import argparse

import numpy as np
from numpy.typing import NDArray

from policies.config import GeneralistConfig
from policies.generalist_train import orca_shield_actions, with_layout
from remarl_fc.offline.rollout import PolicyFileAct
from remarl_fc.offline.suite import fly_episodes
from remarl_fc.policy_io import load_policy
from sim.config import ScenarioConfig
from sim.encounters import Family, sample_family
from sim.state import SwarmState
from sim.suite import load_suite

FAMILIES = (
    "paper-3u2o,crossing-fast-5u,swarms-2x5,beyond-20u4o,crossing-20u,beyond-50u8o,"
    "crossing-50u,dense-10u"
)


class Recorded:
    """The policy as a suite act function that also keeps, at every decision, its actions and
    the teacher's labels of the UAVs still flying."""

    def __init__(self, act: PolicyFileAct, teacher_cfg: ScenarioConfig, horizon_s: float) -> None:
        self.act, self.teacher_cfg, self.horizon_s = act, teacher_cfg, horizon_s
        self.layout = act.layout  # `observe_for` builds the observations the policy reads
        self.mine: list[NDArray[np.float32]] = []
        self.taught: list[NDArray[np.float32]] = []

    def __call__(
        self, obs: NDArray[np.float32], state: SwarmState, cfg: ScenarioConfig
    ) -> NDArray[np.float32]:
        actions = self.act(obs, state, cfg)
        labels = orca_shield_actions(state, self.teacher_cfg, self.horizon_s)
        self.mine.append(actions[state.active])
        self.taught.append(labels[state.active])
        return actions


def gap(
    act: PolicyFileAct, family: Family, seed: int, episodes: int, horizon_s: float
) -> dict[str, float]:
    """The policy against the teacher's labels on its own states in one family."""
    cfg, batch = sample_family(family, seed, range(episodes))
    assert act.layout is not None  # main refuses other policies
    recorded = Recorded(act, with_layout(cfg, act.layout), horizon_s)  # sensing as the policy
    fly_episodes(cfg, batch, recorded)
    a, t = np.concatenate(recorded.mine), np.concatenate(recorded.taught)
    error, variance = float(np.mean((a - t) ** 2)), float(np.var(t))
    return {
        "labels": float(a.size),
        "gap": error,
        "variance": variance,
        "r2": 1.0 - error / max(variance, 1e-12),
        "policy_abs": float(np.mean(np.abs(a))),
        "teacher_abs": float(np.mean(np.abs(t))),
    }


def main() -> None:
    """Print one row per family."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--policy", required=True, help="a generalist policy file or zoo name")
    p.add_argument("--families", default=FAMILIES, help="comma-separated suite families")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--teacher-horizon", type=float, default=GeneralistConfig.teacher_horizon_s)
    args = p.parse_args()
    act = PolicyFileAct(load_policy(args.policy))
    if act.layout is None:
        raise SystemExit(f"{args.policy}: not a generalist (no version-2 layout), no teacher")
    print("| family | labels | gap (MSE) | labels' variance | R² | mean abs: policy / teacher |")
    print("|---|---:|---:|---:|---:|---|")
    suite = load_suite("standard")
    for family in args.families.split(","):
        g = gap(act, suite.family(family), suite.seed, args.episodes, args.teacher_horizon)
        print(
            f"| {family} | {g['labels']:.0f} | {g['gap']:.3f} | {g['variance']:.3f} | "
            f"{g['r2']:.2f} | {g['policy_abs']:.3f} / {g['teacher_abs']:.3f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
