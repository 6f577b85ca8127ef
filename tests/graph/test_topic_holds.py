"""A link's topic held back while a subscriber it congested catches up; the others go on.

``TopicHolds`` on a stand-in gate whose hold ends when the test says so: the
held topic's samples wait in order and come back, oldest first, when the hold
ends; another topic's samples, and events that are no sample, are never held.
"""

from __future__ import annotations

import anyio
import anyio.lowlevel
import pytest

from rwt_graph.topic_holds import TopicHolds

pytestmark = pytest.mark.anyio


class _Hold:
    """An ``InflowHold`` that ends when ``end`` is called."""

    def __init__(self) -> None:
        self.ended = anyio.Event()

    async def wait(self) -> None:
        await self.ended.wait()


class _Gate:
    """An ``InflowGate`` that says a delivery congested a subscriber when told to."""

    def __init__(self) -> None:
        self.hold: _Hold | None = None

    def congested(self) -> bool:
        return self.hold is not None

    def take_hold(self, publisher: str | None = None) -> _Hold | None:
        hold, self.hold = self.hold, None
        return hold


async def test_a_congested_topic_waits_in_order_and_the_others_go_on() -> None:
    resumed: list[list[str]] = []
    gate = _Gate()
    async with anyio.create_task_group() as tg:
        holds: TopicHolds[str] = TopicHolds(tg.start_soon, resumed.append)
        holds.delivered("/cam", gate)  # nothing congested: nothing held
        assert "/cam" not in holds
        assert not holds.park("/cam", "cam-0")

        hold = gate.hold = _Hold()
        holds.delivered("/cam", gate)
        await anyio.lowlevel.checkpoint()
        assert "/cam" in holds
        assert holds.park("/cam", "cam-1")
        assert holds.park("/cam", "cam-2")
        assert not holds.park("/odom", "odom-1")  # another topic is delivered at once

        gate.hold = _Hold()  # a second congestion of a held topic starts no new hold
        holds.delivered("/cam", gate)
        gate.hold = _Hold()  # nor does one by an event that is no sample
        holds.delivered(None, gate)
        assert resumed == []

        hold.ended.set()
        with anyio.fail_after(5):
            while "/cam" in holds:
                await anyio.sleep(0.001)
    assert resumed == [["cam-1", "cam-2"]]
    assert not holds.park("/cam", "cam-3")  # the hold is over: delivered at once


async def test_a_hold_with_nothing_waiting_gives_nothing_back() -> None:
    resumed: list[list[str]] = []
    gate = _Gate()
    async with anyio.create_task_group() as tg:
        holds: TopicHolds[str] = TopicHolds(tg.start_soon, resumed.append)
        hold = gate.hold = _Hold()
        holds.delivered("/cam", gate)
        await anyio.lowlevel.checkpoint()
        hold.ended.set()
    assert "/cam" not in holds
    assert resumed == []
