"""Services across processes: local services answer Zenoh queries; remote ones are queried.

``serve_query`` runs a remote caller's request through the graph (so a local
provider, client or in-process, answers it); ``RemoteService`` is the graph's
provider of a service of another process, each call a Zenoh query matching the
service's key with a wildcard in place of the type hash, which providers'
keys carry (``payload.service_hash``), so another distribution's hash still matches.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from rwt_protocol.errors import RwtError

from .payload import decode_message, encode_message
from .wire import WireError, topic_keyexpr

if TYPE_CHECKING:
    import zenoh
    from rwt_graph.types import ServiceType
    from rwt_protocol.ops import CallService
    from rwt_protocol.ports import ClientId

    from .link import ZenohLink
    from .wire import Topic

__all__ = ["RemoteService", "serve_query"]

logger = logging.getLogger("rwt.zenoh")


def serve_query(link: ZenohLink, service: str, type_name: str, query: zenoh.Query) -> None:
    """A remote caller's request for the local ``service`` of ``type_name``: call it in the graph.

    The reply is the response's CDR, or an error reply with the failure's text.
    """
    registry = link.graph.registry
    answered = False

    def reply(result: bool, values: object) -> None:
        nonlocal answered
        if answered:
            return
        answered = True
        try:
            if result:
                assert isinstance(values, dict)
                srvtype = registry.service(type_name)
                response = encode_message(registry, srvtype.response, values)
                link.reply(query, response)
            else:
                query.reply_err(str(values))
        finally:
            query.drop()  # type: ignore[no-untyped-call]  # answered: free it now

    if link.cancels_goal(service, query):
        return
    try:
        srvtype = registry.service(type_name)
        payload = query.payload
        request = decode_message(
            registry, srvtype.request, b"" if payload is None else payload.to_bytes()
        )
        link.graph.port.call_service(link.caller, service, request, reply)
    except (RwtError, WireError) as exc:
        reply(False, f"service {service} failed: {exc}")


class RemoteService:
    """The provider of a remote service in the graph: forwards each call as a query.

    The reply, an error, or no reply within the link's ``call_timeout_s`` comes
    back as the provider's response; if the provider goes first, its release has
    already answered the caller (D15).

    Args:
        link: the link the queries go through.
        client: the participant standing for the remote server.
        topic: the service as the server's token names it (its key's parts).
        srvtype: its type in the graph's registry.
    """

    def __init__(
        self, link: ZenohLink, client: ClientId, topic: Topic, srvtype: ServiceType
    ) -> None:
        self._link = link
        self._client = client
        self._topic = topic
        self._srvtype = srvtype

    def on_service_request(self, request: CallService) -> None:
        """Send a local caller's request (``args`` in the internal form) as a query."""
        request_id, args = str(request.id), request.args
        topic, srvtype = self._topic, self._srvtype
        service = topic.name
        registry = self._link.graph.registry
        try:
            payload = encode_message(registry, srvtype.request, args)
        except (RwtError, WireError) as exc:
            self._respond(request_id, False, str(exc))
            return
        # the hash is matched by a wildcard: see the module text
        key = topic_keyexpr(self._link.domain_id, service, topic.dds_type, "*")
        graph = self._link.graph
        entry = graph.services.entries.get(service)
        call = None if entry is None else entry.pending.get(request_id)
        node = self._link.clients.caller_node(None if call is None else call.caller)
        attachment = self._link.clients.attachment(node, service, topic.dds_type, topic.type_hash)

        def answer(ok: bool, value: object) -> None:
            if not ok:
                value = f"service {service} failed: {value}"
            self._finish(request_id, ok, value)

        self._link.query(key, payload, answer, self._link.call_timeout_s, attachment)

    def _finish(self, request_id: str, ok: bool, value: object) -> None:
        if ok:
            assert isinstance(value, bytes)
            try:
                value = decode_message(self._link.graph.registry, self._srvtype.response, value)
            except RwtError as exc:  # not CDR of the type, or a value that does not fit it
                ok, value = False, str(exc)
        self._respond(request_id, ok, value)

    def _respond(self, request_id: str, ok: bool, value: object) -> None:
        graph, service = self._link.graph, self._topic.name
        entry = graph.services.entries.get(service)
        if entry is None or entry.owner != self._client or request_id not in entry.pending:
            return  # timed out, or the provider is gone (its callers were answered)
        if ok:
            entry.pending.pop(request_id).resolve(True, value)
        else:
            graph.port.service_response(self._client, service, request_id, False, value)

    def on_service_lost(self, service: str, reason: str) -> None:
        """A local provider replaced the remote one here; the remote one lives on."""
        logger.info("event=zenoh_service_shadowed service=%s reason=%r", service, reason)
