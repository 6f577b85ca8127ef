"""Foxglove clients under rosauth (``--auth-secret-file``): the token is in the URL.

A Foxglove client has no ``auth`` op, so it carries the op's fields as the URL's
query parameters (``rwt_protocol.auth.auth_query``, docs/foxglove.md). The real
Node client (@foxglove/ws-protocol) with a valid token gets in, receives data and
shows in rosapi as a participant; a missing, bad or expired token is refused at
the handshake (HTTP 401/403) and logged; rosbridge clients still authenticate with
the ``auth`` op, whatever their URL says.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from rwt_graph.graph import Graph
from rwt_protocol.auth import (
    URL_MAC_LABEL,
    auth_from_query,
    auth_query,
    bound_mac,
    rosauth_mac,
    rosauth_op,
)
from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.ops import Auth
from rwt_protocol.server.session import SessionConfig
from rwt_transports.foxglove import FoxgloveOptions
from rwt_transports.server import RosbridgeServer, ServerConfig, rosauth_authenticator
from tests.support.realclients import node_missing, run_node

pytestmark = pytest.mark.anyio

SECRET = "foxglove-secret-0123456789"
FOXGLOVE = ["foxglove.sdk.v1"]


@dataclass
class Served:
    graph: Graph
    url: str
    foxglove_url: str


@pytest.fixture
async def served() -> AsyncIterator[Served]:
    graph = Graph()
    server = RosbridgeServer(
        graph,
        ServerConfig(port=0, foxglove=FoxgloveOptions(port=0)),
        authenticator=rosauth_authenticator(SECRET, graph.clock),
    )
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield Served(graph, url, server.urls["foxglove"])
        tg.cancel_scope.cancel()


def token(*, secret: str = SECRET, age_s: float = 1.0, valid_s: float = 60.0) -> Auth:
    now = time.time()
    return rosauth_op(
        secret,
        client="192.168.1.20",
        dest="127.0.0.1",
        rand="a-fresh-random-string",
        t=now - age_s,
        level="user",
        end=now + valid_s,
    )


def with_token(url: str, op: Auth | None = None) -> str:
    return f"{url}/?{auth_query(op or token())}"


async def next_op(ws: ClientConnection, op: str) -> dict[str, object]:
    with anyio.fail_after(10):
        while True:
            frame = json.loads(await ws.recv())
            if frame["op"] == op:
                return frame  # type: ignore[no-any-return]


async def rosapi(ws: ClientConnection, service: str, **args: object) -> dict[str, list[str]]:
    await ws.send(json.dumps({"op": "call_service", "service": service, "args": args}))
    reply = await next_op(ws, "service_response")
    assert reply["result"] is True, reply
    return reply["values"]  # type: ignore[return-value]


async def participant_with(ws: ClientConnection, topic: str) -> tuple[str, dict[str, list[str]]]:
    """The node that subscribes to ``topic`` and its rosapi details, once there is one."""
    with anyio.fail_after(20):
        while True:
            for node in (await rosapi(ws, "/rosapi/nodes"))["nodes"]:
                details = await rosapi(ws, "/rosapi/node_details", node=node)
                if topic in details["subscribing"]:
                    return node, details
            await anyio.sleep(0.02)  # the Node client has not subscribed yet


async def rosbridge(url: str) -> ClientConnection:
    ws = await connect(url)
    await ws.send(json.dumps(token().model_dump()))
    return ws


@pytest.mark.skipif(node_missing() is not None, reason=str(node_missing()))
async def test_the_real_client_with_a_url_token_gets_data_and_is_a_participant(
    served: Served,
) -> None:
    chatter = served.graph.create_publisher("/fa_chatter", "std_msgs/msg/String")
    script = f"""
        import rosmsg from "@foxglove/rosmsg";
        import serialization from "@foxglove/rosmsg2-serialization";
        import wsProtocol from "@foxglove/ws-protocol";
        import WebSocket from "ws";

        const {{ FoxgloveClient }} = wsProtocol;
        // without a token the handshake is refused: ws reports the HTTP status
        const refused = await new Promise((resolve) => {{
          const ws = new WebSocket({json.dumps(served.url)}, {json.dumps(FOXGLOVE)});
          ws.on("unexpected-response", (_, res) => {{ resolve(res.statusCode); ws.terminate(); }});
          ws.on("open", () => resolve("open"));
          ws.on("error", () => {{}});
        }});
        const ws = new WebSocket({json.dumps(with_token(served.url))}, {json.dumps(FOXGLOVE)});
        const client = new FoxgloveClient({{ ws }});
        // both listen from the start: advertise comes right after serverInfo
        const info = new Promise((resolve) => client.on("serverInfo", resolve));
        const channel = await new Promise((resolve) => client.on("advertise", (channels) => {{
          const found = channels.find((c) => c.topic === "/fa_chatter");
          if (found) resolve(found);
        }}));
        const reader = new serialization.MessageReader(
          rosmsg.parse(channel.schema, {{ ros2: true }}));
        const message = new Promise((resolve) => client.on("message", (m) => resolve(m)));
        client.subscribe(channel.id);
        client.advertise({{ topic: "/fa_from_fox", encoding: "json",
                            schemaName: "std_msgs/msg/String" }});
        const got = reader.readMessage((await message).data);
        console.log(JSON.stringify({{ refused, protocol: ws.protocol, name: (await info).name,
                                     data: got.data }}));
        client.close();
    """
    result: dict[str, object] = {}

    async def foxglove_client() -> None:
        result.update(json.loads((await run_node(script)).strip().splitlines()[-1]))

    async with anyio.create_task_group() as tg:
        tg.start_soon(foxglove_client)
        async with await rosbridge(served.url) as ws:
            node, details = await participant_with(ws, "/fa_chatter")
            while "/fa_from_fox" not in details["publishing"]:
                details = await rosapi(ws, "/rosapi/node_details", node=node)
        # the Foxglove client is a participant as a rosbridge client is
        assert node.startswith("/rwt_client_")
        assert details["subscribing"] == ["/fa_chatter"]
        assert details["publishing"] == ["/fa_from_fox"]
        chatter.publish({"data": "hello through the token"})
    assert result == {
        "refused": 401,
        "protocol": "foxglove.sdk.v1",
        "name": result["name"],
        "data": "hello through the token",
    }


@pytest.mark.parametrize("port", ["websocket", "foxglove"])
async def test_a_missing_bad_or_expired_token_is_refused_and_logged(
    served: Served, port: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)
    url = served.url if port == "websocket" else served.foxglove_url
    good = auth_query(token())
    cases = {
        f"{url}/": 401,
        f"{url}/?other=1": 401,
        with_token(url, token(secret="not the secret")): 403,
        with_token(url, token(age_s=120, valid_s=-60)): 403,  # its window ended
        with_token(url, token(age_s=-60)): 403,  # not yet valid
        f"{url}/?{good.replace('&t=', '&t=x')}": 403,  # unreadable
        f"{url}/?{good}&mac=00": 403,  # a field twice
        f"{url}/?{good.replace('&rand=', '&rand=x')}": 403,  # a field changed
    }
    for target, status in cases.items():
        with pytest.raises(InvalidStatus) as refused:
            async with connect(target, subprotocols=FOXGLOVE):
                pass
        assert refused.value.response.status_code == status, target
    text = caplog.text
    # each refusal is logged (rosauth_authenticator's own line, rate-limited, says why)
    assert text.count("event=refused") == len(cases)
    assert text.count("status=401 reason='authentication required") == 2
    assert "a-fresh-random-string" not in text  # the token is not logged


async def test_with_a_token_on_either_port_foxglove_answers(served: Served) -> None:
    for url in (served.url, served.foxglove_url):
        async with connect(with_token(url), subprotocols=FOXGLOVE) as ws:
            assert ws.subprotocol == "foxglove.sdk.v1"
            assert json.loads(await ws.recv())["op"] == "serverInfo"


async def test_rosbridge_clients_still_send_the_auth_op(served: Served) -> None:
    # a URL token admits no rosbridge client: its first op must still be auth
    async with connect(with_token(served.url)) as ws:
        assert ws.subprotocol is None
        await ws.send(json.dumps({"op": "subscribe", "topic": "/client_count"}))
        status = await next_op(ws, "status")
        assert "the first op must be auth" in str(status["msg"])
        with pytest.raises(ConnectionClosed) as closed:
            await ws.recv()
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
    async with await rosbridge(served.url) as ws:
        assert (await rosapi(ws, "/rosapi/get_time"))["time"]


async def test_bind_connection_servers_take_the_url_tokens_own_mac_in_the_url() -> None:
    """With ``--auth-bind-connection`` a URL token is signed as one (``URL_MAC_LABEL``).

    An ``auth`` op signed for a rosbridge connection's challenge, captured and put
    in a Foxglove URL, opens nothing (it did: it could set parameters, advertise and
    call services); a URL token sent as a rosbridge ``auth`` op opens nothing either.
    """
    graph = Graph()
    server = RosbridgeServer(
        graph,
        ServerConfig(port=0, session=SessionConfig(auth_challenge=True)),
        authenticator=rosauth_authenticator(SECRET, graph.clock, bind_connection=True),
    )
    now = time.time()
    fields = {"client": "c", "dest": "d", "t": now, "level": "user", "end": now + 60}
    url_token = Auth(
        mac=bound_mac(SECRET, rand="r", label=URL_MAC_LABEL, **fields), rand="r", **fields
    )  # type: ignore[arg-type]
    plain = Auth(mac=rosauth_mac(SECRET, rand="r", **fields), rand="r", **fields)  # type: ignore[arg-type]
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        # a rosbridge client authenticates with its own challenge
        async with connect(url) as rosbridge:
            challenge = json.loads(await rosbridge.recv())
            assert challenge["id"] == "auth_challenge"
            rand = challenge["msg"]
            signed = Auth(mac=bound_mac(SECRET, rand=rand, **fields), rand=rand, **fields)  # type: ignore[arg-type]
            await rosbridge.send(json.dumps({"op": "auth", **signed.model_dump()}))
            await rosbridge.send(
                json.dumps({"op": "call_service", "service": "/rosapi/topics", "id": "1"})
            )
            assert json.loads(await rosbridge.recv())["result"] is True
        # captured: that op opens no Foxglove connection, nor does rosauth's plain MAC
        for captured in (signed, plain):
            with pytest.raises(InvalidStatus) as refused:
                async with connect(with_token(url, captured), subprotocols=FOXGLOVE):
                    pass
            assert refused.value.response.status_code == 403
        async with connect(with_token(url, url_token), subprotocols=FOXGLOVE) as ws:
            assert json.loads(await ws.recv())["op"] == "serverInfo"
        # the URL token is no auth op (its rand is no challenge, and its MAC is the URL's)
        async with connect(url) as rosbridge:
            rand = json.loads(await rosbridge.recv())["msg"]
            forged = Auth(
                mac=bound_mac(SECRET, rand=rand, label=URL_MAC_LABEL, **fields), rand=rand, **fields
            )  # type: ignore[arg-type]
            await rosbridge.send(json.dumps({"op": "auth", **forged.model_dump()}))
            with pytest.raises(ConnectionClosed):
                while True:
                    await rosbridge.recv()
        tg.cancel_scope.cancel()


def test_a_token_reads_back_as_its_auth_op_and_bad_queries_are_refused() -> None:
    op = rosauth_op(
        SECRET, client="c d", dest="host:9090", rand="r&=?", t=100.9, level="user", end=200.2
    )
    query = auth_query(op)
    assert query.startswith("mac=") and "t=100&" in query and query.endswith("end=200")
    back = auth_from_query(f"ds=foxglove&{query}")  # other parameters are ignored
    assert back is not None
    assert (back.client, back.rand, back.t, back.end) == ("c d", "r&=?", 100, 200)
    assert rosauth_authenticator(SECRET, FixedWall(150.0))(back, "peer")
    assert auth_from_query("") is None and auth_from_query("ds=1") is None
    for bad in (
        query.replace("&level=user", ""),  # a field missing
        query.replace("end=200", "end=inf"),
        "&".join([query, *(f"x{n}=1" for n in range(40))]),  # too many parameters
    ):
        with pytest.raises(RemoteProtocolError):
            auth_from_query(bad)


class FixedWall:
    """A clock whose wall time stands still (only ``wall`` is read by the authenticator)."""

    def __init__(self, wall: float) -> None:
        self._wall = wall

    def wall(self) -> float:
        return self._wall
