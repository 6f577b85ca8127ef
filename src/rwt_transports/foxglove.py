"""Foxglove clients on the server's WebSocket listeners (docs/foxglove.md).

A client that offers ``foxglove.sdk.v1`` or ``foxglove.websocket.v1`` in its
handshake gets the Foxglove WebSocket protocol (``rwt_foxglove``) on the same
graph; one that offers neither gets rosbridge. ``FoxgloveOptions.port`` opens a
listener that speaks only Foxglove (foxglove_bridge's default port is 8765).

A Foxglove connection is admitted as any WebSocket connection (the server's
``open_session``: ``--max-connections``, the host shares, ``/connected_clients``)
and uses that session's client id in the graph; its rosbridge ops are never read.

With an authenticator (``--auth-secret-file``) a Foxglove client, which has no
``auth`` op and whose user can only type a URL, carries the ``auth`` op's fields
in its URL's query string (``rwt_protocol.auth.auth_query``); ``url_token_gate``
checks them with the same authenticator during the handshake and refuses the
connection (HTTP 401 without a token, 403 with a bad one) before any session (D33).

Its queue takes part in the server's flow control as a rosbridge connection's
outbox does (``FoxgloveOutlet``, docs/limits.md "Backpressure"): a publishing
connection's reader, or a link's deliveries, whose batch filled the queue of a
Foxglove client past half its bounds waits while that client reads, within its
hold budget; a client that does not read is found slow and left to drop its
own oldest data. A publisher in the server's process is never held. Its reader
is a publishing connection's reader too (``FoxgloveReadGate``): a slice of its
frames at a time (``pump.READ_SLICE_FRAMES``, ``READ_SLICE_BYTES``), each a batch
of the flow control, after which it waits for the queues it filled.
"""

from __future__ import annotations

import functools
import logging
import os
import uuid
from dataclasses import dataclass, field
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

import anyio

from rwt_foxglove import AssetRoots, FoxgloveLimits, FoxgloveSession, Wakeup, run_foxglove
from rwt_protocol.auth import auth_from_query
from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.shortcuts import enabled

from .admission import current_ticket
from .holding import Held, wait_for
from .pump import READ_SLICE_BYTES, READ_SLICE_FRAMES, flush_deferred

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from rwt_graph.parameters.store import Parameters
    from rwt_graph.port import GraphFront
    from rwt_protocol.auth import Authenticator
    from rwt_protocol.server.access import AccessPolicy
    from rwt_protocol.server.session import Session

    from .flow import FlowControl, HoldAccount
    from .websocket import FoxgloveGate, FoxgloveServe, WebSocketChannel

__all__ = [
    "FoxgloveOptions",
    "FoxgloveOutlet",
    "FoxgloveReadGate",
    "foxglove_server",
    "url_token_gate",
]

logger = logging.getLogger("rwt.foxglove")


@dataclass(frozen=True)
class FoxgloveOptions:
    """Where the server answers Foxglove clients.

    Attributes:
        on_rosbridge_port: answer the Foxglove subprotocols on the rosbridge
            WebSocket port (``rwt serve --no-foxglove``: off).
        port: a WebSocket port that speaks only Foxglove (``--foxglove-port``;
            0 picks a free one; None: no such listener). A client there that
            offers no Foxglove subprotocol is refused with HTTP 400.
        limits: each Foxglove client's bounds (docs/limits.md).
        assets: answer ``fetchAsset`` (the ``assets`` capability) from
            ``package_paths``, then ``ROS_PACKAGE_PATH`` and ``AMENT_PREFIX_PATH``'s
            share folders (``rwt serve --assets``; off where none of them exists).
        package_paths: directories holding ROS packages (``--package-path``).
    """

    on_rosbridge_port: bool = True
    port: int | None = None
    limits: FoxgloveLimits = field(default_factory=FoxgloveLimits)
    assets: bool = False
    package_paths: Sequence[Path] = ()


def foxglove_server(
    graph: GraphFront,
    access: AccessPolicy,
    options: FoxgloveOptions,
    params: Parameters | None = None,
    flow: FlowControl[Held] | None = None,
) -> FoxgloveServe:
    """The function that runs each accepted Foxglove connection of one server.

    Args:
        graph: the served graph's core.
        access: the server's access globs (a topic a client may not see is not advertised).
        options: each client's bounds (``limits``) and where assets are found
            (read once, with the environment's ROS paths, here).
        params: the graph's parameters (``Graph.params``); None: no parameters capability.
        flow: the server's flow control, which each client's queue takes part in;
            None: publishers never wait for a Foxglove client.
    """
    limits = options.limits
    assets = (
        AssetRoots.from_environment(options.package_paths, os.environ) if options.assets else None
    )
    session_id = uuid.uuid4().hex  # one per server run: clients tell a restart by it

    async def serve(channel: WebSocketChannel, session: Session, subprotocol: str) -> None:
        if not session.authenticated:  # an authenticator, and no gate admitted the client
            logger.warning(
                "event=foxglove_refused client=%s reason='not authenticated'", session.client_id
            )
            return
        wakeup = Wakeup()
        outlet: FoxgloveOutlet | None = None

        foxglove = FoxgloveSession(
            graph,
            session.client_id,
            session_id=session_id,
            access=access,
            limits=limits,
            on_output=wakeup.set,
            params=params,
            assets=assets is not None,
        )
        gate: FoxgloveReadGate | None = None
        if flow is not None:
            outlet = FoxgloveOutlet(foxglove, channel, limits)
            account = flow.open_connection(
                outlet, session.peer, session.config.hold_budget_s, outlet.water_marks
            )
            gate = FoxgloveReadGate(flow, account, channel, outlet)
            wakeup.on_sent = outlet.sent
            wakeup.batch = flow
            wakeup.on_batch_output = functools.partial(outlet.note_output, flow)
        logger.info("event=foxglove client=%s subprotocol=%s", session.client_id, subprotocol)
        # ``deferred-send`` (rwt_protocol/shortcuts.py): off, the writer task writes everything
        direct = channel.abilities.send_now and enabled("deferred-send")
        # First input first (admission.py): this connection's first frames go before
        # what the others get later; once they are handled, the others go on.
        ticket = current_ticket()
        if ticket is not None:
            if channel.abilities.probe_input:
                ticket.watch(channel.input_pending)
            else:
                ticket.release()
        try:
            await run_foxglove(
                channel,
                foxglove,
                wakeup,
                assets=assets,
                direct=direct,
                read_slice=(READ_SLICE_FRAMES, READ_SLICE_BYTES),
                gate=gate,
                first_input=None if ticket is None else ticket.release,
            )
        finally:
            if ticket is not None:
                ticket.release()
            if outlet is not None:
                outlet.close()  # readers waiting for it go on

    return serve


NO_TOKEN = "authentication required: add the token to the URL (docs/foxglove.md)"
"""The reason of a Foxglove handshake refused for want of a URL token (HTTP 401)."""

BAD_TOKEN = "authentication failed"
"""The reason of a Foxglove handshake whose URL token was refused (HTTP 403)."""


def url_token_gate(authenticator: Authenticator) -> FoxgloveGate:
    """Admit Foxglove handshakes whose URL carries a token ``authenticator`` admits.

    The token is the ``auth`` op's fields as query parameters (``mac``, ``client``,
    ``dest``, ``rand``, ``t``, ``level``, ``end``; ``rwt_protocol.auth.auth_query``),
    checked as an ``auth`` op is: the same MAC, the same time window.

    Args:
        authenticator: the server's (``rosauth_authenticator``, or embedding code's).

    Returns:
        The gate: given the request path and the peer, (401, ``NO_TOKEN``) for a
        URL without ``mac``, (403, reason) for an unreadable or refused token (the
        reason says only what the client sent wrong; the authenticator logs its
        own), None to accept.
    """

    def refusal(path: str, peer: str) -> tuple[int, str] | None:
        try:
            op = auth_from_query(urlsplit(path).query)
        except (RemoteProtocolError, ValueError) as exc:
            return 403, f"{BAD_TOKEN}: {exc}"
        if op is None:
            return 401, NO_TOKEN
        try:
            admitted = authenticator(op, peer)
        except Exception:  # embedding code's check failed: a refusal, logged
            logger.exception("event=authenticator_failed peer=%s", peer)
            admitted = False
        if not admitted:
            return 403, BAD_TOKEN
        logger.info("event=auth_ok peer=%s level=%s via=foxglove_url", peer, op.level)
        return None

    return refusal


class FoxgloveOutlet(Held):
    """A Foxglove client's queue as the server's flow control sees it (the module's text).

    Its fill is counted in bytes, a message counting at least its share of the
    byte bound (``max_queue_bytes / max_queue_messages``), so that either bound
    congests: the watermarks are half and a quarter of ``max_queue_bytes``.

    Args:
        session: the client's session.
        channel: its connection (the socket's send queue tells progress).
        limits: its bounds.
    """

    def __init__(
        self, session: FoxgloveSession, channel: WebSocketChannel, limits: FoxgloveLimits
    ) -> None:
        super().__init__()
        self._session = session
        self._channel = channel
        self._per_message = max(1, limits.max_queue_bytes // max(1, limits.max_queue_messages))
        self.water_marks = (limits.max_queue_bytes // 2, limits.max_queue_bytes // 4)
        self._closed = False

    def fill(self) -> int:
        """The queue's fill in bytes (each message at least its share of the byte bound)."""
        session = self._session
        return max(session.queued_bytes, session.queued_messages * self._per_message)

    def note_output(self, flow: FlowControl[Held]) -> None:
        """Output was queued during a batch: the batch congested it if it is past its mark."""
        if not self._closed and flow.congests(self, self.fill()):
            flow.note_congested(self, anyio.current_time())

    def sent(self) -> None:
        """A batch went to the socket: the client makes progress (wakes held readers)."""
        self.note_take(self._session.queued_bytes == 0)

    def close(self) -> None:
        """The connection ended: nobody waits for it any more."""
        self._closed = True
        self.note_take(True)

    def over_water(self, *, own: bool, mark: int) -> bool:
        """Whether its fill is over ``mark`` (never for its own reader, which is no pump)."""
        return not own and not self._closed and self.fill() > mark

    def backlog_bytes(self) -> int:
        """What the client has yet to read: its queue and the socket's send queue."""
        return self._session.queued_bytes + (self.unsent_bytes() or 0)

    def unsent_bytes(self) -> int | None:
        """Bytes the socket's kernel still holds for the client (sendqueue.py)."""
        return self._channel.unsent_bytes()


class FoxgloveReadGate:
    """A Foxglove client's reader in the server's flow control, as a rosbridge reader is.

    Each slice of its frames is a batch (``FlowControl.begin``/``end``): what it
    published is written at the batch's end, and a queue of another client
    (either protocol) or a link it filled past the high watermark is waited for
    while that one reads, within this client's hold budget (docs/limits.md,
    "Backpressure"); its socket is not read meanwhile, so TCP pushes back.

    Args:
        flow: the server's flow control.
        account: this client's hold budget (``FlowControl.open_connection``).
        channel: its connection (paused while it waits).
        own: its own queue, never waited for by its own reader.
    """

    def __init__(
        self,
        flow: FlowControl[Held],
        account: HoldAccount,
        channel: WebSocketChannel,
        own: FoxgloveOutlet,
    ) -> None:
        self._flow = flow
        self._account = account
        self._channel = channel
        self._own = own

    def begin(self) -> None:
        """A slice starts: output queued from here on belongs to this reader's batch."""
        self._flow.begin()

    def end(self) -> None:
        """The slice ends: what it queued for idle connections is written now."""
        self._flow.end()
        flush_deferred(self._flow)

    async def hold(self) -> None:
        """Wait for each queue the slice pushed over its high watermark, as the flow says."""
        flow = self._flow
        for held in flow.take_congested():
            if held is self._own or not held.over_water(own=False, mark=held.high_water):
                continue
            if self._channel.abilities.pause_reading:
                self._channel.pause_reading()
            await wait_for(flow, held, own=False, account=self._account)
