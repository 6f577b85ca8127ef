"""One transport contract, run over memory, WebSocket, TCP, UDP, stdio and WebRTC (D22).

Every scenario pairs a client of the transport under test with an in-process
(memory) client of the same server: they share one graph, so each scenario is
also a cross-transport test.
"""

from __future__ import annotations

import json
import random
from collections.abc import AsyncIterator

import anyio
import cbor2
import pytest
from websockets.exceptions import ConnectionClosed

from rwt_protocol.framing.streams import JsonStreamFramer
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.runtime.inframes import FramerEvent, InFrame
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from rwt_transports.webrtc.stacks import stack_refusal
from tests.support.clients import (
    CONTRACT_TRANSPORTS,
    HAS_AIORTC,
    NATIVE_WEBRTC,
    REACTOR_WEBRTC,
    Client,
    Harness,
    StreamClient,
    is_op,
    running_server,
)

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10


PAIRED = (
    (*CONTRACT_TRANSPORTS, NATIVE_WEBRTC, REACTOR_WEBRTC) if HAS_AIORTC else CONTRACT_TRANSPORTS
)
"""``pair``'s transports: WebRTC on each stack (D51, D70)."""

_STACKS = {NATIVE_WEBRTC: "native", REACTOR_WEBRTC: "reactor"}


@pytest.fixture
async def harness(request: pytest.FixtureRequest) -> AsyncIterator[Harness]:
    """The server; on the native (reactor) WebRTC stack for ``pair``'s ``webrtc-native``
    (``webrtc-reactor``)."""
    callspec = getattr(request.node, "callspec", None)
    stack = _STACKS.get(callspec.params.get("pair") if callspec is not None else None, "aiortc")
    if (missing := stack_refusal(stack)) is not None:
        pytest.skip(missing)
    async with running_server(webrtc_stack=stack) as h:
        yield h


@pytest.fixture(params=PAIRED)
async def pair(request: pytest.FixtureRequest, harness: Harness) -> tuple[Client, Client]:
    client = await harness.connect(request.param)
    other = await harness.connect("memory", "other")
    return client, other


async def test_subscriber_receives_what_another_transport_publishes(
    pair: tuple[Client, Client],
) -> None:
    client, other = pair
    with anyio.fail_after(TIMEOUT_S):
        await client.send({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/String"})
        await client.send({"op": "set_level", "level": "info", "id": "barrier"})
        await client.expect(is_op("status", id="barrier"))
        await other.send({"op": "advertise", "topic": "/chatter", "type": "std_msgs/String"})
        await other.send({"op": "publish", "topic": "/chatter", "msg": {"data": "hello"}})
        message = await client.expect(is_op("publish"))
    assert message == {"op": "publish", "topic": "/chatter", "msg": {"data": "hello"}}


async def test_publisher_reaches_a_subscriber_on_another_transport(
    pair: tuple[Client, Client],
) -> None:
    client, other = pair
    with anyio.fail_after(TIMEOUT_S):
        await other.send({"op": "subscribe", "topic": "/up", "type": "std_msgs/Int32"})
        await other.send({"op": "set_level", "level": "info", "id": "barrier"})
        await other.expect(is_op("status", id="barrier"))
        await client.send({"op": "publish", "topic": "up", "msg": {"data": 42}})
        message = await other.expect(is_op("publish"))
    assert message["msg"] == {"data": 42}


async def test_service_round_trip_across_transports(pair: tuple[Client, Client]) -> None:
    client, other = pair
    with anyio.fail_after(TIMEOUT_S):
        await client.send(
            {"op": "advertise_service", "service": "/set", "type": "std_srvs/SetBool"}
        )
        await client.send({"op": "set_level", "level": "info", "id": "barrier"})
        await client.expect(is_op("status", id="barrier"))
        await other.send(
            {"op": "call_service", "service": "/set", "args": {"data": True}, "id": "c1"}
        )
        request = await client.expect(is_op("call_service"))
        assert request["args"] == {"data": True}
        await client.send(
            {
                "op": "service_response",
                "service": "/set",
                "id": request["id"],
                "values": {"success": True, "message": "done"},
                "result": True,
            }
        )
        response = await other.expect(is_op("service_response"))
    assert response == {
        "op": "service_response",
        "service": "/set",
        "values": {"success": True, "message": "done"},
        "result": True,
        "id": "c1",
    }


async def test_client_calls_an_in_process_service(
    pair: tuple[Client, Client], harness: Harness
) -> None:
    client, _ = pair
    harness.server.graph.create_service(
        "/add", "example_interfaces/srv/AddTwoInts", lambda r: {"sum": r["a"] + r["b"]}
    )
    with anyio.fail_after(TIMEOUT_S):
        await client.send({"op": "call_service", "service": "add", "args": [2, 40], "id": 9})
        response = await client.expect(is_op("service_response"))
    assert response["values"] == {"sum": 42} and response["id"] == 9


async def test_a_large_message_arrives_whole(pair: tuple[Client, Client]) -> None:
    # UDP sends it as fragment ops (datagram limit); the client reassembles them.
    client, other = pair
    text = 'é{}"\\x' * 6000
    with anyio.fail_after(TIMEOUT_S):
        await client.send({"op": "subscribe", "topic": "/big", "type": "std_msgs/String"})
        await client.send({"op": "set_level", "level": "info", "id": "barrier"})
        await client.expect(is_op("status", id="barrier"))
        await other.send({"op": "publish", "topic": "/big", "msg": {"data": text}})
        message = await client.expect(is_op("publish"))
    assert message["msg"]["data"] == text


async def test_a_message_sent_in_fragments_is_reassembled(pair: tuple[Client, Client]) -> None:
    client, other = pair
    whole = json.dumps({"op": "publish", "topic": "/frag", "msg": {"data": "pieces"}})
    pieces = [whole[i : i + 10] for i in range(0, len(whole), 10)]
    with anyio.fail_after(TIMEOUT_S):
        await other.send({"op": "subscribe", "topic": "/frag", "type": "std_msgs/String"})
        await other.send({"op": "set_level", "level": "info", "id": "barrier"})
        await other.expect(is_op("status", id="barrier"))
        await client.send({"op": "advertise", "topic": "/frag", "type": "std_msgs/String"})
        for num, data in enumerate(pieces):
            await client.send(
                {"op": "fragment", "id": "f1", "data": data, "num": num, "total": len(pieces)}
            )
        message = await other.expect(is_op("publish"))
    assert message["msg"] == {"data": "pieces"}


@pytest.mark.parametrize(
    "frame",
    [b"not json", b"5", b'{"op":"nope","id":"x"}', b'{"op":["publish"]}', b"}"],
    ids=["invalid-json", "number", "unknown-op", "unhashable-op", "stray-brace"],
)
async def test_bad_frames_get_an_error_status_and_the_connection_keeps_serving(
    pair: tuple[Client, Client], frame: bytes
) -> None:
    client, _ = pair
    with anyio.fail_after(TIMEOUT_S):
        await client.send_raw(frame + b"\n")
        status = await client.expect(is_op("status"))
        assert status["level"] == "error"
        await client.send({"op": "set_level", "level": "info", "id": "after"})
        after = await client.expect(is_op("status", id="after"))
    assert after["level"] == "info"


async def test_random_bytes_never_break_the_server(
    pair: tuple[Client, Client], harness: Harness
) -> None:
    """Only status frames or a clean close for the sender; nothing for anyone else."""
    client, other = pair
    rng = random.Random(5)
    garbage = [rng.randbytes(rng.randrange(1, 600)) for _ in range(30)]
    garbage += [b'{"op":"publish","topic":', b'"\\', b"[[[[", b"\x00" * 50, b"\n"]
    with anyio.fail_after(TIMEOUT_S):
        for chunk in garbage:
            await client.send_raw(chunk)
        await client.send({"op": "set_level", "level": "info", "id": "me"})
        if isinstance(client, StreamClient) and client.name == "tcp":
            # Random bytes may open a CBOR item that claims megabytes: only the end of
            # the stream (or max_message_size) ends it. Everything before is a status.
            assert client.stream is not None
            await client.stream.send_eof()
        try:
            while (message := await client.receive()).get("id") != "me":
                assert message["op"] == "status" and message["level"] == "error", message
        except (anyio.EndOfStream, anyio.BrokenResourceError, ConnectionClosed):
            pass  # a clean close
        await other.send({"op": "set_level", "level": "info", "id": "fine"})
        assert (await other.expect(is_op("status", id="fine")))["level"] == "info"
        fresh = await harness.connect("ws", "fresh")
        await fresh.send({"op": "set_level", "level": "info", "id": "new"})
        assert (await fresh.expect(is_op("status", id="new")))["level"] == "info"


async def test_access_rules_apply_on_every_transport() -> None:
    policy = AccessPolicy(topics=("/public/*",), services=("/public/*",))
    config = ServerConfig(session=SessionConfig(access=policy))
    async with running_server(config) as harness:
        for transport in CONTRACT_TRANSPORTS:
            client = await harness.connect(transport)
            with anyio.fail_after(TIMEOUT_S):
                await client.send({"op": "subscribe", "topic": "/secret", "id": "s"})
                status = await client.expect(is_op("status", id="s"))
                assert status["msg"] == "subscribe: topic /secret is not allowed on this server"
                await client.send({"op": "call_service", "service": "/secret", "id": "c"})
                reply = await client.expect(is_op("service_response", id="c"))
                assert reply["result"] is False
        assert "/secret" not in harness.server.graph.topics


async def test_tcp_carries_cbor_both_ways(harness: Harness) -> None:
    """CBOR maps in, told apart from JSON by their first byte; CBOR items out (D21, D22)."""
    stream = await anyio.connect_tcp("127.0.0.1", harness.port("tcp"))
    framer = JsonStreamFramer(1 << 20)
    events: list[FramerEvent] = []
    async with stream:
        with anyio.fail_after(TIMEOUT_S):
            await stream.send(
                cbor2.dumps(
                    {
                        "op": "subscribe",
                        "topic": "/c",
                        "type": "std_msgs/String",
                        "compression": "cbor",
                    }
                )
                + b'{"op":"advertise","topic":"/c","type":"std_msgs/String"}'
                + cbor2.dumps({"op": "publish", "topic": "/c", "msg": {"data": "binary"}})
                + b'\n{"op":"set_level","level":"info","id":"done"}\n'
            )
            while not any(isinstance(e, InFrame) and b'"done"' in e.data for e in events):
                events += framer.receive_data(await stream.receive())
    frames = [e for e in events if isinstance(e, InFrame)]
    [cbor_frame] = [f for f in frames if f.binary]
    assert cbor2.loads(cbor_frame.data) == {
        "op": "publish",
        "topic": "/c",
        "msg": {"data": "binary"},
    }
    assert all(json.loads(f.data)["op"] == "status" for f in frames if not f.binary)


async def test_rosapi_lists_only_what_the_access_rules_allow() -> None:
    policy = AccessPolicy(topics=("/public/*",))
    async with running_server(ServerConfig(session=SessionConfig(access=policy))) as harness:
        graph = harness.server.graph
        graph.create_publisher("/public/chat", "std_msgs/msg/String")
        graph.create_publisher("/secret/plans", "std_msgs/msg/String")
        client = await harness.connect("ws")
        with anyio.fail_after(TIMEOUT_S):
            await client.send({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
            reply = await client.expect(is_op("service_response", id="t"))
    assert reply["result"] is True
    assert "/public/chat" in reply["values"]["topics"]
    assert "/secret/plans" not in reply["values"]["topics"]
