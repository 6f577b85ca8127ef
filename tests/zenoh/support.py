"""Helpers of the Zenoh tests: loopback endpoints on free ports, checked configs.

Every Zenoh config a test uses goes through ``checked``: multicast scouting off
and no endpoint outside 127.0.0.0/8, so the tests never talk to another machine.
"""

from __future__ import annotations

import json
import socket
from typing import TYPE_CHECKING

import anyio

from rwt_zenoh.config import ZenohOptions, is_loopback_endpoint, make_config

if TYPE_CHECKING:
    from collections.abc import Callable

WAIT_S = 10.0
"""Every wait of a test for the network is bounded by this (seconds)."""


async def until(condition: Callable[[], bool], what: str = "the condition") -> None:
    """Poll ``condition`` every 20 ms until it holds.

    Raises:
        TimeoutError: it did not hold within ``WAIT_S`` (the message names ``what``).
    """
    try:
        with anyio.fail_after(WAIT_S):
            while not condition():
                await anyio.sleep(0.02)
    except TimeoutError:
        raise TimeoutError(f"no {what} within {WAIT_S} s") from None


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def endpoint(port: int | None = None) -> str:
    """``tcp/127.0.0.1:<port>``, a free port by default."""
    return f"tcp/127.0.0.1:{free_port() if port is None else port}"


def checked(options: ZenohOptions) -> ZenohOptions:
    """``options`` after asserting that its Zenoh config stays on loopback, multicast off."""
    config = make_config(options)
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    for section in ("listen/endpoints", "connect/endpoints"):
        endpoints = json.loads(config.get_json(section))
        if isinstance(endpoints, dict):  # per-mode form: {"peer": [...], ...}: this mode's
            endpoints = endpoints.get(options.mode, [])
        assert all(is_loopback_endpoint(e) for e in endpoints), endpoints
    return options


def peer(*, listen: str | None = None, connect: tuple[str, ...] = ()) -> ZenohOptions:
    """Checked peer options listening on ``listen`` and connecting to ``connect``."""
    return checked(
        ZenohOptions(listen=() if listen is None else (listen,), connect=connect, domain_id=0)
    )
