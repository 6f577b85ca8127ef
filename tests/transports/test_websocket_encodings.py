"""Encodings over a real WebSocket: CBOR frames both ways (D21, D27), throttle timers (D12)."""

from __future__ import annotations

import json

import anyio
import cbor2
import pytest
from websockets.asyncio.client import connect

from rwt_graph.graph import Graph
from rwt_transports.server import RosbridgeServer, ServerConfig

pytestmark = pytest.mark.anyio


async def test_binary_ops_in_and_cbor_frames_out() -> None:
    server = RosbridgeServer(Graph(), ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        with anyio.fail_after(10):
            async with connect(url) as ws:
                subscribe = {"op": "subscribe", "topic": "/b", "type": "std_msgs/UInt8MultiArray"}
                await ws.send(cbor2.dumps({**subscribe, "compression": "cbor"}))
                await ws.send(
                    cbor2.dumps({"op": "publish", "topic": "/b", "msg": {"data": b"\x01\x02"}})
                )
                frame = await ws.recv()
                assert isinstance(frame, bytes)
                message = cbor2.loads(frame)
                assert message["op"] == "publish" and message["msg"]["data"] == b"\x01\x02"
                # Text frames are JSON: CBOR sent as text is not an op.
                await ws.send(cbor2.dumps({"op": "set_level", "level": "info"}).decode("latin-1"))
                status = await ws.recv()
                assert isinstance(status, str)
                assert "invalid JSON" in json.loads(status)["msg"]
        tg.cancel_scope.cancel()


async def test_the_trailing_throttled_message_arrives_without_more_traffic() -> None:
    # The trailing send is due on the session's timer while the writer is idle:
    # scheduling it must wake the writer (Session.call_at), or it never goes out.
    graph = Graph()
    publisher = graph.create_publisher("/t", "std_msgs/msg/String")
    server = RosbridgeServer(graph, ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        with anyio.fail_after(10):
            async with connect(url) as ws:
                subscribe = {"op": "subscribe", "topic": "/t", "throttle_rate": 1000}
                await ws.send(json.dumps({**subscribe, "type": "std_msgs/String"}))
                await ws.send(json.dumps({"op": "set_level", "level": "info"}))
                assert json.loads(await ws.recv())["op"] == "status"  # processed in order
                publisher.publish({"data": "first"})
                assert json.loads(await ws.recv())["msg"]["data"] == "first"
                publisher.publish({"data": "second"})
                publisher.publish({"data": "latest"})
                received = []
                while not received or received[-1] != "latest":
                    received.append(json.loads(await ws.recv())["msg"]["data"])
                assert received in (["latest"], ["second", "latest"])
        tg.cancel_scope.cancel()
