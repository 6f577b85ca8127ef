"""Per-connection caps (docs/limits.md): each refuses the op over it, with a status, and
bounds what one connection can make the server hold.

Before, 600k subscriptions from one connection reached 1.4 GB, advertisements grew
without end, and fragment limits counted characters (astral ones hold 4 bytes each).
"""

from __future__ import annotations

import json
import tracemalloc
from collections.abc import AsyncIterator, Callable

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.server.session import Session, SessionConfig
from rwt_transports.server import ServerConfig
from tests.conftest import FakeClock
from tests.support.clients import Harness, is_op, running_server

CAPS = SessionConfig(
    status_level=StatusLevel.ERROR,
    max_subscriptions=3,
    max_advertisements=3,
    max_ids_per_topic=2,
    max_pending_calls=2,
    max_pending_goals=2,
    max_message_size=4000,
)


HOLDS_2 = "this connection holds 2 already (the server's limit)"


class Client:
    """A session with small caps, driven without sockets."""

    def __init__(self, graph: Graph, name: str, config: SessionConfig = CAPS) -> None:
        self.session = Session(graph.port, name, config=config)
        self.now = 100.0

    def send(self, **op: object) -> None:
        self.session.receive_frame(json.dumps(op), self.now)

    def received(self) -> list[dict[str, object]]:
        return [json.loads(frame.data) for frame in self.session.frames_to_send()]

    def errors(self) -> list[str]:
        return [str(m["msg"]) for m in self.received() if m.get("level") == "error"]


@pytest.fixture
def graph() -> Graph:
    return Graph(clock=FakeClock())


def test_subscriptions_are_capped_per_connection(graph: Graph) -> None:
    client = Client(graph, "c")
    for i in range(3):
        client.send(op="subscribe", topic=f"/t{i}", type="std_msgs/String")
    assert client.errors() == []
    client.send(op="subscribe", topic="/t3", type="std_msgs/String", id="over")
    assert client.errors() == [
        "subscribe: subscriptions: this connection holds 3 already (the server's limit)"
    ]
    assert "/t3" not in graph.topics  # nothing was registered
    client.send(op="subscribe", topic="/t0", type="std_msgs/String", id="again")  # same topic
    client.send(op="unsubscribe", topic="/t1")
    client.send(op="subscribe", topic="/t3", type="std_msgs/String")  # room again
    assert client.errors() == []


def test_ids_on_one_topic_are_capped(graph: Graph) -> None:
    client = Client(graph, "c")
    for op in ("subscribe", "advertise"):
        for i in range(2):
            client.send(op=op, topic="/t", type="std_msgs/String", id=f"{op}{i}")
        client.send(op=op, topic="/t", type="std_msgs/String", id=f"{op}-over")
        assert client.errors() == [
            f"{op}: ids on /t: this connection holds 2 already (the server's limit)"
        ]
        client.send(op=op, topic="/t", type="std_msgs/String", id=f"{op}0")  # a known id is fine
        assert client.errors() == []


def test_topics_services_and_actions_share_the_advertisement_cap(graph: Graph) -> None:
    client = Client(graph, "c")
    client.send(op="advertise", topic="/a", type="std_msgs/String")
    client.send(op="advertise_service", service="/s", type="std_srvs/srv/Trigger")
    client.send(op="advertise_action", action="/f", type="example_interfaces/action/Fibonacci")
    assert client.errors() == []
    for op in (
        {"op": "advertise", "topic": "/b", "type": "std_msgs/String"},
        {"op": "advertise_service", "service": "/s2", "type": "std_srvs/srv/Trigger"},
        {"op": "advertise_action", "action": "/f2", "type": "example_interfaces/action/Fibonacci"},
    ):
        client.send(**op)
        [error] = client.errors()
        assert error.endswith(
            "advertisements: this connection holds 3 already (the server's limit)"
        )
    assert "/s2" not in graph.services.entries and "/f2" not in graph.actions.entries
    client.send(op="unadvertise_service", service="/s")
    client.send(op="advertise_service", service="/s2", type="std_srvs/srv/Trigger")
    assert client.errors() == []


def test_a_service_taken_by_another_client_frees_its_slot(graph: Graph) -> None:
    first, second = Client(graph, "first"), Client(graph, "second")
    for name in ("/x", "/y", "/z"):
        first.send(op="advertise_service", service=name, type="std_srvs/srv/Trigger")
    second.send(op="advertise_service", service="/x", type="std_srvs/srv/Trigger")  # D15
    first.send(op="advertise_service", service="/w", type="std_srvs/srv/Trigger")
    assert first.errors() == []


def test_pending_calls_are_capped_and_answered(graph: Graph) -> None:
    provider, caller = Client(graph, "p"), Client(graph, "c")
    provider.send(op="advertise_service", service="/s", type="std_srvs/srv/Trigger")
    for i in range(3):
        caller.send(op="call_service", service="/s", id=i)
    replies = caller.received()
    assert replies[0] == {
        "op": "service_response",
        "service": "/s",
        "values": f"pending calls: {HOLDS_2}",
        "result": False,
        "id": 2,
    }
    assert replies[1]["op"] == "status"
    assert len(provider.received()) == 2  # the third never reached the provider
    provider.send(op="service_response", service="/s", id="service_request:/s:1", result=True)
    caller.received()
    caller.send(op="call_service", service="/s", id="after")  # an answer freed a slot
    assert caller.errors() == []


def test_pending_goals_are_capped_and_answered(graph: Graph) -> None:
    provider, caller = Client(graph, "p"), Client(graph, "c")
    provider.send(op="advertise_action", action="/f", type="example_interfaces/action/Fibonacci")
    for i in range(3):
        caller.send(
            op="send_action_goal",
            action="/f",
            action_type="example_interfaces/action/Fibonacci",
            args={"order": 3},
            id=f"g{i}",
        )
    result, status = caller.received()
    assert result["op"] == "action_result" and result["result"] is False
    assert result["id"] == "g2" and "pending goals" in str(result["values"])
    assert status["op"] == "status"
    goals = [m for m in provider.received() if m["op"] == "send_action_goal"]
    assert len(goals) == 2
    provider.send(op="action_result", action="/f", id=goals[0]["id"], result=True, values={})
    caller.received()
    caller.send(
        op="send_action_goal",
        action="/f",
        action_type="example_interfaces/action/Fibonacci",
        args={"order": 3},
        id="after",
    )
    assert caller.errors() == []


def test_fragments_count_bytes_held_not_characters(graph: Graph) -> None:
    client = Client(graph, "c")
    astral = "\U0001f600" * 300  # 300 characters, 1200 bytes held
    for num in range(4):  # 4800 bytes held > 4000: refused, though only 1200 characters
        client.send(op="fragment", id="big", num=num, total=10, data=astral)
    [error] = client.errors()
    assert "would hold more than 4000 bytes" in error
    assert client.session.fragments._bytes == 0  # the message was dropped whole


# ---- resource tests: memory stays bounded over a real transport ------------------------


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    config = ServerConfig(
        session=SessionConfig(
            max_subscriptions=200,
            max_advertisements=200,
            max_pending_calls=200,
            max_pending_goals=200,
        )
    )
    graph = Graph()
    graph.create_service("/never", "std_srvs/srv/Trigger", _never)
    graph.create_action_server("/slow", "example_interfaces/action/Fibonacci", _never_goal)
    async with running_server(config, graph=graph) as h:
        yield h


async def _never(request: dict[str, object]) -> dict[str, object]:
    await anyio.sleep_forever()
    raise AssertionError


async def _never_goal(goal: dict[str, object], context: object) -> dict[str, object]:
    await anyio.sleep_forever()
    raise AssertionError


OPS: dict[str, Callable[[int], dict[str, object]]] = {
    "subscriptions": lambda i: {"op": "subscribe", "topic": f"/t{i}", "type": "std_msgs/String"},
    "advertisements": lambda i: {"op": "advertise", "topic": f"/a{i}", "type": "std_msgs/String"},
    "services": lambda i: {
        "op": "advertise_service",
        "service": f"/s{i}",
        "type": "std_srvs/srv/Trigger",
    },
    "pending calls": lambda i: {"op": "call_service", "service": "/never", "id": i},
    "pending goals": lambda i: {
        "op": "send_action_goal",
        "action": "/slow",
        "action_type": "example_interfaces/action/Fibonacci",
        "args": {"order": 1},
        "id": i,
    },
}


@pytest.mark.anyio
@pytest.mark.parametrize("cap", OPS)
async def test_memory_stays_bounded_past_each_cap(harness: Harness, cap: str) -> None:
    """Filling a cap costs what it costs; 4x as many ops past it cost (almost) nothing."""
    attacker = await harness.connect("ws", "attacker")
    bystander = await harness.connect("tcp", "bystander")
    make = OPS[cap]

    async def send(start: int, count: int) -> None:
        for i in range(start, start + count):
            await attacker.send(make(i))
        # a round trip on the attacker's own connection: every op before it is done
        await attacker.send({"op": "set_level", "level": "info", "id": f"sync{start}"})
        await attacker.expect(is_op("status", id=f"sync{start}"))
        await attacker.send({"op": "set_level", "level": "error"})
        attacker.backlog.clear()
        await bystander.send({"op": "call_service", "service": "/rosapi/topics", "id": start})
        reply = await bystander.expect(is_op("service_response", id=start))
        assert reply["result"] is True

    tracemalloc.start()
    try:
        with anyio.fail_after(60):
            await send(0, 200)  # up to the cap
            await anyio.sleep(0.2)
            filled, _ = tracemalloc.get_traced_memory()
            await send(200, 800)  # four times as many past it
            await anyio.sleep(0.2)
            beyond, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert beyond - filled < 1_000_000, (cap, filled, beyond)  # 800 refused ops held nothing
