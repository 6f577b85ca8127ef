"""A thin blocking facade over the async client, for scripts and notebooks.

``SyncRos`` runs an event loop in a background thread (anyio's blocking
portal) and exposes blocking versions of the common calls; callbacks run in
that thread. The thread starts with ``connect`` and ends with ``close``, or
with a ``connect`` that fails, so a script whose server is down gets its
error and ends.

Its calls take what the async API takes (docs/client.md): a topic, service or
action by name (with its type where the server needs one) or as the ``Topic``,
``Service`` or ``Action`` object.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Self, TypeVar

import anyio
from anyio.from_thread import BlockingPortal, start_blocking_portal

from rwt_protocol.errors import ConfigError

from .api import Action, GoalHandle, Service, Topic
from .connectors import ConnectionClosedError
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

    Attributes:
        ros: the async ``Ros`` this runs, for ``run``.
    """

    def __init__(self, url: str, **options: Any) -> None:
        self.ros = Ros(url, **options)
        self._portal_cm: AbstractContextManager[BlockingPortal] | None = None
        self._portal: BlockingPortal | None = None
        self._stop: anyio.Event | None = None
        self._main: Future[None] | None = None
        self._topics: dict[str, Topic] = {}

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def connect(self) -> None:
        """Start the background thread and connect; the connection lives in one of its tasks.

        A failed connect ends the thread before it raises, so the process can exit.

        Raises:
            ConnectionClosedError: the server cannot be reached.
            ConfigError: the URL is not one the client takes.
        """
        if self._portal is not None:
            return
        portal_cm = start_blocking_portal()
        portal = portal_cm.__enter__()
        try:
            self._main, self._stop = portal.start_task(self._hold)
        except BaseException:
            portal_cm.__exit__(None, None, None)  # the thread must not outlive a failed connect
            raise
        self._portal_cm, self._portal = portal_cm, portal

    async def _hold(self, *, task_status: TaskStatus[anyio.Event]) -> None:
        # connect and close must run in one task: the client's task group lives here
        stop = anyio.Event()
        async with self.ros:
            task_status.started(stop)
            await stop.wait()

    def close(self) -> None:
        """Close the connection and stop the background thread. Idempotent."""
        portal_cm, portal = self._portal_cm, self._portal
        if portal_cm is None or portal is None:
            return
        self._portal_cm = self._portal = None
        try:
            if self._stop is not None and self._main is not None:
                portal.call(self._stop.set)
                self._main.result()
        finally:
            portal_cm.__exit__(None, None, None)

    def run(self, function: Callable[..., Awaitable[T]], *args: object) -> T:
        """Run any coroutine function of the async API and return its result.

        Raises:
            ConnectionClosedError: not connected (``connect`` first, or use ``with``).
        """
        if self._portal is None:
            raise ConnectionClosedError(f"not connected to {self.ros.url}: call connect() first")
        return self._portal.call(function, *args)

    def topic(self, name: str, message_type: str | None = None, **options: Any) -> Topic:
        """A ``Topic`` of this connection (options as ``Topic``'s: ``throttle_rate``...)."""
        return Topic(self.ros, name, message_type, **options)

    def subscribe(
        self,
        topic: Topic | str,
        callback: Callback,
        message_type: str | None = None,
        **options: Any,
    ) -> Topic:
        """Blocking ``Topic.subscribe``: ``callback(msg)`` for each message (in the thread).

        Args:
            topic: a ``Topic``, or a topic name (with ``message_type`` and ``Topic``'s
                options, or None to take the type the server knows).
            callback: a plain or ``async`` function.
            message_type: for a name: ``pkg/msg/Type``.
            **options: for a name: ``Topic``'s options (``throttle_rate``...).

        Returns:
            The ``Topic``, for ``unsubscribe``.
        """
        handle = topic if isinstance(topic, Topic) else self.topic(topic, message_type, **options)
        self.run(handle.subscribe, callback)
        return handle

    def unsubscribe(self, topic: Topic) -> None:
        """Blocking ``Topic.unsubscribe``."""
        self.run(topic.unsubscribe)

    def publish(self, topic: Topic | str, msg: object, message_type: str | None = None) -> None:
        """Blocking ``Topic.publish``: advertises on first use, then publishes ``msg``.

        Args:
            topic: a ``Topic``, or a topic name; one ``Topic`` is kept per name, so a
                name is advertised once.
            msg: a dict or a message-class instance.
            message_type: for a name: ``pkg/msg/Type`` (None publishes without advertising).

        Raises:
            OpRefusedError: the server refused the advertisement.
        """
        if isinstance(topic, str):
            kept = self._topics.get(topic)
            if kept is None or kept.message_type != message_type:
                kept = self._topics[topic] = self.topic(topic, message_type)
            topic = kept
        self.run(topic.publish, msg)

    def call_service(
        self,
        service: Service | str,
        args: object = None,
        *,
        type_name: str | None = None,
        timeout_s: float | None = None,
    ) -> Any:
        """Blocking ``Ros.call_service``: the response values.

        Args:
            service: a service name, or a ``Service``.
            args: the request (a dict or a message-class instance).
            type_name: the service type, for a name (servers may ignore it).
            timeout_s: seconds to wait (default: the ``Ros``'s ``timeout_s``).

        Raises:
            ServiceCallError: ``result: false``.
            CallTimeoutError: no reply in time.
            ConnectionClosedError: the connection is down or dropped.
        """
        handle = service if isinstance(service, Service) else Service(self.ros, service, type_name)
        return self.run(lambda: handle.call(args, timeout_s=timeout_s))

    def send_goal(
        self,
        action: Action | str,
        goal: object = None,
        on_feedback: Callback | None = None,
        *,
        action_type: str | None = None,
    ) -> GoalHandle:
        """Blocking ``Action.send_goal``; ``result`` waits for its end.

        Args:
            action: an ``Action``, or an action name with ``action_type``.
            goal: the goal values.
            on_feedback: called with each feedback's values (in the thread).
            action_type: for a name: ``pkg/action/Type``.

        Raises:
            ConfigError: a name without ``action_type``.
            ConnectionClosedError: the connection is down.
        """
        if isinstance(action, str):
            if action_type is None:
                raise ConfigError(f"sending a goal to {action} needs its action_type")
            action = Action(self.ros, action, action_type)
        handle = action
        return self.run(lambda: handle.send_goal(goal, on_feedback=on_feedback))

    def result(self, handle: GoalHandle, timeout_s: float | None = None) -> Any:
        """Blocking ``GoalHandle.result``."""
        return self.run(lambda: handle.result(timeout_s=timeout_s))
