"""Fixtures for the Python client: an in-process rwt server per test."""

from __future__ import annotations

from collections.abc import AsyncIterator

import anyio
import pytest

from rwt_transports.server import RosbridgeServer, ServerConfig


@pytest.fixture(params=["ws", "tcp"])
def transport(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
async def url(transport: str) -> AsyncIterator[str]:
    """The URL of a fresh in-process server over ``transport``."""
    server = RosbridgeServer(config=ServerConfig(port=0, tcp_port=0))
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        yield server.urls["websocket" if transport == "ws" else "tcp"]
        tg.cancel_scope.cancel()
