"""A Foxglove client and protocol 2.1.0's ``qos`` (D62-D63).

A rosbridge client fixes a transient-local offer of depth 2 on ``/cmd``; a Foxglove
client publishes there (message data in CDR): the topic keeps its last two for a late
rosbridge subscriber, as it keeps anyone's.

A Foxglove subscriber (the real client, @foxglove/ws-protocol in Node) is never sent a
message past its lifespan, its topic's or the server's (``--qos-lifespan``), as no
subscriber is (``SessionBase.message_end``): the graph's clock is moved back while a
message is published, so it has waited that long when its turn comes, as behind a
stalled link, without the test waiting.
"""

from __future__ import annotations

import json
import struct
import time
from dataclasses import replace

import anyio
import pytest

from rwt import QosProfile
from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.conftest import Peer
from tests.foxglove import extras
from tests.foxglove.sansio import Client, cdr
from tests.integration.client_harness import JS_DIR

TWIST = "geometry_msgs/msg/Twist"
STRING = "std_msgs/msg/String"
AGE_S = 30.0  # how long the old message has waited when its turn comes


def test_a_foxglove_clients_messages_are_kept_as_the_topics_offer_says(
    ros2_types: TypeRegistry,
) -> None:
    graph = Graph(ros2_types)
    owner = Peer(graph, "owner")
    owner.send(
        op="advertise",
        topic="/cmd",
        type=TWIST,
        qos={"durability": "transient_local", "depth": 2},
    )
    client = Client(graph)
    channel = {"id": 1, "topic": "/cmd", "encoding": "cdr", "schemaName": TWIST}
    client.send({"op": "advertise", "channels": [channel]})
    for x in (1.0, 2.0, 3.0):
        twist = {"linear": {"x": x, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
        client.send_raw(b"\x01" + struct.pack("<I", 1) + cdr(graph, TWIST, twist), binary=True)
    assert client.take_ops("status") == []
    late = Peer(graph, "late")
    late.send(op="subscribe", topic="/cmd", qos={"durability": "transient_local"})
    got = [json.loads(f.data) for f in late.session.frames_to_send()]
    assert [m["msg"]["linear"]["x"] for m in got] == [2.0, 3.0]


class Shifted:
    """The real clocks plus ``offset`` seconds (an ``rwt.Clock``), as the graph's clock."""

    def __init__(self) -> None:
        self.offset = 0.0

    def monotonic(self) -> float:
        return time.monotonic() + self.offset

    def wall(self) -> float:
        return time.time() + self.offset


async def _collected(graph: Graph, clock: Shifted, config: ServerConfig, topic: str) -> list[str]:
    """What the real Foxglove client subscribed to ``topic`` gets of "old" and "fresh".

    "old" is published ``AGE_S`` ago by the graph's clock, "fresh" now, once the
    client's subscription is in the graph.
    """
    server = RosbridgeServer(graph, replace(config, port=0))
    publisher = graph.create_publisher(topic, STRING)
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        command = extras.command("collect", server.urls["websocket"], topic, "fresh")
        async with await anyio.open_process(command, cwd=JS_DIR) as node:
            with anyio.fail_after(60):
                while not graph.topics[topic].subscribers:
                    await anyio.sleep(0.01)
                clock.offset = -AGE_S
                publisher.publish({"data": "old"})
                clock.offset = 0.0
                publisher.publish({"data": "fresh"})
                assert node.stdout is not None
                out = b"".join([chunk async for chunk in node.stdout])
                assert await node.wait() == 0
        tg.cancel_scope.cancel()
    return extras.result_of(out.decode())["received"]  # type: ignore[no-any-return]


@pytest.mark.anyio
@pytest.mark.node
async def test_a_foxglove_subscriber_gets_no_message_past_its_topics_lifespan(
    ros2_types: TypeRegistry,
) -> None:
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    clock = Shifted()
    graph = Graph(ros2_types, clock=clock)
    graph.create_publisher("/scan", STRING, qos=QosProfile(lifespan_s=AGE_S / 2))
    assert await _collected(graph, clock, ServerConfig(), "/scan") == ["fresh"]


@pytest.mark.anyio
@pytest.mark.node
async def test_the_servers_lifespan_binds_a_foxglove_subscriber_too(
    ros2_types: TypeRegistry,
) -> None:
    # a Foxglove client states no QoS: --qos-lifespan is its lifespan, as a rosbridge
    # subscription's whose qos gives none
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    clock = Shifted()
    graph = Graph(ros2_types, clock=clock)
    config = ServerConfig(session=SessionConfig(qos_lifespan_s=AGE_S / 2))
    assert await _collected(graph, clock, config, "/scan") == ["fresh"]


@pytest.mark.anyio
@pytest.mark.node
async def test_without_a_lifespan_a_foxglove_subscriber_gets_the_old_message_too(
    ros2_types: TypeRegistry,
) -> None:
    # the control: the same publications without any lifespan both arrive
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    clock = Shifted()
    graph = Graph(ros2_types, clock=clock)
    assert await _collected(graph, clock, ServerConfig(), "/scan") == ["old", "fresh"]
