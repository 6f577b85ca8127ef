"""One Foxglove client's session on the graph, without I/O (docs/foxglove.md).

A ``SessionBase`` like rosbridge's ``Session``: the server's one connection
runtime (``rwt_transports.pump``) hands it each received frame
(``receive_frame``), runs its timers (server time, service call deadlines, the
announcement of what changed in the graph) and its background jobs (asset files
read off the event loop), and sends what ``frames_to_send`` gives; it is bound
by the same per-client rules (``ClientRules``: the send buffer and its
slow-consumer rule, subscriptions, calls in flight, the idle timeout), plus the
Foxglove section (``FoxgloveLimits``). Graph messages reach it
through one ``TopicSink`` per subscribed topic, which only queues (a slow client
never slows a publisher or another client: its outbox drops its oldest data).
What topics and services there are it learns from the graph's change feed
(``graphindex.GraphIndex``): nothing walks the graph but once, at the start; a
change marks its name, and the names marked are announced in a turn of the loop,
at most ``FoxgloveLimits.advertise_batch`` channels a frame, the next once the
client took the last (a client new to thousands of topics gets them in bounded
frames, one that reads nothing holds one).

What maps to what: a server channel is a topic of the graph that has a
publisher (and that the access globs let this client subscribe to, D50); a
subscription is a graph subscription of this client id; a client channel is a
graph publisher of this client id. Services, parameters and the connection graph are parts of
their own (``services``, ``params``, ``conngraph``), which send through the
session (``output.SessionOutput``). Every bad input is answered with an error
``status`` and the session goes on.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Final

from rwt_graph.feed import EntityKind
from rwt_graph.types.registry import codec_for
from rwt_graph.visibility import Visibility
from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import RemoteProtocolError, RwtError
from rwt_protocol.levels import StatusLevel as Level
from rwt_protocol.names import name_problem, resolve_name
from rwt_protocol.runtime.access import Family, TopicUse
from rwt_protocol.runtime.backpressure import lost_text
from rwt_protocol.runtime.connection import SessionBase
from rwt_protocol.runtime.outbox import OutFrame
from rwt_protocol.runtime.rules import ClientRules
from rwt_protocol.shortcuts import enabled

from .assetrequests import ASSETS_CAPABILITY, MAX_PENDING_ASSETS, AssetJob, AssetRequests
from .conngraph import ConnectionGraph
from .graphindex import GraphIndex
from .limits import FoxgloveLimits
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
from .servertime import TIME_CAPABILITY, TIME_INTERVAL_S, ServerTime
from .services import ServiceCalls

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.feed import GraphChange
    from rwt_graph.parameters.store import Parameters
    from rwt_graph.port import GraphFront
    from rwt_graph.types import MessageType
    from rwt_protocol.ports import MessageEvent, PublishNote
    from rwt_protocol.qos import QosProfile
    from rwt_protocol.runtime.jobs import Job
    from rwt_protocol.runtime.memory import MemoryBudget
    from rwt_protocol.runtime.timers import Timer

    from .assetrequests import AssetReader

__all__ = [
    "CAPABILITIES",
    "PARAMETER_CAPABILITIES",
    "FoxgloveLimits",
    "FoxgloveSession",
]

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
withdrawn (``removeStatus``) once it caught up (the slow-consumer rule's episode ends)."""
_LEVELS: Final = {Level.ERROR: StatusLevel.ERROR, Level.WARNING: StatusLevel.WARNING}
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


_NO_END: Final = math.inf
"""A run of messages without an end (D63): ``queue_run``'s ``expires`` default."""


class _TopicSink:
    """The graph's subscriber of one topic for this client: queues message data."""

    __slots__ = ("_channel", "_ends", "_session")

    def __init__(self, session: FoxgloveSession, channel: _ServerChannel) -> None:
        self._session = session
        self._channel = channel
        self._ends = False  # the topic's offer gives its messages an end (D63)

    def on_qos_offered(
        self, offered: QosProfile | None, reasons: list[str], latest: Callable[[], float]
    ) -> None:
        """The topic's QoS (``rwt_graph.topic_qos``): whether its messages have an end (D63).

        A topic whose offer has no lifespan, and one without QoS (never told),
        queue their runs without looking at each message's end.
        """
        self._ends = offered is not None and offered.lifespan_s != math.inf

    def on_message(
        self, event: MessageEvent, subscriptions: list[int] | tuple[int, ...] | None = None
    ) -> None:
        """Queue ``event`` as message data for each of ``subscriptions``; never raises.

        ``subscriptions``: the channel's (None, the graph's call) or the one a
        latched message is replayed to. ``on_messages`` of one message.
        """
        self.on_messages((event,), subscriptions)

    def on_lost(self, count: int) -> None:
        """``count`` messages were lost before they reached the server (``LossSink``, D61)."""
        self._session.report(Level.WARNING, lost_text(count, self._channel.topic))

    def on_messages(
        self,
        events: list[MessageEvent] | tuple[MessageEvent, ...],
        subscriptions: list[int] | tuple[int, ...] | None = None,
        end: float | None = None,
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
        two Python calls less per message of a burst. Messages with a lifespan
        (their topic's, or ``--qos-lifespan``) come back here in runs of one
        ``end`` (``SessionBase.message_end``, D63; ``math.inf``: none): never sent
        after it. None: not yet split into such runs.
        """
        session, channel = self._session, self._channel
        if end is None:
            if self._ends or not session._timeless:
                self._by_end(events, subscriptions)
                return
            end = _NO_END
        if subscriptions is None:
            subscriptions = channel.subscriptions
        if not subscriptions:
            return
        clock = session._time
        now = None if clock is None else clock.now()
        share = session._share
        # on the bag's clock, told first (a client reads time from it)
        time_frame = None if now is None else session._time_frame(now)
        run: list[OutFrame] = [] if time_frame is None else [time_frame]
        append = run.append
        try:  # fails for the first frame or none: a message's frames share payload and time
            for event in events:
                memos = event.memos if share else {}  # the shortcut off: one for each
                for sid in subscriptions:  # (not a comprehension: its closure costs a call)
                    # made once per message, subscription id and log time (which a bag's
                    # could move); keyed by the id itself: the keys of ``MessageEvent.memos``
                    # that are not these frames' are strings or start with one
                    key = sid if now is None else (sid, now)
                    frame: OutFrame | None = memos.get(key)  # type: ignore[assignment]
                    if frame is None:  # the payload only then: every other client shares it
                        payload = event.wire  # as it came (a link's CDR, a bag's record)
                        if payload is None:
                            payload = session._payload(channel, event)
                        log_time = int(event.stamp * 1e9) if now is None else now
                        # positional: keywords to a class cost a dict per call
                        frame = memos[key] = OutFrame(
                            payload, True, True, None, None, encode_message_header(sid, log_time)
                        )
                    append(frame)
        except Exception as exc:  # a type rosbags cannot write
            session._encode_failed(channel, exc)
        if end == _NO_END:  # (fewer arguments: a call per client and batch)
            session.queue_run(run, channel.topic, events[-1].now)
        else:
            session.queue_run(run, channel.topic, events[-1].now, 0.0, end)

    def _by_end(
        self,
        events: list[MessageEvent] | tuple[MessageEvent, ...],
        subscriptions: list[int] | tuple[int, ...] | None,
    ) -> None:
        """``on_messages`` of ``events`` in runs of one end each (D63), in order."""
        session = self._session
        timeless = session._timeless  # the end the topic's offer gave, else the earlier
        ends = [event.expires if timeless else session.message_end(event) for event in events]
        start = 0
        for i in range(1, len(events) + 1):
            if i == len(events) or ends[i] != ends[start]:
                self.on_messages(events[start:i], subscriptions, ends[start])
                start = i


class FoxgloveSession(SessionBase):
    """The Foxglove protocol for one client on the graph.

    Args:
        graph: the graph's core (``Graph.port``), which subscriptions and
            client publishers go through on behalf of ``client_id``.
        client_id: this connection's identity in the graph.
        session_id: sent in ``serverInfo`` (clients tell a restarted server by it).
        config: the per-client rules every protocol shares (``ClientRules``: the
            access globs, ``--send-buffer-limit``, ``--send-timeout``,
            ``--max-subscriptions``, ``--max-pending-calls``, ``--call-timeout``,
            ``--idle-timeout``, ``--hold-budget``).
        limits: the Foxglove section of its bounds.
        on_output: called when frames, commands or a timer were queued; the
            transport wakes its writer.
        peer: the client's address, for logs.
        on_closed: called once with ``client_id`` when the session closes.
        name: the server's name in ``serverInfo``.
        params: the graph's parameters (``Graph.params``); None: the
            ``parameters`` capabilities are not announced.
        assets: reads the files clients ask for (``assets.AssetRoots``), in
            background jobs; None: ``fetchAsset`` is refused and not announced.
        show_plumbing: list rwt's own helpers too (rosapi's services, the client
            counts, the TF republisher) and their nodes (``Visibility.plumbing``;
            ``rwt serve --foxglove-show-plumbing``); other connections' entities
            and nodes show either way (D47).
        memory: the server's memory budget (``--memory-budget``, D44) the client's
            queue and asset files are charged to; while it is full, asset
            requests are refused. None: its own bounds alone.
    """

    protocol = "foxglove"
    wakes_each_run = True  # its bursts gathered into few writes (``SessionBase.queue_run``)

    def __init__(
        self,
        graph: GraphFront,
        client_id: str,
        *,
        session_id: str,
        config: ClientRules | None = None,
        limits: FoxgloveLimits | None = None,
        on_output: Callable[[], None] | None = None,
        peer: str = "",
        on_closed: Callable[[str], None] | None = None,
        name: str = "rwt",
        params: Parameters | None = None,
        assets: AssetReader | None = None,
        show_plumbing: bool = False,
        memory: MemoryBudget | None = None,
    ) -> None:
        config = config or ClientRules()
        self.limits = limits or FoxgloveLimits()
        super().__init__(
            graph,
            client_id,
            config=config,
            on_output=on_output,
            peer=peer,
            on_closed=on_closed,
            max_messages=self.limits.max_queue_messages,
            memory=memory,
        )
        self._graph: GraphFront = graph
        self._access = config.access
        self._ids = itertools.count(1)
        self._channels: dict[str, _ServerChannel] = {}  # topic -> channel
        self._by_id: dict[int, _ServerChannel] = {}
        self._subscriptions: dict[int, _ServerChannel] = {}
        self._client_channels: dict[int, _ClientChannel] = {}
        self._failed_topics: set[str] = set()  # told once that their data cannot be encoded
        self._tracked: dict[int, OutFrame] = {}  # id -> frame of ``tracked`` not yet taken
        self._unadvertised = 0  # topics left out by ``max_channels`` when last told
        self._left_out: dict[str, None] = {}  # topics with a publisher and no channel (cap)
        self._announce_timer: Timer | None = None
        self._advertised: OutFrame | None = None  # the last advertise batch, while it waits
        self._tick_timer: Timer | None = None
        # ``foxglove-shared-frames`` (rwt_protocol/shortcuts.py): off, each client makes its own
        self._share = enabled("foxglove-shared-frames")
        self._timeless = self.config.qos_lifespan_s == math.inf  # no --qos-lifespan (D63)
        dialect = graph.registry.dialect
        self._wire = wire_encoding(dialect)
        # what the client sees of the graph: the feed's snapshot, then each change
        visibility = replace(Visibility.of(self._access), plumbing=show_plumbing)
        self._index = GraphIndex(graph.feed, visibility)
        self._dirty: dict[str, None] = dict.fromkeys(self._index.names(EntityKind.PUBLISHER))
        self._stop_feed = graph.feed.listen(self._changed)
        self.services = ServiceCalls(
            graph,
            client_id,
            self,
            self._index,
            self.calls,
            self.limits.advertise_batch,
        )
        self.graph_updates = ConnectionGraph(self._index, self)
        self.params = (
            None
            if params is None
            else ParameterBridge(graph, params, self, self._access, self.limits, client_id)
        )
        # a bag playing when the client connects: its clock is server time
        self._time = None if graph.timeline is None else ServerTime(graph)
        # that clock a player's (not sim time): the client's playback bar drives it
        playback = graph.playback
        self._playback = None if playback is None else PlaybackControl(playback)
        self._reader = assets
        self._assets = AssetRequests() if assets is not None else None
        self._hello(name, session_id)
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

    def _hello(self, name: str, session_id: str) -> None:
        """Queue ``serverInfo``: the capabilities this client gets."""
        dialect = self._graph.registry.dialect
        capabilities = list(CAPABILITIES)
        capabilities += PARAMETER_CAPABILITIES if self.params is not None else []
        capabilities += [TIME_CAPABILITY] if self._time else []
        capabilities += [PLAYBACK_CAPABILITY] if self._playback else []
        capabilities += [ASSETS_CAPABILITY] if self._assets is not None else []
        first, last = (None, None) if self._playback is None else self._playback.time_range()
        self.control(
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

    # ---- the connection runtime's side ---------------------------------------------

    def start(self, now: float) -> None:
        """The transport serves the client from ``now``: the graph and the clock are watched."""
        super().start(now)
        if self._time is not None:
            self._tick_timer = self.call_at(now + TIME_INTERVAL_S, self._on_tick)

    def _on_tick(self, now: float) -> None:
        self.tick()
        self._tick_timer = self.call_at(now + TIME_INTERVAL_S, self._on_tick)

    def status_frames(
        self, level: Level, text: str, op_id: str | int | None = None
    ) -> tuple[OutFrame, ...]:
        """An error or warning ``status`` for the client (info and debug are not sent)."""
        foxglove_level = _LEVELS.get(level)
        if foxglove_level is None:
            return ()
        return (OutFrame(encode_op(Status(level=int(foxglove_level), message=text))),)

    def holds_anything(self) -> bool:
        """Whether the client subscribes, publishes, waits for calls or follows updates."""
        return bool(
            self._subscriptions
            or self._client_channels
            or self.services.in_flight
            or self.graph_updates.subscribed
            or (self.params is not None and self.params.watching)
            or (self._assets is not None and (self._assets.reading or self._assets.queued))
        )

    def warn_dropping(self, text: str) -> None:
        """The slow-consumer rule dropped data: one warning ``status``, with its id."""
        self.control(
            Status(
                level=int(StatusLevel.WARNING),
                message="messages dropped: this client reads slower than they arrive "
                "(the oldest go first)",
                id=DROPPING_STATUS,
            )
        )

    def dropping_over(self) -> None:
        """The client caught up: its warning is withdrawn."""
        self.control(RemoveStatus(statusIds=[DROPPING_STATUS]))

    def taken(self, frames: list[OutFrame]) -> None:
        """Frames left the queue: tracked updates may be followed, the next file read."""
        assets = self._assets
        if assets is not None and assets.queued:
            assets.queued -= sum(frame.group is _ASSET for frame in frames)
            if not assets.queued:
                self._read_next_asset()
        if self._tracked:
            for frame in frames:
                self._tracked.pop(id(frame), None)
            if self.params is not None:
                self.params.flush()
            if self._dirty or self.services.waiting or self.graph_updates.subscribed:
                self._announce_soon()  # the next batch, or the changes since the last update

    @property
    def queued_messages(self) -> int:
        """Topic messages (and time frames) waiting to be taken."""
        return self.outbox.topic_frames

    @property
    def dropped(self) -> int:
        """Message data frames dropped for this client so far (it read too slowly)."""
        return self.outbox.dropped

    # ---- SessionOutput: what the services, parameters and graph parts send --------

    def control(self, op: ServerOp) -> None:
        """Queue a server op that is never dropped."""
        self.send_frames((OutFrame(encode_op(op)),))

    def answer(self, data: bytes, *, binary: bool) -> None:
        """Queue an answer to the client's input, never dropped (the client pays for it)."""
        self.send_frames((OutFrame(data, binary),))

    def error(self, message: str) -> None:
        """Queue an error ``status``."""
        self._status(StatusLevel.ERROR, message)

    def tracked(self, op: ServerOp) -> OutFrame:
        """Queue ``op`` (never dropped); ``unsent`` tells when it left the queue."""
        frame = OutFrame(encode_op(op))
        self._tracked[id(frame)] = frame
        self.send_frames((frame,))
        return frame

    def unsent(self, frame: OutFrame) -> bool:
        """Whether ``frame`` (from ``tracked``) still waits in the queue."""
        return self._tracked.get(id(frame)) is frame

    def _status(self, level: StatusLevel, message: str, status_id: str | None = None) -> None:
        status = Status(level=int(level), message=message, id=status_id)
        self.send_frames((OutFrame(encode_op(status)),))

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
        if self._time is None or not self._state.sends:
            return
        now = self._time.now()
        told = None if now is None else self._time_frame(now)
        state = None if self._playback is None else self._playback.frame()
        run = [] if told is None else [told]
        if state is not None:  # droppable as time frames are
            run.append(OutFrame(state, True, True))
        self.queue_run(run, None, self._now)

    def _time_frame(self, now: int) -> OutFrame | None:
        """The server time frame of ``now`` (ns) if it moved since told, else None.

        Droppable: a client that reads nothing cannot grow the queue with them.
        """
        frame = None if self._time is None else self._time.frame(now)
        return None if frame is None else OutFrame(frame, True, True)

    # ---- input --------------------------------------------------------------------

    def handle_frame(self, frame: bytes | str, now: float, binary: bool) -> None:
        """Handle one frame of the client; its answers are queued (``frames_to_send``).

        ``receive_frame`` (``SessionBase``) calls it while the session takes input.
        Each problem with what the client sent is an error ``status``; a bug in a
        handler is contained (``contain``: ``internal error``) and the session
        goes on, as rosbridge's does.
        """
        data = frame.encode() if isinstance(frame, str) else frame
        try:
            if binary:
                request = parse_binary(data)
                if isinstance(request, ServiceCallRequest):
                    self.services.call(request)
                elif isinstance(request, PlaybackControlRequest):
                    self._playback_request(request)
                else:
                    self._message_data(request)
                return
            op = parse_text(data)
            self._handlers[type(op)](op)
        except RwtError as exc:
            self._status(StatusLevel.ERROR, exc.message)

    def _playback_request(self, request: PlaybackControlRequest) -> None:
        if self._playback is None:  # as the SDK's server: an error status
            raise FoxgloveInputError("playback control is not supported by this server")
        self.answer(self._playback.apply(request), binary=True)

    def _parameters(
        self,
        op: GetParameters | SetParameters | SubscribeParameterUpdates | UnsubscribeParameterUpdates,
    ) -> None:
        if self.params is None:
            raise FoxgloveInputError("parameters are not supported by this server")
        self.params.handle(op)

    def _subscribe(self, op: Subscribe) -> None:
        problems = _Problems("subscribe")
        for each in op.subscriptions:
            try:
                self._subscribe_one(each.id, each.channelId)
            except RwtError as exc:
                problems.add(exc.message)
        problems.report(self)

    def _subscribe_one(self, sid: int, channel_id: int) -> None:
        if sid in self._subscriptions:
            raise FoxgloveInputError(f"subscription id {sid} is in use")
        channel = self._by_id.get(channel_id)
        if channel is None:
            raise FoxgloveInputError(f"unknown channel {channel_id}")
        self.require_access(Family.TOPICS, channel.topic, "subscribe", TopicUse.SUBSCRIBE)
        if channel.subscriptions:  # one subscription per channel, as the SDK's server
            first = channel.subscriptions[0]
            raise FoxgloveInputError(
                f"channel {channel_id} is subscribed already (subscription {first})"
            )
        cap = self._config.max_subscriptions
        if len(self._subscriptions) >= cap:
            raise FoxgloveInputError(f"more than {cap} subscriptions (--max-subscriptions)")
        self._subscriptions[sid] = channel
        channel.subscriptions.append(sid)
        try:  # the graph hands the latched message to the new sink at once (D13)
            sink = _TopicSink(self, channel)
            self._graph.subscribe(self._client_id, channel.topic, channel.mtype.name, sink)
        except RwtError:
            channel.subscriptions.remove(sid)
            del self._subscriptions[sid]
            raise

    def _unsubscribe(self, op: Unsubscribe) -> None:
        unknown: list[int] = []
        for sid in op.subscriptionIds:
            channel = self._subscriptions.pop(sid, None)
            if channel is None:
                unknown.append(sid)
                continue
            channel.subscriptions.remove(sid)
            if not channel.subscriptions:
                self._graph.unsubscribe(self._client_id, channel.topic)
        if unknown:
            self._status(StatusLevel.ERROR, f"unsubscribe: {_ids('unknown subscription', unknown)}")

    def _client_advertise(self, op: ClientAdvertise) -> None:
        problems = _Problems("advertise")
        for channel in op.channels:
            try:
                self._advertise_one(channel)
            except RwtError as exc:
                problems.add(exc.message)
        problems.report(self)

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
        self.require_access(Family.TOPICS, topic, "advertise", TopicUse.PUBLISH)
        type_name = self._graph.advertise(self._client_id, topic, spec.schemaName)
        mtype = self._graph.registry.message(type_name)
        self._client_channels[spec.id] = _ClientChannel(spec.id, topic, mtype, spec.encoding)

    def _client_unadvertise(self, op: ClientUnadvertise) -> None:
        unknown: list[int] = []
        for cid in op.channelIds:
            channel = self._client_channels.pop(cid, None)
            if channel is None:
                unknown.append(cid)
                continue
            if all(other.topic != channel.topic for other in self._client_channels.values()):
                self._graph.unadvertise(self._client_id, channel.topic)
        if unknown:
            self._status(
                StatusLevel.ERROR, f"unadvertise: {_ids('unknown client channel', unknown)}"
            )

    # ---- assets (assetrequests) ----------------------------------------------------

    def _fetch_asset(self, op: FetchAsset) -> None:
        if self._assets is None:
            raise FoxgloveInputError("op 'fetchAsset' is not supported by this server")
        if not self._assets.add(op):
            error = f"more than {MAX_PENDING_ASSETS} asset requests wait: ask again later"
            self.answer(encode_fetch_asset_response(op.requestId, None, error), binary=True)
            return
        self._read_next_asset()

    def _read_next_asset(self) -> None:
        """Leave the oldest waiting request to a background job, one file at a time.

        While the server's memory budget is full (D44) the requests are answered
        with its refusal instead, without reading their files.
        """
        if self._assets is None or self._reader is None or not self._state.sends:
            return
        memory = self._memory
        while (request := self._assets.next()) is not None:
            if memory is None or not memory.budget.pressed:
                self._assets.reading = True
                self.add_job(AssetJob(self._reader, request), background=True)
                return
            error = memory.budget.refusal(request.uri)
            self.answer(encode_fetch_asset_response(request.requestId, None, error), binary=True)
        self.sweep_memory()

    def job_done(self, job: Job, result: object, now: float) -> None:
        """Queue the response to an asset job: its file, or the reason it has none.

        ``finish_job`` (``SessionBase``) calls it and contains what it raises.
        """
        if not isinstance(job, AssetJob):
            super().job_done(job, result, now)
            return
        if self._assets is None:
            return
        self._assets.reading = False
        if not self._state.sends:
            return
        request_id = job.request.requestId
        memory = self._memory
        if isinstance(result, bytes) and memory is not None and not memory.budget.fits(len(result)):
            result = RemoteProtocolError(memory.budget.refusal(job.request.uri))  # D44
        if isinstance(result, bytes):  # the header apart: the file's bytes are not copied
            header = encode_fetch_asset_response(request_id, b"")
            frame = OutFrame(result, True, False, _ASSET, None, header)
        else:
            if isinstance(result, RwtError):
                error = result.message
            else:
                logger.error(
                    "event=bug client=%s asset read failed",
                    self._client_id,
                    exc_info=result if isinstance(result, BaseException) else None,
                )
                error = "internal error"
            frame = OutFrame(
                encode_fetch_asset_response(request_id, None, error), True, False, _ASSET
            )
        self._assets.queued += 1
        self.send_frames((frame,))

    def _message_data(self, op: ClientMessageData) -> None:
        channel = self._client_channels.get(op.channel_id)
        if channel is None:
            raise FoxgloveInputError(f"message data on unknown client channel {op.channel_id}")
        if channel.encoding == JSON:
            value = decode_json_text(bytes(op.payload), "message")
            self._graph.publish(self._client_id, channel.topic, value, notes=self._noted)
            return
        # checked by decoding it once; the client's bytes then go on as they are to every
        # subscriber that sends the wire form (Foxglove clients, cbor-raw)
        data = bytes(op.payload)
        self._graph.publish_serialized(
            self._client_id, channel.topic, data, encoding=self._wire, notes=self._noted
        )

    def _noted(self, note: PublishNote) -> None:
        """The safety envelope's clamp or drop: a warning status, once per episode (D67)."""
        if note.first:
            self._status(StatusLevel.WARNING, note.text)

    # ---- the graph ----------------------------------------------------------------

    def _changed(self, change: GraphChange) -> None:
        """A change of the graph's feed: mark what it touched, announce it in a loop turn.

        A listener of the feed must not change the graph, so the announcement
        (which may unsubscribe a channel that went) runs from a timer, at once.
        """
        if self.closed or not self._index.apply(change):
            return
        if change.kind is EntityKind.PUBLISHER:
            self._dirty[change.name] = None
        elif change.kind is EntityKind.SERVICE:
            self.services.touched(change.name)
        self.graph_updates.touched(change)
        self._announce_soon()

    def _announce_soon(self) -> None:
        if self._announce_timer is None and self._state.sends:
            self._announce_timer = self.call_at(self._now, self._announce)

    def _announce(self, now: float) -> None:
        self._announce_timer = None
        self.sync()

    def sync(self, now: float = 0.0) -> None:
        """Bring the client up to date with what changed in the graph.

        Advertise the topics and services that appeared, unadvertise those gone
        (or retyped), at most a batch at a time, and send the connection graph's
        changes to a client that follows it. A channel is a topic with a
        publisher that this client may see. Costs what the changes touched, not
        a pass over the graph.

        Args:
            now: unused; kept for callers that pass the time.
        """
        if not self._state.sends:
            return
        self._announce_channels()
        self.services.sync()
        self.graph_updates.sync()

    def _announce_channels(self) -> None:
        """(Un)advertise the topics marked, a batch of channels at most (module text)."""
        if not self._dirty or (self._advertised is not None and self.unsent(self._advertised)):
            return
        gone: list[int] = []
        added: list[Channel] = []
        while self._dirty and len(added) < self.limits.advertise_batch:
            topic = next(iter(self._dirty))
            del self._dirty[topic]
            type_name = self._index.type_of(EntityKind.PUBLISHER, topic)
            if not self._access.allows(Family.TOPICS, topic, TopicUse.SUBSCRIBE):
                type_name = None  # a channel is for subscribing: --topics-sub-glob (D50)
            channel = self._channels.get(topic)
            if channel is not None and channel.mtype.name != type_name:
                self._drop_channel(channel)
                gone.append(channel.id)
                channel = None
            if type_name is None:
                self._left_out.pop(topic, None)
            elif channel is None:
                if len(self._channels) >= self.limits.max_channels:
                    self._left_out[topic] = None
                    continue
                self._left_out.pop(topic, None)
                added.append(self._new_channel(topic, type_name))
        if gone:
            self.control(Unadvertise(channelIds=gone))
            for topic in list(self._left_out)[: len(gone)]:  # room again for the left out
                self._dirty[topic] = None
            if self._dirty:
                self._announce_soon()
        if added:
            self._advertised = self.tracked(Advertise(channels=added))
        self._tell_left_out(len(self._left_out))

    def _new_channel(self, topic: str, type_name: str) -> Channel:
        """Make the channel of ``topic`` and its advertisement."""
        mtype = self._graph.registry.message(type_name)
        channel = _ServerChannel(next(self._ids), topic, mtype)
        schema = schema_of(mtype)
        self._channels[topic] = channel
        self._by_id[channel.id] = channel
        return Channel(
            id=channel.id,
            topic=topic,
            encoding=schema.encoding,
            schemaName=schema.schema_name,
            schema=schema.schema,
            schemaEncoding=schema.schema_encoding,
        )

    def _tell_left_out(self, left_out: int) -> bool:
        """A warning when topics begin to be left out (``max_channels``); once per episode."""
        before, self._unadvertised = self._unadvertised, left_out
        if before and not left_out:  # every topic advertised again
            self.control(RemoveStatus(statusIds=[LEFT_OUT_STATUS]))
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
        if not self.closed:
            self._stop_feed()
            self.services.close()
            if self.params is not None:
                self.params.close()
            if self._assets is not None:
                self._assets.clear()
            logger.info(
                "event=foxglove_closed client=%s dropped=%d queue_peak_bytes=%d",
                self._client_id,
                self.outbox.dropped,
                self.outbox.peak_bytes,
            )
            self._subscriptions.clear()
            self._client_channels.clear()
        super().close()


class _Problems:
    """The refused entries of one list op, told in one ``status`` (not one each)."""

    __slots__ = ("_count", "_first", "_op")

    _SHOWN: Final = 3

    def __init__(self, op: str) -> None:
        self._op = op
        self._first: list[str] = []
        self._count = 0

    def add(self, message: str) -> None:
        self._count += 1
        if len(self._first) < self._SHOWN:
            self._first.append(message)

    def report(self, session: FoxgloveSession) -> None:
        if not self._count:
            return
        text = "; ".join(self._first)
        if self._count > len(self._first):
            text += f" (and {self._count - len(self._first)} more refused)"
        session.error(f"{self._op}: {text}")


def _ids(what: str, ids: list[int]) -> str:
    """``unknown subscription 7``, or ``3 unknown subscriptions: 7, 8, 9`` (five at most)."""
    if len(ids) == 1:
        return f"{what} {ids[0]}"
    shown = ", ".join(str(each) for each in ids[:5])
    more = f" and {len(ids) - 5} more" if len(ids) > 5 else ""
    return f"{len(ids)} {what}s: {shown}{more}"
