"""A Foxglove client lives under the server's per-client rules, the same as a rosbridge client.

One connection runtime runs every protocol (docs/architecture.md): ``rwt serve``'s
``--max-subscriptions``, ``--call-timeout``, ``--idle-timeout``, ``--send-timeout``
and ``--send-buffer-limit`` bind a Foxglove client; one that never reads loses its
oldest data and is closed once past its bound; a bug in a handler is reported
and the connection goes on. Real WebSocket clients, a real ``rwt serve``.
"""

from __future__ import annotations

import json
import logging
import struct

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from rwt_foxglove.protocol import ClientAdvertise
from rwt_foxglove.session import FoxgloveSession
from rwt_graph.graph import Graph
from rwt_protocol.server.session import SessionConfig
from tests.foxglove.sansio import cdr
from tests.foxglove.test_hardening import fox, serving
from tests.support.cli import rwt_serve
from tests.support.rawws import masked_text, raw_websocket

pytestmark = pytest.mark.anyio

FOXGLOVE = ["foxglove.sdk.v1"]


async def _op(ws: ClientConnection, name: str) -> dict[str, object]:
    """The next text op ``name`` (binary frames and other ops on the way are skipped)."""
    while True:
        frame = await ws.recv()
        if isinstance(frame, str) and (op := json.loads(frame))["op"] == name:
            return op  # type: ignore[no-any-return]


async def _advertised(
    ws: ClientConnection, topics: set[str], services: set[str]
) -> tuple[dict[str, int], dict[str, int]]:
    """Read ``advertise`` and ``advertiseServices`` until all of these came: ids by name."""
    channel_ids: dict[str, int] = {}
    service_ids: dict[str, int] = {}
    while not (topics <= channel_ids.keys() and services <= service_ids.keys()):
        frame = await ws.recv()
        if not isinstance(frame, str):
            continue
        op = json.loads(frame)
        if op["op"] == "advertise":
            channel_ids.update((each["topic"], each["id"]) for each in op["channels"])
        elif op["op"] == "advertiseServices":
            service_ids.update((each["name"], each["id"]) for each in op["services"])
    return channel_ids, service_ids


async def test_rwt_serve_options_bind_a_foxglove_client() -> None:
    async with rwt_serve(
        "--port=0", "--max-subscriptions=1", "--call-timeout=1", "--idle-timeout=1"
    ) as (_, urls):
        url = urls["ws"]
        async with connect(url) as rosbridge:  # two topics and a service that never answers
            for topic in ("/a", "/b"):
                await rosbridge.send(
                    json.dumps({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String"})
                )
            await rosbridge.send(
                json.dumps(
                    {"op": "advertise_service", "service": "/never", "type": "std_srvs/srv/Trigger"}
                )
            )
            async with (
                connect(url, subprotocols=FOXGLOVE) as client,  # type: ignore[list-item]
                connect(url, subprotocols=FOXGLOVE) as idle,  # type: ignore[list-item]
            ):
                channels, services = await _advertised(client, {"/a", "/b"}, {"/never"})
                subscriptions = [
                    {"id": n, "channelId": channels[topic]} for n, topic in ((1, "/a"), (2, "/b"))
                ]
                await client.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
                status = await _op(client, "status")
                assert status["message"] == (
                    "subscribe: more than 1 subscriptions (--max-subscriptions)"
                )
                request = cdr(Graph(), "std_srvs/srv/Trigger_Request", {})
                header = struct.pack("<BIII", 2, services["/never"], 7, 3)
                await client.send(header + b"cdr" + request)
                failure = await _op(client, "serviceCallFailure")
                assert (failure["callId"], failure["message"]) == (7, "no response within 1 s")
                with pytest.raises(ConnectionClosed) as closed:  # holds nothing, says nothing
                    while True:
                        await idle.recv()
                assert closed.value.rcvd is not None
                assert closed.value.rcvd.reason == "idle: no input for 1 s and nothing held"
                await client.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [1]}))
                await client.send(
                    json.dumps({"op": "subscribe", "subscriptions": subscriptions[1:]})
                )
                await client.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [9]}))
                status = await _op(client, "status")  # the subscribe was taken: no refusal first
                assert status["message"] == "unsubscribe: unknown subscription 9"


async def test_a_foxglove_client_that_never_reads_is_closed_past_its_bound(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    graph = Graph()
    fast = graph.create_publisher("/fast", "std_msgs/msg/String")
    session = SessionConfig(send_buffer_limit=64 * 1024, send_timeout_s=0.5)
    async with serving(graph, session=session) as server:
        stalled = await raw_websocket(server.urls["websocket"], "foxglove.sdk.v1")
        received = b""
        while b'"advertise"' not in received:  # the response, serverInfo, the channels
            received += await stalled.receive()
        channel = json.loads(received[received.index(b'{"op":"advertise"') :].split(b"\x81", 1)[0])
        payload = json.dumps(
            {
                "op": "subscribe",
                "subscriptions": [{"id": 1, "channelId": channel["channels"][0]["id"]}],
            }
        ).encode()
        await stalled.send(masked_text(payload))
        while not graph.topics["/fast"].subscribers:
            await anyio.sleep(0.01)
        async with fox(server) as bystander:  # from here the stalled client reads nothing
            await bystander.subscribe(1, "/fast")
            await bystander.barrier()
            while "closed by server: slow consumer" not in caplog.text:
                fast.publish({"data": "x" * 1000})
                assert len(await bystander.data_frames(1)) == 1  # served all along
        await stalled.aclose()
    assert "event=slow_consumer" in caplog.text and "protocol=foxglove" in caplog.text


async def test_a_bug_in_a_handler_is_reported_and_the_session_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    def broken(op: object) -> None:
        raise ZeroDivisionError  # a bug in the server, not the client's fault

    graph = Graph()
    graph.create_publisher("/a", "std_msgs/msg/String")
    async with serving(graph) as server, fox(server) as client:
        session = next(iter(server.sessions.values()))
        assert isinstance(session, FoxgloveSession)
        session._handlers[ClientAdvertise] = broken
        for _ in range(2):
            await client.ws.send(json.dumps({"op": "advertise", "channels": []}))
            assert (await client.status())["message"] == "internal error"
        await client.subscribe(1, "/a")  # the connection goes on
        await client.barrier()
    assert caplog.text.count("bug while handling") == 1  # once per connection, with a traceback
