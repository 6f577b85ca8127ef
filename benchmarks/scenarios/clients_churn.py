"""B10 churn of ``/connected_clients``: its subscribers and a bystander while clients come and go.

``subscribers`` WebSocket connections subscribe to ``/connected_clients`` (D14:
the whole client list, republished on every connect and disconnect, so one
message is about 60 bytes a client). A bystander measures round trips (a
``set_level`` and its status) first with no churn, then while ``churn``
connections open and close one after another. The ratio of the two p99s, from
one run, shows what churn costs the others. Every subscriber is drained as it
goes; at the end each one's last list must be the final one (the subscribers
and the bystander), and the lists each got are counted (coalesced:
``ServerConfig.clients_interval_s``). Only ``rwt`` has the topic.
"""

from __future__ import annotations

import json
import selectors
import socket
import time

from .. import msgs
from ..loadgen.engine import GeneratorError, Peer, close_all, percentile_ms
from ..loadgen.wire import FrameReader, client_frame, connect
from .common import Metrics, Run

__all__ = ["clients_churn_run"]

_TIMEOUT_S = 60.0
_TYPE = "rosbridge_msgs/msg/ConnectedClients"


class _Listener:
    """One subscriber of the client list: counts the lists, keeps the last one unparsed."""

    __slots__ = ("counted", "last", "lists", "peer", "reader")

    def __init__(self, peer: Peer) -> None:
        self.peer = peer
        self.reader = FrameReader()
        self.lists = 0
        self.last = b""
        self.counted: tuple[bytes, int] = (b"", -1)  # the last list parsed, its length
        self.feed(peer.leftover)

    def clients(self) -> int:
        """Entries of the last list (parsed once per new list)."""
        if self.counted[0] is not self.last:
            count = len(json.loads(self.last)["msg"]["clients"]) if self.last else -1
            self.counted = (self.last, count)
        return self.counted[1]

    def feed(self, data: bytes) -> None:
        for _, payload in self.reader.feed(data):
            if b'"/connected_clients"' in payload[:80]:
                self.lists += 1
                self.last = payload


class _Loop:
    """Drains every subscriber; times the bystander's round trips."""

    def __init__(self, listeners: list[_Listener], bystander: Peer) -> None:
        self.sel = selectors.DefaultSelector()
        for listener in listeners:
            self.sel.register(listener.peer.sock, selectors.EVENT_READ, listener)
        self.sel.register(bystander.sock, selectors.EVENT_READ, None)
        self.bystander = bystander
        self.reader = FrameReader()

    def drain(self, timeout: float) -> bool:
        """Read what is there (waiting up to ``timeout``); True when the bystander got its reply."""
        answered = False
        for key, _ in self.sel.select(timeout):
            sock: socket.socket = key.fileobj  # type: ignore[assignment]
            try:
                data = sock.recv(1 << 20)
            except BlockingIOError:
                continue
            if not data:
                raise GeneratorError("the server closed a connection")
            if key.data is None:
                answered = answered or any(b'"id":"rt"' in p for _, p in self.reader.feed(data))
            else:
                key.data.feed(data)
        return answered

    def round_trip(self) -> float:
        """Seconds from sending a ``set_level`` to its status, draining meanwhile."""
        started = time.perf_counter()
        self.bystander.sock.sendall(client_frame(b'{"op":"set_level","level":"info","id":"rt"}'))
        while not self.drain(0.05):
            if time.perf_counter() - started > _TIMEOUT_S:
                raise GeneratorError("the bystander got no answer")
        return time.perf_counter() - started


def clients_churn_run(run: Run, *, subscribers: int, churn: int, round_trips: int) -> Metrics:
    """Quiet round trips, then round trips amid ``churn`` connections opened and closed."""
    subscribers = max(10, int(subscribers * run.scale))
    churn = max(10, int(churn * run.scale))
    listeners: list[_Listener] = []
    peers: list[Peer] = []
    try:
        for _ in range(subscribers):
            peer = Peer(run.port, run.kind, [], receives=True)
            peers.append(peer)
            # after the barrier: the latched list comes at once
            peer.sock.sendall(client_frame(msgs.subscribe("/connected_clients", _TYPE)))
            listeners.append(_Listener(peer))
        bystander = Peer(run.port, run.kind, [], receives=False)
        peers.append(bystander)
        loop = _Loop(listeners, bystander)
        _settle(loop, listeners, subscribers + 1)
        quiet = [loop.round_trip() for _ in range(round_trips)]
        before = [listener.lists for listener in listeners]
        server_before = run.server.stats()
        cpu_before = time.process_time()
        started = time.perf_counter()
        amid: list[float] = []
        for i in range(churn):
            sock, _ = connect(run.port)
            sock.close()
            loop.drain(0.0)
            if i % max(1, churn // round_trips) == 0:
                amid.append(loop.round_trip())
        _settle(loop, listeners, subscribers + 1)
        elapsed = time.perf_counter() - started
        generator_cpu = time.process_time() - cpu_before
        server_cpu = run.server.stats().cpu_s - server_before.cpu_s
        lists = max(listener.lists - n for listener, n in zip(listeners, before, strict=True))
    finally:
        close_all(peers)
    quiet_p99 = percentile_ms(quiet, 0.99)
    amid_p99 = percentile_ms(amid, 0.99)
    return {
        "quiet_p50_ms": percentile_ms(quiet, 0.5),
        "quiet_p99_ms": quiet_p99,
        "churn_p50_ms": percentile_ms(amid, 0.5),
        "churn_p99_ms": amid_p99,
        "p99_ratio": amid_p99 / quiet_p99,
        "churned": float(churn),
        "churn_s": elapsed,
        "lists_per_subscriber": float(lists),
        "server_cpu_pct": 100.0 * server_cpu / elapsed,
        "generator_cpu_pct": 100.0 * generator_cpu / elapsed,
    }


def _settle(loop: _Loop, listeners: list[_Listener], clients: int) -> None:
    """Drain until every subscriber's last list has ``clients`` entries."""
    deadline = time.perf_counter() + _TIMEOUT_S
    while True:
        if all(listener.clients() == clients for listener in listeners):
            return
        if time.perf_counter() > deadline:
            raise GeneratorError("a subscriber never got the final client list")
        loop.drain(0.05)
