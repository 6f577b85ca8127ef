"""A thin blocking facade over the async client, for scripts and notebooks.

``SyncRos`` runs an event loop in a background thread (anyio's blocking
portal) and exposes blocking versions of the common calls; callbacks run in
that thread.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Self, TypeVar

import anyio
from anyio.from_thread import BlockingPortal, start_blocking_portal

from .api import Action, GoalHandle, Service, Topic
from .ros import Callback, Ros

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable
    from concurrent.futures import Future
    from contextlib import AbstractContextManager
    from types import TracebackType

    from anyio.abc import TaskStatus

__all__ = ["SyncRos"]

T = TypeVar("T")


class SyncRos:
    """A blocking rosbridge client: ``with SyncRos(url) as ros: ros.call_service(...)``.

    Args:
        url: as for ``Ros``.
        **options: passed to ``Ros`` (``reconnect``, ``timeout_s``...).
    """

    def __init__(self, url: str, **options: Any) -> None:
        self._portal_cm: AbstractContextManager[BlockingPortal] = start_blocking_portal()
        self._portal = self._portal_cm.__enter__()
        self.ros = Ros(url, **options)
        self._stop: anyio.Event | None = None
        self._main: Future[None] | None = None

    def __enter__(self) -> Self:
        self.connect()
        return self

    def connect(self) -> None:
        """Connect; the connection lives in one task of the background loop.

        Raises:
            ConnectionClosedError: the server cannot be reached.
        """
        self._main, self._stop = self._portal.start_task(self._hold)

    async def _hold(self, *, task_status: TaskStatus[anyio.Event]) -> None:
        # connect and close must run in one task: the client's task group lives here
        stop = anyio.Event()
        async with self.ros:
            task_status.started(stop)
            await stop.wait()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def run(self, function: Callable[..., Awaitable[T]], *args: object) -> T:
        """Run any coroutine function of the async API and return its result."""
        return self._portal.call(function, *args)

    def close(self) -> None:
        """Close the connection and stop the background thread."""
        try:
            if self._stop is not None and self._main is not None:
                self._portal.call(self._stop.set)
                self._main.result()
        finally:
            self._portal_cm.__exit__(None, None, None)

    def topic(self, name: str, message_type: str | None = None, **options: Any) -> Topic:
        """A ``Topic`` of this connection (use ``subscribe``/``publish`` below)."""
        return Topic(self.ros, name, message_type, **options)

    def subscribe(self, topic: Topic, callback: Callback) -> None:
        """Blocking ``Topic.subscribe``."""
        self.run(topic.subscribe, callback)

    def publish(self, topic: Topic, msg: object) -> None:
        """Blocking ``Topic.publish``."""
        self.run(topic.publish, msg)

    def call_service(
        self, name: str, request: object = None, *, timeout_s: float | None = None
    ) -> Any:
        """Blocking service call; returns the response values."""
        return self._portal.call(lambda: Service(self.ros, name).call(request, timeout_s=timeout_s))

    def send_goal(
        self, action: Action, goal: object, on_feedback: Callback | None = None
    ) -> GoalHandle:
        """Blocking ``Action.send_goal``."""
        return self._portal.call(lambda: action.send_goal(goal, on_feedback=on_feedback))

    def result(self, handle: GoalHandle, timeout_s: float | None = None) -> Any:
        """Blocking ``GoalHandle.result``."""
        return self._portal.call(lambda: handle.result(timeout_s=timeout_s))
