"""The graph's services as Foxglove server services, and one client's calls, without I/O.

Every service of the graph is advertised (``advertiseServices``) whoever
provides it: a rosbridge client's ``advertise_service``, a ROS 2 node through
the link, the server's own (rosapi); ``unadvertiseServices`` follows when it
goes or changes type. Its request and response are described as channels are
(``schemas.schema_of``: ``ros2msg`` text with its dependencies).

A call (binary ``serviceCallRequest``) carries the request in the dialect's
wire encoding (CDR for ROS 2); it becomes a graph call of this client, and its
answer a binary ``serviceCallResponse`` with the same call id, or a
``serviceCallFailure`` (unknown service, an encoding other than the wire one,
a request that does not decode, too many calls in flight, the provider gone or
refusing, no answer within ``--call-timeout``, ``SessionConfig.call_timeout_s``,
a deadline timer of the session). Calls in flight are independent: each is
answered by its call id when its answer comes, once. The number in flight is
``--max-pending-calls`` (``SessionConfig.max_pending_calls``), as for a rosbridge
client: one set of per-client rules (docs/limits.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_graph.visibility import Visibility
from rwt_protocol.errors import RwtError

from .protocol import (
    AdvertiseServices,
    FoxgloveInputError,
    Service,
    ServiceCallFailure,
    ServiceCallRequest,
    ServiceSchema,
    UnadvertiseServices,
    encode_op,
    encode_service_call_response,
)
from .schemas import schema_of, wire_encoding
from .wire import decode_wire, encode_wire

if TYPE_CHECKING:
    from rwt_graph.port import GraphFront
    from rwt_graph.types import MessageType, ServiceType
    from rwt_protocol.ports import Pending
    from rwt_protocol.server.access import AccessPolicy
    from rwt_protocol.server.timers import Timer

    from .output import SessionOutput

__all__ = ["ServiceCalls"]


@dataclass(eq=False, slots=True)
class _Service:
    id: int
    name: str
    srvtype: ServiceType


@dataclass(eq=False, slots=True)
class _Call:
    service: _Service
    pending: Pending | None = None
    timer: Timer | None = None  # its deadline (``call_timeout_s``)


def _schema(mtype: MessageType) -> ServiceSchema:
    schema = schema_of(mtype)
    return ServiceSchema(schema.encoding, schema.schema_name, schema.schema_encoding, schema.schema)


class ServiceCalls:
    """The server services one client sees, and its calls in flight.

    Args:
        graph: the graph's core; calls go through it as ``client_id``.
        client_id: this connection's identity in the graph.
        out: where advertisements and answers go.
        access: which services the client may see and call (``--services-glob``).
        max_pending_calls: calls in flight at once (``--max-pending-calls``).
        call_timeout_s: seconds a call waits for its answer (``--call-timeout``);
            None: for ever.
    """

    def __init__(
        self,
        graph: GraphFront,
        client_id: str,
        out: SessionOutput,
        access: AccessPolicy,
        max_pending_calls: int,
        call_timeout_s: float | None,
    ) -> None:
        self._graph = graph
        self._client_id = client_id
        self._out = out
        self._access = access
        self._max_pending = max_pending_calls
        self._timeout_s = call_timeout_s
        self._wire = wire_encoding(graph.registry.dialect)
        self._ids = itertools.count(1)
        self._by_name: dict[str, _Service] = {}
        self._by_id: dict[int, _Service] = {}
        self._calls: dict[int, _Call] = {}  # call id -> the call in flight

    def sync(self) -> bool:
        """Advertise the services that appeared, unadvertise those gone.

        Returns:
            Whether anything was queued.
        """
        registry, visible = self._graph.registry, Visibility.of(self._access)
        current = {
            change.name: registry.service(change.type_name)
            for change in self._graph.feed.snapshot()[1]
            if change.kind == "service" and visible.sees(change)
        }
        gone = [
            service
            for name, service in self._by_name.items()
            if (srvtype := current.get(name)) is None or srvtype.name != service.srvtype.name
        ]
        for service in gone:
            del self._by_name[service.name]
            del self._by_id[service.id]
        if gone:
            self._out.control(UnadvertiseServices(serviceIds=[service.id for service in gone]))
        added = [
            self._add(name, srvtype)
            for name, srvtype in sorted(current.items())
            if name not in self._by_name
        ]
        if added:
            self._out.control(AdvertiseServices(services=added))
        return bool(gone or added)

    def _add(self, name: str, srvtype: ServiceType) -> Service:
        service = _Service(next(self._ids), name, srvtype)
        self._by_name[name] = service
        self._by_id[service.id] = service
        request, response = _schema(srvtype.request), _schema(srvtype.response)
        return Service(
            id=service.id,
            name=name,
            type=srvtype.name,
            request=request,
            response=response,
            requestSchema=request.schema,
            responseSchema=response.schema,
        )

    def call(self, op: ServiceCallRequest) -> None:
        """Start the client's call; its answer or failure is queued when it comes; never raises."""
        service = self._by_id.get(op.service_id)
        problem = self._refusal(op, service)
        if problem is not None or service is None:
            self._fail(op.service_id, op.call_id, problem or "unknown service")
            return
        try:
            request = decode_wire(self._graph.registry, service.srvtype.request, bytes(op.payload))
        except FoxgloveInputError as exc:
            self._fail(op.service_id, op.call_id, f"bad request: {exc.message}")
            return
        call = self._calls[op.call_id] = _Call(service)

        def reply(result: bool, values: object) -> None:
            self._answer(op.call_id, call, result, values)

        try:
            call.pending = self._graph.call_service(self._client_id, service.name, request, reply)
        except RwtError as exc:
            if self._calls.get(op.call_id) is call:
                del self._calls[op.call_id]
                self._fail(service.id, op.call_id, exc.message)
            return
        if self._calls.get(op.call_id) is call and self._timeout_s is not None:
            timeout = self._timeout_s

            def expire(now: float) -> None:
                if self._calls.get(op.call_id) is not call:
                    return
                del self._calls[op.call_id]
                if call.pending is not None:
                    call.pending.forget()
                self._fail(service.id, op.call_id, f"no response within {timeout:g} s")

            call.timer = self._out.call_at(self._out.now + timeout, expire)

    def _refusal(self, op: ServiceCallRequest, service: _Service | None) -> str | None:
        if service is None:
            return f"unknown service {op.service_id}"
        if op.encoding != self._wire:
            return f"unsupported encoding {op.encoding[:40]!r} (expected {self._wire})"
        if op.call_id in self._calls:
            return f"call id {op.call_id} is already in flight"
        if len(self._calls) >= self._max_pending:
            return f"too many calls in flight (at most {self._max_pending})"
        return None

    def _answer(self, call_id: int, call: _Call, result: bool, values: object) -> None:
        if self._calls.get(call_id) is not call:
            return  # timed out or closed: the client heard already
        del self._calls[call_id]
        if call.timer is not None:
            call.timer.cancel()
        service = call.service
        if not result or not isinstance(values, dict):
            self._fail(service.id, call_id, str(values))
            return
        try:
            payload = encode_wire(self._graph.registry, service.srvtype.response, values)
        except Exception as exc:  # a type rosbags cannot write
            self._fail(service.id, call_id, f"cannot encode the response: {exc}")
            return
        frame = encode_service_call_response(service.id, call_id, self._wire, payload)
        self._out.answer(frame, binary=True)

    def _fail(self, service_id: int, call_id: int, message: str) -> None:
        failure = ServiceCallFailure(serviceId=service_id, callId=call_id, message=message)
        self._out.answer(encode_op(failure), binary=False)

    @property
    def in_flight(self) -> int:
        """Calls waiting for their answer."""
        return len(self._calls)

    def close(self) -> None:
        """The connection is gone: its calls are forgotten (their answers go nowhere)."""
        calls, self._calls = list(self._calls.values()), {}
        for call in calls:
            if call.timer is not None:
                call.timer.cancel()
            if call.pending is not None:
                call.pending.forget()
