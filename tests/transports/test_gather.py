"""Output made outside a reader's batch, gathered over loop turns (rwt_transports.gather).

The gatherer writes a connection once the turn after its first output brings no
more, once it holds ``GATHER_BYTES``, or else (a burst) once ``GATHER_S`` have
passed since the gathering began. Every protocol's connections share it: a
Foxglove client's and a rosbridge subscriber's output from an in-process
publisher both go through it (the burst benchmarks, benchmarks/foxglove.py; a
burst over a real server: tests/foxglove/test_bursts.py).
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence

import anyio
import anyio.lowlevel
import pytest

from rwt_transports.gather import GATHER_BYTES, Gatherer

pytestmark = [pytest.mark.anyio, pytest.mark.uvloop_too]  # the loops' clocks differ


class Member:
    """A connection as the gatherer sees it: bytes queued, and when it was flushed."""

    def __init__(self, queued: int = 0) -> None:
        self.queued = queued
        self.flushed_at: int | None = None  # the turn
        self.turn = 0

    def queued_bytes(self) -> int:
        return self.queued

    def flush(self) -> None:
        self.flushed_at = self.turn


async def _turns(members: Sequence[Member], count: int, gatherer: Gatherer | None = None) -> None:
    """Let the loop turn ``count`` times; with ``gatherer``, output comes each turn."""
    for _ in range(count):
        if gatherer is not None:
            gatherer.more = True
        await asyncio.sleep(0)
        for member in members:
            member.turn += 1


async def test_a_lone_output_is_written_after_one_quiet_turn() -> None:
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=3600)
    member = Member()
    gatherer.join(member)
    await _turns([member], 5)
    # the first look waits for the publisher's next turn, the second finds it quiet
    assert member.flushed_at == 1


async def test_output_that_keeps_coming_is_gathered_until_the_time_bound() -> None:
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=0.2)
    member = Member()
    gatherer.join(member)
    await _turns([member], 5, gatherer)  # a message each turn: a burst, gathered
    await _turns([member], 3)  # the burst ended: its tail waits for the bound, no longer
    assert member.flushed_at is None
    with anyio.fail_after(10):
        while member.flushed_at is None:
            await anyio.sleep(0.01)


async def test_a_burst_that_never_ends_is_still_written() -> None:
    gatherer = Gatherer(asyncio.get_running_loop())
    member = Member()
    gatherer.join(member)
    with anyio.fail_after(10):
        while member.flushed_at is None:  # the time bound (GATHER_S) ends the gathering
            await _turns([member], 1, gatherer)


async def test_a_burst_is_gathered_for_its_bound_on_a_clock_finer_than_the_loops() -> None:
    # uvloop's loop.time moves in whole milliseconds: read there, a 1 ms gathering
    # that began just before a tick seemed over at its second look
    now = [0.0]
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=0.001, clock=lambda: now[0])
    member = Member()
    gatherer.join(member)
    now[0] = 0.0004  # the second look: 0.4 ms into the gathering
    await _turns([member], 2, gatherer)  # both looks (the end is on a later turn's timer)
    assert member.flushed_at is None  # a burst: gathered until the bound
    with anyio.fail_after(10):
        while member.flushed_at is None:  # the rest of the bound, on the loop's timer
            await anyio.sleep(0.001)


async def test_a_connection_that_holds_enough_is_written_alone_at_once() -> None:
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=0.2)
    small, full = Member(), Member(GATHER_BYTES)
    gatherer.join(small)
    gatherer.join(full)
    await _turns([small, full], 3, gatherer)
    assert full.flushed_at is not None and full.flushed_at <= 1
    assert small.flushed_at is None  # still gathering while output comes
    with anyio.fail_after(10):
        while small.flushed_at is None:  # written at the bound
            await anyio.sleep(0.01)


async def test_a_connection_that_fills_up_during_a_burst_is_released_at_once() -> None:
    gatherer = Gatherer(asyncio.get_running_loop(), max_s=3600)
    small, filling = Member(), Member()
    gatherer.join(small)
    gatherer.join(filling)
    await _turns([small, filling], 3, gatherer)  # a burst: gathered until the bound
    filling.queued = GATHER_BYTES
    gatherer.release(filling)  # what the pump's wake-up does then
    assert filling.flushed_at == 3
    await _turns([small, filling], 3, gatherer)
    assert small.flushed_at is None
