"""The in-memory robot graph as Python code in the same process sees it (the embedding API).

``Graph`` is the "robot that runs no ROS": ``create_publisher``,
``create_subscription``, ``create_service``, ``create_action_server``,
``params`` (the parameter store) and ``topic_names_and_types``
(docs/embedding.md). Every participant belongs to a node (``nodes``), which
rosapi reports. Sessions, links and the server drive the same graph through
its other face, ``Graph.port`` (``core.GraphCore``, the ``GraphPort`` of
``rwt_protocol.ports``).
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING

from rwt_protocol.names import resolve_name

from .actions import ActionEntry, LocalActionHandler
from .core import GraphCore
from .local import LocalActionServer, LocalPublisher, LocalService, LocalSubscription
from .nodes import DEFAULT_NODE, node_name
from .parameters.store import Parameters
from .services import Amend, CallerServiceHandler, LocalServiceHandler, ServiceEntry

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from rwt_protocol.ports import ClientId
    from rwt_protocol.qos import QosProfile

    from .clock import Clock
    from .safety.envelope import Envelope
    from .safety.rules import SafetyRules
    from .types import TypeRegistry

__all__ = ["Graph"]

Message = dict[str, object]


DEFAULT_ROS_DISTRO = "jazzy"
"""The ROS 2 distribution a graph reports with no running ROS: the one whose
definitions rwt bundles (``rwt_graph/interfaces``)."""


class Graph:
    """Topics, services, actions, parameters and nodes of one server.

    Args:
        registry: the message types; a ROS 2 registry by default. Its dialect is
            also the naming of the parameters (``params``).
        clock: time source; the system clock by default.
        safety: the safety rules every remote client's publish is held to
            (docs/safety.md); None: none (``use_safety`` adds them later).

    Raises:
        RulesError: ``safety`` does not fit the graph's types (``use_safety``).

    Attributes:
        params: the parameter store (``graph.params.set("/robot:speed", 1.0)``).
        nodes: the node of each participant.
        port: the graph's core, which sessions, links and the server drive
            (``GraphPort`` on behalf of a client id; the clock and the spawner
            of async handlers, ``use_clock`` and ``serving``). Not for embedding
            code: ``create_*`` and ``rwt.call_service`` are its API.
        taps: functions that see every published message (``topics.Tap``).
        type_checks: functions of links telling why they cannot carry a type
            (``GraphCore.type_warning``); a link adds one while it runs.
        ros_distro: the ROS distribution rosapi's ``get_ros_version`` reports:
            ``jazzy`` (what the bundled ROS 2 definitions match) until a link to a
            running ROS sets that ROS's own (docs/ros2.md).
    """

    def __init__(
        self,
        registry: TypeRegistry | None = None,
        *,
        clock: Clock | None = None,
        safety: SafetyRules | None = None,
    ) -> None:
        self.port = core = GraphCore(registry, clock=clock)
        # the core's containers themselves (never rebound), for code that reads the graph
        self.registry = core.registry
        self.topics = core.topics
        self.services = core.services
        self.actions = core.actions
        self.nodes = core.nodes
        self.taps = core.taps
        self.type_checks = core.type_checks
        self.params = Parameters(self.registry.dialect, nodes=self.nodes)
        self.ros_distro = DEFAULT_ROS_DISTRO
        if safety is not None:
            self.use_safety(safety)

    @property
    def safety(self) -> Envelope | None:
        """The safety envelope (``use_safety``), or None."""
        return self.port.envelope

    def use_safety(self, rules: SafetyRules) -> Envelope:
        """Hold every remote client's publish to ``rules`` from now on (docs/safety.md).

        In-process code and the links are not bound. The envelope holds each
        bounded topic as a publisher of its type (node ``/rwt_safety``); its
        dead-man timer runs while a server serves the graph.

        Returns:
            The envelope.

        Raises:
            RulesError: a rule does not fit the graph's types (an unknown type or
                field, a bound on a field that is not a number, a bad stop), a
                bounded topic exists with another type, or the graph has rules already.
        """
        from .safety.envelope import Envelope  # noqa: PLC0415  # only for graphs that use it

        envelope = Envelope(rules, self.registry)
        envelope.install(self.port)
        return envelope

    @property
    def clock(self) -> Clock:
        """The graph's time source now (``GraphCore.use_clock`` may swap it for a while)."""
        return self.port.clock

    def create_publisher(
        self,
        topic: str,
        type_name: str,
        *,
        latch: bool = False,
        node: str = DEFAULT_NODE,
        reserved: bool = False,
        qos: QosProfile | None = None,
    ) -> LocalPublisher:
        """Publish on ``topic`` from Python code in this process.

        Args:
            topic: topic name.
            type_name: message type, ``std_msgs/msg/String`` or ``std_msgs/String``.
            latch: transient-local durability: late subscribers get the last message.
            node: the node rosapi lists as the publisher (``/rwt`` by default).
            reserved: only in-process code may publish on the topic (``reserve_topic``).
            qos: the QoS offered on the topic (protocol 2.1.0's policies, D62-D65
                of docs/decisions.md): the topic's first publisher with one fixes
                it for every publisher; ``latch`` is then not read.

        Raises:
            InvalidTypeNameError, UnknownTypeError, GraphError: as ``advertise``; a bad node name.
        """
        name = resolve_name(topic)
        if reserved:
            self.reserve_topic(name)
        latch = latch and qos is None
        with self._participant(node) as client:
            self.port.advertise(client, name, type_name, latch=latch, qos=qos)
        return LocalPublisher(self.port, client, self.topics[name], latch=latch)

    def create_subscription(
        self,
        topic: str,
        callback: Callable[[Message], None],
        type_name: str | None = None,
        *,
        node: str = DEFAULT_NODE,
        qos: QosProfile | None = None,
    ) -> LocalSubscription:
        """Call ``callback(msg)`` with each message on ``topic``, in this process.

        ``msg`` is the message as a dict in the internal form (``bytes`` for
        ``uint8[]``; other numeric arrays are lists, or read-only numpy arrays
        when a client sent them as CBOR typed arrays, D27); treat it as
        read-only, it is shared with other subscribers.
        ``node`` is the node rosapi lists as the subscriber. ``qos``: what it
        asks of the topic (D63-D65): a transient-local one gets the messages
        the topic keeps at once; one incompatible with the topic's offer gets
        nothing while it stands. The callback runs as each message is
        published, so no queue holds it: depth, reliability and lifespan
        bound nothing here.

        Raises:
            GraphError, InvalidTypeNameError, UnknownTypeError: as ``subscribe``; a bad node name.
        """
        with self._participant(node) as client:
            subscription = LocalSubscription(self.port, client, resolve_name(topic), callback)
            self.port.subscribe(client, topic, type_name, subscription, qos=qos)
        return subscription

    def create_service(
        self,
        service: str,
        type_name: str,
        handler: LocalServiceHandler,
        *,
        node: str = DEFAULT_NODE,
    ) -> LocalService:
        """Provide ``service`` from Python code in this process.

        Args:
            service: service name.
            type_name: ``std_srvs/srv/SetBool`` or ``std_srvs/SetBool``.
            handler: ``handler(request) -> response``, a plain or async function of
                dicts; missing response fields get defaults; an exception fails the
                call with its text (D4). Async handlers need a running server.
            node: the node rosapi lists as the provider.

        Raises:
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
            GraphError: a bad node name.
        """
        return self._local_service(service, type_name, node, handler=handler)

    def create_caller_service(
        self,
        service: str,
        type_name: str,
        handler: CallerServiceHandler,
        *,
        node: str = DEFAULT_NODE,
        amend: Amend | None = None,
    ) -> LocalService:
        """Like ``create_service``, with ``handler(caller, request)`` told who calls.

        ``caller`` is the calling participant (a connection's id); rosapi uses it
        to show each client only the names it may see. ``amend(response)`` rewrites
        each checked response before it is sent.

        Raises:
            InvalidTypeNameError, UnknownTypeError, GraphError: as ``create_service``.
        """
        return self._local_service(service, type_name, node, caller_handler=handler, amend=amend)

    def _local_service(
        self,
        service: str,
        type_name: str,
        node: str,
        *,
        handler: LocalServiceHandler | None = None,
        caller_handler: CallerServiceHandler | None = None,
        amend: Amend | None = None,
    ) -> LocalService:
        srvtype = self.registry.service(type_name)
        name = resolve_name(service)
        with self._participant(node) as client:
            entry = ServiceEntry(
                name,
                service,
                srvtype,
                client,
                handler=handler,
                caller_handler=caller_handler,
                amend=amend,
            )
            self.services.advertise(entry)
        return LocalService(self.port, client, name)

    def create_action_server(
        self,
        action: str,
        type_name: str,
        handler: LocalActionHandler,
        *,
        node: str = DEFAULT_NODE,
    ) -> LocalActionServer:
        """Provide ``action`` from Python code in this process.

        Args:
            action: action name.
            type_name: ``example_interfaces/action/Fibonacci`` or the short form.
            handler: ``async def handler(goal, context) -> result``; it may call
                ``context.publish_feedback(dict)`` and should honour
                ``context.cancel_requested`` by raising ``GoalCanceledError``.
            node: the node rosapi lists as the action server.

        Raises:
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
            GraphError: a bad node name.
        """
        actiontype = self.registry.action(type_name)
        name = resolve_name(action)
        with self._participant(node) as client:
            self.port.offer_action(
                ActionEntry(name, action, type_name, actiontype, client, handler=handler)
            )
        return LocalActionServer(self.port, client, name)

    def topic_names_and_types(self) -> list[tuple[str, str]]:
        """Every topic in use with its canonical type, sorted by name."""
        return sorted((name, t.msgtype.name) for name, t in self.topics.items())

    def reserve_topic(self, name: str) -> None:
        """Keep topic ``name`` (or, ending in ``*``, every topic starting so) for in-process code.

        A client's ``advertise`` or ``publish`` on it is refused, so it cannot
        forge what the server publishes there (docs/limits.md).
        """
        self.port.reserve_topic(name)

    @contextlib.contextmanager
    def _participant(self, node: str) -> Iterator[ClientId]:
        """A new in-process participant of ``node``, forgotten if its registration fails."""
        checked = node_name(node)
        client = self.port.local_client()
        self.nodes.bind(client, checked)
        try:
            yield client
        except BaseException:
            self.nodes.forget(client)
            raise
