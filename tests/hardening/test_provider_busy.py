"""A service provider is never disconnected by its callers; a busy one fails its callers.

Requests to a client provider are never dropped (D24), so they used to pile up
in its send buffer, and once more than ``--send-buffer-limit`` (16 MiB) waited
the server cut the provider ("the peer stopped reading"): three connections
each sending three calls with 9 MB of arguments disconnected a provider that
reads at 10 MB/s every time, and its service was gone. Now a request that does
not fit is refused at once: its caller gets ``service_response`` with
``result: false`` and ``provider busy`` (and an error status), the provider
stays connected and answers every request it was given, and a client calling
another provider meanwhile is served as if nothing happened (docs/limits.md).
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import anyio
import anyio.to_thread
import pytest

from tests.hardening.peers import Peer, TcpPeer, open_peer, settle
from tests.support.clients import Harness

pytestmark = pytest.mark.anyio

SERVICE = "/slow_store"
OTHER = "/quick"
TYPE = "rosbridge_test_msgs/TestMultipleRequestFields"
ARG_BYTES = 9_000_000
CALLERS = ("ws", "tcp", "ws")
CALLS_EACH = 3
READ_RATE = 10_000_000  # the slow provider's reading, bytes/s
CHUNK = 64 * 1024
QUICK_CALLS = 20


@dataclass
class Provider:
    """A TCP service provider that reads ``rate`` bytes/s (None: as fast as it can).

    Every request is answered with ``result: true``; ``answered`` lists the
    request ids in order, and ``events`` (shared) records each answer.
    """

    peer: TcpPeer
    service: str
    events: list[str]
    lock: threading.Lock
    rate: float | None = None
    answered: list[str] = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def advertise(self) -> None:
        self.peer.send({"op": "advertise_service", "service": self.service, "type": TYPE})
        settle(self.peer, "advertised")

    def serve(self) -> None:
        """Answer requests until ``stop``; read at ``rate``."""
        sock, buffer = self.peer.sock, b""
        sock.settimeout(0.2)
        started, total = time.monotonic(), 0
        while not self.stop.is_set():
            try:
                chunk = sock.recv(CHUNK)
            except TimeoutError:
                continue
            if not chunk:
                return
            total += len(chunk)
            if self.rate:  # keep to the rate: sleep off what was read ahead of it
                time.sleep(max(0.0, started + total / self.rate - time.monotonic()))
            *lines, buffer = (buffer + chunk).split(b"\n")
            for line in lines:
                self._answer(json.loads(line))

    def _answer(self, message: dict[str, Any]) -> None:
        if message.get("op") != "call_service":
            return
        self.peer.send(
            {
                "op": "service_response",
                "service": self.service,
                "id": message["id"],
                "values": {},
                "result": True,
            }
        )
        with self.lock:
            self.answered.append(message["id"])
            self.events.append(self.service)


def call(peer: Peer, service: str, tag: str, arg: str = "") -> None:
    peer.send(
        {
            "op": "call_service",
            "service": service,
            "id": tag,
            "args": {"int_value": 1, "float_value": 0.5, "string": arg, "bool_value": True},
        }
    )


def responses(peer: Peer, count: int) -> dict[str, dict[str, Any]]:
    """The next ``count`` ``service_response`` ops, by id; status texts under ``status:<n>``.

    A refused call's error status follows its ``service_response``, so reading goes on
    until every refusal has had its status.
    """
    got: dict[str, dict[str, Any]] = {}
    statuses = 0

    def refused() -> int:
        return sum(1 for k, m in got.items() if not k.startswith("status:") and not m["result"])

    while len(got) - statuses < count or statuses < refused():
        message = peer.receive()
        if message.get("op") == "service_response":
            got[str(message["id"])] = message
        elif message.get("op") == "status":
            got[f"status:{statuses}"] = message
            statuses += 1
    return got


def flood(peer: Peer, index: int) -> dict[str, dict[str, Any]]:
    """Send ``CALLS_EACH`` calls with ``ARG_BYTES`` of arguments; collect their answers."""
    arg = "x" * ARG_BYTES
    for n in range(CALLS_EACH):
        call(peer, SERVICE, f"c{index}-{n}", arg)
    return responses(peer, CALLS_EACH)


async def test_callers_flooding_a_slow_provider_get_busy_and_it_stays_connected(
    harness: Harness,
) -> None:
    addresses = {kind: harness.port(kind) for kind in ("websocket", "tcp")}
    events: list[str] = []
    lock = threading.Lock()
    slow = Provider(
        await anyio.to_thread.run_sync(lambda: TcpPeer(addresses["tcp"], rcvbuf=CHUNK)),
        SERVICE,
        events,
        lock,
        rate=READ_RATE,
    )
    quick = Provider(await anyio.to_thread.run_sync(TcpPeer, addresses["tcp"]), OTHER, events, lock)
    for provider in (slow, quick):
        await anyio.to_thread.run_sync(provider.advertise)
    callers = [await anyio.to_thread.run_sync(open_peer, t, addresses) for t in CALLERS]
    bystander = await anyio.to_thread.run_sync(open_peer, "ws", addresses)
    answers: dict[int, dict[str, dict[str, Any]]] = {}
    quick_done: list[int] = []

    async def run_flood(index: int) -> None:
        answers[index] = await anyio.to_thread.run_sync(flood, callers[index], index)

    def call_quick() -> None:
        # Once the slow provider has the flood to chew on, call the other one.
        while True:
            with lock:
                if SERVICE in events:
                    break
            time.sleep(0.01)
        for n in range(QUICK_CALLS):
            call(bystander, OTHER, f"q{n}")
            reply = responses(bystander, 1)
            assert reply[f"q{n}"]["result"] is True, reply
        with lock:  # how many slow answers there were when the last quick one came
            quick_done.append(events.count(SERVICE))

    with anyio.fail_after(120):
        async with anyio.create_task_group() as serving:
            serving.start_soon(anyio.to_thread.run_sync, slow.serve)
            serving.start_soon(anyio.to_thread.run_sync, quick.serve)
            async with anyio.create_task_group() as tg:
                for index in range(len(CALLERS)):
                    tg.start_soon(run_flood, index)
                tg.start_soon(anyio.to_thread.run_sync, call_quick)
            # The slow provider is still connected and serving: a new call succeeds.
            await anyio.to_thread.run_sync(call, bystander, SERVICE, "after")
            after = await anyio.to_thread.run_sync(responses, bystander, 1)
            slow.stop.set()
            quick.stop.set()
    assert after["after"]["result"] is True, after
    replies = [
        reply
        for got in answers.values()
        for key, reply in got.items()
        if not key.startswith("status:")
    ]
    assert len(replies) == len(CALLERS) * CALLS_EACH  # every caller heard back (D4)
    busy = [r for r in replies if not r["result"]]
    served = [r for r in replies if r["result"]]
    assert busy, "no call was refused"
    for reply in busy:
        assert "provider busy" in reply["values"], reply
    # Each refusal came with an error status to its caller too.
    statuses = [
        reply["msg"]
        for got in answers.values()
        for k, reply in got.items()
        if k.startswith("status:")
    ]
    assert len([s for s in statuses if "provider busy" in s]) == len(busy), statuses
    # The provider answered every request it was given: the served calls and "after".
    assert len(slow.answered) == len(served) + 1
    # The other provider's caller finished while the flooded one still had work.
    assert quick_done[0] < len(served), (quick_done, len(served))
    for peer in (*callers, bystander, slow.peer, quick.peer):
        await anyio.to_thread.run_sync(peer.close)
