"""TLS on WebSocket (wss) and TCP with a certificate made in the test (--certfile, --keyfile)."""

from __future__ import annotations

import ssl
from pathlib import Path

import anyio
import pytest

from tests.transports.clients import Harness
from tests.transports.realclients import run_python
from tests.transports.test_contract import is_op

pytestmark = pytest.mark.anyio


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


async def test_urls_say_tls(tls_harness: Harness) -> None:
    assert tls_harness.server.urls["websocket"].startswith("wss://")
    assert tls_harness.server.urls["tcp"].startswith("tcp+tls://")


async def test_wss_and_tls_tcp_clients_share_the_graph(tls_harness: Harness) -> None:
    ws = await tls_harness.connect("ws")
    tcp = await tls_harness.connect("tcp")
    with anyio.fail_after(10):
        await ws.send({"op": "subscribe", "topic": "/secure", "type": "std_msgs/String"})
        await ws.send({"op": "set_level", "level": "info", "id": "b"})
        await ws.expect(is_op("status", id="b"))
        await tcp.send({"op": "publish", "topic": "/secure", "msg": {"data": "sealed"}})
        message = await ws.expect(is_op("publish"))
    assert message["msg"] == {"data": "sealed"}


async def test_a_client_that_does_not_trust_the_certificate_fails_and_others_go_on(
    tls_harness: Harness,
) -> None:
    untrusting = ssl.create_default_context()
    with anyio.fail_after(10):
        with pytest.raises(ssl.SSLCertVerificationError):
            await anyio.connect_tcp("127.0.0.1", tls_harness.port("tcp"), ssl_context=untrusting)
        plain = await anyio.connect_tcp("127.0.0.1", tls_harness.port("websocket"))
        await plain.send(b"GET / HTTP/1.1\r\n\r\n")  # not TLS at all
        with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError, OSError)):
            await plain.receive()
        await plain.aclose()
        ws = await tls_harness.connect("ws")
        await ws.send({"op": "set_level", "level": "info", "id": "ok"})
        assert (await ws.expect(is_op("status", id="ok")))["level"] == "info"


async def test_roslibpy_connects_over_wss(
    tls_harness: Harness, tls_files: tuple[Path, Path, Path]
) -> None:
    _, _, cafile = tls_files
    graph = tls_harness.server.graph
    graph.create_service(
        "/add", "example_interfaces/srv/AddTwoInts", lambda r: {"sum": r["a"] + r["b"]}
    )
    port = tls_harness.port("websocket")
    out = await run_python(
        f"""
        import roslibpy
        ros = roslibpy.Ros("127.0.0.1", {port}, is_secure=True, transport="asyncio")
        ros.run(timeout=20)
        service = roslibpy.Service(ros, "/add", "example_interfaces/AddTwoInts")
        print(service.call(roslibpy.ServiceRequest({{"a": 2, "b": 3}}), timeout=20)["sum"])
        ros.terminate()
        """,
        env={"SSL_CERT_FILE": str(cafile)},
    )
    assert out.split() == ["5"]
