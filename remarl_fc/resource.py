"""`Resource`: the base of the project's async context managers.

``async with`` opens the resource (its own ``__aenter__``) and, on any exit, awaits
`Resource.aclose` with the exception type that ended the block (None on a normal exit), so
each resource says once what closing means and leaves its vehicles or sockets safe.
`SyncResource` is one that closes without awaiting (`SyncResource.close`); a `StackOwner` opens
what it owns on one exit stack, all or nothing.
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
from types import TracebackType
from typing import Self

ExcInfo = tuple[type[BaseException] | None, BaseException | None, TracebackType | None]
"""What ended an ``async with`` block: (type, exception, traceback), all None on a normal exit."""


class Resource(abc.ABC):
    """An async context manager whose exit is `aclose`."""

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._exit((exc_type, exc, tb))

    async def _exit(self, exc_info: ExcInfo) -> None:
        """Leave the ``async with`` block: `aclose` (a subclass may need the whole exception)."""
        await self.aclose(exc_info[0])

    @abc.abstractmethod
    async def aclose(self, exc_type: type[BaseException] | None = None) -> None:
        """Close (idempotent); ``exc_type`` is what ended the ``async with`` block, if any."""


class SyncResource(Resource):
    """A resource whose closing needs no await: `aclose` is `close`, which plain code may call."""

    async def aclose(self, exc_type: type[BaseException] | None = None) -> None:
        """Close (`close`), however the block ended."""
        self.close()

    @abc.abstractmethod
    def close(self) -> None:
        """Close (idempotent)."""


class StackOwner(Resource):
    """An async context manager that opens what it owns on one exit stack, all or nothing.

    ``async with`` calls `_enter` with a new exit stack. If `_enter` raises, what it entered so
    far is closed (as on a normal exit, so that a task group on the stack does not wrap the
    error in a group) and the error propagates. On exit `_leave` runs first (e.g. hold every
    vehicle while the links are still open), then the stack closes: a cancellation is passed
    through to it, so that a task group on the stack sees its own cancel; any other ending
    closes it as a normal exit, so that the caller's own error propagates as it is, not wrapped
    in a group. Not reentrant: one ``async with`` at a time.
    """

    _stack: contextlib.AsyncExitStack | None = None

    async def __aenter__(self) -> Self:
        if self._stack is not None:
            raise RuntimeError(f"this {type(self).__name__} is already open; use one `async with`")
        stack = contextlib.AsyncExitStack()
        await stack.__aenter__()
        try:
            await self._enter(stack)
        except BaseException:
            await stack.aclose()
            raise
        self._stack = stack
        return self

    async def aclose(self, exc_type: type[BaseException] | None = None) -> None:
        """`_leave`, then close the stack (as on an ``async with`` ended by ``exc_type``)."""
        await self._exit((exc_type, None, None))

    async def _exit(self, exc_info: ExcInfo) -> None:
        try:
            await self._leave(exc_info[0])
        finally:
            stack, self._stack = self._stack, None
            if stack is not None:
                exc_type = exc_info[0]
                if exc_type is not None and issubclass(exc_type, asyncio.CancelledError):
                    await stack.__aexit__(*exc_info)
                else:
                    await stack.aclose()

    @abc.abstractmethod
    async def _enter(self, stack: contextlib.AsyncExitStack) -> None:
        """Open everything this owns, on ``stack``."""

    @abc.abstractmethod
    async def _leave(self, exc_type: type[BaseException] | None) -> None:
        """What to do before the stack closes; ``exc_type`` ended the block, if anything."""
