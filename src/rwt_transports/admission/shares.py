"""Per-host shares of the connection slots (docs/limits.md, per server).

``--max-connections`` and ``--udp-max-sessions`` bound the server; without a
share, one host could take every slot and keep it. But in local use and in tests
every client is 127.0.0.1, so a fixed small share would break them. The rule:
while fewer than ``SHARES_FROM`` of the slots are taken, anyone gets one; past
that, a host gets one more only while it holds fewer than its share, and its
share is the smaller of ``--max-connections-per-host`` (or
``--udp-max-sessions-per-host``) and the slots still free. So the share shrinks
as the slots fill: of the slots free past ``SHARES_FROM`` a host takes at most
half (rounded up), the next host at most half of the rest, and the last free
slot only goes to a host that holds none. However the first hosts connect (one
after another, in turn, with a per-host option above ``--max-connections``),
hosts that each hold a slot cannot take the last one while another host
waits. A fixed share alone let three addresses hold all 40 slots of
``--max-connections 40`` at the default 64 a host.

A host is a network prefix of the source address (``HostPrefixes``): an IPv6
machine gets a whole /64, so IPv6 addresses count by their /64 by default, and a
LAN attacker may hold several IPv4 addresses, so IPv4 ones can count by a
shorter prefix than the default /32 (``--host-prefix-v4``, ``--host-prefix-v6``).
IPv4-mapped IPv6 addresses (``::ffff:a.b.c.d``) count as their IPv4 address.
"""

from __future__ import annotations

import ipaddress
from collections import Counter
from dataclasses import dataclass

from rwt_protocol.errors import ConfigError

__all__ = [
    "DEFAULT_PREFIX_V4",
    "DEFAULT_PREFIX_V6",
    "SHARES_FROM",
    "HostPrefixes",
    "HostShares",
    "address_of",
]

SHARES_FROM = 0.75
"""The fraction of the slots taken past which per-host shares apply."""

DEFAULT_PREFIX_V4 = 32
"""Bits of an IPv4 source address that name its host: the address itself."""
DEFAULT_PREFIX_V6 = 64
"""Bits of an IPv6 source address that name its host: its /64, what one machine gets (RFC 4291)."""


def address_of(peer: str) -> str:
    """The address part of a peer's ``HOST:PORT`` (IPv6 addresses keep their colons).

    A peer without a port (``stdio``, ``memory``) is returned as it is.
    """
    host, sep, _ = peer.rpartition(":")
    return host if sep else peer


@dataclass(frozen=True, slots=True)
class HostPrefixes:
    """How source addresses group into hosts: by their leading bits.

    Attributes:
        v4: prefix length of an IPv4 host, 0 to 32 bits (``--host-prefix-v4``).
        v6: prefix length of an IPv6 host, 0 to 128 bits (``--host-prefix-v6``).

    Raises:
        ConfigError: a prefix length outside its address's width.
    """

    v4: int = DEFAULT_PREFIX_V4
    v6: int = DEFAULT_PREFIX_V6

    def __post_init__(self) -> None:
        for option, bits, width in (
            ("--host-prefix-v4", self.v4, ipaddress.IPV4LENGTH),
            ("--host-prefix-v6", self.v6, ipaddress.IPV6LENGTH),
        ):
            if not 0 <= bits <= width:
                raise ConfigError(f"{option} must be 0 to {width} bits, not {bits}")

    def host(self, address: str) -> str:
        """The host that ``address`` (an IP address without port) counts as.

        Returns:
            The address itself at a full-length prefix (``192.0.2.7``), else its
            network (``192.0.2.0/24``, ``2001:db8:1:2::/64``); anything that is
            not an IP address (a Unix socket, ``unknown``) as it is.
        """
        try:
            ip = ipaddress.ip_address(address.strip("[]").partition("%")[0])
        except ValueError:
            return address
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped  # a dual-stack socket's IPv4 client: its IPv4 host
        bits = self.v4 if ip.version == 4 else self.v6
        if bits == ip.max_prefixlen:
            return str(ip)
        return str(ipaddress.ip_network((ip, bits), strict=False))

    def host_of(self, peer: str) -> str:
        """The host a peer (``HOST:PORT``, ``stdio``, ``memory``) counts as (``host``)."""
        return self.host(address_of(peer))


class HostShares:
    """The slots each host holds, and whether it may take one more.

    Args:
        share: the most slots a host may hold once ``SHARES_FROM`` of ``limit``
            are taken (the per-host option); ``allowance`` shrinks it with the
            free slots.
    """

    def __init__(self, share: int) -> None:
        self.share = share
        self._held: Counter[str] = Counter()

    def allowance(self, taken: int, limit: int) -> int:
        """The slots a host may hold past ``SHARES_FROM`` while ``taken`` of ``limit`` are.

        ``share``, but never more than the slots still free: a host holding as
        many as are free leaves them to others (the module's docstring says why).
        """
        return min(self.share, limit - taken)

    def admits(self, host: str, taken: int, limit: int) -> bool:
        """Whether ``host`` may take a slot while ``taken`` of ``limit`` are taken.

        Below ``SHARES_FROM`` of ``limit`` anyone may; past it only a host holding
        fewer than ``allowance(taken, limit)``.
        """
        return taken < limit * SHARES_FROM or self._held[host] < self.allowance(taken, limit)

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
