"""Per-host shares of the connection slots (docs/limits.md, rwt_transports.shares)."""

from __future__ import annotations

from rwt_transports.shares import HostShares, host_key


def test_hosts_are_ips_ipv6_by_its_64_prefix() -> None:
    assert host_key("192.0.2.7") == "192.0.2.7"
    assert host_key("::ffff:192.0.2.7") == "192.0.2.7"
    assert host_key("2001:db8:1:2:aaaa::1") == host_key("2001:db8:1:2:bbbb::9")
    assert host_key("2001:db8:1:2::1") != host_key("2001:db8:1:3::1")
    assert host_key("stdio") == "stdio"


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
