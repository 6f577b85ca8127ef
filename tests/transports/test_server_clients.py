"""The server's own topics and nodes over real WebSocket connections (D14, REF §7.1)."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt_graph.graph import Graph
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.conftest import FakeClock

pytestmark = pytest.mark.anyio


@pytest.fixture
async def served(clock: FakeClock) -> AsyncIterator[tuple[str, Graph]]:
    graph = Graph(clock=clock)
    server = RosbridgeServer(graph, ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield url, graph
        tg.cancel_scope.cancel()


async def next_op(ws: ClientConnection, op: str) -> dict[str, object]:
    with anyio.fail_after(5):
        while True:
            frame = json.loads(await ws.recv())
            if frame["op"] == op:
                return frame  # type: ignore[no-any-return]


async def rosapi(ws: ClientConnection, service: str, **args: object) -> object:
    await ws.send(json.dumps({"op": "call_service", "service": service, "args": args}))
    reply = await next_op(ws, "service_response")
    assert reply["result"] is True, reply
    return reply["values"]


async def test_connected_clients_and_client_count_are_latched_and_follow_connections(
    served: tuple[str, Graph], clock: FakeClock
) -> None:
    url, _ = served
    async with connect(url) as watcher:
        await watcher.send(json.dumps({"op": "subscribe", "topic": "/connected_clients"}))
        first = await next_op(watcher, "publish")
        stamp = {"sec": 1_700_000_000, "nanosec": 250_000_000}
        assert first == {
            "op": "publish",
            "topic": "/connected_clients",
            "msg": {"clients": [{"ip_address": "127.0.0.1", "connection_time": stamp}]},
        }
        await watcher.send(json.dumps({"op": "subscribe", "topic": "/client_count"}))
        assert (await next_op(watcher, "publish"))["msg"] == {"data": 1}
        clock.epoch += 5
        async with connect(url):
            joined = await next_op(watcher, "publish")
            assert joined["topic"] == "/client_count" and joined["msg"] == {"data": 2}
            clients = (await next_op(watcher, "publish"))["msg"]["clients"]  # type: ignore[index]
            assert [c["connection_time"]["sec"] for c in clients] == [1_700_000_000, 1_700_000_005]
        left = await next_op(watcher, "publish")
        assert left["msg"] == {"data": 1}
        assert len((await next_op(watcher, "publish"))["msg"]["clients"]) == 1  # type: ignore[index]


async def test_rosapi_names_the_server_rosapi_and_each_connection(
    served: tuple[str, Graph],
) -> None:
    url, graph = served
    graph.create_publisher("/battery", "sensor_msgs/msg/BatteryState", node="/power")
    async with connect(url) as first, connect(url) as second:
        assert await rosapi(first, "/rosapi/nodes") == {
            "nodes": [
                "/power",
                "/rosapi",
                "/rosbridge_websocket",
                "/rwt_client_1",
                "/rwt_client_2",
                "/tf2_web_republisher",
            ]
        }
        assert await rosapi(second, "rosapi/publishers", topic="/client_count") == {
            "publishers": ["/rosbridge_websocket"]
        }
        topics = await rosapi(second, "/rosapi/topics")
        listed = dict(zip(topics["topics"], topics["types"], strict=True))
        assert {
            name: listed[name] for name in ("/battery", "/client_count", "/connected_clients")
        } == {
            "/battery": "sensor_msgs/msg/BatteryState",
            "/client_count": "std_msgs/msg/Int32",
            "/connected_clients": "rosbridge_msgs/msg/ConnectedClients",
        }
        # the rest is the built-in tf2_web_republisher's (tests/graph/tf/)
        assert all(
            name.startswith("/tf")
            for name in set(listed) - {"/battery", "/client_count", "/connected_clients"}
        )
    async with connect(url) as third:
        await third.send(json.dumps({"op": "subscribe", "topic": "/client_count"}))
        while (await next_op(third, "publish"))["msg"] != {"data": 1}:
            pass  # the server has not seen both others leave yet
        nodes = await rosapi(third, "/rosapi/nodes")
        assert nodes == {
            "nodes": [
                "/power",
                "/rosapi",
                "/rosbridge_websocket",
                "/rwt_client_3",
                "/tf2_web_republisher",
            ]
        }
