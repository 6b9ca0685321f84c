"""DAgger before PPO: the student flies, the teacher labels, supervised steps on every label.

The first ``dagger_fraction`` of a PPO run with a teacher (`policies.generalist_ppo`). Every
iteration flies every world ``ppo_rollout`` steps as PPO does, except that each UAV flies the
teacher's action with probability β (falling linearly from ``dagger_beta`` to 0 over the first
half of the phase) and the student's deterministic action otherwise, both with N(0,
`TEACHER_NOISE`²) noise; the teacher labels every state flown (Ross, Gordon & Bagnell 2011:
the aggregated data set of the states the student's own mixture visits). Then:

- the labels join `Labels`, a ring of the last ``dagger_rows`` (observation, teacher action,
  weight) rows, and the actor takes ``dagger_updates`` supervised steps (mean squared error,
  weighted by ``dagger_turn_weight`` where it is > 0: `label_weights`; Adam of its own at
  ``dagger_lr``) on minibatches of ``dagger_batch`` drawn from all of it, plus, where
  ``dagger_separation_weight`` is > 0, that weight times the own-view separation penalty of
  the actor's actions (`policies.own_view`); where ``dagger_safe_set_weight`` is > 0 (the
  "self-shield" teacher alone), each label keeps the set of headings the shield let pass where
  it intervened, and there the error is that weight times the squared distance to the nearest
  of them (`safe_set_error`);
- where PPO follows (``dagger_fraction`` < 1), the value network learns the rollout's GAE
  targets (``ppo_epochs`` passes, the value loss alone: `warm_critic`), so that PPO starts from
  a critic of the policy it inherits. A run that is DAgger from end to end skips them: its
  critic would serve nothing, and the passes were a quarter of the learner's time.

Why (docs/MODEL.md §20): inside the PPO loss the cloning term fits the teacher to a mean
squared error of 0.07–0.10 on normalised actions, where the labels' own variance is 0.09 — it
barely clones; the same network fitted by supervised steps alone on the teacher's labels
reaches 0.035 on held-out states.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from policies.config import GeneralistConfig
from policies.own_view import OwnView
from policies.train import optimiser_tensors, restore_optimiser
from sim.orca import goal_turn_rad
from sim.shield import ShieldConfig, candidate_grid

if TYPE_CHECKING:
    from policies.generalist import SetNet
    from policies.generalist_ppo import PPONets
    from policies.generalist_train import RunBook, World

CHECKPOINT_PREFIX = "dagger."
"""Names of the DAgger phase's state in a run's ``last.safetensors``: its labels and its
optimiser, kept while the phase lasts so that a run resumed inside it goes on with them."""


@dataclass
class Labels:
    """The aggregated data set: the last ``capacity`` (observation, teacher action, weight) rows.

    With ``headings`` K > 0, each row also keeps the teacher's safe set: which of the shield's
    K candidate headings pass there (all False where the label is its one heading).
    """

    capacity: int
    size: int
    obs: NDArray[np.float32] = field(repr=False)
    action: NDArray[np.float32] = field(repr=False)
    weight: NDArray[np.float32] = field(repr=False)
    safe: NDArray[np.bool_] = field(repr=False)
    count: int = 0
    head: int = 0

    @classmethod
    def create(cls, capacity: int, size: int, headings: int = 0) -> Labels:
        """An empty ring of ``capacity`` rows of observations of length ``size``.

        With ``headings`` K > 0 each row keeps a safe set of K candidates too.
        """
        return cls(
            capacity,
            size,
            np.zeros((capacity, size), np.float32),
            np.zeros(capacity, np.float32),
            np.zeros(capacity, np.float32),
            np.zeros((capacity, headings), bool),
        )

    @property
    def headings(self) -> int:
        """K, the candidates of each row's safe set (0: no sets kept)."""
        return int(self.safe.shape[1])

    def add(
        self,
        obs: NDArray[np.float32],
        action: NDArray[np.float32],
        weight: NDArray[np.float32],
        safe: NDArray[np.bool_] | None = None,
    ) -> None:
        """Append rows (T, size), (T,), (T,) and safe sets (T, K), overwriting the oldest.

        ``safe`` None: no set (every row's label its one heading).
        """
        if safe is None:
            safe = np.zeros((action.shape[0], self.headings), bool)
        if (
            obs.shape[0] != action.shape[0]
            or weight.shape != action.shape
            or obs.shape[1:] != (self.size,)
            or safe.shape != (action.shape[0], self.headings)
        ):
            raise ValueError(
                f"labels: obs {obs.shape}, actions {action.shape}, weights {weight.shape} and"
                f" safe sets {safe.shape} do not match"
            )
        rows = obs.shape[0]
        if rows >= self.capacity:  # only the newest fit
            keep = slice(rows - self.capacity, rows)
            obs, action, weight, safe = obs[keep], action[keep], weight[keep], safe[keep]
            rows = self.capacity
        idx = (self.head + np.arange(rows)) % self.capacity
        self.obs[idx], self.action[idx], self.weight[idx] = obs, action, weight
        self.safe[idx] = safe
        self.head = int((self.head + rows) % self.capacity)
        self.count = min(self.count + rows, self.capacity)

    def oldest_first(self) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
        """The rows held (observations, actions, weights), oldest first.

        Added in this order to an empty ring of the same capacity, they give a ring that holds
        the same rows and drops the same ones first.
        """
        order = self._order()
        return self.obs[order], self.action[order], self.weight[order]

    def safe_oldest_first(self) -> NDArray[np.bool_]:
        """The rows' safe sets (count, K), in `oldest_first`'s order."""
        return self.safe[self._order()]

    def _order(self) -> NDArray[np.intp]:
        return np.arange(self.head - self.count, self.head) % self.capacity

    def sample(
        self, batch: int, rng: np.random.Generator
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
        """``batch`` rows (observations, actions, weights) drawn uniformly with replacement."""
        obs, action, weight, _ = self.sample_sets(batch, rng)
        return obs, action, weight

    def sample_sets(
        self, batch: int, rng: np.random.Generator
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_]]:
        """`sample`'s rows with their safe sets (batch, K)."""
        if self.count == 0:
            raise ValueError("labels: nothing to sample yet")
        idx = rng.integers(0, self.count, batch)
        return self.obs[idx], self.action[idx], self.weight[idx], self.safe[idx]


def label_weights(
    taught: NDArray[np.floating[Any]], goal: NDArray[np.floating[Any]], turn_weight: float
) -> NDArray[np.float32]:
    """Each label's weight, 1 + κ·|a_teacher − a_goal| (`GeneralistConfig.dagger_turn_weight`).

    ``taught`` and ``goal``: the teacher's action and the turn straight toward the target, both
    normalised to [−1, 1]; ``turn_weight``: κ ≥ 0.
    """
    return (1.0 + turn_weight * np.abs(taught - goal)).astype(np.float32)


def dagger_beta(cfg: GeneralistConfig, frac: float) -> float:
    """β, the chance a UAV flies the teacher's action, at the run's fraction ``frac`` done."""
    half = 0.5 * cfg.dagger_share()
    return cfg.dagger_beta * max(0.0, 1.0 - frac / half) if half > 0 else 0.0


@dataclass
class Dagger:
    """The DAgger phase's state: the aggregated labels and the actor's own optimiser."""

    labels: Labels
    opt: torch.optim.Optimizer

    @classmethod
    def create(cls, cfg: GeneralistConfig, size: int, nets: PPONets) -> Dagger:
        """Empty labels of observations of length ``size``; Adam over ``nets.actor``."""
        opt = torch.optim.Adam(nets.actor.parameters(), lr=cfg.dagger_lr)
        headings = ShieldConfig().headings if cfg.dagger_safe_set_weight > 0 else 0
        return cls(Labels.create(cfg.dagger_rows, size, headings), opt)

    def state_tensors(self) -> dict[str, torch.Tensor]:
        """The labels (oldest first) and the optimiser's moments, as checkpoint tensors.

        Named `CHECKPOINT_PREFIX`…: `policies.train.save_checkpoint`'s ``extra``.
        """
        obs, action, weight = self.labels.oldest_first()
        sets = {}
        if self.labels.headings:
            safe = torch.from_numpy(self.labels.safe_oldest_first().astype(np.uint8))
            sets = {f"{CHECKPOINT_PREFIX}labels.safe": safe}
        return {
            f"{CHECKPOINT_PREFIX}labels.obs": torch.from_numpy(obs),
            f"{CHECKPOINT_PREFIX}labels.action": torch.from_numpy(action),
            f"{CHECKPOINT_PREFIX}labels.weight": torch.from_numpy(weight),
            **sets,
            **optimiser_tensors(f"{CHECKPOINT_PREFIX}opt", self.opt),
        }

    def restore(self, tensors: Mapping[str, torch.Tensor]) -> int:
        """Take back what `state_tensors` wrote; returns the labels restored.

        No tensors (a checkpoint from before the labels were kept, or written after the DAgger
        phase) leave the phase as it was: empty labels, a fresh optimiser.

        Raises:
            ValueError: the labels' observations are not of this run's length.
        """
        if not tensors:
            return 0
        obs = tensors[f"{CHECKPOINT_PREFIX}labels.obs"].numpy()
        if obs.ndim != 2 or obs.shape[1] != self.labels.size:
            raise ValueError(
                f"checkpoint: DAgger labels of shape {tuple(obs.shape)}, this run's observations"
                f" have {self.labels.size} entries; resume the run with its own settings"
            )
        safe = None
        if self.labels.headings:
            kept = tensors.get(f"{CHECKPOINT_PREFIX}labels.safe")
            if kept is None or tuple(kept.shape) != (obs.shape[0], self.labels.headings):
                raise ValueError(
                    "checkpoint: its DAgger labels hold no safe sets of "
                    f"{self.labels.headings} headings; resume the run with its own settings"
                    " (--safe-set-weight)"
                )
            safe = kept.numpy().astype(bool)
        self.labels.add(
            obs,
            tensors[f"{CHECKPOINT_PREFIX}labels.action"].numpy(),
            tensors[f"{CHECKPOINT_PREFIX}labels.weight"].numpy(),
            safe,
        )
        restore_optimiser(f"{CHECKPOINT_PREFIX}opt", self.opt, tensors)
        return int(obs.shape[0])


def clone_update(
    actor: nn.Module,
    opt: torch.optim.Optimizer,
    obs: torch.Tensor,
    teacher: torch.Tensor,
    clip: float,
    weight: torch.Tensor | None = None,
    separation: tuple[OwnView, float] | None = None,
    safe: tuple[torch.Tensor, float] | None = None,
) -> float:
    """One supervised step of ``actor`` toward the teacher's actions; returns the imitation loss.

    The mean squared error, weighted by ``weight`` (Σ w·e² / Σ w) where given. With ``safe``
    (sets (batch, K) bool, w): in the rows whose set holds a heading, w times the squared
    distance to its nearest (`safe_set_error`) instead. With ``separation`` (view, w): plus w
    times the mean own-view separation penalty of the actor's actions (`policies.own_view`;
    ``dagger_separation_weight``).
    """
    action = actor(obs)
    error = (action - teacher) ** 2
    if safe is not None:
        sets, w = safe
        error = torch.where(sets.any(dim=-1), w * safe_set_error(action, sets), error)
    loss = error.mean() if weight is None else (weight * error).sum() / weight.sum()
    total = loss
    if separation is not None:
        view, w = separation
        total = loss + w * view.penalty(obs, action).mean()
    opt.zero_grad(set_to_none=True)
    total.backward()
    nn.utils.clip_grad_norm_(list(actor.parameters()), clip)
    opt.step()
    return float(loss.detach())


NOT_SAFE = 16.0
"""Squared distance standing in for a heading outside the set: above any two actions' (2² = 4),
finite, so that no gradient meets an infinity."""


def safe_set_error(action: torch.Tensor, sets: torch.Tensor) -> torch.Tensor:
    """(B,) squared distance of each action (B,) to the nearest heading of its set (B, K).

    The headings are the shield's candidates (`sim.shield.candidate_grid`); a row with an
    empty set gets `NOT_SAFE`.
    """
    grid = torch.from_numpy(candidate_grid(sets.shape[-1])).to(action)
    gap = (action[:, None] - grid[None, :]) ** 2
    return torch.where(sets, gap, torch.full_like(gap, NOT_SAFE)).min(dim=-1).values


def label_of(taught: NDArray[np.float32]) -> NDArray[np.float32]:
    """The teacher's action (B, N) of what `teach` gave.

    Itself, or ``[..., 0]`` of (B, N, 1 + K) labels with their safe sets
    (`policies.generalist_train.shielded_sets`).
    """
    return taught[..., 0] if taught.ndim == 3 else taught


def separation_view(book: RunBook) -> OwnView | None:
    """The own-view separation penalty of ``book``'s run, or None where its weight is 0."""
    cfg = book.cfg
    if cfg.dagger_separation_weight <= 0:
        return None
    intruder_weight = cfg.dagger_separation_intruder_weight
    if intruder_weight < 0:
        intruder_weight = cfg.dagger_separation_weight
    return OwnView.of(
        book.layout,
        [world.cfg for world in book.worlds],
        cfg.dagger_separation_horizon_s,
        cfg.separation_factor,
        cfg.dagger_separation_reciprocal,
        cfg.dagger_separation_intruders,
        cfg.dagger_separation_intruder_horizon_s,
        intruder_weight / cfg.dagger_separation_weight,
    )


def value_update(nets: PPONets, obs: torch.Tensor, target: torch.Tensor, clip: float) -> float:
    """One step of the value network toward GAE targets (the PPO value loss alone)."""
    loss = 0.5 * ((nets.values(obs) - target) ** 2).mean()
    nets.opt.zero_grad(set_to_none=True)
    loss.backward()
    nn.utils.clip_grad_norm_(list(nets.value.parameters()), clip)
    nets.opt.step()
    return float(loss.detach())


@dataclass(frozen=True)
class DaggerRollout:
    """One DAgger rollout of some worlds: what `learn_dagger` takes from it.

    Attributes:
        flown: per world, per step, (`WorldStep`, action flown, zeros, teacher's label): the
            rows of `policies.generalist_ppo.rollout_columns`. weights: per world, per step,
            each UAV's label weight (`label_weights`). ended: the metrics of the episodes that
            ended, each with its "family". transitions: UAV transitions flown. drawn: per
            world, the episodes drawn so far. beta: the β it was flown with.
    """

    flown: list[list[tuple[Any, ...]]]
    weights: list[list[NDArray[np.float32]]]
    ended: list[dict[str, Any]]
    transitions: int
    drawn: list[int]
    beta: float

    @classmethod
    def merge(cls, parts: list[DaggerRollout]) -> DaggerRollout:
        """The rollouts of disjoint runs of worlds, in order, as one."""
        return cls(
            [rows for part in parts for rows in part.flown],
            [rows for part in parts for rows in part.weights],
            [row for part in parts for row in part.ended],
            sum(part.transitions for part in parts),
            [count for part in parts for count in part.drawn],
            parts[0].beta,
        )


def fly_dagger(
    worlds: list[World],
    actor: SetNet,
    teach: Callable[[list[World]], list[NDArray[np.float32]]],
    beta: float,
    cfg: GeneralistConfig,
    goal_value: float,
    rng: np.random.Generator,
    device: str,
) -> DaggerRollout:
    """Fly ``ppo_rollout`` steps of every world with the β-mixture of ``teach`` and ``actor``.

    Each UAV flies the teacher's action with probability ``beta``, the actor's deterministic
    one otherwise, both with N(0, `TEACHER_NOISE`²) noise; the teacher labels every state.
    """
    from policies.generalist_train import (
        TEACHER_NOISE,
        actor_actions,
        advance_world,
        joint_obs,
        per_world,
    )

    size = worlds[0].obs.shape[-1]
    flown: list[list[tuple[Any, ...]]] = [[] for _ in worlds]
    weights: list[list[NDArray[np.float32]]] = [[] for _ in worlds]
    ended: list[dict[str, Any]] = []
    transitions = 0
    for _ in range(cfg.ppo_rollout):
        student = per_world(actor_actions(actor, joint_obs(worlds, size), device), worlds)
        for k, (world, own, full) in enumerate(zip(worlds, student, teach(worlds), strict=True)):
            taught = label_of(full)
            pick = rng.random(own.shape) < beta
            noise = rng.normal(0.0, TEACHER_NOISE, own.shape)
            action = np.clip(np.where(pick, taught, own) + noise, -1.0, 1.0).astype(np.float32)
            goal = goal_turn_rad(world.state, world.cfg) / world.cfg.uav.max_turn_rad
            step, finished = advance_world(world, action, cfg, goal_value, rng)
            weights[k].append(label_weights(taught, goal, cfg.dagger_turn_weight))
            flown[k].append((step, action, np.zeros_like(action), full.astype(np.float32)))
            transitions += int(step.acted.sum())
            ended += [{"family": world.family.name, **row} for row in finished]
    return DaggerRollout(flown, weights, ended, transitions, [w.drawn for w in worlds], beta)


def dagger_iteration(
    book: RunBook, dagger: Dagger, recent: list[dict[str, Any]]
) -> dict[str, float]:
    """Fly one rollout of every world with the β-mixture in this process, then learn.

    Returns the iteration's scalars (losses, β); finished episodes join ``recent``.
    """
    with book.clock("simulator"):
        rollout = fly_dagger(
            book.worlds,
            book.nets.actor,
            book.teach,
            dagger_beta(book.cfg, book.fraction_done()),
            book.cfg,
            book.goal_value,
            book.rng,
            book.device,
        )
    return learn_dagger(book, dagger, rollout, recent)


def warm_critic(
    nets: PPONets,
    rollout: DaggerRollout,
    cfg: GeneralistConfig,
    device: str,
    rng: np.random.Generator,
) -> float:
    """``ppo_epochs`` passes of the value network over the rollout's GAE targets; the last loss."""
    from policies.generalist_ppo import rollout_columns

    columns = rollout_columns(nets, rollout.flown, cfg, device)
    obs_t = torch.from_numpy(columns["obs"]).to(device)
    target_t = torch.from_numpy(columns["target"]).to(device)
    value_loss = 0.0
    for _ in range(cfg.ppo_epochs):
        order = torch.from_numpy(rng.permutation(len(obs_t))).to(device)
        for start in range(0, len(obs_t), cfg.ppo_minibatch):
            idx = order[start : start + cfg.ppo_minibatch]
            value_loss = value_update(nets, obs_t[idx], target_t[idx], cfg.grad_clip)
    return value_loss


def learn_dagger(
    book: RunBook, dagger: Dagger, rollout: DaggerRollout, recent: list[dict[str, Any]]
) -> dict[str, float]:
    """Aggregate a rollout's labels and learn from them; returns the iteration's scalars.

    The labels join in the order they were flown (step by step, world by world); where PPO
    follows, the value network takes ``ppo_epochs`` passes over the rollout's GAE targets
    (`warm_critic`); the actor takes ``dagger_updates`` supervised steps on all the labels.
    The rollout's finished episodes join ``recent``, its transitions and the episodes drawn
    the book's counters.
    """
    cfg, nets, device, rng = book.cfg, book.nets, book.device, book.rng
    labels = dagger.labels
    for t in range(cfg.ppo_rollout):
        for rows, weights in zip(rollout.flown, rollout.weights, strict=True):
            step, full, weight = rows[t][0], rows[t][3], weights[t]
            acted = step.acted
            sets = full[acted][:, 1:] > 0.5 if full.ndim == 3 else None
            labels.add(step.obs[acted], label_of(full)[acted], weight[acted], sets)
    for world, drawn in zip(book.worlds, rollout.drawn, strict=True):
        world.drawn = drawn
    book.transitions += rollout.transitions
    recent += rollout.ended
    del recent[:-2000]
    book.iteration += 1

    scalars: dict[str, float] = {}
    with book.clock("learner"):
        if cfg.ppo_follows():
            scalars["losses/value"] = warm_critic(nets, rollout, cfg, device, rng)
        clone_loss = 0.0
        view = separation_view(book)
        separation = None if view is None else (view, cfg.dagger_separation_weight)
        for _ in range(cfg.dagger_updates):
            obs, taught, weight, sets = labels.sample_sets(cfg.dagger_batch, rng)
            clone_loss = clone_update(
                nets.actor,
                dagger.opt,
                torch.from_numpy(obs).to(device),
                torch.from_numpy(taught).to(device),
                cfg.grad_clip,
                torch.from_numpy(weight).to(device) if cfg.dagger_turn_weight > 0 else None,
                separation,
                (torch.from_numpy(sets).to(device), cfg.dagger_safe_set_weight)
                if labels.headings
                else None,
            )
            book.updates += 1
        if separation is not None and cfg.dagger_updates:  # the last minibatch's, after them
            with torch.no_grad():
                obs_t = torch.from_numpy(obs).to(device)
                penalty = separation[0].penalty(obs_t, nets.actor(obs_t)).mean()
            scalars["losses/own_separation"] = float(penalty)
    return scalars | {
        "losses/clone": clone_loss,
        "charts/dagger_beta": rollout.beta,
        "charts/dagger_labels": float(labels.count),
    }
