"""Z3 at the link's harness (benchmarks/zenoh_link.py) runs each pair and counts all."""

from __future__ import annotations

import asyncio

from benchmarks.scaleout import link_level
from benchmarks.zenoh_link import rclpy_available


def test_link_bare_and_rclpy_pairs_deliver_every_message() -> None:
    pair = asyncio.run(link_level(100, 300, 1))
    kinds = {"link", "bare", "rclpy"} if rclpy_available() else {"link", "bare"}
    assert set(pair) == kinds
    for kind in kinds:
        assert (pair[kind]["got"], pair[kind]["sent"]) == (300, 300), kind
        assert pair[kind]["msg_per_s"] > 0
