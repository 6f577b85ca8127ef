"""A recorded ROS 2 bag keeps a topic's offered QoS (protocol 2.1.0, D62), as ``ros2 bag`` does.

rosbag2 stores each connection's publishers' offered profiles (``offered_qos_profiles``
in ``metadata.yaml``), which its player reads back. A topic whose first registration
gave a ``qos`` is stored with that offer, every policy; a latched one without stays
transient local of depth 1. The bag is read with rosbags, as other tools read it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability, QosHistory, QosReliability, QosTime

import rwt
from rwt.types import Durability, History, Reliability

from .support import read_bag

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = pytest.mark.anyio

STRING = "std_msgs/msg/String"


async def test_the_bag_stores_each_topics_offer(tmp_path: Path) -> None:
    graph = rwt.Graph()
    offer = rwt.QosProfile(
        durability=Durability.TRANSIENT_LOCAL,
        depth=5,
        reliability=Reliability.BEST_EFFORT,
        deadline_s=0.25,
        lifespan_s=3.0,
    )
    kept = graph.create_publisher("/kept", STRING, qos=offer)
    everything = graph.create_publisher(
        "/all", STRING, qos=rwt.QosProfile(history=History.KEEP_ALL)
    )
    latched = graph.create_publisher("/latched", STRING, latch=True)
    for publisher in (kept, everything, latched):
        publisher.publish({"data": "before"})
    async with rwt.bag.Recorder(graph, tmp_path / "bag", discover_s=0.05):
        kept.publish({"data": "during"})
        everything.publish({"data": "during"})
    assert [m["data"] for m in read_bag(tmp_path / "bag")["/kept"]] == ["before", "during"]
    with AnyReader([tmp_path / "bag"]) as reader:
        offered = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
    qos = offered["/kept"]
    assert (qos.history, qos.depth) == (QosHistory.KEEP_LAST, 5)
    assert qos.reliability == QosReliability.BEST_EFFORT
    assert qos.durability == QosDurability.TRANSIENT_LOCAL
    assert qos.deadline == QosTime(sec=0, nsec=250_000_000)
    assert qos.lifespan == QosTime(sec=3, nsec=0)
    assert (offered["/all"].history, offered["/all"].depth) == (QosHistory.KEEP_ALL, 0)
    assert offered["/all"].durability == QosDurability.VOLATILE
    assert offered["/latched"].durability == QosDurability.TRANSIENT_LOCAL
    assert offered["/latched"].depth == 1
