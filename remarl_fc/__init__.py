"""remarl-fc: cooperative collision avoidance for UAV swarms, from training to flight.

The product face of the project; no module here imports torch on the flight path. Rooms:

* ``flight/`` — the `fly` runtime: a sans-I/O decision core (``core``, ``status``) inside a thin
  asyncio shell (``runtime``), with preparation and take-off, the command channel, the policy
  controller, telemetry tracking, the mission file, parameter checks, the swarm-bus glue and
  the flight log;
* ``mavlink/`` — MAVLink 2: codec (signing), UDP endpoint, links (udp/tcp/serial), named
  numbers, the parameter wire encoding;
* ``bus/`` — the swarm bus between `fly` processes (in-process or MQTT);
* ``sitl/`` — the mock autopilot fleet (ArduCopter and PX4 flavours over real MAVLink);
* ``offline/`` — evaluation, rollouts and plots of the simulator and of flight logs;
* ``bench/`` — the ``remarl-fc bench`` measurements;
* ``cli/`` — the ``remarl-fc`` command line: argument parsing, one module per command group.

Beside them: ``demo`` (the mock fleet and the runtime wired together), ``policy_io`` (policy
files and numpy inference), ``frames`` (every unit and frame conversion), ``errors`` (the one
error tree) and ``resource`` (the base of the async context managers). docs/ARCHITECTURE.md
draws the data flow and says where to add an autopilot, a method or a scenario.
"""

from remarl_fc._version import __version__

__all__ = ["__version__"]
