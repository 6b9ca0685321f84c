"""The error tree of remarl-fc.

Everything the project raises on purpose derives from `RemarlError`; third-party errors are
converted where they enter (``raise X from exc``), so callers need to know only this tree::

    RemarlError
     └── ConfigError (also a ValueError)     bad configuration value or file
          └── ScenarioError                  scenario name/file that cannot be used

Messages say what to do next. Later layers (policy files, MAVLink link, swarm bus) add their
branches here.
"""

from __future__ import annotations

from sim.errors import ConfigError, RemarlError, ScenarioError

__all__ = ["ConfigError", "RemarlError", "ScenarioError"]
