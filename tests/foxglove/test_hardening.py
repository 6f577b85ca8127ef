"""A Foxglove client's bad input and slow reading, over real sockets on a real server.

Each bad frame gets an error ``status`` on its own connection, which goes on;
another Foxglove client and a rosbridge client on the same server keep
receiving. A client that never reads fills only its own bounded queue: a fast
Foxglove client and a rosbridge client beside it get every message, and the
stalled one hears of its drops once (docs/limits.md, "Foxglove clients").
"""

from __future__ import annotations

import base64
import json
import logging
import os
import re
import socket
import struct
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from rwt_foxglove import FoxgloveLimits
from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from rwt_protocol.server.session import SessionConfig
from rwt_transports.foxglove import FoxgloveOptions
from rwt_transports.server import RosbridgeServer, ServerConfig

pytestmark = pytest.mark.anyio

FOXGLOVE = ["foxglove.sdk.v1"]
MAX_MESSAGE_SIZE = 256 * 1024
DROPPED = "messages dropped: this client reads slower than they arrive (the oldest go first)"


@asynccontextmanager
async def serving(
    graph: Graph, limits: FoxgloveLimits | None = None, session: SessionConfig | None = None
) -> AsyncIterator[RosbridgeServer]:
    options = FoxgloveOptions(limits=limits or FoxgloveLimits())
    config = ServerConfig(
        port=0,
        max_message_size=MAX_MESSAGE_SIZE,
        foxglove=options,
        session=session or SessionConfig(),
    )
    server = RosbridgeServer(graph, config)
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        try:
            with anyio.fail_after(60):
                yield server
        finally:
            tg.cancel_scope.cancel()


@dataclass
class Fox:
    """A Foxglove client (``websockets``) that keeps what it received, by kind."""

    ws: ClientConnection
    ops: list[dict[str, object]] = field(default_factory=list)
    data: list[bytes] = field(default_factory=list)

    async def next_op(self, name: str) -> dict[str, object]:
        """Read until a text op ``name`` arrives (data on the way is kept)."""
        while True:
            frame = await self.ws.recv()
            if isinstance(frame, bytes):
                self.data.append(frame)
                continue
            op = json.loads(frame)
            self.ops.append(op)
            if op["op"] == name:
                return op  # type: ignore[no-any-return]

    async def channel(self, topic: str) -> int:
        """The id of the server channel of ``topic`` (from the advertisements)."""
        while True:
            for op in self.ops:
                if op["op"] == "advertise":
                    for channel in op["channels"]:  # type: ignore[attr-defined]
                        if channel["topic"] == topic:
                            return int(channel["id"])
            await self.next_op("advertise")

    async def subscribe(self, sid: int, topic: str) -> None:
        channel = await self.channel(topic)
        subscription = {"id": sid, "channelId": channel}
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))

    async def barrier(self) -> None:
        """Until the server read what was sent before: a refused unsubscribe's status comes."""
        await self.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [99]}))
        while not any(
            op["op"] == "status" and "subscription 99" in str(op["message"]) for op in self.ops
        ):
            await self.next_op("status")

    async def status(self) -> dict[str, object]:
        return await self.next_op("status")

    async def data_frames(self, count: int) -> list[tuple[int, bytes]]:
        """Read until ``count`` message data frames were kept; return them as (sid, payload)."""
        while len(self.data) < count:
            frame = await self.ws.recv()
            if isinstance(frame, bytes):
                self.data.append(frame)
            else:
                self.ops.append(json.loads(frame))
        taken, self.data = self.data[:count], self.data[count:]
        out = []
        for frame in taken:
            assert frame[0] == 1, frame[:13]
            out.append((struct.unpack_from("<I", frame, 1)[0], frame[13:]))
        return out


@asynccontextmanager
async def fox(server: RosbridgeServer) -> AsyncIterator[Fox]:
    async with connect(
        server.urls["websocket"],
        subprotocols=FOXGLOVE,
        max_size=None,  # type: ignore[list-item]
    ) as ws:
        client = Fox(ws)
        assert (await client.next_op("serverInfo"))["op"] == "serverInfo"
        yield client


async def rosbridge_messages(ws: ClientConnection, count: int) -> list[str]:
    """The ``data`` of the next ``count`` rosbridge ``publish`` ops."""
    out = []
    while len(out) < count:
        op = json.loads(await ws.recv())
        assert op["op"] == "publish", op
        out.append(op["msg"]["data"])
    return out


def _cdr_string(text: bytes, declared_length: int | None = None) -> bytes:
    """A CDR ``std_msgs/String`` (little endian), its length field as given."""
    length = len(text) + 1 if declared_length is None else declared_length
    return b"\x00\x01\x00\x00" + struct.pack("<I", length) + text + b"\x00"


def _client_data(channel_id: int, payload: bytes) -> bytes:
    return struct.pack("<BI", 1, channel_id) + payload


_ADVERTISE = {
    "op": "advertise",
    "channels": [
        {"id": 7, "topic": "/from_fox", "encoding": "cdr", "schemaName": "std_msgs/msg/String"}
    ],
}

# (frames sent before, the bad frame, what its error status says)
BAD_INPUTS: list[tuple[str, list[str | bytes], str | bytes, str]] = [
    ("unknown op", [], '{"op": "nope"}', "unknown op 'nope'"),
    ("unsupported op", [], '{"op": "fetchAsset", "uri": "x", "requestId": 1}', "not supported"),
    ("malformed JSON", [], '{"op": "subscribe", ', "invalid JSON"),
    ("non-object JSON", [], "[1, 2, 3]", "expected a JSON object"),
    ("JSON string", [], '"subscribe"', "expected a JSON object"),
    ("no op", [], '{"subscriptions": []}', "no op"),
    ("op not a string", [], '{"op": 5}', "no op"),
    ("field of a wrong type", [], '{"op": "subscribe", "subscriptions": 5}', "subscribe:"),
    ("unknown binary opcode", [], b"\x09abc", "unknown binary opcode 0x09"),
    ("empty binary frame", [], b"", "empty binary frame"),
    ("truncated service call", [], b"\x02\x00\x00\x00\x00", "shorter than its 13-byte header"),
    (
        "unknown channel",
        [],
        '{"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 4242}]}',
        "unknown channel 4242",
    ),
    (
        "unknown subscription",
        [],
        '{"op": "unsubscribe", "subscriptionIds": [77]}',
        "unknown subscription 77",
    ),
    ("unknown client channel", [], _client_data(55, b"x"), "unknown client channel 55"),
    (
        "unadvertise unknown client channel",
        [],
        '{"op": "unadvertise", "channelIds": [56]}',
        "unknown client channel 56",
    ),
    ("truncated binary frame", [], b"\x01\x07\x00", "shorter than its 5-byte header"),
    (
        "truncated CDR payload",
        [json.dumps(_ADVERTISE)],
        _client_data(7, b"\x00\x01\x00\x00\x10\x00"),
        "not a cdr message",
    ),
    (
        "huge length inside a binary frame",
        [json.dumps(_ADVERTISE)],
        _client_data(7, _cdr_string(b"hi", declared_length=0xFFFFFFF0)),
        "not a cdr message",
    ),
    (
        "huge sequence length inside a binary frame",
        [
            json.dumps(
                {
                    "op": "advertise",
                    "channels": [
                        {
                            "id": 8,
                            "topic": "/pts",
                            "encoding": "cdr",
                            "schemaName": "std_msgs/msg/Float64MultiArray",
                        }
                    ],
                }
            )
        ],
        # layout: dims (sequence length 0x7fffffff), then nothing
        _client_data(8, b"\x00\x01\x00\x00\xff\xff\xff\x7f"),
        "not a cdr message",
    ),
    (
        "lone surrogate",
        [],
        '{"op": "subscribe", "subscriptions": [], "x": "\\udc00"}',
        "lone surrogate",
    ),
    (
        "lone surrogate in a client JSON message",
        [
            json.dumps(
                {
                    "op": "advertise",
                    "channels": [
                        {
                            "id": 9,
                            "topic": "/json_in",
                            "encoding": "json",
                            "schemaName": "std_msgs/msg/String",
                        }
                    ],
                }
            )
        ],
        _client_data(9, b'{"data": "\\ud800"}'),
        "lone surrogate",
    ),
    (
        "huge integer",
        [],
        '{"op": "unsubscribe", "subscriptionIds": [' + "9" * 60 + "]}",
        "64 bits",
    ),
    (
        "integer of 4300+ digits",
        [],
        '{"op": "unsubscribe", "subscriptionIds": [' + "9" * 5000 + "]}",
        "invalid JSON",
    ),
    (
        "id wider than 32 bits",
        [],
        '{"op": "subscribe", "subscriptions": [{"id": 4294967296, "channelId": 1}]}',
        "not a 32-bit unsigned integer",
    ),
    (
        "negative id",
        [],
        '{"op": "unsubscribe", "subscriptionIds": [-1]}',
        "not a 32-bit unsigned integer",
    ),
    (
        "deep nesting",
        [],
        '{"op": "subscribe", "x": ' + "[" * 5000 + "]" * 5000 + "}",
        "nesting deeper than 100",
    ),
    (
        "deep nesting in a client JSON message",
        [
            json.dumps(
                {
                    "op": "advertise",
                    "channels": [
                        {
                            "id": 9,
                            "topic": "/json_in",
                            "encoding": "json",
                            "schemaName": "std_msgs/msg/String",
                        }
                    ],
                }
            )
        ],
        _client_data(9, b'{"data": ' + b"[" * 5000 + b"]" * 5000 + b"}"),
        "nesting deeper than 100",
    ),
    (
        "name too long",
        [],
        json.dumps(
            {
                "op": "advertise",
                "channels": [
                    {
                        "id": 1,
                        "topic": "/" + "a" * 5000,
                        "encoding": "cdr",
                        "schemaName": "std_msgs/msg/String",
                    }
                ],
            }
        ),
        "topic:",
    ),
    (
        "unknown type",
        [],
        json.dumps(
            {
                "op": "advertise",
                "channels": [
                    {"id": 1, "topic": "/t", "encoding": "cdr", "schemaName": "nope_msgs/msg/X"}
                ],
            }
        ),
        "advertise:",
    ),
    (
        "unknown encoding",
        [],
        json.dumps(
            {
                "op": "advertise",
                "channels": [{"id": 1, "topic": "/t", "encoding": "protobuf", "schemaName": "x"}],
            }
        ),
        "not supported",
    ),
]


@pytest.mark.parametrize(
    ("before", "frame", "expected"),
    [case[1:] for case in BAD_INPUTS],
    ids=[case[0] for case in BAD_INPUTS],
)
async def test_bad_input_gets_a_status_and_every_connection_goes_on(
    ros2_types: TypeRegistry, before: list[str | bytes], frame: str | bytes, expected: str
) -> None:
    graph = Graph(ros2_types)
    chatter = graph.create_publisher("/chatter", "std_msgs/msg/String")
    async with (
        serving(graph) as server,
        fox(server) as bad,
        fox(server) as other,
        connect(server.urls["websocket"]) as rosbridge,
    ):
        await rosbridge.send(json.dumps({"op": "subscribe", "topic": "/chatter"}))
        await other.subscribe(1, "/chatter")
        for each in before:
            await bad.ws.send(each)
        await bad.ws.send(frame)
        status = await bad.status()
        assert status["level"] == 2, status
        assert expected in str(status["message"]), status
        assert len(str(status["message"])) < 1000  # the input is not echoed whole
        # the same connection goes on: it subscribes and receives
        await bad.subscribe(2, "/chatter")
        await _wait_subscribed(graph, "/chatter", 3)
        chatter.publish({"data": "still here"})
        assert await bad.data_frames(1) == [(2, _cdr_string(b"still here"))]
        assert await other.data_frames(1) == [(1, _cdr_string(b"still here"))]
        assert await rosbridge_messages(rosbridge, 1) == ["still here"]
        assert [op for op in bad.ops if op["op"] == "status"] == [status]


async def _wait_subscribed(graph: Graph, topic: str, count: int) -> None:
    """Until ``count`` clients subscribe to ``topic`` (their ops were read)."""
    while len(graph.port.topics[topic].subscribers) < count:
        await anyio.sleep(0.01)


async def test_an_oversize_frame_closes_only_its_connection(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    chatter = graph.create_publisher("/chatter", "std_msgs/msg/String")
    async with (
        serving(graph) as server,
        fox(server) as bad,
        fox(server) as other,
        connect(server.urls["websocket"]) as rosbridge,
    ):
        await rosbridge.send(json.dumps({"op": "subscribe", "topic": "/chatter"}))
        await other.subscribe(1, "/chatter")
        await bad.ws.send(b"\x01" + b"\x00" * (MAX_MESSAGE_SIZE + 1))
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                await bad.ws.recv()
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1009
        await _wait_subscribed(graph, "/chatter", 2)
        chatter.publish({"data": "others go on"})
        assert await other.data_frames(1) == [(1, _cdr_string(b"others go on"))]
        assert await rosbridge_messages(rosbridge, 1) == ["others go on"]


async def test_too_many_subscriptions_and_client_channels_get_a_status(
    ros2_types: TypeRegistry,
) -> None:
    """``--max-subscriptions`` binds a Foxglove client; a list op's refusals come in one status."""
    graph = Graph(ros2_types)
    topics = [f"/chatter{n}" for n in range(1, 6)]
    publishers = [graph.create_publisher(topic, "std_msgs/msg/String") for topic in topics]
    limits = FoxgloveLimits(max_client_channels=2)
    session = SessionConfig(max_subscriptions=3)
    async with serving(graph, limits, session) as server, fox(server) as client:
        channels = [await client.channel(topic) for topic in topics]
        subscriptions = [{"id": sid, "channelId": c} for sid, c in enumerate(channels, 1)]
        await client.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
        refusal = "more than 3 subscriptions (--max-subscriptions)"
        assert (await client.status())["message"] == f"subscribe: {refusal}; {refusal}"
        channels = [
            {"id": cid, "topic": f"/in{cid}", "encoding": "json", "schemaName": "std_msgs/String"}
            for cid in range(1, 4)
        ]
        await client.ws.send(json.dumps({"op": "advertise", "channels": channels}))
        assert (await client.status())["message"] == "advertise: more than 2 channels"
        # the ones within the bounds work
        for publisher in publishers:
            publisher.publish({"data": "x"})
        assert sorted(sid for sid, _ in await client.data_frames(3)) == [1, 2, 3]
        await client.ws.send(_client_data(2, b'{"data": "in"}'))
        await client.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [1, 2, 3]}))
        await client.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions[3:]}))
        await client.barrier()
        for publisher in publishers:
            publisher.publish({"data": "y"})
        assert sorted(sid for sid, _ in await client.data_frames(2)) == [4, 5]
        statuses = [op["message"] for op in client.ops if op["op"] == "status"]
        assert statuses[2:] == ["unsubscribe: unknown subscription 99"]  # no other refusal


async def test_too_many_topics_are_not_all_advertised(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    for index in range(6):
        graph.create_publisher(f"/t{index}", "std_msgs/msg/String")
    async with serving(graph, FoxgloveLimits(max_channels=4)) as server, fox(server) as client:
        advertise = await client.next_op("advertise")
        warning = await client.status()
        assert len(advertise["channels"]) == 4  # type: ignore[arg-type]
        assert warning["level"] == 1
        # the server's own topics (/client_count...) are not the client's (test_plumbing.py)
        assert "2 topics are not advertised" in str(warning["message"]), warning


# ---- a client that never reads ------------------------------------------------------


class RawFoxglove:
    """A Foxglove client on a bare socket, whose reading the test controls."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        # a small window (what the kernel holds for it is small too), not so small
        # that reading what waits takes long (an ACK per window)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 65536)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
            ).encode()
        )
        self.buf = b""
        while b"\r\n\r\n" not in self.buf:
            self.buf += self.sock.recv(65536)
        head, _, self.buf = self.buf.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 101"), head

    def send_text(self, text: str) -> None:
        payload = text.encode()
        assert len(payload) < 65536
        header = struct.pack("!BBH", 0x81, 0x80 | 126, len(payload)) + b"\0\0\0\0"
        self.sock.sendall(header + payload)

    def frame(self) -> tuple[int, bytes]:
        """The next frame (opcode, payload), read as needed."""
        while True:
            frame = self._cut()
            if frame is not None:
                return frame
            chunk = self.sock.recv(65536)
            assert chunk, "connection closed"
            self.buf += chunk

    def _cut(self) -> tuple[int, bytes] | None:
        buf = self.buf
        if len(buf) < 2:
            return None
        length, start = buf[1] & 0x7F, 2
        if length == 126:
            if len(buf) < 4:
                return None
            length, start = struct.unpack_from("!H", buf, 2)[0], 4
        elif length == 127:
            if len(buf) < 10:
                return None
            length, start = struct.unpack_from("!Q", buf, 2)[0], 10
        if len(buf) < start + length:
            return None
        self.buf = buf[start + length :]
        return buf[0] & 0x0F, buf[start : start + length]

    def op(self, name: str) -> dict[str, object]:
        while True:
            opcode, payload = self.frame()
            if opcode == 1 and (op := json.loads(payload))["op"] == name:
                return op  # type: ignore[no-any-return]


async def test_a_stalled_reader_drops_its_own_data_and_slows_nobody(
    ros2_types: TypeRegistry,
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="rwt.foxglove")
    graph = Graph(ros2_types)
    big = graph.create_publisher("/big", "std_msgs/msg/String")
    limits = FoxgloveLimits(max_queue_messages=40)
    session = SessionConfig(send_buffer_limit=200_000)  # --send-buffer-limit binds it too
    total, window, size = 1500, 10, 10_000
    async with (
        serving(graph, limits, session) as server,
        fox(server) as fast,
        connect(server.urls["websocket"], max_size=None) as rosbridge,
    ):
        port = int(server.urls["websocket"].rsplit(":", 1)[1])
        stalled = await anyio.to_thread.run_sync(RawFoxglove, port)
        channel = int(
            next(c for c in (await anyio.to_thread.run_sync(stalled.op, "advertise"))["channels"])[
                "id"
            ]
        )
        stalled.send_text(
            json.dumps({"op": "subscribe", "subscriptions": [{"id": 9, "channelId": channel}]})
        )
        await rosbridge.send(json.dumps({"op": "subscribe", "topic": "/big"}))
        await fast.subscribe(1, "/big")
        await _wait_subscribed(graph, "/big", 3)
        # from here the stalled client reads nothing
        got_fast = got_rosbridge = 0
        for start in range(0, total, window):
            for index in range(start, start + window):
                big.publish({"data": f"{index:06d}".ljust(size, "x")})
            fast_frames = await fast.data_frames(window)
            got_fast += sum(
                p[8:14] == f"{i:06d}".encode()
                for (_, p), i in zip(fast_frames, range(start, start + window), strict=True)
            )
            got_rosbridge += sum(
                d[:6] == f"{i:06d}"
                for d, i in zip(
                    await rosbridge_messages(rosbridge, window),
                    range(start, start + window),
                    strict=True,
                )
            )
        assert (got_fast, got_rosbridge) == (total, total)
        assert not [op for op in fast.ops if op["op"] == "status"]
        # the stalled client catches up: it was told once, and got the newest
        big.publish({"data": "end"})
        statuses, data = await anyio.to_thread.run_sync(_read_until_end, stalled)
        assert statuses == [DROPPED]
        assert data[-1].endswith(b"end\x00") and len(data) < total
        stalled.sock.close()
        while "event=foxglove_closed" not in caplog.text:
            await anyio.sleep(0.02)
    line = next(r.getMessage() for r in caplog.records if "event=foxglove_closed" in r.getMessage())
    dropped = int(re.search(r"dropped=(\d+)", line).group(1))  # type: ignore[union-attr]
    assert dropped == total + 1 - len(data)
    slow = [r.getMessage() for r in caplog.records if "event=slow_consumer" in r.getMessage()]
    assert len(slow) == 1 and "protocol=foxglove" in slow[0]


def _read_until_end(client: RawFoxglove) -> tuple[list[str], list[bytes]]:
    statuses: list[str] = []
    data: list[bytes] = []
    while True:
        opcode, payload = client.frame()
        if opcode == 1:
            op = json.loads(payload)
            if op["op"] == "status":
                statuses.append(op["message"])
        elif opcode == 2:
            data.append(payload)
            if payload.endswith(b"end\x00"):
                return statuses, data


# ---- a flood of tiny frames -----------------------------------------------------------

FLOOD = 100_000
FAIR = "/fair"


def _masked_binary(payload: bytes) -> bytes:
    """A client's binary frame (masked with a zero key: the payload as it is)."""
    assert len(payload) < 126
    return bytes([0x82, 0x80 | len(payload)]) + b"\0\0\0\0" + payload


def _statuses_until(client: RawFoxglove, last: str) -> list[dict[str, object]]:
    """Every status the client gets until one whose message holds ``last``."""
    statuses: list[dict[str, object]] = []
    while True:
        opcode, payload = client.frame()
        if opcode == 1 and (op := json.loads(payload))["op"] == "status":
            statuses.append(op)
            if last in str(op["message"]):
                return statuses


async def test_a_flood_of_tiny_frames_from_a_foxglove_client_does_not_starve_a_bystander(
    ros2_types: TypeRegistry,
) -> None:
    """As tests/hardening/test_fairness.py, the flooder a Foxglove client: 100,000 frames of
    an unknown opcode in one write, then a message on /fair; right after, a rosbridge
    bystander publishes on /fair too, and its own message comes back first. The flood's
    error statuses are answers, dropped as message data are when they pile up (one
    warning); the flooder's connection goes on."""
    from tests.hardening.peers import WsPeer, settle  # noqa: PLC0415

    graph = Graph(ros2_types)
    async with serving(graph) as server:
        port = int(server.urls["websocket"].rsplit(":", 1)[1])
        bystander = await anyio.to_thread.run_sync(WsPeer, port)
        bystander.send({"op": "subscribe", "topic": FAIR, "type": "std_msgs/String"})
        bystander.send({"op": "advertise", "topic": FAIR, "type": "std_msgs/String"})
        await anyio.to_thread.run_sync(settle, bystander, "b")
        flooder = await anyio.to_thread.run_sync(RawFoxglove, port)
        channel = {"id": 1, "topic": FAIR, "encoding": "json", "schemaName": "std_msgs/String"}
        flooder.send_text(json.dumps({"op": "advertise", "channels": [channel]}))
        flooder.send_text(json.dumps({"op": "unsubscribe", "subscriptionIds": [99]}))
        await anyio.to_thread.run_sync(_statuses_until, flooder, "subscription 99")
        end = _masked_binary(_client_data(1, b'{"data": "flood end"}'))
        statuses: list[dict[str, object]] = []
        order: list[str] = []

        def flood_then_bystander() -> list[str]:
            """The flood, the bystander's publish, then what the bystander got on /fair."""
            flooder.sock.sendall(_masked_binary(b"\x09") * FLOOD + end)
            bystander.send({"op": "publish", "topic": FAIR, "msg": {"data": "bystander"}})
            data: list[str] = []
            while len(data) < 2:
                message = bystander.receive()
                if message.get("op") == "publish" and message.get("topic") == FAIR:
                    data.append(message["msg"]["data"])
            return data

        async def drain_flooder() -> None:
            got = await anyio.to_thread.run_sync(_statuses_until, flooder, "subscription 77")
            statuses.extend(got)

        async with anyio.create_task_group() as tg:
            tg.start_soon(drain_flooder)
            order.extend(await anyio.to_thread.run_sync(flood_then_bystander))
            # every flood frame was read: the flooder's connection goes on
            flooder.send_text(json.dumps({"op": "unsubscribe", "subscriptionIds": [77]}))
        # the bystander was served while the flood was still being read
        assert order == ["bystander", "flood end"]
        errors = [s for s in statuses if s["level"] == 2]
        assert "unknown binary opcode 0x09" in str(errors[0]["message"])
        assert str(errors[-1]["message"]) == "unsubscribe: unknown subscription 77"
        assert len(errors) <= FLOOD + 1
        # answers the flooder did not read in time were dropped, and it was told so
        warnings = {str(s["message"]) for s in statuses if s["level"] == 1}
        assert warnings <= {DROPPED}, warnings
        flooder.sock.close()
        # off the loop: a WebSocket close waits for the server's answer
        await anyio.to_thread.run_sync(bystander.close)
