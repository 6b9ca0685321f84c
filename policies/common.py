"""What every training method shares: the baselines' discrete heading set, and the learning curve.

* `heading_actions`: the discrete action set of COMA and of the BenchMARL baselines (SPEC §8).
* `CurveWriter` and `read_curve`: a run's ``curve.csv``, one row per finished training episode,
  written the same way by every method (`policies.train`, `policies.coma_train`,
  `policies.baseline_env`) and read by `remarl-fc compare` for the learning curves.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.errors import ConfigError

CURVE_COLUMNS = ("env_steps", "episode", "swarming_return", "success")
"""Columns of ``curve.csv``."""


def heading_actions(n_actions: int = 11) -> NDArray[np.float32]:
    """The discrete action set: ``n_actions`` normalised heading changes evenly on [−1, 1].

    A normalised action a turns the UAV by a·π/4 over the decision step (`sim.env`), so the set
    spans [−π/4, π/4]. An odd count holds 0, straight ahead: the default 11 are 9° apart.
    ``n_actions=10`` is the paper's literal grid linspace(−1, 1, 10), 10° apart, with no
    straight ahead. In degrees:

    >>> (heading_actions() * 45).round(1).tolist()
    [-45.0, -36.0, -27.0, -18.0, -9.0, 0.0, 9.0, 18.0, 27.0, 36.0, 45.0]
    >>> (heading_actions(10) * 45).round(1).tolist()
    [-45.0, -35.0, -25.0, -15.0, -5.0, 5.0, 15.0, 25.0, 35.0, 45.0]

    Raises:
        ConfigError: ``n_actions`` is not an integer >= 2.
    """
    if isinstance(n_actions, bool) or not isinstance(n_actions, int) or n_actions < 2:
        raise ConfigError(f"n_actions must be an integer >= 2, got {n_actions!r}")
    values: NDArray[np.float32] = np.linspace(-1.0, 1.0, n_actions).astype(np.float32)
    return values


class CurveWriter:
    """Appends one row per finished training episode to ``curve.csv``: a run's learning curve.

    Columns `CURVE_COLUMNS`: the environment steps of the run when the episode ended, the
    episode's number (1, 2, …), its Swarming return (from the simulator's own episode metrics,
    written as Python's shortest exact decimal) and its success (0 or 1). Each row is appended
    as its episode ends, so the file is whole whenever the run stops.

    Args:
        path: the file; created with its header line unless ``resume`` finds it.
        resume: continue an existing file, numbering episodes on from its last row.
    """

    def __init__(self, path: Path, *, resume: bool = False) -> None:
        self.path = Path(path)
        self.episodes = 0
        """Rows written so far (the last episode's number)."""
        if resume and self.path.exists():
            with self.path.open() as fh:
                self.episodes = max(0, sum(1 for _ in fh) - 1)
        else:
            self.path.write_text(",".join(CURVE_COLUMNS) + "\n")

    def add(self, env_steps: int, swarming_return: float, success: bool) -> None:
        """One finished episode."""
        self.episodes += 1
        with self.path.open("a") as fh:
            fh.write(
                f"{int(env_steps)},{self.episodes},{float(swarming_return)!r},{int(success)}\n"
            )


def read_curve(path: Path) -> NDArray[np.float64]:
    """(E, 3) rows env_steps, swarming_return, success of a ``curve.csv`` (`CurveWriter`)."""
    with path.open() as fh:
        rows = [
            (float(r["env_steps"]), float(r["swarming_return"]), float(r["success"]))
            for r in csv.DictReader(fh)
        ]
    return np.array(rows).reshape(-1, 3)
