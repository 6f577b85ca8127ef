"""The ROS 2 link's handoff runs its batches inside the graph's inflow gate and waits on it."""

from __future__ import annotations

import asyncio

import pytest

from rwt_ros2.handoff import Handoff

pytestmark = pytest.mark.anyio


class RecordingGate:
    """An ``InflowGate`` that records its calls and holds until released."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.release = asyncio.Event()
        self.congest = False  # what ``congested`` answers: a subscriber over its watermark

    def begin(self) -> None:
        self.calls.append("begin")

    def end(self) -> None:
        self.calls.append("end")

    def congested(self) -> bool:
        return self.congest

    async def hold(self) -> None:
        self.calls.append("hold")
        await self.release.wait()
        self.calls.append("released")


async def test_a_batch_runs_inside_the_gate_and_the_next_waits_for_its_hold() -> None:
    handoff = Handoff()
    gate = RecordingGate()
    handoff.put(gate.calls.append, "first", size=10, topic="/t")
    task = asyncio.create_task(handoff.drain(lambda: gate))
    for _ in range(20):
        await asyncio.sleep(0)
    assert gate.calls == ["begin", "first", "end", "hold"]
    handoff.put(gate.calls.append, "second", size=10, topic="/t")
    for _ in range(20):
        await asyncio.sleep(0)
    assert gate.calls[-1] == "hold"  # held: the second sample waits in the handoff
    assert handoff.queued_bytes == 10
    gate.release.set()
    for _ in range(20):
        await asyncio.sleep(0)
    assert gate.calls[4:] == ["released", "begin", "second", "end", "hold", "released"]
    assert handoff.queued_bytes == 0
    task.cancel()
    handoff.close()


async def test_a_batch_ends_at_the_delivery_that_congested_a_subscriber() -> None:
    handoff = Handoff()
    gate = RecordingGate()
    gate.congest = True
    for name in ("first", "second"):
        handoff.put(gate.calls.append, name, size=10, topic="/t")
    task = asyncio.create_task(handoff.drain(lambda: gate))
    for _ in range(20):
        await asyncio.sleep(0)
    assert gate.calls == ["begin", "first", "end", "hold"]  # the second waits for the hold
    assert handoff.queued_bytes == 10
    gate.congest = False
    gate.release.set()
    for _ in range(20):
        await asyncio.sleep(0)
    assert gate.calls[4:] == ["released", "begin", "second", "end", "hold", "released"]
    task.cancel()
    handoff.close()
