"""Per-host shares of the connection slots (docs/limits.md, per server).

``--max-connections`` and ``--udp-max-sessions`` bound the server; without a
share, one host could take every slot and keep it. But in local use and in tests
every client is 127.0.0.1, so a fixed small share would break them. The rule:
while fewer than ``SHARES_FROM`` of the slots are taken, anyone gets one; past
that, a host that holds its share (``--max-connections-per-host``,
``--udp-max-sessions-per-host``) or more gets no more. One host can so take at
most ``SHARES_FROM`` of the slots, and the rest stays for hosts holding less
than their share.

A host is the source IP address; IPv6 addresses count by their /64 prefix (one
machine gets a whole /64), IPv4-mapped IPv6 addresses as the IPv4 address.
"""

from __future__ import annotations

import ipaddress
from collections import Counter

__all__ = ["SHARES_FROM", "HostShares", "host_key"]

SHARES_FROM = 0.75
"""The fraction of the slots taken past which per-host shares apply."""


def host_key(address: str) -> str:
    """The host that ``address`` (an IP address without port) counts as."""
    try:
        ip = ipaddress.ip_address(address.strip("[]"))
    except ValueError:
        return address  # not an IP (a Unix socket, "unknown"): itself
    if isinstance(ip, ipaddress.IPv6Address):
        if ip.ipv4_mapped is not None:
            return str(ip.ipv4_mapped)
        return str(ipaddress.IPv6Network((ip, 64), strict=False))
    return str(ip)


class HostShares:
    """The slots each host holds, and whether it may take one more.

    Args:
        share: slots a host may hold once ``SHARES_FROM`` of ``limit`` are taken.
    """

    def __init__(self, share: int) -> None:
        self.share = share
        self._held: Counter[str] = Counter()

    def admits(self, host: str, taken: int, limit: int) -> bool:
        """Whether ``host`` may take a slot while ``taken`` of ``limit`` are taken."""
        return taken < limit * SHARES_FROM or self._held[host] < self.share

    def held(self, host: str) -> int:
        """Slots ``host`` holds."""
        return self._held[host]

    def add(self, host: str) -> None:
        """``host`` took a slot."""
        self._held[host] += 1

    def remove(self, host: str) -> None:
        """``host`` freed a slot."""
        self._held[host] -= 1
        if self._held[host] <= 0:
            del self._held[host]
