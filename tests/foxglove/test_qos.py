"""A Foxglove client's publish follows the topic's QoS (protocol 2.1.0's ``qos``, D62-D63).

A rosbridge client fixes a transient-local offer of depth 2 on ``/cmd``; a Foxglove
client publishes there (message data in CDR): the topic keeps its last two for a late
rosbridge subscriber, as it keeps anyone's.
"""

from __future__ import annotations

import json
import struct

from rwt_graph.graph import Graph
from rwt_graph.types import TypeRegistry
from tests.conftest import Peer
from tests.foxglove.sansio import Client, cdr

TWIST = "geometry_msgs/msg/Twist"


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
