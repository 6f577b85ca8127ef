"""Starting a task in an anyio task group from any code running on the event loop.

anyio starts a task (and makes its cancel scope) only where it can tell which
async library runs: inside a task, or where sniffio's context variable says
so. A callback that another thread scheduled on the loop (the ROS 2 link's
hand-over, the Zenoh link's) is neither, and everything it calls into (a
graph service's handler, a subscriber that publishes) may want a task. There
the task is started from a short asyncio task of its own, one loop turn later.
"""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable, Coroutine

    from anyio.abc import TaskGroup

__all__ = ["start_soon"]

_starters: set[asyncio.Task[None]] = set()  # held until they ran: the loop keeps weak refs


def start_soon(
    tg: TaskGroup, function: Callable[..., Coroutine[Any, Any, Any]], *args: Any
) -> None:
    """``tg.start_soon(function, *args)``, also from a plain event-loop callback.

    Raises:
        RuntimeError: ``tg`` is closed (as ``start_soon`` does); from a plain
            callback the error goes to the loop's exception handler instead.
    """
    if _in_task():
        tg.start_soon(function, *args)
        return

    async def start() -> None:
        tg.start_soon(function, *args)

    starter = asyncio.get_running_loop().create_task(start())
    _starters.add(starter)
    starter.add_done_callback(_starters.discard)


def _in_task() -> bool:
    """Whether a task runs, not a plain callback (no asyncio loop: trio's, always a task)."""
    try:
        return asyncio.current_task() is not None
    except RuntimeError:
        return True
