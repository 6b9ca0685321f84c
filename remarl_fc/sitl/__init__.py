"""A software-in-the-loop mock autopilot fleet that speaks real MAVLink 2 over UDP.

`fleet.SitlFleet` runs N simulated multirotors in one event loop, each imitating ArduCopter or
PX4 (`autopilot`): HEARTBEAT, requested or default telemetry streams (`telemetry`), the command
protocol, GUIDED/OFFBOARD setpoints (`setpoints`), a batched kinematic model (`vehicle`),
scenario obstacles as ADS-B traffic (`traffic`), injectable faults (`faults`) and the ground
truth of the flight (`groundtruth`). numpy only; no torch.
"""
