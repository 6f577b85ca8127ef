"""Fixtures of the fuzz suite: an in-process server per test module, driven from a portal.

Hypothesis drives plain functions, so the server (``tests/support/clients.py``'s
``running_server``) runs in a blocking portal's event loop and every example is a
``portal.call``. A server that died (a violation) is reported, then started anew
so the next example, and hypothesis's shrinking, run against a live one. The
``fuzz`` profile is derandomized (the same examples on every run, CI included)
and prints the failing example and its reproduction blob.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from concurrent.futures import Future
from dataclasses import dataclass, field

import anyio
import pytest
from anyio.abc import TaskStatus
from anyio.from_thread import BlockingPortal, start_blocking_portal
from hypothesis import HealthCheck, Phase, settings

from tests.support.clients import Client, Harness, running_server

settings.register_profile(
    "fuzz",
    max_examples=int(os.environ.get("RWT_FUZZ_EXAMPLES", "120")),
    deadline=None,
    derandomize=True,
    print_blob=True,
    report_multiple_bugs=False,
    # Shrinking restarts a dead server per attempt: minutes on main, so opt in.
    phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.target]
    + ([Phase.shrink] if os.environ.get("RWT_FUZZ_SHRINK") else []),
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.filter_too_much,
    ],
)
FUZZ = settings.get_profile("fuzz")


@dataclass
class Live:
    """A running server, the portal to its loop, and the bystanders connected throughout."""

    portal: BlockingPortal
    harness: Harness | None = None
    bystanders: list[Client] = field(default_factory=list)
    future: Future[None] | None = None
    stop: anyio.Event | None = None

    def start(self) -> None:
        """Start the server and connect its bystanders (in one task: their cancel scopes)."""
        from tests.fuzz.test_transports import connect_bystanders  # noqa: PLC0415

        async def host(
            *, task_status: TaskStatus[tuple[Harness, list[Client], anyio.Event]]
        ) -> None:
            stop = anyio.Event()
            async with running_server() as harness:
                bystanders = await connect_bystanders(harness)
                task_status.started((harness, bystanders, stop))
                await stop.wait()

        self.future, (self.harness, self.bystanders, self.stop) = self.portal.start_task(host)

    def died(self) -> BaseException | None:
        """What ended the server, if it ended."""
        if self.future is None or not self.future.done():
            return None
        return self.future.exception() or RuntimeError("the server stopped")

    def ensure(self) -> None:
        """A live server for the next example: a new one if the last one died."""
        if self.future is None or self.future.done():
            self.start()

    def close(self) -> None:
        if self.future is not None and not self.future.done() and self.stop is not None:
            self.portal.call(self.stop.set)
            with contextlib.suppress(Exception):
                self.future.result(timeout=30)


@pytest.fixture(scope="module")
def live() -> Iterator[Live]:
    with start_blocking_portal("asyncio") as portal:
        state = Live(portal)
        state.start()
        try:
            yield state
        finally:
            state.close()
