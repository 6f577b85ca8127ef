"""Whole client messages taken off the stream before websockets' parser (benchmarks B4/B6).

websockets' sans-IO parser appends each chunk it is given to one ``bytearray``,
cuts every frame back out of it and then unmasks it: three copies of a large
message, and the ``bytearray`` is copied again each time it grows (``perf``:
a fifth of the server's CPU for 4.8 MB CBOR point clouds). ``FrameReader``
reads the common frame itself: a whole text or binary frame (FIN set), masked,
reserved bits clear, not inside a fragmented message. Such a frame is unmasked
straight from the received chunks: one copy to join a frame that spans chunks,
one to unmask.

Every other frame goes to websockets as its raw bytes, in stream order:

- pings, pongs and the fragments of a fragmented message are passed on and
  reading goes on (websockets answers pings and hands back the fragments);
- anything else (a close frame, an unmasked frame, reserved bits, an unknown
  opcode, a fragment out of order, a frame over the size limit) is passed on
  together with everything after it, for good: websockets then closes the
  connection as RFC 6455 says (1000, 1002 or 1009), and what follows a close
  frame is never read as data.

Use it only on a connection without extensions (permessage-deflate sets the
reserved bit RSV1 and is decoded by websockets) and only from the first byte
after the handshake request.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

from rwt_protocol.runtime.inframes import InFrame

if TYPE_CHECKING:
    from collections.abc import Iterator

try:  # websockets' C unmasking, as websockets itself picks it
    from websockets.speedups import apply_mask
except ImportError:  # pragma: no cover - websockets built without its extension
    from websockets.utils import apply_mask

__all__ = ["FrameReader"]

_CONT, _TEXT, _BINARY, _PING, _PONG = 0x0, 0x1, 0x2, 0x9, 0xA
_MAX_HEADER = 14  # 2 + 8 (64-bit length) + 4 (mask key)
_MAX_CONTROL = 125  # RFC 6455 5.5


class _Header(NamedTuple):
    fin: bool
    opcode: int
    reserved: int
    masked: bool
    size: int  # header bytes, mask key included
    length: int  # payload bytes


def _header(data: bytes | memoryview, at: int) -> _Header | None:
    """The frame header that starts at ``data[at]``, or None when it is not all there."""
    available = len(data) - at
    if available < 2:
        return None
    first, second = data[at], data[at + 1]
    length = second & 0x7F
    size = 2
    if length == 126:
        size = 4
        if available < size:
            return None
        length = int.from_bytes(data[at + 2 : at + 4], "big")
    elif length == 127:
        size = 10
        if available < size:
            return None
        length = int.from_bytes(data[at + 2 : at + 10], "big")
    masked = bool(second & 0x80)
    if masked:
        size += 4
        if available < size:
            return None
    return _Header(bool(first & 0x80), first & 0x0F, first & 0x70, masked, size, length)


class FrameReader:
    """Splits the bytes of a WebSocket connection into whole messages and frames for websockets.

    Args:
        max_size: the largest message accepted, in bytes; a larger frame is
            left to websockets, which closes the connection with 1009.

    ``feed`` yields, in stream order, an ``InFrame`` for each message read
    here and ``bytes`` to give to websockets' ``receive_data``. It parses as it
    is iterated: once websockets has stopped reading frames (it failed the
    connection, or the close handshake began), the caller calls ``stop`` and
    the rest goes to websockets as it is. Memory is bounded by ``max_size``:
    a frame is kept only until it is whole, and a frame announced larger than
    that is never collected.
    """

    def __init__(self, max_size: int) -> None:
        self.max_size = max_size
        self.passthrough = False
        """Whether every byte now goes to websockets."""
        self._fragmented = False  # websockets holds the start of a fragmented message
        self._pieces: list[bytes | memoryview] = []  # a frame begun in earlier chunks
        self._have = 0
        self._pending: _Header | None = None  # its header, once whole

    @property
    def held(self) -> int:
        """Bytes of the frame begun in earlier chunks and kept until it is whole."""
        return self._have

    def stop(self) -> None:
        """Hand every byte to websockets from now on (a frame begun here included)."""
        self.passthrough = True

    def discard(self) -> None:
        """Forget the frame begun here, and hand every later byte to websockets.

        Only once websockets was made to fail the connection: it then drops
        what it is given, so the rest of that frame is never read as a frame.
        """
        self.passthrough = True
        self._pieces, self._have, self._pending = [], 0, None

    def feed(self, data: bytes) -> Iterator[InFrame | bytes]:
        """Read one received chunk; see the class docstring for what comes out."""
        view = memoryview(data)
        pos = 0
        if self._pieces and not self.passthrough:
            pos, item = self._resume(view)
            if item is not None:
                yield item
        end = len(data)
        while pos < end:
            if self.passthrough:
                if self._pieces:  # begun before ``stop``
                    yield b"".join(self._pieces)
                    self._pieces, self._have, self._pending = [], 0, None
                yield data[pos:] if pos else data
                return
            header = _header(data, pos)
            if header is None:
                self._pieces, self._have = [view[pos:]], end - pos
                return
            if not self._accept(header):
                continue  # now passing through, from this frame on
            stop = pos + header.size + header.length
            if stop > end:
                self._pieces, self._have, self._pending = [view[pos:]], end - pos, header
                return
            yield self._emit(view[pos:stop], header)
            pos = stop

    def _resume(self, view: memoryview) -> tuple[int, InFrame | bytes | None]:
        """Go on with the frame begun earlier.

        Returns where the next frame starts in ``view`` and the frame's item
        once it is whole.
        """
        header = self._pending
        if header is None:  # its header was cut: at most 13 bytes so far
            start = b"".join(self._pieces) + bytes(view[:_MAX_HEADER])
            header = _header(start, 0)
            if header is None:  # still short: all of ``view`` is in ``start``
                self._pieces, self._have = [start], len(start)
                return len(view), None
            if not self._accept(header):
                return 0, None  # ``feed`` passes the begun frame and ``view`` on
            self._pending = header
        take = min(header.size + header.length - self._have, len(view))
        self._pieces.append(view[:take])
        self._have += take
        if self._have < header.size + header.length:
            return take, None
        frame = b"".join(self._pieces)
        self._pieces, self._have, self._pending = [], 0, None
        return take, self._emit(memoryview(frame), header)

    def _accept(self, header: _Header) -> bool:
        """Whether reading goes on after this frame; else pass everything on from its start."""
        ok = header.masked and not header.reserved and header.length <= self.max_size
        opcode = header.opcode
        if opcode in (_TEXT, _BINARY):
            ok = ok and not self._fragmented
            self._fragmented = ok and not header.fin
        elif opcode == _CONT:
            ok = ok and self._fragmented
            self._fragmented = ok and not header.fin
        elif opcode in (_PING, _PONG):
            ok = ok and header.fin and header.length <= _MAX_CONTROL
        else:  # a close frame, or an opcode RFC 6455 reserves
            ok = False
        if not ok:
            self.passthrough = True
        return ok

    @staticmethod
    def _emit(frame: memoryview, header: _Header) -> InFrame | bytes:
        """A whole message as an ``InFrame`` (unmasked); any other frame as its bytes."""
        if header.fin and header.opcode in (_TEXT, _BINARY):  # ``_accept`` saw no open fragment
            mask = bytes(frame[header.size - 4 : header.size])
            return InFrame(apply_mask(frame[header.size :], mask), binary=header.opcode == _BINARY)
        return bytes(frame)
