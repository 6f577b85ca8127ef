"""Message data frames shared by the clients subscribed with one id (``foxglove-shared-frames``).

With the shortcut on, a message's frame (the 13-byte header and the payload) is
made once per subscription id and queued by every client subscribed with that
id; off, each client makes its own. Clients must get the same bytes either way,
each queue keeps its own bounds (a client that reads nothing drops its own
oldest, not another's), and a client subscribed with another id gets its own
header.
"""

from __future__ import annotations

import itertools
import json
import struct
from collections import Counter
from collections.abc import Iterator

import anyio
import anyio.lowlevel
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt_foxglove import session as session_module
from rwt_foxglove.limits import FoxgloveLimits
from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.foxglove.sansio import Client
from tests.support.shortcuts import switch_off

SIDS = (7, 7, 3)  # two clients share an id, the third has its own
_IDS = itertools.count(1)  # each client its own identity in the graph


@pytest.fixture
def made(monkeypatch: pytest.MonkeyPatch) -> Iterator[Counter[int]]:
    """Counts the message data frames made (their headers), by subscription id."""
    counts = Counter[int]()
    real = session_module.encode_message_header

    def counted(sid: int, log_time: int) -> bytes:
        counts[sid] += 1
        return real(sid, log_time)

    monkeypatch.setattr(session_module, "encode_message_header", counted)
    yield counts


def _texts() -> list[str]:
    return [f"small {i}" for i in range(50)] + [
        f"large {i} ".ljust(100_000 + i, "x") for i in range(3)
    ]


def _subscribed(graph: Graph, sid: int, **kwargs: object) -> Client:
    client = Client(graph, client_id=f"foxglove:test#{next(_IDS)}", **kwargs)
    channel = client.channel("/shared")
    client.send({"op": "subscribe", "subscriptions": [{"id": sid, "channelId": channel["id"]}]})
    return client


@pytest.mark.parametrize("off", [None, "foxglove-shared-frames", "1"])
def test_each_client_gets_its_frames_whether_shared_or_not(
    ros2_types: TypeRegistry, monkeypatch: pytest.MonkeyPatch, made: Counter[int], off: str | None
) -> None:
    switch_off(monkeypatch, off)
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/shared", "std_msgs/msg/String")
    clients = [_subscribed(graph, sid) for sid in SIDS]
    texts = _texts()
    for text in texts:
        publisher.publish({"data": text})
    for client in clients:
        client.drain()
    for client, sid in zip(clients, SIDS, strict=True):
        assert len(client.binary) == len(texts)
        for frame, text in zip(client.binary, texts, strict=True):
            assert frame[0] == 1 and struct.unpack_from("<I", frame, 1) == (sid,)
            assert frame[13 + 8 : 13 + 8 + len(text)] == text.encode()  # after CDR's 8 bytes
    assert clients[0].binary == clients[1].binary  # the same id: the same bytes
    assert [f[5:] for f in clients[0].binary] == [f[5:] for f in clients[2].binary]
    if off is None:  # one frame a message for each id, however many clients have it
        assert made == {7: len(texts), 3: len(texts)}
    else:
        assert made == {7: 2 * len(texts), 3: len(texts)}


@pytest.mark.parametrize("off", [None, "foxglove-shared-frames"])
def test_a_client_that_reads_nothing_drops_only_its_own_oldest(
    ros2_types: TypeRegistry, monkeypatch: pytest.MonkeyPatch, off: str | None
) -> None:
    switch_off(monkeypatch, off)
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/shared", "std_msgs/msg/String")
    reader = _subscribed(graph, 7)
    stalled = _subscribed(graph, 7, limits=FoxgloveLimits(max_queue_messages=5))
    for index in range(20):
        publisher.publish({"data": f"m {index:02d}"})
        reader.drain()  # this one reads each message; ``stalled`` only at the end
    stalled.drain()
    assert [frame[21:25] for frame in reader.binary] == [f"m {i:02d}".encode() for i in range(20)]
    assert stalled.binary == reader.binary[-5:]  # its own oldest went, the reader's stayed
    assert stalled.session.dropped == 15 and reader.session.dropped == 0
    warnings = [op for op in stalled.take_ops("status") if op.get("id") == "rwt.dropping"]
    assert len(warnings) == 1
    assert not reader.take_ops("status")


async def _over_the_wire(monkeypatch: pytest.MonkeyPatch, off: str | None) -> list[list[bytes]]:
    """The binary frames each client (``SIDS``) got for ``_texts``, through the server."""
    switch_off(monkeypatch, off)
    graph = Graph()
    publisher = graph.create_publisher("/shared", "std_msgs/msg/String")
    texts = _texts()
    got: list[list[bytes]] = [[] for _ in SIDS]
    server = RosbridgeServer(graph, ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        with anyio.fail_after(60):
            async with anyio.create_task_group() as readers:
                for index, sid in enumerate(SIDS):
                    readers.start_soon(
                        _receive, server.urls["websocket"], sid, len(texts), got[index]
                    )
                entry = None
                while entry is None or len(entry.subscribers) < len(SIDS):
                    await anyio.sleep(0.01)  # the graph announces no subscription: looked at
                    entry = graph.port.topics.get("/shared")
                for text in texts:
                    publisher.publish({"data": text})
                    await anyio.lowlevel.checkpoint()
        tg.cancel_scope.cancel()
    return got


@pytest.mark.anyio
async def test_clients_get_the_same_bytes_over_the_wire_shared_or_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    shared = await _over_the_wire(monkeypatch, None)
    own = await _over_the_wire(monkeypatch, "foxglove-shared-frames")
    general = await _over_the_wire(monkeypatch, "1")  # websockets frames each message

    def without_log_time(run: list[list[bytes]]) -> list[list[bytes]]:
        return [[frame[:5] + frame[13:] for frame in frames] for frames in run]

    assert without_log_time(shared) == without_log_time(own) == without_log_time(general)
    assert len(shared[0]) == len(_texts())
    assert shared[0] == shared[1]
    assert all(struct.unpack_from("<I", frame, 1) == (3,) for frame in shared[2])


async def _receive(url: str, sid: int, count: int, frames: list[bytes]) -> None:
    async with connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:  # type: ignore[list-item]
        await _subscribe(ws, sid)
        while len(frames) < count:
            frame = await ws.recv()
            if isinstance(frame, bytes):
                frames.append(frame)


async def _subscribe(ws: ClientConnection, sid: int) -> None:
    while True:
        frame = await ws.recv()
        if isinstance(frame, str) and json.loads(frame)["op"] == "advertise":
            for channel in json.loads(frame)["channels"]:
                if channel["topic"] == "/shared":
                    subscription = {"id": sid, "channelId": channel["id"]}
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))
                    return
