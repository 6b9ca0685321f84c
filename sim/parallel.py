"""Jobs on a Ray cluster: what ``compare --ray-address`` and ``eval --suite --ray-address`` share.

Ray is optional (``pip install 'ray[default]'``) and imported only here, only when asked for.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from sim.errors import ConfigError

J = TypeVar("J")


def run_on_ray(fn: Callable[[J], Any], jobs: Sequence[J], address: str) -> list[Any]:
    """``fn(job)`` for every job as Ray tasks on the cluster at ``address``; results in order.

    ``fn`` must be a module-level function and the jobs picklable (they travel to the workers).

    Raises:
        ConfigError: Ray is not installed.
    """
    try:
        import ray
    except ImportError as exc:
        raise ConfigError("--ray-address needs Ray: pip install 'ray[default]'") from exc
    ray.init(address=address)
    remote = ray.remote(fn)
    return list(ray.get([remote.remote(j) for j in jobs]))
