"""Actions across processes: the Zenoh link's half for ROS 2 actions (``actions``' mapping).

Provider side: each local action server gets the ``send_goal`` and ``get_result``
queryables and their tokens (its ``cancel_goal`` service is in the graph's
service table, shared like any service), and the ``feedback`` and ``status``
publishers with theirs: a ROS 2 action client waits for all three services and a
feedback publisher (rcl_action ``rcl_action_server_is_available``), and ``ros2
action list`` finds actions by their feedback topics (rcl_action graph.c). A
``send_goal`` query starts a goal in the graph for the remote caller; its feedback
is put on the ``feedback`` key; a ``get_result`` query is answered when the goal
ends; a ``cancel_goal`` query naming one of these goals cancels it. The
``status`` topic carries the state of those goals (``GoalStatusArray``), as a
ROS 2 action server publishes it on each change; goals of local callers have
rosbridge ids, not UUIDs, and are not in it.

Caller side: a remote ``send_goal`` token makes the action a graph action whose
provider forwards each goal as those queries; feedback samples reach the goal's
caller; when the remote server's token goes, its goals abort (D15).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

import zenoh.ext

import zenoh
from rwt_graph.actions import CANCEL_GOAL_TYPE
from rwt_graph.calls import guarded
from rwt_graph.feed import EntityKind as GraphKind
from rwt_protocol.errors import RwtError
from rwt_protocol.ports import GoalStatus

from .actions import (
    CANCEL_SUFFIX,
    FEEDBACK_SUFFIX,
    GET_RESULT_SUFFIX,
    SEND_GOAL_SUFFIX,
    ActionWire,
    stamp_of,
)
from .payload import (
    decode_message,
    encode_message,
    message_hash,
    named_service_hash,
    service_hash,
)
from .wire import (
    LATCHED_QOS,
    SERVICES_QOS,
    VOLATILE_QOS,
    Topic,
    WireError,
    dds_type_name,
    topic_keyexpr,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.mirror import RemoteEntity
    from rwt_protocol.ops import CancelActionGoal, SendActionGoal
    from rwt_protocol.ports import ClientId

    from .link import OwnPublisher, ZenohLink

__all__ = ["ActionLink"]

logger = logging.getLogger("rwt.zenoh")

MAX_SERVED = 10_000
"""Goals of remote callers held at once (running, or ended and not yet fetched)."""
RESULT_TIMEOUT_S = 24 * 3600.0
"""How long a caller's ``get_result`` query waits for its goal to end."""
STATUS_SUFFIX = "/_action/status"
GOAL_STATUS_ARRAY = "action_msgs/msg/GoalStatusArray"

FEEDBACK_SETTLE_S = 0.05
"""Seconds a remote goal's result waits, once it came, for the goal's feedback to be
quiet before the goal ends for its caller here (``MAX_FEEDBACK_SETTLE_S`` at most). The
server puts every feedback before it answers the result, but the two take separate
ways through Zenoh (a subscription, a query's reply) and this process's Zenoh threads,
which wait for the interpreter in turn: the result came 5-10 ms before the last feedback
in about one run in five of tests/zenoh/test_serve_zenoh.py, and a goal that ended
refuses its late feedback (docs/zenoh.md, "Reliability")."""
MAX_FEEDBACK_SETTLE_S = 0.5
"""The longest a result waits for its goal's feedback to be quiet (``FEEDBACK_SETTLE_S``)."""

MAX_RESULT_WAITERS = 16
"""``get_result`` queries one served goal keeps waiting for its result at most (a
remote caller asks once, or again after a timeout); past it a query is answered with
an error at once, so a peer repeating it cannot grow the link's memory. A peer that
queries first could so crowd out the goal's caller, as it could cancel the goal: the
action services are open to every peer, as in ROS 2."""


@dataclass(eq=False)
class _Served:
    """A goal a remote caller sent to a local action server."""

    action: str
    wire: ActionWire
    accepted_at: float  # seconds since the epoch
    handle: Any = None  # the graph's GoalHandle
    status: GoalStatus = GoalStatus.EXECUTING  # the provider has it at once
    outcome: tuple[GoalStatus, bool, object] | None = None
    waiting: list[Any] = field(default_factory=list)  # get_result queries


@dataclass(eq=False)
class _Offer:
    """A local action server as the network sees it."""

    owner: ClientId
    handles: list[Any]  # each service's queryable and liveliness token
    feedback: OwnPublisher
    status: OwnPublisher


class _RemoteAction:
    """The provider of a remote action in the graph: forwards each goal as queries."""

    def __init__(self, link: ActionLink, client: ClientId, action: str, wire: ActionWire) -> None:
        self.link = link
        self.client = client
        self.action = action
        self.wire = wire

    def on_action_goal(self, goal: SendActionGoal) -> None:
        """Send the goal (``args`` in the graph's internal form)."""
        self.link.send_remote_goal(self, str(goal.id), goal.args)

    def on_action_cancel(self, cancel: CancelActionGoal) -> None:
        """Ask the remote server to cancel."""
        self.link.cancel_remote_goal(self, str(cancel.id))

    def on_action_lost(self, action: str, reason: str) -> None:
        """A local server replaced the remote one here."""
        logger.info("event=zenoh_action_shadowed action=%s reason=%r", action, reason)


class ActionLink:
    """The action half of a ``ZenohLink`` (see the module text)."""

    def __init__(self, link: ZenohLink) -> None:
        self.link = link
        self._wires: dict[str, ActionWire] = {}
        self._offers: dict[str, _Offer] = {}
        self._served: dict[bytes, _Served] = {}
        self._status_due: set[str] = set()  # actions whose status is to be published
        self._feedback_subs: dict[str, Any] = {}  # by key expression
        self._feedback_of: dict[ClientId, str] = {}  # a mirrored action's remote -> its key
        self._unheld_of: dict[str, str] = {}  # a feedback key -> its topic in never_held
        self._calling: dict[bytes, tuple[_RemoteAction, str]] = {}
        self._fed: dict[bytes, float] = {}  # a goal sent from here -> its last feedback (s)

    def wire(self, type_name: str) -> ActionWire:
        """The wire of an action type (cached)."""
        wire = self._wires.get(type_name)
        if wire is None:
            registry = self.link.graph.registry
            wire = self._wires[type_name] = ActionWire(registry, registry.action(type_name))
        return wire

    def _key(self, name: str, wire: ActionWire, part: str, hash_text: str = "*") -> str:
        return topic_keyexpr(self.link.domain_id, name, wire.dds_type(part), hash_text)

    def _call(
        self,
        provider: _RemoteAction,
        goal_id: str,
        part: str,
        payload: bytes | bytearray,
        answer: Callable[[bool, object], None],
        timeout_s: float,
    ) -> None:
        """Call the remote server's ``part`` service as the goal's caller's client of it.

        ``part`` is ``SendGoal``, ``GetResult`` or ``CancelGoal``.
        """
        link = self.link
        graph = link.graph
        entry = graph.actions.entries.get(provider.action)
        goal = None if entry is None else entry.goals.get(goal_id)
        node = link.clients.caller_node(None if goal is None else goal.caller)
        if part == "CancelGoal":
            name, dds_type = provider.action + CANCEL_SUFFIX, dds_type_name(CANCEL_GOAL_TYPE)
            hash_text = service_hash(graph.registry, graph.registry.service(CANCEL_GOAL_TYPE))
            key = topic_keyexpr(link.domain_id, name, dds_type, "*")
        else:
            suffix = SEND_GOAL_SUFFIX if part == "SendGoal" else GET_RESULT_SUFFIX
            name, dds_type = provider.action + suffix, provider.wire.dds_type(part)
            hash_text = self._hash(provider.wire, part)
            key = self._key(name, provider.wire, part)
        attachment = link.clients.attachment(node, name, dds_type, hash_text)
        link.query(key, payload, answer, timeout_s, attachment)

    def _hash(self, wire: ActionWire, part: str) -> str:
        """The RIHS01 of an action's part: its two services' hash, its feedback message's."""
        name, registry = f"{wire.actiontype.name}_{part}", self.link.graph.registry
        if part in ("SendGoal", "GetResult"):
            return named_service_hash(registry, name)
        return message_hash(registry, name)

    # ---- provider side ------------------------------------------------------------

    def sweep(self) -> None:
        """Offer each local action server; withdraw the ones gone (``ZenohLink.outward``)."""
        wanted = self.link.outward.owners(GraphKind.ACTION)
        for name in list(self._offers):
            entry = wanted.get(name)
            if entry is None or entry.client != self._offers[name].owner:
                self._withdraw(name)
        for name, entry in wanted.items():
            if name not in self._offers:
                try:
                    self._offer(name, entry.client, entry.type_name)
                except (RwtError, WireError) as exc:
                    logger.debug("zenoh link: action %s is not shared: %s", name, exc)

    def _offer(self, name: str, owner: ClientId, type_name: str) -> None:
        link = self.link
        wire = self.wire(type_name)
        node = link.graph.nodes.name_of(owner)
        handles: list[Any] = []
        for suffix, part, handler in (
            (SEND_GOAL_SUFFIX, "SendGoal", self._on_send_goal),
            (GET_RESULT_SUFFIX, "GetResult", self._on_get_result),
        ):
            topic = Topic(name + suffix, wire.dds_type(part), self._hash(wire, part), SERVICES_QOS)
            handles += link.declare_service(node, topic, self._on_query_thread(handler, name, wire))
        part = "FeedbackMessage"
        feedback = Topic(
            name + FEEDBACK_SUFFIX, wire.dds_type(part), self._hash(wire, part), VOLATILE_QOS
        )
        status = Topic(
            name + STATUS_SUFFIX,
            dds_type_name(GOAL_STATUS_ARRAY),
            message_hash(link.graph.registry, GOAL_STATUS_ARRAY),
            LATCHED_QOS,
        )
        self._offers[name] = _Offer(
            owner,
            handles,
            link.declare_publisher(node, feedback, block=True),
            link.declare_publisher(node, status),
        )

    def _on_query_thread(
        self, handler: Callable[[str, ActionWire, zenoh.Query], None], name: str, wire: ActionWire
    ) -> Callable[[zenoh.Query], None]:
        def on_query(query: zenoh.Query) -> None:  # a Zenoh thread
            self.link.soon(handler, name, wire, query)

        return on_query

    def _withdraw(self, name: str) -> None:
        offer = self._offers.pop(name)
        for handle in offer.handles:
            guarded("undeclaring an action's entity", handle.undeclare)
        offer.feedback.undeclare()
        offer.status.undeclare()

    def _on_send_goal(self, action: str, wire: ActionWire, query: zenoh.Query) -> None:
        link = self.link
        goal_id = b""
        try:
            goal_id, goal = wire.read_send_goal(_payload(query))
            if len(self._served) >= MAX_SERVED or goal_id in self._served:
                link.reply(query, wire.accepted(False, link.graph.clock.wall()))
                return
            served = self._served[goal_id] = _Served(action, wire, link.graph.clock.wall())
            served.handle = link.graph.port.send_action_goal(
                link.caller,
                action,
                goal,
                partial(self._goal_done, goal_id),
                partial(self._goal_feedback, action, wire, goal_id),
            )
            link.reply(query, wire.accepted(True, served.accepted_at))
            self._status_changed(action)
        except (RwtError, WireError) as exc:
            self._served.pop(goal_id, None)
            query.reply_err(f"action {action} refused the goal: {exc}")
        finally:
            query.drop()  # type: ignore[no-untyped-call]

    def _goal_feedback(
        self, action: str, wire: ActionWire, goal_id: bytes, msg: dict[str, object]
    ) -> None:
        offer = self._offers.get(action)
        if offer is not None:  # reliable: lost to no full queue, and before the result
            self.link.put_queued(offer.feedback, wire.feedback(goal_id, msg))

    def _goal_done(self, goal_id: bytes, status: GoalStatus, result: bool, values: object) -> None:
        served = self._served.get(goal_id)
        if served is None:
            return
        served.outcome = (status, result, values)
        served.status = status
        self._status_changed(served.action)
        waiting, served.waiting = served.waiting, []
        for query in waiting:
            self._answer(goal_id, served, query)

    def _on_get_result(self, action: str, wire: ActionWire, query: zenoh.Query) -> None:
        try:
            goal_id = wire.read_get_result(_payload(query))
        except WireError as exc:
            query.reply_err(str(exc))
            query.drop()  # type: ignore[no-untyped-call]
            return
        served = self._served.get(goal_id)
        if served is None:
            query.reply_err(f"action {action}: unknown goal")
            query.drop()  # type: ignore[no-untyped-call]
        elif served.outcome is None and len(served.waiting) >= MAX_RESULT_WAITERS:
            query.reply_err(
                f"action {action}: {MAX_RESULT_WAITERS} get_result queries wait for this goal"
            )
            query.drop()  # type: ignore[no-untyped-call]
        elif served.outcome is None:
            served.waiting.append(query)
        else:
            self._answer(goal_id, served, query)

    def _answer(self, goal_id: bytes, served: _Served, query: zenoh.Query) -> None:
        assert served.outcome is not None
        status, result, values = served.outcome
        self._served.pop(goal_id, None)
        link = self.link
        payload: bytes | None = None
        try:
            if result and isinstance(values, dict):
                payload = served.wire.result(int(status), values)
        except (RwtError, WireError) as exc:
            values = f"action {served.action}: {exc}"

        def answer() -> None:  # after the goal's feedback (the outbox's thread)
            try:
                if payload is not None:
                    link.reply(query, payload)
                else:
                    query.reply_err(str(values))
            finally:
                query.drop()  # type: ignore[no-untyped-call]

        link.after_puts(answer)

    def try_cancel(self, service: str, query: zenoh.Query) -> bool:
        """Cancel one of the goals remote callers sent, if ``query`` names one."""
        if not service.endswith(CANCEL_SUFFIX):
            return False
        registry = self.link.graph.registry
        srvtype = registry.service(CANCEL_GOAL_TYPE)
        try:
            request = decode_message(registry, srvtype.request, _payload(query))
        except WireError:
            return False
        info = request.get("goal_info")
        goal_id = info.get("goal_id") if isinstance(info, dict) else None
        uuid = goal_id.get("uuid") if isinstance(goal_id, dict) else None
        served = self._served.get(bytes(uuid)) if isinstance(uuid, bytes | bytearray) else None
        if served is None or served.handle is None:
            return False
        served.handle.request_cancel()
        if served.outcome is None:
            served.status = GoalStatus.CANCELING
            self._status_changed(served.action)
        response = {"return_code": 0, "goals_canceling": [info]}
        try:
            self.link.reply(query, encode_message(registry, srvtype.response, response))
        finally:
            query.drop()  # type: ignore[no-untyped-call]
        return True

    def _status_changed(self, action: str) -> None:
        """Publish ``action``'s status once the events at hand are handled.

        So a burst of goals costs one ``GoalStatusArray``, not one per goal.
        """
        if action not in self._status_due:
            self._status_due.add(action)
            self.link.soon(self._publish_status, action)

    def _publish_status(self, action: str) -> None:
        self._status_due.discard(action)
        offer = self._offers.get(action)
        if offer is None:
            return
        status_list: list[dict[str, object]] = []
        for goal_id, served in self._served.items():
            if served.action == action:
                sec, nanosec = stamp_of(served.accepted_at)
                info = {"goal_id": {"uuid": goal_id}, "stamp": {"sec": sec, "nanosec": nanosec}}
                status_list.append({"goal_info": info, "status": int(served.status)})
        registry = self.link.graph.registry
        msgtype = registry.message(GOAL_STATUS_ARRAY)
        offer.status.put(encode_message(registry, msgtype, {"status_list": status_list}))

    # ---- caller side ----------------------------------------------------------------

    def mirror(self, client: ClientId, entity: RemoteEntity) -> _RemoteAction:
        """The provider of a remote action server (``entity``), listening to its feedback.

        Raises:
            RwtError: the action type is unknown here.
        """
        wire = self.wire(entity.type_name)
        provider = _RemoteAction(self, client, entity.name, wire)
        # Subscribed now, as an rclpy ActionClient is from its creation: declared with the
        # first goal, the subscription could reach the server after the goal and miss its
        # first feedback.
        self._feedback_of[client] = self._listen_feedback(provider)
        return provider

    def unmirror(self, client: ClientId) -> None:
        """Drop the feedback subscription of ``client``'s action, if it was one mirrored here."""
        key = self._feedback_of.pop(client, None)
        if key is not None and key not in self._feedback_of.values():
            handle = self._feedback_subs.pop(key, None)
            if handle is not None:
                guarded("undeclaring an action's entity", handle.undeclare)
            topic = self._unheld_of.pop(key, None)
            if topic is not None and topic not in self._unheld_of.values():
                self.link.never_held.discard(topic)

    def send_remote_goal(
        self, provider: _RemoteAction, goal_id: str, args: dict[str, object]
    ) -> None:
        """Send a local caller's goal to the remote server."""
        link = self.link
        uuid = os.urandom(16)
        try:
            payload = provider.wire.send_goal(uuid, args)
        except (RwtError, WireError) as exc:
            self._finish(provider, goal_id, GoalStatus.ABORTED, False, str(exc))
            return
        self._calling[uuid] = (provider, goal_id)

        def accepted(ok: bool, value: object) -> None:
            if not ok:
                self._end(uuid, GoalStatus.ABORTED, False, value)
                return
            assert isinstance(value, bytes)
            if not provider.wire.read_accepted(value):
                self._end(uuid, GoalStatus.ABORTED, False, f"{provider.action} rejected the goal")
                return
            self._call(
                provider,
                goal_id,
                "GetResult",
                provider.wire.get_result(uuid),
                resulted,
                RESULT_TIMEOUT_S,
            )

        def resulted(ok: bool, value: object) -> None:
            if not ok:
                self._end(uuid, GoalStatus.ABORTED, False, value)
                return
            assert isinstance(value, bytes)
            status, result = provider.wire.read_result(value)
            try:
                final = GoalStatus(status)
            except ValueError:
                final = GoalStatus.ABORTED
            self._end_settled(uuid, final, result, time.monotonic())

        self._call(provider, goal_id, "SendGoal", payload, accepted, link.call_timeout_s)

    def _end_settled(self, uuid: bytes, status: GoalStatus, values: object, came: float) -> None:
        """End a goal whose result ``came`` (monotonic s) once its feedback is quiet.

        ``FEEDBACK_SETTLE_S`` after the result and after its last feedback, at most
        ``MAX_FEEDBACK_SETTLE_S`` after the result: the feedback put before the result
        may reach this process after it.
        """
        now = time.monotonic()
        quiet_from = max(came, self._fed.get(uuid, came))
        wait_s = min(quiet_from + FEEDBACK_SETTLE_S, came + MAX_FEEDBACK_SETTLE_S) - now
        if wait_s > 0 and uuid in self._calling:
            self.link.later(wait_s, self._end_settled, uuid, status, values, came)
            return
        self._end(uuid, status, True, values)

    def _end(self, uuid: bytes, status: GoalStatus, result: bool, values: object) -> None:
        self._fed.pop(uuid, None)
        calling = self._calling.pop(uuid, None)
        if calling is not None:
            self._finish(calling[0], calling[1], status, result, values)

    def _finish(
        self,
        provider: _RemoteAction,
        goal_id: str,
        status: GoalStatus,
        result: bool,
        values: object,
    ) -> None:
        entry = self.link.graph.actions.entries.get(provider.action)
        if entry is None or entry.owner != provider.client:
            return  # the server went: its goals were aborted already (D15)
        goal = entry.goals.get(goal_id)
        if goal is not None:
            goal.finish(status, result, values)

    def _listen_feedback(self, provider: _RemoteAction) -> str:
        """Subscribe to the feedback of ``provider``'s action, once per key (name and type).

        Returns:
            The subscription's key expression.
        """
        action = provider.action
        key = self._key(action + FEEDBACK_SUFFIX, provider.wire, "FeedbackMessage")
        if key in self._feedback_subs:
            return key
        wire = provider.wire

        def deliver(payload: bytes, _attachment: bytes | None) -> None:
            self._on_feedback(wire, payload)

        def on_sample(sample: zenoh.Sample) -> None:  # a Zenoh thread
            self.link.soon_sample(action + FEEDBACK_SUFFIX, deliver, sample.payload.to_bytes())

        # never held back behind a congested subscriber: the goal's result would pass it
        self._unheld_of[key] = action + FEEDBACK_SUFFIX
        self.link.never_held.add(action + FEEDBACK_SUFFIX)

        self._feedback_subs[key] = self.link.session.declare_subscriber(
            key, on_sample, allowed_origin=zenoh.Locality.REMOTE
        )
        return key

    def _on_feedback(self, wire: ActionWire, payload: bytes) -> None:
        try:
            uuid, feedback = wire.read_feedback(payload)
        except (RwtError, WireError) as exc:
            self.link.peer_log.log(
                logging.WARNING,
                "zenoh_bad_feedback",
                "event=zenoh_bad_feedback reason=%r",
                str(exc),
            )
            return
        calling = self._calling.get(uuid)
        if calling is None:
            return  # another process's goal
        provider, goal_id = calling
        entry = self.link.graph.actions.entries.get(provider.action)
        goal = None if entry is None else entry.goals.get(goal_id)
        if goal is not None:
            self._fed[uuid] = time.monotonic()
            goal.forward_feedback(feedback)

    def cancel_remote_goal(self, provider: _RemoteAction, goal_id: str) -> None:
        """Ask the remote server to cancel a goal sent from here."""
        uuid = next(
            (u for u, (p, g) in self._calling.items() if p is provider and g == goal_id), None
        )
        if uuid is None:
            return
        registry = self.link.graph.registry
        srvtype = registry.service(CANCEL_GOAL_TYPE)
        stamp = {"sec": 0, "nanosec": 0}
        request: dict[str, object] = {"goal_info": {"goal_id": {"uuid": uuid}, "stamp": stamp}}
        payload = encode_message(registry, srvtype.request, request)
        self._call(
            provider,
            goal_id,
            "CancelGoal",
            payload,
            lambda ok, value: None,
            self.link.call_timeout_s,
        )

    def close(self) -> None:
        """Withdraw everything; goals of remote callers end for them when this process goes."""
        for name in list(self._offers):
            self._withdraw(name)
        for handle in self._feedback_subs.values():
            guarded("undeclaring an action's entity", handle.undeclare)
        self._feedback_subs.clear()
        self._feedback_of.clear()
        self.link.never_held.difference_update(self._unheld_of.values())
        self._unheld_of.clear()
        self._calling.clear()
        self._fed.clear()
        self._served.clear()


def _payload(query: zenoh.Query) -> bytes:
    payload = query.payload
    return b"" if payload is None else payload.to_bytes()
