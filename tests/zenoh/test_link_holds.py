"""A slow reader of one topic from a Zenoh peer holds no other topic of the link.

A peer (a linked graph in its own process, ``camodom_peer``) publishes
``/cam`` (100 KB at 100 msg/s) and ``/odom`` (50 msg/s) to ``rwt serve
--zenoh``. One client of the server reads ``/cam`` 64 KB every 0.5 s over a
small receive buffer; another subscribes only to ``/odom``. The link holds
``/cam``'s samples in its inbox while that reader is congested, within the
hold budget, and delivers ``/odom``'s at once. Before, the whole link was
held: ``/odom`` stood still most of the run, in gaps of about the hold budget.
The same with ``--workers 2``, whose workers are linked over Zenoh: the
kernel puts the two clients on either worker, and on one worker (the case
that held ``/odom`` before) or two, ``/odom`` goes on.
"""

from __future__ import annotations

import sys
import time

import anyio
import pytest

from tests.hardening.link_readers import Bystander, SlowReader, wait_until

from .processes import serving, started
from .support import endpoint

pytestmark = pytest.mark.anyio

ODOM_MESSAGES = 400  # the window: 8 s at 50 msg/s
STILL_S = 0.2  # a gap longer than ten periods counts as standing still
LONGEST_GAP_S = 1.0  # half the hold budget: the held link stood still a whole budget at a time
FROZEN_SHARE = 0.25  # of the window: a loaded machine's own stalls add up to 10-15 % of it


def watch(url: str) -> tuple[Bystander, float, float, int]:
    """Read ``/cam`` slowly and ``/odom`` at once; the bystander and its window."""
    odom = Bystander(url, "/odom", "std_msgs/String")
    cam = SlowReader(url, "/cam", "sensor_msgs/Image")
    try:
        wait_until(lambda: odom.data and cam.received > 0, "both topics to flow")
        start, first = time.monotonic(), len(odom.data)
        wait_until(lambda: len(odom.data) >= first + ODOM_MESSAGES, "/odom", 60.0)
        return odom, start, time.monotonic(), first
    finally:
        cam.close()
        odom.close()


@pytest.mark.parametrize("workers", [(), ("--workers", "2")], ids=["one", "workers"])
async def test_a_slow_camera_reader_holds_up_no_other_topic_from_a_peer(
    workers: tuple[str, ...],
) -> None:
    listen = endpoint()
    extra = ("--hold-budget", "2", *workers)
    async with serving("B", listen=listen, extra=extra) as (server, url):
        publisher = [sys.executable, "-m", "tests.zenoh.camodom_peer", listen]
        async with started(publisher, "camodom") as peer:
            assert (await peer.line()).strip() == "ready", peer.stderr()
            odom, start, end, first = await anyio.to_thread.run_sync(watch, url)
        stderr = server.stderr()
    frozen = odom.frozen(start, end, STILL_S)
    assert frozen.longest_s < LONGEST_GAP_S, (frozen, stderr)
    assert frozen.total_s < FROZEN_SHARE * frozen.window_s, (frozen, stderr)
    counts = [int(msg["data"]) for msg in odom.data[first:]]
    assert len(counts) >= 0.9 * (counts[-1] - counts[0] + 1)  # full rate: next to no loss
