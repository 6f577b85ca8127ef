"""A message larger than ``--send-buffer-limit`` still reaches a subscriber (docs/limits.md).

A 20 MB ``sensor_msgs/PointCloud2`` (15 MiB of points, sent as base64) is over a
4 MiB send buffer limit. Before, the outbox dropped it on arrival however fast the
subscriber read, and then closed the idle subscriber as a slow consumer: it had
taken nothing. Now it goes out through an empty outbox, over WebSocket and TCP,
to every subscriber, and two in a row reach subscribers that read. A subscriber
that is behind (other messages still wait for it when one comes) loses it and
is told, with a warning naming the option to raise.

Real clients on their own threads: websockets' client, a plain TCP socket, and
roslibpy in a subprocess; a stalled WebSocket subscriber reads only when the
test says so (websockets' sans-IO protocol on a socket with a small buffer).
"""

from __future__ import annotations

import base64
import hashlib
import json
import socket
from collections import deque
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import anyio
import anyio.to_thread
import pytest
from websockets.client import ClientProtocol
from websockets.frames import Opcode
from websockets.http11 import Response
from websockets.uri import parse_uri

from rwt_protocol.runtime.outbox import OutFrame
from rwt_protocol.server.session import Session, SessionConfig
from rwt_transports.server import ServerConfig
from rwt_transports.tcp import stream_writes
from tests.hardening.peers import TIMEOUT_S, Peer, TcpPeer, WsPeer, settle
from tests.support.clients import Harness, running_server
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio

MiB = 1024 * 1024
LIMIT = 4 * MiB
POINTS = 15 * MiB  # bytes of point data: 20 MiB of base64, five times the limit
TOPIC = "/points"
TYPE = "sensor_msgs/PointCloud2"
Message = dict[str, Any]


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    config = ServerConfig(
        max_message_size=32 * MiB,  # the publisher's 20 MB must get in
        session=SessionConfig(send_buffer_limit=LIMIT, send_timeout_s=300.0),
    )
    async with running_server(config) as h:
        yield h


@pytest.fixture
async def opened() -> AsyncIterator[list[Peer | StalledWsPeer]]:
    """Peers a test opens, closed after it (off the loop: a WebSocket close awaits the server)."""
    peers: list[Peer | StalledWsPeer] = []
    yield peers
    for peer in peers:
        await anyio.to_thread.run_sync(peer.close)


class LongLineTcpPeer(TcpPeer):
    """``TcpPeer`` for lines of megabytes: the parts of a line are joined once, at its end."""

    def __init__(self, port: int, rcvbuf: int | None = None) -> None:
        super().__init__(port, rcvbuf)
        self._parts: list[bytes] = []

    def receive(self) -> Message:
        while not self._lines:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise EOFError("the server closed the connection")
            if b"\n" not in chunk:
                self._parts.append(chunk)
                continue
            *lines, rest = (b"".join(self._parts) + chunk).split(b"\n")
            self._parts = [rest]
            self._lines.extend(lines)
        return json.loads(self._lines.popleft())  # type: ignore[no-any-return]


class StalledWsPeer:
    """A WebSocket client that reads its socket only in ``receive``, with a 4 KB buffer.

    Until it reads, what the server sends backs up in the server's writer and outbox.
    """

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        self.sock.settimeout(TIMEOUT_S)
        self.sock.connect(("127.0.0.1", port))
        self.protocol = ClientProtocol(parse_uri(f"ws://127.0.0.1:{port}/"), max_size=None)
        self.protocol.send_request(self.protocol.connect())
        self._flush()
        self._messages: deque[Message] = deque()
        self._parts: list[bytes] = []
        while not self._events():  # the handshake's response
            self.protocol.receive_data(self.sock.recv(1 << 16))

    def _flush(self) -> None:
        for data in self.protocol.data_to_send():
            if data:
                self.sock.sendall(data)

    def _events(self) -> bool:
        """Take what the protocol parsed; True once the handshake's response came."""
        responded = False
        for event in self.protocol.events_received():
            if isinstance(event, Response):
                assert event.status_code == 101, event
                responded = True
            elif event.opcode in (Opcode.TEXT, Opcode.CONT):
                self._parts.append(event.data)
                if event.fin:
                    self._messages.append(json.loads(b"".join(self._parts)))
                    self._parts = []
        self._flush()  # pongs
        return responded

    def send(self, op: Message) -> None:
        self.protocol.send_text(json.dumps(op).encode())
        self._flush()

    def receive(self) -> Message:
        while not self._messages:
            data = self.sock.recv(1 << 20)
            if not data:
                raise EOFError("the server closed the connection")
            self.protocol.receive_data(data)
            self._events()
        return self._messages.popleft()

    def close(self) -> None:
        self.sock.close()


def open_reader(transport: str, harness: Harness) -> Peer:
    if transport == "ws":
        return WsPeer(harness.port("websocket"))
    return LongLineTcpPeer(harness.port("tcp"))


def cloud(tag: int, size: int = POINTS) -> tuple[Message, str]:
    """A publish of a ``size``-byte point cloud whose bytes all equal ``tag``, and its base64."""
    data = base64.b64encode(bytes([tag]) * size).decode()
    msg = {
        "header": {"frame_id": f"cloud{tag}"},
        "height": 1,
        "width": size // 16,
        "fields": [{"name": "x", "offset": 0, "datatype": 7, "count": 1}],
        "is_bigendian": False,
        "point_step": 16,
        "row_step": size,
        "data": data,
        "is_dense": True,
    }
    return {"op": "publish", "topic": TOPIC, "msg": msg}, data


def subscribe(peer: Peer | StalledWsPeer, tag: str) -> None:
    """Subscribe with warnings on (``set_level``, D2): the status of a drop is a warning."""
    peer.send({"op": "set_level", "level": "warning"})
    peer.send({"op": "subscribe", "topic": TOPIC, "type": TYPE})
    if isinstance(peer, StalledWsPeer):
        peer.send({"op": "call_service", "service": "/rosapi/topics", "id": tag})
        while peer.receive().get("id") != tag:
            pass
    else:
        settle(peer, tag)


def read_clouds(peer: Peer | StalledWsPeer, count: int) -> tuple[list[Message], list[str]]:
    """Read until ``count`` clouds came: them, and the texts of the statuses meanwhile."""
    clouds: list[Message] = []
    statuses: list[str] = []
    while len(clouds) < count:
        message = peer.receive()
        if message.get("op") == "publish":
            clouds.append(message["msg"])
        elif message.get("op") == "status":
            statuses.append(message["msg"])
    return clouds, statuses


def session_of(harness: Harness, before: set[object]) -> Session:
    [client] = set(harness.server.sessions) - before
    return harness.server.sessions[client]


@pytest.mark.parametrize("transport", ["ws", "tcp"])
async def test_two_in_a_row_over_the_limit_reach_every_subscriber_intact(
    harness: Harness, opened: list[Peer | StalledWsPeer], transport: str
) -> None:
    readers = [await anyio.to_thread.run_sync(open_reader, transport, harness) for _ in range(3)]
    opened.extend(readers)
    for i, reader in enumerate(readers):
        await anyio.to_thread.run_sync(subscribe, reader, f"s{i}")
    publisher = await anyio.to_thread.run_sync(open_reader, transport, harness)
    opened.append(publisher)
    (first, first_data), (second, second_data) = cloud(1), cloud(2)
    assert len(json.dumps(first)) > 5 * LIMIT
    results: list[tuple[list[Message], list[str]]] = []

    async def read(reader: Peer) -> None:
        results.append(await anyio.to_thread.run_sync(read_clouds, reader, 2))

    def publish() -> None:
        publisher.send({"op": "advertise", "topic": TOPIC, "type": TYPE})
        publisher.send(first)  # and at once the next one
        publisher.send(second)

    with anyio.fail_after(240):
        async with anyio.create_task_group() as tg:
            for reader in readers:
                tg.start_soon(read, reader)
            await anyio.to_thread.run_sync(publish)
    assert len(results) == 3
    for clouds, statuses in results:
        assert [c["header"]["frame_id"] for c in clouds] == ["cloud1", "cloud2"]
        assert clouds[0]["data"] == first_data and clouds[1]["data"] == second_data
        assert statuses == []
    assert all(session.stats.dropped_frames == 0 for session in harness.server.sessions.values())


@pytest.mark.parametrize("transport", ["ws", "tcp"])
async def test_a_subscriber_that_is_behind_is_told_to_raise_the_limit(
    harness: Harness, opened: list[Peer | StalledWsPeer], transport: str
) -> None:
    before = set(harness.server.sessions)

    def open_stalled() -> Peer | StalledWsPeer:
        if transport == "ws":
            return StalledWsPeer(harness.port("websocket"))
        return LongLineTcpPeer(harness.port("tcp"), rcvbuf=4096)

    stalled = await anyio.to_thread.run_sync(open_stalled)
    opened.append(stalled)
    await anyio.to_thread.run_sync(subscribe, stalled, "s")
    subscriber = session_of(harness, before)
    publisher = await anyio.to_thread.run_sync(open_reader, transport, harness)
    opened.append(publisher)
    await anyio.to_thread.run_sync(
        publisher.send, {"op": "advertise", "topic": TOPIC, "type": TYPE}
    )
    first, first_data = cloud(1)
    small, small_data = cloud(3, size=64 * 1024)
    late, _ = cloud(2)
    again, again_data = cloud(4)
    smalls = 0
    with anyio.fail_after(240):
        await anyio.to_thread.run_sync(publisher.send, first)  # its writer is stuck on it
        await anyio.to_thread.run_sync(settle, publisher, "first")
        while subscriber.stats.queued_bytes == 0:  # small ones until one waits in the outbox
            await anyio.to_thread.run_sync(publisher.send, small)
            await anyio.to_thread.run_sync(settle, publisher, f"small{smalls}")
            smalls += 1
            if subscriber.stats.queued_bytes:  # unless the writer was only about to take it
                await anyio.sleep(0.1)
        await anyio.to_thread.run_sync(publisher.send, late)  # behind: it cannot go
        await anyio.to_thread.run_sync(settle, publisher, "late")
        assert subscriber.stats.dropped_frames == 1
        clouds, statuses = await anyio.to_thread.run_sync(read_clouds, stalled, 1 + smalls)
        assert clouds[0]["data"] == first_data
        assert [c["data"] == small_data for c in clouds[1:]] == [True] * smalls
        while not statuses:  # it follows the messages that waited
            message = await anyio.to_thread.run_sync(stalled.receive)
            assert message["op"] == "status", message
            statuses.append(message["msg"])
        # Caught up: the next one goes out again.
        await anyio.to_thread.run_sync(publisher.send, again)
        [after], more = await anyio.to_thread.run_sync(read_clouds, stalled, 1)
    assert after["data"] == again_data and more == []
    [text] = statuses
    assert f"larger than the send buffer limit (--send-buffer-limit {LIMIT} bytes)" in text, text
    assert f"message of {TOPIC}" in text, text


ROSLIBPY_SUBSCRIBER = """
import hashlib, threading, roslibpy
ros = roslibpy.Ros(host="127.0.0.1", port={port})
ros.run(timeout=60)
seen, done = [], threading.Event()
def on_cloud(message):
    digest = hashlib.sha256(message["data"].encode()).hexdigest()
    seen.append((message["header"]["frame_id"], digest))
    if len(seen) == 2:
        done.set()
topic = roslibpy.Topic(ros, "{topic}", "{type}")
topic.subscribe(on_cloud)
roslibpy.Service(ros, "/rosapi/topics", "rosapi/Topics").call(roslibpy.ServiceRequest())
open("{ready}", "w").close()
done.wait(150)
for frame_id, digest in seen:
    print(frame_id, digest, flush=True)
ros.terminate()
"""


async def test_roslibpy_gets_two_clouds_over_the_limit(harness: Harness, tmp_path: Path) -> None:
    """roslibpy, the real client, subscribed over WebSocket."""
    ready = tmp_path / "ready"
    code = ROSLIBPY_SUBSCRIBER.format(
        port=harness.port("websocket"), topic=TOPIC, type=TYPE, ready=ready
    )
    clouds = [cloud(1), cloud(2)]
    output: list[str] = []

    async def subscriber() -> None:
        output.append(await run_python(code))

    def publish() -> None:
        publisher = WsPeer(harness.port("websocket"))
        try:
            publisher.send({"op": "advertise", "topic": TOPIC, "type": TYPE})
            for message, _ in clouds:
                publisher.send(message)
            settle(publisher, "published")
        finally:
            publisher.close()

    with anyio.fail_after(240):
        async with anyio.create_task_group() as tg:
            tg.start_soon(subscriber)
            while not await anyio.Path(ready).exists():
                await anyio.sleep(0.05)  # roslibpy subscribed (its rosapi call was answered)
            await anyio.to_thread.run_sync(publish)
    expected = [
        f"cloud{i + 1} {hashlib.sha256(data.encode()).hexdigest()}"
        for i, (_, data) in enumerate(clouds)
    ]
    assert output[0].splitlines() == expected, output[0]


def test_tcp_writes_a_large_frame_as_it_is_shared() -> None:
    """Every subscriber's TCP writer sends the shared payload itself, then its newline."""
    big, small = OutFrame(b"{" + b" " * (2 * MiB) + b"}"), OutFrame(b"{}")
    writes = stream_writes([small, big, small])
    assert writes[1] is big.data
    assert b"".join(writes) == b"{}\n" + big.data + b"\n{}\n"
