"""The vectorised swarm simulator: state, reset and one pure batched step.

``step(state, actions, rng, cfg) -> (state, StepResult)`` advances B environments of N UAVs and
M obstacles by one decision step, with no per-agent Python loop:

1. every active UAV flies the constant-turn-rate arc of its action; obstacles fly straight;
   the virtual centre keeps the swarm's initial velocity;
2. swept checks find the closest approach, *during* the step, of every UAV to every obstacle,
   to every other UAV and to its target (`sim.metrics`);
3. collisions (closer than d_col) end the episode; a UAV that comes within d_col of its target
   has arrived and leaves the episode (masked); all arrived is a success; the step limit
   truncates;
4. every UAV's new arc is scored against the field at mid-step and pushed into its contour
   window; the full reMARL reward and its Swarming part are computed for all agents at once;
5. contour levels are (re)assigned by PSO where SPEC §6 says: at episode start (`reset`) and on
   the first step on which any UAV of an environment senses an obstacle (avoidance begins).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from sim.config import ScenarioConfig
from sim.contour import ArcWindow, arc_external_xy
from sim.field import FieldSources
from sim.kinematics import scale_action, sinc_series, wrap_angle
from sim.metrics import substep_fractions, swept_min_distance_xy
from sim.observation import ObservationLayout, Observations, build_observations
from sim.reward import RewardTerms, assign_contour_levels, reward
from sim.spawn import spawn_obstacles, swarm_layout

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class EpisodeStats:
    """Per-episode accumulators behind the metrics (SPEC §9), reset with the episode.

    Attributes:
        energy_rad: (B, N) Σ|a| flown so far (E = ∫|S''| dρ on arcs).
        flown_m: (B, N) distance flown so far.
        min_u2o_m: (B,) smallest swept UAV–obstacle distance so far (+inf if none).
        min_u2u_m: (B,) smallest swept UAV–UAV distance so far (+inf if none).
        swarming_return: (B, N) Σ of the Swarming part of the reward.
        total_return: (B, N) Σ of the full reMARL reward.
    """

    energy_rad: FloatArray
    flown_m: FloatArray
    min_u2o_m: FloatArray
    min_u2u_m: FloatArray
    swarming_return: FloatArray
    total_return: FloatArray


@dataclass(frozen=True)
class SwarmState:
    """Everything the simulator knows about B environments, batch first.

    Attributes:
        pos_m: (B, N, 2) UAV positions.  heading_rad: (B, N).
        active: (B, N) UAVs still flying (not arrived; the episode is not over).
        reached: (B, N) UAVs that arrived at their target.
        start_m: (B, N, 2) spawn positions.  target_m: (B, N, 2).
        obstacle_pos_m, obstacle_vel_m_s: (B, M, 2).  obstacle_speed_m_s: (B, M).
        centre_m: (B, 2) virtual centre p*.  swarm_vel_m_s: (B, 2) its constant velocity.
        levels: (B, N) contour levels φ_i.
        avoiding: (B,) whether avoidance has begun (levels were reassigned for it).
        window: the contour windows (B, N, K).
        steps: (B,) decision steps taken in the current episode.
        stats: the episode accumulators.
    """

    pos_m: FloatArray
    heading_rad: FloatArray
    active: BoolArray
    reached: BoolArray
    start_m: FloatArray
    target_m: FloatArray
    obstacle_pos_m: FloatArray
    obstacle_vel_m_s: FloatArray
    obstacle_speed_m_s: FloatArray
    centre_m: FloatArray
    swarm_vel_m_s: FloatArray
    levels: FloatArray
    avoiding: BoolArray
    window: ArcWindow
    steps: IntArray
    stats: EpisodeStats

    @property
    def num_envs(self) -> int:
        """B."""
        return int(self.pos_m.shape[0])

    def sources(self, swarm_speed_m_s: float, dt_s: float = 0.0) -> FieldSources:
        """Field sources, optionally advanced by ``dt_s`` (obstacles and p* move straight)."""
        return FieldSources(
            obstacle_pos_m=self.obstacle_pos_m + dt_s * self.obstacle_vel_m_s,
            obstacle_speed_m_s=self.obstacle_speed_m_s,
            centre_m=self.centre_m + dt_s * self.swarm_vel_m_s,
            swarm_speed_m_s=swarm_speed_m_s,
        )


@dataclass(frozen=True)
class StepResult:
    """What one step produced, batch first.

    Attributes:
        obs: observations after the step (for the next decision).
        reward: every reward term, (B, N); zero for UAVs that did not fly this step.
        acted: (B, N) UAVs that flew this step.
        turn_rad: (B, N) the heading change flown.
        collided_u2o, collided_u2u: (B, N) collisions during the step, by kind.
        arrived: (B, N) UAVs that reached their target during this step.
        min_u2o_m, min_u2u_m: (B, N) swept closest approach this step (+inf if none).
        terminated: (B,) collision, or every UAV arrived.
        truncated: (B,) step limit reached without termination.
        success: (B,) every UAV arrived and nothing collided.
        levels_assigned: (B,) contour levels were reassigned this step (avoidance began).
    """

    obs: Observations
    reward: RewardTerms
    acted: BoolArray
    turn_rad: FloatArray
    collided_u2o: BoolArray
    collided_u2u: BoolArray
    arrived: BoolArray
    min_u2o_m: FloatArray
    min_u2u_m: FloatArray
    terminated: BoolArray
    truncated: BoolArray
    success: BoolArray
    levels_assigned: BoolArray


def _fresh_stats(b: int, n: int) -> EpisodeStats:
    return EpisodeStats(
        energy_rad=np.zeros((b, n)),
        flown_m=np.zeros((b, n)),
        min_u2o_m=np.full(b, np.inf),
        min_u2u_m=np.full(b, np.inf),
        swarming_return=np.zeros((b, n)),
        total_return=np.zeros((b, n)),
    )


def _difference_operator(n: int, m: int) -> NDArray[np.float32]:
    """The difference operator of the swept checks, (N + M, N·M + P + N).

    It maps [UAV, obstacle] coordinates to UAV i − obstacle k, UAV i − UAV j (i < j) and
    UAV i itself (its target is subtracted afterwards).
    """
    i, j = np.triu_indices(n, k=1)
    op = np.zeros((n + m, n * m + len(i) + n), dtype=np.float32)
    col = np.arange(n * m)
    op[col // m, col] = 1.0  # UAV of the UAV–obstacle pair
    op[n + col % m, col] = -1.0  # obstacle of the pair
    pairs = n * m + np.arange(len(i))
    op[i, pairs], op[j, pairs] = 1.0, -1.0
    own = n * m + len(i) + np.arange(n)
    op[np.arange(n), own] = 1.0
    return op


def _merge(old: object, new: object, mask: BoolArray) -> object:
    """Replace the masked environments of a dataclass of arrays (recursively)."""
    if dataclasses.is_dataclass(old) and not isinstance(old, type):
        fields = {
            f.name: _merge(getattr(old, f.name), getattr(new, f.name), mask)
            for f in dataclasses.fields(old)
        }
        return dataclasses.replace(old, **fields)
    if isinstance(old, np.ndarray):
        out = old.copy()
        out[mask] = new
        return out
    return old


class SwarmSim:
    """The simulator of one scenario: constants computed once, and pure batched functions.

    Every method takes the state and returns a new one; the object holds only the scenario and
    arrays derived from it (never modified), so one instance serves any number of batches.
    """

    def __init__(self, cfg: ScenarioConfig) -> None:
        self.cfg = cfg
        self.layout = swarm_layout(cfg)
        self.obs_layout = ObservationLayout.from_scenario(cfg)
        self.fractions = substep_fractions(cfg.substeps)
        self.pairs = np.triu_indices(cfg.uav.count, k=1)
        self.difference_op = _difference_operator(cfg.uav.count, cfg.obstacles.count)

    def initial_state(self, rng: np.random.Generator, num_envs: int) -> SwarmState:
        """B new episodes: spawn, obstacles, virtual centre, and contour levels by PSO."""
        cfg, layout = self.cfg, self.layout
        b, n = num_envs, cfg.uav.count
        obs_pos, obs_vel = spawn_obstacles(cfg, rng, b)
        pos = np.broadcast_to(layout.positions_m, (b, n, 2)).copy()
        state = SwarmState(
            pos_m=pos,
            heading_rad=np.broadcast_to(layout.headings_rad, (b, n)).copy(),
            active=np.ones((b, n), dtype=bool),
            reached=np.zeros((b, n), dtype=bool),
            start_m=pos.copy(),
            target_m=np.broadcast_to(layout.targets_m, (b, n, 2)).copy(),
            obstacle_pos_m=obs_pos,
            obstacle_vel_m_s=obs_vel,
            obstacle_speed_m_s=np.full((b, cfg.obstacles.count), cfg.obstacles.speed_m_s),
            centre_m=np.broadcast_to(layout.centre_m, (b, 2)).copy(),
            swarm_vel_m_s=np.broadcast_to(layout.velocity_m_s, (b, 2)).copy(),
            levels=np.zeros((b, n)),
            avoiding=np.zeros(b, dtype=bool),
            window=ArcWindow.empty(b, n, cfg.reward.window_steps),
            steps=np.zeros(b, dtype=np.int64),
            stats=_fresh_stats(b, n),
        )
        levels, _ = assign_contour_levels(
            pos, state.sources(cfg.uav.speed_m_s), cfg.field, cfg.pso, rng
        )
        return dataclasses.replace(state, levels=levels)

    def reset_where(
        self, state: SwarmState, mask: BoolArray, rng: np.random.Generator
    ) -> SwarmState:
        """Start new episodes in the environments selected by ``mask`` (B,); others untouched."""
        count = int(mask.sum())
        if count == 0:
            return state
        merged = _merge(state, self.initial_state(rng, count), mask)
        return cast(SwarmState, merged)

    def observe(self, state: SwarmState, envs: BoolArray | None = None) -> Observations:
        """Every UAV's observation of the current state (the shared builder).

        Args:
            envs: (B,) observe only these environments (the result has their count first).
        """
        sel: slice | BoolArray = slice(None) if envs is None else envs
        heading = state.heading_rad[sel]
        velocity = self.cfg.uav.speed_m_s * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
        return build_observations(
            self.obs_layout,
            state.pos_m[sel],
            heading,
            velocity,
            state.target_m[sel],
            state.centre_m[sel],
            state.obstacle_pos_m[sel],
            state.obstacle_vel_m_s[sel],
        )

    def step(
        self, state: SwarmState, actions: NDArray[Any], rng: np.random.Generator
    ) -> tuple[SwarmState, StepResult]:
        """Advance every environment by one decision step.

        Args:
            state: the current state (not modified).
            actions: (B, N) normalised heading changes in [−1, 1] (clipped); ignored for UAVs that
                are not active.
            rng: the caller's generator (PSO when avoidance begins).

        Returns:
            (the next state, what happened). Environments whose episode ended stay ended (their
            UAVs are inactive) until `reset_where` starts a new one.
        """
        cfg = self.cfg
        b, n = state.pos_m.shape[:2]
        m = state.obstacle_pos_m.shape[1]
        dt, length, v_s = cfg.dt_s, cfg.step_length_m, cfg.uav.speed_m_s
        acted = state.active
        commanded = scale_action(np.asarray(actions, dtype=np.float64), cfg.uav.max_turn_rad)
        turn = np.where(acted, commanded, 0.0)
        # ---- kinematics at the T + 1 sub-step instants: arcs for the UAVs (inactive ones stay
        # put: zero length), straight lines for the obstacles.
        # float32 for the sub-step grid (collision checks, reward quadrature: millimetres at
        # kilometre range); the state itself advances in float64.
        f32 = np.float32
        frac = self.fractions  # (T + 1,)
        u = frac.astype(f32)[:, None, None]  # time first: (T + 1, B, N) slices are contiguous
        half = (f32(0.5) * u) * turn.astype(f32)
        chord = (f32(length) * u) * acted * sinc_series(half)  # |half| ≤ a_max/2 ≤ π/4
        direction = state.heading_rad.astype(f32) + half
        px = state.pos_m[..., 0].astype(f32) + chord * np.cos(direction)  # (T + 1, B, N)
        py = state.pos_m[..., 1].astype(f32) + chord * np.sin(direction)
        end_half = 0.5 * turn
        end_chord = length * acted * sinc_series(end_half)
        end_dir = state.heading_rad + end_half
        new_pos = state.pos_m + end_chord[..., None] * np.stack(
            [np.cos(end_dir), np.sin(end_dir)], axis=-1
        )
        new_heading = np.where(acted, wrap_angle(state.heading_rad + turn), state.heading_rad)
        tdt = (dt * frac).astype(f32)[:, None, None]
        obs_pos, obs_vel = state.obstacle_pos_m.astype(f32), state.obstacle_vel_m_s.astype(f32)
        ox = obs_pos[..., 0] + tdt * obs_vel[..., 0]  # (T + 1, B, M)
        oy = obs_pos[..., 1] + tdt * obs_vel[..., 1]

        # ---- swept closest approaches during the step, every kind in one float32 call:
        # UAV–obstacle (N·M), UAV–UAV pairs (P), UAV–own target (N). The relative positions of all
        # of them come from one matrix product with a difference operator.
        i, j = self.pairs
        k_uo, k_uu = n * m, len(i)
        op = self.difference_op  # (N + M, K)
        steps_b = len(frac) * b
        rel = []
        for p, o, t in ((px, ox, state.target_m[..., 0]), (py, oy, state.target_m[..., 1])):
            movers = np.concatenate([p, o], axis=-1).reshape(steps_b, n + m)
            r = (movers @ op).reshape(len(frac), b, -1)  # (T + 1, B, K)
            r[..., k_uo + k_uu :] -= t.astype(np.float32)
            rel.append(r)
        swept = swept_min_distance_xy(*rel).astype(np.float64)  # (B, N·M + P + N)
        d_uo = swept[:, :k_uo].reshape(b, n, m)
        d_pair = np.where(acted[:, i] & acted[:, j], swept[:, k_uo : k_uo + k_uu], np.inf)
        d_target = swept[:, k_uo + k_uu :]
        min_u2o = np.where(acted, d_uo.min(axis=-1, initial=np.inf), np.inf)
        d_uu = np.full((b, n, n), np.inf)
        d_uu[:, i, j] = d_pair
        d_uu[:, j, i] = d_pair
        min_u2u = d_uu.min(axis=-1)

        collided_u2o = acted & (min_u2o < cfg.d_col_m)
        collided_u2u = acted & (min_u2u < cfg.d_col_m)
        collided = collided_u2o | collided_u2u
        arrived = acted & ~collided & (d_target <= cfg.d_col_m)
        any_collision = collided.any(axis=-1)
        reached = state.reached | arrived
        all_reached = reached.all(axis=-1)
        running = acted.any(axis=-1)
        terminated = running & (any_collision | all_reached)
        steps = state.steps + running
        truncated = running & ~terminated & (steps >= cfg.max_steps)
        over = terminated | truncated
        active = acted & ~arrived & ~over[:, None]

        # ---- reward: score the new arc on the mid-step field, push it, evaluate the window
        mid = state.sources(v_s, 0.5 * dt)
        stride = cfg.substeps // cfg.reward.quadrature_intervals
        qx = px[::stride].transpose(1, 2, 0)  # (B, N, Q + 1)
        qy = py[::stride].transpose(1, 2, 0)
        ext = arc_external_xy(
            np.ascontiguousarray(qx),
            np.ascontiguousarray(qy),
            state.levels.astype(np.float32),
            mid,
            cfg.field,
            cfg.reward,
        ).astype(np.float64)
        window = state.window.push(turn, ext, acted)
        terms = reward(
            window, new_heading, new_pos, state.target_m, collided, cfg.uav.max_turn_rad, cfg.reward
        )
        terms = RewardTerms(*(np.where(acted, t, 0.0) for t in dataclasses.astuple(terms)))

        stats = state.stats
        stats = EpisodeStats(
            energy_rad=stats.energy_rad + np.abs(turn),
            flown_m=stats.flown_m + length * acted,
            min_u2o_m=np.minimum(stats.min_u2o_m, min_u2o.min(axis=-1)),
            min_u2u_m=np.minimum(stats.min_u2u_m, min_u2u.min(axis=-1)),
            swarming_return=stats.swarming_return + terms.swarming,
            total_return=stats.total_return + terms.total,
        )
        new_state = SwarmState(
            pos_m=new_pos,
            heading_rad=new_heading,
            active=active,
            reached=reached,
            start_m=state.start_m,
            target_m=state.target_m,
            obstacle_pos_m=state.obstacle_pos_m + dt * state.obstacle_vel_m_s,
            obstacle_vel_m_s=state.obstacle_vel_m_s,
            obstacle_speed_m_s=state.obstacle_speed_m_s,
            centre_m=state.centre_m + dt * state.swarm_vel_m_s,
            swarm_vel_m_s=state.swarm_vel_m_s,
            levels=state.levels,
            avoiding=state.avoiding,
            window=window,
            steps=steps,
            stats=stats,
        )
        obs = self.observe(new_state)

        # ---- avoidance begins: the first sensing of an obstacle reassigns the contour levels
        begin = ~new_state.avoiding & ~over & (obs.sensed & active[..., None]).any(axis=(1, 2))
        if begin.any():
            sub = FieldSources(
                new_state.obstacle_pos_m[begin],
                new_state.obstacle_speed_m_s[begin],
                new_state.centre_m[begin],
                v_s,
            )
            levels, _ = assign_contour_levels(
                new_state.pos_m[begin], sub, cfg.field, cfg.pso, rng, active[begin]
            )
            new_levels = new_state.levels.copy()
            new_levels[begin] = levels
            new_state = dataclasses.replace(
                new_state, levels=new_levels, avoiding=new_state.avoiding | begin
            )
        result = StepResult(
            obs=obs,
            reward=terms,
            acted=acted,
            turn_rad=turn,
            collided_u2o=collided_u2o,
            collided_u2u=collided_u2u,
            arrived=arrived,
            min_u2o_m=min_u2o,
            min_u2u_m=min_u2u,
            terminated=terminated,
            truncated=truncated,
            success=terminated & all_reached & ~any_collision,
            levels_assigned=begin,
        )
        return new_state, result


def initial_state(cfg: ScenarioConfig, rng: np.random.Generator, num_envs: int) -> SwarmState:
    """B new episodes of a scenario (see `SwarmSim.initial_state`)."""
    return SwarmSim(cfg).initial_state(rng, num_envs)


def reset_where(
    state: SwarmState, mask: BoolArray, cfg: ScenarioConfig, rng: np.random.Generator
) -> SwarmState:
    """New episodes where ``mask`` (B,) is set (see `SwarmSim.reset_where`)."""
    return SwarmSim(cfg).reset_where(state, mask, rng)


def observe(state: SwarmState, cfg: ScenarioConfig, envs: BoolArray | None = None) -> Observations:
    """Every UAV's observation (see `SwarmSim.observe`)."""
    return SwarmSim(cfg).observe(state, envs)


def step(
    state: SwarmState, actions: NDArray[Any], rng: np.random.Generator, cfg: ScenarioConfig
) -> tuple[SwarmState, StepResult]:
    """One decision step of every environment (see `SwarmSim.step`)."""
    return SwarmSim(cfg).step(state, actions, rng)
