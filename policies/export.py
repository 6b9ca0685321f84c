"""Export a trained swarm to one self-describing policy file (safetensors, no pickle).

Tensors: the actors (``actor.*``) — all inference needs — and the critics (``critic.*``) for
Q-value plots, each with a leading agent dimension (1 when parameters are shared). Metadata
(``remarl_policy``, JSON): schema version, scenario and its units, observation layout and scales,
action bound, dt, speed, agent count, sharing, network size, training commit, metrics.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import subprocess
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import save_file

from policies.config import DDPGConfig
from policies.ddpg import DDPGNets
from policies.train import load_checkpoint
from sim.observation import CLIP, COLUMNS, ObservationLayout
from sim.scenarios import load_scenario

POLICY_SCHEMA = 1
"""Version of the policy file layout; `remarl_fc.policy_io` refuses others."""


def _commit() -> str:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
            cwd=Path(__file__).resolve().parent,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() or "unknown"


def export_policy(
    run_dir: Path, out: Path, *, checkpoint: str = "best", metrics: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Write ``out`` from a training run folder; returns the metadata written.

    Args:
        run_dir: the ``--out`` folder of ``remarl-fc train``.
        checkpoint: "best" or "last".
        metrics: evaluation figures to embed (e.g. the eval JSON of the shipped policy).
    """
    config = json.loads((run_dir / "config.json").read_text())
    train_cfg = config["train"]
    cfg = load_scenario(train_cfg["scenario"])
    ddpg = DDPGConfig(**train_cfg["ddpg"])
    layout = ObservationLayout.from_scenario(cfg)
    agents = 1 if ddpg.shared else cfg.uav.count
    nets = DDPGNets.create(agents, layout.size, ddpg)
    meta_ckpt = load_checkpoint(run_dir / f"{checkpoint}.safetensors", nets)
    tensors: dict[str, torch.Tensor] = {}
    for prefix, module in (("actor", nets.actor), ("critic", nets.critic)):
        for key, value in module.state_dict().items():
            tensors[f"{prefix}.{key}"] = value.detach().contiguous().to(torch.float32)
    scenario = dataclasses.asdict(cfg)
    meta = {
        "schema": POLICY_SCHEMA,
        "scenario": cfg.name,
        "scenario_config": scenario,
        "scenario_hash": hashlib.sha256(json.dumps(scenario, sort_keys=True).encode()).hexdigest(),
        "agents": cfg.uav.count,
        "shared": ddpg.shared,
        "hidden": ddpg.hidden,
        "observation": {
            **dataclasses.asdict(layout),
            "size": layout.size,
            "rows": layout.rows,
            "columns": COLUMNS,
            "clip": CLIP,
            "frame": "heading (x ahead, y left); positions / range_m, velocities / speed_m_s",
        },
        "action": {"normalised_bound": 1.0, "max_turn_rad": cfg.uav.max_turn_rad},
        "dt_s": cfg.dt_s,
        "speed_m_s": cfg.uav.speed_m_s,
        "d_col_m": cfg.d_col_m,
        "reward": train_cfg["reward"],
        "training": {"commit": _commit(), "steps": meta_ckpt["step"], "seed": train_cfg["seed"]},
        "metrics": metrics or {},
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".part")
    save_file(tensors, str(tmp), metadata={"remarl_policy": json.dumps(meta)})
    tmp.replace(out)
    return meta
