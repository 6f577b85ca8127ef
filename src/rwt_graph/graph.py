"""The in-memory robot graph: what every session and in-process participant shares.

``Graph`` implements ``rwt_protocol.ports.GraphPort`` for sessions and offers an
embedding API for Python code in the same process (the "robot that runs no ROS"):
``create_publisher``, ``create_subscription``, ``create_service``,
``create_action_server``, ``params`` (the parameter store) and
``topic_names_and_types``. Every participant belongs to a node (``nodes``), which
rosapi reports.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
from functools import partial
from typing import TYPE_CHECKING

from rwt_protocol.errors import GraphError
from rwt_protocol.names import resolve_name
from rwt_protocol.ports import (
    ActionProvider,
    ClientId,
    GoalDone,
    GoalFeedback,
    GoalHandle,
    MessageEvent,
    Pending,
    ServiceProvider,
    ServiceReply,
    TopicSink,
)

from .actions import (
    CANCEL_GOAL_TYPE,
    ActionEntry,
    Actions,
    LocalActionHandler,
    cancel_goals_handler,
    cancel_service_name,
)
from .calls import LOCAL_PREFIX, Spawner, guarded, is_local
from .clock import Clock, SystemClock
from .local import LocalActionServer, LocalPublisher, LocalService, LocalSubscription
from .nodes import DEFAULT_NODE, Nodes, node_name
from .params import Parameters
from .ratelog import EpisodeLog
from .services import Amend, CallerServiceHandler, LocalServiceHandler, ServiceEntry, Services
from .topics import Tap, Topic
from .types import Dialect, MessageType, TypeRegistry

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

__all__ = ["Graph"]

logger = logging.getLogger("rwt.graph")
_episodes = EpisodeLog(logger)  # a peer can trigger these per message

Message = dict[str, object]


class Graph:
    """Topics, services, actions, parameters and nodes of one server.

    Args:
        registry: the message types; a ROS 2 registry by default. Its dialect is
            also the naming of the parameters (``params``).
        clock: time source; the system clock by default.

    Attributes:
        params: the parameter store (``graph.params.set("/robot:speed", 1.0)``).
        nodes: the node of each participant.
        taps: functions that see every published message (``topics.Tap``).
        type_checks: functions of links telling why they cannot carry a type
            (``type_warning``); a link adds one while it runs.
    """

    def __init__(self, registry: TypeRegistry | None = None, *, clock: Clock | None = None) -> None:
        self.registry = registry or TypeRegistry(Dialect.ROS2)
        self.clock: Clock = clock or SystemClock()
        self.topics: dict[str, Topic] = {}
        self.spawner: Spawner | None = None
        self.services = Services(self.registry, self.clock, lambda: self.spawner)
        self.actions = Actions(self.registry, self.clock, lambda: self.spawner)
        self.nodes = Nodes()
        self.params = Parameters(self.registry.dialect)
        self._local_ids = itertools.count(1)
        self._reserved_topics: set[str] = set()
        self._reserved_prefixes: tuple[str, ...] = ()
        self.taps: list[Tap] = []
        self.type_checks: list[Callable[[str], str | None]] = []
        # client -> the topics it publishes or subscribes to, so that its release
        # costs what it holds, not the size of the graph (a peer's thousands of
        # entities leave one by one: docs/limits.md, "Zenoh peers")
        self._held: dict[ClientId, set[str]] = {}

    # ---- GraphPort ------------------------------------------------------------

    def advertise(self, client: ClientId, topic: str, type_name: str, *, latch: bool) -> str:
        """Register ``client`` as a publisher of ``topic`` (spec 3.3.1).

        Returns:
            The canonical type name.

        Raises:
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
            GraphError: the topic exists with another type.
        """
        msgtype = self.registry.message(type_name)
        self._check_reserved(client, topic)
        entry = self._topic(topic, msgtype)
        entry.publishers[client] = latch or entry.publishers.get(client, False)
        self._hold(client, entry.name)
        self.nodes.name_of(client)
        return entry.msgtype.name

    def unadvertise(self, client: ClientId, topic: str) -> None:
        """Remove ``client`` as a publisher; the topic goes when nobody uses it."""
        entry = self.topics.get(resolve_name(topic))
        if entry is not None:
            entry.remove_publisher(client)
            self._unhold(client, entry)
            self._collect(entry)

    def publish(
        self, client: ClientId, topic: str, msg: object, *, latch: bool = False, path: str = "$"
    ) -> tuple[str, ...]:
        """Validate ``msg`` against the topic's type and deliver it (spec 3.3.3).

        Publishing without advertising is allowed once the topic's type is known
        (REF §2.3); the client then counts as a publisher until it leaves.

        Args:
            client: the publishing participant.
            topic: topic name (any spelling).
            msg: the message as decoded JSON (a dict).
            latch: keep the message for later subscribers (D13).
            path: JSON path of ``msg``, for error texts.

        Returns:
            Paths of the fields that were filled with defaults (D7).

        Raises:
            GraphError: the topic's type is unknown.
            FieldError: ``msg`` does not fit the type (D9).
        """
        entry, converted, missing = self.convert_publish(topic, msg, path=path)
        if client not in entry.publishers:  # the first publish of this client: check it once
            self._check_reserved(client, entry.name)
            self._hold(client, entry.name)
            self.nodes.name_of(client)
        latched = entry.publishers.setdefault(client, False) or latch
        self._send(entry, converted, latch=latched, client=client)
        return missing

    def convert_publish(
        self, topic: str, msg: object, *, path: str = "$"
    ) -> tuple[Topic, Message, tuple[str, ...]]:
        """Find ``topic`` and convert ``msg`` to its type: the check half of ``publish``.

        Returns:
            The topic's entry, the message in the internal form and the paths
            of the fields filled with defaults (D7).

        Raises:
            GraphError: the topic's type is unknown.
            FieldError: ``msg`` does not fit the type (D9).
        """
        # Names are kept resolved, so a name found as given needs no resolving.
        entry = self.topics.get(topic)
        if entry is None:
            entry = self.topics.get(resolve_name(topic))
            if entry is None:
                raise GraphError(f"{topic} has no type yet (advertise it first)")
        msgtype = entry.msgtype
        converted = msgtype.fast(msg)  # complete and well-typed: no clock, no context
        if converted is not None:
            return entry, converted, ()
        result = msgtype.from_json(msg, path=path, now=self.clock.wall())
        return entry, result.msg, result.missing

    def subscribe(
        self, client: ClientId, topic: str, type_name: str | None, sink: TopicSink
    ) -> str:
        """Attach ``sink`` as ``client``'s subscriber of ``topic`` (spec 3.3.4).

        A new subscriber receives the latched message, if any, at once (D13).

        Returns:
            The canonical type name.

        Raises:
            GraphError: no type given and the topic is unknown, or a conflicting type.
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
        """
        name = resolve_name(topic)
        if type_name is None:
            entry = self.topics.get(name)
            if entry is None:
                raise GraphError(f"cannot infer the type of {topic}: give a type")
        else:
            entry = self._topic(name, self.registry.message(type_name))
        is_new = client not in entry.subscribers
        entry.subscribers[client] = sink
        self._hold(client, entry.name)
        self.nodes.name_of(client)
        if is_new and entry.latched is not None:
            sink.on_message(entry.latched)
        return entry.msgtype.name

    def unsubscribe(self, client: ClientId, topic: str) -> None:
        """Detach ``client`` from ``topic``."""
        entry = self.topics.get(resolve_name(topic))
        if entry is not None:
            entry.subscribers.pop(client, None)
            self._unhold(client, entry)
            self._collect(entry)

    def release(self, client: ClientId) -> None:
        """Drop every registration of ``client`` (it disconnected).

        Its services and actions go, failing their pending callers (D15); its own
        calls and goals are forgotten. Each step runs even if an earlier one
        failed (logged as a bug), so nothing of the client stays registered.
        Its cost is proportional to what ``client`` holds, not to the graph's size.
        """
        for name in sorted(self._held.pop(client, ())):
            entry = self.topics.get(name)
            if entry is not None:
                guarded(f"releasing {client} from {name}", partial(self._drop, entry, client))
        guarded(f"releasing the services of {client}", lambda: self.services.release(client))
        guarded(f"releasing the actions of {client}", lambda: self.actions.release(client))
        guarded(f"forgetting the node of {client}", lambda: self.nodes.forget(client))

    def type_warning(self, type_name: str) -> str | None:
        """Why a link cannot carry ``type_name`` (the package to install), or None.

        The session reports it as a warning status after an advertise or a
        subscribe that succeeded here: the graph has the type, the other
        middleware cannot carry it (docs/ros2.md).
        """
        for check in self.type_checks:
            warning = check(type_name)
            if warning:
                return warning
        return None

    def _drop(self, entry: Topic, client: ClientId) -> None:
        entry.remove_publisher(client)
        entry.subscribers.pop(client, None)
        self._collect(entry)

    def _hold(self, client: ClientId, name: str) -> None:
        held = self._held.get(client)
        if held is None:
            held = self._held[client] = set()
        held.add(name)

    def _unhold(self, client: ClientId, entry: Topic) -> None:
        """Forget that ``client`` holds ``entry`` once it neither publishes nor subscribes."""
        if client in entry.publishers or client in entry.subscribers:
            return
        held = self._held.get(client)
        if held is not None:
            held.discard(entry.name)
            if not held:
                del self._held[client]

    def fail_pending(self, reason: str) -> None:
        """Answer every pending service call and goal with a failure (D4; server shutdown)."""
        for service in list(self.services.entries.values()):
            service.end_all(reason)
        for action in list(self.actions.entries.values()):
            action.end_all(reason)

    # ---- ServicePort: services and actions of clients ---------------------------

    def advertise_service(
        self, client: ClientId, service: str, type_name: str, provider: ServiceProvider
    ) -> str:
        """Offer ``service`` provided by a client session (spec 3.3.6, D15).

        Raises:
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
        """
        srvtype = self.registry.service(type_name)
        entry = ServiceEntry(resolve_name(service), service, srvtype, client, provider=provider)
        self.services.advertise(entry)
        self.nodes.name_of(client)
        return srvtype.name

    def unadvertise_service(self, client: ClientId, service: str) -> None:
        """Withdraw ``service``; its pending calls fail (spec 3.3.7, D15).

        Raises:
            GraphError: ``client`` does not provide it.
        """
        self.services.unadvertise(client, service)

    def call_service(
        self,
        client: ClientId,
        service: str,
        args: object,
        reply: ServiceReply,
        *,
        type_name: str | None = None,
        path: str = "$",
    ) -> Pending:
        """Call ``service``; ``reply(result, values)`` runs once (spec 3.3.8, D4).

        ``args`` is an object, a list (positional, D25) or None. For an in-process
        service with a sync handler, ``reply`` runs before this returns.

        Raises:
            GraphError: the service does not exist or has another type.
            FieldError: ``args`` does not fit the request.
        """
        return self.services.call(client, service, args, reply, type_name=type_name, path=path)

    def service_response(
        self,
        client: ClientId,
        service: str,
        request_id: str,
        result: bool,
        values: object,
        *,
        path: str = "$",
    ) -> None:
        """Answer a forwarded request (spec 3.3.9); see ``Services.respond`` for errors."""
        self.services.respond(client, service, request_id, result, values, path=path)

    def advertise_action(
        self, client: ClientId, action: str, type_name: str, provider: ActionProvider
    ) -> str:
        """Offer ``action`` provided by a client session (spec 3.3.10, D15).

        Raises:
            InvalidTypeNameError, UnknownTypeError: ``type_name`` is bad or unknown.
        """
        actiontype = self.registry.action(type_name)
        name = resolve_name(action)
        self._offer_action(
            ActionEntry(name, action, type_name, actiontype, client, provider=provider)
        )
        self.nodes.name_of(client)
        return actiontype.name

    def unadvertise_action(self, client: ClientId, action: str) -> None:
        """Withdraw ``action`` and its cancel service; its goals abort (spec 3.3.11).

        Raises:
            GraphError: ``client`` does not provide it.
        """
        entry = self.actions.owned(client, action)
        self.actions.unadvertise(client, action)
        with contextlib.suppress(GraphError):  # replaced by another participant meanwhile
            self.services.unadvertise(client, cancel_service_name(entry.name))

    def send_action_goal(
        self,
        client: ClientId,
        action: str,
        action_type: str,
        args: object,
        done: GoalDone,
        feedback: GoalFeedback | None,
        *,
        path: str = "$",
    ) -> GoalHandle:
        """Send a goal; ``done(status, result, values)`` runs once (spec 3.3.12, D4, D18).

        Raises:
            GraphError: the action does not exist.
            FieldError: ``args`` does not fit the goal.
        """
        return self.actions.send_goal(client, action, action_type, args, done, feedback, path=path)

    def action_feedback(
        self, client: ClientId, action: str, goal_id: str, values: object, *, path: str = "$"
    ) -> None:
        """Feedback from the provider (spec 3.3.14); see ``Actions.feedback``."""
        self.actions.feedback(client, action, goal_id, values, path=path)

    def action_result(
        self,
        client: ClientId,
        action: str,
        goal_id: str,
        status: int | None,
        result: bool,
        values: object,
        *,
        path: str = "$",
    ) -> None:
        """The provider's result (spec 3.3.15, D18); see ``Actions.result``."""
        self.actions.result(client, action, goal_id, status, result, values, path=path)

    # ---- embedding API ---------------------------------------------------------

    def create_publisher(
        self,
        topic: str,
        type_name: str,
        *,
        latch: bool = False,
        node: str = DEFAULT_NODE,
        reserved: bool = False,
    ) -> LocalPublisher:
        """Publish on ``topic`` from Python code in this process.

        Args:
            topic: topic name.
            type_name: message type, ``std_msgs/msg/String`` or ``std_msgs/String``.
            latch: transient-local durability: late subscribers get the last message.
            node: the node rosapi lists as the publisher (``/rwt`` by default).
            reserved: only in-process code may publish on the topic (``reserve_topic``).

        Raises:
            InvalidTypeNameError, UnknownTypeError, GraphError: as ``advertise``; a bad node name.
        """
        name = resolve_name(topic)
        if reserved:
            self.reserve_topic(name)
        with self._participant(node) as client:
            self.advertise(client, name, type_name, latch=latch)
        return LocalPublisher(self, client, name, self.topics[name].msgtype, latch=latch)

    def create_subscription(
        self,
        topic: str,
        callback: Callable[[Message], None],
        type_name: str | None = None,
        *,
        node: str = DEFAULT_NODE,
    ) -> LocalSubscription:
        """Call ``callback(msg)`` with each message on ``topic``, in this process.

        ``msg`` is the message as a dict in the internal form (``bytes`` for
        ``uint8[]``; other numeric arrays are lists, or read-only numpy arrays
        when a client sent them as CBOR typed arrays, D27); treat it as
        read-only, it is shared with other subscribers.
        ``node`` is the node rosapi lists as the subscriber.

        Raises:
            GraphError, InvalidTypeNameError, UnknownTypeError: as ``subscribe``; a bad node name.
        """
        with self._participant(node) as client:
            subscription = LocalSubscription(self, client, resolve_name(topic), callback)
            self.subscribe(client, topic, type_name, subscription)
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
        return LocalService(self, client, name)

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
            self._offer_action(
                ActionEntry(name, action, type_name, actiontype, client, handler=handler)
            )
        return LocalActionServer(self, client, name)

    def _offer_action(self, entry: ActionEntry) -> None:
        # ROS 2 action servers also answer <action>/_action/cancel_goal, which
        # roslib's Action.cancelAllGoals calls; it belongs to the same provider.
        self.actions.advertise(entry)
        service = cancel_service_name(entry.name)
        srvtype = self.registry.service(CANCEL_GOAL_TYPE)
        handler = cancel_goals_handler(entry)
        self.services.advertise(
            ServiceEntry(service, service, srvtype, entry.owner, handler=handler)
        )

    def topic_names_and_types(self) -> list[tuple[str, str]]:
        """Every topic in use with its canonical type, sorted by name."""
        return sorted((name, t.msgtype.name) for name, t in self.topics.items())

    # ---- internals ---------------------------------------------------------------

    def publish_local(self, client: ClientId, topic: str, msg: Message, *, latch: bool) -> None:
        """Deliver an already-converted message from an in-process publisher."""
        entry = self.topics.get(topic)
        if entry is None or client not in entry.publishers:
            raise GraphError(f"the publisher of {topic} was closed")
        self._send(entry, msg, latch=latch, client=client)

    def _send(self, entry: Topic, msg: Message, *, latch: bool, client: ClientId) -> None:
        event = MessageEvent(
            entry.name,
            entry.msgtype.name,
            msg,
            self.clock.monotonic(),
            stamp=self.clock.wall(),
            codec=self.registry.codec(entry.msgtype),
        )
        entry.fan_out(event, latch=latch, client=client)
        for tap in self.taps:
            try:
                tap(entry, event, client, latch)
            except Exception:  # a broken tap must not fail the publisher
                _episodes.log(
                    logging.ERROR,
                    f"tap_failed {entry.name}",
                    "tap of %s failed",
                    entry.name,
                    exc_info=True,
                )

    def _topic(self, topic: str, msgtype: MessageType) -> Topic:
        name = resolve_name(topic)
        entry = self.topics.get(name)
        if entry is None:
            entry = self.topics[name] = Topic(name, msgtype)
        else:
            entry.check_type(msgtype)
        return entry

    def _collect(self, entry: Topic) -> None:
        if not entry.in_use and self.topics.get(entry.name) is entry:
            del self.topics[entry.name]

    def reserve_topic(self, name: str) -> None:
        """Keep topic ``name`` (or, ending in ``*``, every topic starting so) for in-process code.

        A client's ``advertise`` or ``publish`` on it is refused, so it cannot
        forge what the server publishes there (docs/limits.md).
        """
        if name.endswith("*"):
            self._reserved_prefixes += (resolve_name(name[:-1]) if name[:-1] else "/",)
        else:
            self._reserved_topics.add(resolve_name(name))

    def _check_reserved(self, client: ClientId, topic: str) -> None:
        if is_local(client):
            return
        name = resolve_name(topic)
        if name in self._reserved_topics or name.startswith(self._reserved_prefixes):
            raise GraphError(f"topic {topic} is reserved by the server")

    def _local_client(self) -> ClientId:
        return f"{LOCAL_PREFIX}{next(self._local_ids)}"

    @contextlib.contextmanager
    def _participant(self, node: str) -> Iterator[ClientId]:
        """A new in-process participant of ``node``, forgotten if its registration fails."""
        checked = node_name(node)
        client = self._local_client()
        self.nodes.bind(client, checked)
        try:
            yield client
        except BaseException:
            self.nodes.forget(client)
            raise

    def local_client(self) -> ClientId:
        """A fresh participant id for in-process code calling services or actions."""
        return self._local_client()
