"""A software-in-the-loop mock autopilot fleet that speaks real MAVLink 2 over UDP.

`fleet.SitlFleet` runs N simulated multirotors in one event loop, each imitating ArduCopter or
PX4: HEARTBEAT, requested or default telemetry streams (`streams`, `telemetry`), the command
and parameter protocols (`commands`, `params`), GUIDED/OFFBOARD setpoints (`setpoints`), a
batched kinematic model (`vehicle`, steered through `motion`), scenario obstacles as ADS-B
traffic (`traffic`), injectable faults (`faults`, acting on the `links`) and the ground truth
of the flight (`groundtruth`). numpy only; no torch.

The autopilot logic is `autopilot.Autopilot`, an abstract base class: both flavours' common
rules, with the flavours' values as data (`flavour.FlavourSpec`, a mode table of
`flavour.ModeRules`) and their own behaviour in `ardupilot.ArduCopterLogic` and
`px4.Px4Logic`. Settings are `config`; a vehicle's replies and counters go through its
`channel.Channel`.
"""
