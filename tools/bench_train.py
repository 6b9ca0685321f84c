"""Training throughput of the generalist by device: the learner on the GPU against the CPU.

Starts one ``remarl-fc train --generalist`` per device and teacher, all at once, one thread
each (``OMP_NUM_THREADS=1``: give it a core per run), for the same budget, and reads back each
run's summary. Per run it prints the UAV transitions and the gradient steps per minute of
training (the simulator's and the learner's clocked time, `policies.generalist_train.TIME_PARTS`;
validations and checkpoints excluded), the simulator's share of that time, the final
validation, and each figure's ratio to the CPU run of the same teacher measured beside it.

    OMP_NUM_THREADS=1 python tools/bench_train.py [--devices cpu,cuda] [--teachers none,orca-shield]
        [--minutes 4] [--seed 1] [--out DIR] [--json]

``--teachers none`` is PPO from the first minute; ``orca-shield`` is the shipped recipe (DAgger
on ORCA's labels for the first half of the budget, then PPO). The simulator stays on the CPU
whatever the device: where the learner is fast, it is what remains.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from sim.config import STATE_TEACHERS

RUN_TEACHERS = ("none", *STATE_TEACHERS)
"""The teachers a run of this benchmark can start with (no policy to distil)."""

DEVICES = ("cpu", "cuda")
"""The devices a run can learn on (``train --generalist --device``)."""


def run_command(device: str, teacher: str, minutes: float, seed: int, out: Path) -> list[str]:
    """The ``train --generalist`` command of one run."""
    return [
        sys.executable,
        "-m",
        "remarl_fc",
        "train",
        "--generalist",
        *("--device", device, "--teacher", teacher),
        *("--minutes", str(minutes), "--seed", str(seed)),
        *("--out", str(out), "--json"),
    ]


def figures(summary: dict[str, Any]) -> dict[str, float]:
    """One run's throughput per minute of clocked training, and its final validation."""
    minutes = (summary["simulator_s"] + summary["learner_s"]) / 60
    return {
        "transitions_per_min": summary["transitions"] / minutes,
        "updates_per_min": summary["updates"] / minutes,
        "simulator_share": summary["simulator_s"] / (minutes * 60),
        "iterations": summary["iterations"],
        "validation": summary["last_eval"]["success_mean"],
    }


def bench_train(
    devices: list[str], teachers: list[str], minutes: float, seed: int, out: Path
) -> dict[str, dict[str, float]]:
    """Every device × teacher run at once; their figures, with ratios to the CPU's."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    runs = {
        f"{teacher}-{device}": subprocess.Popen(
            run_command(device, teacher, minutes, seed, out / f"{teacher}-{device}"),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for device in devices
        for teacher in teachers
    }
    results: dict[str, dict[str, float]] = {}
    failed = []
    for name, proc in runs.items():
        stdout, stderr = proc.communicate()
        if proc.returncode != 0:
            failed.append(f"{name} (exit {proc.returncode}): {stderr.strip()[-400:]}")
            continue
        results[name] = figures(json.loads(stdout))
    if failed:
        sys.exit("bench_train: runs failed:\n" + "\n".join(failed))
    for name, row in results.items():
        teacher = name.rsplit("-", 1)[0]
        cpu = results.get(f"{teacher}-cpu")
        if cpu is not None:
            for key in ("transitions_per_min", "updates_per_min"):
                row[f"{key}_per_cpu"] = row[key] / cpu[key]
    return results


def main() -> None:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", default="cpu,cuda", help="comma-separated: cpu, cuda")
    parser.add_argument(
        "--teachers", default="none,orca-shield", help=f"comma-separated, of {RUN_TEACHERS}"
    )
    parser.add_argument("--minutes", type=float, default=4.0, help="budget of every run")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default=None, help="folder of the run folders (default: temp)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    devices = args.devices.split(",")
    teachers = args.teachers.split(",")
    for value, known, flag in (
        (devices, DEVICES, "--devices"),
        (teachers, RUN_TEACHERS, "--teachers"),
    ):
        unknown = sorted(set(value) - set(known))
        if unknown:
            parser.error(f"{flag}: unknown {', '.join(unknown)}; choose from {', '.join(known)}")
    with tempfile.TemporaryDirectory() as temp:
        out = Path(args.out or temp)
        results = bench_train(devices, teachers, args.minutes, args.seed, out)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(
        f"{'run':24} {'transitions/min':>16} {'x cpu':>6} {'updates/min':>12} {'x cpu':>6} "
        f"{'simulator':>10} {'validation':>11}"
    )
    nan = float("nan")
    for name, row in results.items():
        print(
            f"{name:24} {row['transitions_per_min']:16,.0f} "
            f"{row.get('transitions_per_min_per_cpu', nan):6.2f} "
            f"{row['updates_per_min']:12,.0f} {row.get('updates_per_min_per_cpu', nan):6.2f} "
            f"{row['simulator_share']:10.0%} {row['validation']:11.1%}"
        )


if __name__ == "__main__":
    main()
