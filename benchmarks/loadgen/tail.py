"""A subscriber that checks frames by their tail without assembling them.

A cbor-raw delivery of a 4 MiB image is a frame whose payload ends with the
image's data. Cutting such frames out of the stream (``FrameReader``) costs the
generator four copies of every byte; with ten subscribers it became the
bottleneck of B4 (the load generator must not be). ``TailSubscriber``
walks the stream as it arrives instead: it parses each frame header, keeps the
first bytes of the payload for a topic check, and compares the tail with the
expected data in place (``bytes.startswith`` on a memoryview: a memcmp, no copy).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence

from .engine import GeneratorError, Subscriber
from .wire import OP_BINARY

__all__ = ["TailStream", "TailSubscriber"]

_HEAD_BYTES = 64


def _header_size(header: bytearray) -> int:
    """Bytes in a server frame header, as far as ``header`` tells (RFC 6455 5.2)."""
    if len(header) < 2:
        return 2
    code = header[1] & 0x7F
    return 4 if code == 126 else 10 if code == 127 else 2


class TailStream:
    """Checks that frame ``i`` is binary, names the topic and ends with ``expected(i)``.

    Socket-free: ``feed`` takes the received bytes in any chunking.

    Args:
        expected: the data frame ``i`` must end with (bytes-like).
        mark: bytes that must occur in the first 64 bytes of each payload
            (the CBOR-encoded topic name).
        slack: how many bytes a payload may carry before the data (the
            envelope and the serialized header fields).
    """

    def __init__(self, expected: Callable[[int], bytes], mark: bytes, *, slack: int = 4096) -> None:
        self.expected = expected
        self.mark = mark
        self.slack = slack
        self.received = 0
        self._header = bytearray()
        self._length = -1  # payload length of the frame being read; -1 between frames
        self._offset = 0
        self._tail_at = 0
        self._want = memoryview(b"")
        self._head = bytearray()

    def feed(self, data: bytes) -> int:
        """Check received bytes; return the number of frames completed so far.

        Raises:
            GeneratorError: a frame of the wrong kind, size, topic or content.
        """
        pos = 0
        end = len(data)
        while pos < end:
            if self._length < 0:
                pos = self._read_header(data, pos)
                continue
            take = min(end - pos, self._length - self._offset)
            self._check_span(data, pos, take)
            pos += take
            self._offset += take
            if self._offset == self._length:
                self._finish()
        return self.received

    def _read_header(self, data: bytes, pos: int) -> int:
        """Consume header bytes from ``data[pos:]``; start the payload once complete."""
        header = self._header
        while pos < len(data) and len(header) < _header_size(header):
            header.append(data[pos])
            pos += 1
        if len(header) < _header_size(header):
            return pos
        code = header[1] & 0x7F
        if code == 126:
            (length,) = struct.unpack_from("!H", header, 2)
        elif code == 127:
            (length,) = struct.unpack_from("!Q", header, 2)
        else:
            length = code
        index = self.received
        want = memoryview(self.expected(index))
        if header[0] & 0x0F != OP_BINARY or not len(want) <= length <= len(want) + self.slack:
            raise GeneratorError(f"frame {index} is not a message of this stream")
        header.clear()
        self._length = length
        self._offset = 0
        self._tail_at = length - len(want)
        self._want = want
        self._head.clear()
        if length == 0:
            self._finish()
        return pos

    def _check_span(self, data: bytes, pos: int, take: int) -> None:
        """Check payload bytes ``[offset, offset + take)``, found at ``data[pos:]``."""
        offset = self._offset
        if offset < _HEAD_BYTES:
            self._head += data[pos : pos + min(take, _HEAD_BYTES - offset)]
        start = max(offset, self._tail_at)
        stop = offset + take
        if start < stop:
            at = pos + start - offset
            piece = self._want[start - self._tail_at : stop - self._tail_at]
            if not data.startswith(piece, at, at + len(piece)):
                raise GeneratorError(f"wrong data in message {self.received}")

    def _finish(self) -> None:
        if self.mark not in self._head:
            raise GeneratorError(f"message {self.received} does not name the topic")
        self.received += 1
        self._length = -1


class TailSubscriber(Subscriber):
    """A subscriber whose stream is checked by a ``TailStream``.

    Args:
        port: the server's port.
        kind: the server kind (``rwt``).
        setup: payloads of the setup ops.
        check: the stream check (its ``expected``, ``mark`` and ``slack``).
    """

    def __init__(self, port: int, kind: str, setup: Sequence[bytes], check: TailStream) -> None:
        super().__init__(port, kind, setup)
        self.check = check

    def feed(self, data: bytes, now: float) -> None:
        if self.first_s is None:
            self.first_s = now
        self.last_s = now
        self.received = self.check.feed(data)
