"""Benchmark suites: families of encounters in a TOML file, and the oracle's cached labels.

A suite file (``sim/suites/*.toml``, or any path) names its families; each family is a named
distribution of `sim.encounters` with changes, or a scenario file's own episodes::

    name = "standard"
    version = 1                    # bump when a family changes: old labels no longer apply
    episodes = 200                 # per family

    [[family]]
    name = "paper-3u2o"
    distribution = "scenario"
    scenario = "3u2o"

    [[family]]
    name = "head-on-3u"
    distribution = "head-on"
    uavs = 3
    formation = "wedge"
    speed_m_s = [5.0, 15.0]        # any field of `sim.encounters.Encounter`

A suite may instead take its families from another (``base = "standard"``), keeping a few
(``families = [...]``) and fewer episodes: its episodes are the first ones of the base's, so the
base's labels serve it.

Labels: which episodes the oracle (`sim.oracle`) proved solvable, per family, cached next to
the suite file (``NAME.labels.json``) with a digest of everything that decides the family's
episodes, so a label never outlives the episode it was computed for.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sim.arrays import BoolArray
from sim.datafiles import read_toml, shipped_names
from sim.encounters import DISTRIBUTIONS, GENERATOR_VERSION, Encounter, Family
from sim.errors import ConfigError
from sim.evaluation import evaluation_seed

PAPER_FAMILY_PREFIX = "paper-"
"""A family named so flies a paper scenario's own episodes (``scenario`` names it)."""

FAMILY_KEYS = {"name", "distribution", "uavs", "formation", "scenario", "overrides", "description"}
"""Keys of a ``[[family]]`` table besides the fields of `Encounter`."""


@dataclass(frozen=True)
class Suite:
    """A benchmark suite.

    Attributes:
        name, version, description: as in the file.
        episodes: per family.
        seed: the first seed of every family's episodes (`sim.encounters.episode_rng`).
        families: in file order.
        labels_path: where its labels are cached (the base suite's for a derived suite).
    """

    name: str
    version: int
    description: str
    episodes: int
    seed: int
    families: tuple[Family, ...]
    labels_path: Path | None

    def paper_scenarios(self) -> list[str]:
        """The scenarios of its ``paper-*`` families (the paper's own episodes), in order."""
        return [f.scenario for f in self.families if f.name.startswith(PAPER_FAMILY_PREFIX)]

    def family(self, name: str) -> Family:
        """The family called ``name``; a ConfigError naming the known ones otherwise."""
        for f in self.families:
            if f.name == name:
                return f
        known = ", ".join(f.name for f in self.families)
        raise ConfigError(f"suite {self.name} has no family {name!r}; its families: {known}")


def suite_names() -> list[str]:
    """The suites shipped with the package."""
    return shipped_names("suites")


def load_suite(name_or_path: str | Path) -> Suite:
    """A shipped suite by name ("standard", "smoke") or a suite file by path.

    Raises:
        ConfigError: unknown name, unreadable or invalid file (the message says which key).
    """
    data, path = read_toml("suites", name_or_path, "suite")
    return _suite(data, path)


def _suite(data: dict[str, Any], path: Path) -> Suite:
    known = {"name", "version", "description", "episodes", "seed", "family", "base", "families"}
    unknown = set(data) - known
    if unknown:
        raise ConfigError(f"{path}: unknown key {sorted(unknown)[0]!r}; allowed: {sorted(known)}")
    if "base" in data:
        base = load_suite(_resolve_base(str(data["base"]), path))
        keep = data.get("families")
        families = base.families if keep is None else tuple(base.family(k) for k in keep)
        episodes = int(data.get("episodes", base.episodes))
        if episodes > base.episodes:
            raise ConfigError(f"{path}: episodes must be <= the base's {base.episodes}")
        return Suite(
            name=str(data.get("name", path.stem)),
            version=base.version,
            description=str(data.get("description", base.description)),
            episodes=episodes,
            seed=base.seed,
            families=families,
            labels_path=base.labels_path,
        )
    tables = data.get("family", [])
    if not tables:
        raise ConfigError(f"{path}: a suite needs [[family]] tables (or base = ...)")
    families = tuple(_family(t, path) for t in tables)
    names = [f.name for f in families]
    if len(set(names)) != len(names):
        raise ConfigError(f"{path}: family names must be unique")
    return Suite(
        name=str(data.get("name", path.stem)),
        version=int(data.get("version", 1)),
        description=str(data.get("description", "")),
        episodes=int(data.get("episodes", 200)),
        seed=int(data.get("seed", evaluation_seed(suite="encounters"))),
        families=families,
        labels_path=path.with_name(f"{path.stem}.labels.json"),
    )


def _resolve_base(base: str, path: Path) -> str:
    sibling = path.with_name(f"{base}.toml")
    return str(sibling) if sibling.is_file() else base


def _family(table: dict[str, Any], path: Path) -> Family:
    name = str(table.get("name", ""))
    if not name:
        raise ConfigError(f"{path}: every [[family]] needs a name")
    distribution = str(table.get("distribution", ""))
    enc_fields = {f.name for f in dataclasses.fields(Encounter)}
    unknown = set(table) - FAMILY_KEYS - enc_fields
    if unknown:
        raise ConfigError(
            f"{path}: family {name}: unknown key {sorted(unknown)[0]!r}; "
            f"allowed: {', '.join(sorted(FAMILY_KEYS | enc_fields))}"
        )
    changes: dict[str, Any] = {
        k: tuple(v) if isinstance(v, list) else v for k, v in table.items() if k in enc_fields
    }
    encounter = None
    if distribution in DISTRIBUTIONS:
        try:
            encounter = dataclasses.replace(DISTRIBUTIONS[distribution], **changes)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{path}: family {name}: {exc}") from exc
    elif changes:
        raise ConfigError(f"{path}: family {name}: {sorted(changes)[0]} needs a distribution")
    kwargs = {k: table[k] for k in ("uavs", "formation", "scenario", "description") if k in table}
    return Family(
        name=name,
        distribution=distribution,
        encounter=encounter,
        overrides=dict(table.get("overrides", {})),
        **kwargs,
    )


def family_digest(suite: Suite, family: Family) -> str:
    """What decides a family's labels, hashed: parameters, seed, generator and oracle."""
    from sim.oracle import ORACLE_VERSION

    blob = json.dumps(
        {
            "family": family.parameters(),
            "seed": suite.seed,
            "generator": GENERATOR_VERSION,
            "oracle": ORACLE_VERSION,
        },
        sort_keys=True,
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def cached_labels(suite: Suite, family: Family, episodes: int) -> BoolArray | None:
    """The cached labels of the family's first ``episodes`` episodes, None if not cached."""
    entry = _read_labels(suite).get(family.name)
    if entry is None or entry.get("digest") != family_digest(suite, family):
        return None
    bits = str(entry.get("solvable", ""))
    if len(bits) < episodes:
        return None
    return np.array([c == "1" for c in bits[:episodes]], dtype=bool)


def store_labels(suite: Suite, family: Family, solvable: BoolArray) -> None:
    """Cache a family's labels (episodes 0..len−1), atomically; others' labels are kept."""
    if suite.labels_path is None:
        return
    entries = _read_labels(suite)
    entries[family.name] = {
        "digest": family_digest(suite, family),
        "solvable": "".join("1" if s else "0" for s in solvable),
    }
    payload = {"suite": suite.name, "version": suite.version, "families": entries}
    path = suite.labels_path
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".part")
    with os.fdopen(fd, "w", encoding="utf-8") as out:
        json.dump(payload, out, indent=1, sort_keys=True)
        out.write("\n")
    os.replace(tmp, path)


def _read_labels(suite: Suite) -> dict[str, Any]:
    path = suite.labels_path
    if path is None or not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return {}  # a damaged cache is recomputed, never trusted
    families = data.get("families", {})
    return families if isinstance(families, dict) else {}


def family_labels(suite: Suite, family: Family, episodes: int, *, store: bool = True) -> BoolArray:
    """Which of the family's first ``episodes`` episodes the oracle proved solvable.

    From the cache when it holds them for this exact family; else planned now
    (`sim.oracle.plan_episodes`, minutes for the largest families) and, with ``store``,
    cached for next time.
    """
    cached = cached_labels(suite, family, episodes)
    if cached is not None:
        return cached
    from sim.encounters import sample_family
    from sim.oracle import plan_episodes

    cfg, batch = sample_family(family, suite.seed, range(episodes))
    solvable = plan_episodes(cfg, batch).solvable
    if store:
        store_labels(suite, family, solvable)
    return solvable
