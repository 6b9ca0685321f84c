"""What a late pop-up leaves to save: the episodes solvable from where a method stood at sighting.

    OMP_NUM_THREADS=1 python tools/sighting_table.py                  # generalist, ORCA, PF, zoo
    OMP_NUM_THREADS=1 python tools/sighting_table.py --shield         # behind the shield
    OMP_NUM_THREADS=1 python tools/sighting_table.py --methods orca --families pop-up-3u

The suite labels an episode solvable where the oracle (`sim.oracle`) flies it to success. Before
a late intruder appears the oracle cannot know it, so it flies its plan against what it sees
(for a swarm alone, straight at its targets) and plans the escape from where that left it. A
method flies its own path until the sighting, as blind as the oracle's and no worse: its
wingmen may stand wider, its leader a few metres aside. Where the intruder appears 25–90 m
ahead, that decides which episodes can still be saved, and the oracle's label only speaks of
its own path.

This table asks the oracle again, at each episode's first sighting, from the state the method
reached (`sim.oracle.oracle_actions` on that state: every UAV's position, heading and arrival;
the intruders seen, with their straight futures). Per family and method:

- **solvable**: the suite's label (the oracle's own path), and the method's success there;
- **at sighting**: episodes with a plan from where the method stood when the intruder
  appeared, and the method's success there: what it did with what the sighting left it;
- **lost, no plan**: solvable episodes the method failed where, at the sighting, the oracle
  found no plan from its state (lost before anything could be seen);
- **success**: over all episodes;
- **off the line at sighting**: the flying UAVs' mean distance from their start–target lines
  when the intruder appeared, metres. The oracle's UAVs fly their lines (0 for one UAV);
- **path ÷ straight line**: each arrived UAV's flown path over its start–target distance
  (``path_length_ratio`` of `sim.env.episode_metrics`), the mean over every arrived UAV.

``--wide-search`` asks with a search 8 times wider (`WIDE_SEARCH`). Only families with late
intruders (``obstacle_appear_step`` > 0) are listed; episodes that end before the first
sighting count as not sighted. With several late intruders the first sighting is asked (a plan
then is against what is seen then).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.offline.shielding import Shielded
from remarl_fc.offline.suite import Act, MethodSpec, fly_episodes, resolve_method
from sim.config import ScenarioConfig
from sim.encounters import Family, sample_family
from sim.oracle import OracleConfig, oracle_actions
from sim.shield import ShieldConfig
from sim.spawn import EpisodeStart
from sim.state import SwarmState
from sim.suite import Suite, family_labels, load_suite

DEFAULT_METHODS = "policy:generalist,orca,potential-field,zoo"

WIDE_SEARCH = OracleConfig(
    beam=256, wide_beam=1024, turns=31, orders=24, cell_m=5.0, heading_bins=64
)
"""``--wide-search``: the oracle's search 8 times wider than its defaults (beam 256 against 32,
31 turns against 9, 24 priority orders against 6, cells of 5 m and 64 heading bins), to tell
"no plan at sighting" from the default search's budget."""


class AtSighting:
    """An act function that asks the oracle, at each episode's first sighting, for a plan.

    ``found`` (B,): a plan existed from the state at the first sighting; ``sighted`` (B,): the
    episode reached it with a UAV still flying; ``off_line_m`` (B,): there, the flying UAVs'
    mean distance from their start–target lines, metres (where the oracle's UAVs stand, alone,
    at 0).
    """

    def __init__(self, act: Any, start: EpisodeStart, oracle: OracleConfig | None = None) -> None:
        self.inner = act
        self.oracle = oracle
        self.first = first_sighting(np.asarray(start.obstacle_appear_step, np.int64))
        self.start_m, self.target_m = start.start_m, start.target_m
        self.sighted = np.zeros(len(self.first), dtype=bool)
        self.found = np.zeros(len(self.first), dtype=bool)
        self.off_line_m = np.zeros(len(self.first))

    @property
    def layout(self) -> Any:
        """The observation layout of the wrapped act function."""
        return getattr(self.inner, "layout", None)

    def __call__(self, obs: NDArray[np.float32], state: SwarmState, cfg: ScenarioConfig) -> Any:
        now = (state.steps == self.first) & state.active.any(axis=-1) & ~self.sighted
        envs = np.flatnonzero(now)
        if envs.size:
            _, found = oracle_actions(state, cfg, self.oracle, envs=envs)
            self.sighted[envs] = True
            self.found[envs] = found
            line = self.target_m[envs] - self.start_m[envs]
            along = line / np.maximum(np.linalg.norm(line, axis=-1, keepdims=True), 1e-9)
            rel = state.pos_m[envs] - self.start_m[envs]
            off = np.abs(rel[..., 0] * along[..., 1] - rel[..., 1] * along[..., 0])
            flying = state.active[envs]
            self.off_line_m[envs] = (off * flying).sum(axis=-1) / flying.sum(axis=-1)
        return self.inner(obs, state, cfg)


def first_sighting(appear: NDArray[np.int64]) -> NDArray[np.int64]:
    """(B,) the step of each episode's first late appearance (−1: none) from (B, M) steps."""
    late = np.where(appear > 0, appear, np.iinfo(np.int64).max)
    first = late.min(axis=-1, initial=np.iinfo(np.int64).max)
    return np.where(first == np.iinfo(np.int64).max, -1, first).astype(np.int64)


def family_row(
    suite: Suite,
    family: Family,
    label: str,
    shield: ShieldConfig | None,
    oracle: OracleConfig | None = None,
) -> dict[str, Any] | None:
    """One family's figures for one method (None: the method cannot fly it)."""
    cfg, batch = sample_family(family, suite.seed, range(suite.episodes))
    act, _ = resolve_method(MethodSpec.from_label(label), family, cfg)
    if act is None:
        return None
    flown: Act = Shielded(act, shield) if shield is not None else act
    probe = AtSighting(flown, batch, oracle)
    rows = fly_episodes(cfg, batch, probe).rows
    success = np.array([bool(r["success"]) for r in rows])
    solvable = family_labels(suite, family, suite.episodes)
    at = probe.sighted & probe.found
    ratios = np.concatenate([r["path_length_ratio"] for r in rows])
    arrived = np.isfinite(ratios)  # NaN: not arrived
    return {
        "family": family.name,
        "method": label.split(":", 1)[-1],
        "episodes": len(rows),
        "solvable": int(solvable.sum()),
        "success_solvable": int((success & solvable).sum()),
        "at_sighting": int(at.sum()),
        "success_at_sighting": int((success & at).sum()),
        "lost_no_plan": int((solvable & ~success & probe.sighted & ~probe.found).sum()),
        "success": int(success.sum()),
        "path_ratio": float(ratios[arrived].mean()) if arrived.any() else None,
        "off_line_m": float(probe.off_line_m[probe.sighted].mean()) if probe.sighted.any() else 0.0,
    }


def _pct(part: int, whole: int) -> str:
    return f"{part} / {whole} ({100.0 * part / whole:.0f}%)" if whole else "–"


def _ratio(value: float | None) -> str:
    return "–" if value is None else f"{value:.3f}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--suite", default="standard")
    p.add_argument("--methods", default=DEFAULT_METHODS, help="names, policy:NAME; comma-separated")
    p.add_argument("--families", default="", help="comma-separated; default: every late one")
    p.add_argument("--shield", action="store_true", help="behind the shield (its defaults)")
    p.add_argument("--wide-search", action="store_true", help="ask with `WIDE_SEARCH`")
    args = p.parse_args()
    oracle = WIDE_SEARCH if args.wide_search else None
    suite = load_suite(args.suite)
    shield = ShieldConfig(mode="on") if args.shield else None
    wanted = set(args.families.split(",")) if args.families else None
    print(
        "| family | method | solvable: success | at sighting: success "
        "| lost, no plan at sighting | success, all | off the line at sighting "
        "| path ÷ straight line |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for family in suite.families:
        if wanted is not None and family.name not in wanted:
            continue
        _, batch = sample_family(family, suite.seed, range(1))
        if wanted is None and not (np.asarray(batch.obstacle_appear_step) > 0).any():
            continue
        for label in args.methods.split(","):
            row = family_row(suite, family, label, shield, oracle)
            if row is None:
                continue
            print(
                f"| {row['family']} | {row['method']} "
                f"| {_pct(row['success_solvable'], row['solvable'])} "
                f"| {_pct(row['success_at_sighting'], row['at_sighting'])} "
                f"| {row['lost_no_plan']} | {_pct(row['success'], row['episodes'])} "
                f"| {row['off_line_m']:.1f} m | {_ratio(row['path_ratio'])} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
