"""The ``remarl-fc bench`` measurements.

Simulator and PSO (``sim``), the mock fleet (``sitl``), the flight runtime against the mock
(``fly``), the swarm bus (``bus``).
"""
