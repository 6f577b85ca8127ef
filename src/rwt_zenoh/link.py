"""The Zenoh link: one graph's entities mirrored to and from a Zenoh network.

A ``ZenohLink`` attaches to a ``Graph`` as its clients do, through the graph's
public API, and speaks rmw_zenoh's wire (``wire``, ``payload``):

- outward, every local publisher, subscription and service gets its liveliness
  token; what local publishers publish (seen through a graph tap) is put on the
  topic's key; a local service answers queries on its key;
- inward, every remote token becomes a participant of the graph (``zenoh:``
  ids, in the remote node), so rosapi lists the whole network; remote samples
  are published in the graph by their publisher's participant; a call to a
  remote service is a query.

Nothing that came from Zenoh goes back to it: the tap skips the link's own
participants, and Zenoh delivers a session's samples only to other sessions
(``Locality.REMOTE``), so with any number of processes each sample reaches each
subscriber once. Zenoh calls back on its own threads; every event is handed to
the event loop that runs the link, so the graph is only touched there.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import time
from collections import Counter, deque
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any, cast

import anyio
import zenoh.ext

import zenoh
from rwt_graph.calls import guarded
from rwt_graph.exports import Exports
from rwt_graph.feed import EntityKind as GraphKind
from rwt_graph.link import PRIVATE_NAMES, LinkRules, Relays
from rwt_graph.mirror import Mirror, RemoteKind
from rwt_graph.nodes import CLIENT_NODE_PREFIX
from rwt_graph.ratelog import EpisodeLog
from rwt_graph.topic_holds import TopicHolds
from rwt_protocol.errors import RwtError

from .config import ZenohOptions, make_config
from .deferred import Deferred, DeferredEncoder, held_payload, payload_bytes
from .gaps import SequenceGaps
from .inbox import Inbox, Sample
from .limits import MAX_OUTBOX_BYTES, MAX_QUEUED_BYTES, MAX_REMOTE_ENTITIES, RELIABLE_WAIT_S
from .link_actions import ActionLink
from .link_clients import LINK_NODE, ClientEntities
from .link_params import ParamLink
from .link_remotes import REMOTE_KINDS, ZenohRemotes, remote_entity
from .link_services import serve_query
from .outbox import Outbox
from .payload import decode_message, encode_message, prepare_codecs, service_hash, type_hash
from .token_qos import token_qos
from .wire import (
    LATCHED_QOS,
    VOLATILE_QOS,
    Durability,
    Entity,
    EntityKind,
    QoS,
    RmwCompat,
    Topic,
    WireError,
    attachment_source,
    dds_type_name,
    pack_attachment,
    reply_attachment,
    topic_keyexpr,
    zid_text,
)

if TYPE_CHECKING:
    from collections.abc import AsyncIterator, Callable, Iterable, Sized

    from anyio.abc import TaskStatus

    from rwt_graph.graph import Graph
    from rwt_graph.topics import Topic as GraphTopic
    from rwt_protocol.ports import ClientId, MessageEvent

__all__ = ["PARTICIPANT_PREFIX", "PRIVATE_NAMES", "ZenohLink", "open_zenoh_link"]

logger = logging.getLogger("rwt.zenoh")

PARTICIPANT_PREFIX = "zenoh:"
"""Participant ids of the link: remote entities, its relays and its caller."""

_Event = tuple["Callable[..., None]", tuple[object, ...], str]
"""A callback for the link's task, its arguments and its sample's topic ("" if none)."""

_DRAIN_BATCH = 1000
_SWEEP_DUTY = 10  # a sweep that took t seconds is followed by a pause of at least 10 t
_DRAIN_BYTES = 4 * 1024 * 1024  # sample bytes handled between two yields to other tasks
#: The graph's kinds of local entity as rmw_zenoh's tokens name them (an action is
#: shared by ``link_actions``, as its services and topics).
_KINDS = {
    GraphKind.PUBLISHER: EntityKind.PUBLISHER,
    GraphKind.SUBSCRIPTION: EntityKind.SUBSCRIPTION,
    GraphKind.SERVICE: EntityKind.SERVICE,
}


def _release(counter: Counter[Any], ref: object) -> None:
    """One reference to ``ref`` fewer; none left, no entry (``in`` then says it is gone)."""
    counter[ref] -= 1
    if counter[ref] <= 0:
        del counter[ref]


@dataclass(eq=False)
class _Export:
    """A local entity as the network sees it: its token and the state of its samples."""

    entity: Entity
    token: Any  # zenoh.LivelinessToken
    type_name: str
    latched: bool = False
    node: str = ""  # the graph node it was exported in
    gid: bytes = b""
    sequence: itertools.count[int] = field(default_factory=lambda: itertools.count(1))
    queryable: Any = None  # zenoh.Queryable of a service


@dataclass(eq=False)
class OwnPublisher:
    """A publisher the link itself owns (an action's feedback or status topic).

    It has its liveliness token, so ROS 2 counts it (an action client waits for a
    feedback publisher: rcl_action ``rcl_action_server_is_available``), and each
    sample carries rmw_zenoh's attachment with the publisher's GID and sequence,
    without which a ROS 2 subscription drops it (rmw_subscription_data.cpp).
    """

    token: Any  # zenoh.LivelinessToken
    handle: Any  # zenoh.Publisher, or an advanced one keeping the last samples
    gid: bytes
    topic: str = ""
    sequence: itertools.count[int] = field(default_factory=lambda: itertools.count(1))

    def put(self, payload: bytes | bytearray) -> None:
        """Publish one CDR sample, now (a publisher with congestion control DROP)."""
        self.handle.put(payload, attachment=self.attachment())

    def attachment(self) -> bytes:
        """rmw_zenoh's attachment of the next sample: sequence number, time, GID."""
        return pack_attachment(next(self.sequence), time.time_ns(), self.gid)

    def undeclare(self) -> None:
        """Withdraw the publisher and its token."""
        guarded("undeclaring a publisher", self.handle.undeclare)
        guarded("undeclaring a token", self.token.undeclare)


def _matching(publisher: Any) -> bool:
    """Whether a subscriber on Zenoh matches ``publisher``, as Zenoh's routing sees it now.

    Such a subscriber is another process's: a ROS 2 node, another worker, a server.
    Zenoh delivers a put to the subscribers its routing knows when it is made, so a put
    without one is dropped unseen: skipping its encoding and put changes nothing a peer
    gets, and saves the publishing server a CDR encode, a hand-over to the outbox's
    thread and Zenoh's own work per message (a quarter of a delivery's CPU at 100
    subscribers a topic, docs/scaling.md). About 1 us; a Zenoh that cannot tell is taken
    to have one.
    """
    try:
        return bool(publisher.matching_status.matching)
    except Exception:  # an older or closing Zenoh: put, as before
        return True


@dataclass(eq=False)
class _Data:
    """The Zenoh publishers or subscriber of one topic and its type."""

    type_name: str
    key: str
    handle: Any
    latched: Any = None  # the cache-keeping publisher of latched samples
    latched_sent: object = None  # the last latched event put there


def _kept(entry: GraphTopic) -> bool:
    """Whether ``entry``'s offer is transient local: its samples go through the cache (D62)."""
    state = entry.qos
    return state is not None and state.offered is not None and state.offered.transient_local


def _caching_publisher(session: zenoh.Session, keyexpr: str, depth: int) -> Any:
    """A transient local publisher as rmw_zenoh's.

    Its last ``depth`` samples are kept for late subscribers, which find it by
    publisher detection.
    """
    return zenoh.ext.declare_advanced_publisher(
        session,
        keyexpr,
        allowed_destination=zenoh.Locality.REMOTE,
        cache=zenoh.ext.CacheConfig(max_samples=depth),
        publisher_detection=True,
    )


class ZenohLink:
    """Mirrors a graph's entities to and from a Zenoh session (see the module text).

    It follows the link contract of ``rwt_graph.link`` (``rules``).

    Args:
        graph: the graph to link; touched only on the event loop running ``run``.
        session: an open Zenoh session; the link does not close it.
        domain_id: the ROS domain, the first part of every key.
        private: names never shared (``PRIVATE_NAMES``; ``*`` ends a prefix).
        sweep_s: how often the link sweeps: relays, callers, actions' and parameters'
            services, remote services another provider shadowed, seconds. Local
            entities are shared as the graph's change feed announces them
            (``rwt_graph.exports``), within a turn of the event loop.
        call_timeout_s: how long a call to a remote service waits for its reply.
        compat: whose token defaults to write and read (``RmwCompat``).
        queue_bytes: bytes of remote samples waiting for the event loop at most
            (``limits.MAX_QUEUED_BYTES``; past it the oldest of a topic go).
        outbox_bytes: bytes of local samples waiting for their put at most
            (``limits.MAX_OUTBOX_BYTES``; ``outbox.Outbox``).
        max_entities: remote entities (tokens) mirrored at once
            (``limits.MAX_REMOTE_ENTITIES``; tokens past it are ignored).

    Attributes:
        zid: the session's id as rmw_zenoh prints it.
        peer_log: the log of what peers cause on every sample or token (bad ones,
            refused ones, ones past a limit): one line per episode, repeats counted.
    """

    def __init__(
        self,
        graph: Graph,
        session: zenoh.Session,
        *,
        domain_id: int = 0,
        private: tuple[str, ...] = PRIVATE_NAMES,
        sweep_s: float = 0.1,
        call_timeout_s: float = 60.0,
        compat: RmwCompat = RmwCompat.CURRENT,
        queue_bytes: int = MAX_QUEUED_BYTES,
        outbox_bytes: int = MAX_OUTBOX_BYTES,
        max_entities: int = MAX_REMOTE_ENTITIES,
    ) -> None:
        self.graph = graph
        self.compat = compat
        self.session = session
        self.domain_id = domain_id
        self.private = private
        self.rules = LinkRules(PARTICIPANT_PREFIX, private)
        self.sweep_s = sweep_s
        self.call_timeout_s = call_timeout_s
        self.zid = zid_text(bytes(cast("Any", session.info.zid())))
        self._ids = itertools.count(1)  # node and entity ids share one counter, as in rmw_zenoh
        self._node_ids: dict[str, int] = {}
        self._exports: dict[tuple[EntityKind, ClientId, str], _Export] = {}
        # how many exports name each node, and each (kind, name): what the sweeps after a
        # change ask, answered without walking every export (10,000 clients subscribing
        # one by one made that quadratic)
        self._node_refs: Counter[str] = Counter()
        self._name_refs: Counter[tuple[EntityKind, str]] = Counter()
        # the local entities to share, from the graph's change feed; its backlog is
        # applied in the link's task as soon as it fills (``_share``)
        self.outward = Exports(graph.port.feed, self.rules, on_backlog=self._share_soon)
        self._node_tokens: dict[str, Any] = {}
        self._pubs: dict[str, _Data] = {}
        self._subs: dict[str, _Data] = {}
        self._remote: dict[str, ClientId] = {}  # token -> its participant
        self._relays = Relays(graph, self.rules, LINK_NODE, self._publisher_of)
        self._gaps = SequenceGaps()  # remote publishers' sequence numbers (D61)
        self._losses_kept: set[str] = set()  # topics with lost messages not told yet
        self._sample_publisher: ClientId | None = None  # of the sample being delivered
        self._caller = f"{PARTICIPANT_PREFIX}caller"
        # A ROS 2 service keeps requests by client GID and sequence number, and refuses
        # a second request with both equal (rmw_service_data.cpp ``take_request``):
        # each caller's calls go out as a client entity of its own, numbered from 1.
        self.clients = ClientEntities(self)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake: asyncio.Event | None = None
        self._events: deque[_Event] = deque()
        self._signalled = False
        self.peer_log = EpisodeLog(logger)
        self._inbox = Inbox(queue_bytes, drop_log=EpisodeLog(logger))  # on Zenoh's threads
        #: keys of samples never held back (``TopicHolds``): the mirrored actions' feedback
        self.never_held: set[str] = set()
        self._outbox = Outbox(outbox_bytes)  # Zenoh's blocking puts, off the loop
        self._deferred = DeferredEncoder(graph.registry)  # large ones serialized there
        self._drained_bytes = 0
        self.max_entities = max_entities
        self._closed = False
        self._liveliness: Any = None
        self._actions = ActionLink(self)
        self._params = ParamLink(self)
        remotes = ZenohRemotes(self, self._actions)
        self._mirror = Mirror(graph, self.rules, remotes, self.peer_log, event="zenoh")

    # ---- running ----------------------------------------------------------------

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """Link until cancelled; then withdraw every token and forget every remote entity.

        Raises:
            RuntimeError: the event loop is not asyncio's (Zenoh's threads wake
                the link's task with ``call_soon_threadsafe``).
        """
        self._loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        self.graph.taps.append(self._tap)
        self.outward.open()
        try:
            self._liveliness = self.session.liveliness().declare_subscriber(
                f"@ros2_lv/{self.domain_id}/**", self._on_token_thread, history=True
            )
            self._sweep()
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._sweeper)
                task_status.started()
                await self._drain()
        finally:
            self._close()

    async def _sweeper(self) -> None:
        # A sweep walks the graph's topics and services: in a large graph (a peer's
        # tens of thousands of entities) the pause after it grows with its cost, so
        # sweeping takes at most 1/_SWEEP_DUTY of the event loop's time.
        pause = self.sweep_s
        while True:
            await anyio.sleep(pause)
            started = time.monotonic()
            self._sweep()
            pause = max(self.sweep_s, (time.monotonic() - started) * _SWEEP_DUTY)

    async def _drain(self) -> None:
        """Handle what Zenoh's threads handed over, in order, in this task.

        A task rather than bare loop callbacks: handlers may start async work
        (an async in-process service), which needs a task's context.
        """
        assert self._wake is not None
        wake = self._wake
        events = self._events

        def resume(held: list[_Event]) -> None:  # a held topic's samples, oldest first
            events.extendleft(reversed(held))
            wake.set()

        async with anyio.create_task_group() as tg:
            holds: TopicHolds[_Event] = TopicHolds(tg.start_soon, resume, self.never_held)
            while True:
                await wake.wait()
                self._signalled = False
                wake.clear()
                while events:
                    # A batch at a time, then others run (during a flood); one yield per
                    # batch, not per event: a checkpoint per sample was a quarter of B's
                    # time in Z3 (benchmarks/README.md, "Scaling out"). A batch ends early
                    # after _DRAIN_BYTES of samples, so large ones (images) do not hold
                    # the loop for long. A sample that congested a subscriber holds its
                    # topic back until that subscriber drains, within its hold budget
                    # (``TopicHolds``): the topic's samples wait in the inbox, which
                    # fills and holds the peer back, so a burst arrives whole; the other
                    # topics go on meanwhile.
                    self._drained_bytes = 0
                    gate = self.graph.port.inflow
                    gate.begin()
                    try:
                        for _ in range(min(len(events), _DRAIN_BATCH)):
                            event = events.popleft()
                            callback, args, topic = event
                            if topic and holds.park(topic, event):
                                continue
                            self._sample_publisher = None
                            self._guarded(callback, *args)
                            holds.delivered(topic or None, gate, self._sample_publisher)
                            if self._drained_bytes >= _DRAIN_BYTES:
                                break
                    finally:
                        gate.end()
                    if events:
                        await asyncio.sleep(0)

    def _close(self) -> None:
        self._closed = True
        self.outward.close()
        with contextlib.suppress(ValueError):
            self.graph.taps.remove(self._tap)
        handles: list[Any] = [self._liveliness]
        handles += [export.queryable for export in self._exports.values()]
        handles += [export.token for export in self._exports.values()]
        handles += list(self._node_tokens.values())
        self._outbox.close()  # what the local publishers sent goes out first
        self._inbox.close()  # Zenoh threads waiting for room give up
        for data in [*self._pubs.values(), *self._subs.values()]:
            handles += [data.handle, data.latched]
        for handle in handles:
            if handle is not None:
                guarded("undeclaring a zenoh entity", handle.undeclare)
        self._actions.close()
        self._params.close()
        self.clients.close()
        self._exports.clear()
        self._node_tokens.clear()
        self._pubs.clear()
        self._subs.clear()
        self._mirror.close()
        self._remote.clear()
        self._relays.close()

    def _soon(self, callback: Callable[..., None], *args: object, topic: str = "") -> None:
        """Run ``callback(*args)`` in the link's task (called from Zenoh's threads).

        For tokens, replies and queries, which are never dropped; samples go
        through ``soon_sample``, bounded in bytes, which names their ``topic``
        (``TopicHolds`` holds it back while it congests a subscriber).
        """
        loop, wake = self._loop, self._wake
        if loop is None or wake is None or self._closed:
            return
        self._events.append((callback, args, topic))
        if not self._signalled:
            self._signalled = True
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(wake.set)

    def later(self, delay_s: float, callback: Callable[..., None], *args: object) -> None:
        """Run ``callback(*args)`` in the link's task ``delay_s`` seconds from now.

        Called from the link's task (the event loop); nothing runs once the link closed.
        """
        loop = self._loop
        if loop is None or self._closed:
            return
        loop.call_later(delay_s, self._soon, callback, *args)

    def _guarded(self, callback: Callable[..., None], *args: object) -> None:
        if self._closed:
            return
        try:
            callback(*args)
        except Exception:
            logger.exception("zenoh link: handling %s failed", getattr(callback, "__name__", ""))

    # ---- what the action half uses ---------------------------------------------------

    @property
    def caller(self) -> ClientId:
        """The participant calling local services and actions for remote callers."""
        return self._caller

    def is_private(self, name: str) -> bool:
        """Whether ``name`` stays in this process (``private``)."""
        return self.rules.is_private(name)

    def entity_of(self, node: str, kind: EntityKind, topic: Topic) -> Entity:
        """A new entity of ``node`` (a fresh id in this session) on ``topic``."""
        owner = self._node_entity(node)
        return Entity(
            self.domain_id,
            self.zid,
            owner.nid,
            next(self._ids),
            kind,
            owner.namespace,
            owner.node,
            topic=topic,
            compat=self.compat,
        )

    def declare_service(
        self, node: str, topic: Topic, on_query: Callable[[zenoh.Query], None]
    ) -> list[Any]:
        """Offer a service of ``node`` on Zenoh: its liveliness token and its queryable.

        ``on_query`` runs on a Zenoh thread (hand the query to ``soon``); queries of
        this session itself are not routed to it. Returns the two handles to
        undeclare, queryable first.
        """
        entity = self.entity_of(node, EntityKind.SERVICE, topic)
        token = self.session.liveliness().declare_token(entity.token())
        keyexpr = topic_keyexpr(self.domain_id, topic.name, topic.dds_type, topic.type_hash)
        queryable = self.declare_queryable(keyexpr, on_query)
        return [queryable, token]

    def declare_publisher(self, node: str, topic: Topic, *, block: bool = False) -> OwnPublisher:
        """A publisher of ``node`` on ``topic``, with its token (see ``OwnPublisher``).

        A transient local ``topic.qos`` keeps its last ``depth`` samples for late
        subscribers, as a latched topic's publisher does. Samples go to other
        sessions only. ``block``: a volatile publisher whose samples must not be
        lost to a full transmission queue (congestion control BLOCK, as the link's
        topics' publishers): put it through ``put_queued``, never ``put``.
        """
        entity = self.entity_of(node, EntityKind.PUBLISHER, topic)
        keyexpr = topic_keyexpr(self.domain_id, topic.name, topic.dds_type, topic.type_hash)
        if topic.qos.durability is Durability.TRANSIENT_LOCAL:
            handle = _caching_publisher(self.session, keyexpr, topic.qos.depth)
        else:
            congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
            handle = self.session.declare_publisher(
                keyexpr,
                allowed_destination=zenoh.Locality.REMOTE,
                congestion_control=congestion,
                reliability=zenoh.Reliability.RELIABLE,
            )
        token = self.session.liveliness().declare_token(entity.token())
        return OwnPublisher(token, handle, entity.gid(), topic.name)

    def put_queued(self, publisher: OwnPublisher, payload: bytes | bytearray) -> None:
        """Put a sample of ``publisher`` (declared with ``block``) from the outbox's thread.

        In order with the link's other queued puts, bounded as they are (``outbox``);
        the event loop never waits for a full transmission queue.
        """
        self._outbox.put(publisher.topic, publisher.handle, payload, publisher.attachment())

    def after_puts(self, call: Callable[[], None]) -> None:
        """Run ``call`` (an answer) once the samples queued before it are put (``outbox``)."""
        self._outbox.call_after_puts(call)

    def declare_queryable(self, keyexpr: str, on_query: Callable[[zenoh.Query], None]) -> Any:
        """A service's queryable as rmw_zenoh declares one: complete, for others only.

        Complete because a ROS 2 client's query targets complete queryables only
        (rmw_service_data.cpp ``qable_options.complete``; rmw_client_data.cpp
        ``send_request``, ``Z_QUERY_TARGET_ALL_COMPLETE``).
        """
        return self.session.declare_queryable(
            keyexpr, on_query, complete=True, allowed_origin=zenoh.Locality.REMOTE
        )

    def reply(self, query: zenoh.Query, payload: bytes | bytearray) -> None:
        """Answer ``query`` to one of this process's services with ``payload`` (CDR).

        The reply carries the request's sequence number and client GID
        (``wire.reply_attachment``), which a ROS 2 client needs to take it.
        """
        asked = query.attachment
        attachment = reply_attachment(None if asked is None else asked.to_bytes(), time.time_ns())
        query.reply(query.key_expr, payload, attachment=attachment)

    def soon(self, callback: Callable[..., None], *args: object) -> None:
        """Run ``callback(*args)`` in the link's task (from a Zenoh thread); see ``_soon``."""
        self._soon(callback, *args)

    def soon_sample(
        self,
        key: str,
        deliver: Callable[[Any, bytes | None], None],
        payload: Sized,
        attachment: bytes | None = None,
        *,
        reliable: bool = False,
    ) -> None:
        """Run ``deliver(payload, attachment)`` in the link's task (from a Zenoh thread).

        A ``reliable`` sample (put with congestion control BLOCK) waits up to
        ``limits.RELIABLE_WAIT_S`` for room in a full queue, holding its peer back,
        before the rule below applies (docs/zenoh.md, "Reliability").

        The samples waiting are bounded in bytes (``queue_bytes``): past it the
        oldest samples of the busiest ``key`` (a topic) are dropped, logged once
        per episode, so a peer publishing faster than this process decodes
        cannot exhaust its memory (docs/limits.md, "Zenoh peers").
        """
        if self._loop is None or self._closed:
            return
        wait_s = RELIABLE_WAIT_S if reliable else 0.0
        if self._inbox.put(key, Sample(deliver, payload, attachment), wait_s=wait_s):
            self._soon(self._take_sample, key, topic=key)

    def _take_sample(self, key: str) -> None:
        sample = self._inbox.take(key)
        if sample is not None:
            self._drained_bytes += sample.size
            sample.deliver(sample.payload, sample.attachment)

    def query(
        self,
        key: str,
        payload: bytes | bytearray,
        answer: Callable[[bool, object], None],
        timeout_s: float,
        attachment: bytes,
    ) -> None:
        """Send a query; ``answer(ok, value)`` runs once in the link's task.

        ``attachment`` is the calling client entity's (``clients.attachment``).

        ``value`` is the first reply's payload (bytes) when ``ok``, else the error
        reply's text or "no reply" when every reply is in or ``timeout_s`` passed.
        """
        outcome: list[tuple[bool, object]] = []

        def on_reply(reply: zenoh.Reply) -> None:  # a Zenoh thread
            if outcome:
                return
            if reply.ok is not None:
                outcome.append((True, reply.ok.payload.to_bytes()))
            else:
                error = reply.err
                outcome.append((False, "" if error is None else error.payload.to_string()))
            self._soon(answer, *outcome[0])

        def on_done() -> None:  # a Zenoh thread
            if not outcome:
                outcome.append((False, "no reply from the network"))
                self._soon(answer, *outcome[0])

        self.session.get(
            key,
            zenoh.handlers.Callback(on_reply, on_done),
            payload=payload,
            attachment=attachment,
            timeout=timeout_s,
        )

    # ---- local entities, outward ---------------------------------------------------

    def _sweep(self) -> None:
        """The periodic sweep: what the graph's change feed does not announce, and the exports."""
        self._share()
        self.clients.sweep()
        self._sweep_nodes()
        self._relays.sweep(self._subs)
        self._params.sweep()
        self._mirror.retry()  # the local provider that shadowed one may have gone
        self._tell_losses()

    def _tell_losses(self) -> None:
        """Tell the subscribers of the lost messages kept for a later report (D61)."""
        now = time.monotonic()
        for topic in list(self._losses_kept):
            entry = self.graph.topics.get(topic)
            if entry is None or not entry.report_lost(0, now):
                self._losses_kept.discard(topic)

    def _share_soon(self) -> None:
        """The feed's backlog filled (inside a graph call): share it in the link's task."""
        self._soon(self._share)

    def _share(self) -> None:
        """Bring tokens, subscribers, publishers and actions in line with the local entities.

        Only the entities the change feed announced since the last call are
        looked at (``Exports.take``): the graph is not walked.
        """
        changed = self.outward.take()
        nodes: set[str] = set()
        names: set[str] = set()
        for (kind, client, name), change in changed.items():
            wire_kind = _KINDS.get(kind)
            if wire_kind is None:
                continue  # an action: ``link_actions`` shares it
            key = (wire_kind, client, name)
            names.add(name)
            export = self._exports.get(key)
            if export is not None and (
                change is None
                or (export.type_name, export.latched) != (change.type_name, change.latched)
                or (change.node is not None and change.node != export.node)
            ):
                nodes.add(export.node)
                self._unexport(key)
                export = None
            if export is None and change is not None:
                export = self._export(key, change.type_name, latched=change.latched)
                if export is not None:
                    nodes.add(export.node)
        if changed:
            self._sweep_nodes(nodes)
            self._sweep_subscribers(names)
            self._sweep_publishers(names)
            self._actions.sweep()

    def _node_id(self, node: str) -> int:
        nid = self._node_ids.get(node)
        if nid is None:
            nid = self._node_ids[node] = next(self._ids)
        return nid

    def _node_entity(self, node: str) -> Entity:
        """The node as others see it; client nodes get the session id, being per process."""
        if node.startswith(CLIENT_NODE_PREFIX):
            node = f"{node}_{self.zid[:8]}"
        namespace, _, name = node.rpartition("/")
        nid = self._node_id(node)
        return Entity(
            self.domain_id,
            self.zid,
            nid,
            nid,
            EntityKind.NODE,
            namespace or "/",
            name,
            compat=self.compat,
        )

    def _export(
        self, key: tuple[EntityKind, ClientId, str], type_name: str, *, latched: bool
    ) -> _Export | None:
        kind, client, name = key
        node_name = self.graph.nodes.name_of(client)
        node = self._node_entity(node_name)
        registry = self.graph.registry
        try:
            if kind is EntityKind.SERVICE:
                srvtype = registry.service(type_name)
                type_hash_text = service_hash(registry, srvtype)
            else:
                type_hash_text = type_hash(registry, type_name)
        except (RwtError, WireError) as exc:
            logger.debug("zenoh link: %s %s is not shared: %s", kind.name.lower(), name, exc)
            return None
        qos = self._token_qos(kind, client, name, latched=latched)
        topic = Topic(name, dds_type_name(type_name), type_hash_text, qos)
        entity = Entity(
            self.domain_id,
            self.zid,
            node.nid,
            next(self._ids),
            kind,
            node.namespace,
            node.node,
            topic=topic,
            compat=self.compat,
        )
        token = self.session.liveliness().declare_token(entity.token())
        export = _Export(
            entity, token, type_name, latched=latched, node=node_name, gid=entity.gid()
        )
        if kind is EntityKind.SERVICE:
            keyexpr = topic_keyexpr(self.domain_id, name, topic.dds_type, topic.type_hash)
            export.queryable = self.declare_queryable(
                keyexpr, lambda query: self._soon(serve_query, self, name, type_name, query)
            )
        self._exports[key] = export
        self._node_refs[node_name] += 1
        self._name_refs[kind, name] += 1
        return export

    def _token_qos(self, kind: EntityKind, client: ClientId, name: str, *, latched: bool) -> QoS:
        """The QoS a token of the graph's endpoint says (``token_qos``; D62, docs/zenoh.md)."""
        entry = self.graph.topics.get(name)
        state = None if entry is None else entry.qos
        if state is not None:
            if kind is EntityKind.PUBLISHER and state.offered is not None:
                return token_qos(state.offered)
            asked = state.resolved(client) if kind is EntityKind.SUBSCRIPTION else None
            if asked is not None:
                return token_qos(asked)
        return LATCHED_QOS if latched else VOLATILE_QOS

    def _unexport(self, key: tuple[EntityKind, ClientId, str]) -> None:
        export = self._exports.pop(key)
        kind, _, name = key
        _release(self._node_refs, export.node)
        _release(self._name_refs, (kind, name))
        if export.queryable is not None:
            guarded("undeclaring a queryable", export.queryable.undeclare)
        guarded("undeclaring a token", export.token.undeclare)

    def _sweep_nodes(self, touched: set[str] | None = None) -> None:
        """A liveliness token for each node with exports or callers, none for the others.

        ``touched``: only these nodes changed (their exports came or went); None
        looks at every node (the periodic sweep, and a caller's node).
        """
        callers = self.clients.nodes()
        if touched is None:
            nodes = {self.graph.nodes.name_of(client) for _, client, _ in self._exports}
            nodes |= callers
            candidates: Iterable[str] = [*self._node_tokens, *nodes]
        else:
            candidates = touched

        for node in set(candidates):
            wanted = node in self._node_refs or node in callers
            if not wanted and node in self._node_tokens:
                guarded("undeclaring a node token", self._node_tokens.pop(node).undeclare)
            elif wanted and node not in self._node_tokens:
                token = self._node_entity(node).token()
                self._node_tokens[node] = self.session.liveliness().declare_token(token)

    def _sweep_subscribers(self, touched: Iterable[str] | None = None) -> None:
        """A Zenoh subscriber for each topic local subscribers listen to, of its type.

        ``touched``: only these topics changed; None looks at every one.
        """
        names = set(self._subs) | {n for k, n in self._name_refs if k is EntityKind.SUBSCRIPTION}
        for name in names if touched is None else set(touched):
            entry = self.graph.topics.get(name)
            listening = None
            if entry is not None and (EntityKind.SUBSCRIPTION, name) in self._name_refs:
                listening = entry.msgtype.name
            data = self._subs.get(name)
            if data is not None and data.type_name != listening:
                guarded("undeclaring a subscriber", self._subs.pop(name).handle.undeclare)
                data = None
            if data is None and listening is not None:
                self._subscribe(name, listening)

    def _sweep_publishers(self, touched: Iterable[str] | None = None) -> None:
        """Zenoh publishers only while local ones publish; the latched cache while one latches.

        ``touched``: only these topics changed; None looks at every one.
        """
        names = set(self._pubs) | {n for k, n in self._name_refs if k is EntityKind.PUBLISHER}
        for name in names if touched is None else set(touched):
            entry = self.graph.topics.get(name)
            publishing = entry is not None and (EntityKind.PUBLISHER, name) in self._name_refs
            latched = (
                publishing
                and entry is not None
                and (
                    _kept(entry)
                    or any(flag for c, flag in entry.publishers.items() if not self.rules.ours(c))
                )
            )
            data = self._pubs.get(name)
            if data is not None:
                if not publishing or entry is None or entry.msgtype.name != data.type_name:
                    self._drop_publisher(name)
                elif not latched and data.latched is not None:
                    guarded("undeclaring a latched publisher", data.latched.undeclare)
                    data.latched = data.latched_sent = None
            if not latched or entry is None or entry.latched is None:
                continue
            owner = entry.latched_by
            if owner is not None and not self.rules.ours(owner):  # published before the link saw it
                self._put_latched(entry, entry.latched, owner)

    def _drop_publisher(self, name: str) -> None:
        data = self._pubs.pop(name)
        for handle in (data.handle, data.latched):
            if handle is not None:
                guarded("undeclaring a publisher", handle.undeclare)

    def _subscribe(self, name: str, type_name: str) -> None:
        registry = self.graph.registry
        try:
            key = topic_keyexpr(
                self.domain_id, name, dds_type_name(type_name), type_hash(registry, type_name)
            )
        except (RwtError, WireError) as exc:
            logger.debug("zenoh link: not subscribing to %s: %s", name, exc)
            return

        deliver = partial(self._on_sample, name, type_name)

        def on_sample(sample: zenoh.Sample) -> None:  # a Zenoh thread
            attachment = sample.attachment
            self.soon_sample(
                name,
                deliver,
                held_payload(sample.payload),  # large ones copied on the loop (``deferred``)
                None if attachment is None else attachment.to_bytes(),
                reliable=sample.congestion_control == zenoh.CongestionControl.BLOCK,
            )

        handle = zenoh.ext.declare_advanced_subscriber(
            self.session,
            key,
            on_sample,
            allowed_origin=zenoh.Locality.REMOTE,
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
        )
        self._subs[name] = _Data(type_name, key, handle)

    def _publisher(self, entry: GraphTopic) -> _Data:
        data = self._pubs.get(entry.name)
        if data is None:
            type_name = entry.msgtype.name
            key = topic_keyexpr(
                self.domain_id,
                entry.name,
                dds_type_name(type_name),
                type_hash(self.graph.registry, type_name),
            )
            # BLOCK: a full transmission queue waits (on the outbox's thread) rather
            # than drops, as rmw_zenoh's reliable KEEP_ALL publishers do (docs/zenoh.md,
            # "Reliability"); Zenoh's default, DROP, lost 1 MB samples in a burst.
            handle = self.session.declare_publisher(
                key,
                allowed_destination=zenoh.Locality.REMOTE,
                congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE,
            )
            data = self._pubs[entry.name] = _Data(type_name, key, handle)
        return data

    def _tap(self, entry: GraphTopic, event: MessageEvent, client: ClientId, latch: bool) -> None:
        """Forward what a local publisher published (the graph calls this on the loop)."""
        if self._closed or not self.rules.forwards(client, entry.name):
            return
        if latch or _kept(entry):
            self._put_latched(entry, event, client)
            return
        export = self._publisher_export(entry, client)
        if export is not None:
            data = self._publisher(entry)
            if not _matching(data.handle):
                return  # no subscriber on Zenoh: a sample would go nowhere, so none is made
            payload: bytes | bytearray | Deferred | None
            payload = event.wire  # what came serialized goes on as it came
            if payload is None:  # large: serialized on the outbox's thread
                payload = self._deferred.defer(entry.msgtype, event.msg)
            if payload is None:
                payload = self._encode(entry, event)
            outbox = self._outbox
            outbox.put(data.key, data.handle, payload, self._attachment(export))
            if outbox.congested:  # the publisher's reader waits for it (``Backlog``)
                self.graph.port.outflow.congested(outbox)

    def _publisher_export(self, entry: GraphTopic, client: ClientId) -> _Export | None:
        key = (EntityKind.PUBLISHER, client, entry.name)
        export = self._exports.get(key)
        if export is None:
            export = self._export(
                key, entry.msgtype.name, latched=entry.publishers.get(client, False)
            )
            if export is not None:
                self._sweep_nodes({export.node})
        return export

    def _put_latched(self, entry: GraphTopic, event: MessageEvent, client: ClientId) -> None:
        export = self._publisher_export(entry, client)
        if export is None:
            return
        data = self._publisher(entry)
        if data.latched_sent is event:
            return
        if data.latched is None:
            offered = None if entry.qos is None else entry.qos.offered
            depth = LATCHED_QOS.depth if offered is None else offered.keep  # (D62)
            data.latched = _caching_publisher(self.session, data.key, depth)
        data.latched.put(self._encode(entry, event), attachment=self._attachment(export))
        data.latched_sent = event

    def _encode(self, entry: GraphTopic, event: MessageEvent) -> bytes | bytearray:
        if event.wire is not None:  # CDR already (a ROS 2 graph's wire form)
            return event.wire
        return encode_message(self.graph.registry, entry.msgtype, event.msg)

    def cancels_goal(self, service: str, query: zenoh.Query) -> bool:
        """Whether ``query`` to ``service`` canceled a remote caller's goal (it is answered)."""
        return self._actions.try_cancel(service, query)

    def _attachment(self, export: _Export) -> bytes:
        return pack_attachment(next(export.sequence), time.time_ns(), export.gid)

    # ---- remote entities, inward ------------------------------------------------------

    def _on_token_thread(self, sample: zenoh.Sample) -> None:  # a Zenoh thread
        alive = sample.kind == zenoh.SampleKind.PUT
        self._soon(self._on_token, str(sample.key_expr), alive)

    def _on_token(self, token: str, alive: bool) -> None:
        """Mirror a remote entity whose token came, release one whose token went."""
        if not alive:
            client = self._remote.pop(token, None)
            if client is not None:
                self._params.unmirror(client)
                self._mirror.remove(client)
            return
        if token in self._remote:
            return
        try:
            entity = Entity.parse(token, self.compat)
        except WireError as exc:
            self.peer_log.log(
                logging.DEBUG, "zenoh_bad_token", "zenoh link: ignored token: %s", exc
            )
            return
        if entity.zid == self.zid or entity.kind not in REMOTE_KINDS:
            return  # this session's, or a client's (which stands for nothing here)
        if len(self._remote) >= self.max_entities:
            self.peer_log.log(
                logging.WARNING,
                "zenoh_entities_full",
                "event=zenoh_entity_ignored limit=%d reason=%r",
                self.max_entities,
                "the link mirrors no more remote entities (--zenoh-max-entities)",
            )
            return
        suffix = "node" if entity.kind is EntityKind.NODE else str(entity.eid)
        client = self._remote[token] = f"{PARTICIPANT_PREFIX}{entity.zid}:{suffix}"
        topic = entity.topic
        if topic is not None and self.rules.is_private(topic.name):
            return
        try:
            remote = remote_entity(entity)
        except WireError as exc:
            assert topic is not None  # a node's token has no type to read
            self._mirror.skip(REMOTE_KINDS[entity.kind], topic.name, str(exc))
            return
        if remote.kind is RemoteKind.SERVICE:
            self._params.mirror(client, remote)
        self._mirror.add(client, remote)

    def _publisher_of(self, gid: bytes) -> ClientId | None:
        """The participant of the remote publisher with ``gid``, once mirrored (``Relays``)."""
        return self._mirror.publisher_of(gid)

    def _on_sample(
        self, topic: str, type_name: str, payload: Any, attachment: bytes | None
    ) -> None:
        """Publish a remote sample in the graph, by its publisher's participant.

        ``payload`` is what ``deferred.held_payload`` kept: ``bytes``, or a large
        sample's ``zenoh.ZBytes``.
        """
        entry = self.graph.topics.get(topic)
        if entry is None or entry.msgtype.name != type_name:
            return
        try:
            data = payload_bytes(payload)
            msg = decode_message(self.graph.registry, entry.msgtype, data)
            sequence, source = (0, None) if attachment is None else attachment_source(attachment)
        except (WireError, RwtError) as exc:
            self.peer_log.log(
                logging.WARNING,
                f"zenoh_bad_sample:{topic}",
                "event=zenoh_bad_sample topic=%s reason=%r",
                topic,
                str(exc),
            )
            return
        if source is not None:
            # a hold this sample starts is charged to its publisher's budget (D61)
            self._sample_publisher = self._publisher_of(source)
            lost = self._gaps.seen(source, sequence)
            if lost and entry.report_lost(lost, time.monotonic()):  # told now or by a sweep
                self._losses_kept.add(topic)
        try:  # by its publisher's participant, or a relay until its token comes
            # a sample tells nothing of its publisher's durability: the relay hands
            # it over as latched once the token says the publisher is transient local
            self._relays.deliver(entry, source, msg, wire=data)
        except RwtError as exc:  # a topic reserved by the server: not the network's
            self.peer_log.log(
                logging.WARNING,
                f"zenoh_sample_refused:{topic}",
                "event=zenoh_sample_refused topic=%s reason=%r",
                topic,
                exc.message,
            )


@asynccontextmanager
async def open_zenoh_link(graph: Graph, options: ZenohOptions) -> AsyncIterator[ZenohLink]:
    """Open a Zenoh session for ``options`` and link ``graph`` while the block runs.

    Raises:
        ValueError: a bad option or config file (see ``make_config``).
        zenoh.ZError: Zenoh cannot start (an endpoint cannot be bound...).
    """
    config = make_config(options)
    # rosbags' type store and numpy take a while to load: not on the event loop
    await anyio.to_thread.run_sync(prepare_codecs, graph.registry)
    session = await anyio.to_thread.run_sync(zenoh.open, config)
    try:
        async with anyio.create_task_group() as tg:
            link = ZenohLink(
                graph,
                session,
                domain_id=options.domain_id,
                compat=options.rmw_compat,
                queue_bytes=options.queue_bytes,
                outbox_bytes=options.outbox_bytes,
                max_entities=options.max_entities,
            )
            await tg.start(link.run)
            try:
                yield link
            finally:
                tg.cancel_scope.cancel()
    finally:
        await anyio.to_thread.run_sync(session.close)
