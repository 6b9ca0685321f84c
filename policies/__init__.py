"""Training side of remarl-fc (torch): agents, baselines, replay, training loops, export.

Imports point one way: `policies` uses `sim`; `remarl_fc` imports `policies` only lazily,
inside the commands that train, compare or export.
"""
