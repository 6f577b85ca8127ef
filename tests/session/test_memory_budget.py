"""The server-wide memory budget as sessions meet it (D44; ``rwt_protocol.runtime.memory``).

Sans-IO: sessions on one graph share one ``MemoryBudget``; the test takes (or
does not take) their frames and moves the clock by hand. What the network tests
show with real clients (tests/hardening/test_memory_budget.py) is pinned here
rule by rule: what is charged, who is stalled, who keeps what, who is closed.
"""

from __future__ import annotations

import json

import pytest

from rwt_graph.graph import Graph
from rwt_protocol.framing.fragments import FragmentBudget
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.commands import CloseConnection
from rwt_protocol.runtime.memory import (
    PRESSURE_FLOOR_BYTES,
    PRESSURE_STALL_S,
    READER_KEEP,
    MemoryBudget,
)
from rwt_protocol.server.session import Session, SessionConfig
from tests.conftest import FakeClock

KiB = 1024
LIMIT = 256 * KiB  # each connection's send buffer
PAYLOAD = 1000


def subscriber(graph: Graph, name: str, budget: MemoryBudget, topic: str = "/t") -> Session:
    config = SessionConfig(
        send_buffer_limit=LIMIT, send_timeout_s=5.0, status_level=StatusLevel.WARNING
    )
    session = Session(graph.port, name, config=config, memory=budget)
    op = {"op": "subscribe", "topic": topic, "type": "std_msgs/String"}
    session.receive_frame(json.dumps(op), graph.clock.monotonic())
    return session


def flood(graph: Graph, count: int, topic: str = "/t", start: int = 0) -> None:
    publisher = graph.create_publisher(topic, "std_msgs/msg/String")
    for i in range(start, start + count):
        publisher.publish({"data": f"{i:08d}" + "x" * PAYLOAD})


def numbers(session: Session) -> list[int]:
    """The sequence numbers of the messages queued for ``session``, taken (and sent)."""
    frames = session.frames_to_send()
    session.frames_sent()
    ops = [json.loads(frame.data) for frame in frames]
    return [int(op["msg"]["data"][:8]) for op in ops if op["op"] == "publish"]


def test_an_outbox_is_charged_until_its_transport_wrote_what_it_took(
    graph: Graph, clock: FakeClock
) -> None:
    budget = MemoryBudget(64 * 1024 * KiB)
    session = subscriber(graph, "a", budget)
    flood(graph, 10)
    queued = session.stats.queued_bytes
    assert queued > 10 * PAYLOAD and budget.used == queued == session.memory.held  # type: ignore[union-attr]
    frames = session.frames_to_send()
    assert len(frames) == 10 and session.stats.queued_bytes == 0
    assert budget.used == queued  # taken, not yet written: still held
    session.frames_sent()
    assert budget.used == 0 and budget.holders == 0
    flood(graph, 3, start=10)
    session.close()
    assert budget.used == 0  # what a peer that left never read is given back


def test_a_connection_that_takes_nothing_keeps_only_its_newest_message_when_full(
    graph: Graph, clock: FakeClock
) -> None:
    """Two subscribers of a flood past the budget: the one that takes its frames loses
    nothing; the one that took nothing for PRESSURE_STALL_S is cut to its newest
    message whenever the budget is full, and is told once."""
    budget = MemoryBudget(LIMIT)  # one send buffer for both
    reader = subscriber(graph, "reader", budget)
    stalled = subscriber(graph, "stalled", budget)
    got: list[int] = []
    for second in range(3):
        flood(graph, 100, start=100 * second)  # 100 KB a second: past the budget together
        got += numbers(reader)
        clock.now += PRESSURE_STALL_S
    assert got == list(range(300))
    assert stalled.stats.dropped_frames > 100 and budget.used <= budget.limit
    frames = [json.loads(frame.data) for frame in stalled.frames_to_send()]
    assert frames[-1]["msg"]["data"].startswith("00000299")  # the newest stays
    warnings = [f["msg"] for f in frames if f["op"] == "status"]
    assert len(warnings) == 1 and "--memory-budget" in warnings[0]


def test_a_connection_that_reads_keeps_its_share_or_three_quarters_of_its_buffer(
    graph: Graph, clock: FakeClock
) -> None:
    """Over the limit, a connection that took something within PRESSURE_STALL_S keeps
    the larger of its share and READER_KEEP of its send buffer: input backpressure
    holds its publishers at half, so it loses nothing it would not lose alone."""
    budget = MemoryBudget(LIMIT // 2)
    reader = subscriber(graph, "reader", budget)
    flood(graph, 1)
    numbers(reader)  # it reads
    flood(graph, 240, start=1)  # 240 KB: past the budget, within its own limit
    keep = int(LIMIT * READER_KEEP)
    assert budget.used > budget.limit
    assert keep - 2 * KiB <= reader.stats.queued_bytes <= keep
    assert reader.stats.dropped_frames > 0
    got = numbers(reader)
    assert got == list(range(241 - len(got), 241))  # the oldest went


def test_a_client_holding_replies_it_does_not_read_is_closed_while_the_budget_is_full(
    graph: Graph, clock: FakeClock
) -> None:
    """Replies are never dropped: while the budget is full, a connection holding more
    than PRESSURE_FLOOR_BYTES that takes nothing for the send timeout is closed."""
    budget = MemoryBudget(LIMIT)
    holder = subscriber(graph, "holder", budget)
    big = "y" * (PRESSURE_FLOOR_BYTES * 3 // 4)  # twice in what it is sent
    holder.receive_frame(
        json.dumps({"op": "call_service", "service": "/nobody", "id": big}),
        clock.now,
    )  # its error status and failure reply hold the id: unread
    assert holder.stats.queued_reply_bytes > PRESSURE_FLOOR_BYTES
    assert not budget.fits(LIMIT)  # someone is refused: the budget is full
    clock.now += 1.0
    reader = subscriber(graph, "reader", budget)
    flood(graph, 1)
    numbers(reader)  # any session's output sweeps the budget
    clock.now += 5.0  # --send-timeout
    holder.handle_timer(clock.now)
    [close] = [c for c in holder.commands_to_run() if isinstance(c, CloseConnection)]
    assert close.reason.startswith("slow consumer:") and "--memory-budget" in close.reason
    assert reader.close_request is None


def test_incomplete_messages_are_counted_never_refused_by_the_budget() -> None:
    budget = MemoryBudget(100)
    fragments = FragmentBudget(1000, budget)
    assert fragments.take(500) and budget.used == 500  # past the memory budget: counted
    assert not fragments.take(600)  # past its own limit: refused, with its own text
    assert "incomplete messages" in fragments.refusal("frame")
    fragments.give(500)
    assert budget.used == 0


@pytest.mark.parametrize("holders", [1, 4])
def test_the_share_is_the_budget_over_the_connections_holding_anything(holders: int) -> None:
    budget = MemoryBudget(1000)
    accounts = [budget.account() for _ in range(holders + 2)]
    for account in accounts[:holders]:
        account.charge(10)
    assert budget.share == 1000 // holders and budget.holders == holders
    accounts[0].close()
    accounts[0].charge(10)  # closed: nothing more is counted
    assert budget.used == 10 * (holders - 1)
