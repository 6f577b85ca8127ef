"""Handlers of the service ops (spec 3.3.6-3.3.9, D4, D15-D17, D25, D28)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...errors import RemoteProtocolError, RwtError
from ...levels import StatusLevel
from ...names import resolve_name
from ...ops import AdvertiseService, CallService, ServiceResponse, UnadvertiseService
from ..compat import late_reply_text, reply_text
from .topics import report_type_warning

if TYPE_CHECKING:
    from .context import HandlerContext

__all__ = ["advertise_service", "call_service", "service_response", "unadvertise_service"]


def advertise_service(session: HandlerContext, op: AdvertiseService, now: float) -> None:
    """Offer a service provided by this client (spec 3.3.6; newest wins, D15).

    Raises:
        GraphError: bad or unknown service type.
    """
    name = resolve_name(op.service)
    holdings = session.holdings
    if ("service", name) not in holdings.offers:
        session.check_cap(holdings.offered(), session.config.max_advertisements, "advertisements")
    type_name = session.graph.advertise_service(
        session.client_id, op.service, op.type, session.provider_link
    )
    holdings.add_offer("service", name)
    report_type_warning(session, "advertise_service", type_name, None)
    session.report(StatusLevel.INFO, f"advertise_service: {op.service} advertised as {type_name}")


def unadvertise_service(session: HandlerContext, op: UnadvertiseService, now: float) -> None:
    """Withdraw a service of this client; its pending callers fail (spec 3.3.7, D15).

    Raises:
        GraphError: this client does not provide the service.
    """
    session.graph.unadvertise_service(session.client_id, op.service)
    session.holdings.drop_offer("service", resolve_name(op.service))
    session.report(StatusLevel.INFO, f"unadvertise_service: {op.service} unadvertised")


class _Call:
    """A call this client made: answers it once, with its id and spelling (D26, D28)."""

    def __init__(
        self, session: HandlerContext, op: CallService, service: str, op_id: str | int | None
    ) -> None:
        self.session = session
        self.op = op
        self.service = service  # as the graph got it: without ``#id``
        self.op_id = op_id
        self.booked = session.calls.book()  # settled once: answer, deadline or close

    def reply(self, result: bool, values: object) -> None:
        if not self.booked.settle():
            return
        if not result:  # a call that waited for discovery in vain: the mode's text
            values = late_reply_text(self.session.config.compat, self.service, values)
        self._send(result, values)

    def expired(self, timeout_s: float) -> None:
        """Its deadline passed (the book settled it): the caller hears so."""
        self._send(False, f"service call timed out after {timeout_s:g} s")

    def _send(self, result: bool, values: object) -> None:
        message = ServiceResponse(
            service=self.op.service,
            result=result,
            values=values if values is not None else {},
            id=self.op_id,
        )
        self.session.send(
            message, compression=self.op.compression, fragment_size=self.op.fragment_size
        )


def call_service(session: HandlerContext, op: CallService, now: float) -> None:
    """Call a service; the reply comes as ``service_response`` (spec 3.3.8).

    ``name#id`` gives the id when ``id`` is absent (D25). The call never blocks
    later ops (D16) and ends by ``op.timeout`` seconds or the server default
    (D16); a refused call is answered with ``result: false`` (D4) and a status.
    ``type`` is not checked: clients send ROS 1 names for rosapi (REF §2.6).

    Raises:
        RwtError: the service does not exist or ``args`` does not fit.
    """
    service, op_id = op.service, op.id
    if op_id is None and "#" in service:
        service, op_id = service.split("#", 1)
    calls = session.calls
    call = _Call(session, op, service, op_id)
    try:
        session.check_cap(calls.in_flight - 1, calls.max_pending, "pending calls")
        # the graph gets the name without ``#id``, no ``type`` to check, and the
        # client's own timeout: how long it waits for a service being discovered
        call.booked.pending = session.graph.call_service(
            session.client_id, service, op.args, call.reply, timeout_s=op.timeout, path="$.args"
        )
    except RwtError as exc:
        call.reply(False, reply_text(session.config.compat, exc))
        raise
    timeout_s = op.timeout or calls.timeout_s
    if timeout_s is not None:
        calls.expire_at(call.booked, now + timeout_s, lambda _now: call.expired(timeout_s))


def service_response(session: HandlerContext, op: ServiceResponse, now: float) -> None:
    """Answer a request this client's service received (spec 3.3.9, D15).

    Raises:
        RemoteProtocolError: no ``id``.
        GraphError: not this client's service, or no such pending request.
        FieldError: ``values`` does not fit the response type.
    """
    if op.id is None:
        raise RemoteProtocolError("missing field at $.id")
    session.graph.service_response(
        session.client_id, op.service, op.id, op.result, op.values, path="$.values"
    )
