"""The reactor stack under the data channels: libwebrtc's own SCTP (dcsctp), tuned (D70).

``rwt serve --webrtc-stack reactor`` (or ``auto`` where it imports, D72) answers an
offer of data channels only with libwebrtc, the WebRTC engine Chromium runs, through
the ``reactor-webrtc`` binding (PyO3, one abi3 wheel for CPython 3.10 and later).
Its factory tunes dcsctp's congestion control (``SCTP_TUNING``): a window that never
falls below 16 packets after a loss, SACKs held at most 20 ms, a minimum
retransmission timeout of 120 ms. Everything above the peer connection is the
other stacks' (peers.py): signalling, the offer's checks, the connecting
and offer bounds, admission, the session, ``DataChannelChannel`` with its flow
control and lossy lane. The channels go through native.py's
``NativeDataChannel`` (its hop onto the loop, its inbox bound, its polled
``bufferedAmount``, here ``bounded``: each read of it waits for libwebrtc's signalling
thread), behind ``_Channel``, a face of the few libdatachannel calls it makes.

Threads and the GIL: libwebrtc calls back on its signalling thread, with the GIL
taken; the binding releases the GIL in every call that waits for a libwebrtc thread
(``send``, ``buffered_amount``, the signalling calls, which are awaitable, and the
release of a peer connection, which closes it), so a call from the loop never waits
for a callback that waits for the GIL. Callbacks here only hop onto the loop
(``_Hop``), as the native stack's do. A peer connection has no ``close``: it closes
when the binding's object is released, which ``close`` does in a worker thread.

The answer carries every candidate (no trickle): they come one by one
(``on_ice_candidate``) and are written into the answer once gathering completes.

What libwebrtc does not tell: a data channel's ``maxRetransmits`` and
``maxPacketLifeTime``. It tells whether a channel is ordered and whether it is
reliable, so an unordered channel that is not reliable is taken as the lossy one
(D36 asks for ``maxRetransmits`` 0; one with a packet lifetime passes here too).
"""

from __future__ import annotations

import contextlib
import logging
from functools import cache
from typing import TYPE_CHECKING, Any

import anyio

from rwt_protocol.distribution import install_hint

from .native import NativeDataChannel, _Hop, _running_loop

if TYPE_CHECKING:
    import asyncio
    from collections.abc import Callable, Sequence

    from .ice import IceServer
    from .native import Inflow

__all__ = [
    "GATHER_TIMEOUT_S",
    "SCTP_TUNING",
    "ReactorPeerConnection",
    "add_candidates",
    "reactor_factory",
    "reactor_missing",
]

logger = logging.getLogger("rwt.webrtc")

SCTP_TUNING: dict[str, int] = {"min_cwnd_mtus": 16, "delayed_ack_max_ms": 20, "rto_min_ms": 120}
"""dcsctp's settings for every data channel of the process (``with_sctp_tuning``, D70):
after a loss the window stays at 16 packets at least (upstream: 4), SACKs wait at most
20 ms (200), and a retransmission timeout is 120 ms at least (400). Measured on a
2 Mbit/s bottleneck beside a TCP download, docs/webrtc.md ("Which stack")."""

GATHER_TIMEOUT_S = 5.0
"""Seconds an answer waits for its candidates (STUN and TURN servers' included)."""

_STATES = {
    "New": "new",
    "Connecting": "connecting",
    "Connected": "connected",
    "Disconnected": "disconnected",
    "Failed": "failed",
    "Closed": "closed",
}


def _import() -> Any:
    import reactor_webrtc  # noqa: PLC0415 (optional: rwt-rosbridge[webrtc])

    return reactor_webrtc


@cache
def reactor_missing() -> str | None:
    """Why the reactor stack cannot run here (None: it can).

    reactor-webrtc (the ``webrtc-reactor`` extra) has abi3 wheels for CPython 3.10+ on
    Linux x86_64 and aarch64 (glibc 2.34+), macOS arm64 and Windows x86_64 (D70).
    """
    try:
        _import()
    except ImportError as exc:
        hint = install_hint("webrtc-reactor")
        return f"the reactor WebRTC stack needs reactor-webrtc: {hint} ({exc})"
    return None


@cache
def reactor_factory() -> Any:
    """The process's one ``PeerConnectionFactory``, with ``SCTP_TUNING``.

    The binding allows one at a time: made at the first peer connection, kept.
    """
    builder = _import().PeerConnectionFactoryBuilder()
    builder.with_sctp_tuning(**SCTP_TUNING)
    return builder.build()


class _Reliability:
    """What ``NativeDataChannel`` reads of a channel's reliability (libdatachannel's names)."""

    __slots__ = ("max_packet_lifetime", "max_retransmits", "unordered")

    def __init__(self, ordered: bool, reliable: bool) -> None:
        self.unordered = not ordered
        self.max_retransmits = None if reliable else 0
        self.max_packet_lifetime = None


class _Channel:
    """A reactor-webrtc ``DataChannel`` with the libdatachannel calls of ``NativeDataChannel``."""

    __slots__ = ("_channel",)

    def __init__(self, channel: Any) -> None:
        self._channel = channel

    def reliability(self) -> _Reliability:
        return _Reliability(self._channel.ordered(), self._channel.reliable())

    def label(self) -> str:
        return str(self._channel.label())

    @staticmethod
    def id() -> None:  # libwebrtc's binding tells no stream id; none is needed here
        return None

    def is_open(self) -> bool:
        return bool(self._channel.state() == _import().DataChannelState.Open)

    def on_message(self, callback: Callable[[str | bytes], None]) -> None:
        def arrived(data: bytes, binary: bool) -> None:  # a text message: its UTF-8
            callback(data if binary else data.decode("utf-8", "replace"))

        self._channel.on_message(arrived)

    def on_open(self, callback: Callable[[], None]) -> None:
        self._channel.on_open(callback)

    def on_closed(self, callback: Callable[[], None]) -> None:
        self._channel.on_close(callback)

    def buffered_amount(self) -> int:
        return int(self._channel.buffered_amount())

    def send(self, data: str | bytes) -> None:
        if isinstance(data, str):
            self._channel.send(data.encode("utf-8"), False)
        else:
            self._channel.send(data, True)

    def close(self) -> None:
        self._channel.close()


class ReactorPeerConnection:
    """A libwebrtc peer connection (reactor-webrtc) answering one offer of data channels.

    The face of ``webrtc.native.NativePeerConnection``: ``connectionState`` in aiortc's
    names, ``on("datachannel"|"connectionstatechange", ...)`` called on the loop,
    ``answer`` and ``close``.

    Args:
        ice_servers: the STUN and TURN servers (``--ice-server``, ice.py:
            TURN over UDP, TCP or TLS); none: host candidates only.
        max_message_size: the largest incoming message, bytes; a larger one is
            skipped (the session answers an error status).
        inflow: the peer's bound on messages waiting for the loop.
        refusal: why a channel the peer opens is closed (label, ordered,
            ``maxRetransmits``, ``maxPacketLifeTime``; None: taken;
            ``webrtc.peers.channel_refusal``), asked on libwebrtc's thread; a second
            channel of a label is refused too.

    Raises:
        RuntimeError: reactor-webrtc does not import (``reactor_missing``).
    """

    def __init__(
        self,
        ice_servers: Sequence[IceServer],
        max_message_size: int,
        inflow: Inflow,
        refusal: Callable[[str, bool, int | None, float | None], str | None],
    ) -> None:
        rw = _import()
        self._loop = _running_loop()
        self._max = max_message_size
        self._inflow = inflow
        self._refusal = refusal
        self._labels: set[str] = set()  # the labels taken (libwebrtc's thread)
        self._handlers: dict[str, list[Callable[[], object]]] = {}
        self._channel_handler: Callable[[NativeDataChannel], object] | None = None
        self._candidates: list[tuple[str | None, str]] = []
        self._gathered = anyio.Event()
        self._closing: set[asyncio.Task[None]] = set()
        self.connectionState = "new"
        hop = self._hop = _Hop(self._loop, self)
        observer = rw.PeerConnectionObserver()  # each callback holds the hop only
        observer.on_data_channel = lambda channel: _new_channel(hop, channel)
        observer.on_connection_state_change = lambda state: hop.post("_state", _name(state))
        observer.on_ice_candidate = lambda c: hop.post("_candidate", c.sdp_mid, c.candidate)
        observer.on_ice_gathering_change = lambda state: hop.post("_gathering", _name(state))
        servers = [
            rw.IceServer(
                urls=[server.url], username=server.username or "", password=server.credential or ""
            )
            for server in ice_servers
        ]
        config = rw.RtcConfiguration(ice_servers=servers, frame_metadata=False)
        self._pc: Any = reactor_factory().create_peer_connection(config, observer)

    def on(self, event: str, handler: Callable[..., object]) -> None:
        """``datachannel`` (one ``NativeDataChannel``) or ``connectionstatechange`` (none)."""
        if event == "datachannel":
            self._channel_handler = handler
        else:
            self._handlers.setdefault(event, []).append(handler)

    def _channel(self, hop: _Hop, channel: Any) -> None:
        """A channel the peer opened (libwebrtc's thread): judge it, hand it to the loop."""
        if hop.target is None:
            return
        wrapped = NativeDataChannel(
            _Channel(channel), self._loop, self._inflow, self._max, self._close_soon, bounded=True
        )
        label = wrapped.label
        reason = self._refusal(
            label, wrapped.ordered, wrapped.maxRetransmits, wrapped.maxPacketLifeTime
        )
        if reason is None and label in self._labels:
            reason = "second"
        if reason is not None:
            with contextlib.suppress(RuntimeError):
                channel.close()
            hop.post("_refused", label, reason)
            return
        self._labels.add(label)
        hop.post("_got_channel", wrapped)  # first: the loop takes it before its messages
        wrapped.listen()

    @staticmethod
    def _refused(label: str, reason: str) -> None:
        logger.info("event=channel_refused label=%r reason=%s", label, reason)

    def _got_channel(self, channel: NativeDataChannel) -> None:
        if self._channel_handler is not None:
            self._channel_handler(channel)
        else:
            channel.close()

    def _close_soon(self) -> None:
        """Close the peer connection (a channel of it closed, from the loop)."""
        if self._hop.target is not None:
            task = self._loop.create_task(self.close())
            self._closing.add(task)
            task.add_done_callback(self._closing.discard)

    def _state(self, name: str) -> None:
        state = _STATES.get(name, "failed")
        if self.connectionState not in (state, "closed"):
            self.connectionState = state
            for handler in list(self._handlers.get("connectionstatechange", ())):
                handler()
            if state == "connected":
                task = self._loop.create_task(self._log_path())
                self._closing.add(task)
                task.add_done_callback(self._closing.discard)

    async def _log_path(self) -> None:
        """Log the candidate pair ICE chose: its local candidate's type and TURN transport.

        ``relay=tcp`` when the server's relayed candidate reaches coturn over TCP.
        """
        pc = self._pc
        if pc is None:
            return
        with contextlib.suppress(RuntimeError):  # closed meanwhile
            report = await pc.get_stats()
            for pair in report.candidate_pairs:
                if pair.nominated:
                    logger.info(
                        "event=webrtc_path stack=reactor candidate=%s relay=%s",
                        _name(pair.local_candidate_type).lower(),
                        _name(pair.local_relay_protocol).lower(),
                    )

    def _candidate(self, mid: str | None, candidate: str) -> None:
        self._candidates.append((mid, candidate))

    def _gathering(self, name: str) -> None:
        if name == "Complete":
            self._gathered.set()

    async def answer(self, sdp: str) -> str:
        """Set the offer, answer it, gather every candidate (no trickle); the answer's SDP.

        Raises:
            ValueError: libwebrtc refused the offer, or made no answer (the message says why).
        """
        rw = _import()
        try:
            await self._pc.set_remote_description(rw.SessionDescription("offer", sdp))
            answer = await self._pc.create_answer()
            await self._pc.set_local_description(answer)
        except RuntimeError as exc:  # the binding's libwebrtc errors
            raise ValueError(str(exc) or type(exc).__name__) from exc
        with anyio.move_on_after(GATHER_TIMEOUT_S):
            await self._gathered.wait()
        return add_candidates(str(answer.sdp), self._candidates)

    async def close(self) -> None:
        """Close the peer connection: release the binding's object, in a worker thread.

        libwebrtc closes it on its signalling thread; the GIL is released meanwhile.
        """
        if self._hop.target is None and self.connectionState == "closed":
            return
        self._hop.target = None
        self.connectionState = "closed"
        held = [self._pc]
        self._pc = None
        await anyio.to_thread.run_sync(held.clear, abandon_on_cancel=True)


def _name(state: object) -> str:
    """An enum value's name (the binding's enums have no ``name``: ``Kind.Name`` is their text)."""
    return str(state).rpartition(".")[2]


def _new_channel(hop: _Hop, channel: Any) -> None:
    """A channel the peer opened (libwebrtc's thread), to its ``ReactorPeerConnection``."""
    target = hop.target
    if target is not None:
        target._channel(hop, channel)


def add_candidates(sdp: str, candidates: Sequence[tuple[str | None, str]]) -> str:
    """``sdp`` with each ``(mid, "candidate:...")`` written into its media section.

    A candidate of no mid goes to the first section (with BUNDLE, every one does);
    each section that got some ends with ``a=end-of-candidates`` (RFC 8840).
    """
    lines = sdp.replace("\r\n", "\n").rstrip("\n").split("\n")
    sections: list[list[str]] = [[]]
    for line in lines:
        if line.startswith("m="):
            sections.append([])
        sections[-1].append(line)
    mids = [_mid(section) for section in sections[1:]]
    for mid, candidate in candidates:
        index = mids.index(mid) if mid in mids else 0
        if len(sections) > index + 1:
            sections[index + 1].append(f"a={candidate}")
    for section in sections[1:]:
        if any(line.startswith("a=candidate:") for line in section):
            section.append("a=end-of-candidates")
    return "\r\n".join(line for section in sections for line in section) + "\r\n"


def _mid(section: Sequence[str]) -> str | None:
    for line in section:
        if line.startswith("a=mid:"):
            return line.removeprefix("a=mid:")
    return None
