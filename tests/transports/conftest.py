"""Fixtures of the transport tests: a TLS server (tests/conftest.py makes its certificate)."""

from __future__ import annotations

import ssl
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
import trustme

from rwt_transports.server import ServerConfig
from tests.support.clients import Harness, running_server


@pytest.fixture
async def tls_harness(tls_files: tuple[Path, Path, Path], ca: trustme.CA) -> AsyncIterator[Harness]:
    certfile, keyfile, _ = tls_files
    async with running_server(ServerConfig(certfile=certfile, keyfile=keyfile)) as harness:
        context = ssl.create_default_context()
        ca.configure_trust(context)
        harness.ssl_context = context
        yield harness
