"""Work on the ground, no vehicle involved.

Evaluate a policy in the simulator (``evaluate``), fly one episode with a hand-written policy
(``rollout``), draw fields, episodes and flights (``plots``).
"""
