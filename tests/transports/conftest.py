"""Fixtures of the transport tests: a TLS server with a certificate made in the test."""

from __future__ import annotations

import ssl
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest
import trustme

from rwt_transports.server import ServerConfig
from tests.transports.clients import Harness, running_server


@pytest.fixture
def ca() -> trustme.CA:
    return trustme.CA()


@pytest.fixture
def tls_files(ca: trustme.CA, tmp_path: Path) -> Iterator[tuple[Path, Path, Path]]:
    cert = ca.issue_cert("127.0.0.1", "localhost")
    certfile, keyfile, cafile = tmp_path / "cert.pem", tmp_path / "key.pem", tmp_path / "ca.pem"
    cert.cert_chain_pems[0].write_to_path(certfile)
    cert.private_key_pem.write_to_path(keyfile)
    ca.cert_pem.write_to_path(cafile)
    yield certfile, keyfile, cafile


@pytest.fixture
async def tls_harness(tls_files: tuple[Path, Path, Path], ca: trustme.CA) -> AsyncIterator[Harness]:
    certfile, keyfile, _ = tls_files
    async with running_server(ServerConfig(certfile=certfile, keyfile=keyfile)) as harness:
        context = ssl.create_default_context()
        ca.configure_trust(context)
        harness.ssl_context = context
        yield harness
