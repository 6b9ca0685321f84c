"""``remarl-fc compare --ray-address``: the grid's cells as tasks on a Ray cluster."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from policies.compare.methods import run_job
from sim.parallel import run_on_ray as run_jobs_on_ray

if TYPE_CHECKING:
    from policies.compare.grid import Job


def run_on_ray(todo: list[Job], address: str) -> list[dict[str, Any]]:
    """Run every cell of ``todo`` as a Ray task on the cluster at ``address``; results in order.

    Raises:
        ConfigError: Ray is not installed.
    """
    return run_jobs_on_ray(run_job, todo, address)
