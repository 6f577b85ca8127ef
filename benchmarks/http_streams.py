"""Many readers of one topic in one process: WebSocket subscribers or HTTP event streams.

``python -m benchmarks.http_streams PORT --kind sse|ws [--count 500] [--host 127.0.0.1]
[--topic /tick]`` opens ``--count`` connections from ``--host`` to ``127.0.0.1:PORT``,
one after another: rosbridge WebSocket subscribers of ``--topic`` (``ws``) or
``GET /api/topics/<topic>/events`` (``sse``), then prints one line of JSON,
``{"ready": N, "statuses": {...}}`` (the HTTP status each request got; a refused one is
closed; the open ones are read meanwhile). It then reads every open connection and drops
what it reads, counting the messages (``data: `` lines, or ``"op":"publish"`` frames:
counted in the bytes, no parsing, so both kinds cost this process the same), until it is
told to stop (SIGTERM or its stdin closed), and prints
``{"messages": M, "bytes": B, "open": K}``.

It is the load of ``benchmarks/attacks_http.py``'s classes; it never imports rwt, so any
server's version works.
"""

from __future__ import annotations

import argparse
import json
import resource
import selectors
import signal
import socket
import struct
import sys
import threading
from collections import Counter

__all__ = ["main", "open_reader"]

UPGRADE = (
    b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
)
TIMEOUT_S = 60.0  # a bound on a hung server, not a speed requirement


def _masked(payload: bytes) -> bytes:
    """One client text frame (masked with an all-zero mask, RFC 6455 5.3)."""
    if len(payload) < 126:
        return bytes((0x81, 0x80 | len(payload))) + bytes(4) + payload
    return bytes((0x81, 0xFE)) + struct.pack("!H", len(payload)) + bytes(4) + payload


def _head(sock: socket.socket) -> tuple[int, bytes]:
    """The response's status and what came after its head."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(4096)
        if not chunk:
            return (int(data.split()[1]) if data.startswith(b"HTTP/") else 0), b""
        data += chunk
    head, _, rest = data.partition(b"\r\n\r\n")
    return int(head.split()[1]), rest


def open_reader(kind: str, port: int, host: str, topic: str) -> tuple[int, socket.socket | None]:
    """One reader: its HTTP status and its socket (None when refused)."""
    sock = socket.create_connection(("127.0.0.1", port), TIMEOUT_S, (host, 0))
    if kind == "ws":
        sock.sendall(UPGRADE)
        status, _ = _head(sock)
        op = {"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"}
        sock.sendall(_masked(json.dumps(op).encode()))
    else:
        sock.sendall(f"GET /api/topics{topic}/events HTTP/1.1\r\nHost: x\r\n\r\n".encode())
        status, _ = _head(sock)
    if status not in (101, 200):
        sock.close()
        return status, None
    sock.setblocking(False)
    return status, sock


def _drain(selector: selectors.BaseSelector, timeout: float, marker: bytes) -> tuple[int, int]:
    """Read what every ready reader has (waiting at most ``timeout``): messages and bytes."""
    messages = total = 0
    for key, _ in selector.select(timeout):
        sock = key.fileobj
        assert isinstance(sock, socket.socket)
        try:
            data = sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            continue
        except OSError:
            data = b""
        if not data:
            selector.unregister(sock)
            sock.close()
            continue
        total += len(data)
        messages += data.count(marker)
    return messages, total


def main(argv: list[str] | None = None) -> None:
    """The command line (the module's docstring)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.http_streams")
    parser.add_argument("port", type=int)
    parser.add_argument("--kind", choices=("ws", "sse"), required=True)
    parser.add_argument("--count", type=int, default=500)
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--topic", default="/tick")
    args = parser.parse_args(argv)
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    marker = b"data: " if args.kind == "sse" else b'"op":"publish"'
    statuses: Counter[int] = Counter()
    selector = selectors.DefaultSelector()
    messages = total = 0
    for _ in range(args.count):
        status, sock = open_reader(args.kind, args.port, args.host, args.topic)
        statuses[status] += 1
        if sock is not None:
            selector.register(sock, selectors.EVENT_READ)
        got = _drain(selector, 0, marker)  # those open keep reading while the next opens
        messages, total = messages + got[0], total + got[1]
    print(json.dumps({"ready": len(selector.get_map()), "statuses": statuses}), flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    while not stop.is_set():
        got = _drain(selector, 0.1, marker)
        messages, total = messages + got[0], total + got[1]
    opened = len(selector.get_map())
    print(json.dumps({"messages": messages, "bytes": total, "open": opened}), flush=True)


if __name__ == "__main__":
    main()
