"""Ground truth of a mock flight: tracks, closest approaches, collisions, targets reached.

Every physics tick the true positions (no GPS fault or noise) are recorded; the closest
approach of every pair between two ticks is found with the simulator's swept-distance metric
(`sim.metrics.swept_min_distance_parts`, in 3-D), so two vehicles that cross between samples
still count. A collision is a pair closer than d_col; it is counted once per encounter.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.metrics import swept_min_distance_parts

FloatArray = NDArray[np.float64]

TRACK_HZ = 2.0
"""Samples per simulated second kept in each vehicle's track."""


class GroundTruth:
    """Records N vehicles and M intruders.

    Args:
        n, m: vehicle and intruder counts.
        d_col_m: collision distance.
        targets_ne_m: (N, 2) targets (north, east), or None when the flight has none.
        arrival_m: horizontal distance to a target that counts as reached.
    """

    def __init__(
        self,
        n: int,
        m: int,
        d_col_m: float,
        targets_ne_m: FloatArray | None = None,
        arrival_m: float | None = None,
    ) -> None:
        self.n, self.m, self.d_col_m = n, m, d_col_m
        self.targets = targets_ne_m
        self.arrival_m = d_col_m if arrival_m is None else arrival_m
        self.iu, self.ju = np.triu_indices(n, k=1)
        self.min_uu = np.full(len(self.iu), math.inf)
        self.min_uo = np.full((n, m), math.inf)
        self.close_uu = np.zeros(len(self.iu), dtype=bool)
        self.close_uo = np.zeros((n, m), dtype=bool)
        self.collisions_uu = np.zeros(len(self.iu), dtype=np.int64)
        self.collisions_uo = np.zeros((n, m), dtype=np.int64)
        self.reached_at_s = np.full(n, math.nan)
        self.tracks: list[list[list[float]]] = [[] for _ in range(n)]
        self._prev: tuple[FloatArray, FloatArray] | None = None
        self._next_track_s = 0.0
        self.duration_s = 0.0

    def record(self, now_s: float, vehicles_ned: FloatArray, intruders_ned: FloatArray) -> None:
        """Add the true positions at ``now_s``: vehicles (N, 3), intruders (M, 3)."""
        veh = np.asarray(vehicles_ned, dtype=np.float64)
        intr = np.asarray(intruders_ned, dtype=np.float64).reshape(self.m, 3)
        self.duration_s = now_s
        if self._prev is not None:
            pv, pi = self._prev
            if len(self.iu):
                rel0, rel1 = pv[self.iu] - pv[self.ju], veh[self.iu] - veh[self.ju]
                d = _swept(rel0, rel1)
                self._update(d, self.min_uu, self.close_uu, self.collisions_uu)
            if self.m:
                rel0 = pv[:, None, :] - pi[None, :, :]
                rel1 = veh[:, None, :] - intr[None, :, :]
                d = _swept(rel0, rel1)
                self._update(d, self.min_uo, self.close_uo, self.collisions_uo)
        self._prev = (veh.copy(), intr.copy())
        if self.targets is not None:
            gap = np.hypot(*(veh[:, :2] - self.targets).T)
            new = np.isnan(self.reached_at_s) & (gap < self.arrival_m)
            self.reached_at_s[new] = now_s
        if now_s + 1e-9 >= self._next_track_s:
            self._next_track_s = now_s + 1.0 / TRACK_HZ
            for i in range(self.n):
                n_, e_, d_ = veh[i]
                self.tracks[i].append([round(now_s, 3), round(n_, 2), round(e_, 2), round(-d_, 2)])

    def _update(
        self, d: FloatArray, smallest: FloatArray, close: NDArray[np.bool_], count: Any
    ) -> None:
        np.minimum(smallest, d, out=smallest)
        now_close = d < self.d_col_m
        count += now_close & ~close
        close[...] = now_close

    def reached(self) -> NDArray[np.bool_]:
        """(N,) which vehicles have reached their targets (all False without targets)."""
        reached: NDArray[np.bool_] = ~np.isnan(self.reached_at_s)
        return reached

    def vehicle_summary(self, i: int) -> dict[str, Any]:
        """Vehicle i's part of the summary."""
        others: dict[str, float | None] = {}
        collisions = 0
        for k, (a, b) in enumerate(zip(self.iu, self.ju, strict=True)):
            if i in (a, b):
                other = int(b if a == i else a) + 1
                others[str(other)] = _finite(self.min_uu[k])
                collisions += int(self.collisions_uu[k])
        intruders = {f"OBST{k:04d}": _finite(self.min_uo[i, k]) for k in range(self.m)}
        collisions += int(self.collisions_uo[i].sum())
        reached = bool(self.reached()[i])
        return {
            "track_t_n_e_up_m": self.tracks[i],
            "min_distance_to_vehicle_m": others,
            "min_distance_to_intruder_m": intruders,
            "collisions": collisions,
            "reached_target": reached if self.targets is not None else None,
            "reached_target_at_s": _finite(self.reached_at_s[i]) if reached else None,
        }

    def overall(self) -> dict[str, Any]:
        """Fleet-wide figures."""
        return {
            "duration_s": round(self.duration_s, 3),
            "d_col_m": self.d_col_m,
            "min_vehicle_vehicle_m": _finite(self.min_uu.min()) if len(self.min_uu) else None,
            "min_vehicle_intruder_m": _finite(self.min_uo.min()) if self.min_uo.size else None,
            "collisions_vehicle_vehicle": int(self.collisions_uu.sum()),
            "collisions_vehicle_intruder": int(self.collisions_uo.sum()),
            "reached_targets": int(self.reached().sum()) if self.targets is not None else None,
        }


def _swept(rel0: FloatArray, rel1: FloatArray) -> FloatArray:
    stacked = np.stack([rel0, rel1])  # (2, ..., 3): time first
    parts = tuple(np.ascontiguousarray(stacked[..., k]) for k in range(3))
    return swept_min_distance_parts(parts).astype(np.float64)


def _finite(x: float) -> float | None:
    return round(float(x), 3) if math.isfinite(x) else None


def write_json_atomic(path: str | Path, data: dict[str, Any]) -> None:
    """Write JSON to ``path`` through a temporary file and a rename: never half-written."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=1)
            fh.write("\n")
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
