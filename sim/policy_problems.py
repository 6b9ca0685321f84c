"""What is wrong with a policy file: `Problem`, the `Checker` that collects them, the base error.

Every failure of a check of `sim.policy_file` is a `PolicyFileError` (a `ValueError`) whose
`Problem` items each name the key or tensor and say what is expected; `remarl_fc.policy_io` turns
them into `PolicyError` subclasses. Each subclass lives with the check that raises it:
`PolicyFormatError` and `PolicySchemaError` in `sim.policy_metadata`, `PolicyUnsignedError` and
`PolicyChecksumError` in `sim.policy_checksum`, `PolicyTensorError` and `PolicyWeightsError` in
`sim.policy_file`. A `Checker` reads typed values out of the metadata key by key and notes a
`Problem` for each bad one. The text of a problem comes from the file: it is kept to one
printable line.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from sim.errors import RemarlError

_MAX_LISTED = 4


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a policy file.

    Attributes:
        key: the dotted metadata key (``observation.size``), the tensor name
            (``actor.l1.weight``), or ``file`` / ``checksum``.
        message: what is expected, and what was found.
    """

    key: str
    message: str

    def __post_init__(self) -> None:  # names come from the file: keep messages one clean line
        object.__setattr__(self, "key", _printable(self.key, 80))
        object.__setattr__(self, "message", _printable(self.message, 400))

    def __str__(self) -> str:
        return f"{self.key}: {self.message}"


class PolicyFileError(RemarlError, ValueError):
    """A policy file breaks the format; ``problems`` name each key or tensor at fault.

    Attributes:
        problems: what is wrong, one `Problem` per key or tensor.
        key: the key of the first problem.
    """

    kind: ClassVar[str] = "invalid"
    summary: ClassVar[str] = "invalid policy file"
    advice: ClassVar[str] = "re-export it with remarl-fc export"

    def __init__(self, problems: Iterable[Problem]) -> None:
        self.problems = tuple(problems)
        self.key = self.problems[0].key if self.problems else ""
        super().__init__(self.describe())

    def details(self) -> str:
        """The problems, on one line (the first few, then how many more)."""
        shown = "; ".join(str(p) for p in self.problems[:_MAX_LISTED])
        more = len(self.problems) - _MAX_LISTED
        return shown + (f"; and {more} more" if more > 0 else "")

    def describe(self, path: str = "FILE") -> str:
        """One line: what is wrong and what to do (``path`` fills the advice's file name)."""
        return f"{self.summary} ({self.details()}): {self.advice.replace('FILE', path)}"


def _printable(text: str, limit: int) -> str:
    """``text`` with control characters escaped, cut to ``limit`` characters."""
    if not text.isprintable():
        text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def show(value: object) -> str:
    """``value`` as a problem message quotes it: its repr, cut to 40 characters."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class Checker:
    """Collects `Problem` items while reading typed values out of nested dicts."""

    def __init__(self) -> None:
        self.problems: list[Problem] = []

    def add(self, key: str, message: str) -> None:
        """Note a problem of ``key`` (only its first: that says enough)."""
        if all(p.key != key for p in self.problems):
            self.problems.append(Problem(key, message))

    def get(self, d: Mapping[str, Any], key: str, prefix: str, expected: str) -> Any:
        """``d[key]``, or None with a problem of ``prefix + key`` if it is missing."""
        if key not in d:
            self.add(prefix + key, f"required key is missing (expected {expected})")
            return None
        return d[key]

    def obj(self, d: Mapping[str, Any], key: str, prefix: str = "") -> dict[str, Any] | None:
        """``d[key]`` if it is an object, else None (a problem noted)."""
        value = self.get(d, key, prefix, "an object")
        if key in d and not isinstance(value, dict):
            self.add(prefix + key, f"must be an object, got {show(value)}")
        return value if isinstance(value, dict) else None

    def integer(
        self, d: Mapping[str, Any], key: str, prefix: str = "", *, minimum: int | None = 1
    ) -> int | None:
        """``d[key]`` if it is an integer (not a bool) >= ``minimum``, else None (noted)."""
        expected = "an integer" if minimum is None else f"an integer >= {minimum}"
        value = self.get(d, key, prefix, expected)
        if key not in d:
            return None
        too_small = minimum is not None and isinstance(value, int) and value < minimum
        if isinstance(value, bool) or not isinstance(value, int) or too_small:
            self.add(prefix + key, f"must be {expected}, got {show(value)}")
            return None
        return value

    def number(
        self,
        d: Mapping[str, Any],
        key: str,
        prefix: str = "",
        *,
        high: float = math.inf,
    ) -> float | None:
        """``d[key]`` as a float if it is a finite number in (0, ``high``], else None (noted)."""
        expected = "a finite number > 0" if high == math.inf else f"a number in (0, {high:.6g}]"
        value = self.get(d, key, prefix, expected)
        if key not in d:
            return None
        ok = not isinstance(value, bool) and isinstance(value, int | float)
        ok = ok and math.isfinite(value) and 0 < value <= high
        if not ok:
            self.add(prefix + key, f"must be {expected}, got {show(value)}")
            return None
        return float(value)

    def string(self, d: Mapping[str, Any], key: str, prefix: str = "") -> str | None:
        """``d[key]`` if it is a non-empty string, else None (noted)."""
        value = self.get(d, key, prefix, "a string")
        if key not in d:
            return None
        if not isinstance(value, str) or not value:
            self.add(prefix + key, f"must be a non-empty string, got {show(value)}")
            return None
        return value

    def boolean(self, d: Mapping[str, Any], key: str, prefix: str = "") -> bool | None:
        """``d[key]`` if it is true or false, else None (noted)."""
        value = self.get(d, key, prefix, "true or false")
        if key not in d:
            return None
        if not isinstance(value, bool):
            self.add(prefix + key, f"must be true or false, got {show(value)}")
            return None
        return value

    def choice(
        self, d: Mapping[str, Any], key: str, choices: Iterable[str], prefix: str = ""
    ) -> str | None:
        """``d[key]`` if it is one of the strings ``choices``, else None (noted)."""
        allowed = tuple(choices)
        expected = f"one of {', '.join(allowed)}"
        value = self.get(d, key, prefix, expected)
        if key not in d:
            return None
        if not isinstance(value, str) or value not in allowed:
            self.add(prefix + key, f"must be {expected}, got {show(value)}")
            return None
        return value

    def known(self, d: Mapping[str, Any], keys: Iterable[str], prefix: str = "") -> None:
        """Note every key of ``d`` not in ``keys``."""
        allowed = set(keys)
        for key in d:
            if key not in allowed:
                self.add(prefix + key, f"unknown key (known: {', '.join(sorted(allowed))})")

    def equal(self, key: str, value: object, expected: object, what: str) -> None:
        """Note ``value`` unless it equals ``expected`` (``what``); None on either side passes."""
        if value is not None and expected is not None and value != expected:
            self.add(key, f"must equal {what} ({show(expected)}), got {show(value)}")
