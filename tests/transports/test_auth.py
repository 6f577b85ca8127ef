"""rosauth over real connections (D23): the first op must be a valid ``auth``.

Valid MACs from the unmodified roslibpy and roslib (``authenticate``) are
accepted; a bad MAC, an expired window or another op first get an error status
and the connection is closed (WebSocket code 1008).
"""

from __future__ import annotations

import json
import time
from collections.abc import AsyncIterator

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from rwt_graph.graph import Graph
from rwt_protocol.auth import rosauth_mac
from rwt_protocol.ops import Auth
from rwt_transports.server import rosauth_authenticator
from tests.support.clients import Harness, is_op, running_server
from tests.support.realclients import node_missing, run_node, run_python

pytestmark = pytest.mark.anyio

SECRET = "1234567890abcdef"


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    graph = Graph()
    authenticator = rosauth_authenticator(SECRET, graph.clock)
    async with running_server(graph=graph, authenticator=authenticator) as h:
        h.server.graph.create_service(
            "/add", "example_interfaces/srv/AddTwoInts", lambda r: {"sum": r["a"] + r["b"]}
        )
        yield h


def credentials(*, secret: str = SECRET, age_s: float = 1.0, valid_s: float = 60.0) -> dict:
    now = time.time()
    fields = {
        "client": "127.0.0.1",
        "dest": "127.0.0.1",
        "rand": "fresh-random-string",
        "t": int(now - age_s),
        "level": "user",
        "end": int(now + valid_s),
    }
    return {"mac": rosauth_mac(secret, **fields), **fields}  # type: ignore[arg-type]


async def test_roslibpy_authenticate_then_call(harness: Harness) -> None:
    c = credentials()
    out = await run_python(
        f"""
        import roslibpy
        ros = roslibpy.Ros("127.0.0.1", {harness.port("websocket")})
        ros.authenticate({c["mac"]!r}, {c["client"]!r}, {c["dest"]!r}, {c["rand"]!r},
                         {c["t"]!r}, {c["level"]!r}, {c["end"]!r})
        ros.run(timeout=20)
        service = roslibpy.Service(ros, "/add", "example_interfaces/AddTwoInts")
        print(service.call(roslibpy.ServiceRequest({{"a": 20, "b": 22}}), timeout=20)["sum"])
        ros.terminate()
        """
    )
    assert out.split() == ["42"]


@pytest.mark.skipif(node_missing() is not None, reason=str(node_missing()))
async def test_roslib_authenticate_then_call(harness: Harness) -> None:
    c = credentials()
    out = await run_node(
        f"""
        import * as ROSLIB from "roslib";
        const ros = new ROSLIB.Ros({{ url: "ws://127.0.0.1:{harness.port("websocket")}" }});
        ros.authenticate({json.dumps(c["mac"])}, {json.dumps(c["client"])},
          {json.dumps(c["dest"])}, {json.dumps(c["rand"])}, {c["t"]},
          {json.dumps(c["level"])}, {c["end"]});
        const add = new ROSLIB.Service({{
          ros, name: "/add", serviceType: "example_interfaces/AddTwoInts" }});
        const timer = setTimeout(() => {{ console.error("timed out"); process.exit(2); }}, 20000);
        add.callService({{ a: 1, b: 2 }}, (result) => {{
          console.log(result.sum); clearTimeout(timer); ros.close();
        }}, (error) => {{ console.error(error); process.exit(3); }});
        """
    )
    assert out.split() == ["3"]


@pytest.mark.parametrize(
    "first",
    [
        {"op": "auth", **credentials(secret="another-secret!!")},
        {"op": "auth", **credentials(age_s=120, valid_s=-60)},
        {"op": "call_service", "service": "/add", "args": [1, 2], "id": "early"},
        {"op": "auth", "mac": "0" * 128},
    ],
    ids=["bad-mac", "expired", "op-before-auth", "incomplete"],
)
async def test_refused_first_ops_get_a_status_and_a_1008_close(
    harness: Harness, first: dict
) -> None:
    with anyio.fail_after(10):
        async with connect(f"ws://127.0.0.1:{harness.port('websocket')}") as ws:
            await ws.send(json.dumps(first))
            received = []
            with pytest.raises(ConnectionClosed) as closed:
                while True:
                    received.append(json.loads(await ws.recv()))
    statuses = [m for m in received if m["op"] == "status"]
    assert len(statuses) == 1 and statuses[0]["level"] == "error"
    assert "authentication" in statuses[0]["msg"]
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
    if first["op"] == "call_service":
        assert received[0]["op"] == "service_response" and received[0]["result"] is False


async def test_tcp_clients_pass_the_same_gate(harness: Harness) -> None:
    with anyio.fail_after(10):
        good = await harness.connect("tcp", "good")
        await good.send({"op": "auth", **credentials()})
        await good.send({"op": "call_service", "service": "/add", "args": [5, 5], "id": 1})
        assert (await good.expect(is_op("service_response")))["values"] == {"sum": 10}
        bad = await harness.connect("tcp", "bad")
        await bad.send({"op": "subscribe", "topic": "/client_count"})
        assert "authentication" in (await bad.expect(is_op("status")))["msg"]
        with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
            await bad.receive()


async def test_a_pluggable_authenticator_sees_the_peer_address() -> None:
    seen: list[str] = []

    def only_admin(op: Auth, peer: str) -> bool:
        seen.append(peer)
        return op.level == "admin"

    async with running_server(authenticator=only_admin) as harness:
        with anyio.fail_after(10):
            client = await harness.connect("ws")
            await client.send({"op": "auth", **credentials(), "level": "admin"})
            await client.send({"op": "set_level", "level": "info", "id": "in"})
            assert (await client.expect(is_op("status", id="in")))["level"] == "info"
    assert len(seen) == 1 and seen[0].startswith("127.0.0.1:")
