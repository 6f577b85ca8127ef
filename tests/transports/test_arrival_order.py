"""Frames are handled in the order they reached the server, across connections.

Three clients: A subscribes (with a throttle), B subscribes, then C advertises and
publishes one message, each frame sent only once the one before was sent (one
thread writes them all, so each is in the server's kernel before the next is
written). Both subscribers must get the message every time: their subscribe
reached the server before C's publish. On new WebSocket connections C is opened
last, or first (a page that opens its publisher, then its subscribers): the order
is the frames' arrival, whichever connection is older. On kept connections a round ends once
every connection's frames are handled, so no read mixes two rounds' frames
(docs/limits.md, "frames are handled in the order they reached the server").

Run over WebSocket and TCP, plain and TLS, with the connections kept from round
to round or new for each round, and (in CI's second run) with every shortcut
off: the order must hold without the ``direct-read`` shortcut and over TLS.
"""

from __future__ import annotations

import json
import socket
import ssl
import time
from collections.abc import Callable
from contextlib import ExitStack
from typing import Any

import anyio
import anyio.to_thread
import pytest
from websockets.sync.client import connect

from rwt_transports import pump
from rwt_transports.admission.arrival import Admission
from tests.support.clients import Harness, running_server

pytestmark = pytest.mark.anyio

ROUNDS = {"kept": 100, "new": 120}
"""Rounds per case: a missed order shows only now and then. On kept connections a
round sends 3 frames on A and B and 4 on C, so all three connections' read slices
end in the same round every ``SLICE_FRAMES`` rounds, where a reader resuming from
its slice's yield once took later input first: 100 rounds cross six of them."""

SLICE_FRAMES = 16
"""``pump.READ_SLICE_FRAMES`` for these tests (256 when serving): a smaller slice puts
the slice ends that matter 16 rounds apart instead of 256, so a run crosses several
in a hundred rounds."""

TIMEOUT_S = 30.0
MESSAGE_WAIT_S = 10.0
"""How long a subscriber waits for its round's message: a missed one never comes, so
only a miss waits this long, and a machine that stalls the server for seconds (CI's
is shared) is not taken for a miss."""
STRING = "std_msgs/msg/String"


@pytest.fixture(autouse=True)
def _small_read_slices(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pump, "READ_SLICE_FRAMES", SLICE_FRAMES)


Message = dict[str, Any]
Accepted = Callable[[int], None]


class _Tcp:
    """A rosbridge TCP client (TLS with a context) that writes each frame at once."""

    def __init__(self, port: int, context: ssl.SSLContext | None) -> None:
        sock = socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S)
        # Nagle would hold a small frame back until the last one is acknowledged:
        # the frame would not have reached the server when the next one is written.
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = context.wrap_socket(sock, server_hostname="127.0.0.1") if context else sock
        self._buffer = b""

    def send(self, op: Message) -> None:
        self.sock.sendall(json.dumps(op).encode())

    def receive(self, timeout: float) -> Message:
        self.sock.settimeout(timeout)
        while b"\n" not in self._buffer:
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                raise EOFError("the server closed the connection")
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        return json.loads(line)  # type: ignore[no-any-return]

    def close(self) -> None:
        self.sock.close()


class _Ws:
    """A rosbridge WebSocket client (websockets' blocking client; wss with a context)."""

    def __init__(self, port: int, context: ssl.SSLContext | None) -> None:
        self._stack = ExitStack()
        scheme = "wss" if context else "ws"
        self.ws = self._stack.enter_context(
            connect(f"{scheme}://127.0.0.1:{port}", ssl=context, open_timeout=TIMEOUT_S)
        )

    def send(self, op: Message) -> None:
        self.ws.send(json.dumps(op))

    def receive(self, timeout: float) -> Message:
        return json.loads(self.ws.recv(timeout=timeout))  # type: ignore[no-any-return]

    def close(self) -> None:
        self._stack.close()


def _gets(peer: _Tcp | _Ws, data: str) -> bool:
    """Whether ``peer`` receives the message ``data`` within ``MESSAGE_WAIT_S``."""
    deadline = time.monotonic() + MESSAGE_WAIT_S
    while (left := deadline - time.monotonic()) > 0:
        try:
            message = peer.receive(left)
        except TimeoutError:
            return False
        if message.get("op") == "publish" and message["msg"]["data"] == data:
            return True
    return False


def _settle(peers: list[_Tcp | _Ws], name: str) -> None:
    """Wait until the server handled every frame the peers sent so far (a call each)."""
    for peer in peers:
        peer.send({"op": "call_service", "service": "/nothing", "id": name})
    for peer in peers:
        while peer.receive(TIMEOUT_S).get("id") != name:
            pass


def _rounds(
    transport: str,
    port: int,
    context: ssl.SSLContext | None,
    mode: str,
    accepted: Accepted,
    publisher_first: bool = False,
) -> list[str]:
    """Run the rounds; return a line for each subscriber that missed its round's message."""
    kind = _Ws if transport == "ws" else _Tcp
    missed: list[str] = []
    peers: list[_Tcp | _Ws] = []
    try:
        for index in range(ROUNDS[mode]):
            if mode == "new" or not peers:
                for peer in peers:
                    peer.close()
                peers = [kind(port, context) for _ in range(3)]
                accepted(3)  # connected, as far as the server is concerned
            if publisher_first:  # C, the publisher, opened first
                c, a, b = peers
            else:
                a, b, c = peers
            topic = f"/arrival_{index}"
            data = f"m{index}"
            a.send({"op": "subscribe", "topic": topic, "type": STRING, "throttle_rate": 400})
            b.send({"op": "subscribe", "topic": topic, "type": STRING})
            c.send({"op": "advertise", "topic": topic, "type": STRING})
            c.send({"op": "publish", "topic": topic, "msg": {"data": data}})
            missed += [f"round {index}: {n}" for n, p in (("A", a), ("B", b)) if not _gets(p, data)]
            if mode == "kept":
                a.send({"op": "unsubscribe", "topic": topic})
                b.send({"op": "unsubscribe", "topic": topic})
                c.send({"op": "unadvertise", "topic": topic})
                # A connection's frames sent back to back reach the server in one read
                # when it is busy, and are handled together (docs/limits.md): the next
                # round starts once these are handled.
                _settle(peers, f"end{index}")
    finally:
        for peer in peers:
            peer.close()
    return missed


async def _check(
    harness: Harness, transport: str, mode: str, publisher_first: bool = False
) -> None:
    port = harness.port("websocket" if transport == "ws" else "tcp")
    sessions = harness.server.sessions
    known = set(sessions)

    def accepted(count: int) -> None:
        """Wait until the server opened ``count`` sessions more (the new clients')."""
        deadline = time.monotonic() + TIMEOUT_S
        while time.monotonic() < deadline:
            new = set(sessions) - known  # a copy: the server's loop changes it meanwhile
            if len(new) >= count:
                known.update(new)
                return
            time.sleep(0.0005)

    missed = await anyio.to_thread.run_sync(
        _rounds, transport, port, harness.ssl_context, mode, accepted, publisher_first
    )
    assert missed == [], f"{len(missed)} missed of {2 * ROUNDS[mode]}: {missed[:10]}"


@pytest.mark.parametrize("mode", ["kept", "new"])
@pytest.mark.parametrize("transport", ["ws", "tcp"])
async def test_subscribers_get_a_publish_sent_after_their_subscribe(
    transport: str, mode: str
) -> None:
    async with running_server() as harness:
        await _check(harness, transport, mode)


async def test_a_publisher_whose_websocket_is_older_does_not_go_first() -> None:
    """New WebSocket connections, the publisher's opened first: its publish comes after.

    A page opens its connections in any order; over WebSocket the order is the
    frames' arrival, whichever connection is older (the reader listens before the
    upgrade response goes, docs/limits.md).
    """
    async with running_server() as harness:
        await _check(harness, "ws", "new", publisher_first=True)


@pytest.mark.parametrize("mode", ["kept", "new"])
@pytest.mark.parametrize("transport", ["ws", "tcp"])
async def test_the_order_holds_over_tls(tls_harness: Harness, transport: str, mode: str) -> None:
    await _check(tls_harness, transport, mode)


async def test_a_publisher_whose_websocket_is_older_does_not_go_first_over_tls(
    tls_harness: Harness,
) -> None:
    await _check(tls_harness, "ws", "new", publisher_first=True)


async def test_readers_wait_for_their_own_servers_starting_connections_only() -> None:
    """Each server keeps its own tickets: another server's new connection holds no reader."""
    mine, other = Admission(), Admission()
    ticket = mine.hold()  # a connection of ``mine`` being set up: it counts as having input
    order: list[str] = []

    async def reader(admission: Admission, name: str) -> None:
        await admission.wait_for_new()
        order.append(name)

    async with anyio.create_task_group() as tg:
        tg.start_soon(reader, mine, "mine")
        tg.start_soon(reader, other, "other")
        await anyio.wait_all_tasks_blocked()
        order.append("released")
        ticket.release()
    assert order == ["other", "released", "mine"]
    assert not mine.starting()
