"""A Foxglove client is one client of the server, as a rosbridge client is (docs/foxglove.md).

Over real sockets on a real server: it is listed in ``/connected_clients`` and
counted in ``/client_count``; rosapi (and so the console's graph, which reads
``node_details``) names it as a node that subscribes to its subscriptions and
publishes its client channels' topics, until it leaves. It counts against
``--max-connections`` and its host's share (docs/limits.md), and the access globs
(``--topics-glob``, ``--services-glob``, ``--params-glob``) decide what it sees.
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import InvalidStatus

from rwt_graph.graph import Graph
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import RosbridgeServer, ServerConfig

pytestmark = pytest.mark.anyio

FOXGLOVE = ["foxglove.sdk.v1"]
ADD = "example_interfaces/srv/AddTwoInts"


@asynccontextmanager
async def serving(graph: Graph, **config: object) -> AsyncIterator[str]:
    """The server's WebSocket URL while it serves ``graph``."""
    server = RosbridgeServer(graph, ServerConfig(port=0, **config))  # type: ignore[arg-type]
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        try:
            with anyio.fail_after(30):
                yield url
        finally:
            tg.cancel_scope.cancel()


async def next_op(ws: ClientConnection, name: str, **fields: object) -> dict[str, object]:
    """The next text op ``name`` whose fields have these values (others are skipped)."""
    while True:
        frame = await ws.recv()
        if isinstance(frame, bytes):
            continue
        op = json.loads(frame)
        if op["op"] == name and all(op.get(k) == v for k, v in fields.items()):
            return op  # type: ignore[no-any-return]


async def rosapi(ws: ClientConnection, service: str, **args: object) -> dict[str, object]:
    await ws.send(json.dumps({"op": "call_service", "service": service, "args": args}))
    reply = await next_op(ws, "service_response", service=service)
    assert reply["result"] is True, reply
    return reply["values"]  # type: ignore[return-value]


async def channel_id(fox: ClientConnection, topic: str) -> int:
    """The server channel of ``topic``, from the advertisements after serverInfo."""
    while True:
        for channel in (await next_op(fox, "advertise"))["channels"]:  # type: ignore[attr-defined]
            if channel["topic"] == topic:
                return int(channel["id"])


async def barrier(fox: ClientConnection) -> str:
    """Until the server read what ``fox`` sent before; the status it got for the probe."""
    await fox.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [99]}))
    return str((await next_op(fox, "status"))["message"])


async def test_a_foxglove_client_is_listed_counted_and_named_by_rosapi_until_it_leaves() -> None:
    graph = Graph()
    graph.create_publisher("/fp_chatter", "std_msgs/msg/String", node="/talker")
    async with serving(graph) as url, connect(url) as watcher:
        await watcher.send(json.dumps({"op": "subscribe", "topic": "/client_count"}))
        assert (await next_op(watcher, "publish"))["msg"] == {"data": 1}
        async with connect(url, subprotocols=FOXGLOVE) as fox:
            assert (await next_op(fox, "serverInfo"))["name"] == "rwt"
            chatter = await channel_id(fox, "/fp_chatter")
            subscription = {"id": 1, "channelId": chatter}
            await fox.send(json.dumps({"op": "subscribe", "subscriptions": [subscription]}))
            mine = {
                "id": 1,
                "topic": "/fp_from_fox",
                "encoding": "json",
                "schemaName": "std_msgs/String",
            }
            await fox.send(json.dumps({"op": "advertise", "channels": [mine]}))
            assert await barrier(fox) == "unsubscribe: unknown subscription 99"  # nothing else
            assert (await next_op(watcher, "publish", topic="/client_count"))["msg"] == {"data": 2}
            await watcher.send(json.dumps({"op": "subscribe", "topic": "/connected_clients"}))
            listed = await next_op(watcher, "publish", topic="/connected_clients")
            clients = listed["msg"]["clients"]  # type: ignore[index]
            assert [c["ip_address"] for c in clients] == ["127.0.0.1", "127.0.0.1"]
            # rosapi names it by the topics it uses, as the console's graph shows it
            [node] = (await rosapi(watcher, "/rosapi/publishers", topic="/fp_from_fox"))[
                "publishers"
            ]  # type: ignore[misc]
            assert str(node).startswith("/rwt_client_")
            assert node in (await rosapi(watcher, "/rosapi/nodes"))["nodes"]  # type: ignore[operator]
            subscribers = await rosapi(watcher, "/rosapi/subscribers", topic="/fp_chatter")
            assert subscribers == {"subscribers": [node]}
            details = await rosapi(watcher, "/rosapi/node_details", node=node)
            assert details["publishing"] == ["/fp_from_fox"]
            assert details["subscribing"] == ["/fp_chatter"]
            topics = await rosapi(watcher, "/rosapi/topics")
            types = dict(zip(topics["topics"], topics["types"], strict=True))  # type: ignore[call-overload]
            assert types["/fp_from_fox"] == "std_msgs/msg/String"
        # it left: counted out, and its node and topic are gone
        while (await next_op(watcher, "publish", topic="/client_count"))["msg"] != {"data": 1}:
            pass
        assert node not in (await rosapi(watcher, "/rosapi/nodes"))["nodes"]  # type: ignore[operator]
        assert "/fp_from_fox" not in (await rosapi(watcher, "/rosapi/topics"))["topics"]  # type: ignore[operator]
        subscribers = await rosapi(watcher, "/rosapi/subscribers", topic="/fp_chatter")
        assert subscribers == {"subscribers": []}


async def admitted(stack: AsyncExitStack, url: str, source: str, *, foxglove: bool) -> bool:
    """Whether a client from ``source`` gets in (kept open); a refusal must be HTTP 503."""
    try:
        ws = await connect(url, subprotocols=FOXGLOVE if foxglove else None, local_addr=(source, 0))
    except InvalidStatus as refused:
        assert refused.response.status_code == 503
        return False
    stack.push_async_callback(ws.close)
    if foxglove:
        return (await next_op(ws, "serverInfo"))["op"] == "serverInfo"
    await ws.send(json.dumps({"op": "set_level", "level": "info", "id": "in"}))
    return (await next_op(ws, "set_level"))["id"] == "in"


async def test_foxglove_clients_count_against_max_connections_and_host_shares() -> None:
    # 4 slots; past 3 taken, a host holding 1 gets no more (docs/limits.md)
    config = {"max_connections": 4, "max_connections_per_host": 1}
    async with serving(Graph(), **config) as url, AsyncExitStack() as stack:
        hog = [await admitted(stack, url, "127.0.0.1", foxglove=True) for _ in range(4)]
        assert hog == [True, True, True, False]  # its share: refused at the handshake
        assert await admitted(stack, url, "127.0.0.2", foxglove=True)  # the last slot
        # full: neither protocol gets in
        assert not await admitted(stack, url, "127.0.0.3", foxglove=True)
        assert not await admitted(stack, url, "127.0.0.3", foxglove=False)


async def test_access_globs_decide_what_a_foxglove_client_sees_and_uses() -> None:
    graph = Graph()
    graph.create_publisher("/ok/chatter", "std_msgs/msg/String")
    graph.create_publisher("/hidden", "std_msgs/msg/String")
    for name in ("/ok/add", "/hidden_add"):
        graph.create_service(name, ADD, lambda request: {"sum": request["a"] + request["b"]})
    graph.params.declare("/ok_node", {"gain": 2})
    graph.params.declare("/other", {"gain": 3})
    access = AccessPolicy(topics=("/ok/*",), services=("/ok/*",), params=("/ok_node:*",))
    async with (
        serving(graph, session=SessionConfig(access=access)) as url,
        connect(url, subprotocols=FOXGLOVE) as fox,
    ):
        await next_op(fox, "serverInfo")
        channels = (await next_op(fox, "advertise"))["channels"]
        topics = {c["topic"] for c in channels}  # type: ignore[attr-defined]
        assert "/ok/chatter" in topics and "/hidden" not in topics
        services = {s["name"] for s in (await next_op(fox, "advertiseServices"))["services"]}  # type: ignore[attr-defined]
        assert "/ok/add" in services and "/hidden_add" not in services
        await fox.send(json.dumps({"op": "getParameters", "parameterNames": [], "id": "all"}))
        every = await next_op(fox, "parameterValues", id="all")
        assert every["parameters"] == [{"name": "/ok_node.gain", "value": 2}]
        await fox.send(json.dumps({"op": "getParameters", "parameterNames": ["/other.gain"]}))
        assert (await next_op(fox, "status"))["message"] == (
            "getParameters: parameter /other:gain is not allowed"
        )
        theirs = {"id": 1, "topic": "/hidden", "encoding": "json", "schemaName": "std_msgs/String"}
        await fox.send(json.dumps({"op": "advertise", "channels": [theirs]}))
        refused = await next_op(fox, "status")
        assert refused["level"] == 2 and "not allowed" in str(refused["message"]), refused
        await fox.send(json.dumps({"op": "subscribeConnectionGraph"}))
        whole = await next_op(fox, "connectionGraphUpdate")
        published = {t["name"] for t in whole["publishedTopics"]}  # type: ignore[attr-defined]
        assert "/ok/chatter" in published and "/hidden" not in published
        provided = {s["name"] for s in whole["advertisedServices"]}  # type: ignore[attr-defined]
        assert "/ok/add" in provided and "/hidden_add" not in provided
