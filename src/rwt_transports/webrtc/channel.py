"""A WebRTC peer's data channels as a pump ``Channel`` (docs/webrtc.md).

A reliable, ordered data channel of a registered label (``rosbridge``; the registry,
``frontends_registry``, names them, peers.py takes them) carries its
front end's session exactly as a WebSocket connection does: one message per frame,
for rosbridge JSON as text, CBOR as binary (D27). The session, its limits and its flow control are
the server's (pump.py); this module only moves frames:

- in: aiortc hands over whole messages from a callback, with no way to make the
  peer wait, so the messages the pump has not read yet, with the fragments its
  SCTP holds for the session (``held_below``, sctp.py), are bounded by
  ``INBOX_LIMIT_BYTES``; past it the peer is disconnected. A message above
  ``--max-message-size`` is skipped with an error status, as UDP does (sctp.py
  abandons it as it arrives). What waits for the session is charged to the
  server's memory budget (``--memory-budget``, D44) as the connection's, never
  refused by it: it is a reader's input.
- out: a text frame above ``MAX_TEXT_FRAME_BYTES`` (64 KiB, the size every
  peer accepts, RFC 8841 6.1) is cut by the session's front end
  (``FrontEnd.split_text``: rosbridge's goes out as ``fragment`` ops, spec 3.1.1,
  D19, which the client reassembles). Any other frame (CBOR, or text of a front end
  that cuts none) goes whole if the peer's ``a=max-message-size`` allows it, else
  it is dropped and logged (D74).
- the SCTP send buffer is flow-controlled like a socket's: ``send`` waits while
  the channel's ``bufferedAmount`` is above ``SEND_HIGH_WATER_BYTES``, until
  its ``bufferedamountlow`` event, so a slow reader fills the session's outbox
  and the slow-consumer rule (D24) applies as on a WebSocket.
- the lossy channel (``rosbridge-lossy``: unordered, no retransmission; D36) is the
  same session's second way out: its incoming messages go to the session as
  any (``LossyInFrame``), and the messages of the subscriptions made on it wait
  in the session's lossy lane, latest-only per topic. aiortc sends every data
  channel's messages of a peer connection in one FIFO (its SCTP transport's
  data channel queue, then its outbound queue), so a lossy message handed over
  behind a reliable backlog would wait for all of it. The lossy writer
  (``background``) therefore hands a message over only while both channels
  buffer at most ``LOSSY_GATE_BYTES`` together (their ``bufferedAmount``; the
  outbound queue holds the rest of one message at most, as aiortc moves the
  next only when it is empty), and while the lane holds a message the
  reliable writer hands aiortc nothing: the lossy messages go next, ahead of
  the reliable backlog, which waits in the session's outbox. The lossy channel
  so has priority: a lossy stream that takes the whole link holds the reliable
  channel's messages back (the peer chooses it; ``throttle_rate`` limits it).
"""

from __future__ import annotations

import logging
from collections import deque
from typing import TYPE_CHECKING

import anyio
from aiortc.exceptions import InvalidStateError

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.runtime.contract import LossySession
from rwt_protocol.runtime.inframes import FramerEvent, FramingError, InFrame, LossyInFrame

from ..channel import PlainChannel

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from aiortc import RTCDataChannel

    from .native import NativeDataChannel

    AnyDataChannel = RTCDataChannel | NativeDataChannel
    """A data channel of either stack: aiortc's, or libdatachannel's (``NativeDataChannel``)."""

    from rwt_protocol.runtime.commands import CloseCode
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.memory import MemoryAccount
    from rwt_protocol.runtime.outbox import OutFrame

__all__ = [
    "INBOX_LIMIT_BYTES",
    "LOSSY_GATE_BYTES",
    "MAX_TEXT_FRAME_BYTES",
    "RECHECK_S",
    "SEND_HIGH_WATER_BYTES",
    "SEND_LOW_WATER_BYTES",
    "DataChannelChannel",
]

logger = logging.getLogger("rwt.webrtc")
_episodes = EpisodeLog(logger)  # a peer can trigger these at will

MiB = 1024 * 1024

MAX_TEXT_FRAME_BYTES = 64 * 1024
"""Largest JSON message sent whole on the data channel; a larger one goes as ``fragment``
ops (RFC 8841 6.1: 64 KiB is what a peer that states no ``max-message-size`` accepts)."""

INBOX_LIMIT_BYTES = 16 * MiB
"""Bytes of received messages the session has not read yet; past it the peer is
disconnected (aiortc cannot make a peer wait, as a paused socket does)."""

SEND_HIGH_WATER_BYTES = 1 * MiB
"""``send`` waits while the data channel buffers more than this for the peer."""

SEND_LOW_WATER_BYTES = 256 * 1024
"""``send`` goes on when the channel's buffer is back under this (``bufferedamountlow``)."""

RECHECK_S = 0.05
"""A writer waiting for a channel's buffer re-reads it this often, whatever the events say:
a stack that counts a message after ``send`` returns (libwebrtc) can let the one
``bufferedamountlow`` a writer waits for go by (native.py, ``_watch``)."""

LOSSY_GATE_BYTES = 2 * 1024
"""A lossy message is handed to aiortc only while the session's data channels buffer at most
this together; while one waits, the reliable writer keeps its channel under it too (D36).
A few small messages: what waits in aiortc's queue is not latest-only, and at 64 KiB a
1 kHz topic on a lossy WAN link queued there 1.5 s (docs/benchmarks.md, "Over a WAN link")."""


class DataChannelChannel(PlainChannel):
    """A peer's ``rosbridge`` data channel, and its ``rosbridge-lossy`` one, as a pump ``Channel``.

    Args:
        channel: the ``rosbridge`` data channel (aiortc), or None to ``attach`` it
            later; the pump runs only once it is attached and open.
        max_message_size: the largest incoming message, bytes (``--max-message-size``).
        remote_max_message_size: the largest message the peer accepts, bytes (its
            SDP's ``a=max-message-size``; 0: any size).
        memory: the session's account of the server's memory budget (D44), charged
            with the messages not read yet; None: not charged.
    """

    transport = "webrtc"
    awaits_peer_close = False

    def __init__(
        self,
        channel: AnyDataChannel | None,
        max_message_size: int,
        remote_max_message_size: int,
        memory: MemoryAccount | None = None,
    ) -> None:
        self.max_message_size = max_message_size
        self.remote_max_message_size = remote_max_message_size
        self._memory = memory
        self._inbox: deque[FramerEvent] = deque()
        self._inbox_bytes = 0
        self._arrived = anyio.Event()
        self._drained = anyio.Event()
        self._ended = False
        self.overflowed = False
        self.split_text: Callable[[bytes, int], Sequence[bytes]] | None = None
        """How the session's front end cuts a text frame too large for a message
        (``FrontEnd.split_text``; set when the session opens); None: sent whole."""
        """The peer sent more than ``INBOX_LIMIT_BYTES`` ahead of the session: it was cut."""
        self.held_below: Callable[[], int] = lambda: 0
        """Bytes the peer connection holds for the session below it (its SCTP reassembly,
        ``webrtc.sctp.SctpBound``): they count toward ``INBOX_LIMIT_BYTES`` with the inbox."""
        self._channels: list[AnyDataChannel] = []  # every channel attached, to close
        self._reliable: AnyDataChannel | None = None
        self._lossy: AnyDataChannel | None = None
        self._lossy_state = anyio.Event()  # the lossy channel came, or went
        self._lane_ready = anyio.Event()  # the session's lossy lane holds a message
        self._lossy_pending = False  # the lane holds messages: the reliable writer yields
        self._room = anyio.Event()  # the lossy writer's wake-up: a channel's buffer went down
        if channel is not None:
            self.attach(channel)

    @property
    def _dc(self) -> AnyDataChannel:
        if self._reliable is None:  # the pump runs only once it is attached
            raise anyio.BrokenResourceError
        return self._reliable

    def charge_to(self, memory: MemoryAccount | None) -> None:
        """Charge what waits for the session to ``memory`` (its account, D44), from now on.

        The session is opened after the peer connection (its first data channel
        opens it, peers.py), so its account comes then.
        """
        if self._memory is not None:
            self._memory.charge(-self._inbox_bytes)
        self._memory = memory
        if memory is not None:
            memory.charge(self._inbox_bytes)

    def attach(self, channel: AnyDataChannel) -> None:
        """Take the ``rosbridge`` channel (reliable, ordered): the session's input and output."""
        self._reliable = channel
        self._channels.append(channel)
        channel.bufferedAmountLowThreshold = SEND_LOW_WATER_BYTES
        channel.on("message", self._on_message)
        channel.on("close", self._on_close)
        channel.on("bufferedamountlow", self._on_low)
        if channel.readyState in ("closing", "closed"):
            self._on_close()

    def attach_lossy(self, channel: AnyDataChannel) -> None:
        """Take the ``rosbridge-lossy`` channel (unordered, sent again once at most; D36, D73).

        Its messages reach the session as ``LossyInFrame``; its output is the
        session's lossy lane, which the caller opens (``lossy_ready`` is the
        lane's wake-up) and ``background`` sends.
        """
        self._lossy = channel
        self._channels.append(channel)
        channel.bufferedAmountLowThreshold = _UNWATCHED  # watched while the gate waits
        channel.on("message", lambda message: self._on_message(message, lossy=True))
        channel.on("close", self._on_lossy_close)
        channel.on("bufferedamountlow", self._on_low)
        self._lossy_state.set()

    def lossy_ready(self) -> None:
        """The session's lossy lane got a message (the lane's ``on_output``)."""
        self._lossy_pending = True
        self._lane_ready.set()

    def _on_lossy_close(self) -> None:
        self._lossy = None
        self._lossy_pending = False
        self._lossy_state.set()
        self._lane_ready.set()
        self._room.set()
        self._drained.set()  # the reliable writer need not yield any more

    def _on_message(self, message: str | bytes, *, lossy: bool = False) -> None:
        """Queue one incoming message for ``receive`` (aiortc's callback)."""
        if self._ended:
            return
        binary = isinstance(message, bytes)
        data = message if isinstance(message, bytes) else message.encode("utf-8", "replace")
        if len(data) > self.max_message_size:
            self.oversized()
            return
        self._inbox.append(LossyInFrame(data, binary) if lossy else InFrame(data, binary))
        self._inbox_bytes += len(data)
        if self._memory is not None:
            self._memory.charge(len(data))
        if self._inbox_bytes + self.held_below() > INBOX_LIMIT_BYTES:
            self.overflow()
        self._arrived.set()

    @property
    def inbox_bytes(self) -> int:
        """Bytes of received messages the session has not read yet."""
        return self._inbox_bytes

    def oversized(self) -> None:
        """A message over ``max_message_size`` was skipped: the session answers an error.

        Skipped here, or abandoned below as it arrived (sctp.py); the
        status is the one UDP answers.
        """
        if not self._ended:
            self._inbox.append(
                FramingError(f"message larger than {self.max_message_size} bytes skipped")
            )
            self._arrived.set()

    def overflow(self) -> None:
        """The peer sent more than ``INBOX_LIMIT_BYTES`` ahead of the session: cut it."""
        if self._ended:
            return
        _episodes.log(
            logging.WARNING,
            "webrtc_inbox",
            "event=webrtc_overflow bytes=%d limit=%d: peer disconnected",
            self._inbox_bytes + self.held_below(),
            INBOX_LIMIT_BYTES,
        )
        self.overflowed = True
        self._inbox.clear()
        self._inbox_read()
        self._on_close()
        self._close_all()

    def _on_low(self) -> None:
        self._drained.set()
        self._room.set()

    def _on_close(self) -> None:
        self._ended = True
        self._arrived.set()
        self._drained.set()
        self._room.set()

    async def receive(self) -> Sequence[FramerEvent]:
        """The messages received since the last call; waits for at least one.

        Raises:
            anyio.EndOfStream: the data channel closed and every message was read.
        """
        while not self._inbox:
            if self._ended:
                raise anyio.EndOfStream
            self._arrived = anyio.Event()
            await self._arrived.wait()
        events = list(self._inbox)
        self._inbox.clear()
        self._inbox_read()
        return events

    def _inbox_read(self) -> None:
        """The inbox was emptied: its bytes are no longer held (nor charged)."""
        if self._memory is not None:
            self._memory.charge(-self._inbox_bytes)
        self._inbox_bytes = 0

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Send the frames in order, waiting while the channel's buffer is full.

        A text frame goes as the session's front end cuts it (``split_text``:
        rosbridge's ``fragment`` ops above ``MAX_TEXT_FRAME_BYTES``, D19); any other
        frame goes whole, or is dropped and logged if the peer's
        ``a=max-message-size`` is smaller (D74).

        Raises:
            anyio.BrokenResourceError: the data channel closed.
        """
        for frame in frames:
            data = frame.prefix + frame.data if frame.prefix else frame.data
            split = None if frame.binary else self.split_text
            if split is not None:
                for part in split(data, MAX_TEXT_FRAME_BYTES):
                    await self._yield_to_lossy()
                    self._send(part.decode("utf-8"))
                    await self._drain()
            else:
                if self._beyond_peer(data):
                    continue
                await self._yield_to_lossy()
                self._send(data if frame.binary else data.decode("utf-8"))
            await self._drain()

    def _beyond_peer(self, data: bytes) -> bool:
        """Whether the peer takes no message as large as ``data``: dropped, logged (an episode)."""
        limit = self.remote_max_message_size
        if not limit or len(data) <= limit:
            return False
        _episodes.log(
            logging.WARNING,
            "webrtc_drop",
            "event=webrtc_drop bytes=%d limit=%d: a frame above the peer's max-message-size "
            "dropped",
            len(data),
            limit,
        )
        return True

    def _send(self, data: str | bytes) -> None:
        if self._ended:
            raise anyio.BrokenResourceError
        try:
            self._dc.send(data)
        except (InvalidStateError, ConnectionError) as exc:
            raise anyio.BrokenResourceError from exc

    async def _drain(self) -> None:
        """Wait while the channel buffers more than ``SEND_HIGH_WATER_BYTES`` for the peer."""
        channel = self._dc
        while _over(channel, SEND_HIGH_WATER_BYTES):
            if self._ended:
                raise anyio.BrokenResourceError
            self._drained = anyio.Event()
            with anyio.move_on_after(RECHECK_S):
                await self._drained.wait()

    async def _yield_to_lossy(self) -> None:
        """Wait while the lossy lane holds messages: they go first (D36).

        The reliable channel's backlog stays in the session's outbox meanwhile,
        so the lossy writer finds room in aiortc's queue soon.
        """
        while self._lossy_pending and self._lossy is not None:
            if self._ended:
                raise anyio.BrokenResourceError
            self._drained = anyio.Event()
            await self._drained.wait()

    async def close(self, code: CloseCode, reason: str) -> None:
        """Close the data channels (they have no close code; the reason is in the server log)."""
        self._on_close()
        self._close_all()

    def _close_all(self) -> None:
        for channel in self._channels:
            channel.close()

    async def background(self, session: ServerSession) -> None:
        """Send the session's lossy lane on the ``rosbridge-lossy`` channel while it is open.

        SCTP has its own heartbeat: nothing else to do. A session without a lossy lane
        (``LossySession``) sends nothing here.
        """
        if not isinstance(session, LossySession):
            await anyio.sleep_forever()
            return
        while True:
            self._lane_ready = anyio.Event()
            self._lossy_state = anyio.Event()
            channel = self._lossy
            if channel is None:
                session.close_lossy_lane()  # closed: its subscriptions go on the reliable one
                await self._lossy_state.wait()
                continue
            while (
                self._lossy is channel
                and self._lossy_pending
                and await self._room_for_lossy(channel)
            ):
                frame = session.lossy_frame_to_send(anyio.current_time())
                if frame is None:  # the lane is empty: the reliable writer goes on
                    self._lossy_pending = False
                    self._drained.set()
                    break
                data = frame.prefix + frame.data if frame.prefix else frame.data
                try:
                    channel.send(data if frame.binary else data.decode("utf-8"))
                except (InvalidStateError, ConnectionError, ValueError):
                    self._on_lossy_close()
            if self._lossy is channel:
                await self._lane_ready.wait()

    async def _room_for_lossy(self, channel: AnyDataChannel) -> bool:
        """Wait until the channels buffer at most ``LOSSY_GATE_BYTES``; False if it closed.

        The lane keeps only each topic's latest message meanwhile, and the
        reliable writer waits (``_yield_to_lossy``). Judged on the channels' bounds
        first (``_bound``: on the reactor stack a read waits for libwebrtc's thread);
        read, and watched (``bufferedamountlow``), only while the bounds say no.
        """
        reliable = self._dc
        if _bound(reliable) + _bound(channel) <= LOSSY_GATE_BYTES:
            return self._lossy is channel
        try:
            reliable.bufferedAmountLowThreshold = LOSSY_GATE_BYTES
            channel.bufferedAmountLowThreshold = 0
            while reliable.bufferedAmount + channel.bufferedAmount > LOSSY_GATE_BYTES:
                if self._lossy is not channel or self._ended:
                    return False
                self._room = anyio.Event()
                with anyio.move_on_after(RECHECK_S):
                    await self._room.wait()
        finally:
            reliable.bufferedAmountLowThreshold = SEND_LOW_WATER_BYTES
            channel.bufferedAmountLowThreshold = _UNWATCHED
        return self._lossy is channel


_UNWATCHED = (1 << 32) - 1
"""The lossy channel's ``bufferedAmountLowThreshold`` while no writer waits for it: the
largest the API takes (an unsigned long, WebRTC's ``RTCDataChannel``), never reached."""


def _bound(channel: AnyDataChannel) -> int:
    """At least the bytes ``channel`` buffers, without waiting for another thread.

    ``bufferedBound`` where a read of ``bufferedAmount`` waits for one (the reactor
    stack, webrtc_native.py), else ``bufferedAmount`` (aiortc's counter; libdatachannel's
    atomic read).
    """
    bound: int | None = getattr(channel, "bufferedBound", None)
    return channel.bufferedAmount if bound is None else bound


def _over(channel: AnyDataChannel, limit: int) -> bool:
    """Whether ``channel`` buffers more than ``limit`` bytes, read only if its bound is over."""
    return _bound(channel) > limit and channel.bufferedAmount > limit
