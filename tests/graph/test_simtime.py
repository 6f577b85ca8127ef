"""Sim time (``rwt serve --use-sim-time``): the latest ``/clock`` is the graph's timeline."""

from __future__ import annotations

import pytest

from rwt_graph.graph import Graph
from rwt_graph.simtime import SIM_TIME_NODE, follow_clock
from rwt_protocol.errors import GraphError


def test_the_latest_clock_message_is_the_timeline_while_followed() -> None:
    graph = Graph()
    clock = graph.create_publisher("/clock", "rosgraph_msgs/msg/Clock")
    assert graph.port.timeline is None
    with follow_clock(graph) as sim:
        assert graph.port.timeline is sim
        assert sim() is None  # no /clock yet: no time
        clock.publish({"clock": {"sec": 12, "nanosec": 500}})
        assert sim() == 12_000_000_500
        clock.publish({"clock": {"sec": 3, "nanosec": 0}})  # a rewind is a step back
        assert sim() == 3_000_000_000
        assert SIM_TIME_NODE in graph.nodes.names()
    assert graph.port.timeline is None  # released with the block


def test_a_clock_without_a_usable_time_is_ignored() -> None:
    graph = Graph()
    with follow_clock(graph) as sim:
        sim.receive({"clock": {"sec": 1, "nanosec": 0}})
        sim.receive({"clock": {"sec": -5, "nanosec": 0}})  # before the epoch
        sim.receive({"clock": {"sec": 2**40, "nanosec": 0}})  # past 64 bits of ns
        sim.receive({"no clock": 1})
        sim.receive("not a message")
        assert sim() == 1_000_000_000


def test_a_clock_topic_of_another_type_is_refused() -> None:
    graph = Graph()
    graph.create_publisher("/clock", "std_msgs/msg/String")
    with pytest.raises(GraphError), follow_clock(graph):
        pass
