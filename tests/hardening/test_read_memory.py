"""What a connection keeps after one large frame: the server's RSS (docs/limits.md).

Before, the pump kept the last batch of frames it had read while it waited for
the next: a TCP or WebSocket connection that sent one 10 MB frame (a refused
``publish``, or the first part of a ``fragment``ed message, refused or dropped)
held 10 MB for as long as it stayed open, 1.2 GB for 120 of them.
Measured on ``rwt serve`` in a subprocess, as a user sees it (VmRSS in /proc).
"""

from __future__ import annotations

import itertools
import json
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest
from websockets.sync.client import ClientConnection, connect

from tests.support.cli import RWT_COLD as RWT  # its pid and memory are the server's own
from tests.support.realclients import REPO

MiB = 1024 * 1024
# Of each transport: a 10 MB frame kept by each would be 600 MB, while the heap the
# allocator may keep (``--heap-keep``, 16 MiB here, 64 by default) is at most 0.3 MiB
# a connection.
CONNECTIONS = 30
HEAP_KEEP_MIB = 4
FRAME_CHARS = 10_000_000
PER_CONNECTION_BOUND = 1 * MiB  # average; measured 0.05 MB (80 each) to 0.3 MB (120 each)
# First parts are dropped at once, so that they never fill the budget of incomplete
# messages, which frames still arriving also draw from (test_partial_frames.py).
FRAGMENT_TIMEOUT_S = 0.001
TIMEOUT_S = 60.0
ENV = {**os.environ, "PYTHONPATH": f"{REPO / 'src'}{os.pathsep}{REPO}", "PYTHONUNBUFFERED": "1"}


def rss(pid: int) -> int:
    """The resident set of process ``pid`` now, bytes (VmRSS)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError(f"no VmRSS for {pid}")


@contextmanager
def rwt_serve() -> Iterator[tuple[int, dict[str, int]]]:
    """``rwt serve`` with WebSocket and TCP on free ports: its pid and ports by scheme."""
    args = ["--host", "127.0.0.1", "--port", "0", "--tcp-port", "0", "--log-level", "error"]
    args += ["--fragment-timeout", str(FRAGMENT_TIMEOUT_S), "--heap-keep", str(HEAP_KEEP_MIB)]
    process = subprocess.Popen(
        [*RWT, "serve", *args],
        env=ENV,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert process.stdout is not None
        ports: dict[str, int] = {}
        while len(ports) < 2:
            line = process.stdout.readline().decode()
            assert line, "rwt serve ended before listening"
            if line.startswith("listening on "):
                url = line.removeprefix("listening on ").strip()
                ports[url.split("://")[0]] = int(url.rsplit(":", 1)[1].split("/")[0])
        yield process.pid, ports
    finally:
        process.kill()
        process.wait(TIMEOUT_S)
        if process.stdout is not None:
            process.stdout.close()


def large_frames() -> Iterator[bytes]:
    """10 MB frames, alternately a refused ``publish`` and a first ``fragment`` part (dropped)."""
    data = "x" * FRAME_CHARS
    publish = {"op": "publish", "id": "big", "topic": "/client_count", "msg": {"data": data}}
    part = {"op": "fragment", "id": "big", "data": data, "num": 0, "total": 2}
    frames = (json.dumps(publish).encode(), json.dumps(part).encode())
    for i in range(CONNECTIONS):
        yield frames[i % 2]


SYNC = json.dumps({"op": "set_level", "level": "info", "id": "sync"})


def tcp_peer(port: int, frame: bytes) -> socket.socket:
    """A TCP connection that sent ``frame``, once the server has handled it."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S)
    sock.sendall(frame + SYNC.encode())
    received = b""
    while b'"sync"' not in received:
        chunk = sock.recv(65536)
        assert chunk, "the server closed the connection"
        received += chunk
    return sock


def ws_peer(port: int, frame: bytes, stack: ExitStack) -> ClientConnection:
    """A WebSocket connection that sent ``frame``, once the server has handled it."""
    ws = stack.enter_context(connect(f"ws://127.0.0.1:{port}", open_timeout=TIMEOUT_S))
    ws.send(frame.decode())
    ws.send(SYNC)
    while '"sync"' not in str(ws.recv(timeout=TIMEOUT_S)):
        pass
    return ws


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_connections_that_sent_one_large_frame_hold_little_afterwards() -> None:
    with rwt_serve() as (pid, ports), ExitStack() as stack:
        # the code paths and the buffers any large frame leaves once, on both transports
        for frame in itertools.islice(large_frames(), 2):
            stack.callback(tcp_peer(ports["tcp"], frame).close)
            ws_peer(ports["ws"], frame, stack)
        before = rss(pid)
        for frame in large_frames():
            stack.callback(tcp_peer(ports["tcp"], frame).close)
        for frame in large_frames():
            ws_peer(ports["ws"], frame, stack)
        grown = rss(pid) - before
    per_connection = grown / (2 * CONNECTIONS)
    print(f"{per_connection / MiB:.3f} MiB a connection")  # shown with -s
    assert per_connection < PER_CONNECTION_BOUND, f"{per_connection / MiB:.2f} MiB a connection"
