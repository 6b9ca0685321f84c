"""TOML data shipped with the package (suites, vehicle profiles), found by name or by path."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from sim.errors import ConfigError


def shipped_names(folder: str) -> list[str]:
    """Names of the ``sim/FOLDER/*.toml`` files, sorted, without the suffix."""
    files = resources.files("sim").joinpath(folder).iterdir()
    return sorted(p.name.removesuffix(".toml") for p in files if p.name.endswith(".toml"))


def read_toml(folder: str, name_or_path: str | Path, what: str) -> tuple[dict[str, Any], Path]:
    """The parsed file and its path: a shipped name in ``sim/FOLDER`` or a ``.toml`` path.

    Raises:
        ConfigError: an unknown name (listing the shipped ones), an unreadable file or bad TOML.
    """
    text = str(name_or_path)
    if text.endswith(".toml") or "/" in text:
        path = Path(text)
    elif text in (known := shipped_names(folder)):
        path = Path(str(resources.files("sim").joinpath(folder, f"{text}.toml")))
    else:
        raise ConfigError(
            f"unknown {what} {text!r}; shipped: {', '.join(known)} "
            "(or pass the path of a .toml file)"
        )
    try:
        return tomllib.loads(path.read_text(encoding="utf-8")), path
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from exc
