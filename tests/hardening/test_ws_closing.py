"""A WebSocket peer still sending when the server closes gets the close frame.

When the server fails a connection (here 1007, a text message that is not
UTF-8) while answers to the frames before it are still queued, it must keep
reading what the peer sends until the peer ends the connection (bounded by
``CLOSE_WAIT_S``), not close the socket at once: a socket closed with unread
bytes is reset by the kernel, the peer's next write fails, and a client whose
write failed (asyncio's transport, as websockets uses) stops reading and never
sees the close frame. B18 (benchmarks/README.md) met this as bursts that
"closed without a close frame" under load.
"""

from __future__ import annotations

import json
import socket
import time

import anyio.to_thread
import pytest
from websockets.client import ClientProtocol
from websockets.frames import Close
from websockets.uri import parse_uri

from rwt_transports import websocket
from tests.hardening.peers import TIMEOUT_S
from tests.support.clients import Harness

pytestmark = pytest.mark.anyio

ANSWERED = 20  # frames each answered with an error status, sent with the bad one
FILLER_BYTES = 16 * 1024 * 1024  # sent after the bad frame: far more than socket buffers hold
FILLER_FRAME = json.dumps({"op": "publish", "topic": "/f", "msg": {"data": "x" * 1000}}).encode()
TRIALS = 3


def _open(port: int) -> tuple[socket.socket, ClientProtocol]:
    """A raw socket and websockets' sans-IO client, the handshake done."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S)
    protocol = ClientProtocol(parse_uri(f"ws://127.0.0.1:{port}/"))
    protocol.send_request(protocol.connect())
    sock.sendall(b"".join(protocol.data_to_send()))
    while protocol.state.name != "OPEN":
        protocol.receive_data(sock.recv(65536))
        protocol.events_received()
    return sock, protocol


def _still_sending_peer(port: int, filler_bytes: int | None) -> tuple[str | None, Close | None]:
    """Send answered frames and a bad one in one write, keep sending, then read.

    ``filler_bytes``: how much to send after the bad frame; None: until a write
    fails (at most ``TIMEOUT_S``). Returns the error of those writes (None: all
    taken) and the server's close frame (None: the connection ended without one).
    """
    sock, protocol = _open(port)
    try:
        for i in range(ANSWERED):
            protocol.send_text(json.dumps({"op": "no_such_op", "id": f"q{i}"}).encode())
        protocol.send_text(b'{"op":"publish","topic":"/f","msg":{"data":"\xff"}}')
        sock.sendall(b"".join(protocol.data_to_send()))  # one write: one chunk for the server
        write_error = None
        try:  # a client that has not read the close frame yet goes on sending
            sent, give_up = 0, time.monotonic() + TIMEOUT_S  # a guard against hanging
            while sent < (filler_bytes or sent + 1) and time.monotonic() < give_up:
                protocol.send_text(FILLER_FRAME)
                sock.sendall(b"".join(protocol.data_to_send()))
                sent += len(FILLER_FRAME)
        except OSError as exc:
            write_error = repr(exc)
        while protocol.close_rcvd is None:
            try:
                data = sock.recv(65536)
            except OSError:
                break
            if not data:
                break
            protocol.receive_data(data)
            protocol.events_received()
        return write_error, protocol.close_rcvd
    finally:
        sock.close()


async def test_a_peer_still_sending_is_read_until_it_sees_the_close(harness: Harness) -> None:
    port = harness.port("websocket")
    for _ in range(TRIALS):
        write_error, close = await anyio.to_thread.run_sync(_still_sending_peer, port, FILLER_BYTES)
        assert write_error is None  # the server read on: the connection was not reset
        assert close is not None and close.code == 1007
    # the server serves the next client
    client = await harness.connect("ws")
    await client.send({"op": "set_level", "level": "info", "id": "after"})
    reply = await client.receive()
    assert reply["op"] == "status" and reply["id"] == "after"


async def test_a_peer_that_never_stops_sending_is_cut_after_the_close_wait(
    harness: Harness, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The wait for the peer's end is bounded (``CLOSE_WAIT_S``): the socket is then closed."""
    monkeypatch.setattr(websocket, "CLOSE_WAIT_S", 0.5)
    port = harness.port("websocket")
    write_error, close = await anyio.to_thread.run_sync(_still_sending_peer, port, None)
    assert write_error is not None  # cut while it was still sending
    assert close is not None and close.code == 1007
