"""Fixtures of the hardening tests: asyncio, and a server on every transport."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from tests.support.clients import Harness, running_server


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    """A default server with WebSocket, TCP, UDP, stdio and in-memory connections."""
    async with running_server() as h:
        yield h
