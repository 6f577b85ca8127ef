"""Messages lost before they reached the server: their subscribers are told (D61).

A link that finds a gap in a remote publisher's messages reports it on the topic
(``Topic.report_lost``); each subscriber whose connection asks for warnings gets one
``warning`` status in its own spelling of the topic, at most once a second however
many gaps come (``LOSS_REPORT_EVERY_S``), the counts of the gaps between kept for the
next report, which the link's sweep makes if no gap comes. A subscriber at the default
level (``error``, D2) is not sent it, as no warning. A Foxglove client gets it as a
warning status.
"""

from __future__ import annotations

from rwt_graph.graph import Graph
from rwt_graph.topics import LOSS_REPORT_EVERY_S
from rwt_protocol.levels import StatusLevel
from tests.conftest import FakeClock, Peer
from tests.foxglove.sansio import Client


def test_a_gap_on_a_topic_is_a_warning_to_each_subscriber_that_asks(
    graph: Graph, clock: FakeClock
) -> None:
    told, quiet, other = (
        Peer(graph, "told", StatusLevel.WARNING),
        Peer(graph, "quiet"),
        Peer(graph, "other", StatusLevel.WARNING),
    )
    told.send(op="subscribe", topic="burst", type="std_msgs/String")
    quiet.send(op="subscribe", topic="/burst", type="std_msgs/String")
    other.send(op="subscribe", topic="/else", type="std_msgs/String")
    for peer in (told, quiet, other):
        peer.received()
    topic = graph.topics["/burst"]
    topic.report_lost(3, clock.monotonic())
    assert told.statuses() == [
        {
            "op": "status",
            "level": "warning",
            "msg": "lost 3 messages of burst on the way to this server: a queue between the "
            "server's processes or a link was full",
        }
    ]
    assert quiet.statuses() == [] and other.statuses() == []
    topic.report_lost(1, clock.monotonic())  # within the second: kept for the next
    clock.now += LOSS_REPORT_EVERY_S / 2
    topic.report_lost(1, clock.monotonic())
    assert told.statuses() == []
    clock.now += LOSS_REPORT_EVERY_S
    topic.report_lost(1, clock.monotonic())
    [status] = told.statuses()
    assert str(status["msg"]).startswith("lost 3 messages of burst")  # 1 + 1 + 1
    assert topic.report_lost(1, clock.monotonic())  # kept again, for a later report
    assert not topic.report_lost(0, clock.monotonic() + LOSS_REPORT_EVERY_S)  # the link's sweep
    [status] = told.statuses()
    assert str(status["msg"]).startswith("lost 1 message of burst on the way")
    assert not topic.report_lost(0, clock.monotonic() + 3 * LOSS_REPORT_EVERY_S)  # nothing kept
    assert told.statuses() == []


def test_a_foxglove_subscriber_is_told_too(graph: Graph, clock: FakeClock) -> None:
    graph.create_publisher("/burst", "std_msgs/msg/String")
    client = Client(graph)
    channel = client.channel("/burst")
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]})
    client.take_ops("status")
    graph.topics["/burst"].report_lost(5, clock.monotonic())
    client.drain()
    [status] = client.take_ops("status")
    assert status["level"] == 1  # warning
    assert str(status["message"]).startswith("lost 5 messages of /burst on the way")
