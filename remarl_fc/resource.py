"""`Resource`: the base of the project's async context managers.

``async with`` opens the resource (its own ``__aenter__``) and, on any exit, awaits
`Resource.aclose` with the exception type that ended the block (None on a normal exit), so
each resource says once what closing means and leaves its vehicles or sockets safe.
"""

from __future__ import annotations

import abc
from types import TracebackType


class Resource(abc.ABC):
    """An async context manager whose exit is `aclose`."""

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.aclose(exc_type)

    @abc.abstractmethod
    async def aclose(self, exc_type: type[BaseException] | None = None) -> None:
        """Close (idempotent); ``exc_type`` is what ended the ``async with`` block, if any."""
