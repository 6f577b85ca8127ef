"""One HTTP API request as a session of the connection runtime (docs/http.md).

``HttpSession`` subclasses ``SessionBase`` (docs/architecture.md, "How to add a
protocol"): the transport (``rwt_transports.http.api``) reads the request, the
server admits it as any connection (``--max-connections``, the host shares) and
the pump runs the session; the request's body is its one frame. It answers with
one whole response and closes, or, for an event stream (a topic's ``/events``,
an action's goal), with the stream's head and then one Server-Sent Event per
message. The events go through ``queue_run``, so the send buffer's bound and the
slow-consumer rule are the same as every client's (D24): a stream that is not
read loses its oldest messages, then is cut after ``--send-timeout``. Names are
checked against the access rules (``require_access``), the listing and the
document show what they let one see (``rwt_graph.visibility``); the calls are
the graph's port's, as a rosbridge or Foxglove client's.

Status codes: 400 bad input (JSON, a type), 403 the access rules, 404 an unknown
topic, service or action, 502 a service that failed (its text), 504 no message
or answer in time; 500 a bug (contained: logged once, the server goes on).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

from rwt_graph.feed import EntityKind
from rwt_graph.visibility import Visibility
from rwt_protocol.codecs.json import decode_json_text, encode_json
from rwt_protocol.errors import GraphError, RwtError, UnknownNameError
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.access import AccessDeniedError, Family, TopicUse
from rwt_protocol.runtime.commands import CloseCode
from rwt_protocol.runtime.connection import SessionBase
from rwt_protocol.runtime.outbox import OutFrame, QueueRule

from .document import DocumentBuild
from .routes import Route, RouteKind
from .wire import (
    Headers,
    error_response,
    event,
    json_response,
    not_modified,
    response_head,
    stream_head,
)

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from rwt_graph.port import GraphFront
    from rwt_protocol.ports import GoalStatus, MessageEvent, PublishNote
    from rwt_protocol.qos import QosProfile
    from rwt_protocol.runtime.memory import MemoryBudget
    from rwt_protocol.runtime.rules import ClientRules

    from .document import Document, DocumentSource
    from .standing import StandingOffers

__all__ = ["HttpApiOptions", "HttpSession"]


@dataclass(frozen=True, slots=True)
class HttpApiOptions:
    """The HTTP API's settings (docs/http.md).

    Attributes:
        latest_wait_s: how long ``GET /api/topics/<name>`` waits for a message
            when the topic has no latched one (then 504).
        max_body_bytes: largest request body (a message, service arguments, a
            goal); None: the server's ``--max-message-size``.
    """

    latest_wait_s: float = 5.0
    max_body_bytes: int | None = None


class HttpSession(SessionBase):
    """One request of the HTTP API (the module's text).

    Args:
        graph: the served graph's port (``GraphFront``: its feed and types too).
        client_id: the connection's id in the graph (``http:127.0.0.1:5000#3``).
        route: what the request asks (``routes.parse_route``).
        headers: the headers every response carries (CORS).
        config: the per-client rules (``ClientRules``).
        options: the API's settings.
        version: the server's version, for the OpenAPI document.
        head_only: a HEAD request: the response's head alone.
        on_output: the pump's wake-up.
        peer: the peer's address.
        on_closed: the server's bookkeeping when it closes.
        memory: the server's memory budget (D44).
        documents: where the OpenAPI document is made and kept (``document``, D59);
            None: made here at once, whole.
        if_none_match: the request's ``If-None-Match`` header: the document is
            answered 304 when it names the current one.
        offers: the API's standing registrations, which keep a publish's ``qos``
            past its request (``standing``, D63); None: it lasts the request.
    """

    protocol = "http"

    def __init__(
        self,
        graph: GraphFront,
        client_id: str,
        route: Route,
        *,
        headers: Headers = (),
        config: ClientRules,
        options: HttpApiOptions | None = None,
        version: str = "0",
        head_only: bool = False,
        on_output: Callable[[], None] | None = None,
        peer: str = "",
        on_closed: Callable[[str], None] | None = None,
        memory: MemoryBudget | None = None,
        documents: DocumentSource | None = None,
        if_none_match: str | None = None,
        offers: StandingOffers | None = None,
    ) -> None:
        super().__init__(
            graph,
            client_id,
            config=config,
            on_output=on_output,
            peer=peer,
            on_closed=on_closed,
            max_messages=route.queue_length or None,
            memory=memory,
        )
        self._front = graph
        self.request_scoped = True  # a request is a command, not a commander's connection (D68)
        self.route = route
        self._headers = headers
        self._options = options or HttpApiOptions()
        self._version = version
        self._head_only = head_only
        self._documents = documents
        self._if_none_match = if_none_match
        self._offers = offers
        self._answered = False  # a response (or a stream's head) is queued
        self._streaming = False
        self._holds = False  # a subscription waits in the graph (a call: the call book)
        self._last_sent = -1.0e18  # an event stream's last message (throttle_rate)
        self._stream_rule: QueueRule | None = None  # an event stream's QoS (``stream_qos``)
        self._stream_lifespan_s = math.inf

    # ---- what the runtime asks ----------------------------------------------------

    def status_frames(
        self, level: StatusLevel, text: str, op_id: str | int | None = None
    ) -> Sequence[OutFrame]:
        """An error response (500) before the answer, an ``error`` event in a stream."""
        if level not in (StatusLevel.ERROR, StatusLevel.WARNING):
            return ()
        if self._streaming:
            data = encode_json({"level": level.wire, "text": text})
            return (OutFrame(event(data, "status")),)
        if self._answered or level is not StatusLevel.ERROR:
            return ()
        return (OutFrame(error_response(500, text, self._headers)),)

    def report(self, level: StatusLevel, text: str, op_id: str | int | None = None) -> None:
        """Tell the client (``status_frames``); a request not yet answered is then over."""
        answered = self._answered
        super().report(level, text, op_id)
        if level is StatusLevel.ERROR and not answered and not self._streaming:
            self._answered = True
            self.request_close(CloseCode.NORMAL, text)

    def holds_anything(self) -> bool:
        """Whether a subscription or a call of this request waits in the graph."""
        return self._holds or self.calls.in_flight > 0

    # ---- the request --------------------------------------------------------------

    def handle_frame(self, frame: str | bytes, now: float, binary: bool) -> None:
        """The request's body (its one frame): do what the route asks.

        Raises:
            Exception: a bug, contained by ``receive_frame`` (500).
        """
        if self._answered:
            return  # more bytes after the request: one request a connection
        route = self.route
        try:
            handler = _HANDLERS[route.kind]
            handler(self, route, frame)
        except AccessDeniedError as exc:
            self._answer(403, {"error": exc.message})
        except UnknownNameError as exc:
            self._answer(404, {"error": exc.message})
        except (GraphError, RwtError) as exc:
            self._answer(400, {"error": exc.message})

    def _answer(self, status: int, value: object) -> None:
        """Queue the whole response and close after it."""
        if self._answered:
            return
        self._answered = True
        body = json_response(status, value, self._headers, head_only=self._head_only)
        self.send_frames((OutFrame(body),))
        self.request_close(CloseCode.NORMAL, f"answered {status}")

    def _body(self, frame: str | bytes, what: str, *, required: bool) -> object:
        if not frame:
            if required:
                raise GraphError(f"{what}: a JSON body is needed")
            return None
        return decode_json_text(frame, what)

    def _openapi(self, route: Route, frame: str | bytes) -> None:
        policy = self.config.access
        if self._documents is None:
            self._send_document(DocumentBuild(self._front, policy, self._version).run())
            return
        self._holds = True
        self._documents.fetch(policy, self._send_document)

    def _send_document(self, document: Document | None) -> None:
        """Answer with ``document`` (its bytes shared, not copied), or 304 if the client has it.

        None: its build failed (a bug, logged where it ran): 500.
        """
        self._holds = False
        if self._answered:
            return
        if document is None:
            self._answer(500, {"error": "internal error: the document could not be made"})
            return
        self._answered = True
        tag = ((b"ETag", document.etag.encode()),)
        frames: tuple[OutFrame, ...]
        if document.matches(self._if_none_match):
            frames = (OutFrame(not_modified((*self._headers, *tag))),)
        else:
            kind, length = "application/json", len(document.body)
            head = OutFrame(response_head(200, kind, length, (*self._headers, *tag)))
            frames = (head,) if self._head_only else (head, OutFrame(document.body))
        self.send_frames(frames)
        self.request_close(CloseCode.NORMAL, "answered the document")

    def _topics(self, route: Route, frame: str | bytes) -> None:
        visibility = Visibility.of(self.config.access)
        found: dict[str, str] = {}
        for change in self._front.feed.snapshot()[1]:
            if change.kind in _TOPIC_KINDS and visibility.sees(change):
                found.setdefault(change.name, change.type_name)
        names = sorted(found)
        self._answer(200, {"topics": names, "types": [found[n] for n in names]})

    def _topic_type(self, name: str, given: str | None) -> str | None:
        """``given``, or the type ``name`` has in the graph now (None: unknown topic)."""
        if given:
            return given
        for change in self._front.feed.snapshot()[1]:
            if change.name == name and change.kind in _TOPIC_KINDS:
                return change.type_name
        return None

    def _latest(self, route: Route, frame: str | bytes) -> None:
        self.require_access(Family.TOPICS, route.name, "subscribe", TopicUse.SUBSCRIBE)
        latched = self._front.latched(route.name)
        if latched is not None:
            self._answer(200, latched.msg)
            return
        if self._topic_type(route.name, route.type_name) is None:
            self._answer(404, {"error": f"topic {route.name} does not exist"})
            return
        self.graph.subscribe(self.client_id, route.name, route.type_name, _LatestSink(self))
        self._holds = True
        wait = self._options.latest_wait_s
        self.call_at(self.now + wait, lambda now: self._no_message(wait))

    def _no_message(self, wait: float) -> None:
        self._answer(504, {"error": f"no message on {self.route.name} within {wait:g} s"})

    def _got_latest(self, event_: MessageEvent) -> None:
        self._answer(200, event_.msg)

    def _publish(self, route: Route, frame: str | bytes) -> None:
        self.require_access(Family.TOPICS, route.name, "publish", TopicUse.PUBLISH)
        msg = self._body(frame, "publish", required=True)
        if not isinstance(msg, dict):
            raise GraphError("publish: the body must be a JSON object (the message)")
        type_name = self._topic_type(route.name, route.type_name)
        if type_name is None:
            raise UnknownNameError("topic", f"{route.name} (give its ?type=)")
        type_name = self.graph.advertise(self.client_id, route.name, type_name, qos=route.qos)
        notes: list[PublishNote] = []
        self.graph.publish(self.client_id, route.name, msg, notes=notes.append)
        if any(note.dropped for note in notes):  # the safety envelope's rate (docs/safety.md)
            self._answer(429, {"error": "; ".join(note.text for note in notes)})
            return
        warnings = [note.text for note in notes]  # a request is one command (D67)
        if route.qos is not None:
            warnings += self._keep_offer(route.name, type_name, route.qos)
        answer: dict[str, object] = {"topic": route.name, "type": type_name}
        if warnings:
            answer["warnings"] = warnings
        self._answer(200, answer)

    def _keep_offer(self, topic: str, type_name: str, qos: QosProfile) -> list[str]:
        """Keep the publish's ``qos`` past the request (``standing``, D63); what to warn of.

        A topic that keeps another registration's QoS is said so, as a rosbridge
        client's ``advertise`` is (D62).
        """
        if self._offers is not None:
            self._offers.hold(topic, type_name, qos)
        offered = self.graph.offered_qos(topic)
        if offered is None or offered == qos.for_publisher():
            return []
        return [
            f"{topic} keeps the QoS of its first registration ({offered.describe()});"
            f" this one's ({qos.describe()}) is not used"
        ]

    def _events(self, route: Route, frame: str | bytes) -> None:
        self.require_access(Family.TOPICS, route.name, "subscribe", TopicUse.SUBSCRIBE)
        if route.type_name is None and self._topic_type(route.name, None) is None:
            self._answer(404, {"error": f"topic {route.name} does not exist"})
            return
        self._open_stream()
        sink = _StreamSink(self)
        self.graph.subscribe(self.client_id, route.name, route.type_name, sink, qos=route.qos)
        self._holds = True

    def _open_stream(self) -> None:
        self._answered = self._streaming = True
        self.send_frames((OutFrame(stream_head(self._headers)),))

    def _stream_messages(self, events: Sequence[MessageEvent]) -> None:
        """Queue ``events`` as Server-Sent Events, under ``throttle_rate`` (and the QoS).

        As a rosbridge subscriber's (``Session.deliver_many``): each message's event is
        one ``OutFrame`` made once for every stream (``_SSE_KEY``), queued in runs of
        one lifespan (a ROS 2 sample's, docs/ros2.md) and woken for once a run. A
        stream with QoS (``stream_qos``) queues each by its rule (``_send_ruled``).
        """
        if self._stream_rule is not None:
            self._send_ruled(events, self._stream_rule)
            return
        gap = self.route.throttle_rate_ms / 1000.0
        name = self.route.name
        timeless = self.config.qos_lifespan_s == math.inf  # no server lifespan (D63)
        run: list[OutFrame] = []
        run_now = run_lifespan = 0.0
        run_end = math.inf  # the run's end (``message_end``, D63)
        for each in events:
            if gap:
                if each.now - self._last_sent < gap:
                    continue  # rosbridge's throttle_rate: at most one message a gap
                self._last_sent = each.now
            frame: OutFrame | None = each.memos.get(_SSE_KEY)  # type: ignore[assignment]
            if frame is None:  # (``encoded``, inline above: a call less per stream)
                frame = each.encoded(_SSE_KEY, partial(_sse, each))
            lifespan = each.lifespan
            end = each.expires if timeless else self.message_end(each)
            if run and (
                lifespan != run_lifespan or end != run_end or (lifespan > 0 and each.now != run_now)
            ):
                self.queue_run(run, name, run_now, run_lifespan, run_end)
                run = []
            run.append(frame)
            run_now = each.now if each.now > run_now else run_now
            run_lifespan, run_end = lifespan, end
        self.queue_run(run, name, run_now, run_lifespan, run_end)

    def _send_ruled(self, events: Sequence[MessageEvent], rule: QueueRule) -> None:
        """Queue ``events`` of a stream with QoS, each with its lifespan's end (D63)."""
        gap = self.route.throttle_rate_ms / 1000.0
        for each in events:
            if gap:
                if each.now - self._last_sent < gap:
                    continue  # rosbridge's throttle_rate: at most one message a gap
                self._last_sent = each.now
            frame = each.encoded(_SSE_KEY, partial(_sse, each))
            expires = self.message_end(each, self._stream_lifespan_s)
            self.send_frames((frame,), self.route.name, 0.0, rule, expires)

    def stream_qos(self, offered: QosProfile | None) -> None:
        """The stream's topic has a QoS (``_StreamSink.on_qos_offered``, D63): its rule."""
        asked = self.route.qos
        if asked is None and offered is None:
            self._stream_rule = None
            return
        effective = None if asked is None else asked.for_subscription(offered)
        self._stream_lifespan_s = math.inf if effective is None else effective.lifespan_s
        self._stream_rule = (
            QueueRule() if effective is None else QueueRule(effective.keep, effective.best_effort)
        )

    def _service(self, route: Route, frame: str | bytes) -> None:
        self.require_access(Family.SERVICES, route.name, "call_service")
        args = self._body(frame, "call_service", required=False)
        calls = self.calls
        booked = calls.book()  # settled once: the answer, the deadline or the close

        def reply(result: bool, values: object) -> None:
            if not booked.settle():
                return
            if result:
                self._answer(200, values)
            else:
                self._answer(502, {"error": str(values)})

        timeout = self.config.call_timeout_s
        try:
            booked.pending = self.graph.call_service(
                self.client_id, route.name, args, reply, timeout_s=timeout
            )
        except RwtError:
            booked.settle()
            raise
        if timeout is not None:
            calls.expire_at(booked, self.now + timeout, lambda now: self._timed_out(timeout))

    def _timed_out(self, timeout: float) -> None:
        self._answer(504, {"error": f"no response within {timeout:g} s"})

    def _action(self, route: Route, frame: str | bytes) -> None:
        """Send the goal; its stream opens once the graph took it (404, 400 before: D59).

        What the goal says before the stream's head is queued (a provider that
        answers within the call) waits in ``early`` and follows the head.
        """
        self.require_access(Family.ACTIONS, route.name, "send_action_goal")
        goal = self._body(frame, "send_action_goal", required=True)
        if not isinstance(goal, dict):
            raise GraphError("send_action_goal: the body must be a JSON object (the goal)")
        early: list[OutFrame] = []
        ended = False
        booked = self.calls.book()  # held until it ends: the goal's answer or the close

        def send(out: OutFrame) -> None:
            if self._streaming:
                self.send_frames((out,))
            else:
                early.append(out)

        def feedback(values: dict[str, object]) -> None:
            send(OutFrame(event(encode_json(values), "feedback"), True, True))

        def done(status: GoalStatus, result: bool, values: object) -> None:
            nonlocal ended
            booked.settle()
            value = {"status": int(status), "result": result, "values": values}
            send(OutFrame(event(encode_json(value), "result")))
            ended = True
            if self._streaming:
                self.request_close(CloseCode.NORMAL, "goal done")

        # raises UnknownNameError (404), FieldError (400) before anything is sent
        try:
            booked.pending = self.graph.send_action_goal(
                self.client_id, route.name, goal, done, feedback
            )
        except RwtError:
            booked.settle()
            raise
        self._open_stream()
        for out in early:
            self.send_frames((out,))
        if ended:
            self.request_close(CloseCode.NORMAL, "goal done")


_TOPIC_KINDS = (EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION)

_SSE_KEY = "rwt_http.sse"
"""The key of a message's Server-Sent Event frame in ``MessageEvent.memos``: made once for all."""

_HANDLERS: dict[RouteKind, Callable[[HttpSession, Route, str | bytes], None]] = {
    RouteKind.OPENAPI: HttpSession._openapi,
    RouteKind.TOPICS: HttpSession._topics,
    RouteKind.LATEST: HttpSession._latest,
    RouteKind.PUBLISH: HttpSession._publish,
    RouteKind.EVENTS: HttpSession._events,
    RouteKind.SERVICE: HttpSession._service,
    RouteKind.ACTION: HttpSession._action,
}


def _sse(message: MessageEvent) -> OutFrame:
    """``message`` as one Server-Sent Event's frame, made once for every stream (``encoded``)."""
    return OutFrame(event(encode_json(message.msg)), True, True)


class _LatestSink:
    """The first message of a topic, for ``GET /api/topics/<name>``."""

    def __init__(self, session: HttpSession) -> None:
        self._session = session

    def on_message(self, event_: MessageEvent) -> None:
        self._session._got_latest(event_)


class _StreamSink:
    """A topic's messages for an event stream (a ``BatchSink``: a turn's run in one call)."""

    def __init__(self, session: HttpSession) -> None:
        self._session = session

    def on_qos_offered(
        self, offered: QosProfile | None, reasons: list[str], latest: Callable[[], float]
    ) -> None:
        """The topic's QoS (``rwt_graph.topic_qos``): the stream's rule follows it (D63)."""
        self._session.stream_qos(offered)

    def on_message(self, event_: MessageEvent) -> None:
        self._session._stream_messages((event_,))

    def on_messages(self, events: list[MessageEvent]) -> None:
        self._session._stream_messages(events)
