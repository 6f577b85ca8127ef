"""Blocking rosbridge peers on their own threads, for hardening tests of the flow of input.

The in-process server runs on the test's event loop; these peers run in worker
threads (``anyio.to_thread.run_sync``), so a publisher really sends as fast as
TCP allows and a subscriber reads as fast as it can, as separate programs would.
Every socket has a timeout, so a broken server fails the test instead of hanging it.
"""

from __future__ import annotations

import json
from collections import deque
from contextlib import ExitStack
from typing import Any

from websockets.sync.client import ClientConnection, connect

from benchmarks import trickling_readers

Message = dict[str, Any]
TIMEOUT_S = 60.0


class TcpPeer(trickling_readers.TcpPeer):
    """rosbridge over TCP: JSON values out, JSON lines in."""

    def __init__(self, port: int, rcvbuf: int | None = None) -> None:
        super().__init__(port, rcvbuf)
        self.sock.settimeout(TIMEOUT_S)
        self._buffer = b""
        self._lines: deque[bytes] = deque()

    def send_raw(self, data: bytes) -> None:
        self.sock.sendall(data)

    def receive(self) -> Message:
        while not self._lines:
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                raise EOFError("the server closed the connection")
            *lines, self._buffer = (self._buffer + chunk).split(b"\n")
            self._lines.extend(lines)
        return json.loads(self._lines.popleft())  # type: ignore[no-any-return]


class WsPeer:
    """rosbridge over WebSocket (websockets' blocking client)."""

    def __init__(self, port: int) -> None:
        self._stack = ExitStack()  # websockets wants its connection used as a context
        self.ws: ClientConnection = self._stack.enter_context(
            connect(f"ws://127.0.0.1:{port}", open_timeout=TIMEOUT_S, max_size=None)
        )

    def send(self, op: Message) -> None:
        self.ws.send(json.dumps(op))

    def receive(self) -> Message:
        return json.loads(self.ws.recv(timeout=TIMEOUT_S))  # type: ignore[no-any-return]

    def close(self) -> None:
        self._stack.close()


Peer = TcpPeer | WsPeer


def open_peer(transport: str, ports: dict[str, int], rcvbuf: int | None = None) -> Peer:
    """A peer on ``transport`` (``ws`` or ``tcp``) of the server listening on ``ports``.

    ``rcvbuf`` sets a TCP peer's kernel receive buffer (bytes), so the kernel
    does not absorb what a slow reader has not read yet.
    """
    return WsPeer(ports["websocket"]) if transport == "ws" else TcpPeer(ports["tcp"], rcvbuf)


def settle(peer: Peer, tag: str) -> None:
    """Wait until the server handled every op ``peer`` sent before: ops of one
    connection are handled in order, so the answer to a rosapi call comes after."""
    peer.send({"op": "call_service", "service": "/rosapi/topics", "id": tag})
    while True:
        message = peer.receive()
        if message.get("op") == "service_response" and message.get("id") == tag:
            return
