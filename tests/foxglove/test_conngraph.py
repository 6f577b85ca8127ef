"""The Foxglove connection graph without I/O: the whole graph, then its changes."""

from __future__ import annotations

import json

from rwt_graph.graph import Graph
from rwt_protocol.runtime.access import AccessPolicy
from tests.conftest import Peer
from tests.foxglove.sansio import Client


def _updates(client: Client) -> list[dict[str, object]]:
    return client.take_ops("connectionGraphUpdate")


def _empty(**changes: object) -> dict[str, object]:
    update: dict[str, object] = {
        "op": "connectionGraphUpdate",
        "publishedTopics": [],
        "subscribedTopics": [],
        "advertisedServices": [],
        "removedTopics": [],
        "removedServices": [],
    }
    update.update(changes)
    return update


def test_the_whole_graph_first_then_what_changed(graph: Graph) -> None:
    graph.create_publisher("/chatter", "std_msgs/msg/String", node="/talker")
    graph.create_subscription("/chatter", lambda msg: None, node="/listener")
    graph.create_service("/add", "example_interfaces/srv/AddTwoInts", lambda req: {}, node="/adder")
    client = Client(graph)  # a rosbridge peer's node shows as any (D47, test_plumbing.py)
    assert _updates(client) == []  # nothing before subscribing
    client.send({"op": "subscribeConnectionGraph"})
    assert _updates(client) == [
        _empty(
            publishedTopics=[{"name": "/chatter", "publisherIds": ["/talker"]}],
            subscribedTopics=[{"name": "/chatter", "subscriberIds": ["/listener"]}],
            advertisedServices=[{"name": "/add", "providerIds": ["/adder"]}],
        )
    ]
    peer = Peer(graph, "rb")
    peer.send(op="advertise", topic="/rb_topic", type="std_msgs/msg/Int32")
    peer.send(op="subscribe", topic="/chatter", type="std_msgs/msg/String")
    node = graph.nodes.name_of("rb")
    client.sync()
    assert _updates(client) == [
        _empty(
            publishedTopics=[{"name": "/rb_topic", "publisherIds": [node]}],
            subscribedTopics=[{"name": "/chatter", "subscriberIds": sorted(["/listener", node])}],
        )
    ]
    client.sync()
    assert _updates(client) == []  # nothing changed: nothing sent
    peer.session.close()
    client.sync()
    assert _updates(client) == [
        _empty(
            subscribedTopics=[{"name": "/chatter", "subscriberIds": ["/listener"]}],
            removedTopics=["/rb_topic"],
        )
    ]
    graph.services.unadvertise(graph.services.entries["/add"].owner, "/add")
    client.sync()
    assert _updates(client) == [_empty(removedServices=["/add"])]
    client.send({"op": "unsubscribeConnectionGraph"})
    graph.create_publisher("/after", "std_msgs/msg/String")
    client.sync()
    assert _updates(client) == []


def test_an_update_waits_until_the_last_one_left_the_queue(graph: Graph) -> None:
    client = Client(graph)
    client.send({"op": "subscribeConnectionGraph"})
    assert _updates(client) == [_empty()]  # an empty graph: the first update comes all the same
    graph.create_publisher("/a", "std_msgs/msg/String", node="/n")
    client.session.sync()
    first = client.session.frames_to_send()
    graph.create_publisher("/b", "std_msgs/msg/String", node="/n")
    client.session.sync()
    graph.create_publisher("/c", "std_msgs/msg/String", node="/n")
    client.session.sync()  # the /b update still waits: /c joins the next
    frames = client.session.frames_to_send()
    ops = [json.loads(frame.data) for frame in first + frames]
    updates = [op for op in ops if op["op"] == "connectionGraphUpdate"]
    published = [[t["name"] for t in u["publishedTopics"]] for u in updates]
    assert published == [["/a"], ["/b"]]
    client.sync()
    assert [[t["name"] for t in u["publishedTopics"]] for u in _updates(client)] == [["/c"]]


def test_twice_subscribed_or_unsubscribed_gets_a_status_and_globs_hide(graph: Graph) -> None:
    graph.create_publisher("/public/a", "std_msgs/msg/String", node="/n")
    graph.create_publisher("/secret", "std_msgs/msg/String", node="/n")
    client = Client(graph, access=AccessPolicy(topics=("/public/*",)))
    client.send({"op": "unsubscribeConnectionGraph"})
    client.send({"op": "subscribeConnectionGraph"})
    client.send({"op": "subscribeConnectionGraph"})
    messages = [op["message"] for op in client.take_ops("status")]
    assert messages == [
        "unsubscribeConnectionGraph: not subscribed",
        "subscribeConnectionGraph: already subscribed",
    ]
    [update] = _updates(client)
    assert update["publishedTopics"] == [{"name": "/public/a", "publisherIds": ["/n"]}]
