"""Connection churn costs O(changes), not O(clients x subscribers) (docs/limits.md).

``/client_count`` and ``/connected_clients`` (D14) are published at most once per
``ServerConfig.clients_interval_s`` with the latest state, so many connections
coming and going send a subscriber a bounded number of whole lists, the last one
right, while every other client is still served.
"""

from __future__ import annotations

import contextlib
import json

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt_protocol.framing.streams import JsonStreamFramer
from rwt_protocol.runtime.inframes import InFrame
from rwt_transports.server import RosbridgeServer, ServerConfig

pytestmark = pytest.mark.anyio

CHURN = 150  # TCP connections opened and closed, one after another
KEPT = 5  # TCP connections that stay
INTERVAL_S = 0.5


async def tcp_round_trip(port: int, tag: str) -> None:
    async with await anyio.connect_tcp("127.0.0.1", port) as tcp:
        await tcp.send(json.dumps({"op": "set_level", "level": "info", "id": tag}).encode())
        assert json.loads((await tcp.receive()).split(b"\n")[0])["id"] == tag


async def ws_round_trip(ws: ClientConnection, tag: str) -> None:
    await ws.send(json.dumps({"op": "set_level", "level": "info", "id": tag}))
    while (reply := json.loads(await ws.recv())).get("id") != tag:
        pass
    assert reply["op"] == "status"


async def test_churn_publishes_the_client_list_at_most_once_per_interval() -> None:
    server = RosbridgeServer(config=ServerConfig(port=0, tcp_port=0, clients_interval_s=INTERVAL_S))
    lists: list[tuple[float, list[dict[str, object]]]] = []
    counts: list[int] = []
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        tcp_port = int(server.urls["tcp"].rsplit(":", 1)[1])
        with anyio.fail_after(60):
            async with connect(url) as watcher, connect(url) as bystander:
                for topic in ("/connected_clients", "/client_count"):
                    await watcher.send(json.dumps({"op": "subscribe", "topic": topic}))

                async def watch() -> None:
                    async for frame in watcher:
                        message = json.loads(frame)
                        if message.get("topic") == "/connected_clients":
                            lists.append((anyio.current_time(), message["msg"]["clients"]))
                        elif message.get("topic") == "/client_count":
                            counts.append(message["msg"]["data"])

                tg.start_soon(watch)
                while not lists:  # the latched list
                    await anyio.sleep(0.01)
                started = anyio.current_time()
                before = len(lists)
                kept = [await anyio.connect_tcp("127.0.0.1", tcp_port) for _ in range(KEPT)]
                for i in range(CHURN):
                    await tcp_round_trip(tcp_port, f"churn-{i}")
                await ws_round_trip(bystander, "bystander")  # served through the churn
                expected = 2 + KEPT  # watcher, bystander, the kept ones
                while len(lists[-1][1]) != expected or counts[-1] != expected:
                    await anyio.sleep(0.05)
                published = len(lists) - before
                elapsed = lists[-1][0] - started
                # the first change at once, then at most one per interval
                assert published <= elapsed / INTERVAL_S + 2, (published, elapsed)
                assert published < CHURN  # not one per connection, let alone two
                assert all(c["ip_address"] == "127.0.0.1" for c in lists[-1][1])
                async with connect(url) as late:  # latched: the current list at once
                    await late.send(json.dumps({"op": "subscribe", "topic": "/connected_clients"}))
                    latest = json.loads(await late.recv())
                    assert len(latest["msg"]["clients"]) in (expected, expected + 1)  # + late
                for tcp in kept:
                    await tcp.aclose()
        tg.cancel_scope.cancel()


SUBSCRIBERS = 60  # TCP connections subscribed to /connected_clients
FANOUT_PER_S = 3600.0  # entries a second: 60 x 60 entries per list, so one list a second
FAST_INTERVAL_S = 0.05  # the interval alone would allow 20 lists a second


async def test_many_subscribers_get_a_list_as_often_as_the_fanout_allows_and_the_last_right() -> (
    None
):
    """A list goes to every subscriber, so its cost is clients x subscribers entries:
    ``clients_fanout_per_s`` stretches the interval to keep that rate, and every
    subscriber still ends with the final list."""
    config = ServerConfig(
        port=0,
        tcp_port=0,
        clients_interval_s=FAST_INTERVAL_S,
        clients_fanout_per_s=FANOUT_PER_S,
    )
    server = RosbridgeServer(config=config)
    lists: list[list[int]] = [[] for _ in range(SUBSCRIBERS)]  # list lengths, per subscriber
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        tcp_port = int(server.urls["tcp"].rsplit(":", 1)[1])
        with anyio.fail_after(120):
            subscribers = [await anyio.connect_tcp("127.0.0.1", tcp_port) for _ in lists]

            async def read(index: int) -> None:
                framer = JsonStreamFramer(1 << 24)
                with contextlib.suppress(anyio.ClosedResourceError):  # closed at the end
                    async for chunk in subscribers[index]:
                        for event in framer.receive_data(chunk):
                            assert isinstance(event, InFrame)
                            message = json.loads(event.data)
                            if message.get("topic") == "/connected_clients":
                                lists[index].append(len(message["msg"]["clients"]))

            for index, stream in enumerate(subscribers):
                tg.start_soon(read, index)
                await stream.send(
                    json.dumps({"op": "subscribe", "topic": "/connected_clients"}).encode()
                )
            while any(not got or got[-1] != SUBSCRIBERS for got in lists):
                await anyio.sleep(0.05)
            before = [len(got) for got in lists]
            started = anyio.current_time()
            for i in range(CHURN):
                await tcp_round_trip(tcp_port, f"churn-{i}")
            while any(got[-1] != SUBSCRIBERS for got in lists):  # the final list, everywhere
                await anyio.sleep(0.05)
            elapsed = anyio.current_time() - started
            # every list has at least SUBSCRIBERS entries and goes to SUBSCRIBERS
            interval = SUBSCRIBERS * SUBSCRIBERS / FANOUT_PER_S
            most = max(len(got) - n for got, n in zip(lists, before, strict=True))
            assert most <= elapsed / interval + 2, (most, elapsed)
            for stream in subscribers:
                await stream.aclose()
        tg.cancel_scope.cancel()
