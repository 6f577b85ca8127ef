"""Flow control's decisions, with numbers and a made-up clock (flow.py).

Each scenario of input backpressure (docs/limits.md, "Backpressure") as a
table: a reader held for a subscriber that keeps up, reads too slowly or does
not read at all; subscribers that fell behind together judged together; the
hold budget shared by whatever a reader waits for and regained slowly; a slow
host's cool-down across reconnections; and what the link gates are told to wait
for. The consumer is a model (bytes taken at fixed times); the hold loop's
decisions are the flow's (``Hold.wait_s``), as the pump takes them
(``holding.wait_for``): wait for the next take or that long, charge the time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest

from rwt_protocol.runtime.flow import (
    COOL_DOWN_BUDGETS,
    HOLD_REFILL,
    INPUT_STALL_S,
    FlowControl,
    HoldAccount,
    HostCoolDowns,
    Outlet,
    Progress,
    ReadingWindow,
    send_queue_shrank,
)
from rwt_transports.admission.shares import HostPrefixes
from rwt_transports.channel import ChannelAbilities

MiB = 1024 * 1024
HIGH, LOW = 8 * MiB, 4 * MiB  # a 16 MiB send buffer's watermarks


@dataclass
class Consumer:
    """A subscriber's peer: ``backlog`` bytes at 0 s, ``chunk`` bytes taken every ``every`` s."""

    backlog: int
    chunk: int
    every: float = 0.25

    def queued(self, now: float) -> int:
        takes = math.floor(now / self.every + 1e-9) if self.chunk else 0
        return max(0, self.backlog - takes * self.chunk)

    def next_take(self, now: float) -> float:
        """When the consumer next takes something after ``now`` (inf: never)."""
        if not self.chunk or self.queued(now) == 0:
            return math.inf
        return (math.floor(now / self.every + 1e-9) + 1) * self.every


def hold_for(
    flow: FlowControl[Outlet], outlet: Outlet, account: HoldAccount, peer: Consumer, now: float
) -> float:
    """Run the pump's hold loop for ``outlet`` from ``now``; return when the reader goes on."""
    hold = flow.hold(outlet, account, now)
    if hold is None:
        return now
    while True:
        queued = peer.queued(now)
        progress = Progress(peer.backlog - queued, queued)
        wait = hold.wait_s(now, queued > outlet.low_water, lambda: progress)  # noqa: B023
        if wait is None:
            break
        end = min(now + wait, peer.next_take(now))
        hold.waited(now, end)
        now = end
    return now


def connection(
    flow: FlowControl[Outlet], peer: str = "192.0.2.7:4000", budget_s: float = 5.0
) -> tuple[Outlet, HoldAccount]:
    outlet = Outlet()
    account = flow.open_connection(outlet, peer, budget_s, (HIGH, LOW))
    return outlet, account


@pytest.mark.parametrize(
    ("name", "peer", "budget_s", "held_s", "slow"),
    [
        # 12 MiB queued, 1 MiB taken every 0.25 s: down to 4 MiB after 2 s, the burst arrives whole
        ("keeps up", Consumer(12 * MiB, 1 * MiB), 5.0, 2.0, False),
        # 1/4 MiB every 0.25 s reads (8 % a second) but would need 8 s: the budget runs out,
        # regained at HOLD_REFILL meanwhile (5 s / (1 - 0.1), taken at the consumer's takes)
        ("reads too slowly", Consumer(12 * MiB, MiB // 4), 5.0, 5.5278, True),
        # 16 KB every 0.25 s is 0.5 % of its backlog a second: not reading, slow after one window
        ("only looks alive", Consumer(12 * MiB, 16 * 1024), 5.0, INPUT_STALL_S, True),
        ("stalled", Consumer(12 * MiB, 0), 5.0, INPUT_STALL_S, True),
        # a small budget ends the hold before the stall window does
        ("small budget", Consumer(12 * MiB, 0), 0.5, 0.5, True),
        ("no budget", Consumer(12 * MiB, 0), 0.0, 0.0, False),  # never held, never judged
        ("under the low mark", Consumer(3 * MiB, 0), 5.0, 0.0, False),
    ],
)
def test_a_reader_is_held_while_the_subscriber_reads_within_the_budget(
    name: str, peer: Consumer, budget_s: float, held_s: float, slow: bool
) -> None:
    flow: FlowControl[Outlet] = FlowControl(cool_downs=HostCoolDowns(HostPrefixes()))
    subscriber, _ = connection(flow, "192.0.2.7:4000", budget_s)
    _, publisher = connection(flow, "192.0.2.9:5000", budget_s)
    assert hold_for(flow, subscriber, publisher, peer, 0.0) == pytest.approx(held_s, abs=1e-4)
    assert subscriber.is_slow(held_s) is slow


def test_several_slow_subscribers_share_the_readers_one_budget() -> None:
    flow: FlowControl[Outlet] = FlowControl()
    _, publisher = connection(flow, budget_s=5.0)
    now, verdicts = 0.0, []
    for _ in range(4):  # each reads 8 % a second: reading, but too slowly to drain
        subscriber, _ = connection(flow)
        start = now
        now = hold_for(flow, subscriber, publisher, Consumer(16 * MiB, MiB // 4), now)
        verdicts.append((round(now - start, 2), subscriber.is_slow(now)))
    # the first spends the whole budget; the others find it spent: not waited for, not judged
    assert verdicts == [(5.53, True), (0.0, False), (0.0, False), (0.0, False)]


def behind(flow: FlowControl[Outlet], peer: str) -> tuple[Outlet, HoldAccount]:
    """A connection whose outbox passed its ``watch_water`` at 0 s (the pump's ``_fell_behind``)."""
    outlet, account = connection(flow, peer)
    outlet.counts_taken = True  # a pump's: it counts what its peer took
    outlet.window = ReadingWindow(0, outlet.watch_water, 0.0)
    return outlet, account


CONGESTED_AT = 0.7  # from the watch mark (1 MiB) to the high one (8 MiB) at 10 MB/s


@pytest.mark.parametrize(
    "peer",
    [Consumer(12 * MiB, 32 * 1024), Consumer(12 * MiB, 0)],  # 64 KB every 0.5 s; stalled
    ids=["only look alive", "stalled"],
)
def test_connections_that_fell_behind_together_are_judged_together(peer: Consumer) -> None:
    flow: FlowControl[Outlet] = FlowControl(cool_downs=HostCoolDowns(HostPrefixes()))
    _, publisher = connection(flow, "192.0.2.9:5000")
    subscribers = [behind(flow, f"192.0.2.{n}:4000")[0] for n in range(1, 5)]
    now = CONGESTED_AT
    for subscriber in subscribers:  # waited for one after another, as the pump does
        now = hold_for(flow, subscriber, publisher, peer, now)
    # what was left of the first one's window; the others' ended with it
    assert now == pytest.approx(INPUT_STALL_S)
    assert all(subscriber.is_slow(now) for subscriber in subscribers)


def test_a_viewer_that_fell_behind_is_waited_for_while_it_reads() -> None:
    flow: FlowControl[Outlet] = FlowControl()
    _, publisher = connection(flow, "192.0.2.9:5000")
    viewer, _ = behind(flow, "192.0.2.1:4000")
    viewer_peer = Consumer(12 * MiB, 225_000)  # three 300 KB frames a second
    # judged reading at 1 s and on; waited for until the budget ran out (it would need 9 s)
    assert hold_for(flow, viewer, publisher, viewer_peer, CONGESTED_AT) > CONGESTED_AT + 5.0


@pytest.mark.parametrize(
    ("found_slow_at", "reconnect_at", "peer", "prefixes", "slow"),
    [
        (10.0, 11.0, "192.0.2.7:4001", HostPrefixes(), True),  # a reconnection starts slow
        (10.0, 11.0, "192.0.2.8:4001", HostPrefixes(), False),  # another host
        (10.0, 11.0, "192.0.2.8:4001", HostPrefixes(v4=24), True),  # its /24
        (10.0, 10.0 + COOL_DOWN_BUDGETS * 5.0, "192.0.2.7:4001", HostPrefixes(), False),
    ],
)
def test_a_slow_connections_host_is_not_waited_for_during_its_cool_down(
    found_slow_at: float, reconnect_at: float, peer: str, prefixes: HostPrefixes, slow: bool
) -> None:
    flow: FlowControl[Outlet] = FlowControl(cool_downs=HostCoolDowns(prefixes))
    first, _ = connection(flow, "192.0.2.7:4000")
    flow.found_slow(first, found_slow_at)
    first.took(caught_up=True)  # catching up does not end a connection's cool-down
    assert first.is_slow(found_slow_at + 1.0)
    again, account = connection(flow, peer)
    assert again.is_slow(reconnect_at) is slow
    assert (flow.hold(again, account, reconnect_at) is None) is slow


def test_without_a_server_a_cool_down_ends_with_its_connection() -> None:
    flow: FlowControl[Outlet] = FlowControl()  # no cool-downs: a pump of its own
    first, _ = connection(flow)
    flow.found_slow(first, 10.0)
    assert first.is_slow(10.0 + COOL_DOWN_BUDGETS * 5.0 - 1.0)
    again, _ = connection(flow)
    assert not again.is_slow(11.0)


def link_outlet() -> Outlet:
    return Outlet(1000, 500)  # a link's queue: slow until it catches up


@pytest.mark.parametrize(
    ("in_batch", "queued", "slow", "noted"),
    [
        (True, 1001, False, True),
        (True, 1000, False, False),  # at the mark, not over it
        (False, 5000, False, False),  # outside a batch (an in-process publisher): nobody held
        (True, 5000, True, False),  # found slow: left to its drop rules
    ],
)
def test_a_batch_notes_the_outlets_it_pushed_over_their_high_watermark(
    in_batch: bool, queued: int, slow: bool, noted: bool
) -> None:
    flow: FlowControl[Outlet] = FlowControl()
    outlet = link_outlet()
    if slow:
        flow.found_slow(outlet, 0.0)
    if in_batch:
        flow.begin()
    if flow.congests(outlet, queued):
        flow.note_congested(outlet, 1.0)
        flow.note_congested(outlet, 1.0)  # noted once per batch
    flow.end()
    assert flow.take_congested() == ([outlet] if noted else [])
    assert not outlet.congested  # taken: the next batch notes it again
    assert flow.take_congested() == []


def test_a_link_found_slow_is_waited_for_again_once_it_caught_up() -> None:
    flow: FlowControl[Outlet] = FlowControl(hold_budget_s=5.0)
    outlet = link_outlet()
    hold = flow.hold(outlet, flow.links, 0.0)
    assert hold is not None
    assert (
        hold.next_wait(0.0, Progress(-2000, 2000)) == INPUT_STALL_S
    )  # (taken: the backlog's shrinking)
    hold.waited(0.0, INPUT_STALL_S)
    assert (
        hold.next_wait(INPUT_STALL_S, Progress(-2000, 2000)) is None
    )  # nothing taken in the window
    assert outlet.is_slow(1000.0)  # however long after
    outlet.took(caught_up=False)
    assert outlet.is_slow(1000.0)
    outlet.took(caught_up=True)
    assert not outlet.is_slow(1000.0)
    assert flow.links.left(INPUT_STALL_S) == pytest.approx(5.0 - INPUT_STALL_S)


def test_the_links_deliveries_are_held_as_one_reader() -> None:
    flow: FlowControl[Outlet] = FlowControl(hold_budget_s=5.0)
    first, second = link_outlet(), link_outlet()
    stalled = Consumer(2000, 0)
    assert hold_for(flow, first, flow.links, stalled, 0.0) == INPUT_STALL_S
    # waits in two tasks that overlap are charged once: 1 s of the budget, then 0.5 s more
    # (0.05 s regained from 1 s to 1.5 s)
    assert hold_for(flow, second, flow.links, stalled, 0.5) == 0.5 + INPUT_STALL_S
    assert flow.links.left(1.5) == pytest.approx(5.0 - 1.45)
    assert flow.links.left(11.5) == pytest.approx(5.0 - 1.45 + 10 * HOLD_REFILL)


@pytest.mark.parametrize(
    ("deferred", "in_batch", "callback"),
    [
        (0, False, True),  # the first output outside a batch: flushed by a loop callback
        (1, False, False),  # that callback flushes the next ones too
        (0, True, False),  # a batch flushes at its end
    ],
)
def test_output_outside_a_batch_asks_for_one_flush(
    deferred: int, in_batch: bool, callback: bool
) -> None:
    class Output:
        def flush_deferred(self) -> None:
            pass

    flow: FlowControl[Outlet] = FlowControl()
    outputs = [Output() for _ in range(deferred)]
    for output in outputs:
        flow.defer(output)
    if in_batch:
        flow.begin()
    assert flow.needs_flush_callback() is callback
    assert flow.take_deferred() == outputs
    assert flow.take_deferred() == []


@pytest.mark.parametrize(
    ("before", "after", "shrank"),
    [(4 * MiB, 4 * MiB - 1, True), (4 * MiB, 4 * MiB, False), (None, 0, False), (0, None, False)],
)
def test_a_send_queue_that_shrank_shows_a_reader(
    before: int | None, after: int | None, shrank: bool
) -> None:
    assert send_queue_shrank(before, after) is shrank


def test_a_channel_has_no_ability_unless_it_says_so() -> None:
    assert ChannelAbilities() == ChannelAbilities(False, False, False, False)
    with pytest.raises(AttributeError):
        ChannelAbilities().send_now = True  # type: ignore[misc]
