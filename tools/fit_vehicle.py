"""Fit the vehicle profiles (`sim.vehicle`) to the real-firmware SITL traces, by least squares.

    python tools/fit_vehicle.py                    # fit, print the table, write nothing
    python tools/fit_vehicle.py --write            # also rewrite sim/vehicles/*.toml
    python tools/fit_vehicle.py --plot docs/img/vehicle-fit.png

For each profile, the delay, velocity time constant and acceleration cap that minimise the RMS
horizontal velocity error over every sample of its traces (the commands replayed as recorded,
zero-order hold, from the recorded initial velocity): an exhaustive search over a grid, then a
grid 4 times finer around the best point. The traces and how they were flown:
tests/data/sitl/README.md.
"""

from __future__ import annotations

import argparse
import itertools
import math
from pathlib import Path

import numpy as np

from sim.arrays import FloatArray
from sim.vehicle import VehicleProfile, read_trace, respond

TRACES = Path(__file__).resolve().parents[1] / "tests" / "data" / "sitl"
PROFILES = Path(__file__).resolve().parents[1] / "sim" / "vehicles"
FITS = {
    "arducopter": ("ardupilot-a", "ardupilot-b", "ardupilot-c"),
    "px4": ("px4-a-fast", "px4-b-fast", "px4-c-fast", "px4-a-gain", "px4-b-gain", "px4-c-gain"),
    "px4-sluggish": ("px4-a", "px4-b", "px4-c"),
}
"""Profile → its trace files. PX4's SIH airframe with its default drag (SIH_KDV 1.0) is
drag-limited near 10 m/s: the sluggish end; the lower-drag and higher-gain runs are typical."""

DESCRIPTIONS = {
    "arducopter": "ArduCopter V4.7.0-dev SITL, default parameters (WPNAV_ACCEL 250 cm/s²)",
    "px4": "PX4 v1.16 SIH, lower drag or higher velocity gain: the typical PX4 multirotor",
    "px4-sluggish": "PX4 v1.16 SIH with its default drag: drag-limited near 10 m/s",
}
DT_S = 0.02
"""Integration step of the fit, seconds (the traces are sampled at 20 Hz)."""

COARSE = {
    "delay_s": np.arange(0.0, 0.85, 0.1),
    "velocity_tau_s": np.geomspace(0.1, 4.0, 17),
    "max_accel_m_s2": np.geomspace(0.8, 12.0, 17),
}


def read(name: str) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(times (T,), commands (T, 2), velocities (T, 2)) of a trace, north/east."""
    trace = read_trace(TRACES / f"{name}.csv")
    return trace.times_s, trace.command_m_s, trace.velocity_m_s


def errors(
    traces: list[tuple[FloatArray, FloatArray, FloatArray]],
    delay: float,
    tau: FloatArray,
    accel: FloatArray,
) -> FloatArray:
    """Sum of squared velocity errors (P,) and sample count, for P (tau, accel) pairs at once."""
    total = np.zeros(len(tau))
    for t, cmd, vel in traces:
        grid = np.arange(t[0], t[-1] + DT_S, DT_S)
        held = np.searchsorted(t, grid - delay, side="right") - 1
        c = np.where((held >= 0)[:, None], cmd[np.maximum(held, 0)], cmd[0])
        v = np.broadcast_to(vel[0], (len(tau), 2)).copy()
        gain = -np.expm1(-DT_S / tau)[:, None]
        cap = (accel * DT_S)[:, None]
        out = np.empty((len(grid), len(tau), 2))
        for k in range(len(grid)):
            out[k] = v
            step = (c[k] - v) * gain
            norm = np.hypot(step[:, 0], step[:, 1])[:, None]
            v = v + step * np.where(norm > cap, cap / np.maximum(norm, 1e-300), 1.0)
        idx = np.clip(np.searchsorted(grid, t), 0, len(grid) - 1)
        total += ((out[idx] - vel[:, None]) ** 2).sum(axis=(0, 2))
    return total


def fit(names: tuple[str, ...]) -> tuple[dict[str, float], float]:
    """The best (delay, tau, accel) and its RMS velocity error (m/s) over the traces."""
    traces = [read(n) for n in names]
    count = sum(len(t) for t, _, _ in traces)

    def search(grids: dict[str, FloatArray]) -> tuple[dict[str, float], float]:
        best: tuple[float, dict[str, float]] = (math.inf, {})
        pairs = np.array(list(itertools.product(grids["velocity_tau_s"], grids["max_accel_m_s2"])))
        for delay in grids["delay_s"]:
            sse = errors(traces, float(delay), pairs[:, 0], pairs[:, 1])
            k = int(np.argmin(sse))
            if sse[k] < best[0]:
                best = (
                    float(sse[k]),
                    {
                        "delay_s": float(delay),
                        "velocity_tau_s": float(pairs[k, 0]),
                        "max_accel_m_s2": float(pairs[k, 1]),
                    },
                )
        return best[1], math.sqrt(best[0] / count / 2)

    coarse, _ = search(COARSE)
    fine = {}
    for key, grid in COARSE.items():
        k = int(np.argmin(np.abs(grid - coarse[key])))
        lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        fine[key] = np.linspace(lo, hi, 9)
    fine["delay_s"] = np.clip(fine["delay_s"], 0.0, None)
    return search(fine)


YAW_GRID = {
    "yaw_tau_s": np.geomspace(0.05, 3.0, 25),
    "max_yaw_rate_rad_s": np.radians(np.geomspace(10.0, 400.0, 25)),
}


def read_yaw(name: str) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(times, commanded yaw, yaw) of a trace, radians (counter-clockwise, unwrapped later)."""
    trace = read_trace(TRACES / f"{name}.csv")
    return trace.times_s, trace.command_yaw_rad, trace.yaw_rad


def fit_yaw(names: tuple[str, ...], delay: float) -> tuple[dict[str, float], float]:
    """The best (yaw τ, yaw rate cap) at the velocity fit's delay; RMS yaw error (degrees)."""
    pairs = np.array(list(itertools.product(*YAW_GRID.values())))
    tau, cap_rate = pairs[:, 0], pairs[:, 1]
    total, count = np.zeros(len(pairs)), 0
    for name in names:
        t, cmd, yaw = read_yaw(name)
        grid = np.arange(t[0], t[-1] + DT_S, DT_S)
        held = np.searchsorted(t, grid - delay, side="right") - 1
        c = np.where(held >= 0, cmd[np.maximum(held, 0)], cmd[0])
        y = np.full(len(pairs), yaw[0])
        out = np.empty((len(grid), len(pairs)))
        gain, cap = -np.expm1(-DT_S / tau), cap_rate * DT_S
        for k in range(len(grid)):
            out[k] = y
            err = np.angle(np.exp(1j * (c[k] - y)))
            y = y + np.clip(err * gain, -cap, cap)
        idx = np.clip(np.searchsorted(grid, t), 0, len(grid) - 1)
        total += (np.angle(np.exp(1j * (out[idx] - yaw[:, None]))) ** 2).sum(axis=0)
        count += len(t)
    k = int(np.argmin(total))
    rms = math.degrees(math.sqrt(total[k] / count))
    return {"yaw_tau_s": float(tau[k]), "max_yaw_rate_rad_s": float(cap_rate[k])}, rms


def write_profile(
    name: str, params: dict[str, float], rms: float, yaw_rms: float, names: tuple[str, ...]
) -> None:
    """Rewrite ``sim/vehicles/NAME.toml`` with the fitted figures."""
    path = PROFILES / f"{name}.toml"
    lines = [
        f"# Fitted by tools/fit_vehicle.py to {', '.join(names)} (tests/data/sitl/).",
        f'description = "{DESCRIPTIONS[name]}"',
        f"delay_s = {params['delay_s']:.3f}",
        f"velocity_tau_s = {params['velocity_tau_s']:.3f}",
        f"max_accel_m_s2 = {params['max_accel_m_s2']:.3f}",
        f"yaw_tau_s = {params['yaw_tau_s']:.3f}",
        f"max_yaw_rate_deg_s = {math.degrees(params['max_yaw_rate_rad_s']):.1f}",
        f"fit_rms_m_s = {rms:.3f}",
        f"# RMS yaw error of the fit: {yaw_rms:.1f}°",
        f"fitted_on = {list(names)!r}".replace("'", '"'),
    ]
    path.write_text("\n".join(lines) + "\n")


def plot(fits: dict[str, dict[str, float]], out: Path) -> None:
    """Trace vs model for the step (a) and policy-like (c) runs of each autopilot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [
        ("arducopter", "ardupilot-a"),
        ("arducopter", "ardupilot-c"),
        ("px4", "px4-a-fast"),
        ("px4-sluggish", "px4-a"),
    ]
    fig, axes = plt.subplots(len(shown), 1, figsize=(9, 2.4 * len(shown)), constrained_layout=True)
    for ax, (profile, trace) in zip(axes, shown, strict=True):
        t, cmd, vel = read(trace)
        fitted = VehicleProfile(name=profile, **fits[profile])  # type: ignore[arg-type]
        model = respond(fitted, t, cmd, vel[0], DT_S)
        ax.plot(t, np.hypot(*cmd.T), color="0.6", lw=1, label="commanded speed")
        ax.plot(t, np.hypot(*vel.T), color="tab:blue", lw=1.4, label=f"{trace} (SITL)")
        ax.plot(t, np.hypot(*model.T), color="tab:red", lw=1.2, ls="--", label=f"model {profile}")
        ax.set_ylabel("speed [m/s]")
        ax.legend(fontsize=7, loc="lower right")
    axes[-1].set_xlabel("t [s]")
    fig.savefig(out, dpi=100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--write", action="store_true", help="rewrite sim/vehicles/*.toml")
    parser.add_argument("--plot", default=None, help="draw trace vs model here")
    args = parser.parse_args()
    fits = {}
    print(
        "| profile | traces | delay | τ_v | a_max | RMS velocity error | τ_yaw | yaw rate cap "
        "| RMS yaw error |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, names in FITS.items():
        params, rms = fit(names)
        yaw, yaw_rms = fit_yaw(names, params["delay_s"])
        params |= yaw
        fits[name] = params
        print(
            f"| {name} | {len(names)} | {params['delay_s']:.2f} s "
            f"| {params['velocity_tau_s']:.2f} s "
            f"| {params['max_accel_m_s2']:.2f} m/s² | {rms:.3f} m/s | {yaw['yaw_tau_s']:.2f} s "
            f"| {math.degrees(yaw['max_yaw_rate_rad_s']):.0f}°/s | {yaw_rms:.1f}° |",
            flush=True,
        )
        if args.write:
            write_profile(name, params, rms, yaw_rms, names)
    if args.plot:
        plot(fits, Path(args.plot))


if __name__ == "__main__":
    main()
