"""A user-space WAN link between two network namespaces: delay, jitter, loss and a rate.

This machine's kernel has no ``tc netem``, so the link is a TUN device in each
namespace and one thread that copies IP packets between them, each direction
through a ``LinkModel``:

- **loss**: each packet is dropped with probability ``loss`` (independently);
- **rate**: packets leave one after another at ``rate_bps`` (a packet of n
  bytes holds the link for 8n/rate s), behind a drop-tail queue of at most
  ``queue_s`` seconds of sending (a router's buffer: a burst above the rate
  waits, then is dropped);
- **delay**: each packet then arrives ``delay_s`` plus a uniform jitter in
  ``[-jitter_s, +jitter_s]`` later, never before the packet ahead of it (one
  path: no reordering).

``LinkModel`` is sans-IO (time in, a delivery time or a drop out), seeded, and
tested on its own; ``WanLink`` moves packets. Run by hand (root)::

    python -m benchmarks.wanlink NS_A 198.18.5.2 NS_B 198.18.5.1 --delay-ms 30 --jitter-ms 10 \\
        --loss 0.02 --rate-mbit 15

gives ``NS_A`` the address 198.18.5.2 and ``NS_B`` 198.18.5.1 on a point-to-point
link between them until interrupted, then prints each direction's counts.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import fcntl
import heapq
import json
import os
import random
import select
import signal
import struct
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import TypeVar

__all__ = ["LinkModel", "LinkProfile", "LinkStats", "WanLink", "in_netns"]

T = TypeVar("T")

_TUNSETIFF = 0x400454CA
_IFF_TUN = 0x0001
_IFF_NO_PI = 0x1000
_CLONE_NEWNET = 0x40000000
_MTU = 1500
_libc = ctypes.CDLL(None, use_errno=True)


@dataclass(frozen=True)
class LinkProfile:
    """One direction of the link (both directions get the same profile).

    Attributes:
        delay_s: one-way delay, s.
        jitter_s: the delay varies uniformly by up to this much either way, s.
        loss: probability that a packet is dropped (0 to 1).
        rate_bps: the link's rate, bit/s (0: unlimited).
        queue_s: the drop-tail queue in front of the rate, as seconds of sending.
    """

    delay_s: float = 0.030
    jitter_s: float = 0.010
    loss: float = 0.02
    rate_bps: float = 15e6
    queue_s: float = 0.100


@dataclass
class LinkStats:
    """Counts of one direction: packets in, lost (random), dropped (queue full), delivered."""

    packets: int = 0
    lost: int = 0
    overflowed: int = 0
    delivered: int = 0
    bytes: int = 0


@dataclass
class LinkModel:
    """One direction of the link, sans-IO: when a packet arrives, or that it is dropped.

    Args:
        profile: delay, jitter, loss, rate, queue.
        rng: the random source (seeded for a repeatable run).
    """

    profile: LinkProfile
    rng: random.Random = field(default_factory=random.Random)
    stats: LinkStats = field(default_factory=LinkStats)
    _free_at: float = 0.0
    _last_at: float = 0.0

    def admit(self, size: int, now: float) -> float | None:
        """A packet of ``size`` bytes sent at ``now`` (s): its arrival time (s); None: dropped."""
        profile = self.profile
        self.stats.packets += 1
        if self.rng.random() < profile.loss:
            self.stats.lost += 1
            return None
        start = max(now, self._free_at)
        if profile.rate_bps:
            if start - now > profile.queue_s:
                self.stats.overflowed += 1
                return None
            self._free_at = start + size * 8 / profile.rate_bps
        else:
            self._free_at = start
        jitter = self.rng.uniform(-profile.jitter_s, profile.jitter_s)
        at = max(self._free_at + profile.delay_s + jitter, self._last_at)  # one path: in order
        self._last_at = at
        self.stats.delivered += 1
        self.stats.bytes += size
        return at


def in_netns(ns: str, work: Callable[[], T]) -> T:
    """Run ``work`` in a thread that entered the network namespace ``ns`` (``ip netns``).

    A socket or TUN device it makes belongs to ``ns``, and stays usable from any
    thread. Needs root (CAP_SYS_ADMIN).

    Raises:
        OSError: ``setns`` failed; whatever ``work`` raised.
    """
    result: list[T] = []
    error: list[BaseException] = []

    def run() -> None:
        fd = os.open(f"/run/netns/{ns}", os.O_RDONLY)
        try:
            if _libc.setns(fd, _CLONE_NEWNET) != 0:
                errno = ctypes.get_errno()
                raise OSError(errno, f"setns {ns}: {os.strerror(errno)}")
            result.append(work())
        except BaseException as exc:  # handed to the caller's thread
            error.append(exc)
        finally:
            os.close(fd)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    if error:
        raise error[0]
    return result[0]


def _open_tun(name: str) -> int:
    """A TUN device ``name`` (IP packets, no header) in this thread's namespace: its fd."""
    fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
    fcntl.ioctl(fd, _TUNSETIFF, struct.pack("16sH", name.encode(), _IFF_TUN | _IFF_NO_PI))
    return fd


class WanLink:
    """A point-to-point link of two TUN devices, ``ns_a`` at ``addr_a``, ``ns_b`` at ``addr_b``.

    Args:
        ns_a, addr_a, ns_b, addr_b: the namespaces (``ip netns`` names) and their
            IPv4 addresses on the link (a /32 each, the other as its peer).
        profile: both directions' delay, jitter, loss and rate.
        seed: the random source's seed (None: a fresh one).
        back: the profile from ``ns_b`` to ``ns_a``, where it differs from ``profile``
            (a link that loses packets one way only).

    ``start()`` makes the devices and starts the forwarding thread; ``stop()``
    ends it and closes them (the devices go with their fds).
    """

    def __init__(
        self,
        ns_a: str,
        addr_a: str,
        ns_b: str,
        addr_b: str,
        profile: LinkProfile,
        seed: int | None = None,
        back: LinkProfile | None = None,
    ) -> None:
        self.ends = ((ns_a, addr_a, addr_b), (ns_b, addr_b, addr_a))
        rng = random.Random(seed)
        self.a_to_b = LinkModel(profile, random.Random(rng.random()))
        self.b_to_a = LinkModel(back or profile, random.Random(rng.random()))
        self._fds: list[int] = []
        self._stop_r, self._stop_w = os.pipe()
        self._thread = threading.Thread(target=self._forward, name="wanlink", daemon=True)

    def start(self) -> None:
        """Make and address both TUN devices, then forward until ``stop``."""
        for ns, address, peer in self.ends:
            self._fds.append(in_netns(ns, lambda: _open_tun("wan0")))
            ipv6 = "net.ipv6.conf.wan0.disable_ipv6=1"  # IPv4 only: no IPv6 chatter to count
            subprocess.run(["ip", "netns", "exec", ns, "sysctl", "-qw", ipv6], check=False)
            for argv in (
                ["addr", "add", address, "peer", peer, "dev", "wan0"],
                # A long device queue: the model's queue, not the kernel's, drops packets.
                ["link", "set", "wan0", "mtu", str(_MTU), "txqueuelen", "10000", "up"],
            ):
                subprocess.run(["ip", "-n", ns, *argv], check=True, capture_output=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop forwarding; the devices are removed with their fds."""
        os.write(self._stop_w, b"x")
        if self._thread.is_alive():
            self._thread.join(5)
        for fd in (*self._fds, self._stop_r, self._stop_w):
            os.close(fd)
        self._fds.clear()

    def _forward(self) -> None:
        """Read packets from both devices, schedule each by its model, write them when due."""
        a, b = self._fds
        route = {a: (b, self.a_to_b), b: (a, self.b_to_a)}
        due: list[tuple[float, int, int, bytes]] = []  # (time, order, out fd, packet)
        order = 0
        while True:
            timeout = max(0.0, due[0][0] - time.monotonic()) if due else None
            ready, _, _ = select.select([a, b, self._stop_r], [], [], timeout)
            if self._stop_r in ready:
                return
            now = time.monotonic()
            for fd in ready:
                out, model = route[fd]
                while True:
                    try:
                        packet = os.read(fd, 65536)
                    except BlockingIOError:
                        break
                    at = model.admit(len(packet), now)
                    if at is not None:
                        heapq.heappush(due, (at, order, out, packet))
                        order += 1
            now = time.monotonic()
            while due and due[0][0] <= now:
                _, _, out, packet = heapq.heappop(due)
                with contextlib.suppress(OSError):  # the device is down (stopping): lost
                    os.write(out, packet)


def main() -> None:
    """Run a link between two namespaces until SIGINT or SIGTERM; print its counts."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    for name in ("ns_a", "addr_a", "ns_b", "addr_b"):
        parser.add_argument(name)
    parser.add_argument("--delay-ms", type=float, default=30.0)
    parser.add_argument("--jitter-ms", type=float, default=10.0)
    parser.add_argument("--loss", type=float, default=0.02)
    parser.add_argument("--rate-mbit", type=float, default=15.0)
    parser.add_argument("--seed", type=int, default=None)
    args = parser.parse_args()
    profile = LinkProfile(
        args.delay_ms / 1000, args.jitter_ms / 1000, args.loss, args.rate_mbit * 1e6
    )
    link = WanLink(args.ns_a, args.addr_a, args.ns_b, args.addr_b, profile, args.seed)
    stopped = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stopped.set())
    link.start()
    print("wanlink up", flush=True)
    stopped.wait()
    link.stop()
    stats = {"a_to_b": asdict(link.a_to_b.stats), "b_to_a": asdict(link.b_to_a.stats)}
    print(json.dumps(stats), flush=True)


if __name__ == "__main__":
    main()
