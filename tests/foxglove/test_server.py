"""Foxglove and rosbridge on one server: the subprotocol in the handshake picks the protocol."""

from __future__ import annotations

import json
import ssl
import struct
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import pytest
import trustme
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import InvalidStatus

from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.foxglove import FoxgloveOptions
from rwt_transports.server import RosbridgeServer, ServerConfig

pytestmark = pytest.mark.anyio


@asynccontextmanager
async def serving(graph: Graph, **config: object) -> AsyncIterator[RosbridgeServer]:
    server = RosbridgeServer(graph, ServerConfig(port=0, **config))
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        try:
            with anyio.fail_after(20):
                yield server
        finally:
            tg.cancel_scope.cancel()


async def _op(ws: ClientConnection, name: str) -> dict[str, object]:
    while True:
        frame = await ws.recv()
        if isinstance(frame, str) and json.loads(frame)["op"] == name:
            return json.loads(frame)


@pytest.mark.parametrize(
    ("offered", "selected"),
    [
        (["foxglove.sdk.v1"], "foxglove.sdk.v1"),
        (["foxglove.websocket.v1"], "foxglove.websocket.v1"),
        (["foxglove.websocket.v1", "foxglove.sdk.v1"], "foxglove.websocket.v1"),
    ],
)
async def test_each_subprotocol_name_gets_foxglove(
    ros2_types: TypeRegistry, offered: list[str], selected: str
) -> None:
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    async with (
        serving(graph) as server,
        connect(server.urls["websocket"], subprotocols=offered) as ws,
    ):
        assert ws.subprotocol == selected
        info = json.loads(await ws.recv())
        assert info["op"] == "serverInfo"
        channel = next(
            c for c in (await _op(ws, "advertise"))["channels"] if c["topic"] == "/chatter"
        )
        await ws.send(
            json.dumps(
                {"op": "subscribe", "subscriptions": [{"id": 4, "channelId": channel["id"]}]}
            )
        )
        await ws.send(json.dumps({"op": "nope"}))
        assert "unknown op" in str((await _op(ws, "status"))["message"])
        publisher.publish({"data": "hello"})
        frame = await ws.recv()
        assert isinstance(frame, bytes) and frame[0] == 1
        assert struct.unpack_from("<I", frame, 1) == (4,)
        assert frame[13:].endswith(b"hello\x00")


async def test_a_foxglove_clients_first_input_lets_the_others_go_on(
    ros2_types: TypeRegistry,
) -> None:
    """A new connection's first input goes before what the others get later (docs/limits.md);
    once a Foxglove client's first input is handled, no reader waits for it any more.

    It held its "starting" ticket, unwatched, until it closed, so every other
    connection's input waited up to half a second after each Foxglove client came.
    """
    graph = Graph(ros2_types)
    graph.create_publisher("/chatter", "std_msgs/msg/String")
    async with (
        serving(graph) as server,
        connect(server.urls["websocket"], subprotocols=["foxglove.sdk.v1"]) as ws,
    ):
        channel = next(
            c for c in (await _op(ws, "advertise"))["channels"] if c["topic"] == "/chatter"
        )
        await ws.send(
            json.dumps(
                {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]}
            )
        )
        await ws.send(json.dumps({"op": "nope"}))  # answered once the subscribe was handled
        assert "unknown op" in str((await _op(ws, "status"))["message"])
        assert not server.admission.starting()


async def test_rosbridge_clients_are_unaffected(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    async with serving(graph) as server:
        for subprotocols in (None, ["chat"]):
            async with connect(server.urls["websocket"], subprotocols=subprotocols) as ws:
                assert ws.subprotocol is None
                await ws.send(json.dumps({"op": "nope"}))
                reply = json.loads(await ws.recv())
                assert reply["op"] == "status" and reply["level"] == "error"


async def test_no_foxglove_gives_rosbridge_to_everyone(ros2_types: TypeRegistry) -> None:
    off = FoxgloveOptions(on_rosbridge_port=False)
    async with (
        serving(Graph(ros2_types), foxglove=off) as server,
        connect(server.urls["websocket"], subprotocols=["foxglove.sdk.v1"]) as ws,
    ):
        assert ws.subprotocol is None
        await ws.send(json.dumps({"op": "nope"}))
        assert json.loads(await ws.recv())["op"] == "status"


async def test_the_foxglove_port_speaks_foxglove_only(ros2_types: TypeRegistry) -> None:
    async with serving(Graph(ros2_types), foxglove=FoxgloveOptions(port=0)) as server:
        url = server.urls["foxglove"]
        async with connect(url, subprotocols=["foxglove.websocket.v1"]) as ws:
            assert json.loads(await ws.recv())["op"] == "serverInfo"
        with pytest.raises(InvalidStatus) as refused:
            async with connect(url):
                pass
        assert refused.value.response.status_code == 400


async def test_access_globs_and_auth(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    graph.create_publisher("/ok/a", "std_msgs/msg/String")
    graph.create_publisher("/hidden", "std_msgs/msg/String")
    session = SessionConfig(access=AccessPolicy(topics=("/ok/*",)))
    async with (
        serving(graph, session=session) as server,
        connect(server.urls["websocket"], subprotocols=["foxglove.sdk.v1"]) as ws,
    ):
        topics = {c["topic"] for c in (await _op(ws, "advertise"))["channels"]}
        assert "/ok/a" in topics and "/hidden" not in topics
    # an authenticator asks a Foxglove client for the token in its URL (tests/foxglove/test_auth.py)
    seen: list[str] = []
    required = SessionConfig(authenticator=lambda op, peer: seen.append(op.level) or True)
    async with serving(Graph(ros2_types), session=required) as server:
        url = server.urls["websocket"]
        with pytest.raises(InvalidStatus) as refused:
            async with connect(url, subprotocols=["foxglove.sdk.v1"]):
                pass
        assert refused.value.response.status_code == 401
        token = "mac=ab&client=c&dest=d&rand=r&t=1&level=viewer&end=2"
        async with connect(f"{url}/?{token}", subprotocols=["foxglove.sdk.v1"]) as ws:
            assert (await _op(ws, "serverInfo"))["op"] == "serverInfo"
        assert seen == ["viewer"]  # the authenticator decided, with the URL's fields


async def test_foxglove_over_tls_on_the_same_port(
    ros2_types: TypeRegistry, tls_files: tuple[Path, Path, Path], ca: trustme.CA
) -> None:
    """With ``--certfile``, a Foxglove client on ``wss://`` gets Foxglove, and its data."""
    certfile, keyfile, _ = tls_files
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    context = ssl.create_default_context()
    ca.configure_trust(context)
    async with serving(graph, certfile=certfile, keyfile=keyfile) as server:
        url = server.urls["websocket"]
        assert url.startswith("wss://")
        async with connect(url, subprotocols=["foxglove.sdk.v1"], ssl=context) as ws:
            assert ws.subprotocol == "foxglove.sdk.v1"
            assert json.loads(await ws.recv())["op"] == "serverInfo"
            channels = (await _op(ws, "advertise"))["channels"]
            channel = next(c for c in channels if c["topic"] == "/chatter")  # type: ignore[union-attr]
            subscription = {"id": 1, "channelId": channel["id"]}
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))
            await ws.send(json.dumps({"op": "nope"}))  # answered after the subscribe is done
            await _op(ws, "status")
            publisher.publish({"data": "over tls"})
            frame = await ws.recv()
            assert isinstance(frame, bytes) and frame[13:].endswith(b"over tls\x00")
