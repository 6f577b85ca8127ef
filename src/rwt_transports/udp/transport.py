"""UDP transport: one datagram per message, one session per peer address (D22).

Every (host, port) that proves it receives at its address gets a session
(``validation``: a token exchange, and the token on every datagram, so a
forged source address can neither draw a stream nor act inside another peer's
session; ``trust_source_address`` restores rosbridge_udp's trust in the address
for trusted links, REF §3.6). A datagram is one frame: JSON text, or CBOR when
its first byte says so (D21). Outgoing messages larger than ``datagram_bytes`` go out as
``fragment`` ops (spec 3.1.1, D19), each within the size, so no message is
silently lost to the datagram limit. UDP has no connection close: a peer that
sends nothing for ``idle_timeout_s`` is forgotten (its session closed). With an
authenticator a session begins with the peer's ``auth`` op (``auth``): other
datagrams from a peer without a session are refused and open nothing.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import anyio

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.codecs.json import encode_op
from rwt_protocol.framing.datagrams import fragment_datagrams
from rwt_protocol.ops import Status
from rwt_protocol.runtime.inframes import FramerEvent, FramingError, InFrame

from ..admission.shares import HostPrefixes, HostShares
from ..channel import PlainChannel
from ..pump import ConnectionPump, run_connection
from .auth import Refusal, UdpAuth, read_first
from .validation import AddressValidator, split_token

if TYPE_CHECKING:
    from collections.abc import Sequence

    from anyio.abc import TaskGroup, UDPSocket
    from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

    from rwt_protocol.runtime.commands import CloseCode
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.outbox import OutFrame

    from ..host import SessionHost

__all__ = ["UdpOptions", "serve_udp"]

logger = logging.getLogger("rwt.udp")
_episodes = EpisodeLog(logger)  # a peer can trigger these at will

MAX_UDP_PAYLOAD = 65507
"""The largest IPv4 UDP payload, bytes."""

_QUEUED_DATAGRAMS = 256  # per peer; more arriving before the session reads them are dropped
_TOO_MANY = encode_op(Status(level="error", msg="too many connections"))
_NO_AUTH = UdpAuth()

Address = tuple[str, int]


@dataclass(frozen=True, slots=True)
class UdpOptions:
    """UDP settings.

    Attributes:
        datagram_bytes: outgoing messages above this many bytes go out as
            ``fragment`` ops (``--udp-datagram-size``; at most 65507).
        idle_timeout_s: seconds without a datagram after which a peer's session
            is closed (``--udp-idle-timeout``).
        max_sessions: most UDP sessions at once (``--udp-max-sessions``), within
            the server's ``max_connections``.
        max_sessions_per_host: UDP sessions one host (source address by
            ``admission.shares.HostPrefixes``, as for ``--max-connections-per-host``) may hold once
            ``admission.shares.SHARES_FROM`` of ``max_sessions`` are taken
            (``--udp-max-sessions-per-host``); before that anyone gets one.
        trust_source_address: serve any source address without validation, as
            rosbridge_udp does (``--udp-trust-source-address``): only on a link
            where addresses cannot be forged (docs/limits.md).
    """

    datagram_bytes: int = 8192
    idle_timeout_s: float = 300.0
    max_sessions: int = 256
    max_sessions_per_host: int = 16
    trust_source_address: bool = False


def _classify(data: bytes, max_bytes: int) -> FramerEvent:
    if len(data) > max_bytes:
        return FramingError(f"datagram larger than {max_bytes} bytes skipped")
    first = data.lstrip()[:1]
    return InFrame(data, binary=bool(first) and 0x80 <= first[0] < 0xC0)


class SharedSocket:
    """The UDP socket every peer's session writes to, one datagram at a time.

    anyio lets one task write a socket at a time (``BusyResourceError`` otherwise),
    and every peer's writer, the challenges and the refusals share one socket.
    """

    def __init__(self, sock: UDPSocket) -> None:
        self._sock = sock
        self._lock = anyio.Lock()

    async def sendto(self, data: bytes, host: str, port: int) -> None:
        """Send one datagram to ``(host, port)``, after the writes already waiting."""
        async with self._lock:
            await self._sock.sendto(data, host, port)


class UdpChannel(PlainChannel):
    """One UDP peer of a shared socket as a pump ``Channel``."""

    transport = "udp"
    awaits_peer_close = False

    def __init__(
        self,
        sock: SharedSocket,
        address: Address,
        inbox: MemoryObjectReceiveStream[bytes],
        options: UdpOptions,
        max_message_size: int,
    ) -> None:
        self.sock = sock
        self.address = address
        self.inbox = inbox
        self.options = options
        self.max_message_size = max_message_size
        self._ids = itertools.count(1)

    async def receive(self) -> Sequence[FramerEvent]:
        """Wait for the peer's next datagram; its end after ``idle_timeout_s`` of silence."""
        with anyio.move_on_after(self.options.idle_timeout_s):
            data = await self.inbox.receive()  # EndOfStream once the listener forgets us
            return [_classify(data, self.max_message_size)]
        raise anyio.EndOfStream

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Send each frame as a datagram, JSON above the size as ``fragment`` ops."""
        limit = self.options.datagram_bytes
        host, port = self.address
        for frame in frames:
            if frame.binary or len(frame.data) <= limit:
                if len(frame.data) > MAX_UDP_PAYLOAD:
                    _episodes.log(
                        logging.WARNING,
                        "udp_drop",
                        "event=udp_drop peer=%s:%d bytes=%d",
                        host,
                        port,
                        len(frame.data),
                    )
                    continue
                await self.sock.sendto(frame.data, host, port)
                continue
            message_id = f"udp:{next(self._ids)}"
            for datagram in fragment_datagrams(frame.data, limit, message_id):
                await self.sock.sendto(datagram, host, port)

    async def close(self, code: CloseCode, reason: str) -> None:
        """Nothing to tell the peer: UDP has no close."""

    async def background(self, session: ServerSession) -> None:
        """Nothing to do."""


async def serve_udp(
    sock: UDPSocket,
    host: SessionHost,
    options: UdpOptions,
    max_message_size: int,
    hosts: HostPrefixes | None = None,
    auth: UdpAuth = _NO_AUTH,
) -> None:
    """Serve every peer of ``sock`` until cancelled.

    Args:
        sock: the bound UDP socket.
        host: makes the sessions.
        options: UDP settings.
        max_message_size: the largest incoming datagram handled, bytes
            (``--max-message-size``); a larger one gets an error status.
        hosts: how source addresses group into hosts for
            ``options.max_sessions_per_host`` (the server's ``--host-prefix-v4``,
            ``--host-prefix-v6``); the defaults when None.
        auth: what the sessions' authentication asks of a peer before its
            session (the server's ``--auth-secret-file``, ``--auth-bind-connection``).
    """
    async with anyio.create_task_group() as tg:
        endpoint = _Endpoint(
            sock, host, options, max_message_size, tg, hosts or HostPrefixes(), auth
        )
        async for data, address in sock:
            try:
                await endpoint.dispatch(data, address)
            except Exception:  # a bug: lose this datagram, never the socket's other peers
                logger.exception("event=bug peer=%s:%d: datagram dropped", *address[:2])


@dataclass(slots=True)
class _Peer:
    inbox: MemoryObjectSendStream[bytes]
    token: str | None  # every datagram carries it (None: the source address is trusted)


class _Endpoint:
    """The peers of one UDP socket: address -> the inbox of that peer's session."""

    def __init__(
        self,
        sock: UDPSocket,
        host: SessionHost,
        options: UdpOptions,
        max_message_size: int,
        tg: TaskGroup,
        hosts: HostPrefixes,
        auth: UdpAuth,
    ) -> None:
        self.sock = SharedSocket(sock)
        self.hosts = hosts
        self.host = host
        self.options = options
        self.max_message_size = max_message_size
        self.tg = tg
        self.auth = auth
        self.peers: dict[Address, _Peer] = {}
        self.validator = AddressValidator()
        self.shares = HostShares(options.max_sessions_per_host)
        self._dropping = False  # a forged or unvalidated datagram was logged (once per episode)

    async def dispatch(self, data: bytes, address: Address) -> None:
        """Hand a datagram to its peer's session; validate an unknown address first."""
        address = (address[0], address[1])
        peer = self.peers.get(address)
        token: str | None = None
        if not self.options.trust_source_address:
            split = split_token(data)
            if peer is not None and (split is None or split[0] != peer.token):
                if split is None or not self.validator.valid(split[0], address):
                    self._drop("forged", address)  # not the session's token: not its peer
                    # A restarted client re-validates; the session's own client, told the
                    # address has a session, keeps its token (a forged datagram costs it nothing).
                    await self._challenge(data, address, has_session=True)
                    return
                # A fresh token for this address: whoever sent it receives there, so it
                # is the address's peer now (a client restarted on the same port).
                self._forget(address, peer)
                peer = None
            if peer is None and (split is None or not self.validator.valid(split[0], address)):
                await self._challenge(data, address)
                return
            assert split is not None
            token, data = split
        if peer is None:
            auth_nonce: str | None = None
            if self.auth.required:
                first = read_first(_classify(data, self.max_message_size))
                if isinstance(first, Refusal):  # no session: a peer must authenticate first
                    await self._refuse(first, address)
                    return
                if self.auth.bound:
                    auth_nonce = self.validator.auth_nonce(address, first.rand)
            peer = await self._open(address, token, auth_nonce)
            if peer is None:
                return
        self._dropping = False
        try:
            peer.inbox.send_nowait(data)
        except anyio.WouldBlock:
            _episodes.log(logging.WARNING, "udp_overrun", "event=udp_overrun peer=%s:%d", *address)

    async def _challenge(self, data: bytes, address: Address, *, has_session: bool = False) -> None:
        replies = self.validator.challenge(
            address, len(data), has_session=has_session, auth=self.auth.bound
        )
        if not replies:
            self._drop("too short to answer", address)
        for reply in replies:
            await self.sock.sendto(reply, *address)

    async def _refuse(self, refusal: Refusal, address: Address) -> None:
        """Answer a datagram that is not ``auth`` from a peer without a session."""
        _episodes.log(
            logging.WARNING,
            "auth_failed",
            "event=auth_failed peer=%s:%d reason=%r",
            *address,
            refusal.reason,
        )
        for frame in refusal.frames:
            await self.sock.sendto(frame, *address)
        if self.auth.bound:  # a peer whose session idled out signs the challenge again
            await self.sock.sendto(self.validator.auth_status(address), *address)

    def _drop(self, why: str, address: Address) -> None:
        if not self._dropping:
            logger.info("event=udp_dropped peer=%s:%d reason=%r", *address, why)
            self._dropping = True

    async def _open(
        self, address: Address, token: str | None, auth_nonce: str | None
    ) -> _Peer | None:
        send, receive = anyio.create_memory_object_stream[bytes](_QUEUED_DATAGRAMS)
        channel = UdpChannel(self.sock, address, receive, self.options, self.max_message_size)
        pump = ConnectionPump(channel, self.host.flow, self.host.admission)
        session = None
        host = self.hosts.host(address[0])
        taken, limit = len(self.peers), self.options.max_sessions
        if taken < limit and self.shares.admits(host, taken, limit):
            peer_name = f"{address[0]}:{address[1]}"
            session = self.host.open_session("udp", peer_name, pump.wake, auth_nonce=auth_nonce)
        if session is None:
            logger.info("event=refused peer=%s:%d reason='too many connections'", *address)
            await self.sock.sendto(_TOO_MANY, *address)
            send.close()
            receive.close()
            return None
        peer = self.peers[address] = _Peer(send, token)
        self.shares.add(host)
        self.tg.start_soon(self._run, pump, session, address, peer, receive)
        return peer

    def _forget(self, address: Address, peer: _Peer) -> None:
        """End ``peer``'s session (its inbox ends) and free its address at once."""
        if self.peers.get(address) is peer:
            del self.peers[address]
            self.shares.remove(self.hosts.host(address[0]))
        peer.inbox.close()

    async def _run(
        self,
        pump: ConnectionPump,
        session: ServerSession,
        address: Address,
        peer: _Peer,
        receive: MemoryObjectReceiveStream[bytes],
    ) -> None:
        try:
            await run_connection(pump, session)
        finally:
            self._forget(address, peer)  # not a newer peer of the same address
            receive.close()
