"""benchmarks/wanlink.py delays, drops and paces packets as configured.

Statistics over many packets with wide bounds, and lower bounds on time only (a
busy machine can make the link slower, never faster than configured).
"""

from __future__ import annotations

import itertools
import random
import socket
import struct
import time

import pytest
from benchmarks.wanlink import LinkModel, LinkProfile, WanLink, in_netns

from tests.support import netns

SO_RCVBUFFORCE = 33
"""Linux's root-only SO_RCVBUF past rmem_max (socket has no name for it before Python 3.12)."""

PROFILE = LinkProfile(delay_s=0.030, jitter_s=0.010, loss=0.02, rate_bps=15e6, queue_s=0.100)


def test_the_model_loses_delays_in_order_and_paces_at_the_rate() -> None:
    model = LinkModel(PROFILE, random.Random(7))
    sent = [(i / 1000, 200) for i in range(20_000)]  # a 1 kHz stream of 200 B: far below the rate
    arrivals = [(now, model.admit(size, now)) for now, size in sent]
    delivered = [(now, at) for now, at in arrivals if at is not None]
    lost = 1 - len(delivered) / len(sent)
    assert 0.01 < lost < 0.03  # 2 % configured: about 400 of 20,000
    assert model.stats.overflowed == 0
    delays = [at - now for now, at in delivered]
    assert min(delays) >= 0.020 and max(delays) <= 0.040 + 0.001  # 30 ms +- 10 ms
    # A packet waits for the one ahead (no reordering), so the mean is above 30 ms here,
    # where packets are 1 ms apart and the jitter 10 ms.
    assert 0.028 < sum(delays) / len(delays) < 0.040
    times = [at for _, at in delivered]
    assert times == sorted(times)  # one path: no reordering


def test_a_burst_above_the_rate_is_paced_then_dropped_at_the_queue() -> None:
    model = LinkModel(
        LinkProfile(delay_s=0.0, jitter_s=0.0, loss=0.0, rate_bps=15e6), random.Random(1)
    )
    times = [model.admit(1500, 0.0) for _ in range(1000)]  # 1.5 MB at once
    kept = [t for t in times if t is not None]
    gaps = [b - a for a, b in itertools.pairwise(kept)]
    assert min(gaps) == pytest.approx(1500 * 8 / 15e6)  # 0.8 ms a packet at 15 Mbit/s
    # The queue holds 100 ms of sending: about 125 packets go, the rest are dropped.
    assert 120 <= len(kept) <= 130 and model.stats.overflowed == 1000 - len(kept)


def test_packets_through_the_link_between_two_namespaces() -> None:
    reason = netns.unavailable(("tun",))
    if reason is not None:
        pytest.skip(reason)
    count, size = 2000, 100
    profile = LinkProfile(delay_s=0.030, jitter_s=0.010, loss=0.02, rate_bps=15e6, queue_s=1.0)
    with netns.namespaces("wan-a", "wan-b") as (a, b):
        link = WanLink(a.ns, "198.18.5.2", b.ns, "198.18.5.1", profile, seed=3)
        link.start()
        try:
            receiver = in_netns(b.ns, lambda: socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
            sender = in_netns(a.ns, lambda: socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
            receiver.bind(("198.18.5.1", 0))
            receiver.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, 16 * 1024 * 1024)
            receiver.settimeout(0.5)  # all are sent before the first read: a buffer for all
            target = receiver.getsockname()
            for seq in range(count):
                sender.sendto(struct.pack("!Id", seq, time.monotonic()).ljust(size), target)
            got: list[tuple[int, float]] = []
            stats = link.a_to_b.stats
            deadline = time.monotonic() + 30  # a hang guard on a busy machine
            while time.monotonic() < deadline:
                try:
                    data = receiver.recv(2048)
                except TimeoutError:  # done once every packet the link let through is here
                    if stats.packets == count and len(got) == stats.delivered:
                        break
                    continue
                seq, sent_at = struct.unpack_from("!Id", data)
                got.append((seq, time.monotonic() - sent_at))
            receiver.close()
            sender.close()
        finally:
            link.stop()
    assert 0.005 < 1 - len(got) / count < 0.05  # 2 % lost: about 40 of 2,000
    assert [s for s, _ in got] == sorted(s for s, _ in got)  # in order
    assert min(delay for _, delay in got) >= 0.020  # never faster than 30 ms - 10 ms
    assert link.a_to_b.stats.packets == count and link.a_to_b.stats.lost == count - len(got)


SMOKE_WARMUP_S = 0.5
"""The smoke runs' warm-up: what is checked is that each transport delivers, not its figures."""


def test_the_wan_benchmark_runs_every_transport_through_the_link() -> None:
    """A smoke run of benchmarks/wan_topic.py, one robot for all: each transport's subscriber
    gets the topic (the lossy channel too), and the camera's transports get pictures whose
    stamp (painted at publish) reads back after decoding."""
    reason = netns.unavailable(("tun",))
    if reason is not None:
        pytest.skip(reason)
    pytest.importorskip("aiortc", reason="the data channels' and the track's rows need aiortc")
    from benchmarks.wan_topic import run  # noqa: PLC0415 (after the skips)

    transports = ["websocket", "webrtc", "webrtc-lossy", "vp8", "mjpeg", "cbor-image"]
    rows = run(
        transports, SMOKE_WARMUP_S + 1, 100.0, LinkProfile(loss=0.0), warmup_s=SMOKE_WARMUP_S
    )
    assert [row["transport"] for row in rows] == transports
    for row in rows:
        assert row["received"] >= 1 and row.get("unread", 0) == 0, row
        assert row["age_p50_ms"] >= 20, row  # the link's delay (30 ms +- 10 ms) is in every age
    for row in rows[:3]:  # 100 Hz on the topic's transports, without loss
        assert row["received"] > 10, row
    for row in rows[:2]:  # the rosbridge sessions' drops, from the robot's log
        assert row["server_dropped"] == 0, row
