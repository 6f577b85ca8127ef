"""One Foxglove client's session on the graph, without I/O (docs/foxglove.md).

The driver (``driver.py``) hands it each received frame (``receive``), calls
``sync`` now and then so that topics that appeared or went are advertised or
unadvertised, and sends what ``take`` gives. Graph messages reach it through one
``TopicSink`` per subscribed topic, which only queues (a slow client never slows
a publisher or another client: the queue drops its oldest data, ``outqueue.py``).

What maps to what: a server channel is a topic of the graph that has a
publisher (and that the access globs let this client see); a subscription is a
graph subscription of this client id; a client channel is a graph publisher of
this client id. Every bad input is answered with an error ``status`` and the
session goes on.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

from rwt_graph.types.registry import codec_for
from rwt_graph.types.wire import CdrError, read_cdr, wire_input
from rwt_protocol import ops as rosbridge  # the graph port takes rosbridge op models
from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import RwtError
from rwt_protocol.names import name_problem, resolve_name
from rwt_protocol.server.access import AccessPolicy, Family
from rwt_protocol.server.outbox import OutFrame

from .outqueue import DEFAULT_MAX_BYTES, DEFAULT_MAX_MESSAGES, OutQueue
from .protocol import (
    Advertise,
    Channel,
    ClientAdvertise,
    ClientChannel,
    ClientMessageData,
    ClientUnadvertise,
    FoxgloveInputError,
    ServerInfo,
    Status,
    StatusLevel,
    Subscribe,
    Unadvertise,
    Unsubscribe,
    encode_message_data,
    encode_op,
    parse_binary,
    parse_text,
)
from .schemas import JSON, metadata_for, schema_of, supported_encodings, wire_encoding

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.core import GraphCore
    from rwt_graph.types import MessageType
    from rwt_protocol.ports import MessageEvent

__all__ = ["CAPABILITIES", "FoxgloveLimits", "FoxgloveSession"]

logger = logging.getLogger("rwt.foxglove")

CAPABILITIES: Final = ("clientPublish",)
"""What ``serverInfo`` announces (services, parameters, time... are not done yet)."""
_WIRE_KEY: Final = "foxglove-wire"  # ``MessageEvent.encoded`` key: one serialization per message


@dataclass(frozen=True, slots=True)
class FoxgloveLimits:
    """Bounds of one Foxglove client (docs/limits.md, Foxglove).

    Attributes:
        max_subscriptions: subscriptions a client may hold at once.
        max_client_channels: channels a client may advertise at once.
        max_queue_bytes: bytes of message data queued for the client before
            the oldest is dropped.
        max_queue_messages: messages queued before the oldest is dropped.
        batch_bytes: about how many bytes the driver sends per write.
    """

    max_subscriptions: int = 4096
    max_client_channels: int = 1024
    max_queue_bytes: int = DEFAULT_MAX_BYTES
    max_queue_messages: int = DEFAULT_MAX_MESSAGES
    batch_bytes: int = 1024 * 1024


@dataclass(eq=False, slots=True)
class _ServerChannel:
    id: int
    topic: str
    mtype: MessageType
    subscriptions: list[int] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class _ClientChannel:
    id: int
    topic: str
    mtype: MessageType
    encoding: str


class _TopicSink:
    """The graph's subscriber of one topic for this client: queues message data."""

    __slots__ = ("_channel", "_session")

    def __init__(self, session: FoxgloveSession, channel: _ServerChannel) -> None:
        self._session = session
        self._channel = channel

    def on_message(self, event: MessageEvent) -> None:
        self._session.deliver(self._channel, event, self._channel.subscriptions)


class FoxgloveSession:
    """The Foxglove protocol for one client on the graph.

    Args:
        graph: the graph's core (``Graph.port``), which subscriptions and
            client publishers go through on behalf of ``client_id``.
        client_id: this connection's identity in the graph.
        session_id: sent in ``serverInfo`` (clients tell a restarted server by it).
        access: which topics this client may see and publish on (``--topics-glob``).
        limits: this client's bounds.
        on_output: called when frames were queued while nobody asked (a graph
            message); the driver wakes its writer.
        name: the server's name in ``serverInfo``.
    """

    def __init__(
        self,
        graph: GraphCore,
        client_id: str,
        *,
        session_id: str,
        access: AccessPolicy | None = None,
        limits: FoxgloveLimits | None = None,
        on_output: Callable[[], None] | None = None,
        name: str = "rwt",
    ) -> None:
        self._graph = graph
        self._client_id = client_id
        self._access = access or AccessPolicy()
        self.limits = limits or FoxgloveLimits()
        self._queue = OutQueue(self.limits.max_queue_bytes, self.limits.max_queue_messages)
        self._on_output = on_output
        self._ids = itertools.count(1)
        self._channels: dict[str, _ServerChannel] = {}  # topic -> channel
        self._by_id: dict[int, _ServerChannel] = {}
        self._subscriptions: dict[int, _ServerChannel] = {}
        self._client_channels: dict[int, _ClientChannel] = {}
        self._failed_topics: set[str] = set()  # told once that their data cannot be encoded
        self._closed = False
        dialect = graph.registry.dialect
        self._wire = wire_encoding(dialect)
        self._control(
            ServerInfo(
                name=name,
                capabilities=list(CAPABILITIES),
                supportedEncodings=supported_encodings(dialect),
                metadata=metadata_for(dialect),
                sessionId=session_id,
            )
        )
        self.sync()

    # ---- outputs ------------------------------------------------------------------

    def take(self, max_bytes: int | None = None) -> list[OutFrame]:
        """Take the frames to send, oldest first (about ``max_bytes``; the limits' batch)."""
        return self._queue.take(self.limits.batch_bytes if max_bytes is None else max_bytes)

    @property
    def dropped(self) -> int:
        """Message data frames dropped for this client so far (it read too slowly)."""
        return self._queue.dropped

    def _control(self, op: Advertise | Unadvertise | ServerInfo | Status) -> None:
        self._queue.push(OutFrame(encode_op(op)))

    def _status(self, level: StatusLevel, message: str) -> None:
        # An answer to the client's input may be dropped like data: a client that
        # sends bad frames and reads nothing cannot grow the queue without bound.
        frame = OutFrame(encode_op(Status(level=int(level), message=message)), droppable=True)
        self._push_data(frame)

    def _push_data(self, frame: OutFrame) -> None:
        if self._queue.push(frame):
            self._queue.push(
                OutFrame(
                    encode_op(
                        Status(
                            level=int(StatusLevel.WARNING),
                            message="messages dropped: this client reads slower than they "
                            "arrive (the oldest go first)",
                        )
                    )
                )
            )

    # ---- input --------------------------------------------------------------------

    def receive(self, data: bytes, *, binary: bool) -> None:
        """Handle one frame of the client; its answers are queued (``take``).

        Never raises for what the client sent: each problem is an error ``status``.
        """
        if self._closed:
            return
        try:
            if binary:
                self._message_data(parse_binary(data))
                return
            op = parse_text(data)
            if isinstance(op, Subscribe):
                self._subscribe(op)
            elif isinstance(op, Unsubscribe):
                self._unsubscribe(op)
            elif isinstance(op, ClientAdvertise):
                self._client_advertise(op)
            else:
                self._client_unadvertise(op)
        except RwtError as exc:
            self._status(StatusLevel.ERROR, exc.message)

    def _subscribe(self, op: Subscribe) -> None:
        for each in op.subscriptions:
            try:
                self._subscribe_one(each.id, each.channelId)
            except RwtError as exc:
                self._status(StatusLevel.ERROR, exc.message)

    def _subscribe_one(self, sid: int, channel_id: int) -> None:
        if sid in self._subscriptions:
            raise FoxgloveInputError(f"subscription id {sid} is in use")
        channel = self._by_id.get(channel_id)
        if channel is None:
            raise FoxgloveInputError(f"subscribe: unknown channel {channel_id}")
        if len(self._subscriptions) >= self.limits.max_subscriptions:
            raise FoxgloveInputError(
                f"subscribe: more than {self.limits.max_subscriptions} subscriptions"
            )
        self._subscriptions[sid] = channel
        channel.subscriptions.append(sid)
        if len(channel.subscriptions) > 1:  # the topic's sink is there: replay its latched
            entry = self._graph.topics.get(channel.topic)
            if entry is not None and entry.latched is not None:
                self.deliver(channel, entry.latched, (sid,))
            return
        try:  # the graph hands the latched message to the new sink at once (D13)
            request = rosbridge.Subscribe(topic=channel.topic, type=channel.mtype.name)
            self._graph.subscribe(self._client_id, request, _TopicSink(self, channel))
        except RwtError:
            channel.subscriptions.remove(sid)
            del self._subscriptions[sid]
            raise

    def _unsubscribe(self, op: Unsubscribe) -> None:
        for sid in op.subscriptionIds:
            channel = self._subscriptions.pop(sid, None)
            if channel is None:
                self._status(StatusLevel.ERROR, f"unsubscribe: unknown subscription {sid}")
                continue
            channel.subscriptions.remove(sid)
            if not channel.subscriptions:
                self._graph.unsubscribe(self._client_id, channel.topic)

    def _client_advertise(self, op: ClientAdvertise) -> None:
        for channel in op.channels:
            try:
                self._advertise_one(channel)
            except RwtError as exc:
                self._status(StatusLevel.ERROR, f"advertise: {exc.message}")

    def _advertise_one(self, spec: ClientChannel) -> None:
        if spec.id in self._client_channels:
            raise FoxgloveInputError(f"client channel id {spec.id} is in use")
        if len(self._client_channels) >= self.limits.max_client_channels:
            raise FoxgloveInputError(f"more than {self.limits.max_client_channels} channels")
        if spec.encoding not in (self._wire, JSON):
            raise FoxgloveInputError(
                f"encoding {spec.encoding[:40]!r} is not supported (expected {self._wire} or json)"
            )
        problem = name_problem(spec.topic)
        if problem is not None:
            raise FoxgloveInputError(f"topic: {problem}")
        topic = resolve_name(spec.topic)
        if not self._access.allows(Family.TOPICS, topic):
            raise FoxgloveInputError(f"{topic} is not allowed")
        request = rosbridge.Advertise(topic=topic, type=spec.schemaName)
        type_name = self._graph.advertise(self._client_id, request)
        mtype = self._graph.registry.message(type_name)
        self._client_channels[spec.id] = _ClientChannel(spec.id, topic, mtype, spec.encoding)

    def _client_unadvertise(self, op: ClientUnadvertise) -> None:
        for cid in op.channelIds:
            channel = self._client_channels.pop(cid, None)
            if channel is None:
                self._status(StatusLevel.ERROR, f"unadvertise: unknown client channel {cid}")
                continue
            if all(other.topic != channel.topic for other in self._client_channels.values()):
                self._graph.unadvertise(self._client_id, channel.topic)

    def _message_data(self, op: ClientMessageData) -> None:
        channel = self._client_channels.get(op.channel_id)
        if channel is None:
            raise FoxgloveInputError(f"message data on unknown client channel {op.channel_id}")
        if channel.encoding == JSON:
            value = decode_json_text(bytes(op.payload), "message")
            self._graph.publish(self._client_id, rosbridge.Publish(topic=channel.topic, msg=value))
            return
        msg = self._decode_wire(channel.mtype, bytes(op.payload))
        self._graph.publish_local(self._client_id, channel.topic, msg, latch=False)

    def _decode_wire(self, mtype: MessageType, data: bytes) -> dict[str, object]:
        """A message in the dialect's wire encoding as the graph's internal form.

        Raises:
            FoxgloveInputError: ``data`` is not a message of ``mtype``.
        """
        store = self._graph.registry.typestore()
        try:
            if self._wire == "cdr":
                obj = read_cdr(store, wire_input(data), mtype.rosbags_name)
            else:
                obj = store.deserialize_ros1(data, mtype.rosbags_name)
            return mtype.from_python(obj)
        except (CdrError, RwtError, KeyError, ValueError, TypeError, IndexError) as exc:
            text = exc.message if isinstance(exc, RwtError) else str(exc)
            raise FoxgloveInputError(
                f"{mtype.name}: not a {self._wire} message of this type ({text[:200]})"
            ) from None

    # ---- the graph ----------------------------------------------------------------

    def sync(self) -> None:
        """Advertise the topics that appeared, unadvertise those gone (or retyped).

        A channel is a topic with a publisher that this client may see. Costs
        one pass over the graph's topics.
        """
        if self._closed:
            return
        current = {
            name: entry.msgtype
            for name, entry in self._graph.topics.items()
            if entry.publishers and self._access.allows(Family.TOPICS, name)
        }
        gone = [
            channel
            for topic, channel in self._channels.items()
            if (mtype := current.get(topic)) is None or mtype.name != channel.mtype.name
        ]
        if gone:
            for channel in gone:
                self._drop_channel(channel)
            self._control(Unadvertise(channelIds=[channel.id for channel in gone]))
        added: list[Channel] = []
        for topic, mtype in current.items():
            if topic in self._channels:
                continue
            channel = _ServerChannel(next(self._ids), topic, mtype)
            schema = schema_of(mtype)
            self._channels[topic] = channel
            self._by_id[channel.id] = channel
            added.append(
                Channel(
                    id=channel.id,
                    topic=topic,
                    encoding=schema.encoding,
                    schemaName=schema.schema_name,
                    schema=schema.schema,
                    schemaEncoding=schema.schema_encoding,
                )
            )
        if added:
            self._control(Advertise(channels=added))
        if (gone or added) and self._on_output is not None:
            self._on_output()

    def _drop_channel(self, channel: _ServerChannel) -> None:
        del self._channels[channel.topic]
        del self._by_id[channel.id]
        if channel.subscriptions:
            for sid in channel.subscriptions:
                del self._subscriptions[sid]
            channel.subscriptions.clear()
            self._graph.unsubscribe(self._client_id, channel.topic)

    def deliver(
        self,
        channel: _ServerChannel,
        event: MessageEvent,
        subscriptions: list[int] | tuple[int, ...],
    ) -> None:
        """Queue ``event`` as message data for each of ``subscriptions``; never raises.

        The payload is serialized once per message for every Foxglove client
        (``MessageEvent.encoded``); the log time is when the graph received it.
        """
        if self._closed or not subscriptions:
            return
        try:
            payload = event.encoded(_WIRE_KEY, lambda: self._serialize(channel.mtype, event))
        except Exception as exc:  # a type rosbags cannot write: say so once per topic
            if channel.topic not in self._failed_topics:
                self._failed_topics.add(channel.topic)
                logger.warning("event=encode_failed topic=%s reason=%r", channel.topic, str(exc))
                self._status(StatusLevel.ERROR, f"{channel.topic}: cannot encode its messages")
            return
        log_time = int(event.stamp * 1e9)
        for sid in subscriptions:
            self._push_data(OutFrame(encode_message_data(sid, log_time, payload), True, True))
        if self._on_output is not None:
            self._on_output()

    def _serialize(self, mtype: MessageType, event: MessageEvent) -> bytes:
        codec = event.codec or codec_for(self._graph.registry, mtype)
        return bytes(codec.serialize(event.msg))

    def close(self) -> None:
        """The connection is gone: release its subscriptions and publishers. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._graph.release(self._client_id)
        self._subscriptions.clear()
        self._client_channels.clear()
