"""The generalist's on-policy learner: PPO over rollouts of every world of the mixture.

The side-by-side of TD3 (`policies.generalist_train`) that the choice of learner rests on
(docs/MODEL.md): the same worlds, network (`policies.generalist.SetNet`), reward, validation
and run folder; only the learning differs. A Gaussian policy on the normalised heading change,
its mean the actor's output and its log std one learned number (the flown action is the sample
clipped to [−1, 1]); a value network of the critic's shape read at action 0 (its action input
unused). Every iteration flies every world ``ppo_rollout`` steps, estimates advantages per
UAV with GAE(λ) (an arrival is the absorbing goal, a collision ends with 0, as in TD3; the
rollout's end and a timed-out episode bootstrap from the value), then takes ``ppo_epochs``
passes of clipped-surrogate steps (Schulman et al. 2017) over the UAV transitions.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor, nn

from policies.config import GeneralistConfig
from policies.generalist import SetNet
from policies.generalist_dagger import (
    CHECKPOINT_PREFIX,
    Dagger,
    dagger_beta,
    dagger_iteration,
    learn_dagger,
)
from policies.generalist_rollouts import RolloutFleet
from policies.train import load_checkpoint_tensors
from sim.arrays import BoolArray
from sim.observation import ObservationLayout

if TYPE_CHECKING:
    from policies.generalist_train import RunBook

LOG_2PI = math.log(2.0 * math.pi)
"""log 2π, of the Gaussian's density."""


class LogStd(nn.Module):
    """The policy's log standard deviation: one learned number, every UAV and state."""

    def __init__(self, value: float) -> None:
        super().__init__()
        self.value = nn.Parameter(torch.tensor(float(value)))


@dataclass
class PPONets:
    """The actor (the Gaussian's mean), its log std, the value network and one optimiser."""

    actor: SetNet
    value: SetNet
    log_std: LogStd
    opt: torch.optim.Optimizer

    @classmethod
    def create(cls, layout: ObservationLayout, cfg: GeneralistConfig, device: str) -> PPONets:
        """Fresh networks on ``device``."""
        actor = SetNet(layout, cfg.hidden, critic=False, pooling=cfg.pooling).to(device)
        value = SetNet(layout, cfg.hidden, critic=True, pooling=cfg.pooling).to(device)
        log_std = LogStd(cfg.ppo_log_std).to(device)
        params = [*actor.parameters(), *value.parameters(), *log_std.parameters()]
        return cls(actor, value, log_std, torch.optim.Adam(params, lr=cfg.ppo_lr))

    def modules(self) -> dict[str, nn.Module]:
        """Every network by checkpoint name."""
        return {"actor": self.actor, "value": self.value, "log_std": self.log_std}

    def optimisers(self) -> dict[str, torch.optim.Optimizer]:
        """Every optimiser by checkpoint name."""
        return {"opt": self.opt}

    def values(self, obs: Tensor) -> Tensor:
        """V(obs) (B,) of flat observations (B, D)."""
        out: Tensor = self.value(obs, obs.new_zeros(obs.shape[0]))
        return out


def log_prob(mean: Tensor, log_std: Tensor, sample: Tensor) -> Tensor:
    """Log density of ``sample`` under N(mean, exp(log_std)²), elementwise."""
    z = (sample - mean) * torch.exp(-log_std)
    return -0.5 * z * z - log_std - 0.5 * LOG_2PI


def advantages(
    reward: NDArray[np.float32],
    value: NDArray[np.float32],
    next_value: NDArray[np.float32],
    terminal: BoolArray,
    terminal_value: NDArray[np.float32],
    cut: BoolArray,
    gamma: float,
    lam: float,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """GAE(λ) advantages and value targets, (T, ...) each, of per-UAV trajectories.

    ``terminal``: the trajectory ended at the step (bootstrap ``terminal_value``); ``cut``:
    it does not go on into the next step of the rollout (its episode ended, or the rollout
    did): bootstrap V(next observation). A UAV that flew a step and is neither terminal nor
    cut flies the next one, so the recursion only meets entries of UAVs that acted.
    """
    adv = np.zeros_like(reward)
    running = np.zeros_like(reward[0])
    for t in range(reward.shape[0] - 1, -1, -1):
        boot = np.where(terminal[t], terminal_value[t], next_value[t])
        delta = reward[t] + gamma * boot - value[t]
        running = delta + gamma * lam * np.where(terminal[t] | cut[t], 0.0, running)
        adv[t] = running
    return adv, adv + value


def ppo_update(
    nets: PPONets,
    obs: Tensor,
    sample: Tensor,
    old_log_prob: Tensor,
    adv: Tensor,
    target: Tensor,
    cfg: GeneralistConfig,
    teacher: Tensor | None = None,
    bc: float = 0.0,
) -> dict[str, float]:
    """One clipped-surrogate step on a minibatch of UAV transitions.

    ``teacher`` (B,): the teacher's action at each observation (NaN: none); with ``bc`` > 0
    the loss gains bc·(mean − teacher)² over the transitions a teacher labelled.
    """
    mean = nets.actor(obs)
    new_log_prob = log_prob(mean, nets.log_std.value, sample)
    ratio = torch.exp(new_log_prob - old_log_prob)
    clipped = torch.clamp(ratio, 1.0 - cfg.ppo_clip, 1.0 + cfg.ppo_clip)
    policy_loss = -torch.min(ratio * adv, clipped * adv).mean()
    value_loss = 0.5 * ((nets.values(obs) - target) ** 2).mean()
    entropy = nets.log_std.value + 0.5 * (LOG_2PI + 1.0)
    loss = policy_loss + cfg.ppo_value_weight * value_loss - cfg.ppo_entropy * entropy
    clone = torch.zeros(())
    if teacher is not None and bc > 0:
        has = ~torch.isnan(teacher)
        if bool(has.any()):
            clone = ((mean[has] - teacher[has]) ** 2).mean()
            loss = loss + bc * clone
    nets.opt.zero_grad(set_to_none=True)
    loss.backward()
    params = [p for group in nets.opt.param_groups for p in group["params"]]
    nn.utils.clip_grad_norm_(params, cfg.grad_clip)
    nets.opt.step()
    if cfg.ppo_min_std > 0:  # projected back onto the floor
        with torch.no_grad():
            nets.log_std.value.clamp_(min=math.log(cfg.ppo_min_std))
    return {
        "losses/policy": float(policy_loss.detach()),
        "losses/value": float(value_loss.detach()),
        "losses/clone": float(clone.detach()),
        "charts/log_std": float(nets.log_std.value.detach()),
        "charts/clip_fraction": float(((ratio - 1.0).abs() > cfg.ppo_clip).float().mean()),
    }


def train_generalist_ppo(
    cfg: GeneralistConfig,
    out_dir: Path,
    *,
    resume: bool = False,
    progress: Callable[[dict[str, float]], None] | None = None,
) -> dict[str, Any]:
    """Train (or resume) the generalist with PPO; the run folder as TD3's."""
    from policies.generalist_train import RunBook, bc_weight

    book = RunBook.open(cfg, out_dir, PPONets.create, resume=resume)
    nets: PPONets = book.nets
    recent: list[dict[str, Any]] = []
    dagger = Dagger.create(cfg, book.layout.size, nets) if cfg.dagger_share() > 0 else None
    if dagger is not None:
        # the labels so far live in last.safetensors while the phase lasts, so that a run
        # resumed inside it goes on with every label (a run resumed after it finds none)
        if book.resumed:
            dagger.restore(load_checkpoint_tensors(out_dir / "last.safetensors", CHECKPOINT_PREFIX))
        phase = dagger

        def dagger_state() -> dict[str, torch.Tensor]:
            in_phase = book.fraction_done() < cfg.dagger_share()
            return phase.state_tensors() if in_phase else {}

        book.run_state = dagger_state
    try:
        # ---- DAgger first, where asked (`policies.generalist_dagger`), its rollouts in
        # processes of their own where asked (`policies.generalist_rollouts`)
        if dagger is not None:
            with contextlib.ExitStack() as stack:
                fleet = None
                if cfg.rollout_processes > 0:
                    fleet = stack.enter_context(RolloutFleet(book, cfg.rollout_processes))
                while (
                    book.fraction_done() < cfg.dagger_share()
                    and book.iteration < cfg.total_iterations
                    and not book.out_of_time()
                ):
                    if fleet is None:
                        scalars = dagger_iteration(book, dagger, recent)
                    else:
                        with book.clock("simulator"):  # waiting for the rollout
                            rollout = fleet.fly(lambda: dagger_beta(cfg, book.fraction_done()))
                        scalars = learn_dagger(book, dagger, rollout, recent)
                    book.log(recent, scalars, progress, every=1)
                    book.save_and_validate_if_due()
        while book.iteration < cfg.total_iterations and not book.out_of_time():
            bc = bc_weight(cfg, book.fraction_done())
            with book.clock("simulator"):
                flown, std = fly_rollout(book, bc, recent)
            del recent[:-2000]
            book.iteration += 1
            with book.clock("learner"):
                losses = learn_rollout(book, flown, bc)
            book.log(
                recent, {"charts/noise": std, "charts/bc_weight": bc, **losses}, progress, every=1
            )
            book.save_and_validate_if_due()
    except KeyboardInterrupt:
        book.save_last()
        raise
    return book.finish()


def fly_rollout(
    book: RunBook, bc: float, recent: list[dict[str, Any]]
) -> tuple[list[list[Any]], float]:
    """Fly every world ``ppo_rollout`` steps with the Gaussian policy.

    Returns each world's steps as (step, sample, log density, teacher's label or None), and
    the policy's σ: the teacher labels the state the student flies from while ``bc`` > 0
    (DAgger inside PPO). Finished episodes join ``recent``.
    """
    from policies.generalist_train import (
        actor_actions,
        advance_world,
        joint_obs,
        per_world,
    )

    cfg, worlds, rng = book.cfg, book.worlds, book.rng
    std = float(torch.exp(book.nets.log_std.value.detach()))
    log_std = float(book.nets.log_std.value.detach())
    flown: list[list[Any]] = [[] for _ in worlds]
    for _ in range(cfg.ppo_rollout):
        mean = actor_actions(book.nets.actor, joint_obs(worlds, book.layout.size), book.device)
        noise = rng.standard_normal(mean.shape)
        sample = (mean + std * noise).astype(np.float32)
        # the behaviour policy's log density of its own sample, (sample − mean)/σ = noise
        density = (-0.5 * noise * noise - log_std - 0.5 * LOG_2PI).astype(np.float32)
        action = np.clip(sample, -1.0, 1.0)
        taught_all = book.teach(worlds) if bc > 0 else [None] * len(worlds)
        for k, (world, a, u, lp, taught) in enumerate(
            zip(
                worlds,
                per_world(action, worlds),
                per_world(sample, worlds),
                per_world(density, worlds),
                taught_all,
                strict=True,
            )
        ):
            step, ended = advance_world(world, a, cfg, book.goal_value, rng)
            flown[k].append((step, u, lp, taught))
            book.transitions += int(step.acted.sum())
            recent.extend({"family": world.family.name, **row} for row in ended)
    return flown, std


def learn_rollout(book: RunBook, flown: list[list[Any]], bc: float) -> dict[str, float]:
    """Learn from one rollout; returns the last step's losses.

    Advantages per world, then ``ppo_epochs`` clipped-surrogate passes over every UAV's
    transitions of the rollout.
    """
    cfg, nets, device, rng = book.cfg, book.nets, book.device, book.rng
    columns = rollout_columns(nets, flown, cfg, device)
    losses: dict[str, float] = {}
    count = len(columns["adv"])
    adv = columns["adv"]
    columns["adv"] = (adv - adv.mean()) / (adv.std() + 1e-8)
    tensors = {k: torch.from_numpy(v).to(device) for k, v in columns.items()}
    for _ in range(cfg.ppo_epochs):
        order = torch.from_numpy(rng.permutation(count)).to(device)
        for start in range(0, count, cfg.ppo_minibatch):
            idx = order[start : start + cfg.ppo_minibatch]
            batch = {k: v[idx] for k, v in tensors.items()}
            losses = ppo_update(
                nets,
                batch["obs"],
                batch["sample"],
                batch["log_prob"],
                batch["adv"],
                batch["target"],
                cfg,
                batch["teacher"],
                bc,
            )
            book.updates += 1
    return losses


def rollout_columns(
    nets: PPONets,
    flown: list[list[Any]],
    cfg: GeneralistConfig,
    device: str,
) -> dict[str, NDArray[np.float32]]:
    """A rollout's UAV transitions as flat columns: obs, sample, log_prob, adv, target, teacher.

    ``flown``: per world, per step, (`WorldStep`, sample, log density of the sample, the
    teacher's actions or None); ``teacher`` is NaN where no teacher labelled.
    """
    out: dict[str, list[NDArray[np.float32]]] = {
        k: [] for k in ("obs", "sample", "log_prob", "adv", "target", "teacher")
    }
    for rows in flown:
        steps = [row[0] for row in rows]
        obs = np.stack([s.obs for s in steps])  # (T, B, N, D)
        nxt = np.stack([s.next_obs for s in steps])
        lead = obs.shape[:-1]
        value, next_value = _values(nets, obs, nxt, np.stack([s.done for s in steps]), device)
        acted = np.stack([s.acted for s in steps])
        cut = np.stack([np.broadcast_to(s.done[:, None], lead[1:]) for s in steps])
        cut[-1] = True  # the rollout ends: bootstrap from the value
        adv, target = advantages(
            np.stack([s.reward for s in steps]),
            value,
            next_value,
            np.stack([s.terminal for s in steps]),
            np.stack([s.terminal_value for s in steps]),
            cut,
            cfg.gamma,
            cfg.ppo_lambda,
        )
        nan = np.full(lead[1:], np.nan, np.float32)
        out["obs"].append(obs[acted])
        out["sample"].append(np.stack([row[1] for row in rows])[acted])
        out["log_prob"].append(np.stack([row[2] for row in rows])[acted])
        out["adv"].append(adv[acted])
        out["target"].append(target[acted])
        out["teacher"].append(np.stack([nan if row[3] is None else row[3] for row in rows])[acted])
    return {k: np.concatenate(v).astype(np.float32) for k, v in out.items()}


def _values(
    nets: PPONets,
    obs: NDArray[np.float32],
    nxt: NDArray[np.float32],
    done: BoolArray,
    device: str,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """V of the observations (T, B, N, D) acted on and of those after each step.

    The observation after step t is the one acted on at t + 1 unless the environment's
    episode ended at t (``done`` (T, B)): the network reads each observation once, plus the
    last step's next observations and the ended episodes' final ones.
    """
    t, b, n, size = obs.shape
    ended = nxt[:-1][done[:-1]]  # (E, N, D): final observations of the episodes that ended
    rows = np.concatenate(
        [obs.reshape(-1, size), nxt[-1].reshape(-1, size), ended.reshape(-1, size)]
    )
    with torch.no_grad():
        v = nets.values(torch.from_numpy(rows).to(device)).cpu().numpy()
    value = v[: t * b * n].reshape(t, b, n)
    next_value = np.empty_like(value)
    next_value[:-1] = value[1:]
    next_value[-1] = v[t * b * n : (t + 1) * b * n].reshape(b, n)
    next_value[:-1][done[:-1]] = v[(t + 1) * b * n :].reshape(-1, n)
    return value, next_value
