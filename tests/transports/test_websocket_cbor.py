"""Binary WebSocket frames carry CBOR both ways (PROTOCOL-DECISIONS D21, D27)."""

from __future__ import annotations

import json

import anyio
import cbor2
import pytest
from websockets.asyncio.client import connect

from rwt_graph.graph import Graph
from rwt_transports.server import RosbridgeServer, ServerConfig

pytestmark = pytest.mark.anyio


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


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
