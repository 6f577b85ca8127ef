"""A WebSocket text message that is not UTF-8 closes the connection with 1007 (RFC 6455 8.1).

Both of the server's readers are covered: a whole text frame (read ahead of
websockets by ``FrameReader``) and a fragmented text message (assembled from
websockets' frames), invalid bytes inside one fragment or split across two.
Valid non-ASCII text is served. After each, the server serves the next client.
"""

from __future__ import annotations

import json
import socket

import anyio
import anyio.to_thread
import pytest
from websockets.client import ClientProtocol
from websockets.frames import Close
from websockets.uri import parse_uri

from tests.hardening.peers import TIMEOUT_S, WsPeer, settle
from tests.support.clients import Harness

pytestmark = pytest.mark.anyio


class RawWs:
    """A WebSocket client that can send any bytes as text (websockets' sans-IO client)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S)
        self.protocol = ClientProtocol(parse_uri(f"ws://127.0.0.1:{port}/"))
        self.protocol.send_request(self.protocol.connect())
        self._flush()
        while self.protocol.handshake_exc is None and not self._opened():
            self.protocol.receive_data(self.sock.recv(65536))
            self.protocol.events_received()

    def _opened(self) -> bool:
        return self.protocol.state.name == "OPEN"

    def _flush(self) -> None:
        for data in self.protocol.data_to_send():
            if data:
                self.sock.sendall(data)

    def send_text(self, *parts: bytes) -> None:
        """One text message of ``parts`` (fragmented when more than one), unchecked."""
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            if i == 0:
                self.protocol.send_text(part, fin=last)
            else:
                self.protocol.send_continuation(part, fin=last)
        self._flush()

    def texts_until_close(self) -> tuple[list[str], Close | None]:
        """The text messages received, then the server's close frame (None: no close frame)."""
        texts: list[str] = []
        while self.protocol.close_rcvd is None:
            data = self.sock.recv(65536)
            if not data:
                break
            self.protocol.receive_data(data)
            for event in self.protocol.events_received():
                if isinstance(event.data, bytes) and event.opcode.name == "TEXT":
                    texts.append(event.data.decode())
        self._flush()
        self.sock.close()
        return texts, self.protocol.close_rcvd


def publish(text: str) -> bytes:
    return json.dumps({"op": "publish", "topic": "/u", "msg": {"data": text}}).encode()


CASES = {
    "whole frame": (b'{"op":"publish","topic":"/u","msg":{"data":"\xff"}}',),
    "one fragment": (b'{"op":"publish",', b'"topic":"/u","msg":{"data":"\xc3\x28"}}'),
    "split sequence": (b'{"op":"publish","topic":"/u","msg":{"data":"\xe2\x82', b'"}}'),
}


@pytest.mark.parametrize("parts", CASES.values(), ids=list(CASES))
async def test_invalid_utf8_text_closes_with_1007(harness: Harness, parts: tuple[bytes]) -> None:
    port = harness.port("websocket")

    def run() -> tuple[list[str], Close | None]:
        client = RawWs(port)
        client.send_text(*parts)
        return client.texts_until_close()

    with anyio.fail_after(60):
        _, close = await anyio.to_thread.run_sync(run)
        assert close is not None and close.code == 1007
        # The server serves the next client.
        late = await anyio.to_thread.run_sync(WsPeer, port)
        await anyio.to_thread.run_sync(settle, late, "late")
        await anyio.to_thread.run_sync(late.close)  # its close handshake needs the loop


async def test_valid_non_ascii_text_is_served(harness: Harness) -> None:
    port = harness.port("websocket")

    def run() -> str:
        client = RawWs(port)
        client.send_text(b'{"op":"subscribe","topic":"/u","type":"std_msgs/String"}')
        client.send_text(b'{"op":"advertise","topic":"/u","type":"std_msgs/String"}')
        data = "h\u00e9 \u20ac \U0001f600".encode()
        client.send_text(b'{"op":"publish","topic":"/u","msg":{"data":"', data + b'"}}')
        while True:
            client.protocol.receive_data(client.sock.recv(65536))
            for event in client.protocol.events_received():
                message = json.loads(event.data)
                if message.get("op") == "publish":
                    client.sock.close()
                    return str(message["msg"]["data"])

    with anyio.fail_after(60):
        assert await anyio.to_thread.run_sync(run) == "h\u00e9 \u20ac \U0001f600"
