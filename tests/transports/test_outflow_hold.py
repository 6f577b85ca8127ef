"""A link's congested queue for the other middleware holds the publishing reader back.

The link here is the graph's tap contract and a ``Backlog`` the test drains by
hand (the Zenoh link's own is ``rwt_zenoh.outbox.Outbox``, exercised end to end
in tests/zenoh/test_serve_zenoh.py): each ``/out`` message the tap sees adds
``SAMPLE`` bytes, and the tap reports congestion past the high watermark, as the
Zenoh link's tap does. The publishing client is a real WebSocket client.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_graph.link import OPEN_OUTFLOW
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.clients import Client, Harness, running_server

pytestmark = pytest.mark.anyio


SAMPLE = 400
HIGH, LOW = 1000, 500  # three samples congest it; two fit under the low watermark


class HandDrainedBacklog:
    """A link's queue that empties only when the test takes from it."""

    def __init__(self) -> None:
        self.queued_bytes = 0
        self.water_marks = (HIGH, LOW)
        self.on_take: Callable[[bool], None] | None = None

    def watch(self, on_take: Callable[[bool], None] | None) -> None:
        self.on_take = on_take

    def take(self, count: int) -> None:
        for _ in range(count):
            self.queued_bytes -= SAMPLE
            if self.on_take is not None:
                self.on_take(self.queued_bytes == 0)


async def linked(harness: Harness) -> tuple[HandDrainedBacklog, list[str]]:
    """A tap on ``harness``'s graph filling a backlog with what ``/out`` carries."""
    backlog, seen = HandDrainedBacklog(), []
    port = harness.server.graph.port

    def tap(entry, event, client, latch):  # type: ignore[no-untyped-def]
        if entry.name != "/out":
            return
        seen.append(event.msg["data"])
        backlog.queued_bytes += SAMPLE
        if backlog.queued_bytes > HIGH:
            port.outflow.congested(backlog)

    port.taps.append(tap)
    return backlog, seen


async def publisher(harness: Harness) -> Client:
    client = await harness.connect("ws")
    await client.send({"op": "advertise", "topic": "/out", "type": "std_msgs/String"})
    return client


async def publish(client: Client, number: int) -> None:
    await client.send({"op": "publish", "topic": "/out", "msg": {"data": str(number)}})


async def seen_reach(seen: list[str], count: int) -> None:
    with anyio.fail_after(10):
        while len(seen) < count:
            await anyio.sleep(0.01)


async def still(seen: list[str], count: int) -> None:
    """``seen`` stays at ``count`` while the server has time to read more (it is held)."""
    await anyio.sleep(0.3)
    assert len(seen) == count, seen


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    config = ServerConfig(session=SessionConfig(hold_budget_s=3.0))
    async with running_server(config) as h:
        yield h


async def test_a_congested_link_queue_pauses_its_publisher_until_under_the_low_watermark(
    harness: Harness,
) -> None:
    backlog, seen = await linked(harness)
    client = await publisher(harness)
    for number in range(3):  # one at a time: each is a batch of its own
        await publish(client, number)
        await seen_reach(seen, number + 1)
    for number in range(3, 8):
        await publish(client, number)
    await still(seen, 3)  # the reader waits: its next frames stay in the socket
    backlog.take(1)  # 800 bytes: under the high watermark, still over the low one
    await still(seen, 3)
    backlog.take(1)  # 400 bytes: under the low watermark
    await seen_reach(seen, 8)
    assert seen == [str(n) for n in range(8)]


async def test_a_link_queue_that_takes_nothing_holds_its_publisher_only_until_it_stalls(
    harness: Harness,
) -> None:
    backlog, seen = await linked(harness)
    client = await publisher(harness)
    for number in range(3):
        await publish(client, number)
        await seen_reach(seen, number + 1)
    for number in range(3, 8):
        await publish(client, number)
    await seen_reach(seen, 8)  # no take for INPUT_STALL_S: slow, no longer waited for
    assert backlog.queued_bytes == 8 * SAMPLE  # its own bound and drop rule apply
    await publish(client, 8)
    await seen_reach(seen, 9)  # slow until it catches up: not waited for again
    backlog.take(9)  # caught up: it may hold publishers again
    for number in range(9, 12):
        await publish(client, number)
        await seen_reach(seen, number + 1)
    await publish(client, 12)
    await still(seen, 12)
    backlog.take(2)
    await seen_reach(seen, 13)


async def test_an_in_process_publisher_is_never_held(harness: Harness) -> None:
    backlog, seen = await linked(harness)
    publisher = harness.server.graph.create_publisher("/out", "std_msgs/String")
    for number in range(10):
        publisher.publish({"data": str(number)})
    assert len(seen) == 10
    assert backlog.queued_bytes == 10 * SAMPLE


async def test_a_graph_no_server_serves_holds_no_publisher() -> None:
    graph = Graph()
    assert graph.port.outflow is OPEN_OUTFLOW
    OPEN_OUTFLOW.congested(HandDrainedBacklog())  # nothing to note, nothing waits
