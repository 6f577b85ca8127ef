"""The native WebRTC stack under the data channels: libdatachannel (docs/webrtc.md, D51).

``rwt serve --webrtc-stack native`` (or ``auto`` where it imports) answers an
offer that asks only for data channels (or for video tracks,
native_video.py) with libdatachannel (usrsctp's SCTP,
libjuice's ICE, in C++) through Shiguredo's ``libdatachannel-py`` binding, in
place of aiortc's SCTP and DTLS in Python. Everything above the peer
connection is the same: signalling, the offer's checks, the connecting and
offer bounds, admission, the session on the pump (peers.py), and
``DataChannelChannel`` (channel.py), which this module feeds through
``NativeDataChannel``, a face of the few members of aiortc's ``RTCDataChannel``
it uses.

libdatachannel calls back on its own threads. Each callback here only hops
onto the event loop (``loop.call_soon_threadsafe``), bounded:

- messages: before a message is queued for the loop, its bytes (and
  ``HOP_OVERHEAD_BYTES``) are counted against the session's inbox bound
  (``INBOX_LIMIT_BYTES`` with what the session has not read yet); past it the
  message is not queued, and the peer is disconnected as on aiortc
  (``event=webrtc_overflow``). A message above the incoming size is not queued
  either: the session gets its error status. So what waits between the threads
  is part of the same 16 MiB a peer may send ahead of its session.
- libdatachannel cuts a message longer than its own size at that size and
  hands the cut on as the whole message. Its size is set one byte over what the
  answer states (``a=max-message-size``, rewritten in the answer), so a message
  over the answer's size always arrives over the incoming size, and is refused
  whole as on aiortc (never a cut op executed); the cut holds at most that size
  and one read (64 KiB) of libdatachannel's.
- the binding holds the GIL while it runs libdatachannel's calls (``send``),
  and libdatachannel runs its buffered-amount callback with its send lock
  held: a Python callback there could wait for the GIL while the loop waits
  for that lock. So no buffered-amount callback is registered: a channel's
  ``bufferedAmount`` (an atomic read) is polled every ``DRAIN_POLL_S`` while a
  writer waits for it to go down, and ``bufferedamountlow`` is emitted on the
  loop, as aiortc emits it.
- for the same reason no call from the loop may wait for libdatachannel's
  threads (its shared thread pool, a peer connection's processor), which may be
  waiting for the GIL in some peer's callback. ``set_remote_description``
  waits for the pool to make the peer's DTLS certificate: seen hanging with the
  pool's threads in gathering callbacks, and under ``rwt conformance`` with them
  in a closing channel's. So the certificate is made once a process
  (``certificate_files``) and handed to each peer connection; the peer
  connection has no state or gathering callback (both are read, every
  ``STATE_POLL_S`` and, while an offer is answered, ``GATHER_POLL_S``); a
  channel is closed only by closing its peer connection
  (``NativeDataChannel.close``; the binding's ``close`` of a peer connection
  releases the GIL), or, refused, on libdatachannel's thread before it has
  callbacks.
- callbacks are set before they can be called (the data channel's before the
  offer is set; a channel's message, open and close ones inside the callback
  that hands it over), and never reset while it runs; each holds only a small
  ``_Hop`` whose target is dropped at close, so no cycle through C++ keeps a
  peer connection alive. Messages hop in batches: one ``call_soon_threadsafe``
  (a write to the loop's wake-up pipe) for those that come before the loop
  drained the last.
"""

from __future__ import annotations

import contextlib
import logging
import re
import threading
from collections import deque
from functools import cache
from typing import TYPE_CHECKING, Any

import anyio

from rwt_protocol.distribution import install_hint

if TYPE_CHECKING:
    import asyncio
    from collections.abc import Callable, Coroutine, Sequence

    from .ice import IceServer

__all__ = [
    "CERTIFICATE_DAYS",
    "DRAIN_POLL_S",
    "GATHER_POLL_S",
    "HOP_OVERHEAD_BYTES",
    "STACKS",
    "STATE_POLL_S",
    "ChannelGate",
    "Inflow",
    "NativeDataChannel",
    "NativePeerConnection",
    "certificate_files",
    "native_ice_refusal",
    "native_ice_server",
    "native_missing",
]

logger = logging.getLogger("rwt.webrtc")

STACKS = ("auto", "reactor", "native", "aiortc")
"""``--webrtc-stack``: ``auto`` (the best that imports, stacks.py, D72), ``reactor``
(libwebrtc's dcsctp, for offers of data channels only, reactor.py, D70),
``native`` (libdatachannel, for offers of data channels only or asking for video
tracks, native_video.py; other offers with audio or video sections stay on
aiortc) or ``aiortc``."""

DRAIN_POLL_S = 0.002
"""Seconds between two reads of a channel's ``bufferedAmount`` while a writer waits."""

STATE_POLL_S = 0.1
"""Seconds between two reads of a peer connection's state (connected, failed, closed)."""

GATHER_POLL_S = 0.005
"""Seconds between two reads of the gathering state while an offer is answered."""

HOP_OVERHEAD_BYTES = 256
"""What one message waiting for the loop is counted beyond its data (the callback and
its frame; the same per-fragment charge as sctp.py's)."""

_STATES = {
    "New": "new",
    "Connecting": "connecting",
    "Connected": "connected",
    "Disconnected": "disconnected",
    "Failed": "failed",
    "Closed": "closed",
}


def _import() -> Any:
    import libdatachannel  # noqa: PLC0415 (optional: rwt-rosbridge[webrtc] on Python 3.12+)

    return libdatachannel


@cache
def native_missing() -> str | None:
    """Why the native stack cannot run here (None: it can).

    libdatachannel-py has wheels for CPython 3.12 and later only (D51).
    """
    try:
        _import()
    except ImportError as exc:
        return (
            f"the native WebRTC stack needs libdatachannel-py (Python 3.12+): "
            f"{install_hint('webrtc')} ({exc})"
        )
    return None


class _Hop:
    """What a native callback holds: the loop and a target, dropped at close."""

    __slots__ = ("loop", "target")

    def __init__(self, loop: asyncio.AbstractEventLoop, target: object) -> None:
        self.loop = loop
        self.target: Any = target

    def post(self, method: str, *args: object) -> None:
        """Call ``target.<method>(*args)`` on the loop (from any thread); nothing once closed."""
        target = self.target
        if target is None:
            return
        with contextlib.suppress(RuntimeError):  # the loop is closed: the server stopped
            self.loop.call_soon_threadsafe(_call, self, method, args)


def _call(hop: _Hop, method: str, args: tuple[object, ...]) -> None:
    target = hop.target
    if target is not None:
        getattr(target, method)(*args)


class Inflow:
    """Bytes of a peer's messages waiting to hop onto the loop, bounded with its inbox.

    Args:
        limit: the most bytes a peer may have sent ahead of its session
            (``webrtc.INBOX_LIMIT_BYTES``).
        inbox: the bytes the session has not read yet (``DataChannelChannel.inbox_bytes``).
    """

    def __init__(self, limit: int, inbox: Callable[[], int]) -> None:
        self.limit = limit
        self.inbox = inbox
        self._lock = threading.Lock()
        self.pending = 0
        """Bytes queued for the loop and not handed to the session yet."""

    def take(self, size: int) -> bool:
        """Count ``size`` more bytes waiting (a libdatachannel thread); False: over the bound."""
        with self._lock:
            if self.pending + size + self.inbox() > self.limit:
                return False
            self.pending += size
            return True

    def give(self, size: int) -> None:
        """``size`` bytes reached the session (the loop)."""
        with self._lock:
            self.pending -= size


class NativeDataChannel:
    """A libdatachannel data channel with the members of aiortc's ``RTCDataChannel`` used here.

    Made on a libdatachannel thread (``NativePeerConnection``'s channel callback),
    which hands it to the loop, then sets its callbacks (``listen``).
    Events (``message``, ``open``, ``close``, ``bufferedamountlow``, and
    ``oversized`` and ``overflow`` for the inbox bounds) are emitted on the loop.

    Args:
        channel: the binding's ``DataChannel``.
        loop: the server's event loop.
        inflow: the peer's bound on messages waiting for the loop.
        max_message_size: the largest incoming message, bytes; a larger one is
            not queued, ``oversized`` is emitted.
        close_peer: closes the channel's peer connection (``close``).
        bounded: a read of the stack's buffered amount waits for another thread
            (libwebrtc's signalling thread, 50-300 us on a busy machine:
            reactor.py), more than a message's send: keep an upper bound
            instead (``bufferedBound``: the last read plus the bytes sent since; the
            amount only falls between two reads but by sending), and read only when
            the bound is over the limit asked about (``buffered_over``). False: the
            amount is an atomic read (libdatachannel), each ``bufferedAmount`` reads it.
    """

    def __init__(
        self,
        channel: Any,
        loop: asyncio.AbstractEventLoop,
        inflow: Inflow,
        max_message_size: int,
        close_peer: Callable[[], object] = lambda: None,
        bounded: bool = False,
    ) -> None:
        self._channel = channel
        self._bounded = bounded
        self._amount_read = 0
        self._sent_since_read = 0
        self._close_peer = close_peer
        self._loop = loop
        self._inflow = inflow
        self._max = max_message_size
        self._handlers: dict[str, list[Callable[..., object]]] = {}
        self._threshold = 0
        self._waiting: deque[tuple[str | bytes | None, int]] = deque()
        self._scheduled = False  # a _deliver is on its way to the loop
        self._polling = False
        self._overflowed = False
        reliability = channel.reliability()
        self.label: str = channel.label()
        self.id: int | None = channel.id()
        self.ordered = not reliability.unordered
        self.maxRetransmits: int | None = reliability.max_retransmits
        lifetime = reliability.max_packet_lifetime
        self.maxPacketLifeTime = None if lifetime is None else float(lifetime.total_seconds())
        self.readyState = "open" if channel.is_open() else "connecting"
        self._hop = _Hop(loop, self)

    def listen(self) -> None:
        """Set the channel's callbacks (on its libdatachannel thread).

        Messages that came before are handed over now, in order: libdatachannel
        keeps them until a message callback is set.
        """
        hop, channel = self._hop, self._channel  # the callbacks hold the hop only, not self
        channel.on_message(lambda message: _arrived(hop, message))
        channel.on_open(lambda: hop.post("_opened"))
        channel.on_closed(lambda: hop.post("_closed"))

    def on(self, event: str, handler: Callable[..., object]) -> None:
        """Call ``handler`` on the loop at each ``event`` (aiortc's ``on``)."""
        self._handlers.setdefault(event, []).append(handler)

    def _emit(self, event: str, *args: object) -> None:
        for handler in list(self._handlers.get(event, ())):
            handler(*args)

    def _arrived(self, hop: _Hop, message: str | bytes) -> None:
        """A message (a libdatachannel thread): queue it for the loop within the bound."""
        if hop.target is None or self._overflowed:
            return
        size = len(message)
        if size > self._max:  # the loop gets a marker, never the data
            if self._inflow.take(HOP_OVERHEAD_BYTES):
                self._queue(hop, None, HOP_OVERHEAD_BYTES)
            return
        if not self._inflow.take(size + HOP_OVERHEAD_BYTES):
            self._overflowed = True
            hop.post("_emit", "overflow")
            return
        self._queue(hop, message, size + HOP_OVERHEAD_BYTES)

    def _queue(self, hop: _Hop, message: str | bytes | None, charged: int) -> None:
        """Queue a message (None: one over the size) for the loop; one wake-up a batch.

        ``call_soon_threadsafe`` wakes the loop with a write to its pipe: once for
        the messages that come while the loop has not drained the queue yet.
        """
        self._waiting.append((message, charged))
        if not self._scheduled:
            self._scheduled = True
            hop.post("_deliver")

    def _deliver(self) -> None:
        """Hand the queued messages to the session (the loop), in order."""
        self._scheduled = False  # first: one queued from now on schedules again
        while self._waiting and self.readyState != "closed":
            message, charged = self._waiting.popleft()
            self._inflow.give(charged)
            if message is None:
                self._emit("oversized")
            else:
                self._emit("message", message)

    def _opened(self) -> None:
        if self.readyState == "connecting":
            self.readyState = "open"
            self._emit("open")

    def _closed(self) -> None:
        if self.readyState != "closed":
            self.readyState = "closed"
            self._hop.target = None
            while self._waiting:  # never handed over: no longer held
                self._inflow.give(self._waiting.popleft()[1])
            self._emit("close")

    @property
    def bufferedAmount(self) -> int:
        """Bytes sent and not yet handed to SCTP: a read of the stack's ``buffered_amount``."""
        try:
            amount = int(self._channel.buffered_amount())
        except RuntimeError:  # closed
            amount = 0
        if self._bounded:
            self._amount_read, self._sent_since_read = amount, 0
        return amount

    @property
    def bufferedBound(self) -> int:
        """At least the bytes ``bufferedAmount`` would read, without reading it when ``bounded``.

        The last read plus the bytes sent since (webrtc.py compares it first).
        """
        if self._bounded:
            return self._amount_read + self._sent_since_read
        return self.bufferedAmount

    def buffered_over(self, limit: int) -> bool:
        """Whether the stack buffers more than ``limit`` bytes; read only if the bound is over."""
        return self.bufferedBound > limit and self.bufferedAmount > limit

    @property
    def bufferedAmountLowThreshold(self) -> int:
        """``bufferedamountlow`` is emitted when ``bufferedAmount`` falls to this, bytes."""
        return self._threshold

    @bufferedAmountLowThreshold.setter
    def bufferedAmountLowThreshold(self, value: int) -> None:
        self._threshold = value
        self._watch()

    def send(self, data: str | bytes) -> None:
        """Send one message.

        Raises:
            ConnectionError: the channel is closed, or libdatachannel refused the
                message (larger than the peer's ``a=max-message-size``).
        """
        if self.readyState != "open":
            raise ConnectionError("the data channel is not open")
        try:
            self._channel.send(data)
        except (RuntimeError, ValueError) as exc:  # closed; over the peer's message size
            raise ConnectionError(str(exc)) from exc
        self._sent_since_read += len(data)
        self._watch()

    def _watch(self) -> None:
        """Poll the buffered amount while above the threshold; then emit ``bufferedamountlow``.

        Judged on ``bufferedBound`` (which counts what was just sent): libwebrtc (the
        reactor stack, reactor.py) counts a message on its network thread,
        after ``send`` returns, so a read at once can show the amount before it, and
        a writer that then waited for the event would wait for a poll nobody scheduled.
        """
        if not self._polling and self.readyState == "open" and self.bufferedBound > self._threshold:
            self._polling = True
            self._loop.call_later(DRAIN_POLL_S, self._poll)

    def _poll(self) -> None:
        self._polling = False
        if self.readyState != "open":
            return
        if not self.buffered_over(self._threshold):
            self._emit("bufferedamountlow")
        else:
            self._watch()

    def close(self) -> None:
        """Close the channel by closing its peer connection; ``close`` is emitted now, once.

        Not libdatachannel's ``close``: it resets the channel's callbacks, so from
        the loop (GIL held) it would wait for a message callback waiting for the
        GIL. A channel closes only as its session ends (a refused one is closed
        before it has callbacks, ``NativePeerConnection``), so its peer
        connection goes (its ``close`` releases the GIL).
        """
        if self.readyState == "closed":
            return
        self._closed()
        self._close_peer()


class ChannelGate:
    """What both libraries' peer connections do alike (``NativePeerConnection``, reactor's).

    The channels the peer opens are judged on the library's thread (``admit``): a
    refused one, or a second of a label, is closed there before it has callbacks;
    a taken one goes to the loop's ``datachannel`` handler. ``connectionState`` is
    in aiortc's names; ``state_changed`` tells the ``connectionstatechange`` handlers.
    A subclass sets ``_loop``, ``_hop`` and ``_refusal`` and has ``close``.
    """

    _loop: asyncio.AbstractEventLoop
    _hop: _Hop
    _refusal: Callable[[str, bool, int | None, float | None], str | None]

    def __init__(self) -> None:
        self._labels: set[str] = set()  # the labels taken (the library's thread)
        self._closing: set[asyncio.Task[None]] = set()
        self._handlers: dict[str, list[Callable[[], object]]] = {}
        self._channel_handler: Callable[[NativeDataChannel], object] | None = None
        self.connectionState = "new"

    async def close(self) -> None:
        """Close the peer connection (the library's own way)."""
        raise NotImplementedError

    def on(self, event: str, handler: Callable[..., object]) -> None:
        """``datachannel`` (one ``NativeDataChannel``) or ``connectionstatechange`` (none)."""
        if event == "datachannel":
            self._channel_handler = handler
        else:
            self._handlers.setdefault(event, []).append(handler)

    def admit(self, hop: _Hop, channel: Any, wrapped: NativeDataChannel) -> None:
        """Judge ``wrapped`` (the library's ``channel``) on the library's thread; hand it on."""
        label = wrapped.label
        reason = self._refusal(
            label, wrapped.ordered, wrapped.maxRetransmits, wrapped.maxPacketLifeTime
        )
        if reason is None and label in self._labels:
            reason = "second"
        if reason is not None:  # closed here, before it has callbacks (close's docstring)
            # the log line first: queued on the loop before the close goes out, it is
            # written before the loop can read the peer's side of the close (and before
            # the peer connection can end, which would drop it)
            hop.post("_refused", label, reason)
            with contextlib.suppress(RuntimeError):
                channel.close()
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
            self.run_soon(self.close())

    def run_soon(self, coroutine: Coroutine[Any, Any, None]) -> None:
        """Run ``coroutine`` on the loop, held until it ends."""
        task = self._loop.create_task(coroutine)
        self._closing.add(task)
        task.add_done_callback(self._closing.discard)

    def state_changed(self, state: str) -> None:
        """``connectionState`` is now ``state``: tell the ``connectionstatechange`` handlers."""
        self.connectionState = state
        for handler in list(self._handlers.get("connectionstatechange", ())):
            handler()


class NativePeerConnection(ChannelGate):
    """A libdatachannel peer connection answering one offer of data channels.

    Its ``connectionState`` uses aiortc's names (``connected``, ``failed``,
    ``closed``...); ``on("datachannel", ...)`` and ``on("connectionstatechange",
    ...)`` are called on the loop.

    Args:
        ice_servers: the STUN and TURN servers (``--ice-server``, ice.py);
            none: host candidates only, no traffic to any other host.
        max_message_size: the largest incoming message, bytes; a larger one is
            skipped (the session answers an error status).
        inflow: the peer's bound on messages waiting for the loop.
        answer_max_message_size: the answer's ``a=max-message-size``, bytes
            (``webrtc.sctp.ANSWER_MAX_MESSAGE_SIZE``, as aiortc's answer states);
            libdatachannel's own is one byte more (the module text says why), so
            ``max_message_size`` must be at most this.
        refusal: why a channel the peer opens is closed (label, ordered,
            ``maxRetransmits``, ``maxPacketLifeTime`` in s; None: taken;
            ``webrtc.peers.channel_refusal``). Asked on libdatachannel's thread,
            where the channel is closed before it has callbacks; a second channel
            of a label is refused too.
        tracks: the offer has media sections the caller gives tracks to
            (native_video.py): ``set_offer`` returns libdatachannel's tracks
            of them, and the answer is made only after (``local_answer``).

    Raises:
        RuntimeError: libdatachannel-py does not import (``native_missing``).
    """

    def __init__(
        self,
        ice_servers: Sequence[IceServer],
        max_message_size: int,
        inflow: Inflow,
        answer_max_message_size: int,
        refusal: Callable[[str, bool, int | None, float | None], str | None],
        *,
        tracks: bool = False,
    ) -> None:
        super().__init__()
        ldc = _import()
        self._ldc = ldc
        self._loop = _running_loop()
        self._max = max_message_size
        self._inflow = inflow
        self._refusal = refusal
        config = ldc.Configuration()
        config.ice_servers = [native_ice_server(ldc, server) for server in ice_servers]
        # one byte over the answer: a message libdatachannel cuts is over it (module text)
        config.max_message_size = answer_max_message_size + 1
        self._answer_max = answer_max_message_size
        config.certificate_pem_file, config.key_pem_file = certificate_files()
        config.disable_auto_negotiation = tracks
        self._manual = tracks
        self._pc = ldc.PeerConnection(config)
        self._offered: list[Any] = []  # set_remote_description calls back on this thread
        if tracks:
            self._pc.on_track(self._offered.append)
        self.localSdp: str | None = None
        hop = self._hop = _Hop(self._loop, self)
        self._pc.on_data_channel(lambda channel: _new_channel(hop, channel))
        self._loop.call_later(STATE_POLL_S, self._poll_state)

    def _channel(self, hop: _Hop, channel: Any) -> None:
        """A channel the peer opened (a libdatachannel thread): wrap it, hand it to the loop."""
        if hop.target is None:
            return
        wrapped = NativeDataChannel(channel, self._loop, self._inflow, self._max, self._close_soon)
        self.admit(hop, channel, wrapped)

    def _poll_state(self) -> None:
        """Read the state (an atomic read); a change calls ``connectionstatechange``."""
        if self._hop.target is None:
            return
        state = _STATES.get(self._pc.state().name, "failed")
        if state != self.connectionState:
            self.state_changed(state)
        if state != "closed":
            self._loop.call_later(STATE_POLL_S, self._poll_state)

    def set_offer(self, sdp: str) -> list[Any]:
        """Set the offer; libdatachannel's tracks of its media sections (with ``tracks``).

        Raises:
            ValueError: libdatachannel refused the offer (the message says why).
        """
        ldc = self._ldc
        try:
            self._pc.set_remote_description(ldc.Description(sdp, ldc.Description.Type.Offer))
        except Exception as exc:  # the binding maps C++'s exceptions to several types
            raise ValueError(str(exc) or type(exc).__name__) from exc
        offered = list(self._offered)
        self._offered.clear()  # the callback's list: it keeps no track
        return offered

    async def local_answer(self) -> str:
        """Make the answer (with ``tracks``: their descriptions as set), gather every candidate.

        No trickle: the answer carries its candidates. Bounded by the caller's deadline.

        Raises:
            ValueError: libdatachannel made no answer.
        """
        if self._manual:
            try:
                self._pc.set_local_description()
            except Exception as exc:  # the binding maps C++'s exceptions to several types
                raise ValueError(str(exc) or type(exc).__name__) from exc
        complete = self._ldc.PeerConnection.GatheringState.Complete
        # polled, not a callback (the module docstring)
        while self._pc.gathering_state() != complete:  # noqa: ASYNC110
            await anyio.sleep(GATHER_POLL_S)
        description = self._pc.local_description()
        if description is None:
            raise ValueError("libdatachannel made no answer")
        self.localSdp = _stated_size(str(description), self._answer_max)
        return self.localSdp

    async def answer(self, sdp: str) -> str:
        """Set the offer and gather every candidate (no trickle); the answer's SDP.

        Raises:
            ValueError: libdatachannel refused the offer (the message says why).
        """
        self.set_offer(sdp)
        return await self.local_answer()

    async def close(self) -> None:
        """Close the peer connection (in a worker thread: libdatachannel waits for its threads).

        Its channels' ``close`` events come as libdatachannel closes them.
        """
        if self._hop.target is None and self.connectionState == "closed":
            return
        self._hop.target = None
        self.connectionState = "closed"
        await anyio.to_thread.run_sync(self._pc.close, abandon_on_cancel=True)


def _stated_size(sdp: str, size: int) -> str:
    """``sdp`` (the answer) stating ``size`` as its ``a=max-message-size`` (RFC 8841).

    libdatachannel states its own size, one byte more (``NativePeerConnection``).
    """
    return re.sub(r"^a=max-message-size:\d+", f"a=max-message-size:{size}", sdp, flags=re.M)


def _arrived(hop: _Hop, message: str | bytes) -> None:
    """A channel's message (libdatachannel's thread), to its ``NativeDataChannel``."""
    target = hop.target
    if target is not None:
        target._arrived(hop, message)


def _new_channel(hop: _Hop, channel: Any) -> None:
    """A channel the peer opened (libdatachannel's thread), to its ``NativePeerConnection``."""
    target = hop.target
    if target is not None:
        target._channel(hop, channel)


CERTIFICATE_DAYS = 30
"""Days the server's DTLS certificate is valid (made once a process, ``certificate_files``)."""


@cache
def certificate_files() -> tuple[str, str]:
    """The DTLS certificate and key of this process's native peer connections (PEM files).

    Made once a process (ECDSA P-256, self-signed, ``CERTIFICATE_DAYS``) in a private
    temporary folder, removed at exit. libdatachannel would otherwise make one a peer
    connection on its shared thread pool, and the offer's answer waits for it with the GIL
    held: a pool thread waiting for the GIL in another peer's callback (a channel closing)
    then hangs the server (seen under ``rwt conformance``; D51). A peer checks the
    certificate by its fingerprint in the answer (RFC 8827), so one a process is what a
    browser's, kept per origin, is too.

    Returns:
        (certificate path, key path).
    """
    import atexit  # noqa: PLC0415 (the native stack only)
    import datetime  # noqa: PLC0415
    import shutil  # noqa: PLC0415
    import tempfile  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    from cryptography import x509  # noqa: PLC0415 (aiortc's dependency, the same extra)
    from cryptography.hazmat.primitives import hashes, serialization  # noqa: PLC0415
    from cryptography.hazmat.primitives.asymmetric import ec  # noqa: PLC0415

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(x509.NameOID.COMMON_NAME, "rwt")])
    now = datetime.datetime.now(datetime.UTC)
    certificate = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(days=1))
        .not_valid_after(now + datetime.timedelta(days=CERTIFICATE_DAYS))
        .sign(key, hashes.SHA256())
    )
    folder = Path(tempfile.mkdtemp(prefix="rwt-webrtc-"))  # mode 0700
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    cert_path, key_path = folder / "cert.pem", folder / "key.pem"
    cert_path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    return str(cert_path), str(key_path)


def _running_loop() -> asyncio.AbstractEventLoop:
    import asyncio  # noqa: PLC0415 (the native stack hops onto asyncio's loop)

    return asyncio.get_running_loop()


def native_ice_refusal(servers: Sequence[IceServer]) -> str | None:
    """Why the native stack cannot use ``servers`` (None: it can).

    libdatachannel-py builds libdatachannel with libjuice for ICE, which reaches TURN
    servers over UDP only: libdatachannel 0.24 ignores a ``turns:`` or
    ``turn:...?transport=tcp`` server with a warning, so a peer that only that relay
    could reach would never connect (tests/webrtc/test_nat.py). aiortc's ICE (aioice)
    speaks TURN over TCP and TLS.
    """
    for server in servers:
        if server.url.startswith("turns:") or server.url.endswith("?transport=tcp"):
            return (
                f"the native WebRTC stack (libjuice) reaches TURN servers over UDP only, "
                f"not {server.url}: use --webrtc-stack aiortc, or a turn: URL over UDP"
            )
    return None


def native_ice_server(ldc: Any, server: IceServer) -> Any:
    """The ``IceServer`` of libdatachannel for one parsed ``--ice-server`` (ice.py).

    Args:
        ldc: the ``libdatachannel`` module.
        server: ``stun:HOST:PORT``, or ``turn:``/``turns:`` with its credentials and
            ``?transport=tcp`` (TURN over UDP, TCP or TLS: RFC 7065's forms).
    """
    scheme, _, rest = server.url.partition(":")
    hostport, _, query = rest.partition("?")
    host, _, port = hostport.rpartition(":")
    if scheme == "stun":
        return ldc.IceServer(host, int(port))
    relay = ldc.IceServer.RelayType
    kind = relay.TurnTls if scheme == "turns" else relay.TurnUdp
    if query == "transport=tcp" and scheme == "turn":
        kind = relay.TurnTcp
    return ldc.IceServer(host, int(port), server.username or "", server.credential or "", kind)
