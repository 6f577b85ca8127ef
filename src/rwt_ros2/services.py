"""Services across the link: ROS 2 servers called from the graph, graph services served to ROS 2.

``RosService`` is the graph's provider of a ROS 2 service: each call goes
through an rclpy client; the reply, a timeout, a server that is not there, or
bytes that do not decode all answer the caller. ``serve_to_ros`` is the
callback of the rclpy service that offers a graph service (a rosbridge
client's ``advertise_service``, an in-process one) to ROS 2 nodes: a coroutine
that hands the request to the event loop and awaits the graph's answer
(``answer.Answer``), so the executor goes on meanwhile. rclpy services cannot
answer with an error, so a failed call (the
provider disconnected, D15; the call timed out) gets the default response at
once, logged once per episode, rather than leaving the ROS 2 caller waiting.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from rwt_protocol.errors import RwtError

from .answer import Answer
from .codec import decode, encode
from .graphview import Qos
from .node import MAX_WAITING
from .runtime import interface_class

if TYPE_CHECKING:
    from collections.abc import Callable, Coroutine

    from rwt_graph.types import ServiceType
    from rwt_protocol.ops import CallService

    from .link import Ros2Link
    from .offers import Offer

__all__ = ["SERVER_MATCH_S", "SERVICE_QOS", "RosService", "serve_to_ros"]

logger = logging.getLogger("rwt.ros2")

SERVICE_QOS = Qos(depth=MAX_WAITING)
"""The QoS of the services rwt offers ROS 2: reliable, volatile, as rmw's services
default, but kept last ``MAX_WAITING`` rather than 10, so a burst of requests, or
of the responses to calls failed at once (their provider went), is not cut to the
last 10 by the middleware's history."""


SERVER_MATCH_S = 2.0
"""Seconds a call waits for the link's new rclpy client to match the server (the
client is made at the first call, and the middleware matches it a moment later)."""

_MATCH_POLL_S = 0.01


class RosService:
    """The graph's provider of the ROS 2 service ``name`` (see the module text).

    Args:
        link: the link.
        client: the participant standing for the ROS 2 server.
        name: the service's name.
        srvtype: its type in the graph's registry; its rclpy class is loaded at
            the first call, whose caller learns the package to install if it is
            missing (``runtime.interface_class``).
    """

    def __init__(self, link: Ros2Link, client: str, name: str, srvtype: ServiceType) -> None:
        self._link = link
        self._client = client
        self._name = name
        self._srvtype = srvtype
        self._ros_type: Any = None
        self._ros_client: Any = None

    def on_service_request(self, request: CallService) -> None:
        """Send a graph caller's request (``args`` in the internal form) to the ROS 2 server."""
        link = self._link
        request_id, args = str(request.id), request.args
        if self._ros_client is None:
            try:
                self._ros_type = interface_class(self._srvtype.name)
            except RwtError as exc:
                self._respond(request_id, False, f"service {self._name}: {exc}")
                return
            self._ros_client = link.ros.node.create_client(
                self._ros_type, self._name, callback_group=link.ros.group
            )
        self._send_when_ready(request_id, args, link.loop.time() + SERVER_MATCH_S)

    def _send_when_ready(self, request_id: str, args: dict[str, object], deadline: float) -> None:
        """Send the request once the rclpy client has matched the server (``SERVER_MATCH_S``)."""
        from rclpy.serialization import deserialize_message  # noqa: PLC0415

        link, ros_client = self._link, self._ros_client
        if ros_client is None or not self._waits(request_id):
            return  # closed, or the caller was answered meanwhile
        if not ros_client.service_is_ready():
            if link.loop.time() < deadline:
                link.loop.call_later(
                    _MATCH_POLL_S, self._send_when_ready, request_id, args, deadline
                )
            else:
                self._respond(
                    request_id, False, f"service {self._name}: no ROS 2 server answers it"
                )
            return
        try:
            payload = encode(link.graph.registry, self._srvtype.request, args)
            ros_request = deserialize_message(payload, self._ros_type.Request)
        except Exception as exc:  # rclpy refuses what rosbags wrote: a type mismatch
            self._respond(request_id, False, f"service {self._name}: request refused: {exc}")
            return
        future = ros_client.call_async(ros_request)
        loop = link.loop
        timer = loop.call_later(link.options.call_timeout_s, self._timeout, request_id, future)

        def done(_: Any) -> None:  # an executor thread: a large response is decoded here,
            # not in one turn of the event loop (a node's list of 20,000 parameters)
            link.handoff.put(self._finish, request_id, self._decoded(future), timer)

        future.add_done_callback(done)

    def _timeout(self, request_id: str, future: Any) -> None:
        if self._ros_client is not None:
            self._ros_client.remove_pending_request(future)
        timeout = self._link.options.call_timeout_s
        self._respond(request_id, False, f"service {self._name}: no reply within {timeout:g} s")

    def _decoded(self, future: Any) -> tuple[bool, object]:
        """``(True, response)`` in the internal form, or ``(False, why)`` (any thread)."""
        from rclpy.serialization import serialize_message  # noqa: PLC0415

        try:
            response = future.result()
            data = serialize_message(response)
            return True, decode(self._link.graph.registry, self._srvtype.response, data)
        except Exception as exc:  # the call was cancelled, or the reply does not decode
            return False, f"service {self._name} failed: {exc}"

    def _finish(self, request_id: str, outcome: tuple[bool, object], timer: Any) -> None:
        timer.cancel()
        self._respond(request_id, *outcome)

    def _waits(self, request_id: str) -> bool:
        entry = self._link.graph.services.entries.get(self._name)
        return entry is not None and entry.owner == self._client and request_id in entry.pending

    def _respond(self, request_id: str, ok: bool, value: object) -> None:
        graph = self._link.graph
        entry = graph.services.entries.get(self._name)
        if entry is None or entry.owner != self._client or request_id not in entry.pending:
            return  # timed out already, or the server went (its callers were answered)
        if ok:
            entry.pending.pop(request_id).resolve(True, value)
        else:
            graph.port.service_response(self._client, self._name, request_id, False, value)

    def on_service_lost(self, service: str, reason: str) -> None:
        """A local provider replaced the ROS 2 one in the graph; the ROS 2 one lives on."""
        logger.info("event=ros2_service_shadowed service=%s reason=%r", service, reason)

    def close(self) -> None:
        """Destroy the rclpy client."""
        if self._ros_client is not None:
            self._link.ros.node.destroy_client(self._ros_client)
            self._ros_client = None


def serve_to_ros(
    link: Ros2Link,
    name: str,
    type_name: str,
    ros_type: Any,
    offer: Offer,
    handler: Callable[[dict[str, object]], dict[str, object]] | None = None,
) -> Callable[[Any, Any], Coroutine[Any, Any, Any]]:
    """The callback of the rclpy service offering the graph's service ``name`` to ROS 2.

    Each request is called in the graph, or, with ``handler``, answered by it on
    the event loop (``handler(request) -> response``, internal forms; a node's
    parameter services, ``rwt_graph.parameters.services``). Each call is inside
    ``offer`` until its response is ready, so the service outlives it (``offers``).
    """
    from rclpy.serialization import deserialize_message, serialize_message  # noqa: PLC0415

    timeout_s = link.options.call_timeout_s

    def call_in_graph(data: bytes, answer: Answer) -> None:  # the event loop
        registry = link.graph.registry
        timer = link.loop.call_later(
            timeout_s, answer.set, False, f"no answer within {timeout_s:g} s"
        )
        try:
            srvtype = registry.service(type_name)
            request = decode(registry, srvtype.request, data)

            def reply(result: bool, values: object) -> None:
                timer.cancel()
                if not result:
                    answer.set(False, values)
                    return
                assert isinstance(values, dict)
                answer.set(True, encode(registry, srvtype.response, values))

            if handler is not None:
                reply(True, handler(request))
            else:
                link.graph.port.call_service(link.caller, name, request, reply)
        except RwtError as exc:
            timer.cancel()
            answer.set(False, str(exc))

    async def callback(request: Any, response: Any) -> Any:  # a task of the executor
        offer.enter()
        try:
            return await answer_call(request, response)
        finally:
            offer.leave()

    async def answer_call(request: Any, response: Any) -> Any:
        answer = Answer(link.ros)
        if not link.ros.waiting.acquire(blocking=False):
            answer.set(False, f"{MAX_WAITING} calls and goals from ROS 2 wait already")
        else:
            link.pending_answers.add(answer)
            try:
                if link.handoff.put(call_in_graph, serialize_message(request), answer):
                    await answer
                else:
                    answer.set(False, "the ROS 2 link is stopping")
            finally:
                link.pending_answers.discard(answer)
                link.ros.waiting.release()
        if answer.ok:
            assert isinstance(answer.value, bytes)
            return deserialize_message(answer.value, ros_type.Response)
        link.episodes.log(
            logging.WARNING,
            f"serve:{name}",
            "event=ros2_call_failed service=%s reason=%r answered=default_response",
            name,
            str(answer.value),
        )
        return response

    return callback
