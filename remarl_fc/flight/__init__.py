"""The ``fly`` runtime: MAVLink telemetry in, policy decisions, setpoints out.

* ``core`` — the decisions as pure functions (`next_actions`): safety checks, status changes,
  what to send; ``status`` — the status machine and its allowed transitions;
* ``runtime`` — the asyncio shell (`SwarmRuntime`): links, tasks, clocks, carrying out the
  core's commands; ``prepare`` — streams, parameter check, take-off; ``commands`` — COMMAND_LONG
  with retries, mode changes, deadline-bound waits;
* ``control`` — the policy as arcs and setpoints (observations from `sim.observation`);
  ``tracking`` — telemetry and ADS-B state; ``mission`` — the mission file; ``paramcheck`` —
  failsafe parameters; ``peers`` — the swarm bus glue; ``flightlog``, ``report`` — logs, the
  console and the summary; ``config`` — `FlyConfig`, the clock, the per-vehicle I/O rows.
"""
