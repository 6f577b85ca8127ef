"""A node copied from another middleware holds at most its share of the parameter store.

The node here is in-process graph services answering as an rclpy node's
parameter services would (tests/ros2/test_param_shares.py runs a real rclpy node).
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from rwt_graph.graph import Graph
from rwt_graph.parameters.replicas import (
    FETCH_SLICE,
    MAX_RETRY_REFRESHES,
    REFRESH_NAMES,
    ParamReplicas,
)
from rwt_graph.parameters.wire import to_wire

if TYPE_CHECKING:
    import pytest

REFRESH = 2  # sweeps a refresh


class FakeNode:
    """``name``'s list/get/set_parameters: ``values`` in order; counts the names asked for."""

    def __init__(self, graph: Graph, name: str, values: dict[str, object]) -> None:
        self.name = name
        self.values = values
        self.asked: list[list[str]] = []  # the names of each get_parameters
        self.listed = 0  # list_parameters calls
        value_type = graph.registry.message("rcl_interfaces/msg/ParameterValue")

        def list_parameters(request: dict) -> dict:
            self.listed += 1
            return {"result": {"names": list(self.values), "prefixes": []}}

        def get_parameters(request: dict) -> dict:
            self.asked.append(request["names"])
            return {"values": [to_wire(value_type, self.values[n]) for n in request["names"]]}

        def set_parameters(request: dict) -> dict:
            return {"results": [{"successful": False, "reason": "read-only"}]}

        self.services = [
            graph.create_service(f"{self.name}/{part}", f"rcl_interfaces/srv/{kind}", handler)
            for part, kind, handler in (
                ("list_parameters", "ListParameters", list_parameters),
                ("get_parameters", "GetParameters", get_parameters),
                ("set_parameters", "SetParameters", set_parameters),
            )
        ]

    def close(self) -> None:
        for service in self.services:
            service.close()


def refresh(replicas: ParamReplicas, node: FakeNode, count: int) -> None:
    """Sweep for ``count`` refreshes: a node listing more names is refreshed less often."""
    periods = max(1, math.ceil(len(node.values) / REFRESH_NAMES))
    for _ in range(count * REFRESH * periods):
        replicas.sweep({node.name})


def partial_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if "param_copy_partial" in r.getMessage()]


def test_a_node_listing_more_than_its_share_gets_its_first_names_and_others_keep_room(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, "rwt.graph")
    graph = Graph()
    share = graph.params.max_node_params
    node = FakeNode(graph, "/big", {f"p{n:05}": n for n in range(share + 300)})
    replicas = ParamReplicas(graph, "link:caller", refresh_sweeps=REFRESH)
    refresh(replicas, node, 10)
    names = graph.params.names()
    assert len(names) == share
    assert names[0] == "/big:p00000" and names[-1] == f"/big:p{share - 1:05}"
    # names past the share are never fetched, so never tried and never refused; the
    # values come FETCH_SLICE names a call
    asked = {name for names in node.asked for name in names}
    assert asked == {f"p{n:05}" for n in range(share)}
    assert max(len(names) for names in node.asked) == FETCH_SLICE
    graph.params.set("/other:gain", 2.5)  # another client's parameter has room
    assert graph.params.get("/other:gain") == 2.5
    [line] = partial_lines(caplog)
    assert f"node=/big held={share} left_out=300" in line
    assert f"holds its share of the parameter store ({share} parameters)" in line
    assert "cleanup_failed" not in caplog.text and "Traceback" not in caplog.text

    for n in range(100):  # the node drops 100 it held: 100 more fit
        del node.values[f"p{n:05}"]
    refresh(replicas, node, 1)
    names = [name for name in graph.params.names() if name.startswith("/big:")]
    assert len(names) == share
    assert names[0] == "/big:p00100" and names[-1] == f"/big:p{share + 99:05}"
    assert len(partial_lines(caplog)) == 1  # the same episode: not logged again
    replicas.close()
    assert graph.params.names() == ["/other:gain"]
    node.close()


def test_a_value_the_store_refuses_is_tried_again_after_a_growing_wait(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, "rwt.graph")
    graph = Graph()
    # a name the store cannot hold (":" in a parameter's name): refused every time
    node = FakeNode(graph, "/odd", {"speed": 1.5, "a:b": 1})
    replicas = ParamReplicas(graph, "link:caller", refresh_sweeps=REFRESH)
    refresh(replicas, node, 4 * MAX_RETRY_REFRESHES)
    tries = sum("a:b" in asked for asked in node.asked)
    # after waits of 1, 2, 4, ... refreshes, at most MAX_RETRY_REFRESHES: not each time
    assert 3 <= tries <= 12
    assert graph.params.names() == ["/odd:speed"]
    [line] = partial_lines(caplog)
    assert "node=/odd held=1 left_out=1" in line
    assert "expected <node>:<parameter>" in line
    replicas.close()
    node.close()


def test_a_node_listing_many_names_is_refreshed_less_often() -> None:
    graph = Graph()
    small = FakeNode(graph, "/small", {"speed": 1.5})
    big = FakeNode(graph, "/big", {f"p{n:05}": n for n in range(3 * REFRESH_NAMES)})
    replicas = ParamReplicas(graph, "link:caller", refresh_sweeps=REFRESH)
    for _ in range(1 + 12 * REFRESH):
        replicas.sweep({small.name, big.name})
    # the first sweep's refresh, then one each period (small) or each third period (big)
    assert small.listed == 1 + 12
    assert big.listed == 1 + 12 // 3
    assert graph.params.get("/big:p01499") == 1499  # its copy is whole all the same
    replicas.close()
    small.close()
    big.close()
