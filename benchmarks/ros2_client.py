"""B21's lean WebSocket subscriber: times and checks each delivery without parsing it.

Ten subscribers of a 640x480 ``rgb8`` image at 30 Hz read 36 MB/s of JSON; with a
WebSocket library in Python (``websockets``: frames reassembled and copied, every
message handed through a task) the benchmark's own process was the tail of B21's
1 -> 10 latency, not the bridge (benchmarks/README.md, B21). A browser's WebSocket
and ``JSON.parse`` are native code, so the client must be cheap to measure the
server. ``LeanCounter`` reads its socket with an ``asyncio.BufferedProtocol`` into
one reused buffer and walks the WebSocket frames as the bytes arrive
(``FrameWalk``):

- a small frame (at most ``SMALL`` bytes: a probe, a ``String``) is collected
  whole; its stamp is read as in ``stamp``;
- a large frame (an image) is never assembled: its first ``HEAD`` bytes are kept
  for the stamp, and its last bytes are compared in place (``startswith`` on the
  receive buffer, a memcmp) with what the frame must end with: ``"``, the base64
  of the image the publisher sends (all zero bytes), ``"`` and the rest of the JSON
  as the bridge wrote it after the data field in the probe frame (learnt from the
  first probe, so it holds for any key order or spacing). The frame's length is
  checked with it: the data must start within ``SLACK`` bytes of the frame's start.

The receive time of a frame is ``time.time()`` when its last byte has been read
(the same moment ``websockets``' ``recv`` would return it, minus that library's
work). Frames of the wrong kind, size or content raise ``ClientError``.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import re
import struct
import time
from urllib.parse import urlsplit

from .loadgen.wire import OP_TEXT, client_frame

__all__ = ["HEAD", "SLACK", "SMALL", "TYPES", "ClientError", "FrameWalk", "LeanCounter", "stamp"]

SMALL = 64 * 1024
"""Frames up to this many bytes are collected whole; larger ones are checked in place."""
HEAD = 1024
"""Bytes kept from the start of a large frame: the stamp is in them."""
SLACK = 4096
"""A large frame's data field starts within this many bytes of the frame's start."""
RECV_BUFFER = 1 << 20
"""The reused receive buffer (bytes); one socket read fills at most this much."""
TYPES = {"string": "std_msgs/msg/String", "image": "sensor_msgs/msg/Image"}
"""The ROS 2 type of each kind of message B21 publishes."""
IMAGE_BYTES = 640 * 480 * 3
"""The image the publisher sends by default: 640x480 ``rgb8``, all zero bytes."""

_STRING_STAMP = re.compile(rb'"data"\s*:\s*"([0-9]+\.[0-9]+)')
_IMAGE_STAMP = re.compile(rb'"sec"\s*:\s*([0-9]+)\s*,\s*"nanosec"\s*:\s*([0-9]+)')
_EMPTY_DATA = re.compile(rb'"data"\s*:\s*""')
_PING = 0x9
_CONTROL = (0x8, _PING, 0xA)  # close, ping, pong (RFC 6455 5.5)


class ClientError(RuntimeError):
    """A delivery that is not the message the publisher sent (or not a frame)."""


def stamp(kind: str, frame: bytes) -> float | None:
    """The publish time (s) in the start of a delivered frame, None for a probe.

    ``frame`` may be only the frame's first ``HEAD`` bytes (an image's stamp is in
    its header, which comes first in every bridge's JSON).
    """
    if kind == "string":
        found = _STRING_STAMP.search(frame, 0, 400)
        return float(found.group(1)) if found else None
    found = _IMAGE_STAMP.search(frame, 0, 600) or _IMAGE_STAMP.search(frame)
    if found is None or b'"probe"' in frame[:600]:
        return None
    return int(found.group(1)) + int(found.group(2)) / 1e9


class FrameWalk:
    """Walks a server's WebSocket frames (RFC 6455 5.2, unmasked, unfragmented).

    Socket-free: ``feed`` takes the received bytes in any chunking. Each timed
    delivery appends its latency (receive time minus stamp, s) to ``latencies``.

    Args:
        kind: ``string`` or ``image`` (what the publisher sends).
        image_bytes: the size of the image's data (all zero bytes).
    """

    def __init__(self, kind: str, image_bytes: int = IMAGE_BYTES) -> None:
        self.kind = kind
        self.latencies: list[float] = []
        self.stamps: list[float] = []
        """The publish time (s) of each timed delivery, in the order of ``latencies``."""
        self.probes = 0
        self.last = 0.0
        self.pongs: list[bytes] = []
        """Payloads of the pings received, for the reader to answer."""
        self._opcode = OP_TEXT
        self._expected = b'"' + base64.b64encode(bytes(image_bytes)) + b'"'
        self._tail: memoryview | None = None  # what a large frame ends with
        self._header = bytearray()
        self._length = -1  # payload length of the frame being read; -1 between frames
        self._offset = 0
        self._tail_at = 0
        self._kept = bytearray()  # a small frame whole, or a large one's head

    def feed(self, data: bytes | bytearray, end: int, now: float) -> None:
        """Walk ``data[:end]``, received at ``now`` (``time.time()``).

        Raises:
            ClientError: a frame of the wrong kind, size or content.
        """
        pos = 0
        while pos < end:
            if self._length < 0:
                pos = self._read_header(data, pos, end)
                if self._length == 0:
                    self._finish(now)
                continue
            take = min(end - pos, self._length - self._offset)
            self._take(data, pos, take)
            pos += take
            self._offset += take
            if self._offset == self._length:
                self._finish(now)

    def _read_header(self, data: bytes | bytearray, pos: int, end: int) -> int:
        header = self._header
        while pos < end and len(header) < _header_size(header):
            header.append(data[pos])
            pos += 1
        if len(header) < _header_size(header):
            return pos
        self._opcode = header[0] & 0x0F
        if not header[0] & 0x80 or self._opcode not in (OP_TEXT, *_CONTROL):
            raise ClientError(f"not a whole text frame: first byte {header[0]:#x}")
        code = header[1] & 0x7F
        length = (
            struct.unpack_from("!H", header, 2)[0]
            if code == 126
            else struct.unpack_from("!Q", header, 2)[0]
            if code == 127
            else code
        )
        header.clear()
        self._length, self._offset = length, 0
        self._kept.clear()
        if length > SMALL:
            if self._opcode != OP_TEXT:
                raise ClientError(f"a {length} B control frame")
            if self._tail is None:
                raise ClientError("a large frame before any probe")
            self._tail_at = length - len(self._tail)
            if not 0 < self._tail_at <= SLACK:
                raise ClientError(f"a {length} B frame is not one image")
        return pos

    def _take(self, data: bytes | bytearray, pos: int, take: int) -> None:
        """Keep or check payload bytes ``[offset, offset + take)``, found at ``data[pos:]``."""
        offset = self._offset
        if self._length <= SMALL:
            self._kept += data[pos : pos + take]
            return
        if offset < HEAD:
            self._kept += data[pos : pos + min(take, HEAD - offset)]
        start = max(offset, self._tail_at)
        stop = offset + take
        if start < stop:
            assert self._tail is not None
            at = pos + start - offset
            piece = self._tail[start - self._tail_at : stop - self._tail_at]
            if not data.startswith(piece, at, at + len(piece)):
                raise ClientError(f"wrong image data in delivery {len(self.latencies)}")

    def _finish(self, now: float) -> None:
        head = bytes(self._kept)
        self._length = -1
        if self._opcode != OP_TEXT:
            if self._opcode == _PING:
                self.pongs.append(head)
            return
        sent = stamp(self.kind, head)
        if sent is None:
            self.probes += 1
            if self.kind == "image" and self._tail is None:
                self._learn(head)
            return
        if self.kind == "image" and len(head) < HEAD:  # a small frame that is no image
            raise ClientError(f"a {len(head)} B frame in an image stream")
        self.latencies.append(now - sent)
        self.stamps.append(sent)
        self.last = now

    def _learn(self, probe: bytes) -> None:
        """Take what follows the data field from a probe (its data is empty)."""
        found = list(_EMPTY_DATA.finditer(probe))  # the image's data: the last one
        if not found:
            raise ClientError(f"no data field in the probe {probe[:200]!r}")
        self._tail = memoryview(self._expected + probe[found[-1].end() :])


def _header_size(header: bytearray) -> int:
    """Bytes in a server frame header, as far as ``header`` tells (RFC 6455 5.2)."""
    if len(header) < 2:
        return 2
    code = header[1] & 0x7F
    return 4 if code == 126 else 10 if code == 127 else 2


class _Reader(asyncio.BufferedProtocol):
    """Handshake, subscribe, then every received byte into one ``FrameWalk``."""

    def __init__(
        self, walk: FrameWalk, request: bytes, subscribe: bytes, probed: asyncio.Event
    ) -> None:
        self.walk = walk
        self.request = request
        self.subscribe = subscribe
        self.probed = probed
        self.buffer = bytearray(RECV_BUFFER)
        self.response: bytes | None = b""  # None once the handshake is through
        self.transport: asyncio.Transport | None = None
        self.done: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        transport.write(self.request)

    def get_buffer(self, sizehint: int) -> memoryview:
        return memoryview(self.buffer)

    def buffer_updated(self, nbytes: int) -> None:
        now = time.time()
        assert self.transport is not None
        try:
            if self.response is None:
                self.walk.feed(self.buffer, nbytes, now)
            else:
                self.response += bytes(self.buffer[:nbytes])
                head, found, rest = self.response.partition(b"\r\n\r\n")
                if not found:
                    return
                if not head.startswith(b"HTTP/1.1 101"):
                    raise ClientError(f"handshake refused: {head[:80]!r}")
                self.response = None
                self.transport.write(self.subscribe)
                self.walk.feed(rest, len(rest), now)
        except ClientError as error:
            self._fail(error)
            return
        for ping in self.walk.pongs:  # masked with the zero key, as client_frame does
            self.transport.write(bytes((0x8A, 0x80 | len(ping))) + bytes(4) + ping)
        self.walk.pongs.clear()
        if self.walk.probes:
            self.probed.set()

    def _fail(self, error: BaseException) -> None:
        if not self.done.done():
            self.done.set_exception(error)
        if self.transport is not None:
            self.transport.abort()

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.done.done():
            self.done.set_exception(exc or ConnectionError("the bridge closed the connection"))


class LeanCounter:
    """One WebSocket subscriber read by ``FrameWalk`` (same face as the ``websockets`` one);
    ``image_bytes``: the size of the images' data."""

    def __init__(self, image_bytes: int = IMAGE_BYTES) -> None:
        self.image_bytes = image_bytes
        self.probed = asyncio.Event()
        self.walk: FrameWalk | None = None

    @property
    def latencies(self) -> list[float]:
        """Latency of each timed delivery so far (s)."""
        return self.walk.latencies if self.walk else []

    @property
    def last(self) -> float:
        """``time.time()`` of the last timed delivery (0 before one)."""
        return self.walk.last if self.walk else 0.0

    async def run(self, url: str, topic: str, kind: str) -> None:
        """Subscribe to ``topic`` (of ``TYPES[kind]``) and read until cancelled.

        Raises:
            ClientError: a delivery was wrong (``FrameWalk``) or the handshake refused.
            ConnectionError: the bridge closed the connection.
        """
        parts = urlsplit(url)
        host, port = parts.hostname or "127.0.0.1", parts.port or 80
        key = base64.b64encode(os.urandom(16)).decode()
        request = (
            f"GET {parts.path or '/'} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
        self.walk = FrameWalk(kind, self.image_bytes)
        op = {"op": "subscribe", "topic": topic, "type": TYPES[kind]}
        reader = _Reader(self.walk, request, client_frame(json.dumps(op).encode()), self.probed)
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_connection(lambda: reader, host, port)
        try:
            await reader.done
        finally:
            transport.abort()
