"""Numpy-only simulator core of remarl-fc.

Modules: `sim.config` (defaults), `sim.scenarios` (TOML scenarios), `sim.spawn` (layouts),
`sim.field` (potential field Φ), `sim.kinematics` (arcs), `sim.contour` (active-contour cost),
`sim.reward` (reMARL reward), `sim.pso` (contour-level separation), `sim.metrics` (swept
distances, energy), `sim.observation` (the one observation builder), `sim.state` (the
simulator's state), `sim.transition` (the stages of one step), `sim.swarm` (the simulator),
`sim.vector_env` and `sim.env` (Gymnasium and PettingZoo faces), `sim.evaluation` (episodes,
metrics and evaluation seeds of every method), `sim.heuristics` and `sim.orca` (hand-written
controllers), `sim.render` (pictures) and
`sim.arrays` (array types). Arrays are batch first: (envs, agents, ...).
"""

from sim.config import (
    FieldConfig,
    ObstacleConfig,
    PSOConfig,
    RewardConfig,
    ScenarioConfig,
    SensingConfig,
    UAVConfig,
)
from sim.errors import ConfigError, RemarlError, ScenarioError
from sim.scenarios import load_scenario, scenario_names

__all__ = [
    "ConfigError",
    "FieldConfig",
    "ObstacleConfig",
    "PSOConfig",
    "RemarlError",
    "RewardConfig",
    "ScenarioConfig",
    "ScenarioError",
    "SensingConfig",
    "UAVConfig",
    "load_scenario",
    "scenario_names",
]
