"""``remarl-fc rollout``: fly one episode with a hand-written policy and draw it.

A PNG shows the last frame (field contours, UAVs, obstacles, targets and the whole trails); a
GIF animates every step. Files are written atomically (a partial file never appears).

Also the act functions of the offline evaluation: `policy_by_name` (hand-written),
`PolicyFileAct` (a loaded policy file), and `observe_for`, the observations an act function
reads (a generalist's own layout, else the scenario's).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.policy_io import Policy as LoadedPolicy
from sim.config import ScenarioConfig
from sim.env import episode_metrics
from sim.errors import ConfigError
from sim.heuristics import potential_field_actions, straight_actions
from sim.observation import ObservationLayout
from sim.orca import orca_actions
from sim.scenarios import load_scenario
from sim.state import SwarmState
from sim.swarm import SwarmSim

POLICIES = ("straight", "potential-field", "orca")
"""Hand-written policies `rollout` can fly."""

GIF_FRAME_MS = 250
"""Duration of one GIF frame (one decision step), milliseconds."""

Policy = Callable[[NDArray[np.float32], SwarmState, ScenarioConfig], NDArray[np.float32]]
"""A hand-written policy: (flat observations (B, N, D), the simulator state, the scenario) →
normalised actions (B, N). Policies that act on what a UAV observes read the observations; a
classical planner such as ORCA reads the state (positions, velocities, targets)."""


def policy_by_name(name: str) -> Policy:
    """The hand-written policy called ``name`` (see `POLICIES`)."""
    if name == "straight":
        return lambda obs, state, cfg: straight_actions(obs)
    if name == "potential-field":
        return lambda obs, state, cfg: potential_field_actions(
            obs, cfg.sensing.max_obstacles, cfg.uav.max_turn_rad
        )
    if name == "orca":
        return lambda obs, state, cfg: orca_actions(state, cfg)
    raise ConfigError(f"unknown policy {name!r}; choose one of: {', '.join(POLICIES)}")


class PolicyFileAct:
    """A loaded policy file as an act function: (obs, state, cfg) → its actions (B, N).

    Attributes:
        policy: the policy. layout: the observation it reads where that is not the scenario's
            (a generalist's version 2), None otherwise: the caller observes with `observe_for`.
    """

    def __init__(self, policy: LoadedPolicy) -> None:
        self.policy = policy
        self.layout: ObservationLayout | None = policy.layout if policy.generalist else None

    def __call__(
        self, obs: NDArray[np.float32], state: SwarmState, cfg: ScenarioConfig
    ) -> NDArray[np.float32]:
        """The policy's actions (B, N) for the observations (B, N, D) of its layout."""
        return self.policy.act(obs)


def observe_for(sim: SwarmSim, state: SwarmState, act: object) -> NDArray[np.float32]:
    """(B, N, D) the flat observations ``act`` reads.

    With ``act.layout`` where it has one (a `PolicyFileAct` of a generalist), else the
    scenario's layout.
    """
    return sim.observe(state, layout=getattr(act, "layout", None)).flat()


def rollout(scenario: str, policy: str, out: Path, seed: int = 0) -> dict[str, Any]:
    """Fly one episode of ``scenario`` with ``policy`` and draw it to ``out`` (.png or .gif).

    Returns:
        The episode's metrics (success, collisions, min distances, energy, returns, length).
    """
    from sim.render import render_frame

    suffix = out.suffix.lower()
    if suffix not in (".png", ".gif"):
        raise ConfigError(f"--out must end in .png or .gif, got {out.name!r}")
    act = policy_by_name(policy)
    cfg = load_scenario(scenario)
    sim = SwarmSim(cfg)
    rng = np.random.default_rng(seed)
    state = sim.initial_state(rng, 1)
    trail = [state.pos_m[0].copy()]
    frames = [render_frame(cfg, state, 0, np.asarray(trail))] if suffix == ".gif" else []
    episode: dict[str, Any] = {}
    for _ in range(cfg.max_steps):
        state, result = sim.step(state, act(observe_for(sim, state, act), state, cfg), rng)
        trail.append(state.pos_m[0].copy())
        if suffix == ".gif":
            frames.append(render_frame(cfg, state, 0, np.asarray(trail)))
        done = result.terminated | result.truncated
        if done[0]:
            episode = {k: _plain(v[0]) for k, v in episode_metrics(state, result, done).items()}
            break
    if not frames:
        frames = [render_frame(cfg, state, 0, np.asarray(trail))]
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".part")
    _write_image(tmp, frames, suffix)
    tmp.replace(out)
    return {"scenario": cfg.name, "policy": policy, "seed": seed, "out": str(out), **episode}


def _write_image(path: Path, frames: list[NDArray[np.uint8]], suffix: str) -> None:
    from PIL import Image

    images = [Image.fromarray(f) for f in frames]
    if suffix == ".gif":
        images[0].save(
            path,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=GIF_FRAME_MS,
            loop=0,
        )
    else:
        images[-1].save(path, format="PNG")


def _plain(value: Any) -> Any:
    """JSON-ready: numpy scalars and arrays to Python, NaN (no value) to None."""
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    return None if isinstance(value, float) and np.isnan(value) else value
