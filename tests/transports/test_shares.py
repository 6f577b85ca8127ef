"""Per-host shares of the connection slots (docs/limits.md, rwt_transports.admission.shares)."""

from __future__ import annotations

import pytest

from rwt_protocol.errors import ConfigError
from rwt_transports.admission.shares import HostPrefixes, HostShares
from rwt_transports.server import RosbridgeServer, ServerConfig


def test_by_default_an_ipv4_address_is_a_host_and_ipv6_counts_by_its_64() -> None:
    host = HostPrefixes().host
    assert host("192.0.2.7") == "192.0.2.7"
    assert host("192.0.2.7") != host("192.0.2.8")
    assert host("::ffff:192.0.2.7") == "192.0.2.7"
    assert host("2001:db8:1:2:aaaa::1") == host("2001:db8:1:2:bbbb::9") == "2001:db8:1:2::/64"
    assert host("[2001:db8:1:2::1]") == "2001:db8:1:2::/64"
    assert host("fe80::1%eth0") == "fe80::/64"
    assert host("2001:db8:1:2::1") != host("2001:db8:1:3::1")
    assert host("::1") == "::/64"
    assert host("stdio") == "stdio"
    assert host("unknown") == "unknown"


def test_an_ipv4_prefix_makes_a_network_one_host() -> None:
    host = HostPrefixes(v4=24).host
    assert host("127.0.0.1") == host("127.0.0.2") == host("127.0.0.3") == "127.0.0.0/24"
    assert host("127.0.1.1") == "127.0.1.0/24"
    assert host("::ffff:127.0.0.9") == "127.0.0.0/24"  # a dual-stack socket's IPv4 client
    assert host("2001:db8:1:2::1") == "2001:db8:1:2::/64"  # IPv6 keeps its own prefix
    assert HostPrefixes(v4=8).host("127.200.3.4") == "127.0.0.0/8"
    assert HostPrefixes(v4=0).host("198.51.100.1") == "0.0.0.0/0"


def test_an_ipv6_prefix_is_configurable() -> None:
    by_48 = HostPrefixes(v6=48).host
    assert by_48("2001:db8:1:2::1") == by_48("2001:db8:1:3::1") == "2001:db8:1::/48"
    assert HostPrefixes(v6=128).host("2001:db8:1:2::1") == "2001:db8:1:2::1"
    assert HostPrefixes(v6=128).host("::1") != HostPrefixes(v6=128).host("::2")
    assert HostPrefixes(v6=128).host("::ffff:192.0.2.7") == "192.0.2.7"


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"host_prefix_v4": 33}, "--host-prefix-v4 must be 0 to 32 bits, not 33"),
        ({"host_prefix_v4": -1}, "--host-prefix-v4 must be 0 to 32 bits, not -1"),
        ({"host_prefix_v6": 129}, "--host-prefix-v6 must be 0 to 128 bits, not 129"),
    ],
)
def test_an_embedding_config_with_a_bad_prefix_is_refused(
    fields: dict[str, int], message: str
) -> None:
    with pytest.raises(ConfigError) as refused:
        RosbridgeServer(config=ServerConfig(port=None, rosapi=False, tf=False, **fields))
    assert str(refused.value) == message


def test_shares_apply_only_past_three_quarters_of_the_slots() -> None:
    shares = HostShares(share=2)
    for _ in range(5):
        shares.add("a")
    assert shares.admits("a", taken=5, limit=8)  # below 6 of 8: anyone
    assert not shares.admits("a", taken=6, limit=8)  # past it: "a" holds its share
    assert shares.admits("b", taken=6, limit=8)
    for _ in range(4):
        shares.remove("a")
    assert shares.admits("a", taken=6, limit=8) and shares.held("a") == 1


def test_past_three_quarters_a_hosts_share_is_at_most_the_free_slots() -> None:
    shares = HostShares(share=64)  # the default, above the slots: the free ones bound it
    assert shares.allowance(taken=30, limit=40) == 10
    assert shares.allowance(taken=39, limit=40) == 1
    assert HostShares(share=2).allowance(taken=30, limit=40) == 2
    for _ in range(10):
        shares.add("a")
    assert not shares.admits("a", taken=30, limit=40)  # holds as many as are free
    taken = 30
    while shares.admits("b", taken=taken, limit=40):  # a newcomer: half the free slots
        shares.add("b")
        taken += 1
    assert shares.held("b") == 5
    while shares.admits("c", taken=taken, limit=40):
        shares.add("c")
        taken += 1
    assert (shares.held("c"), taken) == (3, 38)
    assert not shares.admits("b", taken=39, limit=40)  # the last slot: only a host with none
    assert shares.admits("d", taken=39, limit=40)
