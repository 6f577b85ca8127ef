"""Replies dropped for a client that floods itself, on any rosbridge v2 server.

rosbridge_suite 2.7.1 / 3.3.1 / 4.2.1 give each connection a write queue of 1000 messages and
drop the *newest* outgoing message when it is full, whatever its op: a `service_response`
meant for a client that subscribed to more than it reads is lost like a topic message
(docs/reference-behaviour.md §13.6). rwt drops only the oldest topic messages of a slow
client and never a reply (docs/limits.md). This measures both from outside, on any URL:

- a publisher connection advertises ``TOPIC`` (``std_msgs/String``) and publishes
  ``--size``-byte messages (data starts with an 8-digit sequence number) at ``--rate``
  messages a second (0: as fast as its socket takes them) for ``--seconds``;
- a reference subscriber reads as fast as it can: what reached a subscriber that keeps up;
- the *flooded* client (a raw socket with a ``--rcvbuf`` receive buffer) subscribes too and
  does not read while the publisher runs; meanwhile it calls ``--service`` (default
  ``/rosapi/get_time``) ``--calls`` times, evenly spread, each with its own id. After the
  publisher stops it reads everything (until ``--quiet`` seconds pass with nothing new).

Reported per URL: messages published, received by the reference reader and by the flooded
client (its drops are the difference), calls sent, answered (``service_response`` with a
matching id; ``result: false`` counted apart) and unanswered, and whether the server closed
the flooded connection. The flooded client's stall must stay shorter than a server's slow-client
timeout (rwt: ``--send-timeout`` 30 s) to measure queueing rather than disconnection.

Run: ``python -m benchmarks.dropped_replies ws://127.0.0.1:9090 [URL ...] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import threading
import time
from dataclasses import asdict, dataclass
from urllib.parse import urlsplit

from .loadgen.wire import OP_TEXT, FrameReader, client_frame, connect

__all__ = ["Result", "main", "measure"]

TOPIC = "/rwt_bench/flood"
SETTLE_S = 2.0  # after subscribing, for the server's graph to match publisher and subscribers


@dataclass
class Result:
    """One URL's run."""

    url: str
    seconds: float
    rate: float
    size: int
    published: int
    reference_received: int
    flooded_received: int
    flooded_dropped: int
    calls_sent: int
    calls_answered: int
    calls_failed: int
    calls_unanswered: int
    flooded_closed: bool
    close_reason: str


class _Conn:
    """A blocking raw-socket WebSocket client: JSON text frames out, frames in."""

    def __init__(self, url: str, rcvbuf: int | None = None) -> None:
        parts = urlsplit(url)
        self.sock, rest = connect(
            parts.port or 80, parts.path or "/", parts.hostname or "127.0.0.1", rcvbuf=rcvbuf
        )
        self.reader = FrameReader()
        self.pending = self.reader.feed(rest) if rest else []
        self.lock = threading.Lock()

    def send(self, op: dict[str, object]) -> None:
        frame = client_frame(json.dumps(op).encode())
        with self.lock:
            self.sock.sendall(frame)

    def send_raw(self, frame: bytes) -> None:
        with self.lock:
            self.sock.sendall(frame)

    def frames(self, timeout: float) -> list[tuple[int, bytes]]:
        """The frames that arrive within ``timeout`` of waiting (``[]``: none); EOFError: closed."""
        if self.pending:
            out, self.pending = self.pending, []
            return out
        self.sock.settimeout(timeout)
        try:
            chunk = self.sock.recv(1 << 20)
        except TimeoutError:
            return []
        if not chunk:
            raise EOFError
        return self.reader.feed(chunk)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()


def _seq(payload: bytes) -> int | None:
    """The sequence number of a ``publish`` frame of ``TOPIC``, else None."""
    try:
        msg = json.loads(payload)
    except ValueError:
        return None
    if msg.get("op") != "publish" or msg.get("topic") != TOPIC:
        return None
    data = (msg.get("msg") or {}).get("data", "")
    return int(data[:8]) if data[:8].isdigit() else None


def _read_reference(conn: _Conn, done: threading.Event, seen: set[int]) -> None:
    while True:
        try:
            frames = conn.frames(0.5)
        except (EOFError, OSError):
            return
        if not frames and done.is_set():
            return
        for opcode, payload in frames:
            if opcode == OP_TEXT and payload[:64].find(b"publish") >= 0:
                seq = _seq(payload)
                if seq is not None:
                    seen.add(seq)


def _discard(conn: _Conn, done: threading.Event) -> None:
    while not done.is_set():
        try:
            conn.frames(0.5)
        except (EOFError, OSError):
            return


def _publish(publisher: _Conn, seconds: float, rate: float, size: int, sent: list[int]) -> None:
    """Publish numbered messages for ``seconds``; their count goes to ``sent[0]``."""
    pad = "x" * max(0, size - 8)
    start = time.monotonic()
    i = 0
    while time.monotonic() - start < seconds:
        if rate > 0:
            delay = start + i / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        op = {"op": "publish", "topic": TOPIC, "msg": {"data": f"{i:08d}{pad}"}}
        publisher.send_raw(client_frame(json.dumps(op).encode()))
        i += 1
    sent[0] = i


def _read_flooded(
    flooded: _Conn, ids: list[str], quiet: float
) -> tuple[set[str], set[str], set[int], bool, str]:
    """Read until ``quiet`` s pass with nothing new: answered and failed ids, seqs, closed, why."""
    answered: set[str] = set()
    failed: set[str] = set()
    flooded_seen: set[int] = set()
    closed, reason = False, ""
    last = time.monotonic()
    while time.monotonic() - last < quiet:
        try:
            frames = flooded.frames(0.5)
        except (EOFError, OSError) as exc:
            closed, reason = True, type(exc).__name__
            break
        if frames:
            last = time.monotonic()
        for opcode, payload in frames:
            if opcode == 0x8:  # close frame: its code and reason
                closed = True
                reason = payload[2:].decode(errors="replace") or (
                    str(int.from_bytes(payload[:2], "big")) if len(payload) >= 2 else "close"
                )
                continue
            if opcode != OP_TEXT:
                continue
            if payload[:64].find(b"service_response") >= 0:
                msg = json.loads(payload)
                if msg.get("id") in ids:
                    (answered if msg.get("result", True) else failed).add(msg["id"])
            elif payload[:64].find(b"publish") >= 0:
                seq = _seq(payload)
                if seq is not None:
                    flooded_seen.add(seq)
        if closed:
            break
    return answered, failed, flooded_seen, closed, reason


def measure(
    url: str,
    *,
    seconds: float = 10.0,
    rate: float = 400.0,
    size: int = 10_000,
    calls: int = 100,
    service: str = "/rosapi/get_time",
    rcvbuf: int = 16 * 1024,
    quiet: float = 5.0,
) -> Result:
    """One run against ``url`` (see the module doc)."""
    publisher = _Conn(url)
    reference = _Conn(url)
    flooded = _Conn(url, rcvbuf=rcvbuf)
    publisher.send({"op": "advertise", "topic": TOPIC, "type": "std_msgs/String"})
    for conn in (reference, flooded):
        conn.send({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String"})
    time.sleep(SETTLE_S)
    done = threading.Event()
    seen: set[int] = set()
    threads = [
        threading.Thread(target=_read_reference, args=(reference, done, seen), daemon=True),
        threading.Thread(target=_discard, args=(publisher, done), daemon=True),
    ]
    for thread in threads:
        thread.start()

    sent = [0]
    pub_thread = threading.Thread(
        target=_publish, args=(publisher, seconds, rate, size, sent), daemon=True
    )
    pub_thread.start()
    ids = [f"dr-{i}" for i in range(calls)]
    start = time.monotonic()
    for i, call_id in enumerate(ids):  # the flooded client calls and does not read
        delay = start + (i + 0.5) * seconds / calls - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        flooded.send({"op": "call_service", "service": service, "id": call_id, "args": {}})
    pub_thread.join()

    answered, failed, flooded_seen, closed, reason = _read_flooded(flooded, ids, quiet)
    done.set()
    for thread in threads:
        thread.join(timeout=5)
    for conn in (publisher, reference, flooded):
        conn.close()
    return Result(
        url=url,
        seconds=seconds,
        rate=rate,
        size=size,
        published=sent[0],
        reference_received=len(seen),
        flooded_received=len(flooded_seen),
        flooded_dropped=len(seen - flooded_seen),
        calls_sent=calls,
        calls_answered=len(answered),
        calls_failed=len(failed),
        calls_unanswered=calls - len(answered) - len(failed),
        flooded_closed=closed,
        close_reason=reason,
    )


def _table(results: list[Result]) -> str:
    head = (
        "url",
        "published",
        "ref recv",
        "flooded recv",
        "flooded dropped",
        "calls",
        "answered",
        "failed",
        "unanswered",
        "closed",
    )
    rows = [
        (
            r.url,
            str(r.published),
            str(r.reference_received),
            str(r.flooded_received),
            str(r.flooded_dropped),
            str(r.calls_sent),
            str(r.calls_answered),
            str(r.calls_failed),
            str(r.calls_unanswered),
            f"yes ({r.close_reason})" if r.flooded_closed else "no",
        )
        for r in results
    ]
    widths = [max(len(c) for c in col) for col in zip(head, *rows, strict=True)]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in (head, *rows)
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.dropped_replies", description=__doc__.split("\n")[0]
    )
    parser.add_argument(
        "urls", nargs="+", metavar="URL", help="rosbridge WebSocket URLs (ws://host:port/path)"
    )
    parser.add_argument(
        "--seconds",
        type=float,
        default=10.0,
        help="publishing time, the flooded client's stall (10)",
    )
    parser.add_argument(
        "--rate", type=float, default=400.0, help="messages a second; 0: as fast as possible (400)"
    )
    parser.add_argument(
        "--size", type=int, default=10_000, help="bytes of a message's data (10000)"
    )
    parser.add_argument(
        "--calls", type=int, default=100, help="service calls by the flooded client (100)"
    )
    parser.add_argument(
        "--service", default="/rosapi/get_time", help="the service it calls (/rosapi/get_time)"
    )
    parser.add_argument(
        "--rcvbuf", type=int, default=16 * 1024, help="its socket receive buffer, bytes (16384)"
    )
    parser.add_argument(
        "--quiet", type=float, default=5.0, help="seconds with nothing new that end its read (5)"
    )
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args(argv)
    results = []
    for url in args.urls:
        result = measure(
            url,
            seconds=args.seconds,
            rate=args.rate,
            size=args.size,
            calls=args.calls,
            service=args.service,
            rcvbuf=args.rcvbuf,
            quiet=args.quiet,
        )
        results.append(result)
        print(_table([result]).splitlines()[-1], file=sys.stderr, flush=True)
    print(_table(results))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump([asdict(r) for r in results], fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
