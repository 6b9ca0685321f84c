"""remarl-fc: cooperative collision avoidance for UAV swarms, from training to flight."""

from remarl_fc._version import __version__

__all__ = ["__version__"]
