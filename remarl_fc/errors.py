"""The error tree of remarl-fc.

Everything the project raises on purpose derives from `RemarlError`; third-party errors are
converted where they enter (``raise X from exc``), so callers need to know only this tree::

    RemarlError
     ├── ConfigError (also a ValueError)     bad configuration value or file
     │    └── ScenarioError                  scenario name/file that cannot be used
     └── PolicyError                         a policy file that cannot be used
          └── PolicySpecMismatch             ... for this scenario or vehicle set

Messages say what to do next. Later layers (policy files, MAVLink link, swarm bus) add their
branches here.
"""

from __future__ import annotations

from sim.errors import ConfigError, RemarlError, ScenarioError

__all__ = ["ConfigError", "PolicyError", "PolicySpecMismatch", "RemarlError", "ScenarioError"]


class PolicyError(RemarlError):
    """A policy file is missing, corrupt or not a remarl-fc policy.

    Attributes:
        source: the file or zoo name.
    """

    def __init__(self, message: str, *, source: str) -> None:
        super().__init__(f"{source}: {message}")
        self.source = source


class PolicySpecMismatch(PolicyError):
    """A policy does not fit the scenario or the vehicles it is asked to fly.

    Attributes:
        field: the mismatching value's name; expected / actual: the two values.
    """

    def __init__(self, source: str, field: str, expected: object, actual: object) -> None:
        super().__init__(
            f"{field} is {actual!r} here but the policy was trained with {expected!r}; "
            "use a policy trained for this scenario (remarl-fc train) or fix the scenario",
            source=source,
        )
        self.field, self.expected, self.actual = field, expected, actual
