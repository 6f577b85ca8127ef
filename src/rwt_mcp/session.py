"""An MCP session on the connection runtime: the robot's graph, called directly.

``rwt serve --mcp`` answers each MCP session (a 2025-era ``initialize``, or one
2026-07-28 request) with an ``McpSession``: a session of the server's connection
runtime, as rosbridge's and Foxglove's are (``rwt_protocol.runtime.connection.SessionBase``),
made by the front end ``frontend`` and admitted by the server as every connection
is (``--max-connections``, the host's share). It is the ``robot.Robot`` the MCP
tools drive: each tool calls the graph port with the session's client id, with no
rosbridge client or JSON between them (docs/architecture.md). So what binds every
protocol binds it, from one place:

- the access gate (``SessionBase.require_access``: ``--topics-sub-glob`` and
  friends, and rosapi's parameter services against ``--params-glob``, as
  rosbridge checks them) with its one log line, for every name the tools touch,
  the agent's or their own (the TF republisher's topic, a service they call);
- the per-client caps (``--max-subscriptions``, ``max_advertisements``,
  ``max_pending_calls``) and the call book (``SessionBase.calls``: each service
  call's deadline, the server's ``--call-timeout``, on the session's timers;
  every call and goal answered once, forgotten when the session closes);
- ``--idle-timeout`` (the runtime's idle watch): the front end marks each request
  as input (``begin_request``, ``end_request``), and a request in flight holds the
  session (``holds_anything``): it ends without a request in flight (D40, D74);
- release: what it held leaves the graph when it closes, whoever closes it.

It takes no frames (MCP is answered over HTTP by the SDK): a frame is refused.
Messages reach the tools as callbacks, in rosbridge's JSON form (bytes as base64,
as a rosbridge client gets them), each subscription's at most once per
``throttle_ms`` (by the messages' times, the latest held on the session's timers);
nothing is queued for a reader, so the slow-consumer rule has nothing to hold. The
session reads no clock: its time comes from its transport, as every session's.
"""

from __future__ import annotations

import logging
import uuid
from functools import partial
from typing import TYPE_CHECKING, Any

import anyio
import msgspec
from mcp.server.mcpserver.exceptions import ToolError

from rwt_client.connectors import ConnectionClosedError
from rwt_client.rosapi import RosapiMixin
from rwt_protocol.codecs.json import encode_other
from rwt_protocol.errors import (
    CallTimeoutError,
    OpRefusedError,
    RemoteProtocolError,
    RwtError,
    ServiceCallError,
)
from rwt_protocol.runtime.access import AccessDeniedError, Family, TopicUse, param_call_name
from rwt_protocol.runtime.commands import CloseCode
from rwt_protocol.runtime.connection import SessionBase

from .guard import FAMILIES, refusal_text
from .robot import GoalEnd, GoalRun, Publisher, Subscription

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from anyio.abc import TaskGroup

    from rwt_protocol.levels import StatusLevel
    from rwt_protocol.ports import GoalStatus, GraphPort, MessageEvent, PublishNote
    from rwt_protocol.qos import QosProfile
    from rwt_protocol.runtime.callbook import BookedCall
    from rwt_protocol.runtime.memory import MemoryBudget
    from rwt_protocol.runtime.outbox import OutFrame
    from rwt_protocol.runtime.rules import ClientRules
    from rwt_protocol.runtime.timers import Timer

__all__ = ["DEFAULT_CALL_TIMEOUT_S", "McpSession", "jsonable"]

logger = logging.getLogger("rwt.mcp")

DEFAULT_CALL_TIMEOUT_S = 30.0
"""Seconds a service call waits when neither the tool nor the server (``call_timeout_s``) says."""
_JSON_FORM = ("mcp", "json")  # ``MessageEvent.memo``'s key of the JSON form
_ABORTED = 6  # action_msgs/GoalStatus: a goal the graph refused ends so (D4)
_TIMED_OUT = object()  # a call's outcome: its deadline came first (``CallBook.expire_at``)
_CLOSED = object()  # a call's outcome: the session closed first
_WHAT = {
    Family.TOPICS: "topic",
    Family.SERVICES: "service",
    Family.ACTIONS: "action",
    Family.PARAMS: "name",
}  # the tool argument each family's name is in, for the refusal's text


def jsonable(values: object) -> Any:
    """The graph's values in rosbridge's JSON form: bytes as base64, arrays as lists.

    What a rosbridge client decodes from the server's JSON
    (``rwt_protocol.codecs.json.encode_json``), without the text between.
    """
    return msgspec.to_builtins(values, enc_hook=encode_other)


class _Watcher:
    """One subscription's callback and its throttle: the latest message is kept (spec 3.3.4).

    The throttle runs on the messages' times and the session's timers (the runtime's),
    so a held message goes when its time comes whoever drives the session.
    """

    __slots__ = ("callback", "closed", "last", "pending", "session", "throttle_s", "timer")

    def __init__(self, session: McpSession, callback: Callable[[Any], None], throttle_ms: int):
        self.session = session
        self.callback = callback
        self.throttle_s = max(throttle_ms, 0) / 1000.0
        self.last = -1e18
        self.pending: MessageEvent | None = None  # the latest, held for the throttle
        self.timer: Timer | None = None  # the held one's, on the session's timers
        self.closed = False

    def offer(self, event: MessageEvent) -> None:
        if self.closed:
            return
        if not self.throttle_s:
            self._deliver(event)
            return
        now = event.now
        if self.pending is None and now - self.last >= self.throttle_s:
            self.last = now
            self._deliver(event)
            return
        held = self.pending is not None
        self.pending = event  # the newest replaces the one held (queue_length 1)
        if not held:
            self.timer = self.session.call_at(self.last + self.throttle_s, self._later)

    def close(self) -> None:
        """The subscription ended: nothing more is delivered, the held message goes."""
        self.closed = True
        self.pending = None
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None

    def _later(self, now: float) -> None:
        self.timer = None
        event, self.pending = self.pending, None
        if event is None or self.closed:
            return
        if self.session.message_end(event) <= now:
            return  # past its lifespan while it waited (D63): never delivered
        self.last = now
        self._deliver(event)

    def _deliver(self, event: MessageEvent) -> None:
        try:  # made once per message for every MCP subscriber (read, never changed)
            self.callback(event.memo(_JSON_FORM, partial(jsonable, event.msg)))
        except Exception:  # a tool's callback: its bug ends nothing else
            logger.exception("event=bug task=mcp_message client=%s", self.session.client_id)


class _Fan:
    """The graph's sink of one topic for the session: every subscription of it."""

    __slots__ = ("watchers",)

    def __init__(self) -> None:
        self.watchers: list[_Watcher] = []

    def on_message(self, event: MessageEvent) -> None:
        for watcher in tuple(self.watchers):
            watcher.offer(event)

    def on_messages(self, events: list[MessageEvent]) -> None:
        for event in events:
            self.on_message(event)


class _Subscription:
    def __init__(self, session: McpSession, topic: str, watcher: _Watcher) -> None:
        self._session = session
        self._topic = topic
        self._watcher = watcher

    async def unsubscribe(self) -> None:
        self._session.drop_watcher(self._topic, self._watcher)


class _Publisher:
    def __init__(self, session: McpSession, topic: str) -> None:
        self._session = session
        self._topic = topic
        self._advertised = True

    async def publish(self, msg: object) -> str | None:
        if not self._advertised:
            raise RemoteProtocolError(f"publish: {self._topic} is not advertised")
        return self._session.publish(self._topic, msg)

    async def unadvertise(self) -> None:
        if self._advertised:
            self._advertised = False
            self._session.drop_advertisement(self._topic)


class _Goal:
    __slots__ = ("_done", "_end", "_id")

    def __init__(self, goal_id: str) -> None:
        self._id = goal_id
        self._done = anyio.Event()
        self._end: GoalEnd | None = None

    @property
    def id(self) -> str:
        return self._id

    @property
    def ended(self) -> bool:
        return self._end is not None

    def finish(self, end: GoalEnd) -> None:
        if self._end is None:
            self._end = end
            self._done.set()

    async def result(self) -> GoalEnd:
        await self._done.wait()
        assert self._end is not None  # set with the event
        return self._end


class McpSession(SessionBase, RosapiMixin):
    """One MCP session (or 2026-07-28 request) of the server: a ``robot.Robot`` (module text).

    Args:
        graph: the served graph's port.
        client_id: its id in the graph (``mcp:127.0.0.1:5123#3``).
        config: the per-client rules of the server (the session's ``ClientRules``).
        on_output: the pump's wake-up.
        peer: the agent's address.
        on_closed: the server's bookkeeping when it closes.
        memory: the server's memory budget (D44).
    """

    protocol = "mcp"

    def __init__(
        self,
        graph: GraphPort,
        client_id: str,
        *,
        config: ClientRules,
        on_output: Callable[[], None] | None = None,
        peer: str = "",
        on_closed: Callable[[str], None] | None = None,
        memory: MemoryBudget | None = None,
    ) -> None:
        super().__init__(
            graph,
            client_id,
            config=config,
            on_output=on_output,
            peer=peer,
            on_closed=on_closed,
            memory=memory,
        )
        self.url = client_id  # ``mcp:HOST:PORT#N``
        self.on_close_requested: Callable[[], None] | None = None
        """Called when the session is asked to close (the server stopping), where no pump
        runs it to take the request (a 2026-07-28 request's session: its request ends)."""
        self._tg: TaskGroup | None = None
        self._clock: Callable[[], float] | None = None  # the transport's (``bind``)
        self._fans: dict[str, _Fan] = {}
        self._advertised: dict[str, int] = {}  # topic -> publishers of the tools holding it
        self._requests = 0  # the client's requests in flight (``begin_request``)

    # ---- the runtime's side ------------------------------------------------------------

    def bind(self, tg: TaskGroup, clock: Callable[[], float]) -> None:
        """Run what the tools leave running (goal watchers) in ``tg``.

        ``clock``: the transport's, monotonic seconds (the event loop's), read for a
        call's deadline on the session's timers (``calls``); the session reads none.
        """
        self._tg = tg
        self._clock = clock

    def begin_request(self, now: float) -> None:
        """A request of the session's client came at ``now``: input, and held until it ends.

        A request in flight (an open event stream included) keeps the session from
        ``--idle-timeout`` (``holds_anything``), as each request is its input (D40).
        """
        self._requests += 1
        self.received(now)

    def end_request(self, now: float) -> None:
        """The request begun last ended at ``now``: the idle time counts from here (D40)."""
        self._requests -= 1
        self.received(now)

    def status_frames(
        self, level: StatusLevel, text: str, op_id: str | int | None = None
    ) -> Sequence[OutFrame]:
        """None: an MCP agent hears of problems as tool errors."""
        return ()

    def handle_frame(self, frame: str | bytes, now: float, binary: bool) -> None:
        """Refuse it: an MCP session's requests come over HTTP, not as frames.

        Raises:
            RemoteProtocolError: always.
        """
        raise RemoteProtocolError("an MCP session takes no frames")

    def request_close(self, code: CloseCode, reason: str, *, abort: bool = False) -> None:
        """As every session's (``SessionBase.request_close``); then ``on_close_requested``."""
        super().request_close(code, reason, abort=abort)
        if self.on_close_requested is not None:
            self.on_close_requested()

    def holds_anything(self) -> bool:
        """Whether a request is in flight (the idle rule: D40's, on the runtime's watch).

        What the tools hold (subscriptions, publishers, goals left running) does not
        hold the session: the client that left them may be gone, and its requests
        are its only sign of life. A 2026-07-28 request's session is held by its
        request and its tasks, which end it.
        """
        return self.request_scoped or self._requests > 0

    def release(self) -> None:
        """Drop what the session holds in the graph (its calls: the call book's, at close)."""
        for fan in self._fans.values():
            for watcher in fan.watchers:
                watcher.close()
        self._fans.clear()
        self._advertised.clear()
        super().release()

    # ---- the robot's side (``robot.Robot``) ----------------------------------------------

    async def call_service(
        self,
        service: str,
        args: object = None,
        *,
        type_name: str | None = None,
        timeout_s: float | None = None,
    ) -> object:
        """Call ``service`` through the graph (``Robot.call_service``).

        ``type_name`` is not checked, as rosbridge does not (REF §2.6).

        Raises:
            ToolError: the access rules refuse the service (or, for rosapi's
                parameter services, the parameter).
            ServiceCallError: the call failed, or a cap refused it.
            CallTimeoutError: no answer within ``timeout_s`` (or the server's call timeout).
        """
        self._require(Family.SERVICES, service, "call_service")
        param = param_call_name(service, args)
        if param is not None:
            self._require(Family.PARAMS, param, "call_service")
        seconds = timeout_s or self.config.call_timeout_s or DEFAULT_CALL_TIMEOUT_S
        outcome = await self._booked_call(service, args, seconds)
        if outcome is _TIMED_OUT:
            raise CallTimeoutError(
                f"no service_response for {service} within {seconds:g} s "
                "(the server may not provide it or may never answer)"
            )
        if outcome is _CLOSED:
            raise ConnectionClosedError("the MCP session was closed by the server")
        assert isinstance(outcome, tuple)  # the callee's answer
        result, values = outcome
        values = jsonable(values) if values is not None else {}
        if not result:
            raise ServiceCallError(f"{service} failed: {values}", values)
        return values

    async def _booked_call(self, service: str, args: object, seconds: float) -> object:
        """Call ``service`` in the session's call book and wait for its outcome.

        Returns:
            The callee's ``(result, values)``; ``_TIMED_OUT`` past ``seconds`` (the
            book's deadline, on the session's timers); ``_CLOSED`` when the session
            closed first.

        Raises:
            ServiceCallError: the graph refused the call, or ``--max-pending-calls`` did.
        """
        outcome: list[object] = []
        answered = anyio.Event()

        def settle(value: object) -> None:
            outcome.append(value)
            answered.set()

        booked: BookedCall | None = None
        try:
            self.check_cap(self.calls.in_flight, self.config.max_pending_calls, "pending calls")
            booked = self.calls.book(on_close=lambda: settle(_CLOSED))
            call = booked

            def reply(result: bool, values: object) -> None:
                if call.settle():  # the first of the answer, the deadline and the close
                    settle((result, values))

            booked.pending = self._graph.call_service(
                self.client_id, service, args, reply, timeout_s=seconds, path="$.args"
            )
        except RwtError as exc:
            if booked is not None:
                booked.settle()
            raise ServiceCallError(f"{service} failed: {exc}", str(exc)) from None
        clock = self._clock or (lambda: self.now)
        self.calls.expire_at(booked, clock() + seconds, lambda _now: settle(_TIMED_OUT))
        try:
            await answered.wait()
        finally:
            if booked.settle() and booked.pending is not None:  # the tool was cancelled
                booked.pending.forget()
        return outcome[0]

    async def subscribe(
        self,
        topic: str,
        type_name: str | None,
        callback: Callable[[Any], None],
        *,
        throttle_ms: int = 0,
        queue_length: int = 0,
        qos: QosProfile | None = None,
    ) -> Subscription:
        """Deliver ``topic``'s messages to ``callback`` (``Robot.subscribe``).

        ``qos``: what the session's subscription of ``topic`` asks of it, given by
        its first watcher (D62-D63; the session holds one subscription a topic).

        Raises:
            ToolError: the access rules refuse the topic.
            OpRefusedError: ``--max-subscriptions``, or a type the topic does not have.
            ConnectionClosedError: the session is closed.
        """
        self.require_connection()
        self._require(Family.TOPICS, topic, "subscribe", TopicUse.SUBSCRIBE)
        watcher = _Watcher(self, callback, throttle_ms)
        fan = self._fans.get(topic)
        if fan is None:
            try:
                self.check_cap(len(self._fans), self.config.max_subscriptions, "subscriptions")
                fan = self._fans[topic] = _Fan()
                fan.watchers.append(watcher)  # a latched message comes at once (D13)
                self._graph.subscribe(self.client_id, topic, type_name, fan, qos=qos)
            except RwtError as exc:
                self._fans.pop(topic, None)
                raise OpRefusedError("subscribe", topic, f"subscribe: {exc}") from None
        else:
            fan.watchers.append(watcher)
        return _Subscription(self, topic, watcher)

    def drop_watcher(self, topic: str, watcher: _Watcher) -> None:
        """End one subscription; the graph's, with the topic's last."""
        watcher.close()
        fan = self._fans.get(topic)
        if fan is None or watcher not in fan.watchers:
            return
        fan.watchers.remove(watcher)
        if not fan.watchers:
            del self._fans[topic]
            if not self.closed:
                self._graph.unsubscribe(self.client_id, topic)

    async def advertise(
        self, topic: str, type_name: str, qos: QosProfile | None = None
    ) -> Publisher:
        """Advertise ``topic`` (``Robot.advertise``); ``qos`` what it offers (D62).

        Raises:
            ToolError: the access rules refuse the topic.
            OpRefusedError: ``max_advertisements``, or another type on the topic.
            ConnectionClosedError: the session is closed.
        """
        self.require_connection()
        self._require(Family.TOPICS, topic, "advertise", TopicUse.PUBLISH)
        try:
            if topic not in self._advertised:
                cap = self.config.max_advertisements
                self.check_cap(len(self._advertised), cap, "advertisements")
            self._graph.advertise(self.client_id, topic, type_name, qos=qos)
        except RwtError as exc:
            raise OpRefusedError("advertise", topic, f"advertise: {exc}") from None
        self._advertised[topic] = self._advertised.get(topic, 0) + 1
        return _Publisher(self, topic)

    def publish(self, topic: str, msg: object) -> str | None:
        """Publish ``msg`` (JSON form) as the session's publisher of ``topic``.

        Returns:
            What the safety envelope did to it (a clamp, a drop), or None (docs/safety.md).

        Raises:
            RwtError: the message does not fit the type (D9), the safety envelope
                refused it (D67), or the session is closed.
        """
        self.require_connection()
        notes: list[PublishNote] = []
        self._graph.publish(self.client_id, topic, msg, path="$.msg", notes=notes.append)
        return "; ".join(note.text for note in notes) or None

    def drop_advertisement(self, topic: str) -> None:
        """One publisher of ``topic`` fewer; the graph's advertisement goes with the last."""
        left = self._advertised.get(topic, 0) - 1
        if left > 0:
            self._advertised[topic] = left
            return
        if self._advertised.pop(topic, None) is not None and not self.closed:
            self._graph.unadvertise(self.client_id, topic)

    async def send_goal(
        self, action: str, type_name: str, goal: object, on_feedback: Callable[[Any], None]
    ) -> GoalRun:
        """Send ``goal`` (``Robot.send_goal``); its id is unique on the server (D35).

        A goal the graph refuses (no such action, a goal that does not fit) ends
        at once, aborted with the reason, as rosbridge answers it (D4).

        Raises:
            ToolError: the access rules refuse the action.
            ConnectionClosedError: the session is closed.
        """
        self.require_connection()
        self._require(Family.ACTIONS, action, "send_action_goal")
        run = _Goal(f"send_action_goal:{action}:{uuid.uuid4().hex[:16]}")  # as a client names it
        booked: BookedCall | None = None

        def done(status: GoalStatus, result: bool, values: object) -> None:
            if booked is not None:
                booked.settle()
            run.finish(GoalEnd(int(status), result, jsonable(values)))

        def feedback(values: dict[str, object]) -> None:
            try:
                on_feedback(jsonable(values))
            except Exception:  # the tool's callback: its bug ends nothing else
                logger.exception("event=bug task=mcp_feedback client=%s", self.client_id)

        try:
            self.check_cap(self.calls.in_flight, self.config.max_pending_calls, "pending calls")
            booked = self.calls.book()  # held in the call book until it ends
            booked.pending = self._graph.send_action_goal(
                self.client_id, action, goal, done, feedback, path="$.goal", request_id=run.id
            )
        except RwtError as exc:
            if booked is not None:
                booked.settle()
            run.finish(GoalEnd(_ABORTED, False, str(exc)))
            return run
        if run.ended:  # it ended while it was sent
            booked.settle()
        return run

    async def cancel_goal(self, action: str, goal_id: str) -> None:
        """Ask to cancel the goal ``goal_id`` of ``action`` (D35; ``Robot.cancel_goal``).

        Raises:
            ToolError: the access rules refuse the action.
            RwtError: the graph refused it.
        """
        self.require_connection()
        self._require(Family.ACTIONS, action, "cancel_action_goal")
        self._graph.cancel_action_goal(self.client_id, action, goal_id)

    def check_access(self, family: str, name: str, what: str, op: str) -> None:
        """Refuse ``name`` (a ``guard.FAMILIES`` family) as the gate would (``Robot.check_access``).

        Raises:
            ToolError: ``<what> <name>: refused by <rule>``, logged by the gate.
        """
        kind, use = FAMILIES[family]
        self._require(kind, name, op, use, what=what)

    def spawn(self, function: Callable[[], Any]) -> bool:
        """Run ``function`` in the session's task group (``bind``).

        Returns:
            Whether it runs: not before ``bind``, nor once the session closed.
        """
        if self._tg is None or self.closed:
            return False
        self._tg.start_soon(function)
        return True

    def require_connection(self) -> None:
        """Raise ``ConnectionClosedError`` once the session is closing or closed."""
        if self.closing or self.closed:
            raise ConnectionClosedError("the MCP session was closed by the server")

    async def connect(self) -> None:
        """Nothing to reach: the graph is in this process."""

    async def aclose(self) -> None:
        """Ask the runtime to close the session (it releases what the session held)."""
        self.request_close(CloseCode.NORMAL, "the MCP session ended")

    def _require(
        self,
        family: Family,
        name: str,
        op: str,
        use: TopicUse | None = None,
        *,
        what: str | None = None,
    ) -> None:
        """The one access gate (``SessionBase.require_access``), its refusal a tool error."""
        try:
            self.require_access(family, name, op, use)
        except AccessDeniedError as exc:
            raise ToolError(
                refusal_text(self.config.access, exc.glob, what or _WHAT[family], name)
            ) from None
