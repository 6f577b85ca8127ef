"""``rwt_graph.tasks.start_soon``: a task group's task, started from any code on the loop."""

from __future__ import annotations

import asyncio
import contextvars

import anyio
import anyio.lowlevel
import pytest

from rwt_graph.tasks import start_soon

pytestmark = pytest.mark.anyio


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


async def test_a_task_starts_from_a_callback_another_thread_scheduled() -> None:
    # such a callback runs in no task and in a context that names no async library
    ran: list[str] = []

    async def task(name: str) -> None:
        await anyio.lowlevel.checkpoint()
        ran.append(name)

    async with anyio.create_task_group() as tg:
        loop = asyncio.get_running_loop()
        await anyio.to_thread.run_sync(
            lambda: loop.call_soon_threadsafe(
                start_soon, tg, task, "from a callback", context=contextvars.Context()
            )
        )
        start_soon(tg, task, "from a task")
    assert sorted(ran) == ["from a callback", "from a task"]


async def test_a_task_started_from_a_callback_belongs_to_the_group() -> None:
    # cancelling the group cancels it: it is the group's task, not a loose one
    started = anyio.Event()
    cancelled: list[bool] = []

    async def task() -> None:
        started.set()
        try:
            await anyio.sleep_forever()
        except anyio.get_cancelled_exc_class():
            cancelled.append(True)
            raise

    async with anyio.create_task_group() as tg:
        asyncio.get_running_loop().call_soon(start_soon, tg, task, context=contextvars.Context())
        with anyio.fail_after(5):
            await started.wait()
        tg.cancel_scope.cancel()
    assert cancelled == [True]
