"""Typed defaults of training (per-agent DDPG, paper §Agent)."""

from __future__ import annotations

from dataclasses import dataclass


def check(ok: bool, name: str, message: str) -> None:
    """Raise ``ValueError("name: message")`` unless ``ok``: the checks of every training config."""
    if not ok:
        raise ValueError(f"{name}: {message}")


def check_at_least(obj: object, minimum: int, *names: str) -> None:
    """`check` that each named field of ``obj`` is >= ``minimum``."""
    for name in names:
        check(getattr(obj, name) >= minimum, name, f"must be >= {minimum}")


@dataclass(frozen=True)
class DDPGConfig:
    """Per-agent DDPG: networks, losses, replay and exploration."""

    hidden: int = 256
    """Hidden units of every layer (the paper's 256)."""

    actor_lr: float = 3e-4
    """Adam learning rate of the actors."""

    critic_lr: float = 1e-3
    """Adam learning rate of the critics."""

    gamma: float = 0.95
    """Discount per decision step (2 s): a horizon of about 20 steps, one episode."""

    tau: float = 0.01
    """Soft target update rate θ' ← τθ + (1 − τ)θ'."""

    batch_size: int = 256
    """Transitions per agent and gradient step."""

    buffer_steps: int = 100_000
    """Replay capacity, in environment steps (each holds every agent's transition)."""

    warmup_steps: int = 2_000
    """Environment steps of uniform random actions before learning starts."""

    updates_per_step: int = 1
    """Gradient steps per vectorised environment step."""

    noise_start: float = 0.3
    """Std of the Gaussian exploration noise on normalised actions at the start."""

    noise_end: float = 0.05
    """... and at the end of training (linear decay)."""

    huber: bool = True
    """Huber (smooth L1) critic loss, mean over the batch; MSE if False."""

    grad_clip: float = 1.0
    """Max gradient norm per network ensemble."""

    shared: bool = False
    """One actor–critic pair for every agent (parameter sharing) instead of one per agent."""

    def __post_init__(self) -> None:
        for name in ("actor_lr", "critic_lr", "tau", "grad_clip"):
            check(getattr(self, name) > 0, name, "must be > 0")
        check(0 < self.gamma < 1, "gamma", "must be in (0, 1)")
        check_at_least(self, 1, "hidden", "batch_size", "buffer_steps", "updates_per_step")
        check_at_least(self, 0, "warmup_steps")
        check(0 <= self.noise_end <= self.noise_start, "noise_end", "must be in [0, noise_start]")


@dataclass(frozen=True)
class TrainConfig:
    """One training run."""

    scenario: str = "3u2o"
    """Scenario name or TOML path."""

    num_envs: int = 16
    """Environments stepped together."""

    total_steps: int = 50_000
    """Vectorised environment steps (each steps every environment once)."""

    minutes: float = 0.0
    """Wall-clock budget in minutes; 0 = no limit (``total_steps`` alone ends the run)."""

    seed: int = 0
    """Seed of the environments, the networks and the noise."""

    eval_every: int = 2_000
    """Environment steps between evaluations on held-out seeds."""

    eval_episodes: int = 100
    """Episodes per evaluation."""

    reward: str = "remarl"
    """"remarl" (full reward) or "swarming" (the Swarming part only: the ablation)."""

    ddpg: DDPGConfig = DDPGConfig()

    def __post_init__(self) -> None:
        check_at_least(self, 1, "num_envs", "total_steps", "eval_every", "eval_episodes")
        check(self.minutes >= 0, "minutes", "must be >= 0")
        check(self.reward in ("remarl", "swarming"), "reward", 'must be "remarl" or "swarming"')
