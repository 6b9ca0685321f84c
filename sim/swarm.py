"""The vectorised swarm simulator: state, reset and one pure batched step.

``step(state, actions, rng, cfg) -> (state, StepResult)`` advances B environments of N UAVs and
M obstacles by one decision step, with no per-agent Python loop:

1. every active UAV flies the constant-turn-rate arc of its action (with the "ideal" vehicle
   of the paper), or follows it as a command with its vehicle's fitted lag and limits
   (`sim.dynamics`); obstacles fly straight; the virtual centre keeps the swarm's initial
   velocity;
2. swept checks find the closest approach, *during* the step, of every UAV to every obstacle,
   to every other UAV and to its target (`sim.metrics`);
3. collisions (closer than d_col) end the episode; a UAV that comes within d_col of its target
   has arrived: it stops acting and hovers where its step ends (brakes, with a fitted
   vehicle), and stays in every separation check until the episode ends, as ``fly`` holds it
   (``arrival = "leave"``: the paper's rule, it leaves the episode); all arrived is a
   success; the step limit truncates;
4. every UAV's new arc is scored against the field at mid-step and pushed into its contour
   window; the full reMARL reward and its Swarming part are computed for all agents at once;
5. contour levels are (re)assigned by PSO where SPEC §6 says: at episode start (`reset`) and on
   the first step on which any UAV of an environment senses an obstacle (avoidance begins).

Each stage is a pure function of `sim.transition`; the state and the step's result are the
dataclasses of `sim.state`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.arrays import BoolArray, FloatArray
from sim.config import ScenarioConfig
from sim.contour import ArcWindow
from sim.dynamics import ResponseSpec
from sim.kinematics import heading_velocity, scale_action
from sim.metrics import substep_fractions
from sim.observation import ObservationLayout, Observations, build_observations
from sim.reward import RewardTerms, assign_contour_levels
from sim.sensors import AdsbTracks, gps_error, picture
from sim.sensors import update as sensor_update
from sim.spawn import EpisodeStart, group_index, obstacle_speeds, spawn_episodes, swarm_layout
from sim.state import EpisodeStats, StepResult, SwarmState, merge_where
from sim.transition import (
    accumulate,
    begin_avoidance,
    closest_approaches,
    fly,
    fly_with_response,
    outcome,
    pair_members,
    score,
)

__all__ = [
    "EpisodeStats",
    "StepResult",
    "SwarmSim",
    "SwarmState",
    "initial_state",
    "observe",
    "reset_where",
    "step",
]


class SwarmSim:
    """The simulator of one scenario: constants computed once, and pure batched functions.

    Every method takes the state and returns a new one; the object holds only the scenario and
    arrays derived from it (never modified), so one instance serves any number of batches.
    """

    def __init__(self, cfg: ScenarioConfig, *, scored: bool = True) -> None:
        """The simulator of ``cfg``.

        Args:
            cfg: the scenario.
            scored: compute the reward (contour windows, PSO levels). An evaluation that
                reports no returns passes False: the flight, the collisions and every other
                metric are the same, the returns stay 0, and a step costs a fraction.
        """
        self.cfg = cfg
        self.scored = scored
        self.layout = swarm_layout(cfg)
        self.groups = group_index(cfg.uav)
        self.obs_layout = ObservationLayout.from_scenario(cfg)
        self.fractions = substep_fractions(cfg.substeps)
        self.pairs = np.triu_indices(cfg.uav.count, k=1)
        self.pair_members = pair_members(cfg.uav.count)
        self.response = ResponseSpec.from_scenario(cfg)
        self.ideal = self.response is None

    def initial_state(self, rng: np.random.Generator, num_envs: int) -> SwarmState:
        """B new episodes of the scenario (`sim.spawn.spawn_episodes`), levels by PSO."""
        return self.start(spawn_episodes(self.cfg, rng, num_envs, self.layout), rng)

    def start(self, episodes: EpisodeStart, rng: np.random.Generator) -> SwarmState:
        """New episodes from given starts, targets and obstacles; contour levels by PSO.

        Every UAV heads for its target unless ``episodes`` gives headings, in flight at the
        UAV speed. ``rng`` serves the randomised vehicle responses (only where the scenario
        randomises them) and the PSO.
        """
        cfg = self.cfg
        episodes.check(cfg)
        b, n = episodes.num_envs, cfg.uav.count
        pos = episodes.start_m.copy()
        heading = episodes.headings().copy()
        state = SwarmState(
            pos_m=pos,
            heading_rad=heading,
            active=np.ones((b, n), dtype=bool),
            reached=np.zeros((b, n), dtype=bool),
            start_m=pos.copy(),
            target_m=episodes.target_m.copy(),
            obstacle_pos_m=episodes.obstacle_pos_m.copy(),
            obstacle_vel_m_s=episodes.obstacle_vel_m_s.copy(),
            obstacle_speed_m_s=obstacle_speeds(episodes.obstacle_vel_m_s),
            obstacle_appear_step=episodes.obstacle_appear_step.copy(),
            centre_m=episodes.centre_m.copy(),
            swarm_vel_m_s=episodes.swarm_vel_m_s.copy(),
            levels=np.zeros((b, n)),
            avoiding=np.zeros(b, dtype=bool),
            window=ArcWindow.empty(b, n, cfg.reward.window_steps),
            steps=np.zeros(b, dtype=np.int64),
            stats=EpisodeStats.fresh(b, n),
            vel_m_s=heading_velocity(heading, cfg.uav.speed_m_s),
            speed_m_s=np.full((b, n), cfg.uav.speed_m_s),
            last_turn_rad=np.zeros((b, n)),
            response=None if self.response is None else self.response.draw(b, n, rng),
            tracks=None,
            gps_error_m=np.zeros((b, n, 2)),
        )
        state = self._sense(state, rng)
        if not self.scored:
            return state
        levels, _ = assign_contour_levels(
            pos, state.sources(cfg.uav.speed_m_s), cfg.field, cfg.pso, rng
        )
        return state.evolve(levels=levels)

    def reset_where(
        self, state: SwarmState, mask: BoolArray, rng: np.random.Generator
    ) -> SwarmState:
        """Start new episodes in the environments selected by ``mask`` (B,); others untouched."""
        return self.restart_where(state, mask, rng)[0]

    def restart_where(
        self, state: SwarmState, mask: BoolArray, rng: np.random.Generator
    ) -> tuple[SwarmState, SwarmState | None]:
        """`reset_where`, and the new episodes alone (their count first; None if none).

        The autoreset observes the new episodes from the second (the same numbers as observing
        them in the first, without selecting them again).
        """
        count = int(mask.sum())
        if count == 0:
            return state, None
        fresh = self.initial_state(rng, count)
        return merge_where(state, fresh, mask), fresh

    def _sense(self, state: SwarmState, rng: np.random.Generator) -> SwarmState:
        """What the UAVs know at this decision: new ADS-B reports and GPS errors.

        Exact sensing (the paper) draws nothing. With "adsb" (`sim.sensors`) every obstacle's
        track takes the reports that arrived by now (a pop-up transmits from when it appears,
        the others all along), and every UAV position gets a fresh GPS error.
        """
        sensors = self.cfg.sensors
        if sensors.model == "exact":
            return state
        b, m = state.obstacle_pos_m.shape[:2]
        tracks = state.tracks
        if tracks is None:
            tracks = AdsbTracks.fresh(b, m, sensors, rng)
        dt = self.cfg.dt_s
        hidden = state.obstacle_appear_step > 0
        since = np.where(hidden, state.obstacle_appear_step * dt, -np.inf)
        now = (state.steps * dt).astype(np.float64)[:, None]
        tracks = sensor_update(
            tracks, state.obstacle_pos_m, state.obstacle_vel_m_s, now, since, sensors, rng
        )
        error = gps_error(state.pos_m.shape, sensors.gps_sigma_m, rng)
        return state.evolve(tracks=tracks, gps_error_m=error)

    def observe(
        self,
        state: SwarmState,
        envs: BoolArray | None = None,
        heading_cos_sin: tuple[FloatArray, FloatArray] | None = None,
        layout: ObservationLayout | None = None,
        commanded_heading_rad: FloatArray | None = None,
    ) -> Observations:
        """Every UAV's observation of the current state (the shared builder).

        With exact sensing the obstacles are where they are; with ADS-B they are the tracks'
        picture (late, noisy, extrapolated; lost tracks are not seen), and the UAV positions
        carry their GPS errors.

        Args:
            envs: (B,) observe only these environments (the result has their count first).
            heading_cos_sin: cos and sin of the observed UAVs' headings, where the caller has
                them (None: computed).
            layout: the observation to build (None: the scenario's): a policy brings its own
                (a generalist's version 2 on a scenario of version 1).
            commanded_heading_rad: version 2: (B, N) of the observed environments, the heading
                each UAV's neighbours see it commanded to fly (their Δψ). None: the heading it
                flies, which is what the simulator's UAVs are commanded; another (e.g. the
                heading after this step's proposal) asks what a different message would show.
        """
        sel: slice | BoolArray = slice(None) if envs is None else envs
        heading = state.heading_rad[sel]
        if heading_cos_sin is None:
            heading_cos_sin = np.cos(heading), np.sin(heading)
        cos_h, sin_h = heading_cos_sin
        # `heading_velocity`, from the cos and sin at hand: the same numbers.
        velocity = self.cfg.uav.speed_m_s * np.stack([cos_h, sin_h], axis=-1)
        if state.tracks is None:
            obstacle_pos = state.obstacle_pos_m[sel]
            obstacle_vel = state.obstacle_vel_m_s[sel]
            seen = state.obstacle_visible[sel]
        else:
            now = (state.steps[sel] * self.cfg.dt_s).astype(np.float64)[:, None]
            picked = state.tracks if envs is None else _select(state.tracks, sel)
            pos, vel, seen = picture(picked, now)
            obstacle_pos = np.where(seen[..., None], pos, 0.0)
            obstacle_vel = np.where(seen[..., None], vel, 0.0)
        layout = self.obs_layout if layout is None else layout
        neighbours: dict[str, Any] = {}
        if layout.version == 2:  # the other UAVs still in the episode, and where they head
            present = state.active[sel] | state.hovering(self.cfg.arrival)[sel]
            told = heading if commanded_heading_rad is None else commanded_heading_rad
            neighbours = {
                "uav_valid": present,
                "commanded_heading_rad": told,
                "uav_group": self.groups,  # other swarms' UAVs are intruder rows
            }
            velocity = velocity * (state.speed_m_s[sel] / self.cfg.uav.speed_m_s)[..., None]
        return build_observations(
            layout,
            state.pos_m[sel] + state.gps_error_m[sel],
            heading,
            velocity,
            state.target_m[sel],
            state.centre_m[sel][:, self.groups],  # each UAV's swarm's p*
            obstacle_pos,
            obstacle_vel,
            seen,
            heading_cos_sin,
            **neighbours,
        )

    def step(
        self,
        state: SwarmState,
        actions: NDArray[Any],
        rng: np.random.Generator,
        speeds_m_s: NDArray[Any] | None = None,
    ) -> tuple[SwarmState, StepResult]:
        """Advance every environment by one decision step (the module docstring's steps 1–5).

        Args:
            state: the current state (not modified).
            actions: (B, N) normalised heading changes in [−1, 1] (clipped); ignored for UAVs that
                are not active.
            rng: the caller's generator (PSO when avoidance begins).
            speeds_m_s: (B, N) commanded speeds, clipped to [0, the UAV speed]; None: the UAV
                speed (the paper's policies command headings only; a multirotor may also slow
                down and stop, which later policies and the safety shield use).

        Returns:
            (the next state, what happened). Environments whose episode ended stay ended (their
            UAVs are inactive) until `reset_where` starts a new one.
        """
        cfg = self.cfg
        dt = cfg.dt_s
        acted = state.active
        present = acted | state.hovering(cfg.arrival)
        commanded = scale_action(np.asarray(actions, dtype=np.float64), cfg.uav.max_turn_rad)
        turn = np.where(acted, commanded, 0.0)
        cruise = cfg.uav.speed_m_s
        speed = (
            np.full(acted.shape, cruise)
            if speeds_m_s is None
            else np.clip(np.asarray(speeds_m_s, dtype=np.float64), 0.0, cruise)
        )
        speed = np.where(acted, speed, 0.0)
        if self.ideal:
            flight = fly(state, turn, acted, self.fractions, speed * dt, dt)
        else:
            flight = fly_with_response(state, turn, speed, acted, present, self.fractions, dt)
        near = closest_approaches(
            flight,
            state.target_m,
            acted,
            present,
            self.pairs,
            self.pair_members,
        )
        out = outcome(state, acted, near, cfg.d_col_m, cfg.max_steps)
        heading_cos_sin = np.cos(flight.heading_rad), np.sin(flight.heading_rad)
        if self.scored:
            window, terms = score(state, flight, turn, acted, out.collided, cfg, heading_cos_sin)
        else:
            window, terms = state.window, _unscored(turn)
        moved = state.evolve(
            pos_m=flight.pos_m,
            heading_rad=flight.heading_rad,
            active=out.active,
            reached=out.reached,
            obstacle_pos_m=state.obstacle_pos_m + dt * state.obstacle_vel_m_s,
            centre_m=state.centre_m + dt * state.swarm_vel_m_s,
            window=window,
            steps=out.steps,
            stats=accumulate(state.stats, turn, flight.flown_m, near, terms),
            vel_m_s=flight.vel_m_s,
            speed_m_s=np.where(present, speed, state.speed_m_s),
            last_turn_rad=np.where(present, turn, state.last_turn_rad),
        )
        moved = self._sense(moved, rng)
        obs = self.observe(moved, heading_cos_sin=heading_cos_sin)
        if self.scored:
            new_state, begin = begin_avoidance(moved, obs, out.over, cfg, rng)
        else:
            new_state, begin = moved, np.zeros(state.num_envs, dtype=bool)
        result = StepResult(
            obs=obs,
            reward=terms,
            acted=acted,
            turn_rad=turn,
            collided_u2o=out.collided_u2o,
            collided_u2u=out.collided_u2u,
            arrived=out.arrived,
            min_u2o_m=near.min_u2o_m,
            min_u2u_m=near.min_u2u_m,
            terminated=out.terminated,
            truncated=out.truncated,
            success=out.success,
            levels_assigned=begin,
        )
        return new_state, result


def _select(tracks: AdsbTracks, sel: slice | BoolArray) -> AdsbTracks:
    """The tracks of the selected environments."""
    return AdsbTracks(**{f.name: getattr(tracks, f.name)[sel] for f in dataclasses.fields(tracks)})


def _unscored(like: NDArray[Any]) -> RewardTerms:
    zero = np.zeros_like(like, dtype=np.float64)
    return RewardTerms(zero, zero, zero, zero, zero)


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
