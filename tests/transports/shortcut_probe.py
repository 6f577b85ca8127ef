"""Run a server through every performance shortcut and report which ones ran.

``python -m tests.transports.shortcut_probe`` (repository root, ``src`` and
``.`` on PYTHONPATH) starts an in-process server with the environment it was
given (``RWT_NO_SHORTCUTS``), counts the calls into each shortcut's own code,
and has WebSocket and TCP subscribers receive small and large messages as
JSON, CBOR and cbor-raw, published over WebSocket as JSON and CBOR. It prints JSON: the
call counts by shortcut name and the exact bytes (hex) of every publish frame
each subscriber received. test_shortcuts_switch.py compares the runs.
"""

from __future__ import annotations

import base64
import functools
import json
import os
import struct
import sys
from collections import Counter
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import anyio
import cbor2
import pybase64
from anyio.abc import ByteStream

from rwt_graph.graph import Graph
from rwt_graph.types import message as message_module
from rwt_protocol.codecs import cbor as codec_cbor
from rwt_protocol.codecs import json as codec
from rwt_protocol.server import session as session_module
from rwt_protocol.server import subscriptions
from rwt_transports import direct, pump, websocket, wsread
from rwt_transports.server import ServerConfig
from tests.conftest import FakeClock
from tests.support.clients import running_server

IMAGE_BYTES = 100_000  # over the 64 KiB from which payloads are spliced


def _count(counts: Counter[str], name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    @functools.wraps(fn)
    def counted(*args: Any, **kwargs: Any) -> Any:
        counts[name] += 1
        return fn(*args, **kwargs)

    return counted


def install_counters() -> Counter[str]:
    """Count the calls into each shortcut's own code, by shortcut name."""
    counts: Counter[str] = Counter()
    message_module.compile_fast = _count(  # type: ignore[assignment]
        counts, "generated-converters", message_module.compile_fast
    )
    message_module.compile_to_rosbags = _count(  # type: ignore[assignment]
        counts, "rosbags-converters", message_module.compile_to_rosbags
    )
    codec._publish_object = _count(counts, "publish-encode", codec._publish_object)  # type: ignore[assignment]
    codec.pybase64 = SimpleNamespace(  # type: ignore[assignment]
        b64encode=_count(counts, "json-base64-splice", pybase64.b64encode)
    )
    codec_cbor._map_parts = _count(counts, "cbor-splice-encode", codec_cbor._map_parts)  # type: ignore[assignment]
    codec_cbor._Splicer = _count(counts, "cbor-splice-decode", codec_cbor._Splicer)  # type: ignore[assignment, misc]
    wsread.FrameReader.feed = _count(counts, "ws-frame-reader", wsread.FrameReader.feed)  # type: ignore[method-assign]
    websocket._framed = _count(counts, "ws-frame-writer", websocket._framed)  # type: ignore[assignment]
    direct.DirectWriter.write = _count(counts, "direct-write", direct.DirectWriter.write)  # type: ignore[method-assign]
    pump.ConnectionPump._defer = _count(counts, "deferred-send", pump.ConnectionPump._defer)  # type: ignore[method-assign]
    session_module.decode_publish = _count(counts, "publish-decode", session_module.decode_publish)  # type: ignore[assignment]
    batch_sink = subscriptions.BatchTopicSubscription
    batch_sink.on_messages = _count(counts, "rosbridge-batch-sink", batch_sink.on_messages)  # type: ignore[method-assign]

    receive = direct.DirectReader.receive

    async def counted_receive(self: direct.DirectReader, max_bytes: int) -> bytes:
        counts["direct-read"] += 1
        return await receive(self, max_bytes)

    direct.DirectReader.receive = counted_receive  # type: ignore[method-assign]

    clock = pump._clock

    def counted_clock() -> Callable[[], float]:
        chosen = clock()
        if chosen is not anyio.current_time:
            counts["loop-clock"] += 1
        return chosen

    pump._clock = counted_clock
    return counts


def _ws_frame(payload: bytes, binary: bool) -> bytes:
    """A client frame masked with the zero key (RFC 6455 allows it; the payload stays as is)."""
    first = 0x82 if binary else 0x81
    n = len(payload)
    if n < 126:
        head = bytes((first, 0x80 | n))
    elif n < 65536:
        head = struct.pack("!BBH", first, 0x80 | 126, n)
    else:
        head = struct.pack("!BBQ", first, 0x80 | 127, n)
    return head + b"\0\0\0\0" + payload


class RawWs:
    """A WebSocket client on a raw stream that keeps each server frame's exact bytes."""

    def __init__(self, stream: ByteStream, rest: bytes) -> None:
        self.stream = stream
        self.buffer = bytearray(rest)

    @classmethod
    async def open(cls, port: int) -> RawWs:
        stream = await anyio.connect_tcp("127.0.0.1", port)
        key = base64.b64encode(os.urandom(16)).decode()
        await stream.send(
            f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n".encode()
        )
        data = b""
        while b"\r\n\r\n" not in data:
            data += await stream.receive()
        head, _, rest = data.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 101"), head
        return cls(stream, rest)

    async def send(self, op: dict[str, Any], *, binary: bool = False) -> None:
        payload = cbor2.dumps(op) if binary else json.dumps(op).encode()
        await self.stream.send(_ws_frame(payload, binary))

    async def frame(self) -> tuple[bytes, bytes]:
        """The next server frame: its whole bytes and its payload."""
        while True:
            buf = self.buffer
            if len(buf) >= 2:
                length, start = buf[1] & 0x7F, 2
                if length == 126 and len(buf) >= 4:
                    length, start = struct.unpack_from("!H", buf, 2)[0], 4
                elif length == 127 and len(buf) >= 10:
                    length, start = struct.unpack_from("!Q", buf, 2)[0], 10
                if length < 126 or start > 2:
                    end = start + length
                    if len(buf) >= end:
                        whole = bytes(buf[:end])
                        del buf[:end]
                        return whole, whole[start:]
            self.buffer += await self.stream.receive()


class RawTcp:
    """A TCP client that keeps each JSON line's exact bytes."""

    def __init__(self, stream: ByteStream) -> None:
        self.stream = stream
        self.buffer = b""

    async def send(self, op: dict[str, Any]) -> None:
        await self.stream.send(json.dumps(op).encode() + b"\n")

    async def frame(self) -> tuple[bytes, bytes]:
        while b"\n" not in self.buffer:
            self.buffer += await self.stream.receive()
        line, _, self.buffer = self.buffer.partition(b"\n")
        return line + b"\n", line


def _is_publish(payload: bytes) -> bool:
    if payload[:1] == b"{":
        return bool(json.loads(payload).get("op") == "publish")
    return bool(cbor2.loads(payload).get("op") == "publish")


async def _publish_frames(client: RawWs | RawTcp, count: int) -> list[str]:
    frames = []
    while len(frames) < count:
        whole, payload = await client.frame()
        if _is_publish(payload):
            frames.append(whole.hex())
    return frames


async def _synced(client: RawWs | RawTcp, ops: list[dict[str, Any]]) -> None:
    """Send ``ops``, then wait until the server has handled them (ops run in order)."""
    for op in ops:
        await client.send(op)
    await client.send({"op": "call_service", "service": "/rosapi/topics", "id": "sync"})
    while True:
        _, payload = await client.frame()
        if b'"service_response"' in payload:
            return


def _image(data: bytes | str, height: int) -> dict[str, object]:
    return {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "cam"},
        "height": height,
        "width": IMAGE_BYTES // height,
        "encoding": "mono8",
        "is_bigendian": 0,
        "step": IMAGE_BYTES // height,
        "data": data,
    }


async def run() -> dict[str, object]:
    counts = install_counters()
    pixels = bytes(i % 251 for i in range(IMAGE_BYTES))
    # a fixed clock: cbor-raw frames carry the time of publication
    async with running_server(ServerConfig(), graph=Graph(clock=FakeClock())) as harness:
        publisher = await RawWs.open(harness.port("websocket"))
        ws_sub = await RawWs.open(harness.port("websocket"))
        raw_sub = await RawWs.open(harness.port("websocket"))
        tcp_sub = RawTcp(await anyio.connect_tcp("127.0.0.1", harness.port("tcp")))
        with anyio.fail_after(30):
            await _synced(
                publisher,
                [
                    {"op": "advertise", "topic": "/s", "type": "std_msgs/msg/String"},
                    {"op": "advertise", "topic": "/img", "type": "sensor_msgs/msg/Image"},
                ],
            )
            await _synced(
                ws_sub,
                [
                    {"op": "subscribe", "topic": "/s", "type": "std_msgs/msg/String"},
                    {"op": "subscribe", "topic": "/img", "compression": "cbor"},
                ],
            )
            raw = {"op": "subscribe", "topic": "/img", "compression": "cbor-raw"}
            await _synced(raw_sub, [raw])
            await _synced(
                tcp_sub,
                [
                    {"op": "subscribe", "topic": "/s", "type": "std_msgs/msg/String"},
                    {"op": "subscribe", "topic": "/img"},
                ],
            )
            await publisher.send({"op": "publish", "topic": "/s", "msg": {"data": "hello"}})
            json_image = _image(pybase64.b64encode(pixels).decode(), 1)
            await publisher.send({"op": "publish", "topic": "/img", "msg": json_image})
            cbor_image = {"op": "publish", "topic": "/img", "msg": _image(pixels[::-1], 2)}
            await publisher.send(cbor_image, binary=True)
            received = {
                "ws": await _publish_frames(ws_sub, 3),
                "tcp": await _publish_frames(tcp_sub, 3),
                "cbor-raw": await _publish_frames(raw_sub, 2),
            }
        for client in (publisher, ws_sub, raw_sub, tcp_sub):
            await anyio.aclose_forcefully(client.stream)
    return {"calls": dict(counts), **received}


if __name__ == "__main__":
    json.dump(anyio.run(run), sys.stdout)
