"""Connection limits, handshake checks and keepalive (D24, REF §1.1-1.2)."""

from __future__ import annotations

import contextlib
import json
import logging

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from rwt_transports.server import ServerConfig
from rwt_transports.websocket import WebSocketOptions
from tests.support.clients import is_op, running_server
from tests.support.rawws import NeverReading

pytestmark = pytest.mark.anyio


async def test_max_connections_counts_every_transport() -> None:
    async with running_server(ServerConfig(max_connections=2)) as harness:
        # stdio and memory would count too; the harness's stdio session is the first.
        with anyio.fail_after(10):
            ws = await harness.connect("ws")
            with pytest.raises(InvalidStatus) as refused:
                await harness.connect("ws", "second")
            assert refused.value.response.status_code == 503
            tcp = await harness.connect("tcp")
            assert (await tcp.expect(is_op("status")))["msg"] == "too many connections"
            with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
                await tcp.receive()
            udp = await harness.connect("udp")
            await udp.send({"op": "set_level", "level": "info"})
            assert (await udp.receive())["msg"] == "too many connections"
            await ws.send({"op": "set_level", "level": "info", "id": "still"})
            assert (await ws.expect(is_op("status", id="still")))["level"] == "info"
            assert len(harness.server.sessions) == 2


async def test_origins_and_url_path_are_checked_at_the_handshake() -> None:
    options = WebSocketOptions(url_path="/rosbridge", allowed_origins=("https://*.example.com",))
    async with running_server(ServerConfig(websocket=options)) as harness:
        base = f"ws://127.0.0.1:{harness.port('websocket')}"
        with anyio.fail_after(10):
            with pytest.raises(InvalidStatus) as wrong_path:
                await connect(f"{base}/")
            assert wrong_path.value.response.status_code == 404
            with pytest.raises(InvalidStatus) as wrong_origin:
                await connect(f"{base}/rosbridge", origin="https://evil.test")  # type: ignore[arg-type]
            assert wrong_origin.value.response.status_code == 403
            for origin in ("https://app.example.com", None):  # None: not a browser
                async with connect(f"{base}/rosbridge", origin=origin) as ws:  # type: ignore[arg-type]
                    await ws.send(json.dumps({"op": "set_level", "level": "info"}))
                    assert json.loads(await ws.recv())["level"] == "info"


async def test_a_websocket_message_over_the_limit_closes_with_1009() -> None:
    async with running_server(ServerConfig(max_message_size=1000)) as harness:
        with anyio.fail_after(10):
            async with connect(f"ws://127.0.0.1:{harness.port('websocket')}") as ws:
                await ws.send("x" * 2000)
                with pytest.raises(ConnectionClosed) as closed:
                    await ws.recv()
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1009


async def test_a_tcp_frame_over_the_limit_is_skipped_with_a_status() -> None:
    async with running_server(ServerConfig(max_message_size=1000)) as harness:
        with anyio.fail_after(10):
            tcp = await harness.connect("tcp")
            big = {"op": "publish", "topic": "/t", "msg": {"data": "}{" * 2000}}
            await tcp.send(big)
            status = await tcp.expect(is_op("status"))
            assert status["msg"] == "frame larger than 1000 bytes skipped"
            await tcp.send({"op": "set_level", "level": "info", "id": "next"})
            assert (await tcp.expect(is_op("status", id="next")))["level"] == "info"


async def test_a_peer_that_does_not_answer_pings_is_closed(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, "rwt")
    options = WebSocketOptions(ping_interval_s=0.1, ping_timeout_s=0.2)
    async with running_server(ServerConfig(websocket=options)) as harness:
        port = harness.port("websocket")
        silent = await NeverReading.connect(port, receive_buffer=None)
        try:
            with anyio.fail_after(10):
                while not harness.server.sessions.keys() - {"stdio:stdio#1"}:
                    await anyio.sleep(0.01)
                [client_id] = harness.server.sessions.keys() - {"stdio:stdio#1"}
                while client_id in harness.server.sessions:  # never reads: no pong
                    await anyio.sleep(0.05)
        finally:
            silent.close()
    assert any(
        "event=ping_timeout" in r.getMessage() and client_id in r.getMessage()
        for r in caplog.records
    )


async def test_clients_that_answer_pings_stay_connected() -> None:
    options = WebSocketOptions(ping_interval_s=0.05, ping_timeout_s=1.0)
    async with running_server(ServerConfig(websocket=options)) as harness:
        with anyio.fail_after(10):
            async with connect(f"ws://127.0.0.1:{harness.port('websocket')}") as ws:
                for i in range(10):  # spans many ping intervals
                    await ws.send(json.dumps({"op": "set_level", "level": "info", "id": i}))
                    assert json.loads(await ws.recv())["id"] == i
                    await anyio.sleep(0.05)


@pytest.mark.parametrize(
    ("request_bytes", "reason"),
    [
        (b"GARBAGE\r\n\r\n", b"did not receive a valid HTTP request"),
        (b"POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\n\r\nhi", b"valid HTTP request"),
        (b"GET /\xed\xa0\x80 HTTP/1.1\r\nHost: x\r\n\r\n", b"valid HTTP request"),
        (b"GET /" + b"a" * 100_000 + b" HTTP/1.1\r\nHost: x\r\n\r\n", b"expected no more than"),
    ],
    ids=["not-http", "post", "not-utf8-path", "huge-path"],
)
async def test_a_request_that_is_not_a_handshake_is_answered_400_at_once(
    request_bytes: bytes, reason: bytes
) -> None:
    """Not left waiting for the handshake timeout (10 s here): a 400 that says why."""
    async with running_server(ServerConfig(handshake_timeout_s=10)) as harness:
        with anyio.fail_after(5):
            async with await anyio.connect_tcp("127.0.0.1", harness.port("websocket")) as peer:
                await peer.send(request_bytes)
                answer = b""
                with contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError):
                    while True:
                        answer += await peer.receive()
        assert answer.startswith(b"HTTP/1.1 400 ")
        assert reason in answer
        ws = await harness.connect("ws")  # and the server serves the next client
        await ws.send({"op": "call_service", "service": "/rosapi/topics", "id": "after"})
        assert (await ws.expect(lambda m: m.get("id") == "after"))["result"] is True
