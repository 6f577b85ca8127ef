"""The ``rosbridge`` WebRTC data channel as a pump ``Channel`` (docs/webrtc.md).

A reliable, ordered data channel labelled ``rosbridge`` carries a rosbridge
session exactly as a WebSocket connection does: one message per frame, JSON as
text, CBOR as binary (D27). The session, its limits and its flow control are
the server's (pump.py); this module only moves frames:

- in: aiortc hands over whole messages from a callback, with no way to make the
  peer wait, so the messages the pump has not read yet are bounded by
  ``INBOX_LIMIT_BYTES``; past it the peer is disconnected. A message above
  ``--max-message-size`` is skipped with an error status, as UDP does.
- out: a JSON frame above ``MAX_TEXT_FRAME_BYTES`` (64 KiB, the size every
  peer accepts, RFC 8841 6.1) goes out as ``fragment`` ops (spec 3.1.1, D19),
  which the client reassembles. A CBOR frame cannot be cut so: it goes whole if
  the peer's ``a=max-message-size`` allows it, else it is dropped and logged.
- the SCTP send buffer is flow-controlled like a socket's: ``send`` waits while
  the channel's ``bufferedAmount`` is above ``SEND_HIGH_WATER_BYTES``, until
  its ``bufferedamountlow`` event, so a slow reader fills the session's outbox
  and the slow-consumer rule (D24) applies as on a WebSocket.
"""

from __future__ import annotations

import itertools
import logging
from collections import deque
from typing import TYPE_CHECKING

import anyio
from aiortc.exceptions import InvalidStateError

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.framing.datagrams import fragment_datagrams
from rwt_protocol.framing.streams import FramerEvent, FramingError, InFrame

from .channel import PlainChannel

if TYPE_CHECKING:
    from collections.abc import Sequence

    from aiortc import RTCDataChannel

    from rwt_protocol.server.commands import CloseCode
    from rwt_protocol.server.contract import ServerSession
    from rwt_protocol.server.outbox import OutFrame

__all__ = [
    "INBOX_LIMIT_BYTES",
    "MAX_TEXT_FRAME_BYTES",
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

_ids = itertools.count(1)


class DataChannelChannel(PlainChannel):
    """One open ``rosbridge`` data channel as a pump ``Channel``.

    Args:
        channel: the open data channel (aiortc).
        max_message_size: the largest incoming message, bytes (``--max-message-size``).
        remote_max_message_size: the largest message the peer accepts, bytes (its
            SDP's ``a=max-message-size``; 0: any size).
    """

    transport = "webrtc"
    awaits_peer_close = False

    def __init__(
        self, channel: RTCDataChannel, max_message_size: int, remote_max_message_size: int
    ) -> None:
        self._dc = channel
        self.max_message_size = max_message_size
        self.remote_max_message_size = remote_max_message_size
        self._inbox: deque[FramerEvent] = deque()
        self._inbox_bytes = 0
        self._arrived = anyio.Event()
        self._drained = anyio.Event()
        self._ended = False
        self.overflowed = False
        """The peer sent more than ``INBOX_LIMIT_BYTES`` ahead of the session: it was cut."""
        channel.bufferedAmountLowThreshold = SEND_LOW_WATER_BYTES
        channel.on("message", self._on_message)
        channel.on("close", self._on_close)
        channel.on("bufferedamountlow", self._on_low)
        if channel.readyState in ("closing", "closed"):
            self._on_close()

    def _on_message(self, message: str | bytes) -> None:
        """Queue one incoming message for ``receive`` (aiortc's callback)."""
        if self._ended:
            return
        binary = isinstance(message, bytes)
        data = message if isinstance(message, bytes) else message.encode("utf-8", "replace")
        if len(data) > self.max_message_size:
            self._inbox.append(
                FramingError(f"message larger than {self.max_message_size} bytes skipped")
            )
        else:
            self._inbox.append(InFrame(data, binary))
            self._inbox_bytes += len(data)
        if self._inbox_bytes > INBOX_LIMIT_BYTES:
            _episodes.log(
                logging.WARNING,
                "webrtc_inbox",
                "event=webrtc_overflow bytes=%d limit=%d: peer disconnected",
                self._inbox_bytes,
                INBOX_LIMIT_BYTES,
            )
            self.overflowed = True
            self._inbox.clear()
            self._inbox_bytes = 0
            self._on_close()
            self._dc.close()
        self._arrived.set()

    def _on_low(self) -> None:
        self._drained.set()

    def _on_close(self) -> None:
        self._ended = True
        self._arrived.set()
        self._drained.set()

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
        self._inbox_bytes = 0
        return events

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Send the frames in order, waiting while the channel's buffer is full.

        Raises:
            anyio.BrokenResourceError: the data channel closed.
        """
        for frame in frames:
            data = frame.prefix + frame.data if frame.prefix else frame.data
            if frame.binary:
                limit = self.remote_max_message_size
                if limit and len(data) > limit:
                    _episodes.log(
                        logging.WARNING,
                        "webrtc_drop",
                        "event=webrtc_drop bytes=%d limit=%d: CBOR frame above the peer's "
                        "max-message-size dropped",
                        len(data),
                        limit,
                    )
                    continue
                self._send(data)
            else:
                parts = fragment_datagrams(data, MAX_TEXT_FRAME_BYTES, f"webrtc:{next(_ids)}")
                for part in parts:
                    self._send(part.decode("utf-8"))
                    await self._drain()
            await self._drain()

    def _send(self, data: str | bytes) -> None:
        if self._ended:
            raise anyio.BrokenResourceError
        try:
            self._dc.send(data)
        except (InvalidStateError, ConnectionError) as exc:
            raise anyio.BrokenResourceError from exc

    async def _drain(self) -> None:
        """Wait while the channel buffers more than ``SEND_HIGH_WATER_BYTES`` for the peer."""
        while self._dc.bufferedAmount > SEND_HIGH_WATER_BYTES:
            if self._ended:
                raise anyio.BrokenResourceError
            self._drained = anyio.Event()
            await self._drained.wait()

    async def close(self, code: CloseCode, reason: str) -> None:
        """Close the data channel (it has no close code; the reason is in the server log)."""
        self._on_close()
        self._dc.close()

    async def background(self, session: ServerSession) -> None:
        """Nothing to do: SCTP has its own heartbeat."""
