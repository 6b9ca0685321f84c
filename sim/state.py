"""The simulator's state and what one step produces: typed dataclasses of arrays, batch first.

`SwarmState` holds everything the simulator knows about B environments; `StepResult` what one
step of `sim.swarm.SwarmSim` produced; `EpisodeStats` the per-episode accumulators behind the
metrics. All are frozen: a step returns new ones (`dataclasses.replace`), and `merge_where`
replaces the environments a partial reset restarts.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from sim.arrays import BoolArray, FloatArray, IntArray
from sim.config import Arrival
from sim.contour import ArcWindow
from sim.dynamics import Response
from sim.field import FieldSources
from sim.observation import Observations
from sim.reward import RewardTerms
from sim.sensors import AdsbTracks

T = TypeVar("T")


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

    @classmethod
    def fresh(cls, b: int, n: int) -> EpisodeStats:
        """Accumulators of B new episodes of N UAVs (nothing flown, no approach yet)."""
        return cls(
            energy_rad=np.zeros((b, n)),
            flown_m=np.zeros((b, n)),
            min_u2o_m=np.full(b, np.inf),
            min_u2u_m=np.full(b, np.inf),
            swarming_return=np.zeros((b, n)),
            total_return=np.zeros((b, n)),
        )


@dataclass(frozen=True)
class SwarmState:
    """Everything the simulator knows about B environments, batch first.

    Attributes:
        pos_m: (B, N, 2) UAV positions.  heading_rad: (B, N).
        active: (B, N) UAVs still flying (not arrived; the episode is not over).
        reached: (B, N) UAVs that arrived at their target.
        start_m: (B, N, 2) spawn positions.  target_m: (B, N, 2).
        obstacle_pos_m, obstacle_vel_m_s: (B, M, 2).  obstacle_speed_m_s: (B, M).
        obstacle_appear_step: (B, M) the decision step from which each obstacle can be sensed
            (a late pop-up is hidden before it, though it is there and collides).
        centre_m: (B, G, 2) each swarm's virtual centre p* (G = 1 but for `UAVConfig.groups`).
        swarm_vel_m_s: (B, G, 2) their constant velocities.
        levels: (B, N) contour levels φ_i.
        avoiding: (B,) whether avoidance has begun (levels were reassigned for it).
        window: the contour windows (B, N, K).
        steps: (B,) decision steps taken in the current episode.
        stats: the episode accumulators.
        vel_m_s: (B, N, 2) UAV velocities (the commanded ones for the ideal vehicle; 0 while
            hovering).
        speed_m_s: (B, N) speed of each UAV's last commanded arc (0 once arrived).
        last_turn_rad: (B, N) heading change of each UAV's last commanded arc.
        response: each UAV's vehicle response (`sim.dynamics`), None for the ideal vehicle.
        tracks: the ADS-B tracks of the obstacles (`sim.sensors`), None when sensing is exact.
        gps_error_m: (B, N, 2) the GPS error of each UAV's position at this decision (0 when
            sensing is exact).
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
    obstacle_appear_step: IntArray
    centre_m: FloatArray
    swarm_vel_m_s: FloatArray
    levels: FloatArray
    avoiding: BoolArray
    window: ArcWindow
    steps: IntArray
    stats: EpisodeStats
    vel_m_s: FloatArray
    speed_m_s: FloatArray
    last_turn_rad: FloatArray
    response: Response | None
    tracks: AdsbTracks | None
    gps_error_m: FloatArray

    @property
    def num_envs(self) -> int:
        """B."""
        return int(self.pos_m.shape[0])

    def evolve(self, **changes: Any) -> SwarmState:
        """This state with the given fields replaced: `dataclasses.replace`'s result.

        A step makes several new states, and `dataclasses.replace` passes all 23 fields through
        the constructor (7 µs, against 1 µs here): the fields are copied as they are instead
        (the same objects; only their names are checked).
        """
        unknown = changes.keys() - self.__dict__.keys()
        if unknown:
            raise TypeError(f"SwarmState has no field {', '.join(sorted(unknown))}")
        new = object.__new__(SwarmState)
        new.__dict__.update(self.__dict__)
        new.__dict__.update(changes)
        return new

    def hovering(self, arrival: Arrival) -> BoolArray:
        """(B, N) UAVs that arrived and hover where they stopped, while the episode goes on.

        None under the paper's rule (``arrival`` "leave"): they left.
        """
        if arrival == "leave":
            return np.zeros_like(self.reached)
        # `.any`'s numbers without its Python wrapper (every step asks)
        running = np.logical_or.reduce(self.active, axis=-1, keepdims=True)
        hover: BoolArray = self.reached & running
        return hover

    def exactly_sensed(self) -> SwarmState:
        """This state as exact sensors would report it (itself where sensing is exact).

        The true intruders, no ADS-B tracks, and the true positions, no GPS error: what a
        privileged teacher reads (`policies.config.GeneralistConfig.teacher_truth`).
        """
        if self.tracks is None and not self.gps_error_m.any():
            return self
        return self.evolve(tracks=None, gps_error_m=np.zeros_like(self.gps_error_m))

    @property
    def obstacle_visible(self) -> BoolArray:
        """(B, M) obstacles that can be sensed now (not hidden as a late pop-up)."""
        visible: BoolArray = self.obstacle_appear_step <= self.steps[:, None]
        return visible

    def sources(self, swarm_speed_m_s: float, dt_s: float = 0.0) -> FieldSources:
        """Field sources, optionally advanced by ``dt_s`` (obstacles and p* move straight).

        Hidden obstacles (`obstacle_visible`) are no sources: the field is what the UAVs know.
        """
        return FieldSources(
            obstacle_pos_m=self.obstacle_pos_m + dt_s * self.obstacle_vel_m_s,
            obstacle_speed_m_s=self.obstacle_speed_m_s,
            centre_m=self.centre_m + dt_s * self.swarm_vel_m_s,
            swarm_speed_m_s=swarm_speed_m_s,
            obstacle_mask=self.obstacle_visible,
        )


@dataclass(frozen=True)
class StepResult:
    """What one step produced, batch first.

    Attributes:
        obs: observations after the step (for the next decision).
        reward: every reward term, (B, N); zero for UAVs that did not fly this step.
        acted: (B, N) UAVs that flew this step (not those hovering where they arrived).
        turn_rad: (B, N) the heading change flown.
        collided_u2o, collided_u2u: (B, N) collisions during the step, by kind (a hovering UAV
            that is run into counts).
        arrived: (B, N) UAVs that reached their target during this step.
        min_u2o_m, min_u2u_m: (B, N) swept closest approach this step (+inf if none), hovering
            UAVs included.
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


def merge_where(old: T, new: T, mask: BoolArray) -> T:
    """``old`` with the environments selected by ``mask`` (B,) taken from ``new`` (count first).

    Recursive over dataclasses of arrays (a `SwarmState`, its window and stats); anything else
    is kept from ``old``.
    """
    return _merge_at(old, new, np.flatnonzero(mask))


def _merge_at(old: T, new: T, envs: IntArray) -> T:
    """`merge_where` with the selected environments as indices, ``envs`` (count,).

    Found once, used by every array: an index assignment skips the search a mask makes. It runs
    at every autoreset, so it stays lean: the arrays among a dataclass's fields are merged in
    its loop (no call each), and the merged dataclass is built by its constructor (what
    `dataclasses.replace` does, given every field).
    """
    if isinstance(old, np.ndarray):
        out = old.copy()
        out[envs] = new
        return out
    if dataclasses.is_dataclass(old) and not isinstance(old, type):
        merged: dict[str, Any] = {}
        for f in dataclasses.fields(old):
            value = getattr(old, f.name)
            if isinstance(value, np.ndarray):  # most fields: no call for them
                array = value.copy()
                array[envs] = getattr(new, f.name)
                merged[f.name] = array
            else:
                merged[f.name] = _merge_at(value, getattr(new, f.name), envs)
        built: T = type(old)(**merged)
        return built
    return old
