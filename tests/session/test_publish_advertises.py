"""A ``publish`` with ``type`` advertises its topic for the client (D48, REF §13.3).

Protocol 2.0.0 (rosbridge_suite 2.6.0, 3.2.0, 4.1.0): the publisher belongs to the
client, goes at ``unadvertise`` (its id, or none) or disconnect, and takes the same
checks as ``advertise``. ``--compat rosbridge-2.1`` keeps 2.1.0's refusal.
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.compat import Compat
from rwt_protocol.server.session import SessionConfig
from tests.conftest import Peer


def peer(graph: Graph, name: str, **config: Any) -> Peer:
    """A peer whose session takes ``config`` (``SessionConfig`` fields)."""
    return Peer(graph, name, config=SessionConfig(**config))


def typed(topic: str = "/t", data: str = "hi", **fields: object) -> dict[str, object]:
    op = {"op": "publish", "topic": topic, "type": "std_msgs/String", "msg": {"data": data}}
    return {**op, **fields}


def send(client: Peer, op: dict[str, object]) -> None:
    client.send_raw(json.dumps(op))


def test_a_typed_publish_to_an_unknown_topic_creates_it(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    send(a, typed(data="first"))
    assert a.statuses() == []
    b.send(op="subscribe", topic="/t")  # no type: the graph now knows it
    send(a, typed(data="second"))
    assert b.received() == [{"op": "publish", "topic": "/t", "msg": {"data": "second"}}]


def test_a_typed_publish_reaches_a_subscriber_that_came_first(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    b.send(op="subscribe", topic="/t", type="std_msgs/msg/String")
    send(a, typed(data="x", id="p1"))
    assert b.received() == [{"op": "publish", "topic": "/t", "msg": {"data": "x"}}]
    a.send(op="unadvertise", topic="/t", id="p1")  # its publisher, under the publish's id
    assert a.statuses() == []


def test_the_publisher_goes_with_unadvertise_of_its_id(graph: Graph) -> None:
    a, b = Peer(graph, "a", StatusLevel.WARNING), Peer(graph, "b")
    send(a, typed(id="p1"))
    a.send(op="unadvertise", topic="/t", id="other")
    [warning] = a.statuses()
    assert warning["level"] == "warning" and "other" in str(warning["msg"])
    a.send(op="unadvertise", topic="/t", id="p1")
    assert a.statuses() == []
    b.send(op="subscribe", topic="/t", id="s")  # nobody holds /t any more
    [status] = b.statuses()
    assert status["level"] == "error" and status["id"] == "s"


def test_the_publisher_goes_with_unadvertise_without_id(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    send(a, typed(id="p1"))
    a.send(op="advertise", topic="/t", type="std_msgs/String", id="a1")
    a.send(op="unadvertise", topic="/t")
    assert a.statuses() == []
    b.send(op="subscribe", topic="/t", id="s")
    assert [s["id"] for s in b.statuses()] == ["s"]


def test_the_publisher_goes_at_disconnect(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    send(a, typed())
    a.session.close()
    b.send(op="subscribe", topic="/t", id="s")
    assert [s["id"] for s in b.statuses()] == ["s"]


def test_a_type_clash_is_refused_and_publishes_nothing(peers: tuple[Peer, Peer]) -> None:
    a, b = peers
    b.send(op="subscribe", topic="/t", type="std_msgs/Int32")
    send(a, typed(id="p1"))
    [status] = a.statuses()
    assert status["level"] == "error" and status["id"] == "p1"
    assert str(status["msg"]).startswith("publish: ")
    assert "std_msgs/msg/Int32" in str(status["msg"])
    assert b.received() == []


def test_without_type_an_unknown_topic_is_still_refused(peers: tuple[Peer, Peer]) -> None:
    a, _ = peers
    a.send(op="publish", topic="/t", msg={"data": "x"}, id="p")
    [status] = a.statuses()
    assert status["level"] == "error" and str(status["msg"]).startswith("publish: ")


def test_once_advertised_a_later_type_is_not_read(peers: tuple[Peer, Peer]) -> None:
    # as rosbridge_suite: the registration holds; the message must fit its type (D9)
    a, b = peers
    send(a, typed())
    b.send(op="subscribe", topic="/t")
    send(a, {"op": "publish", "topic": "/t", "type": "std_msgs/Int32", "msg": {"data": "y"}})
    assert a.statuses() == []
    assert b.received() == [{"op": "publish", "topic": "/t", "msg": {"data": "y"}}]


def test_max_advertisements_counts_a_typed_publish(graph: Graph) -> None:
    a, b = peer(graph, "a", max_advertisements=1), Peer(graph, "b")
    b.send(op="subscribe", topic="/u", type="std_msgs/String")
    send(a, typed("/t"))
    send(a, typed("/u", id="over"))
    [status] = a.statuses()
    assert status["id"] == "over" and "advertisements" in str(status["msg"])
    assert b.received() == []


def test_the_topic_rules_refuse_it_as_they_refuse_advertise(graph: Graph) -> None:
    a, b = peer(graph, "a", access=AccessPolicy(topics=("/open/*",))), Peer(graph, "b")
    send(a, typed("/closed", id="p"))
    [status] = a.statuses()
    assert status["id"] == "p" and "not allowed" in str(status["msg"])
    b.send(op="subscribe", topic="/closed", id="s")  # nothing was made
    assert [s["id"] for s in b.statuses()] == ["s"]


@pytest.mark.parametrize("compat", [Compat.RWT, Compat.ROSBRIDGE])
def test_both_modes_advertise(graph: Graph, compat: Compat) -> None:
    a, b = peer(graph, "a", compat=compat), Peer(graph, "b")
    send(a, typed())
    b.send(op="subscribe", topic="/t")
    send(a, typed(data="z"))
    assert b.received() == [{"op": "publish", "topic": "/t", "msg": {"data": "z"}}]


def test_compat_rosbridge_2_1_refuses_an_unknown_topic_even_with_type(graph: Graph) -> None:
    a = peer(graph, "a", compat=Compat.ROSBRIDGE_2_1)
    a.send(op="set_level", level="error")  # rosbridge modes send no status until asked
    send(a, typed(id="p"))
    [status] = a.statuses()
    assert status["level"] == "error" and status["id"] == "p"
    assert "advertise it first" in str(status["msg"])


def test_compat_rosbridge_2_1_publishes_to_a_known_topic_without_advertising(graph: Graph) -> None:
    a, b = peer(graph, "a", compat=Compat.ROSBRIDGE_2_1), Peer(graph, "b")
    a.send(op="set_level", level="warning")
    b.send(op="subscribe", topic="/t", type="std_msgs/String")
    send(a, typed(id="p"))
    assert b.received() == [{"op": "publish", "topic": "/t", "msg": {"data": "hi"}}]
    a.send(op="unadvertise", topic="/t", id="p")  # no advertisement was made
    [warning] = a.statuses()
    assert warning["level"] == "warning" and "not advertised" in str(warning["msg"])
