"""The ROS 2 link's handoff runs its batches inside the graph's inflow gate and holds per topic."""

from __future__ import annotations

import asyncio

import pytest

from rwt_ros2.handoff import Handoff

pytestmark = pytest.mark.anyio


class Hold:
    """An ``InflowHold`` that waits until the test releases it."""

    def __init__(self, calls: list[str]) -> None:
        self.calls = calls
        self.release = asyncio.Event()

    async def wait(self) -> None:
        self.calls.append("hold")
        await self.release.wait()
        self.calls.append("released")


class RecordingGate:
    """An ``InflowGate`` that records its calls; ``congest`` makes the next delivery congest."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.congest = False
        self.holds: list[Hold] = []

    def begin(self) -> None:
        self.calls.append("begin")

    def end(self) -> None:
        self.calls.append("end")

    def congested(self) -> bool:
        return self.congest

    def take_hold(self) -> Hold | None:
        if not self.congest:
            return None
        self.congest = False
        self.holds.append(Hold(self.calls))
        return self.holds[-1]


async def settle() -> None:
    for _ in range(20):
        await asyncio.sleep(0)


def delivered(gate: RecordingGate) -> list[str]:
    return [call for call in gate.calls if call not in ("begin", "end")]


async def test_a_sample_that_congested_a_subscriber_holds_its_topic_alone() -> None:
    handoff = Handoff()
    gate = RecordingGate()

    def congesting(name: str) -> None:
        gate.calls.append(name)
        gate.congest = True  # this delivery pushed a subscriber over its high watermark

    handoff.put(congesting, "cam 1", size=10, topic="/cam")
    handoff.put(gate.calls.append, "cam 2", size=10, topic="/cam")
    handoff.put(gate.calls.append, "odom 1", size=10, topic="/odom")
    task = asyncio.create_task(handoff.drain(lambda: gate))
    await settle()
    # /cam 2 waits for the hold; /odom goes on, and so does an event that is no sample
    assert delivered(gate) == ["cam 1", "odom 1", "hold"]
    handoff.put(gate.calls.append, "cam 3", size=10, topic="/cam")
    handoff.put(gate.calls.append, "odom 2", size=10, topic="/odom")
    handoff.put(gate.calls.append, "event")
    await settle()
    assert delivered(gate) == ["cam 1", "odom 1", "hold", "odom 2", "event"]
    assert handoff.queued_bytes == 20  # the held samples still count against the bound
    gate.holds[0].release.set()
    await settle()
    assert delivered(gate)[5:] == ["released", "cam 2", "cam 3"]  # in order
    assert handoff.queued_bytes == 0
    task.cancel()
    handoff.close()


async def test_what_an_event_that_is_no_sample_congested_holds_nothing() -> None:
    handoff = Handoff()
    gate = RecordingGate()

    def congesting(name: str) -> None:
        gate.calls.append(name)
        gate.congest = True  # a reply pushed its caller over the watermark

    handoff.put(congesting, "reply")
    handoff.put(gate.calls.append, "cam 1", size=10, topic="/cam")
    task = asyncio.create_task(handoff.drain(lambda: gate))
    await settle()
    assert delivered(gate) == ["reply", "cam 1"]  # no "hold": nothing waited for
    task.cancel()
    handoff.close()
