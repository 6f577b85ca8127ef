"""WebSocket subscribers on their own threads, for the links' per-topic holds.

``SlowReader`` subscribes over a raw socket with a small receive buffer and
reads 64 KB every 0.5 s: a viewer on a slow network, far behind a camera.
``Bystander`` subscribes with websockets' blocking client, reads as fast as
it can and notes when each message came, so a test can tell how long its
topic stood still (``Bystander.frozen``).
"""

from __future__ import annotations

import itertools
import json
import socket
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

from websockets.client import ClientProtocol
from websockets.frames import Frame, Opcode
from websockets.sync.client import connect
from websockets.uri import parse_uri

TIMEOUT_S = 30.0
SMALL_RCVBUF = 16 * 1024


def _address(url: str) -> tuple[str, int]:
    host, port = url.removeprefix("ws://").rstrip("/").rsplit(":", 1)
    return host, int(port)


class SlowReader:
    """Subscribes to ``topic`` and reads ``chunk`` bytes every ``period_s`` on a thread.

    ``received`` counts the bytes read (frames are not parsed).
    """

    def __init__(
        self, url: str, topic: str, type_name: str, chunk: int = 64 * 1024, period_s: float = 0.5
    ) -> None:
        self.received = 0
        self._stop = threading.Event()
        sock = self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SMALL_RCVBUF)
        sock.settimeout(TIMEOUT_S)
        sock.connect(_address(url))
        protocol = ClientProtocol(parse_uri(url))
        protocol.send_request(protocol.connect())
        for data in protocol.data_to_send():
            sock.sendall(data)
        while protocol.handshake_exc is None and not protocol.events_received():
            protocol.receive_data(sock.recv(4096))
        assert protocol.handshake_exc is None, protocol.handshake_exc
        subscribe = {"op": "subscribe", "topic": topic, "type": type_name}
        protocol.send_frame(Frame(Opcode.TEXT, json.dumps(subscribe).encode()))
        for data in protocol.data_to_send():
            sock.sendall(data)
        self._thread = threading.Thread(target=self._read, args=(chunk, period_s), daemon=True)
        self._thread.start()

    def _read(self, chunk: int, period_s: float) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(chunk)
            except OSError:
                return
            if not data:
                return
            self.received += len(data)
            self._stop.wait(period_s)

    def close(self) -> None:
        self._stop.set()
        self.sock.close()
        self._thread.join(TIMEOUT_S)


@dataclass(frozen=True, slots=True)
class Frozen:
    """How long a topic stood still in a window: its longest gap and the gaps' sum (s)."""

    longest_s: float
    total_s: float
    window_s: float
    messages: int


class Bystander:
    """Subscribes to ``topic`` and notes each message's arrival (``time.monotonic``)."""

    def __init__(self, url: str, topic: str, type_name: str) -> None:
        self.arrivals: list[float] = []
        self.data: list[Any] = []
        self._stack = ExitStack()
        self._ws = self._stack.enter_context(connect(url, open_timeout=TIMEOUT_S, max_size=None))
        self._ws.send(json.dumps({"op": "subscribe", "topic": topic, "type": type_name}))
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            for text in self._ws:
                message = json.loads(text)
                if message.get("op") == "publish":
                    self.arrivals.append(time.monotonic())
                    self.data.append(message["msg"])
        except Exception:  # closed by the test: arrivals end there
            return

    def frozen(self, start: float, end: float, still_s: float) -> Frozen:
        """The gaps between ``start`` and ``end`` (monotonic) longer than ``still_s``."""
        times = [start, *(t for t in self.arrivals if start < t < end), end]
        gaps = [b - a for a, b in itertools.pairwise(times)]
        still = [gap for gap in gaps if gap > still_s]
        return Frozen(max(gaps), sum(still), end - start, len(times) - 2)

    def close(self) -> None:
        self._stack.close()
        self._thread.join(TIMEOUT_S)


def wait_until(check: Any, what: str, within: float = TIMEOUT_S) -> None:
    """Poll ``check()`` until true (AssertionError naming ``what`` past ``within`` s)."""
    deadline = time.monotonic() + within
    while not check():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)
