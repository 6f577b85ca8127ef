"""rosbridge_suite's newer WebSocket tests (REF §13.9: W16-W18, W20-W22), in their intent, on rwt.

Each runs against an in-process server (``running_server``) with WebSocket clients
(websockets', or raw sockets where a client must vanish without a close); the graph's
in-process publishers, services and action servers play the reference's ROS nodes.
The scenarios whose intent rwt already tests elsewhere are listed with those tests in
docs/reference-behaviour.md §13.9. Sizes are smaller than upstream's, to keep the
suite quick; each scenario keeps its shape.
"""

from __future__ import annotations

import json
import socket
import struct
from collections.abc import AsyncIterator

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from rwt_graph.actions import GoalContext
from rwt_graph.graph import Graph
from rwt_transports.server import ServerConfig
from tests.support.clients import Client, Harness, Message, WsClient, is_op, running_server
from tests.support.rawws import masked_text

pytestmark = pytest.mark.anyio

FIB = "example_interfaces/action/Fibonacci"


@pytest.fixture
async def served() -> AsyncIterator[tuple[Graph, Harness]]:
    graph = Graph()
    async with running_server(graph=graph) as harness:
        yield graph, harness


async def ws_client(harness: Harness, name: str) -> WsClient:
    client = await harness.connect("ws", name)
    assert isinstance(client, WsClient)
    return client


async def call(client: Client, service: str, call_id: str, **fields: object) -> Message:
    await client.send({"op": "call_service", "service": service, "id": call_id, **fields})
    return await client.expect(is_op("service_response", id=call_id))


async def topics_named(client: Client, prefix: str) -> list[str]:
    reply = await call(client, "/rosapi/topics", f"topics-{prefix}")
    assert reply["result"] is True
    return [name for name in reply["values"]["topics"] if name.startswith(prefix)]


async def wait_until_no_topics(client: Client, prefix: str) -> None:
    """Ask rosapi until no topic starts with ``prefix`` (disconnects are handled in turn)."""
    while await topics_named(client, prefix):
        await anyio.sleep(0.02)


async def own_round_trip(client: Client, topic: str) -> None:
    """The client advertises, subscribes to and publishes on ``topic``; its message returns."""
    await client.send({"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await client.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    await client.send({"op": "publish", "topic": topic, "msg": {"data": "still here"}})
    message = await client.expect(is_op("publish", topic=topic))
    assert message["msg"] == {"data": "still here"}


async def registered_client(harness: Harness, name: str, each: int) -> WsClient:
    """A client with ``each`` subscriptions and ``each`` advertisements, all handled."""
    client = await ws_client(harness, name)
    for j in range(each):
        await client.send(
            {"op": "subscribe", "topic": f"/stress/{name}/s{j}", "type": "std_msgs/String"}
        )
        await client.send(
            {"op": "advertise", "topic": f"/stress/{name}/a{j}", "type": "std_msgs/String"}
        )
    await call(client, "/rosapi/get_time", f"{name}-ready")  # answered after the ops before it
    assert not [m for m in client.backlog if m.get("op") == "status"]  # no op refused
    return client


async def test_many_clients_with_many_registrations_leaving_together_leave_it_serving(
    served: tuple[Graph, Harness],
) -> None:
    """rosbridge_suite's stress-clients test (REF §13.9, W16).

    Thirty clients with twenty subscriptions and twenty advertisements each leave at
    one instant; then clients are made and dropped in quick succession, and in
    overlapping waves. Afterwards none of their topics is left, and a new client is
    served as usual.
    """
    _, harness = served
    with anyio.fail_after(30):
        clients = [await registered_client(harness, f"c{i}", 20) for i in range(30)]
        assert len(await topics_named(clients[0], "/stress/")) == 30 * 40
        async with anyio.create_task_group() as tg:
            for client in clients:
                tg.start_soon(client.aclose)
        for i in range(50):  # quick create-and-drop cycles, no reply awaited
            client = await ws_client(harness, f"q{i}")
            await client.send(
                {"op": "subscribe", "topic": f"/stress/q{i}", "type": "std_msgs/String"}
            )
            await client.send(
                {"op": "advertise", "topic": f"/stress/q{i}/a", "type": "std_msgs/String"}
            )
            await client.aclose()

        async def wave(w: int) -> None:
            members = [await registered_client(harness, f"w{w}_{k}", 2) for k in range(10)]
            for member in members:
                await member.aclose()

        async with anyio.create_task_group() as tg:  # overlapping waves
            for w in range(5):
                tg.start_soon(wave, w)
        fresh = await ws_client(harness, "fresh")
        await wait_until_no_topics(fresh, "/stress/")
        await own_round_trip(fresh, "/after_stress")


async def test_calls_sent_right_after_connecting_are_all_answered(
    served: tuple[Graph, Harness],
) -> None:
    """rosbridge_suite's start-up race test (REF §13.9, W17).

    Five clients connect at once and each sends three calls the moment its
    connection is open, before reading anything: all fifteen are answered, true.
    """
    _, harness = served
    replies: list[Message] = []

    async def eager(i: int) -> None:
        client = await ws_client(harness, f"e{i}")
        for k in range(3):
            await client.send(
                {"op": "call_service", "service": "/rosapi/get_time", "id": f"e{i}-{k}"}
            )
        for k in range(3):
            replies.append(await client.expect(is_op("service_response", id=f"e{i}-{k}")))

    with anyio.fail_after(20):
        async with anyio.create_task_group() as tg:
            for i in range(5):
                tg.start_soon(eager, i)
    assert len(replies) == 15
    assert all(reply["result"] is True for reply in replies)


async def test_a_new_client_is_served_while_large_messages_stream_to_another(
    served: tuple[Graph, Harness],
) -> None:
    """rosbridge_suite's event-loop starvation test (REF §13.9, W18).

    In-process publishers send arrays of 2048 doubles on ten topics, round after
    round, to a client subscribed to all of them, and a heartbeat every round.
    Meanwhile a second client connects, subscribes to the heartbeat and gets ten
    heartbeats in a row, none missing, while the stream goes on.
    """
    graph, harness = served
    arrays = [
        graph.create_publisher(f"/load/t{i}", "std_msgs/msg/Float64MultiArray") for i in range(10)
    ]
    heartbeat = graph.create_publisher("/heartbeat", "std_msgs/msg/Int32")
    payload = {"data": [float(i) / 7 for i in range(2048)]}
    loaded = anyio.Event()
    received = [0]

    async def stream() -> None:
        beat = 0
        while True:
            for publisher in arrays:
                publisher.publish(payload)
            heartbeat.publish({"data": beat})
            beat += 1
            await anyio.sleep(0.01)

    async def load_reader(loader: Client) -> None:
        while True:
            message = await loader.receive()
            if str(message.get("topic", "")).startswith("/load/"):
                received[0] += 1
                if received[0] >= 100:
                    loaded.set()

    with anyio.fail_after(30):
        loader = await ws_client(harness, "loader")
        for i in range(10):
            await loader.send(
                {"op": "subscribe", "topic": f"/load/t{i}", "type": "std_msgs/Float64MultiArray"}
            )
        async with anyio.create_task_group() as tg:
            tg.start_soon(load_reader, loader)
            tg.start_soon(stream)
            await loaded.wait()  # the stream is flowing
            late = await ws_client(harness, "late")
            await late.send({"op": "subscribe", "topic": "/heartbeat", "type": "std_msgs/Int32"})
            beats = [
                (await late.expect(is_op("publish", topic="/heartbeat")))["msg"]["data"]
                for _ in range(10)
            ]
            tg.cancel_scope.cancel()
    assert beats == list(range(beats[0], beats[0] + 10))
    assert received[0] >= 100


async def test_bursts_of_goals_from_one_and_from_many_clients_all_succeed(
    served: tuple[Graph, Harness],
) -> None:
    """rosbridge_suite's action goal stress test (REF §13.9, W20).

    One client sends fifty Fibonacci goals without waiting between them; then, five
    rounds over, five clients send one goal each at once. Every goal ends with its
    own result: ``result`` true, status 4 (succeeded), the right sequence.
    """
    graph, harness = served

    async def fibonacci(goal: Message, context: GoalContext) -> Message:
        sequence = [0, 1]
        while len(sequence) <= int(goal["order"]):
            sequence.append(sequence[-1] + sequence[-2])
        return {"sequence": sequence[: int(goal["order"]) + 1]}

    graph.create_action_server("/fibonacci", FIB, fibonacci)

    def order_of(goal_id: str) -> int:
        return 2 + int(goal_id.rsplit("-", 1)[1]) % 5

    async def goals(client: Client, ids: list[str]) -> list[Message]:
        for goal_id in ids:
            await client.send(
                {
                    "op": "send_action_goal",
                    "action": "/fibonacci",
                    "action_type": FIB,
                    "args": {"order": order_of(goal_id)},
                    "id": goal_id,
                }
            )
        return [await client.expect(is_op("action_result", id=goal_id)) for goal_id in ids]

    def check(results: list[Message]) -> None:
        for result in results:
            order = order_of(str(result["id"]))
            assert (result["result"], result["status"]) == (True, 4), result
            assert len(result["values"]["sequence"]) == order + 1

    with anyio.fail_after(30):
        burst = await ws_client(harness, "burst")
        check(await goals(burst, [f"burst-{n}" for n in range(50)]))
        clients = [await ws_client(harness, f"r{k}") for k in range(5)]

        async def one(k: int, n: int, results: list[Message]) -> None:
            results.extend(await goals(clients[k], [f"r{k}-{n}"]))

        for round_ in range(5):
            results: list[Message] = []
            async with anyio.create_task_group() as tg:
                for k in range(5):
                    tg.start_soon(one, k, round_, results)
            assert len(results) == 5
            check(results)


LIMIT = 10_000  # bytes: max_message_size, scaled down from upstream's 1 000 000


async def test_a_call_just_under_the_message_size_limit_is_served_one_just_over_closes() -> None:
    """rosbridge_suite's message-size limit test (REF §13.9, W21).

    With ``max_message_size`` at 10 000 bytes, a call of 9 900 bytes keeps the
    connection and is answered; a call of 10 050 bytes closes it with 1009.
    """

    def padded_call(size: int) -> str:
        frame = {"op": "call_service", "service": "/rosapi/get_time", "id": ""}
        frame["id"] = "x" * (size - len(json.dumps(frame)))
        text = json.dumps(frame)
        assert len(text) == size
        return text

    async with running_server(ServerConfig(max_message_size=LIMIT)) as harness:
        with anyio.fail_after(10):
            async with connect(f"ws://127.0.0.1:{harness.port('websocket')}") as ws:
                await ws.send(padded_call(LIMIT - 100))
                reply = json.loads(await ws.recv())
                assert (reply["op"], reply["result"]) == ("service_response", True)
                await ws.send(padded_call(LIMIT + 50))
                with pytest.raises(ConnectionClosed) as closed:
                    await ws.recv()
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1009


UPGRADE = (
    b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
)


def drop_abruptly(port: int, topic: str) -> None:
    """Open a WebSocket, subscribe to ``topic``, take its first message and reset the
    connection: no close frame, unread data left behind (blocking; run in a thread)."""
    with socket.create_connection(("127.0.0.1", port), timeout=20) as sock:
        sock.sendall(UPGRADE)
        received = b""
        while b"\r\n\r\n" not in received:  # RFC 6455 4.1: no frame before the answer
            chunk = sock.recv(4096)
            assert chunk, "the server closed the connection"
            received += chunk
        sock.sendall(masked_text(json.dumps({"op": "subscribe", "topic": topic}).encode()))
        while topic.encode() not in received:  # the subscription is in place
            chunk = sock.recv(65536)
            assert chunk, "the server closed the connection"
            received += chunk
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # RST


async def test_clients_vanishing_mid_stream_leave_the_server_serving(
    served: tuple[Graph, Harness],
) -> None:
    """rosbridge_suite's rapid-disconnect smoke test (REF §13.9, W22).

    While strings of 10 kB are published without pause, five rounds of twenty
    clients subscribe and drop their connections with a reset. The server keeps
    going: every one of them is gone from the graph, and a new subscriber gets the
    stream.
    """
    graph, harness = served
    port = harness.port("websocket")
    publisher = graph.create_publisher("/big", "std_msgs/msg/String")
    text = "y" * 10_000

    async def stream() -> None:
        while True:
            publisher.publish({"data": text})
            await anyio.sleep(0.001)

    with anyio.fail_after(30):
        async with anyio.create_task_group() as tg:
            tg.start_soon(stream)
            for _ in range(5):
                async with anyio.create_task_group() as wave:
                    for _ in range(20):
                        wave.start_soon(anyio.to_thread.run_sync, drop_abruptly, port, "/big")
            fresh = await ws_client(harness, "fresh")
            while True:  # until the vanished subscribers are released
                reply = await call(fresh, "/rosapi/subscribers", "subs", args={"topic": "/big"})
                if not reply["values"]["subscribers"]:
                    break
                await anyio.sleep(0.02)
            await fresh.send({"op": "subscribe", "topic": "/big", "type": "std_msgs/String"})
            message = await fresh.expect(is_op("publish", topic="/big"))
            tg.cancel_scope.cancel()
    assert message["msg"] == {"data": text}
