"""The checksum of a policy file: what it hashes, how, and the check of it.

A policy file's metadata carries ``checksum`` (`CHECKSUM_KEY`): ``"sha256:"`` and the hex digest
of `policy_checksum`, over every tensor and the metadata without the checksum, so any change to
a weight or a metadata value shows. `check_checksum` compares the two: `PolicyUnsignedError`
without a checksum, `PolicyChecksumError` on a mismatch.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.policy_problems import PolicyFileError, Problem

CHECKSUM_KEY = "checksum"
"""Metadata key of the checksum, ``"sha256:<64 hex digits>"``; excluded from what it hashes."""

CHECKSUM_PREFIX = "sha256:"
"""The algorithm tag of `CHECKSUM_KEY` values."""

CHECKSUM_DOMAIN = b"remarl-fc policy checksum v1\n"
"""First bytes hashed, so that the digest of a policy file can be no other format's digest."""


class PolicyUnsignedError(PolicyFileError):
    """The file has no checksum: it was written before policy files carried one."""

    kind = "unsigned"
    summary = "no checksum"
    advice = (
        "if you trust the file, add one with `python -m policies.export --rehash FILE` "
        "(or re-export it with remarl-fc export)"
    )

    def describe(self, path: str = "FILE") -> str:
        """One line: what is wrong and what to do."""
        return (
            "no checksum: written by a remarl-fc older than policy checksums; "
            + self.advice.replace("FILE", path)
        )


class PolicyChecksumError(PolicyFileError):
    """The checksum does not match the contents: the file changed after it was written.

    Attributes:
        expected: the checksum the file carries. actual: the checksum of its contents.
    """

    kind = "checksum"
    summary = "corrupt"
    advice = "re-export it or restore the file"

    def __init__(self, expected: str, actual: str) -> None:
        self.expected, self.actual = expected, actual
        super().__init__([Problem(CHECKSUM_KEY, f"file says {expected}, contents give {actual}")])

    def describe(self, path: str = "FILE") -> str:
        """One line: what is wrong and what to do."""
        return (
            f"corrupt: checksum mismatch (the file says {_short(self.expected)}, its contents "
            f"hash to {_short(self.actual)}); {self.advice}"
        )


def _short(checksum: str) -> str:
    return checksum[: len(CHECKSUM_PREFIX) + 16] + "…" if len(checksum) > 40 else repr(checksum)


def canonical_json(value: object) -> bytes:
    """Canonical JSON bytes: sorted keys, no whitespace, ASCII, no NaN (raises ValueError)."""
    return json.dumps(
        value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False
    ).encode("ascii")


def policy_checksum(tensors: Mapping[str, NDArray[Any]], meta: Mapping[str, Any]) -> str:
    """``"sha256:<hex>"`` of a policy's tensors and metadata (the metadata's checksum excluded).

    SHA-256 over `CHECKSUM_DOMAIN`, then for each tensor in sorted name order a record
    ``len(h) h len(d) d`` (lengths as 8-byte little-endian) where ``h`` is the canonical JSON
    ``{"dtype": "<f4", "name": ..., "shape": [...]}`` (numpy dtype string, little-endian) and ``d``
    the raw little-endian bytes in C order; then the record ``len(m) m`` of the canonical JSON
    `canonical_json` of the metadata without `CHECKSUM_KEY`.
    """
    h = hashlib.sha256(CHECKSUM_DOMAIN)

    def record(data: bytes | memoryview) -> None:
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)

    for name in sorted(tensors):
        arr = np.asarray(tensors[name])
        arr = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<"))
        record(canonical_json({"dtype": arr.dtype.str, "name": name, "shape": list(arr.shape)}))
        record(arr.reshape(-1).view(np.uint8).data)
    record(canonical_json({k: v for k, v in meta.items() if k != CHECKSUM_KEY}))
    return CHECKSUM_PREFIX + h.hexdigest()


def check_checksum(tensors: Mapping[str, NDArray[Any]], meta: Mapping[str, Any]) -> None:
    """Raise `PolicyUnsignedError` without a checksum, `PolicyChecksumError` on a mismatch."""
    if CHECKSUM_KEY not in meta:
        raise PolicyUnsignedError([Problem(CHECKSUM_KEY, "missing")])
    actual = policy_checksum(tensors, meta)
    if meta[CHECKSUM_KEY] != actual:
        raise PolicyChecksumError(str(meta[CHECKSUM_KEY]), actual)
