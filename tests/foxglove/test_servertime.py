"""Server time: while a bag plays, Foxglove clients get its clock (``time`` frames, log times)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import anyio
import pytest
from websockets.asyncio.client import connect

from rwt_bag.player import Player
from rwt_graph.graph import Graph
from rwt_graph.simtime import follow_clock
from rwt_graph.types import Dialect, TypeRegistry
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.bag.bags import CHATTER, CHATTER_GAP_S, T0, write_bag

from .test_session import Client


def frames(client: Client) -> list[tuple[str, int, bytes]]:
    """The binary frames so far, in order: ("time", ns, b"") or ("data", log time, payload).

    Playback states (opcode 0x05, a played bag's) are left out: test_playback.py reads them.
    """
    client.drain()
    out = []
    for frame in client.binary:
        if frame[0] == 5:
            continue
        if frame[0] == 2:
            assert len(frame) == 9
            out.append(("time", struct.unpack_from("<Q", frame, 1)[0], b""))
        else:
            assert frame[0] == 1
            out.append(("data", struct.unpack_from("<Q", frame, 5)[0], frame[13:]))
    client.binary = []
    return out


def subscribe(client: Client, topic: str) -> None:
    channel = client.channel(topic)
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]})


def test_no_bag_no_time(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    client = Client(graph)
    assert "time" not in client.ops[0]["capabilities"]  # type: ignore[operator]
    subscribe(client, "/chatter")
    client.session.tick()
    publisher.publish({"data": "x"})
    ((kind, log_time, _),) = frames(client)
    assert kind == "data" and log_time > 1_600_000_000 * 10**9  # the wall clock


def test_the_timeline_is_announced_sent_when_it_moves_and_stamps_message_data(
    ros2_types: TypeRegistry,
) -> None:
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    now = [5_000]
    with graph.port.use_timeline(lambda: now[0]):
        client = Client(graph)
        assert client.ops[0]["capabilities"] == [
            "clientPublish",
            "services",
            "connectionGraph",
            "time",
        ]
        assert frames(client) == [("time", 5_000, b"")]  # told at once
        subscribe(client, "/chatter")
        client.session.tick()
        assert frames(client) == []  # the same time is not told twice
        now[0] = 7_000
        publisher.publish({"data": "x"})  # the new time first, then the message on it
        assert [(kind, ns) for kind, ns, _ in frames(client)] == [("time", 7_000), ("data", 7_000)]
        now[0] = 1_000  # a seek back: a step
        client.session.tick()
        assert frames(client) == [("time", 1_000, b"")]
    client.session.tick()  # the bag is gone: nothing more
    publisher.publish({"data": "y"})
    ((kind, log_time, _),) = frames(client)
    assert kind == "data" and log_time > 1_600_000_000 * 10**9


@pytest.mark.anyio
async def test_a_played_bag_stamps_its_record_times_and_a_seek_steps_back(
    tmp_path: Path,
) -> None:
    graph = Graph(TypeRegistry(Dialect.ROS2))
    player = Player(graph, [write_bag(tmp_path / "bag", "mcap")], paused=True, rate=4.0)
    async with anyio.create_task_group() as tasks:
        await tasks.start(player.run)
        client = Client(graph)
        assert "time" in client.ops[0]["capabilities"]  # type: ignore[operator]
        assert frames(client) == [("time", T0, b"")]  # paused at the first message
        subscribe(client, "/chatter")
        player.resume()
        got: list[tuple[str, int, bytes]] = []
        with anyio.fail_after(20):
            while sum(kind == "data" for kind, _, _ in got) < 4:
                await anyio.sleep(0.01)
                client.session.tick()
                got += frames(client)
        player.seek(0.0)
        client.session.tick()
        stepped = frames(client)
        tasks.cancel_scope.cancel()
    chatter = [ns for kind, ns, _ in got if kind == "data"]
    # each message's log time is its record time in the bag
    gap = int(CHATTER_GAP_S * 1e9)
    assert chatter == [T0 + 100_000_000 + i * gap for i in range(len(chatter))]
    assert len(chatter) <= CHATTER
    times = [ns for kind, ns, _ in got if kind == "time"]
    assert times == sorted(times) and times[-1] >= chatter[-1]
    assert set(chatter) <= set(times)  # each told as time before its message
    ((kind, step, _),) = stepped  # the seek back to the start: one step back in time
    assert kind == "time" and T0 <= step < chatter[0]


def test_sim_time_is_the_latest_clock_from_its_first_message(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    chatter = graph.create_publisher("/chatter", "std_msgs/msg/String")
    clock = graph.create_publisher("/clock", "rosgraph_msgs/msg/Clock", node="/sim")
    with follow_clock(graph):
        client = Client(graph)
        assert "time" in client.ops[0]["capabilities"]  # type: ignore[operator]
        subscribe(client, "/chatter")
        client.session.tick()
        assert frames(client) == []  # no /clock yet: no time
        clock.publish({"clock": {"sec": 100, "nanosec": 5}})
        client.session.tick()
        assert frames(client) == [("time", 100_000_000_005, b"")]
        clock.publish({"clock": {"sec": -1, "nanosec": 0}})  # not a time Foxglove carries
        chatter.publish({"data": "x"})  # stamped with the latest /clock
        assert [(kind, ns) for kind, ns, _ in frames(client)] == [("data", 100_000_000_005)]
        clock.publish({"clock": {"sec": 90, "nanosec": 0}})  # a simulator reset: a step back
        client.session.tick()
        assert frames(client) == [("time", 90 * 10**9, b"")]
    client.session.tick()  # sim time is over: nothing more, log times on the wall clock
    chatter.publish({"data": "y"})
    ((kind, log_time, _),) = frames(client)
    assert kind == "data" and log_time > 1_600_000_000 * 10**9
    assert not graph.port.topics["/clock"].subscribers  # follow_clock unsubscribed


@pytest.mark.anyio
async def test_use_sim_time_serves_clock_as_server_time_over_the_wire(
    ros2_types: TypeRegistry,
) -> None:
    graph = Graph(ros2_types)
    clock = graph.create_publisher("/clock", "rosgraph_msgs/msg/Clock", node="/sim")
    server = RosbridgeServer(graph, ServerConfig(port=0, use_sim_time=True))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        async with connect(url, subprotocols=["foxglove.sdk.v1"]) as ws:
            info = json.loads(await ws.recv())
            assert "time" in info["capabilities"]
            clock.publish({"clock": {"sec": 1_234, "nanosec": 500}})
            with anyio.fail_after(10):
                frame = await ws.recv()
                while not isinstance(frame, bytes):  # advertise and the like first
                    frame = await ws.recv()
            assert frame[0] == 2 and struct.unpack_from("<Q", frame, 1)[0] == 1_234_000_000_500
        tg.cancel_scope.cancel()
