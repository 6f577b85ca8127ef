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
refusing, no answer within ``--call-timeout``, ``ClientRules.call_timeout_s``,
a deadline timer of the session). Calls in flight are independent: each is
answered by its call id when its answer comes, once. The number in flight is
``--max-pending-calls`` (``ClientRules.max_pending_calls``), as for a rosbridge
client: one set of per-client rules (docs/limits.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_graph.feed import EntityKind
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
    from rwt_protocol.runtime.callbook import BookedCall, CallBook
    from rwt_protocol.runtime.outbox import OutFrame

    from .graphindex import GraphIndex
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
    booked: BookedCall  # in the connection's call book until settled


def _schema(mtype: MessageType) -> ServiceSchema:
    schema = schema_of(mtype)
    return ServiceSchema(schema.encoding, schema.schema_name, schema.schema_encoding, schema.schema)


class ServiceCalls:
    """The server services one client sees, and its calls in flight.

    Args:
        graph: the graph's core; calls go through it as ``client_id``.
        client_id: this connection's identity in the graph.
        out: where advertisements and answers go.
        index: the services the client may see (kept by the session from the
            change feed, under the access globs: ``--services-glob``).
        calls: the connection's call book (``--max-pending-calls``,
            ``--call-timeout``), the same as a rosbridge client's.
        batch: services one ``advertiseServices`` carries at most.
    """

    def __init__(
        self,
        graph: GraphFront,
        client_id: str,
        out: SessionOutput,
        index: GraphIndex,
        calls: CallBook,
        batch: int,
    ) -> None:
        self._graph = graph
        self._client_id = client_id
        self._out = out
        self._index = index
        self._batch = max(1, batch)
        self._dirty: dict[str, None] = dict.fromkeys(index.names(EntityKind.SERVICE))
        self._advertised: OutFrame | None = None  # the last batch, while it waits
        self._book = calls
        self._wire = wire_encoding(graph.registry.dialect)
        self._ids = itertools.count(1)
        self._by_name: dict[str, _Service] = {}
        self._by_id: dict[int, _Service] = {}
        self._calls: dict[int, _Call] = {}  # call id -> the call in flight

    def touched(self, name: str) -> None:
        """A change of the graph touched service ``name``: it is looked at in the next batch."""
        self._dirty[name] = None

    @property
    def waiting(self) -> bool:
        """Whether services wait to be (un)advertised."""
        return bool(self._dirty)

    def sync(self) -> bool:
        """Advertise the services that appeared, unadvertise those gone or retyped.

        Only the names a change touched are looked at, at most ``batch`` of them
        advertised per frame, the next once the client took the last.

        Returns:
            Whether anything was queued.
        """
        if not self._dirty or (self._advertised is not None and self._out.unsent(self._advertised)):
            return False
        registry = self._graph.registry
        gone: list[int] = []
        added: list[Service] = []
        while self._dirty and len(added) < self._batch:
            name = next(iter(self._dirty))
            del self._dirty[name]
            type_name = self._index.type_of(EntityKind.SERVICE, name)
            service = self._by_name.get(name)
            if service is not None and service.srvtype.name != type_name:
                del self._by_name[name]
                del self._by_id[service.id]
                gone.append(service.id)
                service = None
            if type_name is not None and service is None:
                added.append(self._add(name, registry.service(type_name)))
        if gone:
            self._out.control(UnadvertiseServices(serviceIds=gone))
        if added:
            self._advertised = self._out.tracked(AdvertiseServices(services=added))
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
        call = self._calls[op.call_id] = _Call(service, self._book.book())

        def reply(result: bool, values: object) -> None:
            self._answer(op.call_id, call, result, values)

        try:
            pending = self._graph.call_service(self._client_id, service.name, request, reply)
        except RwtError as exc:
            if call.booked.settle():
                del self._calls[op.call_id]
                self._fail(service.id, op.call_id, exc.message)
            return
        call.booked.pending = pending
        timeout = self._book.timeout_s
        if timeout is not None:

            def expired(now: float) -> None:
                del self._calls[op.call_id]
                self._fail(service.id, op.call_id, f"no response within {timeout:g} s")

            self._book.expire_at(call.booked, self._out.now + timeout, expired)

    def _refusal(self, op: ServiceCallRequest, service: _Service | None) -> str | None:
        if service is None:
            return f"unknown service {op.service_id}"
        if op.encoding != self._wire:
            return f"unsupported encoding {op.encoding[:40]!r} (expected {self._wire})"
        if op.call_id in self._calls:
            return f"call id {op.call_id} is already in flight"
        if self._book.full:
            return f"too many calls in flight (at most {self._book.max_pending})"
        return None

    def _answer(self, call_id: int, call: _Call, result: bool, values: object) -> None:
        if not call.booked.settle():
            return  # timed out or closed: the client heard already
        del self._calls[call_id]
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
        """The connection is gone: its calls are forgotten (the book settles them)."""
        self._calls.clear()
