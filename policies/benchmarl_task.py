"""`SwarmTask`, the BenchMARL ``TaskClass`` of the swarm (needs the ``baselines`` extra).

It builds `policies.baseline_env.SwarmBaselineEnv` inside TorchRL's ``PettingZooWrapper``: one
group ``"agents"`` (`GROUP`), the episode done when all agents are. `make_task` configures one
for a scenario; `policies.benchmarl_train.train_benchmarl` runs it.

Importing this module imports BenchMARL and TorchRL, and raises `BaselinesNotInstalledError`
where the extra is missing: import it only where the extra is needed (`train_benchmarl` does,
lazily).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

from policies.baseline_env import EpisodeLog, SwarmBaselineEnv
from policies.benchmarl_train import (
    BaselinesNotInstalledError,
    quiet_benchmarl,
    require_benchmarl,
)
from policies.common import heading_actions
from sim.scenarios import load_scenario

require_benchmarl()  # a clear BaselinesNotInstalledError, not a bare ImportError below
with quiet_benchmarl():
    from benchmarl.environments.pettingzoo.common import PettingZooClass
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

__all__ = ["ENV_SEED_STRIDE", "GROUP", "BaselinesNotInstalledError", "SwarmTask", "make_task"]

GROUP = "agents"
"""The one BenchMARL agent group: every UAV, sharing its networks."""

ENV_SEED_STRIDE = 10_007
"""The k-th environment a `SwarmTask` environment function builds is seeded
seed + k·ENV_SEED_STRIDE, so the collector's environments fly different spawn draws."""


class SwarmTask(PettingZooClass):  # type: ignore[misc]
    """BenchMARL task: the adapter in TorchRL's PettingZoo wrapper (config: see `make_task`).

    The attribute ``episode_log`` (an `EpisodeLog`, or None) receives the episodes of the
    environments this task builds.
    """

    episode_log: EpisodeLog | None = None

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], Any]:
        """A function that builds one wrapped environment per call, each seeded differently."""
        config = dict(self.config)
        counter = itertools.count()
        base = 0 if seed is None else int(seed)
        log = self.episode_log

        def make() -> Any:
            env_seed = base + next(counter) * ENV_SEED_STRIDE
            env = SwarmBaselineEnv(config["scenario"], n_actions=config["n_actions"], log=log)
            with quiet_benchmarl():
                return PettingZooWrapper(
                    env=env,
                    return_state=True,
                    group_map={GROUP: list(env.possible_agents)},
                    categorical_actions=True,
                    seed=env_seed,
                    done_on_any=False,  # done when every agent is: arrived agents stay
                    use_mask=False,
                    device=device,
                )

        return make

    def supports_continuous_actions(self) -> bool:
        """No: the baselines pick from the discrete heading set."""
        return False

    def supports_discrete_actions(self) -> bool:
        """Yes: ``Discrete(n_actions)`` headings."""
        return True

    def has_state(self) -> bool:
        """Yes: `SwarmBaselineEnv.state`, for the MAPPO critic and the QMIX mixer."""
        return True

    def has_render(self, env: Any) -> bool:
        """No: rendering would import torchvision (`policies.benchmarl_train`)."""
        return False

    def max_steps(self, env: Any) -> int:
        """The scenario's step limit."""
        return int(self.config["max_steps"])

    @staticmethod
    def env_name() -> str:
        """BenchMARL's name of this environment family."""
        return "remarl"


def make_task(scenario: str, n_actions: int = 11, log: EpisodeLog | None = None) -> SwarmTask:
    """A `SwarmTask` for a shipped scenario name or scenario file."""
    cfg = load_scenario(scenario)
    heading_actions(n_actions)  # validates
    task = SwarmTask(
        name=cfg.name.upper(),
        config={"scenario": str(scenario), "n_actions": n_actions, "max_steps": cfg.max_steps},
    )
    task.episode_log = log
    return task
