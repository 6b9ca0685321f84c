"""Typed defaults of training (per-agent DDPG, paper §Agent)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sim.config import SWARM_FIELDS, TEACHERS, ScenarioConfig
from sim.setnet import ATTENTION_HEADS, POOLINGS
from sim.shield import NEIGHBOUR_ARCS


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


@dataclass(frozen=True)
class GeneralistConfig:
    """The generalist: one shared set-encoder policy trained on a mixture of encounters.

    The mixture is every family of ``suites`` (`sim.suite`), their episodes drawn from the
    run's own seed (never the suites' evaluation seeds); each family runs
    ceil(``agents_per_family`` / N) environments, so every family feeds about as many UAV
    transitions. See `policies.generalist_train` and ``docs/MODEL.md``.
    """

    suites: tuple[str, ...] = ("standard", "generalist-extra")
    """Suites whose families make up the training mixture."""

    agents_per_family: int = 24
    """UAVs stepped per family and iteration (environments = ceil(this / N), at least 1)."""

    family_weights: tuple[tuple[str, float], ...] = ()
    """(pattern, weight) pairs: a family whose name matches a shell pattern (the first that
    does) runs ``weight`` times its share of UAVs, ceil(weight · agents_per_family / N)
    environments; e.g. (("swarms-*", 3.0),) to train more on crossing swarms."""

    max_neighbours: int = 6
    """k: neighbour rows of the observation (version 2), the nearest first (``train
    --generalist --max-neighbours``). Twelve flew the suite two points lower than six on two
    seeds, and decide 0.25 ms slower for 50 UAVs (docs/MODEL.md §20)."""

    max_intruders: int = 8
    """m: intruder rows of the observation (version 2)."""

    sensing_range_m: float = 200.0
    """Range of the observation's neighbour and intruder rows, metres, and the scale of its
    positions; 0: the base scenario's ``sensing.range_m`` (100 m, the paper's forward sensor).
    A generalist reads its neighbours from their telemetry and the intruders from ADS-B, neither
    of which ends at 100 m: 200 m all around is the shipped run's, 8 s of warning at the
    suite's largest closing speed (docs/MODEL.md §20, "How far it sees")."""

    sensing_aperture_deg: float = 360.0
    """Full aperture of the sector the rows are kept from, degrees, centred on the heading;
    0: the base scenario's ``sensing.aperture_rad`` (270°); 360: all around (the shipped run)."""

    max_uavs: int = 50
    """Largest swarm the exported policy declares it flies (the smallest is 1)."""

    hidden: int = 64
    """Units of every hidden layer of the set networks (`sim.setnet`)."""

    pooling: str = "max-mean"
    """How the set networks pool the neighbour and intruder rows (`sim.setnet.POOLINGS`):
    "max-mean" (deep sets) or "max-attention" (a query from the self block, 4 heads)."""

    actor_lr: float = 3e-4
    """Adam learning rate of the actor."""

    critic_lr: float = 1e-3
    """Adam learning rate of the twin critics."""

    gamma: float = 0.95
    """Discount per decision step, as the per-scenario policies."""

    tau: float = 0.005
    """Soft target update rate."""

    batch_size: int = 512
    """UAV transitions per gradient step."""

    buffer_size: int = 1_000_000
    """Replay capacity, UAV transitions."""

    warmup_transitions: int = 20_000
    """UAV transitions of uniform random actions before learning starts."""

    updates_per_iteration: int = 4
    """Critic gradient steps per iteration (one step of every family)."""

    policy_delay: int = 2
    """Critic steps per actor step (TD3)."""

    target_noise: float = 0.2
    """Std of the target-policy smoothing noise on normalised actions (TD3)."""

    target_noise_clip: float = 0.5
    """Bound of that noise."""

    noise_start: float = 0.3
    """Std of the Gaussian exploration noise at the start ..."""

    noise_end: float = 0.05
    """... and at the end of the run (linear in the run's fraction done)."""

    grad_clip: float = 1.0
    """Max gradient norm per network."""

    separation_horizon_s: float = 0.0
    """0: the separation term reads each UAV's closest approach to another UAV during the step.
    > 0: the smaller of that and the closest approach predicted within this horizon, seconds,
    at constant velocities, to every other UAV and every intruder in view: a conflict is
    charged while it can still be turned away from, as a velocity obstacle sees it."""

    swarm_field: str = "all"
    """Which worlds' reward holds the swarm's peak Φ_s around the virtual centre p*: "all" (the
    paper's one swarm, everywhere) or "formation" (only the families that fly one formation:
    the paper's scenarios and the "formation" encounters; two crossing swarms, converging,
    diverging and random paths train without it, `sim.config.FieldConfig.swarm_peak`)."""

    separation_weight: float = 0.5
    """w_sep: reward lost per step at a UAV–UAV closest approach of d_col, falling linearly to
    0 at ``separation_factor``·d_col (the evidence: without it, UAVs of one swarm learn to
    meet; see docs/MODEL.md)."""

    separation_factor: float = 1.5
    """Where the separation term starts, in d_col (the PSO threshold d̄_U2U and the spacing
    targets keep)."""

    teacher: str = "orca-shield"
    """A teacher to learn from: "orca-shield" (ORCA's actions through the safety shield, heading
    changes only: the strongest hand-written method of the suite, 87 % mean solvable success;
    the shipped recipe), "oracle" (the oracle replanned at every step:
    far stronger, about 100 times slower), "self-shield" (the ``init`` policy's own proposals
    through the safety shield: what it flies behind the shield, distilled into it; docs/MODEL.md
    §20) or "none" (from scratch). With PPO the run is DAgger first for its
    ``dagger_fraction`` (`policies.generalist_dagger`); then the teacher labels every state the
    student's own rollouts visit and the PPO loss gains α·(π − a_teacher)² on them. With TD3
    the run first collects ``teacher_transitions`` of the teacher's flights, clones it
    (``bc_updates`` supervised steps, the critics learning its values meanwhile), then
    fine-tunes with TD3 plus a behaviour-cloning term on the teacher's transitions (TD3+BC).
    Either way α falls from ``bc_weight`` to 0 over the run's first ``bc_fraction``."""

    init: str = ""
    """A generalist policy file to start from (a zoo name or a path; "": fresh networks): its
    actor, and its critic as the value network (PPO). Its observation (range, aperture, rows),
    hidden width and pooling must be the run's. The "self-shield" teacher's proposals are its
    actor's, frozen as the run starts."""

    teacher_horizon_s: float = 20.0
    """τ_o of the ORCA teacher, seconds: how far ahead it checks its candidates against the
    intruders (`sim.orca.orca_plan`'s ``horizon_s``; ORCA's own default, 10 s, suits the
    scenarios' 100 m sensor). With the run's 200 m, 20 s covers what the teacher sees: a
    head-on intruder closing at 12.5 m/s is in view 16 s before it arrives. The teacher then
    flies 20u4o 91 % instead of 78 %, 50u8o 46 % instead of 28 % (its students, over four
    seeds, about as well as with 10 s: docs/MODEL.md §20, "A teacher that looks as far as it
    sees")."""

    teacher_transitions: int = 400_000
    """UAV transitions flown by the teacher before learning (its replay share)."""

    bc_updates: int = 4_000
    """Supervised steps cloning the teacher (and critic steps on its transitions)."""

    bc_weight: float = 2.5
    """α of TD3+BC at the start of fine-tuning: the actor's loss is −Q/mean|Q| + α·(π − a_teacher)²
    on the teacher's transitions (Fujimoto & Gu 2021's normalisation); with PPO, the weight of
    (π − a_teacher)² next to the clipped surrogate (on normalised advantages)."""

    bc_fraction: float = 0.75
    """Share of the run's budget over which α falls linearly from ``bc_weight`` to 0 (the
    shipped recipe: to 0 a quarter of the run after DAgger ends)."""

    dagger_fraction: float = 0.5
    """PPO with a teacher: share of the run spent in DAgger before PPO (0: none; the shipped
    recipe: the first half, docs/MODEL.md §20; without a teacher, or with TD3, there is no
    DAgger phase, as there is no cloning term: `dagger_share`). The student
    flies (the teacher with probability β), the teacher labels every state flown, and the actor
    takes supervised steps on all the labels so far; the value network learns the rollouts'
    returns meanwhile (`policies.generalist_dagger`). PPO then goes on from the clone, with
    the cloning term's α where ``bc_fraction`` has it; 1: DAgger alone, the whole run."""

    dagger_beta: float = 1.0
    """DAgger: β at the start, the chance that a UAV flies the teacher's action rather than the
    student's; it falls linearly to 0 over the first half of the DAgger phase."""

    dagger_rows: int = 1_000_000
    """DAgger: the aggregated labels kept (the oldest dropped first)."""

    dagger_updates: int = 250
    """DAgger: supervised steps of the actor per iteration (≈ the time of the iteration's
    rollout on one core, when the teacher labels every state)."""

    dagger_lr: float = 1e-3
    """DAgger: Adam learning rate of the actor's supervised steps (its own optimiser)."""

    dagger_batch: int = 1024
    """DAgger: labels per supervised step."""

    dagger_turn_weight: float = 0.0
    """DAgger: κ, the weight of a label in the supervised step's squared error is 1 + κ·|a_teacher
    − a_goal|, where a_goal is the turn straight toward the UAV's target (what it flies alone,
    `sim.orca.goal_turn_rad`); the mean is weighted (Σ w·e² / Σ w). 0: every label alike, the
    shipped recipe. Meant for the large swarms, where most labels say "fly on"; measured with
    κ = 2 on two seeds it made both worse (docs/MODEL.md §20, "Weighting the turns")."""

    dagger_separation_weight: float = 0.0
    """DAgger: w, the weight of the own-view separation penalty beside the squared error of
    each supervised step (`policies.own_view`): the actor's own action charged for the closest
    approach to each visible neighbour that its observation predicts over
    ``dagger_separation_horizon_s``, from ``separation_factor``·d_col in. 0: the imitation loss
    alone, the shipped recipe (docs/MODEL.md §20, "A penalty the student can see")."""

    dagger_separation_horizon_s: float = 4.0
    """DAgger: seconds ahead the own-view separation penalty predicts (the safety shield's
    look-ahead at the swarm, `sim.shield.ShieldConfig.neighbour_horizon_s`)."""

    dagger_separation_reciprocal: bool = False
    """DAgger: the own-view separation penalty predicts each neighbour turning as the UAV itself
    does, from its own course (a formation that turns together keeps its spacing), rather than
    flying straight on (`policies.own_view.OwnView.reciprocal`)."""

    dagger_separation_intruders: bool = False
    """DAgger: the own-view separation penalty charges the closest approach to each visible
    intruder too (straight on at its velocity), so that the student does not buy its distance
    from its neighbours with its distance from the intruders."""

    dagger_separation_intruder_horizon_s: float = 0.0
    """DAgger: seconds ahead the own-view separation penalty predicts the intruders it charges
    (``dagger_separation_intruders``). 0: ``dagger_separation_horizon_s``, as the neighbours.
    The safety shield looks at its swarm 4 s and at intruders 25 s ahead
    (`sim.shield.ShieldConfig`): a gap that opens only inside 4 s of an intruder may be too
    late for a turn-limited UAV."""

    dagger_separation_intruder_weight: float = -1.0
    """DAgger: the weight of the intruder rows' part of the own-view separation penalty
    (``dagger_separation_intruders``); negative: ``dagger_separation_weight``, as the
    neighbours'. The neighbour rows want a strong weight to keep UAVs apart, and the same
    weight on the intruder rows looked at far ahead outweighs them (docs/MODEL.md §20,
    "Further ahead for the intruders")."""

    dagger_safe_set_weight: float = 0.0
    """DAgger with the "self-shield" teacher alone (``dagger_fraction`` 1): where the shield
    changed the proposal and some candidate heading passes, the label is the set of headings
    that pass (`sim.shield.ShieldDecision.safe_headings`) rather than the one nearest the
    proposal, and the student's error there is this weight times its squared distance to the
    nearest of them; elsewhere the error is the squared distance to the label, as before. 0:
    off, every label one heading. Why (docs/MODEL.md §20, "A set for a label"): fitted to the
    one heading, the student lands in the safe set on 4 % of the interventions of episodes it
    did not see; fitted to the set, weighted 4, on 40 % (`tools/intent_probe.py`). In flight
    a round so taught was level with its plain twin, not better."""

    dagger_safe_set_side: bool = False
    """With ``dagger_safe_set_weight``: each safe set cut to the side the shield turned to —
    the run of passing headings that holds its label, no failing heading between
    (`sim.shield.passing_side`). Where threats leave a gap on either side the whole set lets
    the student pick a heading on one side at one decision and on the other at the next; the
    shield's label keeps one side. Measured on two seeds: level with the plain rounds
    (92.57 % of the suite against 92.68 %; docs/MODEL.md §20, "The side the shield keeps")."""

    learner: str = "ppo"
    """"ppo" (on-policy: clipped surrogate over rollouts of every world, GAE,
    `policies.generalist_ppo`) or "td3" (off-policy: one replay buffer of every UAV's
    transitions, `policies.generalist`). PPO by the side-by-side at equal wall time
    (docs/MODEL.md §20): 45.6 % mean validation success at 45 minutes against TD3's 36.7 %."""

    ppo_rollout: int = 16
    """PPO: steps of every world per update (≈ 22,000 UAV transitions on the default mixture)."""

    ppo_epochs: int = 4
    """PPO: passes over each rollout."""

    ppo_minibatch: int = 2048
    """PPO: UAV transitions per gradient step."""

    ppo_clip: float = 0.2
    """PPO: ε of the clipped probability ratio."""

    ppo_lambda: float = 0.95
    """PPO: λ of the generalised advantage estimate."""

    ppo_lr: float = 3e-4
    """PPO: Adam learning rate of the actor, the value network and the log std."""

    ppo_log_std: float = -1.2
    """PPO: initial log std of the Gaussian policy on the normalised action (σ ≈ 0.3, TD3's
    starting exploration noise)."""

    ppo_entropy: float = 0.0
    """PPO: weight of the entropy bonus."""

    ppo_min_std: float = 0.0
    """PPO: floor of the policy's σ on the normalised action (0: none). Without one σ falls
    from 0.3 to 0.1 in 30 minutes and to 0.05 in 60 (the PPO run from scratch), where validation
    stops rising: a floor keeps the exploration that finds a wider turn."""

    ppo_value_weight: float = 0.5
    """PPO: weight of the value loss."""

    real_share: float = 0.35
    """Share of families flown in the real world (fitted ArduCopter/PX4 responses randomised
    per UAV, ADS-B intruders, GPS noise) rather than the paper's ideal one."""

    real_error_tau_s: tuple[float, float] = (0.0, 0.0)
    """In the real-world families, the range of the ADS-B report errors' correlation time,
    seconds (`sim.config.SensorConfig.adsb_error_tau_s`, drawn per intruder): (0, 0) draws every
    report's error afresh, as the evaluations' real world does; a real GNSS error wanders over
    minutes, and a policy flies steady offsets worse than jumping ones (docs/MODEL.md §18)."""

    real_track_filter: bool = False
    """In the real-world families, each ADS-B track fuses its reports in the track filter
    (`sim.config.SensorConfig.adsb_filter`, `fly --track-filter on`) rather than holding the
    newest one: train for the picture the flight will give."""

    real_hover: bool = False
    """In the real-world families, a UAV that arrives hovers where it stops (as `fly` holds it,
    and as the real world of `remarl-fc eval --arrival hover` scores it) rather than leaving, as
    the suite's families do: the neighbours still flying learn to keep clear of it
    (docs/MODEL.md §17)."""

    teacher_truth: bool = False
    """The teacher reads the true state in the real-world families (`SwarmState.exactly_sensed`:
    the intruders where they are, not their ADS-B tracks, and no GPS error) — a privileged
    teacher, which the student, seeing its own noisy observation, imitates as far as it can.
    False: its safety shield reads what the UAVs sense, as the shield does in flight (ORCA
    itself reads the true positions either way). The ideal-world families are the same
    either way."""

    teacher_neighbours: str = "proposals"
    """What the "self-shield" teacher's shield expects of each UAV's neighbours
    (`sim.shield.ShieldConfig.neighbour_arcs`): "proposals" (what the proposer proposes for
    them this step, two passes: the shield as it flies) or "straight" (each flies on at its
    heading and speed, one pass: a label made from what the UAV itself sees, which a student
    can copy; docs/MODEL.md §20, "A teacher the student can copy")."""

    minutes: float = 60.0
    """Wall-clock budget of the run (resumes count the time already spent): the shipped
    generalist's run, whose best validation came at 45.7 minutes (docs/MODEL.md §20)."""

    schedule_minutes: float = 0.0
    """The minutes over which the run's schedule is laid out — DAgger's share, the cloning
    term's fade, TD3's exploration noise, all fractions of it (`fraction_of`); 0: ``minutes``.
    A resumed run given a new budget keeps its first one here (`resumed_config`): the minutes
    added come after the schedule, which never starts over."""

    total_iterations: int = 1_000_000
    """Upper bound on iterations (the budget usually ends the run first)."""

    eval_minutes: float = 15.0
    """Wall-clock minutes between validation evaluations."""

    eval_episodes: int = 10
    """Validation episodes per family (seeds of their own)."""

    seed: int = 0
    """Seed of the networks, the noise and the training episodes."""

    device: str = "auto"
    """"cpu", "cuda" or "auto" (cuda when available)."""

    rollout_processes: int = 0
    """Processes that fly the DAgger phase's rollouts while this one learns
    (`policies.generalist_rollouts`): 0 flies them here, between the learning steps; 1 on a
    2-core machine overlaps the two halves of an iteration, about 1.5–1.7 times the iterations per
    minute (docs/MODEL.md §20, `tools/bench_rollouts.py`). The rollouts are then flown with
    the actor one iteration behind, and with random draws of their own; the recipe, the
    teacher and the labels are the same."""

    def __post_init__(self) -> None:
        for name in ("actor_lr", "critic_lr", "tau", "grad_clip", "separation_factor"):
            check(getattr(self, name) > 0, name, "must be > 0")
        check(0 < self.gamma < 1, "gamma", "must be in (0, 1)")
        check(0.0 <= self.real_share <= 1.0, "real_share", "must be in [0, 1]")
        check(self.rollout_processes >= 0, "rollout_processes", "must be >= 0")
        lo, hi = self.real_error_tau_s
        check(0.0 <= lo <= hi and math.isfinite(hi), "real_error_tau_s", "must be 0 <= low <= high")
        check(self.learner in ("td3", "ppo"), "learner", 'must be "td3" or "ppo"')
        check(self.pooling in POOLINGS, "pooling", f"must be one of {POOLINGS}")
        check(
            self.pooling == "max-mean" or self.hidden % ATTENTION_HEADS == 0,
            "hidden",
            f"must be divisible by {ATTENTION_HEADS} for attention pooling (its heads)",
        )
        check(self.swarm_field in SWARM_FIELDS, "swarm_field", f"must be one of {SWARM_FIELDS}")
        check(
            all(len(p) == 2 and p[1] > 0 for p in self.family_weights),
            "family_weights",
            "must be (pattern, weight > 0) pairs",
        )
        check(0 < self.ppo_clip < 1 and 0 <= self.ppo_lambda <= 1, "ppo_clip", "out of range")
        check(self.ppo_lr > 0 and self.ppo_entropy >= 0, "ppo_lr", "must be > 0")
        check(0 <= self.ppo_min_std < 1, "ppo_min_std", "must be in [0, 1)")
        check(self.separation_weight >= 0, "separation_weight", "must be >= 0")
        check(self.separation_horizon_s >= 0, "separation_horizon_s", "must be >= 0")
        check(self.minutes >= 0 and self.eval_minutes > 0, "minutes", "must be >= 0")
        check(self.schedule_minutes >= 0, "schedule_minutes", "must be >= 0")
        step_s = ScenarioConfig.dt_s
        check(
            self.teacher_horizon_s >= step_s,
            "teacher_horizon_s",
            f"must be >= one decision step ({step_s} s)",
        )
        check(self.sensing_range_m >= 0, "sensing_range_m", "must be >= 0 (0: the scenario's)")
        check(
            0 <= self.sensing_aperture_deg <= 360,
            "sensing_aperture_deg",
            "must be in [0, 360] (0: the scenario's)",
        )
        check_at_least(
            self,
            1,
            "agents_per_family",
            "max_intruders",
            "max_uavs",
            "hidden",
            "batch_size",
            "buffer_size",
            "updates_per_iteration",
            "policy_delay",
            "ppo_rollout",
            "ppo_epochs",
            "ppo_minibatch",
            "total_iterations",
            "eval_episodes",
        )
        check_at_least(self, 0, "max_neighbours", "warmup_transitions")
        check(0 <= self.noise_end <= self.noise_start, "noise_end", "must be in [0, noise_start]")
        check(self.device in ("cpu", "cuda", "auto"), "device", 'must be "cpu", "cuda" or "auto"')
        check(self.teacher in TEACHERS, "teacher", f"must be one of {TEACHERS}")
        check(
            self.teacher != "self-shield" or bool(self.init),
            "teacher",
            '"self-shield" distils a policy behind the shield: name it with init',
        )
        check(
            self.teacher_neighbours in NEIGHBOUR_ARCS,
            "teacher_neighbours",
            f"must be one of {NEIGHBOUR_ARCS}",
        )
        check(
            self.teacher_neighbours == "proposals" or self.teacher == "self-shield",
            "teacher_neighbours",
            'the "self-shield" teacher only',
        )
        check(not self.init or self.learner == "ppo", "init", "the ppo learner only")
        check(self.bc_weight >= 0, "bc_weight", "must be >= 0")
        check(0 < self.bc_fraction <= 1, "bc_fraction", "must be in (0, 1]")
        check_at_least(self, 0, "teacher_transitions", "bc_updates", "dagger_updates")
        check_at_least(self, 1, "dagger_rows", "dagger_batch")
        check(0 <= self.dagger_fraction <= 1, "dagger_fraction", "must be in [0, 1]")
        check(0 <= self.dagger_beta <= 1, "dagger_beta", "must be in [0, 1]")
        check(self.dagger_lr > 0, "dagger_lr", "must be > 0")
        for name in (
            "dagger_separation_weight",
            "dagger_separation_horizon_s",
            "dagger_separation_intruder_horizon_s",
        ):
            value = getattr(self, name)
            check(math.isfinite(value) and value >= 0, name, "must be finite and >= 0")
        check(
            math.isfinite(self.dagger_separation_intruder_weight),
            "dagger_separation_intruder_weight",
            "must be finite (negative: the neighbours' weight)",
        )
        check(
            math.isfinite(self.dagger_turn_weight) and self.dagger_turn_weight >= 0,
            "dagger_turn_weight",
            "must be >= 0",
        )
        check(
            math.isfinite(self.dagger_safe_set_weight) and self.dagger_safe_set_weight >= 0,
            "dagger_safe_set_weight",
            "must be finite and >= 0",
        )
        check(
            self.dagger_safe_set_weight == 0
            or (self.teacher == "self-shield" and self.dagger_fraction == 1),
            "dagger_safe_set_weight",
            'needs the "self-shield" teacher and DAgger for the whole run (dagger_fraction 1)',
        )
        check(
            not self.dagger_safe_set_side or self.dagger_safe_set_weight > 0,
            "dagger_safe_set_side",
            "cuts the safe sets: it needs dagger_safe_set_weight > 0 (--safe-set-weight W)",
        )

    def dagger_share(self) -> float:
        """The share of the run spent in DAgger.

        ``dagger_fraction`` where it applies (PPO with a teacher), else 0.
        """
        return self.dagger_fraction if self.teacher != "none" and self.learner == "ppo" else 0.0

    def ppo_follows(self) -> bool:
        """Whether a PPO phase follows the DAgger phase (``dagger_share`` < 1).

        A run that is DAgger from end to end has no use for a critic: its value network is
        left as it began (the init's), and its passes are not spent.
        """
        return self.dagger_share() < 1.0

    def fraction_of(self, elapsed_s: float) -> float:
        """The schedule's fraction done after ``elapsed_s`` seconds, in [0, 1] (``minutes`` > 0)."""
        minutes = self.schedule_minutes or self.minutes
        return min(elapsed_s / max(60.0 * minutes, 1e-9), 1.0)


SETTINGS_BEFORE_THEY_EXISTED: dict[str, Any] = {
    "teacher": "none",
    "learner": "td3",
    "dagger_fraction": 0.0,
    "sensing_range_m": 0.0,
    "sensing_aperture_deg": 0.0,
    "teacher_horizon_s": 10.0,
}
"""What a generalist run did before a setting existed, where that is not today's default: the
first runs had no teacher and learned with TD3, DAgger came after the teacher, and every run
sensed as the scenarios do (100 m, 270°) until the range and aperture were the run's, and the
ORCA teacher looked 10 s ahead (ORCA's own default) until its horizon was the run's. A run's
stored settings (its ``config.json``) that lack one of these take this value when the run is
resumed; any other missing setting takes its default, which is what the code did before it."""


def resumed_config(
    stored: Mapping[str, Any],
    *,
    minutes: float | None = None,
    device: str | None = None,
    rollout_processes: int | None = None,
) -> GeneralistConfig:
    """The settings of a stored generalist run (``config.json``'s "generalist"), to resume it.

    A resumed run is the run it was: every setting comes from ``stored``. Three may change,
    none of which changes what is learned from: ``minutes``, a new budget (the schedule keeps
    the first budget's minutes, `GeneralistConfig.schedule_minutes`), ``device`` and
    ``rollout_processes``.

    Raises:
        ValueError: ``stored`` holds a setting this version does not know, or a value out of
            range.
    """
    fields = {f.name for f in dataclasses.fields(GeneralistConfig)}
    unknown = sorted(set(stored) - fields)
    check(
        not unknown,
        ", ".join(unknown),
        "not a setting of this version: resume the run with the version that started it",
    )
    values = {**SETTINGS_BEFORE_THEY_EXISTED, **stored}
    values["suites"] = tuple(values.get("suites", GeneralistConfig.suites))
    weights = values.get("family_weights", ())
    values["family_weights"] = tuple((str(p), float(w)) for p, w in weights)
    tau = values.get("real_error_tau_s", GeneralistConfig.real_error_tau_s)
    values["real_error_tau_s"] = (float(tau[0]), float(tau[1]))
    if minutes is not None and minutes != values.get("minutes", GeneralistConfig.minutes):
        first = values.get("schedule_minutes") or values.get("minutes", GeneralistConfig.minutes)
        values["schedule_minutes"], values["minutes"] = first, minutes
    if device is not None:
        values["device"] = device
    if rollout_processes is not None:
        values["rollout_processes"] = rollout_processes
    return GeneralistConfig(**values)
