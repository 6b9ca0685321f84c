"""Training side of remarl-fc (torch): agents, baselines, replay, training loops, export.

Modules: `policies.config` (DDPG and training defaults), `policies.ddpg` and `policies.buffer`
(per-agent DDPG), `policies.train` (its training loop), `policies.export` (policy files),
`policies.common` (the baselines' heading set, the learning-curve file), `policies.coma` and
`policies.coma_train` (COMA), `policies.baseline_env`, `policies.benchmarl_task` and
`policies.benchmarl_train` (MAPPO, IQL, VDN, QMIX through BenchMARL, the ``baselines`` extra),
`policies.e2coop` (the contour meta-heuristic), `policies.compare` (``remarl-fc compare``).

Imports point one way: `policies` uses `sim`; `remarl_fc` imports `policies` only lazily,
inside the commands that train, compare or export.
"""
