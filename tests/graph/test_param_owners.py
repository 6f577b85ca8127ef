"""rosapi's ``set_param`` on the copy of another node's parameter asks that node (docs/ros2.md).

The node here is in-process: its ``list_parameters``, ``get_parameters`` and
``set_parameters`` services keep ``speed`` a double and refuse a negative one, as an
rclpy node's type check and validation callback do (tests/ros2/test_params.py has the
real rclpy node).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import anyio
import pytest

from rwt_graph.async_calls import call_service
from rwt_graph.graph import Graph
from rwt_graph.parameters.replicas import ParamReplicas
from rwt_graph.rosapi import install_rosapi

if TYPE_CHECKING:
    from collections.abc import AsyncIterator, Awaitable, Callable

pytestmark = pytest.mark.anyio

DOUBLE = 3  # rcl_interfaces/msg/ParameterType


class Node:
    """A node's parameter services; ``answer`` False: set_parameters never answers."""

    def __init__(self, graph: Graph, answer: bool = True) -> None:
        self.speed = 2.5
        self.answer = answer
        prefix = "rcl_interfaces/srv/"
        for part, handler in [
            ("list_parameters", self.list),
            ("get_parameters", self.get),
            ("set_parameters", self.set),
        ]:
            kind = prefix + "".join(word.title() for word in part.split("_"))
            graph.create_service(f"/robot/{part}", kind, handler, node="/robot")

    def list(self, request: dict) -> dict:
        return {"result": {"names": ["speed"], "prefixes": []}}

    def get(self, request: dict) -> dict:
        return {"values": [{"type": DOUBLE, "double_value": self.speed}]}

    async def set(self, request: dict) -> dict:
        if not self.answer:
            await anyio.sleep_forever()
        [param] = request["parameters"]
        value = param["value"]
        if value["type"] != DOUBLE:
            return {"results": [{"successful": False, "reason": "speed is a double"}]}
        if value["double_value"] < 0:
            return {"results": [{"successful": False, "reason": "speed must not be negative"}]}
        self.speed = value["double_value"]
        return {"results": [{"successful": True, "reason": ""}]}


@pytest.fixture
async def graph() -> AsyncIterator[Graph]:
    """A graph with rosapi, serving async handlers in this test's event loop."""
    graph = Graph()
    install_rosapi(graph)
    async with anyio.create_task_group() as tg:

        def spawn(job: Callable[[], Awaitable[None]]) -> Callable[[], None]:
            scope = anyio.CancelScope()

            async def run() -> None:
                with scope:
                    await job()

            tg.start_soon(run)
            return scope.cancel

        with graph.port.serving(spawn):
            yield graph
        tg.cancel_scope.cancel()


async def copied(graph: Graph) -> ParamReplicas:
    replicas = ParamReplicas(graph, "link:robot")
    replicas.sweep({"/robot"})
    with anyio.fail_after(5):
        while not graph.params.has("/robot:speed"):
            await anyio.sleep(0.01)
    return replicas


async def set_param(graph: Graph, value: str) -> dict:
    request = {"name": "/robot:speed", "value": value}
    return await call_service(graph, "/rosapi/set_param", request, timeout_s=10)


async def test_the_nodes_refusals_and_acceptance_are_answered(graph: Graph) -> None:
    node = Node(graph)
    replicas = await copied(graph)
    assert await set_param(graph, '"fast"') == {"successful": False, "reason": "speed is a double"}
    assert await set_param(graph, "-1.0") == {
        "successful": False,
        "reason": "speed must not be negative",
    }
    assert node.speed == 2.5
    assert graph.params.get("/robot:speed") == 2.5
    assert await set_param(graph, "3.5") == {"successful": True, "reason": ""}
    assert node.speed == 3.5
    # the copy holds what the node accepted as soon as the answer comes (a get right after it)
    assert graph.params.get("/robot:speed") == 3.5
    replicas.close()
    assert graph.params.owned_by("/robot") is None


async def test_a_node_that_does_not_answer_is_a_refusal(
    graph: Graph, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("rwt_graph.parameters.replicas.NODE_SET_TIMEOUT_S", 0.1)
    Node(graph, answer=False)
    await copied(graph)
    answer = await set_param(graph, "3.0")
    assert answer["successful"] is False
    assert "node /robot did not set speed" in str(answer["reason"])
