"""The graph's two faces (embedding API, session port) and its collaborators (clock, spawner)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import anyio
import pytest

import rwt
from rwt_graph.graph import Graph
from rwt_protocol.ports import MessageEvent

POSE = "geometry_msgs/msg/PoseStamped"
TRIGGER = "std_srvs/srv/Trigger"


class _Clock:
    def __init__(self, now: float) -> None:
        self.now = now

    def monotonic(self) -> float:
        return self.now

    def wall(self) -> float:
        return self.now


class _Sink:
    def __init__(self) -> None:
        self.events: list[MessageEvent] = []

    def on_message(self, event: MessageEvent) -> None:
        self.events.append(event)


def _stamp_of_a_pose(graph: Graph) -> object:
    """The header stamp a pose published without one gets (D8: now)."""
    heard: list[dict[str, object]] = []
    subscription = graph.create_subscription("/pose", heard.append, POSE)
    publisher = graph.create_publisher("/pose", POSE)
    publisher.publish({})
    publisher.close()
    subscription.close()
    return heard[0]["header"]["stamp"]  # type: ignore[index]


def test_the_port_and_the_embedding_api_are_one_graph() -> None:
    graph = Graph()
    sink = _Sink()
    graph.port.subscribe("ws:1", "/chatter", "std_msgs/String", sink)
    heard: list[dict[str, object]] = []
    graph.create_subscription("/chatter", heard.append)
    graph.create_publisher("/chatter", "std_msgs/msg/String").publish({"data": "from python"})
    graph.port.publish("ws:2", "/chatter", {"data": "from a client"}, path="$.msg")
    assert [event.msg["data"] for event in sink.events] == ["from python", "from a client"]
    assert [msg["data"] for msg in heard] == ["from python", "from a client"]
    assert graph.topic_names_and_types() == [("/chatter", "std_msgs/msg/String")]


def test_the_embedding_api_has_no_session_plumbing() -> None:
    # what sessions call on behalf of a client id is the port's, not the robot's
    for name in ("advertise", "publish", "subscribe", "release", "call_service", "spawner"):
        assert not hasattr(rwt.Graph(), name), name


def test_use_clock_makes_stamps_follow_it_and_restores_the_clock() -> None:
    graph = Graph(clock=_Clock(10.0))
    assert _stamp_of_a_pose(graph) == {"sec": 10, "nanosec": 0}
    with graph.port.use_clock(_Clock(1234.5)):
        assert graph.clock.wall() == 1234.5
        assert _stamp_of_a_pose(graph) == {"sec": 1234, "nanosec": 500_000_000}
    assert graph.clock.wall() == 10.0
    assert _stamp_of_a_pose(graph) == {"sec": 10, "nanosec": 0}


def test_use_clock_blocks_may_end_in_any_order() -> None:
    graph = Graph(clock=_Clock(1.0))
    first, second = graph.port.use_clock(_Clock(2.0)), graph.port.use_clock(_Clock(3.0))
    first.__enter__()
    second.__enter__()
    assert graph.clock.wall() == 3.0
    first.__exit__(None, None, None)
    assert graph.clock.wall() == 3.0  # the latest still open wins
    second.__exit__(None, None, None)
    assert graph.clock.wall() == 1.0


def test_service_request_stamps_follow_the_clock_in_use() -> None:
    graph = Graph(clock=_Clock(5.0))
    seen: list[object] = []

    def plan(request: dict[str, object]) -> dict[str, object]:
        seen.append(request["start"]["header"]["stamp"])  # type: ignore[index]
        return {}

    graph.create_service("/plan", "nav_msgs/srv/GetPlan", plan)
    client = graph.port.local_client()
    with graph.port.use_clock(_Clock(7.0)):
        graph.port.call_service(client, "/plan", {}, lambda *reply: None)
    graph.port.call_service(client, "/plan", {}, lambda *reply: None)
    assert seen == [{"sec": 7, "nanosec": 0}, {"sec": 5, "nanosec": 0}]


def test_collaborators_cannot_be_assigned() -> None:
    graph = Graph()
    with pytest.raises(AttributeError):
        graph.clock = _Clock(0.0)  # type: ignore[misc]
    with pytest.raises(AttributeError):
        graph.port.clock = _Clock(0.0)  # type: ignore[misc]
    with pytest.raises(AttributeError):
        graph.port.spawner = None  # type: ignore[misc]


def test_async_handlers_run_only_while_a_server_serves_the_graph() -> None:
    graph = Graph()

    async def trigger(request: dict[str, object]) -> dict[str, object]:
        return {"success": True, "message": "done"}

    graph.create_service("/async", TRIGGER, trigger)
    replies: list[tuple[bool, object]] = []

    def call() -> None:
        client = graph.port.local_client()
        graph.port.call_service(client, "/async", {}, lambda *reply: replies.append(reply))

    call()
    assert replies == [(False, "service /async is async but no event loop runs it")]

    jobs: list[Callable[[], Awaitable[None]]] = []

    def spawner(job: Callable[[], Awaitable[None]]) -> Callable[[], None]:
        jobs.append(job)
        return lambda: None

    with graph.port.serving(spawner):
        assert graph.port.spawner is spawner
        call()
        anyio.run(jobs.pop())
    assert replies[1] == (True, {"success": True, "message": "done"})
    assert graph.port.spawner is None
    call()
    assert replies[2][0] is False and not jobs
