"""Fixtures for the Python client: an in-process rwt server per test."""

from __future__ import annotations

from collections.abc import AsyncIterator

import anyio
import pytest

from rwt_transports.server import RosbridgeServer, ServerConfig


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


@pytest.fixture(params=["ws", "tcp"])
def transport(request: pytest.FixtureRequest) -> str:
    if request.param == "tcp" and not hasattr(ServerConfig(), "tcp_port"):
        pytest.skip("rwt serves TCP with issue 5")
    return str(request.param)


@pytest.fixture
async def url(transport: str) -> AsyncIterator[str]:
    """The URL of a fresh in-process server over ``transport``."""
    server = RosbridgeServer(config=ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        ws_url = await tg.start(server.serve)
        yield ws_url if transport == "ws" else ws_url.replace("ws://", "tcp://")
        tg.cancel_scope.cancel()
