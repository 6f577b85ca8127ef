"""A rosbridge session over the ``rosbridge`` data channel, from a real WebRTC stack (aiortc).

The same ops, limits and fragments as a WebSocket connection (docs/webrtc.md).
"""

from __future__ import annotations

import json

import anyio
import cbor2
import httpx
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

import anyio.lowlevel

from rwt_graph.graph import Graph
from rwt_transports.server import RosbridgeServer, ServerConfig
from rwt_transports.webrtc.channel import MAX_TEXT_FRAME_BYTES, SEND_HIGH_WATER_BYTES
from rwt_transports.webrtc.sctp import ANSWER_MAX_MESSAGE_SIZE
from rwt_transports.webrtc.signalling import WebRtcOptions
from tests.webrtc.peer import RtcClient, Served, peers_of, rtc_client, serving

pytestmark = pytest.mark.anyio


async def test_json_subscribe_publish_and_call_service(served_on: Served) -> None:
    received: list[object] = []
    served_on.graph.create_subscription("/from_browser", received.append, "std_msgs/msg/String")
    robot = served_on.graph.create_publisher("/from_robot", "std_msgs/msg/String", node="/robot")
    async with rtc_client(served_on.base) as client:
        client.send({"op": "subscribe", "topic": "/from_robot", "type": "std_msgs/String"})
        client.send({"op": "call_service", "service": "/rosapi/topics", "id": "c1"})
        reply = await client.next_op("service_response")
        assert reply["id"] == "c1" and reply["result"] is True
        assert "/from_robot" in reply["values"]["topics"]  # type: ignore[index]
        robot.publish({"data": "hello"})
        message = await client.next_op("publish")
        assert message["topic"] == "/from_robot" and message["msg"] == {"data": "hello"}
        client.send({"op": "advertise", "topic": "/from_browser", "type": "std_msgs/String"})
        client.send({"op": "publish", "topic": "/from_browser", "msg": {"data": "hi"}})
        with anyio.fail_after(10):
            while not received:
                await anyio.sleep(0.02)
    assert [dict(m) for m in received] == [{"data": "hi"}]  # type: ignore[call-overload]


async def test_cbor_in_and_out(served_on: Served) -> None:
    robot = served_on.graph.create_publisher("/count", "std_msgs/msg/Int32", node="/robot")
    async with rtc_client(served_on.base) as client:
        client.send(
            {"op": "subscribe", "topic": "/count", "type": "std_msgs/Int32", "compression": "cbor"},
            cbor=True,
        )
        client.send({"op": "call_service", "service": "/rosapi/topics", "id": "c"}, cbor=True)
        await client.next_op("service_response")
        robot.publish({"data": 42})
        raw = await _next_raw(client)
        assert isinstance(raw, bytes)  # CBOR goes as a binary message
        assert cbor2.loads(raw) == {"op": "publish", "topic": "/count", "msg": {"data": 42}}


async def _next_fragment_text(client: RtcClient) -> str:
    """The ``data`` of the next message that came in ``fragment`` ops, reassembled."""
    parts: dict[int, str] = {}
    while True:
        part = json.loads(await client.receive())
        if part["op"] != "fragment":
            continue
        parts[part["num"]] = part["data"]
        if len(parts) == part["total"]:
            whole = json.loads("".join(parts[i] for i in range(part["total"])))
            return str(whole["msg"]["data"])


async def _next_raw(client: RtcClient) -> str | bytes:
    while True:
        raw = await client.receive()
        if isinstance(raw, bytes):
            return raw


async def test_a_message_above_64_kib_arrives_whole_through_fragments(served_on: Served) -> None:
    robot = served_on.graph.create_publisher("/big", "std_msgs/msg/String", node="/robot")
    text = "".join(chr(0x41 + i % 26) for i in range(200_000)) + '"\\é'
    async with rtc_client(served_on.base) as client:
        client.send({"op": "subscribe", "topic": "/big", "type": "std_msgs/String"})
        client.send({"op": "call_service", "service": "/rosapi/topics", "id": "c"})
        await client.next_op("service_response")
        robot.publish({"data": text})
        parts: dict[int, str] = {}
        total = None
        while total is None or len(parts) < total:
            raw = await client.receive()
            assert isinstance(raw, str) and len(raw.encode()) <= 64 * 1024
            part = json.loads(raw)
            assert part["op"] == "fragment"
            parts[part["num"]] = part["data"]
            total = part["total"]
    assert total > 1
    whole = json.loads("".join(parts[i] for i in range(total)))
    assert whole["op"] == "publish" and whole["msg"] == {"data": text}


async def test_the_session_counts_in_connected_clients_and_delete_ends_it(
    served_on: Served,
) -> None:
    async with rtc_client(served_on.base) as client:
        client.send({"op": "subscribe", "topic": "/client_count"})
        assert (await client.next_op("publish"))["msg"] == {"data": 1}
        client.send({"op": "subscribe", "topic": "/connected_clients"})
        clients = (await client.next_op("publish"))["msg"]["clients"]  # type: ignore[index]
        assert [c["ip_address"] for c in clients] == ["127.0.0.1"]
        assert [cid.split(":")[0] for cid in served_on.server.sessions] == ["webrtc"]
        async with httpx.AsyncClient(base_url=served_on.base) as http:
            assert (await http.delete(client.location)).status_code == 204
            with anyio.fail_after(10):
                await client.closed.wait()  # the server closed the data channel
                while served_on.server.sessions:
                    await anyio.sleep(0.02)
            assert (await http.delete(client.location)).status_code == 404


async def test_closing_the_peer_connection_frees_the_session(served: Served) -> None:
    async with rtc_client(served.base) as client:
        client.send({"op": "subscribe", "topic": "/client_count"})
        await client.next_op("publish")
        assert len(served.server.sessions) == 1
        await client.pc.close()
        with anyio.fail_after(15):
            while served.server.sessions:
                await anyio.sleep(0.05)
    assert not peers_of(served.server).peers


async def test_an_idle_session_is_closed_as_on_other_transports(stack: str) -> None:
    config = ServerConfig(port=0, idle_timeout_s=0.5, webrtc=WebRtcOptions(stack=stack))
    async with serving(config) as running, rtc_client(running.base) as client:
        client.send({"op": "set_level", "level": "info", "id": "hello"})
        await client.next_op("status")
        with anyio.fail_after(15):  # the idle timeout is 0.5 s: this bounds a hang only
            await client.closed.wait()  # nothing held, nothing sent: the server closed it
            while running.server.sessions:
                await anyio.sleep(0.05)
        assert not peers_of(running.server).peers


async def test_stopping_the_server_closes_webrtc_sessions(stack: str) -> None:
    graph = Graph()
    server = RosbridgeServer(graph, ServerConfig(port=0, webrtc=WebRtcOptions(stack=stack)))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        async with rtc_client(url.replace("ws://", "http://")) as client:
            client.send({"op": "subscribe", "topic": "/client_count"})
            await client.next_op("publish")
            server.stop()
            with anyio.fail_after(15):
                await client.closed.wait()
    assert not server.sessions and not peers_of(server).peers


async def test_the_data_channel_buffer_is_flow_controlled(served_on: Served) -> None:
    """A burst far above the channel's buffer waits in the session, not in SCTP's queue."""
    robot = served_on.graph.create_publisher("/burst", "std_msgs/msg/String", node="/robot")
    payload = "y" * 100_000
    count = 100  # 10 MB of JSON: ten times the buffer's high-water mark
    async with rtc_client(served_on.base) as client:
        client.send({"op": "subscribe", "topic": "/burst", "type": "std_msgs/String"})
        client.send({"op": "call_service", "service": "/rosapi/topics", "id": "c"})
        await client.next_op("service_response")
        (peer,) = peers_of(served_on.server).peers.values()
        channel = peer.channel
        assert channel is not None
        highest = 0
        done = anyio.Event()

        async def watch() -> None:
            nonlocal highest
            while not done.is_set():
                highest = max(highest, channel.bufferedAmount)
                await anyio.lowlevel.checkpoint()

        async with anyio.create_task_group() as tg:
            tg.start_soon(watch)
            for i in range(count):
                robot.publish({"data": f"{i:03d}{payload}"})
                await anyio.lowlevel.checkpoint()
            last = f"{count - 1:03d}"  # dropping is oldest first: the last one comes
            with anyio.fail_after(60):
                while not (await _next_fragment_text(client)).startswith(last):
                    pass
            done.set()
    assert highest > 0  # the channel did buffer: the bound below was tested
    assert highest <= SEND_HIGH_WATER_BYTES + MAX_TEXT_FRAME_BYTES


async def test_a_message_over_max_message_size_is_skipped_with_a_status(stack: str) -> None:
    config = ServerConfig(port=0, max_message_size=1000, webrtc=WebRtcOptions(stack=stack))
    async with serving(config) as running, rtc_client(running.base) as client:
        client.send({"op": "set_level", "level": "info", "id": "x" * 2000})
        status = await client.next_op("status")
        assert status["level"] == "error"
        assert status["msg"] == "message larger than 1000 bytes skipped"
        client.send({"op": "set_level", "level": "info", "id": "after"})  # the session goes on
        assert (await client.next_op("status"))["id"] == "after"


async def test_a_message_over_the_answers_size_is_refused_whole_on_each_stack(
    served_on: Served,
) -> None:
    # libdatachannel cut such a message at the answer's size and handed the start on as
    # the whole message: JSON padded with spaces, its start a whole op, was executed
    received: list[object] = []
    served_on.graph.create_subscription("/cmd", received.append, "std_msgs/msg/String")
    async with rtc_client(served_on.base) as client:
        sctp = client.pc.sctp
        assert sctp is not None
        limit = sctp._remote_max_message_size  # the answer's a=max-message-size
        assert limit == ANSWER_MAX_MESSAGE_SIZE
        sctp._remote_max_message_size = 0  # no bound: aiortc's own refuses to send more
        client.send({"op": "advertise", "topic": "/cmd", "type": "std_msgs/String"})
        over = json.dumps({"op": "publish", "topic": "/cmd", "msg": {"data": "cut"}})
        client.channel.send(over + " " * (limit + 1 - len(over)))  # one byte over
        status = await client.next_op("status")
        assert status["level"] == "error"
        assert status["msg"] == f"message larger than {limit} bytes skipped"
        at_limit = json.dumps({"op": "publish", "topic": "/cmd", "msg": {"data": "whole"}})
        client.channel.send(at_limit + " " * (limit - len(at_limit)))  # the largest taken
        client.send({"op": "publish", "topic": "/cmd", "msg": {"data": "after"}})
        with anyio.fail_after(10):
            while len(received) < 2:
                await anyio.sleep(0.02)
    assert [dict(m) for m in received] == [{"data": "whole"}, {"data": "after"}]  # type: ignore[call-overload]
