"""B7's service round trips: to a second client's service, and to an in-process one.

The caller keeps ``window`` calls outstanding (1 for latency); the provider
answers each request with the id it carried. Against the bare relay the
request and the response each cross the relay once, like rwt's forwarding.
"""

from __future__ import annotations

import time
from collections import deque

import msgspec

from ..loadgen.engine import GeneratorError, Peer, Publisher, close_all, percentile_ms, run_loop
from ..loadgen.wire import FrameReader, client_frame
from .common import Metrics, Run, server_figures, settle

__all__ = ["service_run"]

_SERVICE = "/b7_svc"
_TYPE = "std_srvs/srv/Trigger"
_decode = msgspec.json.Decoder()


class _Provider(Peer):
    """Answers every ``call_service`` with a Trigger response carrying the request's id."""

    def __init__(self, port: int, kind: str) -> None:
        setup = [f'{{"op":"advertise_service","service":"{_SERVICE}","type":"{_TYPE}"}}'.encode()]
        super().__init__(port, kind, setup, receives=True)
        self.reader = FrameReader()
        self.answered = 0
        self.start_data = self.leftover

    def readable(self, now: float) -> None:
        data = self.start_data + self._recv()
        self.start_data = b""
        out = []
        for _, payload in self.reader.feed(data):
            request = _decode.decode(payload)
            if request.get("op") != "call_service" or request.get("service") != _SERVICE:
                raise GeneratorError(f"provider got {payload[:80]!r}")
            response = msgspec.json.encode(
                {
                    "op": "service_response",
                    "service": _SERVICE,
                    "id": request["id"],
                    "values": {"success": True, "message": "ok"},
                    "result": True,
                }
            )
            out.append(client_frame(response))
        if out:
            self.sock.sendall(b"".join(out))
            self.answered += len(out)


class _Caller(Publisher):
    """Calls ``service`` with ``window`` calls in flight; records each round trip."""

    def __init__(
        self, port: int, kind: str, service: str, *, window: int, calls: int, check: bytes
    ) -> None:
        super().__init__(port, kind, [], receives=True)
        self.service = service
        self.window = window
        self.calls = calls
        self.check = check
        self.reader = FrameReader()
        self.in_flight: deque[tuple[int, float]] = deque()
        self.rtts_s: list[float] = []
        self.duration_s = 0.0

    def push(self, now: float) -> None:
        frames = []
        while len(self.in_flight) < self.window and self.sent < self.calls:
            call = (
                f'{{"op":"call_service","service":"{self.service}","id":"c{self.sent}",'
                f'"args":{{}}}}'
            )
            frames.append(client_frame(call.encode()))
            self.in_flight.append((self.sent, time.perf_counter()))
            self.sent += 1
        if frames:
            self.sock.sendall(b"".join(frames))

    def readable(self, now: float) -> None:
        for _, payload in self.reader.feed(self._recv()):
            reply = _decode.decode(payload)
            number, sent_at = self.in_flight.popleft()
            if reply.get("id") != f"c{number}" or self.check not in payload:
                raise GeneratorError(f"reply {payload[:120]!r} for call c{number}")
            self.rtts_s.append(now - sent_at)

    @property
    def finished(self) -> bool:
        return len(self.rtts_s) >= self.calls


def service_run(run: Run, *, in_process: bool, window: int, calls: int) -> Metrics:
    """Round trips of ``calls`` calls; p50/p99 in ms and calls/s."""
    calls = max(10, int(calls * run.scale))
    provider = None if in_process else _Provider(run.port, run.kind)
    service = "/rosapi/get_time" if in_process else _SERVICE
    check = b'"result":true' if in_process else b'"message":"ok"'
    caller = _Caller(run.port, run.kind, service, window=window, calls=calls, check=check)
    peers = [caller] if provider is None else [caller, provider]
    try:
        before = run.server.stats()
        loop = run_loop(
            [caller],
            [],
            done=lambda: caller.finished,
            limit_s=60.0,
            others=[] if provider is None else [provider],
        )
        after = run.server.stats()
    finally:
        close_all(peers)
    figures = server_figures(before, after, loop, calls, loop.wall_s)
    figures.update(
        {
            "p50_ms": percentile_ms(caller.rtts_s, 0.5),
            "p99_ms": percentile_ms(caller.rtts_s, 0.99),
            "calls_per_s": calls / loop.wall_s,
        }
    )
    settle()
    return figures
