"""One visibility rule for every listing, rosapi's and a Foxglove client's: rwt_graph.visibility."""

from __future__ import annotations

from rwt_graph.graph import Graph
from rwt_graph.rosapi import listing
from rwt_graph.visibility import EVERYTHING, Visibility
from rwt_protocol.runtime.access import AccessPolicy
from tests.foxglove.sansio import Client

STRING = "std_msgs/msg/String"
TRIGGER = "std_srvs/srv/Trigger"


def a_graph() -> Graph:
    graph = Graph()
    for topic in ("/ok/odom", "/ok/scan", "/secret/pose", "/other"):
        graph.create_publisher(topic, STRING)
    for service in ("/ok/reset", "/secret/wipe"):
        graph.create_service(service, TRIGGER, lambda request: {})
    return graph


def test_rosapi_and_a_foxglove_client_list_the_same_names_under_one_policy() -> None:
    graph = a_graph()
    policy = AccessPolicy(topics=("/ok/*",), services=("/ok/*",))
    visibility = Visibility.of(policy)
    client = Client(graph, access=policy)
    channels = sorted(
        str(op["topic"]) for op in client.take_ops("advertise") for op in op["channels"]
    )  # type: ignore[attr-defined]
    services = sorted(
        str(service["name"])
        for op in client.take_ops("advertiseServices")
        for service in op["services"]  # type: ignore[attr-defined]
    )
    assert channels == listing.topics(graph, visibility)[0] == ["/ok/odom", "/ok/scan"]
    assert services == listing.services(graph, visibility) == ["/ok/reset"]


def test_the_rule_is_the_access_policy_and_unrestricted_shows_everything() -> None:
    policy = AccessPolicy(topics=("/ok/*",), services=("/ok/*",), actions=("/ok/*",))
    visibility = Visibility.of(policy)
    assert visibility.topic("/ok/odom") and not visibility.topic("/secret/pose")
    assert visibility.service("/rosapi/topics")  # rosapi's own services stay callable
    assert not visibility.action("/secret/fib")
    assert visibility.param("/any:param")  # no parameter patterns: every parameter
    assert Visibility.of(AccessPolicy()) is EVERYTHING
    graph = a_graph()
    seen = {c.name for c in graph.port.feed.snapshot()[1] if visibility.sees(c)}
    assert seen == {"/ok/odom", "/ok/scan", "/ok/reset"}
