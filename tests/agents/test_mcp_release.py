"""A 2026-07-28 request's server goes when its request does, without the cyclic collector.

Each such request builds an MCP server (``rwt_mcp.tools.build_server``); left as a cycle,
a flood's servers were collected in batches that stopped the event loop for every other
client (benchmarks B25). ``release_server`` empties it once it answers nothing more.
"""

from __future__ import annotations

import gc
import weakref

import pytest

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from rwt_mcp.link import RobotLink
from rwt_mcp.tools import build_server, release_server


def _built() -> weakref.ref[object]:
    server, _ = build_server(RobotLink("ws://127.0.0.1:9"))
    release_server(server)
    return weakref.ref(server)


def _kept() -> weakref.ref[object]:
    server, _ = build_server(RobotLink("ws://127.0.0.1:9"))
    return weakref.ref(server)


def test_a_released_server_is_freed_by_its_last_reference() -> None:
    gc.collect()
    gc.disable()
    try:
        released, kept = _built(), _kept()
        assert released() is None  # gone as the function returned
        assert kept() is not None  # a cycle: it waits for the collector (what was fixed)
    finally:
        gc.enable()
    gc.collect()
    assert kept() is None
