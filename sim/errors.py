"""Errors raised by the simulator core.

These are the roots of the project's error tree; `remarl_fc.errors` documents the whole tree
and re-exports them, so a user catches ``remarl_fc.errors.RemarlError`` for anything the
project raises on purpose.

::

    RemarlError
     ├── ConfigError (also a ValueError)
     │    └── ScenarioError          a scenario name or file that cannot be used
     └── WorkerFailed               a process of a run stopped or failed
"""

from __future__ import annotations

from typing import Any


class RemarlError(Exception):
    """Base class of every error remarl-fc raises on purpose.

    Every error of the tree crosses a process boundary whole (a pool's worker raising it to
    the parent: `remarl-fc eval --workers`, the training's rollout processes): pickle rebuilds
    it from its message and attributes, not by calling its ``__init__``, whose keyword-only
    arguments it would not know (it would raise a TypeError in the parent, and the user would
    see a broken pool instead of what to do).
    """

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild_error, (type(self), self.args, dict(self.__dict__)))


def _rebuild_error(
    cls: type[RemarlError], args: tuple[Any, ...], state: dict[str, Any]
) -> RemarlError:
    """``cls`` with ``args`` and the attributes ``state``, its ``__init__`` not called."""
    error = cls.__new__(cls, *args)
    error.args = args
    error.__dict__.update(state)
    return error


class ConfigError(RemarlError, ValueError):
    """A configuration value is missing, of the wrong type or out of range."""


class ScenarioError(ConfigError):
    """A scenario cannot be resolved or loaded.

    Attributes:
        source: the scenario name or file path involved.
        key: the offending key (dotted path), if the problem is one value.
    """

    def __init__(self, message: str, *, source: str, key: str | None = None) -> None:
        where = f"{source}: {key}: " if key else f"{source}: "
        super().__init__(where + message)
        self.source = source
        self.key = key


class WorkerFailed(RemarlError):
    """A process that a run started to share its work stopped or failed.

    A training run's rollout process (`policies.generalist_rollouts`); the message holds its
    exit code or its traceback, and what to do.
    """
