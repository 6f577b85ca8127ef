"""A topic's QoS on the graph, through the embedding API (``rwt_graph.topic_qos``, D62-D64)."""

from __future__ import annotations

import rwt
from rwt.types import Durability, Reliability
from rwt_graph.topic_qos import event_bytes

STRING = "std_msgs/msg/String"
DURABLE = rwt.QosProfile(durability=Durability.TRANSIENT_LOCAL, depth=3)


def test_an_in_process_publisher_offers_and_a_late_subscriber_gets_the_kept_messages() -> None:
    graph = rwt.Graph()
    publisher = graph.create_publisher("/t", STRING, qos=DURABLE)
    for i in range(5):
        publisher.publish({"data": str(i)})
    got: list[object] = []
    graph.create_subscription("/t", lambda msg: got.append(msg["data"]), qos=DURABLE)
    volatile: list[object] = []
    graph.create_subscription("/t", lambda msg: volatile.append(msg["data"]), qos=rwt.QosProfile())
    assert got == ["2", "3", "4"] and volatile == []
    publisher.publish({"data": "5"})
    assert got[-1] == volatile[-1] == "5"


def test_an_incompatible_subscription_gets_nothing_until_the_offer_goes() -> None:
    graph = rwt.Graph()
    sensor = rwt.QosProfile(reliability=Reliability.BEST_EFFORT)
    publisher = graph.create_publisher("/scan", STRING, qos=sensor)
    got: list[object] = []
    graph.create_subscription("/scan", lambda msg: got.append(msg["data"]), qos=rwt.QosProfile())
    publisher.publish({"data": "lost"})
    assert got == []
    publisher.close()
    plain = graph.create_publisher("/scan", STRING)
    plain.publish({"data": "matched"})
    assert got == ["matched"]


def test_the_store_is_bounded_by_bytes_too() -> None:
    graph = rwt.Graph()
    graph.port.max_store_bytes = 1000
    publisher = graph.create_publisher(
        "/big", STRING, qos=rwt.QosProfile(durability=Durability.TRANSIENT_LOCAL, depth=100)
    )
    for i in range(50):
        publisher.publish({"data": f"{i:03}" + "x" * 97})
    state = graph.topics["/big"].qos
    assert state is not None
    assert state.store_bytes <= 1000 and len(state.store) == 1000 // event_bytes(state.store[0])
    assert state.store[-1].msg["data"].startswith("049")


def test_a_topic_without_qos_keeps_no_state_and_batches_as_before() -> None:
    graph = rwt.Graph()
    graph.create_publisher("/plain", STRING, latch=True).publish({"data": "kept"})
    got: list[object] = []
    graph.create_subscription("/plain", lambda msg: got.append(msg["data"]))
    assert got == ["kept"]  # D13 as before
    entry = graph.topics["/plain"]
    assert entry.qos is None and "fan_out" not in vars(entry)


def test_all_stores_together_keep_the_graphs_bound_each_its_newest() -> None:
    graph = rwt.Graph()
    graph.port.stores.limit = 2000
    deep = rwt.QosProfile(durability=Durability.TRANSIENT_LOCAL, depth=100)
    publishers = [graph.create_publisher(f"/t{n}", STRING, qos=deep) for n in range(4)]
    for i in range(20):
        for publisher in publishers:
            publisher.publish({"data": f"{i:03}" + "x" * 97})
    states = [graph.topics[f"/t{n}"].qos for n in range(4)]
    assert all(state is not None and len(state.store) >= 1 for state in states)
    assert graph.port.stores.used == sum(s.store_bytes for s in states if s is not None)
    assert graph.port.stores.used <= 2000 + 3 * 120  # the others' newest stay
    for state in states:
        assert state is not None and state.store[-1].msg["data"].startswith("019")
    for publisher in publishers:
        publisher.close()
    assert graph.port.stores.used == 0  # the stores went with their offers
