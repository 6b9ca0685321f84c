"""``remarl-fc compare --ray-address``: the grid's cells as tasks on a Ray cluster."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from policies.compare.methods import run_job
from sim.errors import ConfigError

if TYPE_CHECKING:
    from policies.compare.grid import Job


def run_on_ray(todo: list[Job], address: str) -> list[dict[str, Any]]:
    """Run every cell of ``todo`` as a Ray task on the cluster at ``address``; results in order.

    Raises:
        ConfigError: Ray is not installed.
    """
    try:
        import ray
    except ImportError as exc:
        raise ConfigError("--ray-address needs Ray: pip install 'ray[default]'") from exc
    ray.init(address=address)
    remote = ray.remote(run_job)
    return list(ray.get([remote.remote(j) for j in todo]))
