"""TLS on WebSocket (wss) and TCP with a certificate made in the test (--certfile, --keyfile)."""

from __future__ import annotations

import contextlib
import json
import socket
import ssl
import threading
from pathlib import Path

import anyio
import anyio.to_thread
import pytest
from websockets.sync.client import connect

from tests.support.clients import Harness, is_op
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio

CHURN_CONNECTIONS = 400
"""wss connections opened one after another (a lost upgrade request: one in a few hundred)."""
TCP_CHURN_CONNECTIONS = 500
"""TLS over TCP exchanges of the threaded client below (a lost first op: about one in 200)."""
OPEN_S = 30.0
"""Far past the handshake timeout (10 s), which ends a stalled wss connection with an error."""


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


async def test_threaded_wss_clients_always_get_their_upgrade_answered(
    tls_harness: Harness,
) -> None:
    """websockets' sync client reads in a thread of its own while it writes its request.

    TLS 1.3 session tickets arriving then made it lose its upgrade request now and
    then: the connection waited for the handshake timeout, which closed it, and
    ``connect`` failed (server.py, ``_tls_context``). Every connection must open,
    each closed before the next.
    """
    url = f"wss://127.0.0.1:{tls_harness.port('websocket')}"
    context = tls_harness.ssl_context

    def churn() -> int:
        opened = 0
        for _ in range(CHURN_CONNECTIONS):
            with connect(url, ssl=context, open_timeout=OPEN_S) as ws:
                opened += ws.protocol.state.name == "OPEN"
        return opened

    assert await anyio.to_thread.run_sync(churn) == CHURN_CONNECTIONS


def _threaded_tls_exchange(port: int, context: ssl.SSLContext, op: bytes) -> bytes:
    """One rosbridge TCP+TLS exchange by a client that reads in a thread of its own.

    From the end of the TLS handshake a reader thread waits for the reply, on a
    blocking socket as a client's receive thread does, while this thread writes
    ``op``. (With a socket timeout, Python's ``ssl`` retries non-blocking reads,
    and a write at the same time can make such a read report an end that never
    came: the client's own race, not the server's.) Returns the reply (one JSON
    line); raises ``TimeoutError`` if none comes within ``OPEN_S``.
    """
    raw = socket.create_connection(("127.0.0.1", port), timeout=OPEN_S)
    raw.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # no 40 ms wait for an ack
    with context.wrap_socket(raw, server_hostname="127.0.0.1") as sock:
        sock.settimeout(None)
        replies: list[bytes] = []

        def read() -> None:
            reply = b""
            with contextlib.suppress(OSError):
                while not reply.endswith(b"\n"):  # one JSON a line
                    chunk = sock.recv(1 << 16)
                    if not chunk:
                        return
                    reply += chunk
                replies.append(reply)

        reader = threading.Thread(target=read)
        reader.start()
        sock.sendall(op)
        reader.join(OPEN_S)
        if reader.is_alive():  # no reply: wake the reader (the kernel socket, not TLS)
            with socket.fromfd(sock.fileno(), sock.family, sock.type) as same:
                same.shutdown(socket.SHUT_RDWR)
            reader.join()
    if not replies:
        raise TimeoutError(f"no reply to the first op within {OPEN_S} s")
    return replies[0]


async def test_threaded_tls_tcp_clients_always_get_their_first_op_read(
    tls_harness: Harness,
) -> None:
    """The same over TLS on TCP: the reply to a client's first op always comes."""
    port = tls_harness.port("tcp")
    context = tls_harness.ssl_context
    assert context is not None
    op = json.dumps({"op": "set_level", "level": "info", "id": "first"}).encode()

    def churn() -> int:
        return sum(
            json.loads(_threaded_tls_exchange(port, context, op))["id"] == "first"
            for _ in range(TCP_CHURN_CONNECTIONS)
        )

    assert await anyio.to_thread.run_sync(churn) == TCP_CHURN_CONNECTIONS
