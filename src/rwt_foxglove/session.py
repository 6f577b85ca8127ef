"""One Foxglove client's session on the graph, without I/O (docs/foxglove.md).

The driver (``driver.py``) hands it each received frame (``receive``), calls
``sync`` now and then so that topics that appeared or went are advertised or
unadvertised, and sends what ``take`` gives. Graph messages reach it through one
``TopicSink`` per subscribed topic, which only queues (a slow client never slows
a publisher or another client: the queue drops its oldest data, ``outqueue.py``).

What maps to what: a server channel is a topic of the graph that has a
publisher (and that the access globs let this client see); a subscription is a
graph subscription of this client id; a client channel is a graph publisher of
this client id. Services, parameters and the connection graph are parts of
their own (``services``, ``params``, ``conngraph``), which send through the
session (``output.SessionOutput``). Every bad input is answered with an error
``status`` and the session goes on.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

from rwt_graph.types.registry import codec_for
from rwt_graph.visibility import Visibility
from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import RwtError
from rwt_protocol.names import name_problem, resolve_name
from rwt_protocol.server.access import AccessPolicy, Family
from rwt_protocol.server.outbox import OutFrame
from rwt_protocol.shortcuts import enabled

from .assetrequests import ASSETS_CAPABILITY, MAX_PENDING_ASSETS, AssetRequests
from .conngraph import ConnectionGraph
from .limits import FoxgloveLimits
from .outqueue import OutQueue
from .params import ParameterBridge
from .playback import PLAYBACK_CAPABILITY, PlaybackControl
from .protocol import (
    Advertise,
    Channel,
    ClientAdvertise,
    ClientChannel,
    ClientMessageData,
    ClientUnadvertise,
    FetchAsset,
    FoxgloveInputError,
    GetParameters,
    PlaybackControlRequest,
    RemoveStatus,
    ServerInfo,
    ServerOp,
    ServiceCallRequest,
    SetParameters,
    Status,
    StatusLevel,
    Subscribe,
    SubscribeConnectionGraph,
    SubscribeParameterUpdates,
    Unadvertise,
    Unsubscribe,
    UnsubscribeConnectionGraph,
    UnsubscribeParameterUpdates,
    encode_fetch_asset_response,
    encode_message_header,
    encode_op,
    parse_binary,
    parse_text,
)
from .schemas import JSON, metadata_for, schema_of, supported_encodings, wire_encoding
from .servertime import TIME_CAPABILITY, ServerTime
from .services import ServiceCalls

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.parameters.store import Parameters
    from rwt_graph.port import GraphFront
    from rwt_graph.types import MessageType
    from rwt_protocol.ports import MessageEvent

__all__ = ["CAPABILITIES", "PARAMETER_CAPABILITIES", "FoxgloveLimits", "FoxgloveSession"]

logger = logging.getLogger("rwt.foxglove")

CAPABILITIES: Final = ("clientPublish", "services", "connectionGraph")
"""What ``serverInfo`` always announces (``time`` too while a bag plays, ``servertime``,
and ``playbackControl`` while it is a player's, ``playback``; ``assets`` when the server
serves them)."""
PARAMETER_CAPABILITIES: Final = ("parameters", "parametersSubscribe")
"""Announced too when the session is given the graph's parameters."""
_WIRE_KEY: Final = "foxglove-wire"  # ``MessageEvent.encoded`` key: one serialization per message
DROPPING_STATUS: Final = "rwt.dropping"
"""The id of the warning that this client's oldest message data is being dropped,
withdrawn (``removeStatus``) once its queue is empty again."""
LEFT_OUT_STATUS: Final = "rwt.channels-left-out"
"""The id of the warning that topics are left out (``max_channels``), withdrawn once
every topic is advertised again."""
_ASSET: Final = object()  # the group of a fetch asset response with a file's outcome


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

    def on_message(
        self, event: MessageEvent, subscriptions: list[int] | tuple[int, ...] | None = None
    ) -> None:
        """Queue ``event`` as message data for each of ``subscriptions``; never raises.

        ``subscriptions``: the channel's (None, the graph's call) or the one a
        latched message is replayed to. ``on_messages`` of one message.
        """
        self.on_messages((event,), subscriptions)

    def on_messages(
        self,
        events: list[MessageEvent] | tuple[MessageEvent, ...],
        subscriptions: list[int] | tuple[int, ...] | None = None,
    ) -> None:
        """Queue each of ``events``, in order, as message data for ``subscriptions``; never raises.

        The graph's batched delivery gives a turn's run of a topic's messages
        in one call (``rwt_protocol.ports.BatchSink``). The payload is the
        message as it arrived where the graph has that (``MessageEvent.wire``:
        a link's CDR, a bag's record), else serialized once per message for
        every Foxglove client (``MessageEvent.encoded``); the log time is when
        the graph received it, on the bag's clock while a bag plays
        (``servertime``). With the ``foxglove-shared-frames`` shortcut the whole
        frame (header and payload) is made once per message, subscription id
        and log time, and every client subscribed with that id queues the same
        one (in ``event.memos``). Here, not in the session, and in one body:
        two Python calls less per message of a burst.
        """
        session, channel = self._session, self._channel
        if subscriptions is None:
            subscriptions = channel.subscriptions
        if session._closed or not subscriptions:
            return
        clock = session._time
        now = None if clock is None else clock.now()
        push = session._queue.push
        share = session._share
        if now is not None:  # on the bag's clock, told first (a client reads time from it)
            session._told_time(now)
        try:  # fails for the first frame or none: a message's frames share payload and time
            for event in events:
                payload = event.wire  # as it came (a link's CDR, a bag's record): no call
                if payload is None:
                    payload = session._payload(channel, event)
                log_time = int(event.stamp * 1e9) if now is None else now
                memos = event.memos if share else {}  # the shortcut off: one for each
                for sid in subscriptions:  # (not a comprehension: its closure costs a call)
                    # made once per message, subscription id and log time (which a bag's
                    # could move); keyed by the id itself: the keys of ``MessageEvent.memos``
                    # that are not these frames' are strings or start with one
                    key = sid if now is None else (sid, now)
                    frame = memos.get(key)
                    if frame is None:  # positional: keywords to a class cost a dict per call
                        frame = memos[key] = OutFrame(
                            payload, True, True, None, None, encode_message_header(sid, log_time)
                        )
                    if push(frame):  # type: ignore[arg-type]
                        session._tell_dropping()
        except Exception as exc:  # a type rosbags cannot write
            session._encode_failed(channel, exc)
        if session._on_output is not None:
            session._on_output()


class FoxgloveSession:
    """The Foxglove protocol for one client on the graph.

    Args:
        graph: the graph's core (``Graph.port``), which subscriptions and
            client publishers go through on behalf of ``client_id``.
        client_id: this connection's identity in the graph.
        session_id: sent in ``serverInfo`` (clients tell a restarted server by it).
        access: which topics, services and parameters this client may use
            (``--topics-glob``, ``--services-glob``, ``--params-glob``).
        limits: this client's bounds.
        params: the graph's parameters (``Graph.params``); None: the
            ``parameters`` capabilities are not announced.
        on_output: called when frames were queued while nobody asked (a graph
            message); the driver wakes its writer.
        name: the server's name in ``serverInfo``.
        assets: answer ``fetchAsset`` (the driver reads the files,
            ``assetrequests``); False: the op is refused and not announced.
    """

    def __init__(
        self,
        graph: GraphFront,
        client_id: str,
        *,
        session_id: str,
        access: AccessPolicy | None = None,
        limits: FoxgloveLimits | None = None,
        on_output: Callable[[], None] | None = None,
        name: str = "rwt",
        params: Parameters | None = None,
        assets: bool = False,
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
        self._tracked: dict[int, OutFrame] = {}  # id -> frame of ``tracked`` not yet taken
        self._unadvertised = 0  # topics left out by ``max_channels`` at the last sync
        self._dropping = False  # the client was told its data is being dropped
        self._closed = False
        # ``foxglove-shared-frames`` (rwt_protocol/shortcuts.py): off, each client makes its own
        self._share = enabled("foxglove-shared-frames")
        dialect = graph.registry.dialect
        self._wire = wire_encoding(dialect)
        self.services = ServiceCalls(graph, client_id, self, self._access, self.limits)
        self.graph_updates = ConnectionGraph(graph, self, self._access)
        self.params = (
            None
            if params is None
            else ParameterBridge(graph, params, self, self._access, self.limits)
        )
        capabilities = list(CAPABILITIES)
        if params is not None:
            capabilities += PARAMETER_CAPABILITIES
        # a bag playing when the client connects: its clock is server time
        self._time = None if graph.timeline is None else ServerTime(graph)
        # that clock a player's (not sim time): the client's playback bar drives it
        playback = graph.playback
        self._playback = None if playback is None else PlaybackControl(playback)
        self._assets = AssetRequests() if assets else None
        capabilities += [TIME_CAPABILITY] if self._time else []
        capabilities += [PLAYBACK_CAPABILITY] if self._playback else []
        capabilities += [ASSETS_CAPABILITY] if assets else []
        first, last = (None, None) if self._playback is None else self._playback.time_range()
        self._control(
            ServerInfo(
                name=name,
                capabilities=capabilities,
                supportedEncodings=supported_encodings(dialect),
                metadata=metadata_for(dialect),
                sessionId=session_id,
                dataStartTime=first,
                dataEndTime=last,
            )
        )
        self._handlers: dict[type, Callable[[Any], None]] = {
            Subscribe: self._subscribe,
            Unsubscribe: self._unsubscribe,
            ClientAdvertise: self._client_advertise,
            ClientUnadvertise: self._client_unadvertise,
            SubscribeConnectionGraph: lambda op: self.graph_updates.subscribe(),
            UnsubscribeConnectionGraph: lambda op: self.graph_updates.unsubscribe(),
            GetParameters: self._parameters,
            SetParameters: self._parameters,
            SubscribeParameterUpdates: self._parameters,
            UnsubscribeParameterUpdates: self._parameters,
            FetchAsset: self._fetch_asset,
        }
        self.tick()
        self.sync()

    # ---- outputs ------------------------------------------------------------------

    def take(self, max_bytes: int | None = None) -> list[OutFrame]:
        """Take the frames to send, oldest first (about ``max_bytes``; the limits' batch).

        Updates merged while an earlier one waited are queued once it is taken.
        """
        frames = self._queue.take(self.limits.batch_bytes if max_bytes is None else max_bytes)
        if self._dropping and not self._queue.episode_drops:  # the episode is over
            self._dropping = False
            self._control(RemoveStatus(statusIds=[DROPPING_STATUS]))
        if self._assets is not None and self._assets.queued:
            self._assets.queued -= sum(frame.group is _ASSET for frame in frames)
        if self._tracked:
            for frame in frames:
                self._tracked.pop(id(frame), None)
            if self.params is not None:
                self.params.flush()
        return frames

    @property
    def queued_bytes(self) -> int:
        """Bytes of message data waiting to be taken."""
        return self._queue.data_bytes

    @property
    def queue(self) -> OutQueue:
        """The frames waiting to be taken (``data_bytes`` read per message: no property call)."""
        return self._queue

    @property
    def queued_messages(self) -> int:
        """Messages of data waiting to be taken."""
        return self._queue.data_count

    @property
    def dropped(self) -> int:
        """Message data frames dropped for this client so far (it read too slowly)."""
        return self._queue.dropped

    def _control(self, op: ServerOp) -> None:
        self._queue.push(OutFrame(encode_op(op)))

    # ---- SessionOutput: what the services, parameters and graph parts send --------

    def control(self, op: ServerOp) -> None:
        """Queue a server op that is never dropped."""
        self._control(op)
        self._wake()

    def answer(self, data: bytes, *, binary: bool) -> None:
        """Queue an answer to the client's input (dropped like data if it reads too slowly)."""
        self._push_data(OutFrame(data, binary, True))
        self._wake()

    def error(self, message: str) -> None:
        """Queue an error ``status``."""
        self._status(StatusLevel.ERROR, message)
        self._wake()

    def tracked(self, op: ServerOp) -> OutFrame:
        """Queue ``op`` (never dropped); ``unsent`` tells when it left the queue."""
        frame = OutFrame(encode_op(op))
        self._tracked[id(frame)] = frame
        self._queue.push(frame)
        self._wake()
        return frame

    def unsent(self, frame: OutFrame) -> bool:
        """Whether ``frame`` (from ``tracked``) still waits in the queue."""
        return self._tracked.get(id(frame)) is frame

    def _wake(self) -> None:
        if self._on_output is not None:
            self._on_output()

    def _status(self, level: StatusLevel, message: str, status_id: str | None = None) -> None:
        # An answer to the client's input may be dropped like data: a client that
        # sends bad frames and reads nothing cannot grow the queue without bound.
        status = Status(level=int(level), message=message, id=status_id)
        frame = OutFrame(encode_op(status), droppable=True)
        self._push_data(frame)

    @property
    def announces_time(self) -> bool:
        """Whether this client was told of server time (``tick`` then sends it).

        Always so with ``playbackControl``: a player's clock is the graph's timeline.
        """
        return self._time is not None

    def tick(self) -> None:
        """Tell the client what changed since last told; never raises.

        The server time if it moved (``servertime``), then the playback state if
        it changed (``playback``).
        """
        if self._time is None or self._closed:
            return
        now = self._time.now()
        told = now is not None and self._told_time(now)
        state = None if self._playback is None else self._playback.frame()
        if state is not None:  # droppable as time frames are
            self._push_data(OutFrame(state, True, True))
        if (told or state is not None) and self._on_output is not None:
            self._on_output()

    def _told_time(self, now: int) -> bool:
        frame = None if self._time is None else self._time.frame(now)
        if frame is not None:  # droppable: a client that reads nothing cannot grow the queue
            self._push_data(OutFrame(frame, True, True))
        return frame is not None

    def _push_data(self, frame: OutFrame) -> None:
        if self._queue.push(frame):
            self._tell_dropping()

    def _tell_dropping(self) -> None:
        """A push began an episode of drops (``OutQueue.push``): warn the client once."""
        self._dropping = True
        logger.warning(
            "event=slow_consumer client=%s protocol=foxglove dropped_total=%d",
            self._client_id,
            self._queue.dropped,
        )
        self._queue.push(
            OutFrame(
                encode_op(
                    Status(
                        level=int(StatusLevel.WARNING),
                        message="messages dropped: this client reads slower than they "
                        "arrive (the oldest go first)",
                        id=DROPPING_STATUS,
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
                frame = parse_binary(data)
                if isinstance(frame, ServiceCallRequest):
                    self.services.call(frame)
                elif isinstance(frame, PlaybackControlRequest):
                    self._playback_request(frame)
                else:
                    self._message_data(frame)
                return
            op = parse_text(data)
            self._handlers[type(op)](op)
        except RwtError as exc:
            self._status(StatusLevel.ERROR, exc.message)

    def _playback_request(self, request: PlaybackControlRequest) -> None:
        if self._playback is None:  # as the SDK's server: an error status
            raise FoxgloveInputError("playback control is not supported by this server")
        # an answer to input: droppable, so a client that floods and reads nothing stays bounded
        self._push_data(OutFrame(self._playback.apply(request), True, True))

    def _parameters(
        self,
        op: GetParameters | SetParameters | SubscribeParameterUpdates | UnsubscribeParameterUpdates,
    ) -> None:
        if self.params is None:
            raise FoxgloveInputError("parameters are not supported by this server")
        self.params.handle(op)

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
            latched = self._graph.latched(channel.topic)
            if latched is not None:
                _TopicSink(self, channel).on_message(latched, (sid,))
            return
        try:  # the graph hands the latched message to the new sink at once (D13)
            sink = _TopicSink(self, channel)
            self._graph.subscribe(self._client_id, channel.topic, channel.mtype.name, sink)
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
        type_name = self._graph.advertise(self._client_id, topic, spec.schemaName)
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

    # ---- assets (assetrequests) ----------------------------------------------------

    def _fetch_asset(self, op: FetchAsset) -> None:
        if self._assets is None:
            raise FoxgloveInputError("op 'fetchAsset' is not supported by this server")
        if not self._assets.add(op):  # droppable: a client that reads nothing stays bounded
            error = f"more than {MAX_PENDING_ASSETS} asset requests wait: ask again later"
            self._push_data(
                OutFrame(encode_fetch_asset_response(op.requestId, None, error), True, True)
            )

    def next_asset_request(self) -> FetchAsset | None:
        """The oldest ``fetchAsset`` to read, once the client took the last response."""
        if self._assets is None or self._assets.queued or self._closed:
            return None
        return self._assets.next()

    def asset_fetched(self, request_id: int, data: bytes | None, error: str = "") -> None:
        """Queue the response to ``request_id``: ``data``, or with None the ``error`` text."""
        if self._assets is None or self._closed:
            return
        frame = encode_fetch_asset_response(request_id, data, error)
        self._assets.queued += 1
        self._queue.push(OutFrame(frame, binary=True, group=_ASSET))

    @property
    def assets_queued(self) -> bool:
        """Whether a response with a file's outcome waits in the queue (the driver waits)."""
        return self._assets is not None and self._assets.queued > 0

    def _message_data(self, op: ClientMessageData) -> None:
        channel = self._client_channels.get(op.channel_id)
        if channel is None:
            raise FoxgloveInputError(f"message data on unknown client channel {op.channel_id}")
        if channel.encoding == JSON:
            value = decode_json_text(bytes(op.payload), "message")
            self._graph.publish(self._client_id, channel.topic, value)
            return
        data = bytes(op.payload)
        self._graph.publish_serialized(self._client_id, channel.topic, data, encoding=self._wire)

    # ---- the graph ----------------------------------------------------------------

    def sync(self, now: float = 0.0) -> None:
        """Bring the client up to date with the graph.

        Advertise the topics and services that appeared, unadvertise those gone
        (or retyped), send the connection graph's changes to a client that
        follows it, and fail service calls older than ``call_timeout_s``. A
        channel is a topic with a publisher that this client may see. Costs one
        pass over the graph's topics and services.

        Args:
            now: seconds on the driver's monotonic clock (service call timeouts).
        """
        if self._closed:
            return
        self._sync_channels()
        self.services.sync(now)
        self.graph_updates.sync()

    def _sync_channels(self) -> None:
        registry, visible = self._graph.registry, Visibility.of(self._access)
        current = {
            change.name: registry.message(change.type_name)
            for change in self._graph.feed.snapshot()[1]
            if change.kind == "publisher" and visible.sees(change)
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
        room = self.limits.max_channels - len(self._channels)
        left_out = 0
        for topic, mtype in current.items():
            if topic in self._channels:
                continue
            if len(added) >= room:
                left_out += 1
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
        told = self._tell_left_out(left_out)
        if (gone or added or told) and self._on_output is not None:
            self._on_output()

    def _tell_left_out(self, left_out: int) -> bool:
        """A warning when topics begin to be left out (``max_channels``); once per episode."""
        before, self._unadvertised = self._unadvertised, left_out
        if before and not left_out:  # every topic advertised again
            self._control(RemoveStatus(statusIds=[LEFT_OUT_STATUS]))
            return True
        if not left_out or before:
            return False
        self._status(
            StatusLevel.WARNING,
            f"{left_out} topics are not advertised: this server advertises at most "
            f"{self.limits.max_channels} channels to a client",
            status_id=LEFT_OUT_STATUS,
        )
        return True

    def _drop_channel(self, channel: _ServerChannel) -> None:
        del self._channels[channel.topic]
        del self._by_id[channel.id]
        if channel.subscriptions:
            for sid in channel.subscriptions:
                del self._subscriptions[sid]
            channel.subscriptions.clear()
            self._graph.unsubscribe(self._client_id, channel.topic)

    def _encode_failed(self, channel: _ServerChannel, exc: Exception) -> None:
        """Say once per topic that its messages cannot be encoded (``_TopicSink.on_messages``)."""
        if channel.topic not in self._failed_topics:
            self._failed_topics.add(channel.topic)
            logger.warning("event=encode_failed topic=%s reason=%r", channel.topic, str(exc))
            self._status(StatusLevel.ERROR, f"{channel.topic}: cannot encode its messages")

    def _payload(self, channel: _ServerChannel, event: MessageEvent) -> bytes:
        """``event``'s message data payload, shared by every client (``_TopicSink.on_messages``).

        Raises:
            Exception: the message cannot be serialized (any error of rosbags).
        """
        payload = event.wire
        if payload is None:
            payload = event.encoded(_WIRE_KEY, lambda: self._serialize(channel.mtype, event))
        return payload

    def _serialize(self, mtype: MessageType, event: MessageEvent) -> bytes:
        codec = event.codec or codec_for(self._graph.registry, mtype)
        return bytes(codec.serialize(event.msg))

    def close(self) -> None:
        """The connection is gone: release its subscriptions and publishers. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self.services.close()
        if self.params is not None:
            self.params.close()
        logger.info(
            "event=foxglove_closed client=%s dropped=%d queue_peak_bytes=%d",
            self._client_id,
            self._queue.dropped,
            self._queue.peak_bytes,
        )
        self._graph.release(self._client_id)
        self._subscriptions.clear()
        self._client_channels.clear()
