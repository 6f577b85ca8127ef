"""TCP transport (D22), plain or TLS.

In: concatenated JSON values (any whitespace between them, or none) and CBOR
items, split by ``rwt_protocol.framing.streams.JsonStreamFramer`` (linear, bounded by
``--max-message-size``). Out: one JSON object per line; CBOR items as they are
(self-delimiting, and their first byte is never ``{``), so rosbridge_tcp
readers that split on newlines or scan braces both work.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import anyio

from rwt_protocol.codecs.json import encode_op
from rwt_protocol.framing.streams import JsonStreamFramer
from rwt_protocol.ops import Status

from .admission import arrival as admission
from .channel import ChannelAbilities
from .direct import DirectReader, DirectWriter
from .pump import ConnectionPump, run_connection
from .sendqueue import stream_unsent_bytes
from .writes import coalesce

if TYPE_CHECKING:
    from collections.abc import Sequence

    from anyio.abc import ByteStream

    from rwt_protocol.framing.fragments import FragmentBudget
    from rwt_protocol.runtime.commands import CloseCode
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.inframes import FramerEvent
    from rwt_protocol.runtime.outbox import OutFrame

    from .host import SessionHost

__all__ = ["StreamChannel", "encode_stream_frames", "serve_tcp_connection"]

logger = logging.getLogger("rwt.tcp")

_READ_SIZE = 65536
_CLOSE_LIMIT_S = 1.0
_TOO_MANY = encode_op(Status(level="error", msg="too many connections")) + b"\n"


def encode_stream_frames(frames: Sequence[OutFrame]) -> bytes:
    """Join outgoing frames for a byte stream: JSON text plus a newline, CBOR as is."""
    return b"".join(frame.data if frame.binary else frame.data + b"\n" for frame in frames)


def stream_writes(frames: Sequence[OutFrame]) -> list[bytes]:
    """The writes that send ``frames`` on a byte stream, in order (``encode_stream_frames``).

    JSON text gets its newline, CBOR goes as is; small frames are joined and a
    large frame's shared payload is written without a copy (``writes.coalesce``).
    """
    return coalesce((b"", f.data, b"" if f.binary else b"\n") for f in frames)


class StreamChannel:
    """A byte stream carrying rosbridge frames (TCP or TLS) as a pump ``Channel``.

    Args:
        stream: the connected stream.
        max_message_size: the largest incoming frame, in bytes.
        transport: ``tcp`` or ``tls``.
        budget: the server-wide budget a frame still arriving is charged to
            (``--max-fragment-memory``); call ``release`` when the connection ends.
    """

    awaits_peer_close = False
    abilities = ChannelAbilities(
        pause_reading=True, probe_input=True, unsent_bytes=True, send_now=True
    )
    """A socket: paused while its reader is held, probed, its send queue read, written at once."""

    def __init__(
        self,
        stream: ByteStream,
        max_message_size: int,
        transport: str = "tcp",
        budget: FragmentBudget | None = None,
    ):
        self.stream = stream
        self.transport = transport
        self._framer = JsonStreamFramer(max_message_size, budget)
        self._ended = False
        self._direct = DirectWriter.for_stream(stream)
        self._reader = DirectReader.for_stream(stream)
        self._probe = admission.stream_probe(stream, self._reader)
        self.sees_input = admission.stream_sees_all(stream, self._reader)
        """Whether ``input_pending`` sees every byte waiting (never None)."""

    async def receive(self) -> Sequence[FramerEvent]:
        """Read the next chunk and return the frames it completes."""
        if self._ended:
            raise anyio.EndOfStream
        try:
            if self._reader is not None:
                data = await self._reader.receive(_READ_SIZE)
            else:
                data = await self.stream.receive(_READ_SIZE)
        except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
            self._ended = True
            events = self._framer.receive_eof()
            if events:
                return events
            raise anyio.EndOfStream from None
        return self._framer.receive_data(data)

    def release(self) -> None:
        """Free the frame still arriving and give its bytes back to the budget."""
        self._framer.release()

    def input_pending(self) -> bool | None:
        """Whether input is here already (a new connection's first read, admission/arrival.py).

        None when none is seen but anyio may hold some (``admission.arrival.stream_probe``).
        """
        return self._probe()

    def pause_reading(self) -> None:
        """Stop reading the socket until ``receive`` must wait (input backpressure, pump.py).

        Only the direct reader needs it: anyio's own ``receive`` pauses after each chunk.
        """
        if self._reader is not None:
            self._reader.pause()

    def unsent_bytes(self) -> int | None:
        """Bytes the socket's kernel still holds for the peer (sendqueue.py)."""
        return stream_unsent_bytes(self.stream)

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Write the frames: small ones joined, a large one as it is (``stream_writes``)."""
        for data in stream_writes(frames):
            await self.stream.send(data)

    def can_send_now(self) -> bool:
        """Whether ``send_now`` may write at once: a plain socket, nothing buffered."""
        return self._direct is not None and self._direct.ready

    def send_now(self, frames: Sequence[OutFrame]) -> None:
        """Write the frames without awaiting; call only when ``can_send_now`` is True.

        Raises:
            RuntimeError: not a plain socket, or the transport started closing.
        """
        if self._direct is None:
            raise RuntimeError("not a plain socket: send through the writer")
        for data in stream_writes(frames):
            self._direct.write(data)

    async def close(self, code: CloseCode, reason: str) -> None:
        """Close the stream (TCP has no close frame; the reason is in the server log)."""
        with anyio.move_on_after(_CLOSE_LIMIT_S):
            await self.stream.aclose()
        await anyio.aclose_forcefully(self.stream)

    async def background(self, session: ServerSession) -> None:
        """Nothing to do: TCP keepalive is the kernel's."""


async def serve_tcp_connection(
    stream: ByteStream,
    peer: str,
    host: SessionHost,
    max_message_size: int,
    transport: str,
    budget: FragmentBudget | None = None,
) -> None:
    """Run one TCP (or TLS) connection to its end; never raises for what the peer does.

    Args:
        stream: the connected stream.
        peer: the peer's address, for logs and the client id.
        host: makes the session.
        max_message_size: the largest incoming frame, in bytes.
        transport: ``tcp`` or ``tls``, for logs and client ids.
        budget: the server-wide budget of incomplete messages that a frame still
            arriving is charged to (``--max-fragment-memory``).
    """
    async with stream:
        channel = StreamChannel(stream, max_message_size, transport, budget)
        try:
            await _serve_channel(channel, stream, peer, host)
        finally:
            channel.release()


async def _serve_channel(
    channel: StreamChannel, stream: ByteStream, peer: str, host: SessionHost
) -> None:
    """Open the session of ``channel`` and run it, or refuse the connection."""
    pump = ConnectionPump(channel, host.flow, host.admission)
    ticket = admission.current_ticket()
    if ticket is not None and channel.sees_input:  # else it counts as having input
        ticket.watch(channel.input_pending)
    session = host.open_session(channel.transport, peer, pump.wake)
    if session is None:
        if ticket is not None:  # its input is not read: nothing to put first
            ticket.release()
        logger.info("event=refused peer=%s reason='too many connections'", peer)
        with anyio.move_on_after(_CLOSE_LIMIT_S):
            await stream.send(_TOO_MANY)
        return
    await run_connection(pump, session)
