"""Draw one suite episode that two methods fly differently, side by side.

    python tools/versus.py FAMILY [FAMILY ...] [--first policy:generalist] [--second orca]
        [--suite standard] [--episodes 40] [--out docs/img] [--shield] [--solvable]

For each family: the first of its suite episodes (of the first ``--episodes``) that the first
method fails and the second flies to success, both flights in one frame, written to
``OUT/versus-FAMILY.png`` (`remarl_fc.offline.suite_report.draw_versus`). A method is a
`remarl-fc eval --method` name (orca, potential-field, straight, zoo) or ``policy:NAME`` (a zoo
name or a policy file). Prints one JSON line per family: both methods' success on the episodes
looked at, the episode drawn (null: none differs that way) and how each ended. With
``--shield`` both fly behind the safety shield at its defaults (planner included), as
``remarl-fc eval --shield on`` flies them, and the picture is ``OUT/versus-FAMILY-shield.png``.
With ``--solvable`` only the episodes the oracle proves solvable are looked at, those the
suite's success counts (an episode no plan exists for may still be flown by one method).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from remarl_fc.offline.suite import MethodSpec
from remarl_fc.offline.suite_report import draw_versus
from sim.shield import ShieldConfig
from sim.suite import load_suite


def main() -> None:
    """Draw every family asked for."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("families", nargs="+", help="family names of the suite")
    parser.add_argument("--first", default="policy:generalist", help="the method that fails")
    parser.add_argument("--second", default="orca", help="the method that succeeds")
    parser.add_argument("--suite", default="standard")
    parser.add_argument("--episodes", type=int, default=40, help="episodes looked at")
    parser.add_argument("--out", default="docs/img", help="folder of the pictures")
    parser.add_argument("--shield", action="store_true", help="both behind the safety shield")
    parser.add_argument(
        "--solvable", action="store_true", help="only episodes the oracle proves solvable"
    )
    args = parser.parse_args()
    shield = ShieldConfig(mode="on") if args.shield else None
    suite = load_suite(args.suite)
    specs = (MethodSpec.from_label(args.first), MethodSpec.from_label(args.second))
    for family in args.families:
        out = Path(args.out) / f"versus-{family}{'-shield' if shield else ''}.png"
        found = draw_versus(
            suite, family, specs, out, episodes=args.episodes, shield=shield, solvable=args.solvable
        )
        print(json.dumps({**found, "picture": str(out) if found["episode"] is not None else None}))


if __name__ == "__main__":
    main()
