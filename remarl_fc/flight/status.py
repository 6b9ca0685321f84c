"""A vehicle's status in a flight, and the only transitions allowed between statuses.

    waiting ──► taking-off ──► ready ──► controlled ──► reached   (hold, released)
       └──────────────────────►┘            ├─────────► pilot     (released, never fought)
                                            ├─────────► held      (hold)
                                            └─────────► lost ───► held (telemetry back: hold)

Any status still flown by this process (waiting, taking-off, ready, controlled) may go to
``held`` (the end of the flight, an error, Ctrl-C). ``reached``, ``pilot`` and ``held`` are
final; ``lost`` only ever leads to ``held``: nothing goes back to ``controlled``.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping


class Status(enum.StrEnum):
    """Where a vehicle is in the flight."""

    WAITING = "waiting"
    TAKING_OFF = "taking-off"
    READY = "ready"
    CONTROLLED = "controlled"
    LOST = "lost"  # telemetry stale: not commanded, an obstacle at its last track
    HELD = "held"  # told to hold after a loss, a breach or the end
    REACHED = "reached"  # at its target: held and released
    PILOT = "pilot"  # the pilot took it: released, never fought


TRANSITIONS: Mapping[Status, frozenset[Status]] = {
    Status.WAITING: frozenset({Status.TAKING_OFF, Status.READY, Status.HELD}),
    Status.TAKING_OFF: frozenset({Status.READY, Status.HELD}),
    Status.READY: frozenset({Status.CONTROLLED, Status.HELD}),
    Status.CONTROLLED: frozenset({Status.LOST, Status.HELD, Status.REACHED, Status.PILOT}),
    Status.LOST: frozenset({Status.HELD}),
    Status.HELD: frozenset(),
    Status.REACHED: frozenset(),
    Status.PILOT: frozenset(),
}
"""Every allowed status change; anything else is a bug (`IllegalTransition`)."""

FLOWN = frozenset({Status.WAITING, Status.TAKING_OFF, Status.READY, Status.CONTROLLED})
"""Statuses in which this process still owns the vehicle: on any exit it is told to hold."""

HOLD_ON_ENTRY = frozenset({Status.HELD, Status.REACHED})
"""Entering these sends the hold mode (``pilot`` never does: the pilot is never fought)."""

BEFORE_CONTROL = frozenset({Status.WAITING, Status.TAKING_OFF, Status.READY})
"""Being prepared: not yet flown by the policy."""

OBSTACLE = frozenset({Status.LOST, Status.PILOT, Status.HELD})
"""Vehicles in these statuses are no longer flown by the policy: obstacles for the others."""

NEIGHBOUR = frozenset({Status.CONTROLLED, Status.REACHED})
"""Vehicles in these statuses are the swarm's own to a version-2 policy (its neighbour rows):
flown by it, or holding at their targets (the simulator's hover on arrival)."""


class IllegalTransition(RuntimeError):
    """A status change that `TRANSITIONS` does not allow (a bug in the runtime, not bad input)."""


def check_transition(old: Status, new: Status) -> None:
    """Raise `IllegalTransition` unless ``old → new`` is allowed.

    >>> check_transition(Status.CONTROLLED, Status.REACHED)
    >>> check_transition(Status.PILOT, Status.CONTROLLED)
    Traceback (most recent call last):
    ...
    remarl_fc.flight.status.IllegalTransition: pilot → controlled is not allowed (pilot is final)
    """
    allowed = TRANSITIONS[old]
    if new not in allowed:
        why = (
            f"{old.value} is final"
            if not allowed
            else "allowed: " + ", ".join(sorted(s.value for s in allowed))
        )
        raise IllegalTransition(f"{old.value} → {new.value} is not allowed ({why})")
