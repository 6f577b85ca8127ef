"""The ROS 2 link: one graph's entities mirrored to and from a ROS 2 graph through rclpy.

``Ros2Link`` follows the link contract of ``rwt_graph.link`` (as the Zenoh link
does), with one rclpy node (``rwt`` by default) standing for the whole local
graph:

- inward, every other ROS 2 node, publisher, subscription, service server and
  action server becomes a participant of the graph (``ros2:`` ids, in its ROS 2
  node), so rosapi lists the ROS 2 graph; a topic local subscribers listen to
  gets a raw rclpy subscription whose QoS matches its publishers'
  (``subscription_qos``), and each sample is published in the graph by its
  publisher's participant; a call to a ROS 2 service goes through an rclpy
  client (``RosService``), a goal through an rclpy action client
  (``RosAction``); ROS 2 nodes' parameters are copied into the store
  (``rwt_graph.parameters.replicas``);
- outward, a topic local publishers publish gets an rclpy publisher (transient
  local when a local publisher latches), fed by a graph tap with the CDR rwt's
  codec writes, through its lane (``outflow``: its first samples wait until it
  has matched the known subscriptions); a local service gets an rclpy service (``serve_to_ros``), a
  local action an rclpy action server (``serve_action_to_ros``); rwt's log goes
  to ``/rosout`` (``rosout``).

The ROS 2 graph is read every ``sweep_s`` seconds on a worker thread, and at once
when its names change (read every ``GRAPH_POLL_S``); the local entities to share
come from the graph's change feed (``rwt_graph.exports``), whose backlog each
sweep applies (not sooner: a service withdrawn at once could lose the answers
its waiting ROS 2 callers are being sent); a call to a service nobody
offers waits for it to be discovered (its own timeout, else
``DISCOVERY_WAIT_S``); samples (on the take loop's thread, ``takeloop``) and
replies (on rclpy's executor's) reach the event loop through a ``Handoff``
bounded in bytes. The node's own publishers' samples are recognised
by their publisher GID and never come back in.
"""

from __future__ import annotations

import contextlib
import logging
import time
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

import anyio

from rwt_graph.exports import Exports
from rwt_graph.feed import EntityKind
from rwt_graph.link import LATCHED_DEPTH, LinkRules, Relays
from rwt_graph.mirror import Mirror
from rwt_graph.parameters.replicas import ParamReplicas
from rwt_graph.parameters.services import answer as answer_param_request
from rwt_graph.parameters.services import param_nodes
from rwt_graph.parameters.wire import PARAM_SERVICES
from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.errors import RwtError
from rwt_protocol.qos import Reliability
from rwt_protocol.shortcuts import enabled

from .actions import serve_action_to_ros
from .codec import decode, encode
from .counters import LinkCounters, TopicCounters
from .graphview import Qos, RosGraph, digest, publisher_depth, rclpy_profile, snapshot
from .graphview import subscription_qos as matching_qos
from .handoff import MAX_QUEUED_BYTES, Handoff, Sample
from .interfaces import BUILD_TIMEOUT_S
from .node import RosNode
from .offers import Offer
from .ondemand import OnDemand
from .outflow import Lane, Outflow
from .remotes import RosRemotes, entities
from .rosout import RosoutHandler
from .runtime import interface_class, ros_distro
from .services import SERVICE_QOS, serve_to_ros
from .takeloop import TAKE_BATCH, Taken, take_queued

if TYPE_CHECKING:
    import asyncio
    from collections.abc import AsyncIterator, Callable

    from anyio.abc import TaskStatus

    from rwt_graph.graph import Graph
    from rwt_graph.topics import Topic as GraphTopic
    from rwt_protocol.ports import ClientId, MessageEvent
    from rwt_protocol.qos import QosProfile

    from .answer import Answer

__all__ = ["PARTICIPANT_PREFIX", "Ros2Link", "Ros2Options", "open_ros2_link"]

PUB, SUB = EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION
SRV, ACT = EntityKind.SERVICE, EntityKind.ACTION

_LocalView = tuple[dict[str, str], dict[str, tuple[str, bool]], dict[str, str], dict[str, str]]
"""The local entities by name: topics listened to, published (type, latched), services, actions."""

logger = logging.getLogger("rwt.ros2")

PARTICIPANT_PREFIX = "ros2:"
"""Participant ids of the link: ROS 2 entities, its relays and its caller."""

SWEEP_S = 0.2
"""How often both graphs are compared, seconds: a ROS 2 entity shows in rosapi
within this (plus discovery), a new rosbridge subscription reaches ROS 2 within it."""

SWEEP_SHARE = 0.1
"""At most this share of the time goes to sweeping: after two sweeps that took t
seconds or more each, the next waits at least t x (1 / SWEEP_SHARE - 1), so a
robot with thousands of endpoints (rcl's graph queries cost per endpoint) slows
the sweep rather than the samples. One costly sweep alone (it mirrored a node's
hundreds of new endpoints) does not hold back the next."""

CALL_TIMEOUT_S = 30.0
"""How long a call across the link waits for its reply, seconds."""

DISCOVERY_WAIT_S = 2.0
"""Seconds a call to a service nobody offers waits for the link to discover it (a
node starting as the call comes), when the call gave no timeout of its own; one
that did waits up to that timeout (``rwt_graph.services.DiscoveryWait``)."""

SAMPLE_LIFESPAN_S = 0.020
"""Seconds of a topic's samples from ROS 2 a subscriber's queue (its outbox) holds: a
sample that came more than this before the newest queued one of its topic is dropped
there (``MessageEvent.lifespan``, ``rwt_protocol.runtime.outbox``; docs/ros2.md,
"Latency under rate"). A ROS 2 publisher cannot be slowed, so a reader that falls
behind gets the newest samples, as from a ROS 2 subscription's history, not a growing
backlog; a burst that came within it reaches the reader whole."""

GRAPH_POLL_S = 0.05
"""How often the link reads the ROS 2 graph's names between sweeps, seconds
(``graphview.digest``: its nodes, topics and services with their types, a
fraction of a sweep's cost); a change starts a sweep at once. rclpy offers no
graph event to wait on (its node's graph guard condition is not exposed)."""


@dataclass(frozen=True)
class Ros2Options:
    """How the link joins ROS 2 (``ROS_DOMAIN_ID`` and the middleware come from the environment).

    Attributes:
        node_name: the rclpy node standing for the graph (``--ros2-node-name``).
        namespace: its namespace (``--ros2-namespace``).
        sweep_s: ``SWEEP_S``.
        call_timeout_s: ``CALL_TIMEOUT_S``.
        max_queued_bytes: ``handoff.MAX_QUEUED_BYTES``.
        build_interfaces: build a package rclpy lacks and rwt can build
            (``rwt_ros2.build.BUILDS``: ``tf2_msgs``) the first time the link needs
            it, in the background (``rwt_ros2.ondemand``; docs/ros2.md); False: its
            types do not cross, as with any missing package.
        build_timeout_s: the longest such a build may run, seconds
            (``rwt_ros2.interfaces.BUILD_TIMEOUT_S``): then it is stopped, and the
            package's types do not cross.
    """

    node_name: str = "rwt"
    namespace: str = "/"
    sweep_s: float = SWEEP_S
    call_timeout_s: float = CALL_TIMEOUT_S
    max_queued_bytes: int = MAX_QUEUED_BYTES
    build_interfaces: bool = True
    build_timeout_s: float = BUILD_TIMEOUT_S


@dataclass(eq=False)
class _Sub:
    type_name: str
    qos: Qos
    handle: Any
    destroy: Callable[[Any], object]  # of the node, or of the take loop


@dataclass(eq=False)
class _Pub:
    type_name: str
    latched: bool
    handle: Any
    depth: int  # of its history (``_depth``)
    lane: Lane  # its samples on their way (``outflow``)
    latched_sent: object = None
    gids: set[bytes] = field(default_factory=set)
    asked: QosProfile | None = None  # the topic's offer it was made with (``_offered_qos``)


class Ros2Link:
    """Mirrors a graph to and from ROS 2 through one rclpy node (see the module text).

    Args:
        graph: the graph; touched only on the event loop running ``run``.
        ros: the rclpy node (not yet spinning); the link closes it.
        options: sweep period, call timeout, queue bound.
    """

    def __init__(self, graph: Graph, ros: RosNode, options: Ros2Options | None = None) -> None:
        self.graph = graph
        self.ros = ros
        self.options = options or Ros2Options()
        self.rules = LinkRules(PARTICIPANT_PREFIX)
        self.handoff = Handoff(self.options.max_queued_bytes)
        if ros.takes is not None:  # it takes no more while the loop is behind
            ros.takes.pace = self.handoff.pause_while_behind
        self.episodes = EpisodeLog(logger)
        self.caller: ClientId = f"{PARTICIPANT_PREFIX}caller"
        self.pending_answers: set[Answer] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._remotes = RosRemotes(self)
        self._mirror = Mirror(
            graph, self.rules, self._remotes, self.episodes, event="ros2", episode_per_entity=True
        )
        self._own_gids: set[bytes] = set()
        self._publisher_qos: dict[str, list[Qos]] = {}  # the view's, by topic
        self._subscription_qos: dict[str, list[Qos]] = {}  # the view's, by topic
        self._subs: dict[str, _Sub] = {}
        self._pubs: dict[str, _Pub] = {}
        self._servers: dict[str, Offer] = {}
        self._action_servers: dict[str, Offer] = {}
        self._param_servers: dict[str, list[Offer]] = {}  # node -> its 3 rclpy services
        self._retired: set[Offer] = set()  # gone from the graph, answering their last calls
        self._relays = Relays(graph, self.rules, ros.fqn, self._mirror.publisher_of)
        # the local entities to share, from the graph's change feed (``_share``)
        self.outward = Exports(graph.port.feed, self.rules)
        self._local: _LocalView = ({}, {}, {}, {})
        self._params: ParamReplicas | None = None
        self._missing_types: set[str] = set()
        self._type_warnings: dict[str, str | None] = {}
        self._builds = OnDemand(
            self._built,
            enabled=self.options.build_interfaces,
            timeout_s=self.options.build_timeout_s,
        )
        self._outflow: Outflow | None = None  # made in ``run``, with its task group
        self._digest: object = None  # the graph's names at the last look (``graphview.digest``)
        self._closed = False
        self._batch_take = enabled("ros2-batch-take")
        #: what each topic's samples did at each stage, logged when the link stops
        self.counters = LinkCounters()

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        """The event loop the link runs on."""
        assert self._loop is not None
        return self._loop

    # ---- running ----------------------------------------------------------------

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """Link until cancelled; then destroy every rclpy entity and release every mirror."""
        import asyncio  # noqa: PLC0415

        self._loop = asyncio.get_running_loop()
        self.graph.nodes.bind(self.caller, self.ros.fqn)
        self.graph.taps.append(self._tap)
        self.outward.open()
        self._params = ParamReplicas(self.graph, self.caller)
        self.graph.type_checks.append(self.type_warning)
        self.graph.services.discoveries.append(self._discovery_wait)
        rosout = RosoutHandler(self.ros.node.get_logger())
        logging.getLogger("rwt").addHandler(rosout)
        try:
            self.ros.start()
            async with anyio.create_task_group() as tg:
                self._outflow = Outflow(tg)
                self._builds.open(tg)
                await self._sweep_once(periodic=True)
                tg.start_soon(self.handoff.drain, lambda: self.graph.port.inflow)
                task_status.started()
                took = last = 0.0
                while True:
                    periodic = await self._next_sweep(min(took, last))
                    started = time.perf_counter()
                    await self._sweep_once(periodic=periodic)
                    took, last = time.perf_counter() - started, took
        finally:
            logging.getLogger("rwt").removeHandler(rosout)
            with contextlib.suppress(ValueError):
                self.graph.type_checks.remove(self.type_warning)
            with contextlib.suppress(ValueError):
                self.graph.services.discoveries.remove(self._discovery_wait)
            self._close()

    async def _next_sweep(self, took: float) -> bool:
        """Wait for the next sweep: ``sweep_s``, or sooner when the graph's names change.

        Returns False when the names changed: a sweep in between the periodic
        ones, which counts for no period (parameter refreshes, relay waits).

        Either way at least ``took x (1 / SWEEP_SHARE - 1)`` after the last one
        (``took``: the cheaper of the last two sweeps), so sweeping takes no more
        than ``SWEEP_SHARE`` of the time while it stays costly.
        """
        start = anyio.current_time()
        await anyio.sleep(max(GRAPH_POLL_S, took * (1 / SWEEP_SHARE - 1)))
        while anyio.current_time() - start < self.options.sweep_s:
            names = await anyio.to_thread.run_sync(digest, self.ros)
            if names != self._digest:
                self._digest = names
                return False
            await anyio.sleep(GRAPH_POLL_S)
        return True

    def _discovery_wait(self, expire: Callable[[], None]) -> Callable[[], None] | None:
        """Hold a call to a service nobody offers for ``DISCOVERY_WAIT_S`` (``DiscoveryWait``)."""
        if self._closed:
            return None
        return self.loop.call_later(DISCOVERY_WAIT_S, expire).cancel

    async def _sweep_once(self, *, periodic: bool) -> None:
        try:
            view = await anyio.to_thread.run_sync(snapshot, self.ros)
        except RuntimeError as exc:  # rclpy's RCLError: the graph changed under a query
            # the ROS 2 graph is other processes' to change at any time: this sweep
            # is skipped, the next one reads it again; the server serves on
            self.episodes.log(logging.WARNING, "sweep", "event=ros2_sweep_failed error=%r", exc)
            return
        if not self._closed:
            self._apply(view)
            self._sweep_local(periodic=periodic)
            if periodic:
                self.ros.forget_destroyed()
            if self._params is not None:  # nodes whose parameter services are mirrored
                listing = PARAM_SERVICES["list_parameters"]
                self._params.sweep(
                    {
                        node
                        for (node, name), type_name in view.services.items()
                        if name == f"{node}/list_parameters" and type_name == listing
                    },
                    tick=periodic,
                )

    def _close(self) -> None:
        self._closed = True
        self.outward.close()
        self.handoff.close()
        for topic, expired in self.handoff.expired.items():
            self.counters.of(topic).expired = expired
        self.counters.log(logger)
        with contextlib.suppress(ValueError):
            self.graph.taps.remove(self._tap)
        if self._params is not None:
            self._params.close()
        for answer in list(self.pending_answers):
            answer.set(False, "the ROS 2 link is stopping")
        self._mirror.close()
        self._relays.close()
        self.graph.nodes.forget(self.caller)
        node = self.ros.node
        for sub in self._subs.values():
            _destroy(sub.destroy, sub.handle)
        for pub in self._pubs.values():
            pub.lane.take_held()
            _destroy(node.destroy_publisher, pub.handle)
        offers = [*self._servers.values(), *self._action_servers.values(), *self._retired]
        for offer in offers + [o for group in self._param_servers.values() for o in group]:
            offer.destroy()
        self._action_servers.clear()
        self._param_servers.clear()
        self._retired.clear()
        self._subs.clear()
        self._pubs.clear()
        self._servers.clear()
        self.ros.close()

    # ---- the ROS 2 graph, inward ---------------------------------------------------

    def _apply(self, view: RosGraph) -> None:
        """Bring the graph's ROS 2 participants in line with ``view`` (``rwt_graph.mirror``)."""
        self._publisher_qos = {}
        self._subscription_qos = {}
        # the node's own non-link publishers count (rcl's transient local /rosout one)
        others = [e for e in view.own_publishers if e.gid not in self._own_gids]
        for endpoint in [*view.endpoints.values(), *others]:
            if endpoint.kind == "publisher":
                self._publisher_qos.setdefault(endpoint.topic, []).append(endpoint.qos)
            else:
                self._subscription_qos.setdefault(endpoint.topic, []).append(endpoint.qos)
        self._mirror.apply(entities(view, PARTICIPANT_PREFIX))

    def _on_sample(
        self,
        topic: str,
        type_name: str,
        data: bytes,
        gid: bytes,
        transient_local: bool,
        counters: TopicCounters,
    ) -> None:
        """Publish a ROS 2 sample in the graph, by its publisher's participant.

        ``transient_local``: the subscription it came on is, so its publisher is
        too (a transient-local reader matches no volatile writer): a relay latches it.
        ``counters``: the topic's, counting it published or skipped.
        """
        self._on_samples([(topic, type_name, data, gid, transient_local, counters)])

    def _bad_sample(self, topic: str, exc: RwtError) -> None:
        """Log a sample of ``topic`` that is not CDR of its type (once per episode)."""
        self.episodes.log(
            logging.WARNING,
            f"bad:{topic}",
            "event=ros2_bad_sample topic=%s reason=%r",
            topic,
            str(exc),
        )

    def _refused(self, topic: str, exc: RwtError) -> None:
        """Log a sample the graph refused (a topic the server reserved), once per episode."""
        self.episodes.log(
            logging.WARNING,
            f"refused:{topic}",
            "event=ros2_sample_refused topic=%s reason=%r",
            topic,
            exc.message,
        )

    # ---- the local graph, outward ---------------------------------------------------

    def _sweep_local(self, *, periodic: bool) -> None:
        self._share()
        self._sweep_param_servers()
        self._relays.sweep(self._subs, tick=periodic)

    def _share(self) -> None:
        """Bring the rclpy subscriptions, publishers and servers in line with the local entities.

        The local entities come from the change feed (``Exports``), gathered by
        topic again only when some changed; the rest follows the ROS 2 graph's
        QoS as the last sweep saw it (a deeper subscription, a new publisher).
        """
        if self.outward.take():
            self._local = (
                {name: type_name for name, (type_name, _) in self.outward.topics(SUB).items()},
                self.outward.topics(PUB),
                {name: c.type_name for name, c in self.outward.owners(SRV).items()},
                {name: c.type_name for name, c in self.outward.owners(ACT).items()},
            )
        listening, publishing, serving, actions = self._local
        self._sweep_subscriptions(listening)
        self._sweep_publishers(publishing)
        self._sweep_servers(serving)
        self._sweep_action_servers(actions)

    def _sweep_subscriptions(self, listening: dict[str, str]) -> None:
        for name, sub in list(self._subs.items()):
            if listening.get(name) != sub.type_name or self._qos_for(name) != sub.qos:
                del self._subs[name]
                _destroy(sub.destroy, sub.handle)
        for name, type_name in listening.items():
            if name not in self._subs:
                self._subscribe(name, type_name)

    def _qos_for(self, topic: str) -> Qos:
        """The QoS of the link's subscription of ``topic``.

        The first local subscriber's that asked one (protocol 2.1.0, D62;
        ``rwt_ros2.qos``) while every local subscriber asked one; else (none
        asked, or one that asked none is there) one matching every ROS 2
        publisher of it. So a subscriber that comes and goes with a ``qos`` (an
        MCP topic resource's read) never has the subscription that others share
        made again under them: samples would be lost in between, and its depth
        would be that subscriber's; what it asked binds its own delivery (D63).
        """
        entry = self.graph.topics.get(topic)
        state = None if entry is None else entry.qos
        if (
            entry is None
            or state is None
            or any(c not in state.requested and not self.rules.ours(c) for c in entry.subscribers)
        ):
            return matching_qos(self._publisher_qos.get(topic, []))
        for client, asked in state.requested.items():
            if not self.rules.ours(client):
                return Qos(
                    reliable=asked.reliability is not Reliability.BEST_EFFORT,
                    transient_local=asked.transient_local,
                    depth=asked.keep,
                    asked=asked,
                )
        return matching_qos(self._publisher_qos.get(topic, []))

    def _offered_qos(self, topic: str) -> QosProfile | None:
        """The QoS the graph's publishers of ``topic`` offer (its first registration's, D62)."""
        entry = self.graph.topics.get(topic)
        return None if entry is None or entry.qos is None else entry.qos.offered

    def _subscribe(self, name: str, type_name: str) -> None:
        ros_type = self._ros_type(name, type_name)
        if ros_type is None:
            return
        qos = self._qos_for(name)
        if qos.asked is not None:
            _report_qos(name, "subscription", qos.asked)
        on_batch = self._hand_over(name, type_name, qos.transient_local)
        takes = self.ros.takes
        if takes is not None:  # ``ros2-take-loop``: its own thread, one batch per wake-up
            handle = takes.subscribe(ros_type, name, rclpy_profile(qos), on_batch)
            self._subs[name] = _Sub(type_name, qos, handle, takes.unsubscribe)
            return
        created: list[Any] = []  # the rclpy subscription, once made (batch take)

        def on_sample(data: bytes, info: dict[str, Any]) -> None:  # the executor's thread
            batch: list[Taken] = [(data, info)]
            if created:
                batch += take_queued(created[0].handle, ros_type, TAKE_BATCH - 1)
            on_batch(batch)

        node = self.ros.node
        handle = node.create_subscription(
            ros_type,
            name,
            on_sample,
            rclpy_profile(qos),
            raw=True,
            callback_group=self.ros.group,
        )
        if self._batch_take:
            created.append(handle)
        self._subs[name] = _Sub(type_name, qos, handle, node.destroy_subscription)

    def _hand_over(self, name: str, type_name: str, latched: bool) -> Callable[[list[Taken]], None]:
        """What queues one wake-up's samples of ``name`` for the event loop (rclpy's thread).

        ``latched``: the subscription is transient local, so only transient-local
        publishers match it (``_on_sample``).
        """
        handoff = self.handoff
        counters = self.counters.of(name)
        on_loop, run = self._on_sample, self._on_samples

        def on_batch(batch: list[Taken]) -> None:
            samples: list[Sample] = []
            now, wall_ns = time.monotonic(), time.time_ns()
            for data, info in batch:
                gid = bytes((info.get("publisher_gid") or {}).get("data", b""))[:16]
                # when it was published, on its publisher's clock (ns; 0 where rmw has none):
                # the handoff compares one publisher's samples only (``Handoff``)
                sent = info.get("source_timestamp") or wall_ns
                args = (name, type_name, data, gid, latched, counters)
                samples.append((args, len(data), now - (wall_ns - sent) * 1e-9, gid))
            queued = handoff.put_many(on_loop, samples, name, run)
            counters.handed += queued
            counters.refused += len(batch) - queued
            counters.woke(len(batch))

        return on_batch

    def _on_samples(self, runs: list[tuple[object, ...]]) -> None:
        """Publish a run of one publisher's samples of one topic (``Handoff``), in order.

        Each is decoded (one that is not CDR of its type is skipped and logged) and
        the run published in the graph at once (``Relays.deliver_many``): a
        subscriber that takes runs gets it in one call.
        """
        topic, type_name, _, gid, transient_local, counters = runs[0]
        assert isinstance(topic, str) and isinstance(type_name, str)  # (``_hand_over``)
        assert isinstance(gid, bytes) and isinstance(counters, TopicCounters)
        counters.skipped += len(runs)  # until published
        if gid in self._own_gids or self._remotes.mismatched(gid):
            return  # the link's own publisher (it came from the graph), or a foreign definition
        entry = self.graph.topics.get(topic)
        if entry is None or entry.msgtype.name != type_name:
            return
        registry, msgtype = self.graph.registry, entry.msgtype
        msgs: list[dict[str, object]] = []
        wires: list[bytes | None] = []
        for args in runs:
            data = args[2]
            assert isinstance(data, bytes)
            try:
                msgs.append(decode(registry, msgtype, data))
            except RwtError as exc:
                self._bad_sample(topic, exc)
                continue
            wires.append(data)
        if not msgs:
            return
        try:  # by its publisher's participant, or a relay until discovery finds it
            self._relays.deliver_many(
                entry,
                gid or None,
                msgs,
                wires,
                latched=bool(transient_local),
                lifespan=SAMPLE_LIFESPAN_S,
            )
            counters.skipped -= len(msgs)
            counters.published += len(msgs)
        except RwtError as exc:  # a topic reserved by the server: not ROS 2's
            self._refused(topic, exc)

    def type_warning(self, type_name: str) -> str | None:
        """Why ROS 2 cannot carry ``type_name`` here (the package to install), or None.

        The graph's sessions report it as a warning status (``Graph.type_checks``).
        A package rwt builds says so instead (``OnDemand.warning``), and starts
        being built if it was not.
        """
        if type_name in self._type_warnings:
            return self._type_warnings[type_name]
        try:
            interface_class(type_name)
            warning = None
        except RwtError as exc:
            package = self._builds.buildable(type_name)
            if package is not None:
                self._builds.start(package)
                warning = self._builds.warning(type_name, str(exc))
            else:
                warning = f"{exc} (it does not cross to ROS 2)"
        # type names reaching here are the registry's: the table stays bounded
        self._type_warnings[type_name] = warning
        return warning

    def _ros_type(self, name: str, type_name: str) -> Any:
        if type_name in self._missing_types or self._builds.pending(type_name):
            return None
        try:
            return interface_class(type_name)
        except RwtError as exc:
            package = self._builds.buildable(type_name)
            if package is not None and self._builds.start(package):
                return None  # being built: a sweep after it is ready carries the type
            # one line per type: installing the package needs a restart anyway
            self._missing_types.add(type_name)
            self.episodes.log(
                logging.WARNING,
                f"type:{type_name}",
                "event=ros2_type_missing topic=%s reason=%r",
                name,
                str(exc),
            )
            return None

    def _built(self, package: str) -> None:
        """A package's build is ready or failed: what was told of its types is told anew."""

        def other(type_name: str) -> bool:
            return type_name.partition("/")[0] != package

        self._type_warnings = {t: w for t, w in self._type_warnings.items() if other(t)}
        self._missing_types = {t for t in self._missing_types if other(t)}

    def _sweep_publishers(self, publishing: dict[str, tuple[str, bool]]) -> None:
        carried: dict[str, tuple[str, list[bytes]]] = {}  # what waited in a replaced lane
        for name, pub in list(self._pubs.items()):
            if (
                publishing.get(name) != (pub.type_name, pub.latched)
                or pub.asked != self._offered_qos(name)  # the topic's offer came or went (D62)
                or (pub.asked is None and pub.depth < self._depth(name, pub.latched))
            ):  # a deeper subscription came: a history that holds its bursts
                carried[name] = (pub.type_name, self._drop_publisher(name))
        for name, (type_name, latched) in publishing.items():
            entry = self.graph.topics.get(name)
            found = self._pubs.get(name) or self._publisher(name, type_name, latched)
            if found is not None and name in carried:
                was, held = carried.pop(name)
                for data in held if was == type_name else ():
                    found.lane.put(data)
            if found is None or entry is None or entry.latched is None:
                continue
            owner = entry.latched_by
            if latched and owner is not None and not self.rules.ours(owner):
                self._put(entry, found, entry.latched)  # published before the link saw it

    def _publisher(self, name: str, type_name: str, latched: bool) -> _Pub | None:
        ros_type = self._ros_type(name, type_name)
        if ros_type is None or self._outflow is None:  # not running yet
            return None
        offered = self._offered_qos(name)
        if offered is None:
            qos = Qos(transient_local=latched, depth=self._depth(name, latched))
        else:  # the client's QoS, as it fixed it (D62)
            qos = Qos(transient_local=offered.transient_local, depth=offered.keep, asked=offered)
            _report_qos(name, "publisher", offered)
        node = self.ros.node
        before = self._own_publishers(name)
        handle = node.create_publisher(ros_type, name, rclpy_profile(qos))
        # its samples come back to the link's own subscription: know them by GID (the
        # node's other publishers, such as rcl's /rosout one, are ROS 2's, not the graph's)
        gids = self._own_publishers(name) - before
        self._own_gids |= gids
        expected = 0 if qos.transient_local else self._expected_subscriptions(name)
        lane = self._outflow.lane(name, handle, expected=expected)
        pub = self._pubs[name] = _Pub(
            type_name, latched, handle, qos.depth, lane, gids=gids, asked=offered
        )
        return pub

    def _expected_subscriptions(self, topic: str) -> int:
        """The subscriptions of ``topic`` a new volatile publisher should match (``outflow``).

        Those the last sweep saw, the link's own included, but no transient-local
        one (it matches no volatile publisher).
        """
        known = [q for q in self._subscription_qos.get(topic, []) if not q.transient_local]
        own = self._subs.get(topic)
        return len(known) + (own is not None and not own.qos.transient_local)

    def _depth(self, topic: str, latched: bool) -> int:
        """The history depth of the link's publisher of ``topic`` (``publisher_depth``)."""
        if latched:  # the last message for each late subscriber (D13)
            return LATCHED_DEPTH
        return publisher_depth(self._subscription_qos.get(topic, []))

    def _own_publishers(self, name: str) -> set[bytes]:
        return {
            bytes(info.endpoint_gid)[:16]
            for info in self.ros.node.get_publishers_info_by_topic(name)
            if self.ros.owns(info.node_name, info.node_namespace)
        }

    def _drop_publisher(self, name: str) -> list[bytes]:
        """Destroy the link's publisher of ``name``; what still waited in its lane."""
        pub = self._pubs.pop(name)
        self._own_gids -= pub.gids
        held = pub.lane.take_held()
        _destroy(self.ros.node.destroy_publisher, pub.handle)
        return held

    def _tap(self, entry: GraphTopic, event: MessageEvent, client: ClientId, latch: bool) -> None:
        """Forward what a local publisher published (the graph calls this on the loop)."""
        if self._closed or not self.rules.forwards(client, entry.name):
            return
        latched = latch or entry.publishers.get(client, False)
        pub = self._pubs.get(entry.name)
        if pub is None or pub.type_name != entry.msgtype.name or (latched and not pub.latched):
            held: list[bytes] = []
            if pub is not None:  # what waited goes on in the new lane if its type is the same
                dropped = self._drop_publisher(entry.name)
                held = dropped if pub.type_name == entry.msgtype.name else []
            pub = self._publisher(entry.name, entry.msgtype.name, latched)
            if pub is None:
                return
            for data in held:
                pub.lane.put(data)
        self._put(entry, pub, event)

    def _put(self, entry: GraphTopic, pub: _Pub, event: MessageEvent) -> None:
        if pub.latched_sent is event:
            return
        try:  # what came serialized (a sample, a record, a robot's CDR) goes on as it came
            data = event.wire
            if data is None:
                data = encode(self.graph.registry, entry.msgtype, event.msg)
        except KeyError as exc:
            self.episodes.log(
                logging.WARNING,
                f"enc:{entry.name}",
                "event=ros2_encode topic=%s %r",
                entry.name,
                exc,
            )
            return
        pub.lane.put(data)
        outflow = self._outflow
        if outflow is not None and outflow.congested:  # the publisher's reader waits for it
            self.graph.port.outflow.congested(outflow)
        if entry.latched is event:
            pub.latched_sent = event

    def _retire(self, offer: Offer) -> None:
        """Destroy ``offer`` once its last call is answered (``offers``)."""
        self._retired = {o for o in self._retired if o.handle is not None}
        self._retired.add(offer)
        offer.retire()

    def _offer(self, type_name: str, destroy: Callable[[Any], object]) -> Offer:
        return Offer(type_name, self.ros.executor, destroy)

    def _sweep_servers(self, serving: dict[str, str]) -> None:
        node = self.ros.node
        for name, server in list(self._servers.items()):
            if serving.get(name) != server.type_name:
                self._retire(self._servers.pop(name))
        for name, type_name in serving.items():
            if name in self._servers:
                continue
            ros_type = self._ros_type(name, type_name)
            if ros_type is None:
                continue
            offer = self._offer(type_name, node.destroy_service)
            offer.handle = node.create_service(
                ros_type,
                name,
                serve_to_ros(self, name, type_name, ros_type, offer),
                qos_profile=rclpy_profile(SERVICE_QOS),
                callback_group=self.ros.group,
            )
            self._servers[name] = offer

    def _sweep_action_servers(self, offered: dict[str, str]) -> None:
        for name, server in list(self._action_servers.items()):
            if offered.get(name) != server.type_name:
                self._retire(self._action_servers.pop(name))
        for name, type_name in offered.items():
            if name in self._action_servers:
                continue
            ros_type = self._ros_type(name, type_name)
            if ros_type is not None:
                offer = self._offer(type_name, lambda handle: handle.destroy())
                offer.handle = serve_action_to_ros(self, name, type_name, ros_type, offer)
                self._action_servers[name] = offer

    def _sweep_param_servers(self) -> None:
        """The parameter services of each local node with parameters, as a ROS 2 node's."""
        copies = self._params.nodes if self._params is not None else frozenset()
        local = {n for n in param_nodes(self.graph) if n not in copies and n != self.ros.fqn}
        node = self.ros.node
        for name in list(self._param_servers):
            if name not in local:
                for offer in self._param_servers.pop(name):
                    self._retire(offer)
        for name in local - self._param_servers.keys():
            offers = []
            for part, type_name in PARAM_SERVICES.items():
                ros_type = self._ros_type(f"{name}/{part}", type_name)
                if ros_type is None:
                    continue
                offer = self._offer(type_name, node.destroy_service)
                handler = partial(answer_param_request, self.graph, name, part)
                offer.handle = node.create_service(
                    ros_type,
                    f"{name}/{part}",
                    serve_to_ros(self, f"{name}/{part}", type_name, ros_type, offer, handler),
                    qos_profile=rclpy_profile(SERVICE_QOS),
                    callback_group=self.ros.group,
                )
                offers.append(offer)
            self._param_servers[name] = offers


def _report_qos(topic: str, role: str, profile: QosProfile) -> None:
    """Say which client QoS the link gave an rclpy endpoint (docs/ros2.md, "QoS")."""
    logger.info("event=ros2_qos topic=%s role=%s qos=%r", topic, role, profile.describe())


def _destroy(destroy: Any, handle: Any) -> None:
    try:
        destroy(handle)
    except Exception:  # the context is going: nothing left to destroy
        logger.debug("ros2 link: destroying %r failed", handle, exc_info=True)


@asynccontextmanager
async def open_ros2_link(
    graph: Graph, options: Ros2Options | None = None
) -> AsyncIterator[Ros2Link]:
    """Join ROS 2 with an rclpy node and link ``graph`` while the block runs.

    This is the one call an embedding program needs (docs/ros2.md)::

        async with open_ros2_link(graph, Ros2Options(node_name="robot_bridge")):
            await server.serve()

    Raises:
        Ros2Unavailable: rclpy cannot be imported (the text says what to install).
        RuntimeError: the event loop is not asyncio's.
    """
    options = options or Ros2Options()
    # rosbags' type store takes a while to build: not on the event loop
    await anyio.to_thread.run_sync(graph.registry.typestore)
    ros = await anyio.to_thread.run_sync(RosNode, options.node_name, options.namespace)
    # rosapi reports the running ROS, not the bundled definitions' distribution
    bundled, graph.ros_distro = graph.ros_distro, ros_distro() or graph.ros_distro
    async with anyio.create_task_group() as tg:
        link = Ros2Link(graph, ros, options)
        await tg.start(link.run)
        try:
            yield link
        finally:
            tg.cancel_scope.cancel()
            graph.ros_distro = bundled
