"""Numpy-only simulator core of remarl-fc.

Modules: `sim.config` (defaults), `sim.scenarios` (TOML scenarios), `sim.spawn` (layouts),
`sim.field` (potential field Φ), `sim.kinematics` (arcs), `sim.contour` (active-contour cost),
`sim.reward` (reMARL reward), `sim.pso` (contour-level separation), `sim.metrics` (episode
metrics). Arrays are batch first: (envs, agents, ...).
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
