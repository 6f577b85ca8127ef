"""A paced rate per host: each host's requests spaced in time, a bounded number of hosts kept.

An HTTP front end whose requests each cost the server a burst of work (MCP's, where each
2026-07-28 request opens a session and builds its server) spaces a host's requests at
``1 / rate`` seconds (the generic cell rate algorithm: a theoretical arrival time per
host): a request that comes early waits its turn, up to ``max_wait_s``; one that would
wait longer is refused. A flood from one host then reaches the event loop as one
request every ``1 / rate`` seconds, never as a burst of them, so other clients' round
trips stay short (benchmarks/README.md, "B25"); a host that sends one request now and
then never waits. The hosts seen least lately are dropped past ``kept`` (a host that
comes back starts afresh), so memory stays bounded whatever the number of addresses.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["HostPace", "host_of"]


def host_of(peer: str) -> str:
    """The host of a peer address (``127.0.0.1:5000`` -> ``127.0.0.1``, IPv6 kept whole)."""
    return peer.rpartition(":")[0] or peer


class HostPace:
    """Requests of each host spaced ``1 / rate`` seconds apart, waits up to ``max_wait_s``.

    Args:
        rate: requests a second a host may make, evenly spaced.
        max_wait_s: the longest a request waits for its turn; longer: refused.
        kept: hosts remembered (least recently seen dropped first).
        clock: monotonic seconds.
    """

    def __init__(
        self,
        rate: float,
        max_wait_s: float,
        kept: int,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.interval, self.max_wait_s, self.kept, self.clock = 1.0 / rate, max_wait_s, kept, clock
        self._due: OrderedDict[str, float] = OrderedDict()  # each host's next free turn

    def turn(self, peer: str) -> float | None:
        """Seconds ``peer``'s request waits for its turn (taken now), or None: refuse it."""
        host, now = host_of(peer), self.clock()
        due = max(self._due.pop(host, now), now)
        wait = due - now
        if wait > self.max_wait_s:
            self._due[host] = due  # a refused request takes no turn
            return None
        self._due[host] = due + self.interval
        if len(self._due) > self.kept:
            self._due.popitem(last=False)
        return wait
