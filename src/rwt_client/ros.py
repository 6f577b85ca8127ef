"""``Ros``: an async rosbridge client connection (the roslibpy ``Ros``, on anyio).

One ``Ros`` owns one connection (WebSocket or TCP, ``connectors``) and one
sans-IO ``ClientSession`` (``rwt_protocol.client``). A reader task turns frames
into events and routes them: topic messages to subscribers, replies to the
calls and goals waiting for them, requests to the services and actions this
client offers. Callbacks may be plain functions or coroutine functions; their
exceptions are logged, never propagated into the connection.

Events are the server's ops as their models (``rwt_protocol.ops``). An op the
protocol does not answer, such as ``advertise``, is confirmed by one round trip,
and an ``error`` status the server sends for its id raises ``OpRefusedError``;
an ``error`` status for a call's id fails the call (``ServiceCallError``), even
from a server that sends no ``service_response`` then.

When the connection drops and ``reconnect`` is on, ``Ros`` reconnects with
back-off (doubling from 0.1 s to 5 s, each wait times a random 0.5-1.5 so that
many clients of one restarted server do not come back in step) and replays the
status level, advertisements, subscriptions and offered services and actions;
calls and goals in flight fail with ``ConnectionClosedError``, and so does a
call or goal made while the connection is down (at once: it would not be sent).
Closing waits at most ``CLOSE_TIMEOUT_S`` for the server to take the close.
Nothing relies on rwt's extensions: a foreign server that never answers makes a
call time out with a clear error.
"""

from __future__ import annotations

import inspect
import logging
import random
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Self

import anyio

from rwt_protocol.client import ClientEvent, ClientSession
from rwt_protocol.errors import CallTimeoutError, OpRefusedError, RwtError, ServiceCallError
from rwt_protocol.ops import (
    ActionFeedback,
    ActionResult,
    CallService,
    CancelActionGoal,
    Publish,
    PublishFrame,
    PublishView,
    SendActionGoal,
    ServiceResponse,
    Status,
)
from rwt_protocol.ops.qos import Qos

from .connectors import Connection, ConnectionClosedError, connect
from .rosapi import RosapiMixin

if TYPE_CHECKING:
    from types import TracebackType

    from anyio.abc import TaskGroup

    from rwt_protocol.levels import StatusLevel
    from rwt_protocol.qos import QosProfile

__all__ = ["CLOSE_TIMEOUT_S", "CallTimeoutError", "Callback", "Ros", "ServiceCallError"]

logger = logging.getLogger("rwt.client")

CLOSE_TIMEOUT_S = 2.0
"""Seconds ``Ros.close`` waits for the server to take the close (a WebSocket close
frame, a TLS close_notify) before it cuts the socket: a server that vanished
without a word, or never reads, cannot hold a client's close (docs/client.md)."""

Callback = Callable[..., object]
"""A plain or ``async`` function; called with the event's payload."""


@dataclass
class _Waiter:
    """A call or goal waiting for its reply."""

    done: anyio.Event = field(default_factory=anyio.Event)
    reply: ServiceResponse | ActionResult | None = None
    error: RwtError | None = None
    on_feedback: Callback | None = None
    refused: Callable[[str], RwtError] | None = None
    """The error an ``error`` status for this id becomes; None: such statuses are not its end."""


class Ros(RosapiMixin):
    """A connection to a rosbridge server.

    Args:
        url: ``ws://HOST:PORT``, ``wss://...`` or ``tcp://HOST:PORT``.
        reconnect: reconnect (with replay) when the connection drops.
        timeout_s: default seconds for connecting and for service calls.
        max_message_size: largest incoming message, bytes.
        connector: opens the connection instead of ``connectors.connect(url)``
            (an in-process connection to a server in the same process); it
            raises ``ConnectionClosedError`` when it cannot.
    """

    def __init__(
        self,
        url: str,
        *,
        reconnect: bool = True,
        timeout_s: float = 10.0,
        max_message_size: int = 64 * 1024 * 1024,
        connector: Callable[[], Awaitable[Connection]] | None = None,
    ) -> None:
        self.url = url
        self._connector = connector
        self.reconnect = reconnect
        self.timeout_s = timeout_s
        self.max_message_size = max_message_size
        self.session = ClientSession()
        self._conn: Connection | None = None
        self._tasks: TaskGroup | None = None
        self._write_lock = anyio.Lock()
        self._topics: dict[str, dict[object, Callback]] = {}
        self._waiters: dict[str | int, _Waiter] = {}
        self._services: dict[str, Callback] = {}
        self._actions: dict[str, Callback] = {}
        self._server_goals: dict[str | int, ServerGoal] = {}
        self._status_callbacks: list[Callback] = []
        self._reconnect_callbacks: list[Callback] = []
        self._connected = anyio.Event()
        self._down = f"not connected to {url}"
        """Why the connection is down, for calls made meanwhile."""
        self._closing = False
        self.reconnects = 0

    # ---- lifetime -----------------------------------------------------------------

    async def __aenter__(self) -> Self:
        await self.connect()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def connect(self) -> None:
        """Connect and start the reader task.

        Raises:
            ConnectionClosedError: the server cannot be reached.
        """
        self._conn = await self._open()
        self._tasks = anyio.create_task_group()
        await self._tasks.__aenter__()
        self._tasks.start_soon(self._read_loop)
        self._connected.set()

    async def _open(self) -> Connection:
        if self._connector is not None:
            return await self._connector()
        return await connect(
            self.url, timeout_s=self.timeout_s, max_message_size=self.max_message_size
        )

    async def close(self) -> None:
        """Close the connection and stop every task; waiting calls fail. Idempotent."""
        if self._tasks is None:
            return
        self._closing = True
        self._down = f"the client closed its connection to {self.url}"
        self._fail_waiters("the client closed the connection")
        await self._close_connection()
        tasks, self._tasks = self._tasks, None
        tasks.cancel_scope.cancel()
        await tasks.__aexit__(None, None, None)

    async def wait_connected(self) -> None:
        """Wait until the connection is up (after a reconnect, once its replay was sent)."""
        await self._connected.wait()

    @property
    def is_connected(self) -> bool:
        """Whether the connection is up right now."""
        return self._connected.is_set() and not self._closing

    def require_connection(self) -> None:
        """Raise unless the connection is up: what is sent meanwhile would be lost.

        Raises:
            ConnectionClosedError: not connected yet, reconnecting, or closed.
        """
        if not self.is_connected:
            raise ConnectionClosedError(self._down)

    async def _close_connection(self) -> None:
        """Close the connection, cutting it after ``CLOSE_TIMEOUT_S`` (shielded)."""
        if self._conn is not None:
            with anyio.move_on_after(CLOSE_TIMEOUT_S, shield=True):
                await self._conn.aclose()  # a cancelled close cuts the socket (anyio)

    # ---- sending ------------------------------------------------------------------

    async def flush(self) -> None:
        """Send everything the session queued.

        Raises:
            ConnectionClosedError: the connection is down and not coming back
                (``reconnect`` off, or closing).
        """
        async with self._write_lock:
            frames = self.session.frames_to_send()
            if not frames:
                return
            if not self._connected.is_set():
                return  # replayed or dropped on reconnect; see the module docstring
            assert self._conn is not None
            try:
                for frame in frames:
                    await self._conn.send(frame)
            except ConnectionClosedError:
                if self._closing or not self.reconnect:
                    raise
                # Dropped under our feet: the reader sees it too and reconnects, and
                # the replay carries what is to be replayed, as when already down.

    def spawn(self, function: Callback, *args: object) -> None:
        """Run a callback: coroutine functions as tasks, plain ones now; errors logged."""
        if inspect.iscoroutinefunction(function):
            if self._tasks is not None:
                self._tasks.start_soon(_logged, function, *args)
            return
        try:
            function(*args)
        except Exception:
            logger.exception("callback %r failed", function)

    # ---- calls ----------------------------------------------------------------------

    async def call_service(
        self,
        service: str,
        args: object = None,
        *,
        type_name: str | None = None,
        timeout_s: float | None = None,
    ) -> object:
        """Call a service and return its response values (spec 3.3.8).

        Args:
            service: the service name.
            args: the request as an object (or a positional list, D25).
            type_name: the service type, sent as roslibjs does (servers may ignore it).
            timeout_s: seconds to wait (default: ``timeout_s`` of this ``Ros``); also
                sent to the server as ``timeout`` (rosbridge 2.2, D16).

        Raises:
            ServiceCallError: the reply had ``result: false``.
            CallTimeoutError: no reply in time.
            ConnectionClosedError: the connection is down (at once: reconnecting, or
                closed), or dropped before the reply.
        """
        self.require_connection()
        seconds = timeout_s or self.timeout_s
        call_id = self.session.call_service(service, args, type=type_name, timeout=seconds)
        waiter = self._waiters[call_id] = _Waiter(
            refused=lambda text: ServiceCallError(f"{service} failed: {text}", text)
        )
        try:
            await self.flush()
            with anyio.fail_after(seconds):
                await waiter.done.wait()
        except TimeoutError:
            raise CallTimeoutError(
                f"no service_response for {service} within {seconds:g} s "
                "(the server may not provide it or may never answer)"
            ) from None
        finally:
            self._waiters.pop(call_id, None)
        return _values(waiter, service)

    async def advertise(
        self,
        topic: str,
        type_name: str,
        *,
        latch: bool = False,
        queue_size: int = 100,
        qos: QosProfile | None = None,
    ) -> str:
        """Advertise ``topic`` and wait until the server took it (spec 3.3.1).

        ``qos``: the QoS offered (protocol 2.1.0; sent only when given).

        The protocol does not acknowledge ``advertise``: one round trip after it
        (a ``/rosapi/topic_type`` call, answered or refused, by any rosbridge
        server) shows whether the server sent an ``error`` status for its id
        (D1). A server that never answers makes this wait ``timeout_s``; with
        the status level ``none`` no refusal can be seen.

        Returns:
            The advertisement id, for ``unadvertise``.

        Raises:
            OpRefusedError: the server refused it (a type conflict, an access
                rule, a limit); it is not replayed after a reconnect.
            ConnectionClosedError: the connection dropped first.
        """
        adv_id = self.session.advertise(
            topic,
            type_name,
            latch=latch,
            queue_size=queue_size,
            qos=None if qos is None else Qos.of(qos),
        )
        refusal = await self.refusal("advertise", adv_id, topic)
        if refusal is not None:
            self.session.forget_advertisement(adv_id)
            raise refusal
        return adv_id

    async def refusal(self, op: str, op_id: str, topic: str) -> RwtError | None:
        """What ended the op ``op_id`` already queued: the server's refusal, if it sent one.

        The protocol acknowledges neither ``advertise`` nor ``subscribe``: one
        round trip after the op (a ``/rosapi/topic_type`` call for ``topic``,
        answered or refused, by any rosbridge server) shows whether the server
        sent an ``error`` status for its id (D1). A server that never answers
        makes this wait ``timeout_s``; with the status level ``none`` no refusal
        can be seen.

        Args:
            op: the op's name, for the error (``subscribe``).
            op_id: its id.
            topic: its topic, which the round trip asks about.

        Returns:
            ``OpRefusedError`` carrying the status text; ``ConnectionClosedError``
            when the connection dropped before the round trip ended (whether the
            server took the op is not known); None when it was not refused.
        """
        waiter = self._waiters[op_id] = _Waiter(
            refused=lambda text: OpRefusedError(op, op_id, text)
        )
        try:
            await self.call_service("/rosapi/topic_type", {"topic": topic})
        except (ServiceCallError, CallTimeoutError, ConnectionClosedError):
            pass  # only a round trip: its own answer does not matter
        finally:
            self._waiters.pop(op_id, None)
        return waiter.error

    def goal_waiter(self, goal_id: str, on_feedback: Callback | None) -> _Waiter:
        """Register a waiter for a goal's feedback and result (used by ``Action``)."""
        waiter = self._waiters[goal_id] = _Waiter(on_feedback=on_feedback)
        return waiter

    def forget(self, op_id: str | int) -> None:
        """Stop routing replies for ``op_id``."""
        self._waiters.pop(op_id, None)

    # ---- routing tables used by Topic, Service and Action ------------------------------

    def add_topic_callback(self, topic: str, key: object, callback: Callback) -> None:
        """Route messages of ``topic`` (as spelled here, D26) to ``callback``."""
        self._topics.setdefault(topic, {})[key] = callback

    def remove_topic_callback(self, topic: str, key: object) -> None:
        """Stop routing messages of ``topic`` to the callback registered as ``key``."""
        self._topics.get(topic, {}).pop(key, None)

    def set_service_handler(self, service: str, handler: Callback | None) -> None:
        """Route requests of an advertised service to ``handler`` (None removes it)."""
        if handler is None:
            self._services.pop(service, None)
        else:
            self._services[service] = handler

    def set_action_handler(self, action: str, handler: Callback | None) -> None:
        """Route goals of an advertised action to ``handler`` (None removes it)."""
        if handler is None:
            self._actions.pop(action, None)
        else:
            self._actions[action] = handler

    # ---- status ----------------------------------------------------------------------

    async def set_level(self, level: StatusLevel) -> None:
        """Choose which status messages arrive: ``StatusLevel.INFO`` ... ``NONE`` (spec 3.2.1)."""
        self.session.set_level(level)
        await self.flush()

    def on_reconnect(self, callback: Callback) -> None:
        """Call ``callback(n)`` after the n-th reconnect, once its replay was sent."""
        self._reconnect_callbacks.append(callback)

    def on_status(self, callback: Callback) -> None:
        """Call ``callback(StatusReceived)`` for each status message (spec 3.2.2)."""
        self._status_callbacks.append(callback)

    async def authenticate(
        self, mac: str, client: str, dest: str, rand: str, t: float, level: str, end: float
    ) -> None:
        """Send ``auth`` (ROS 1 spec 3.3.1, D23): the first op on servers that need it."""
        self.session.auth(mac, client, dest, rand, t, level, end)
        await self.flush()

    # ---- reader and reconnection -----------------------------------------------------------

    async def _read_loop(self) -> None:
        while True:
            try:
                assert self._conn is not None
                while True:
                    frame = await self._conn.receive()
                    for event in self.session.receive_frame(frame, anyio.current_time()):
                        self._route(event)
            except ConnectionClosedError as exc:
                self._connected = anyio.Event()
                then = "reconnecting" if self.reconnect else "reconnect is off"
                why = exc.message.removeprefix(f"{self.url}: ")  # the URL once
                self._down = f"not connected to {self.url}: {why} ({then})"
                self._fail_waiters(f"connection lost: {exc.message}")
                await self._close_connection()  # the lost connection's socket; never raises
                if self._closing or not self.reconnect:
                    return
                logger.warning("%s; reconnecting", exc.message)
                await self._reconnect()

    async def _reconnect(self) -> None:
        delay_s = 0.1
        while not self._closing:
            try:
                self._conn = await self._open()
            except ConnectionClosedError:
                await anyio.sleep(jittered(delay_s))  # back-off, not synchronisation
                delay_s = min(delay_s * 2, 5.0)
                continue
            self.reconnects += 1
            self.session.frames_to_send()  # whatever was queued while down is replayed instead
            self.session.replay()
            self._connected.set()
            await self.flush()
            for callback in self._reconnect_callbacks:
                self.spawn(callback, self.reconnects)
            return

    def _fail_waiters(self, reason: str) -> None:
        for waiter in self._waiters.values():
            waiter.error = ConnectionClosedError(reason)
            waiter.done.set()
        self._waiters.clear()

    def _route(self, event: ClientEvent) -> None:
        handler = _ROUTES.get(type(event))
        if handler is not None:
            handler(self, event)
        else:
            logger.debug("ignored from %s: %s", self.url, event)

    def _on_message(self, event: PublishView) -> None:
        for callback in list(self._topics.get(event.topic, {}).values()):
            self.spawn(callback, event.msg)

    def _on_reply(self, event: ServiceResponse | ActionResult) -> None:
        waiter = None if event.id is None else self._waiters.get(event.id)
        if waiter is not None:
            waiter.reply = event
            waiter.done.set()

    def _on_feedback(self, event: ActionFeedback) -> None:
        waiter = None if event.id is None else self._waiters.get(event.id)
        if waiter is not None and waiter.on_feedback is not None:
            self.spawn(waiter.on_feedback, event.values)

    def _on_request(self, event: CallService) -> None:
        handler = self._services.get(event.service)
        if handler is not None and self._tasks is not None:
            self._tasks.start_soon(self._serve_request, handler, event)

    async def _serve_request(self, handler: Callback, event: CallService) -> None:
        request_id = event.id if event.id is not None else ""
        try:
            values = await _maybe_await(handler(event.args))
            self.session.service_response(
                event.service, request_id, {} if values is None else values, True
            )
        except Exception as exc:  # the caller gets result false with the text (D4)
            self.session.service_response(
                event.service, request_id, f"{type(exc).__name__}: {exc}", False
            )
        await self.flush()

    def _on_goal(self, event: SendActionGoal) -> None:
        handler = self._actions.get(event.action)
        if handler is not None and self._tasks is not None:
            goal = ServerGoal(self, event)
            self._server_goals[goal.id] = goal
            self._tasks.start_soon(goal.run, handler)

    def _on_cancel(self, event: CancelActionGoal) -> None:
        goal = self._server_goals.get(event.id)
        if goal is not None:
            goal.cancel_requested.set()

    def _on_status(self, event: Status) -> None:
        waiter = None if event.id is None else self._waiters.get(event.id)
        if waiter is not None and waiter.refused is not None and event.level == "error":
            waiter.error = waiter.refused(event.msg)
            waiter.done.set()
        for callback in self._status_callbacks:
            self.spawn(callback, event)


class ServerGoal:
    """A goal received by an action this client advertised (spec 3.3.12-3.3.15).

    The handler gets this object: ``args`` is the goal, ``send_feedback`` sends
    feedback, ``cancel_requested`` is set when the sender cancels. Returning
    values ends the goal with status 4 (SUCCEEDED), or 5 (CANCELED) if
    ``canceled()`` was called; raising ends it with status 6 (ABORTED).
    """

    def __init__(self, ros: Ros, event: SendActionGoal) -> None:
        self.ros = ros
        self.id: str | int = event.id if event.id is not None else ""
        self.action = event.action
        self.args = event.args
        self.cancel_requested = anyio.Event()
        self._status = 4

    async def send_feedback(self, values: object) -> None:
        """Send ``action_feedback`` for this goal (spec 3.3.14)."""
        self.ros.session.action_feedback(self.action, self.id, values)
        await self.ros.flush()

    def canceled(self) -> None:
        """Mark the goal as canceled: its result goes out with status 5."""
        self._status = 5

    async def run(self, handler: Callback) -> None:
        """Run the handler and send the result."""
        try:
            values = await _maybe_await(handler(self))
            self.ros.session.action_result(
                self.action, self.id, values or {}, status=self._status, result=True
            )
        except Exception as exc:
            logger.warning("action %s goal %s aborted: %s", self.action, self.id, exc)
            self.ros.session.action_result(self.action, self.id, {}, status=6, result=False)
        finally:
            self.ros._server_goals.pop(self.id, None)
        await self.ros.flush()


#: The jitter's own generator: the ``random`` module's shared one belongs to the
#: application (a seeded simulation, a property-based test drawing its examples).
_JITTER = random.Random()


def jittered(delay_s: float) -> float:
    """One wait between reconnection attempts: ``delay_s`` times a random 0.5-1.5.

    The jitter keeps the clients of a restarted server from all coming back in
    the same instant (and again at each doubling of the back-off).
    """
    return delay_s * _JITTER.uniform(0.5, 1.5)


def _values(waiter: _Waiter, name: str) -> object:
    if waiter.error is not None:
        raise waiter.error
    reply = waiter.reply
    assert isinstance(reply, ServiceResponse)
    if not reply.result:
        raise ServiceCallError(f"{name} failed: {reply.values}", reply.values)
    return reply.values


async def _maybe_await(value: object) -> object:
    if inspect.isawaitable(value):
        return await value
    return value


async def _logged(function: Callable[..., Awaitable[object]], *args: object) -> None:
    try:
        await function(*args)
    except Exception:
        logger.exception("callback %r failed", function)


_ROUTES: dict[type, Callable[[Ros, ClientEvent], None]] = {
    Publish: Ros._on_message,  # type: ignore[dict-item]
    PublishFrame: Ros._on_message,  # type: ignore[dict-item]
    ServiceResponse: Ros._on_reply,  # type: ignore[dict-item]
    ActionResult: Ros._on_reply,  # type: ignore[dict-item]
    ActionFeedback: Ros._on_feedback,  # type: ignore[dict-item]
    CallService: Ros._on_request,  # type: ignore[dict-item]
    SendActionGoal: Ros._on_goal,  # type: ignore[dict-item]
    CancelActionGoal: Ros._on_cancel,  # type: ignore[dict-item]
    Status: Ros._on_status,  # type: ignore[dict-item]
}
