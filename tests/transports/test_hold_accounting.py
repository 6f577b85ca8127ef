"""Input backpressure's accounting, with numbers and a made-up clock (flow.py).

The hold budget is charged to the reader being held, whatever it waits for, and
regained at ``HOLD_REFILL`` a second (a link's holds to the remote publisher's); a
peer reads when it takes ``READING_SHARE`` of its backlog per ``INPUT_STALL_S``
since it fell behind, or most of what reached its socket; a host found slow is not
waited for until its cool-down ends (docs/limits.md, input backpressure).
"""

from __future__ import annotations

import math

import pytest

from rwt_protocol.runtime.flow import (
    HOLD_REFILL,
    INPUT_STALL_S,
    LINK_ACCOUNTS,
    READING_SHARE,
    FlowControl,
    HoldAccount,
    HostCoolDowns,
    Outlet,
    ReadingWindow,
)
from rwt_transports.admission.shares import HostPrefixes

MiB = 1024 * 1024


@pytest.mark.parametrize(
    ("charges", "now", "left"),
    [
        ([], 0.0, 5.0),  # a whole budget to start with
        ([(0.0, 2.0)], 2.0, 3.0),
        ([(0.0, 5.0)], 5.0, 0.0),  # spent
        ([(0.0, 5.0)], 15.0, 10 * HOLD_REFILL),  # regained slowly ...
        ([(0.0, 5.0)], 5.0 + 5 / HOLD_REFILL, 5.0),  # ... up to the whole budget
        ([(0.0, 5.0)], 1000.0, 5.0),
        # four slow readers waited for one after another share one budget
        ([(0.0, 2.0), (2.0, 4.0), (4.0, 5.0), (5.0, 6.0)], 6.0, 0.0),
        # waits that overlap (two links' deliveries) are charged once
        ([(0.0, 2.0), (1.0, 3.0)], 3.0, 2.0 + HOLD_REFILL * 1.0),
        ([(0.0, 2.0), (0.5, 1.5)], 2.0, 3.0),
    ],
)
def test_a_hold_account_is_charged_once_per_second_and_regained_slowly(
    charges: list[tuple[float, float]], now: float, left: float
) -> None:
    account = HoldAccount(5.0)
    for start, end in charges:
        account.charge(start, end)
    assert account.left(now) == pytest.approx(left)


def test_a_reader_held_whenever_it_can_be_is_held_a_tenth_of_the_time_past_its_budget() -> None:
    account, now, held = HoldAccount(5.0), 0.0, 0.0
    while now < 1000.0:  # hold it for all that is left, every second
        wait = min(account.left(now), 1.0)
        account.charge(now, now + wait)
        held += wait
        now += 1.0
    assert held == pytest.approx(5.0 + HOLD_REFILL * 1000.0, rel=0.01)


def test_a_zero_budget_never_holds() -> None:
    assert HoldAccount(0.0).left(123.0) == 0.0


@pytest.mark.parametrize(
    ("backlog", "after", "reading"),
    [
        (12 * MiB, 12 * MiB, False),  # took nothing
        (12 * MiB, 12 * MiB - 128 * 1024, False),  # 64 KB every 0.5 s: 1 % of 10 MB/s
        (12 * MiB, 12 * MiB - 900 * 1000, True),  # a viewer at three 300 KB frames a second
        (12 * MiB, int(12 * MiB * (1 - READING_SHARE)), True),
        (12 * MiB, 0, True),  # caught up
        (1 * MiB, 1 * MiB - 64 * 1024, True),  # a small backlog: a small share
    ],
)
def test_reading_is_a_useful_share_of_the_backlog(backlog: int, after: int, reading: bool) -> None:
    window = ReadingWindow(0, backlog, 10.0)
    assert window.ends == 10.0 + INPUT_STALL_S
    assert window.reading(backlog - after, after, window.ends) is reading


@pytest.mark.parametrize(
    ("taken", "elapsed_s", "reading"),
    [
        # fell behind at 1 MiB; 12 MiB now: the share is of the 12 MiB
        (128 * 1024, INPUT_STALL_S, False),  # 64 KB every 0.5 s
        (900 * 1000, INPUT_STALL_S, True),  # a viewer at three 300 KB frames a second
        (3 * 900 * 1000, 3 * INPUT_STALL_S, True),  # judged late: the same rate
        (900 * 1000, 3 * INPUT_STALL_S, False),  # a third of it
    ],
)
def test_a_window_started_when_the_peer_fell_behind_asks_the_rate_of_its_backlog_since(
    taken: int, elapsed_s: float, reading: bool
) -> None:
    window = ReadingWindow(5 * MiB, 1 * MiB, 10.0)  # 5 MiB taken before
    assert window.reading(5 * MiB + taken, 12 * MiB, 10.0 + elapsed_s) is reading


@pytest.mark.parametrize(
    ("prefixes", "slow", "peer", "until"),
    [
        (HostPrefixes(), "192.0.2.7:4000", "192.0.2.7:4001", 30.0),  # reconnected
        (HostPrefixes(), "192.0.2.7:4000", "192.0.2.8:4001", -math.inf),
        (HostPrefixes(v4=24), "192.0.2.7:4000", "192.0.2.8:4001", 30.0),  # its /24
        (HostPrefixes(), "[2001:db8::1]:4000", "[2001:db8::2]:9", 30.0),  # its /64
        (HostPrefixes(), "[2001:db8::1]:4000", "[2001:db8:0:1::1]:9", -math.inf),
        (HostPrefixes(), "memory", "memory", 30.0),
    ],
)
def test_a_slow_host_cools_down_across_its_connections(
    prefixes: HostPrefixes, slow: str, peer: str, until: float
) -> None:
    cool_downs = HostCoolDowns(prefixes)
    cool_downs.cool(cool_downs.host(slow), 30.0, now=10.0)
    assert cool_downs.until(cool_downs.host(peer)) == until


def test_cool_downs_keep_the_latest_end_and_forget_expired_hosts() -> None:
    cool_downs = HostCoolDowns(HostPrefixes())
    cool_downs.cool("192.0.2.1", 30.0, now=10.0)
    cool_downs.cool("192.0.2.1", 20.0, now=11.0)  # found slow again: the later end stays
    assert cool_downs.until("192.0.2.1") == 30.0
    cool_downs.cool("192.0.2.2", 60.0, now=40.0)  # the first one's is over: it goes
    assert cool_downs.until("192.0.2.1") == -math.inf
    assert len(cool_downs) == 1


@pytest.mark.parametrize(
    ("unsent_before", "written", "unsent_after", "reading"),
    [
        (0, 232 * 1024, 0, True),  # took all the server gave it: the server fell behind
        (64 * 1024, 128 * 1024, 64 * 1024, True),  # took most of it
        (0, 2 * MiB, 2 * MiB, False),  # took nothing of it: its socket's queue grew
        (3 * MiB, 0, 3 * MiB, False),  # nothing new, and it left what was there
        (0, 0, 0, False),  # nothing reached it: the share rule alone
    ],
)
def test_a_peer_that_took_what_reached_its_socket_reads_whatever_its_backlog(
    unsent_before: int, written: int, unsent_after: int, reading: bool
) -> None:
    """D61: 8 MiB wait in the server for a peer that the server wrote little to."""
    window = ReadingWindow(5 * MiB, 1 * MiB + unsent_before, 10.0, unsent_before)
    taken = 5 * MiB + written + unsent_before - unsent_after
    assert window.reading(taken, 8 * MiB + unsent_after, window.ends, unsent_after) is reading
    if reading and written < MiB // 2:  # where the queue cannot be read: the share rule alone
        blind = ReadingWindow(5 * MiB, 1 * MiB + unsent_before, 10.0)
        assert not blind.reading(taken, 8 * MiB + unsent_after, blind.ends)


def test_each_remote_publisher_is_held_on_a_budget_of_its_own() -> None:
    """D61: a link's holds are charged to the publisher whose sample congested, as a local
    publisher's reader is; the links' own budget for samples of no known publisher."""
    flow: FlowControl[Outlet] = FlowControl(hold_budget_s=5.0)
    first = flow.link_account("zenoh:a:1")
    assert first is flow.link_account("zenoh:a:1")
    assert first is not flow.link_account("zenoh:a:2") and first is not flow.links
    assert flow.link_account(None) is flow.links
    first.charge(0.0, 5.0)  # spent by one burst
    assert first.left(5.0) == 0.0
    assert flow.link_account("zenoh:b:1").left(5.0) == 5.0  # another publisher's is whole
    for n in range(LINK_ACCOUNTS):  # a bounded table: the least recently held goes
        flow.link_account(f"zenoh:c:{n}")
    assert flow.link_account("zenoh:a:1").left(5.0) == 5.0
