"""A job that runs in the background of an ``async with`` block."""

from __future__ import annotations

from typing import TYPE_CHECKING, Self

import anyio

if TYPE_CHECKING:
    from types import TracebackType

    from anyio.abc import TaskGroup, TaskStatus

__all__ = ["BackgroundJob"]


class BackgroundJob:
    """``async with job:`` starts ``job.run`` in a task group and cancels it on exit.

    Subclasses define ``run``, which calls ``task_status.started()`` once it is
    under way (the block is entered then) and cleans up when cancelled.
    """

    _tg: TaskGroup | None = None

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """The job; runs until done or cancelled."""
        raise NotImplementedError

    async def __aenter__(self) -> Self:
        self._tg = anyio.create_task_group()
        await self._tg.__aenter__()
        await self._tg.start(self.run)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        assert self._tg is not None
        self._tg.cancel_scope.cancel()
        return await self._tg.__aexit__(exc_type, exc, tb)
