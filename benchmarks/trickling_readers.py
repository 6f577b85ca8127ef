"""How long readers that only look alive freeze a topic for a reading subscriber.

``rwt serve`` (this checkout's ``src``, or ``$RWT_BENCH_SRC``'s, its default flow settings unless
``--serve-args`` says otherwise: ``--hold-budget 5``, ``--send-buffer-limit``
16 MiB) carries a 100 KB ``std_msgs/String`` topic at 100 msg/s (10 MB/s) from a
publisher over TCP for ``--seconds``. A bystander subscriber reads as fast as it
can and notes when each message arrives. The attack runs beside it (docs/limits.md,
input backpressure):

- ``four``: four subscribers with 64 KiB receive buffers reading 64 KB every
  0.5 s (about 1 % of the topic: their send queues shrink, so they look alive);
- ``staggered``: the same four, subscribing ``STAGGER_S`` apart (each falls behind
  on its own, so each is judged on its own);
- ``reconnect``: one such subscriber that closes and reconnects every budget + 1 s;
- ``drain``: one that catches up after each budget and trickles again;
- ``none``: no attacker, the reference.

Reported per attack: the bystander's messages, the seconds of its gaps over
``FROZEN_GAP_S`` (frozen), their share of the run and the longest gap. The
issue's bound for ``four`` at the defaults: frozen under 5 % of a 40 s attack,
no gap of 1 s.

Run: ``python -m benchmarks.trickling_readers [--seconds 40] [--attack four ...]
[--serve-args "--hold-budget 1"]``; results: ``results/trickling_readers.json``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import shlex
import socket
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from .servers import ROOT, rwt_pythonpath

__all__ = ["AttackResult", "main", "measure"]

RESULTS = Path(__file__).resolve().parent / "results" / "trickling_readers.json"
TOPIC = "/stream"
RATE = 100  # messages a second
PAYLOAD = 100_000  # bytes of a message's data
TRICKLE_BYTES = 64 * 1024  # what an attacker reads at a time ...
TRICKLE_EVERY_S = 0.5  # ... this often
RCVBUF = 64 * 1024  # an attacker's kernel receive buffer
FROZEN_GAP_S = 0.25  # a gap between two messages this long counts as frozen (25 periods)
TIMEOUT_S = 30.0
STAGGER_S = 0.3  # between the subscriptions of ``staggered``


@dataclass
class AttackResult:
    """One attack's run: what the bystander got and how long it was frozen."""

    attack: str
    seconds: float
    messages: int
    expected: int
    frozen_s: float
    frozen_share: float
    longest_gap_s: float
    gaps: list[float]


class TcpPeer:
    """rosbridge over TCP, blocking: JSON values out, raw bytes in (the attack replays'
    clients too)."""

    def __init__(self, port: int, rcvbuf: int | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf is not None:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.settimeout(TIMEOUT_S)
        self.sock.connect(("127.0.0.1", port))

    def send(self, op: dict[str, object]) -> None:
        self.sock.sendall(json.dumps(op).encode())

    def settle(self) -> None:
        """Wait until the server handled everything sent so far (a service call's reply)."""
        self.send({"op": "call_service", "service": "/rosapi/topics", "id": "settle"})
        buffer = b""
        while b'"id": "settle"' not in buffer and b'"id":"settle"' not in buffer:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise EOFError("the server closed the connection")
            buffer = buffer[-64:] + chunk

    def close(self) -> None:
        self.sock.close()


def _subscriber(port: int, rcvbuf: int | None = None) -> TcpPeer:
    peer = TcpPeer(port, rcvbuf)
    peer.send({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String"})
    peer.settle()
    return peer


def _publish(peer: TcpPeer, seconds: float) -> None:
    peer.send({"op": "advertise", "topic": TOPIC, "type": "std_msgs/String"})
    frame = json.dumps({"op": "publish", "topic": TOPIC, "msg": {"data": "x" * PAYLOAD}}).encode()
    start = time.monotonic()
    for i in range(int(RATE * seconds)):
        delay = start + i / RATE - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        peer.sock.sendall(frame)


def _arrivals(peer: TcpPeer, done: threading.Event, out: list[float]) -> None:
    sock = peer.sock
    sock.settimeout(FROZEN_GAP_S)
    while True:
        try:
            chunk = sock.recv(1 << 20)
        except TimeoutError:
            if done.is_set():
                return
            continue
        if not chunk:
            return
        out.extend([time.monotonic()] * chunk.count(b"\n"))


def trickle(sock: socket.socket, until: float, done: threading.Event) -> None:
    """Read ``TRICKLE_BYTES`` every ``TRICKLE_EVERY_S`` until ``until`` (monotonic) or ``done``."""
    sock.settimeout(TRICKLE_EVERY_S)
    while time.monotonic() < until and not done.is_set():
        try:
            sock.recv(TRICKLE_BYTES)
        except TimeoutError:
            continue
        done.wait(TRICKLE_EVERY_S)


def drain(sock: socket.socket, until: float) -> None:
    """Read everything that comes until ``until``: catch up."""
    sock.settimeout(0.1)
    while time.monotonic() < until:
        try:
            sock.recv(1 << 20)
        except TimeoutError:
            continue


def _attack(name: str, port: int, budget_s: float, done: threading.Event) -> list[TcpPeer]:
    """Run attack ``name`` until ``done``; the peers it opened (to close)."""
    opened: list[TcpPeer] = []
    if name in ("four", "staggered"):
        threads = []
        for _ in range(4):
            opened.append(_subscriber(port, RCVBUF))
            threads.append(threading.Thread(target=trickle, args=(opened[-1].sock, math.inf, done)))
            threads[-1].start()
            if name == "staggered":
                done.wait(STAGGER_S)
        for thread in threads:
            thread.join()
    elif name == "reconnect":
        while not done.is_set():
            peer = _subscriber(port, RCVBUF)
            opened.append(peer)
            trickle(peer.sock, time.monotonic() + budget_s + 1.0, done)
            peer.close()
    elif name == "drain":
        peer = _subscriber(port, RCVBUF)
        opened.append(peer)
        while not done.is_set():
            trickle(peer.sock, time.monotonic() + budget_s + 2.0, done)
            drain(peer.sock, time.monotonic() + 0.5)
    return opened


def run_attack(name: str, port: int, seconds: float, budget_s: float) -> AttackResult:
    """One attack against the server on TCP ``port``, ``seconds`` of publishing."""
    bystander = _subscriber(port)
    publisher = TcpPeer(port)
    done = threading.Event()
    arrivals: list[float] = []
    opened: list[TcpPeer] = []
    watcher = threading.Thread(target=_arrivals, args=(bystander, done, arrivals))
    attacker = threading.Thread(
        target=lambda: opened.extend(_attack(name, port, budget_s, done)), daemon=True
    )
    watcher.start()
    attacker.start()
    try:
        _publish(publisher, seconds)
        publisher.settle()
    finally:
        done.set()
        watcher.join()
        attacker.join(TIMEOUT_S)
        for peer in [bystander, publisher, *opened]:
            peer.close()
    gaps = [b - a for a, b in itertools.pairwise(arrivals) if b - a > FROZEN_GAP_S]
    run_s = arrivals[-1] - arrivals[0] if arrivals else 0.0
    frozen_s = sum(gaps)
    return AttackResult(
        attack=name,
        seconds=round(run_s, 2),
        messages=len(arrivals),
        expected=int(RATE * seconds),
        frozen_s=round(frozen_s, 3),
        frozen_share=round(frozen_s / run_s, 4) if run_s else 0.0,
        longest_gap_s=round(max(gaps, default=0.0), 3),
        gaps=[round(g, 3) for g in gaps],
    )


def _budget(serve_args: list[str]) -> float:
    if "--hold-budget" in serve_args:
        return float(serve_args[serve_args.index("--hold-budget") + 1])
    return 5.0  # rwt serve's default


def measure(attacks: list[str], seconds: float, serve_args: list[str]) -> list[AttackResult]:
    """Each attack against a fresh ``rwt serve`` (this checkout) with ``serve_args``."""
    results = []
    for name in attacks:
        command = [sys.executable, "-m", "rwt", "serve", "--port", "0", "--tcp-port", "0"]
        command += ["--log-level", "error", *serve_args]
        env = {"PYTHONPATH": rwt_pythonpath(), "PATH": "/usr/bin:/bin"}
        with subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE) as server:
            try:
                assert server.stdout is not None
                lines = [server.stdout.readline().decode() for _ in range(2)]
                tcp = next(line for line in lines if line.startswith("listening on tcp://"))
                port = int(tcp.strip().rsplit(":", 1)[1])
                results.append(run_attack(name, port, seconds, _budget(serve_args)))
            finally:
                server.terminate()
    return results


def main(argv: list[str] | None = None) -> int:
    """Run the attacks, print a table and write ``results/trickling_readers.json``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=40.0)
    parser.add_argument(
        "--attack", action="append", choices=["four", "staggered", "reconnect", "drain", "none"]
    )
    parser.add_argument("--serve-args", default="", help="more rwt serve options, one string")
    args = parser.parse_args(argv)
    serve_args = shlex.split(args.serve_args)
    results = measure(args.attack or ["four"], args.seconds, serve_args)
    source = os.environ.get("RWT_BENCH_SRC") or "this checkout"
    settings = " ".join(serve_args) or "(defaults)"
    print(f"rwt serve {settings} ({source}), {args.seconds:g} s of 10 MB/s")
    print("attack     messages  frozen s  share   longest gap s")
    for r in results:
        print(
            f"{r.attack:<10} {r.messages:>5}/{r.expected:<5} {r.frozen_s:>7.2f}"
            f"  {r.frozen_share:6.1%}  {r.longest_gap_s:6.2f}"
        )
    RESULTS.parent.mkdir(exist_ok=True)
    source = os.environ.get("RWT_BENCH_SRC") or "this checkout"
    record = {"src": source, "serve_args": serve_args, "results": [asdict(r) for r in results]}
    RESULTS.write_text(json.dumps(record, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
