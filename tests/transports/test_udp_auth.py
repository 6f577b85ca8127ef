"""Authentication over UDP: a peer's session begins with its ``auth`` op (docs/server.md).

Before, with ``--auth-bind-connection`` no UDP client could authenticate: the
session, and its challenge, began with the first datagram served, which could not
be an ``auth`` op carrying that challenge, so the session closed; every later
datagram began a new session with a new challenge. Now the challenge comes with
the address validation, and a datagram that is not ``auth`` from a peer without
a session is refused without opening one. Real datagrams on loopback, from
sockets doing what the docs tell a client to do.
"""

from __future__ import annotations

import json
import logging
import socket
import time
from collections.abc import AsyncIterator
from typing import Any

import anyio
import pytest
from anyio.abc import ConnectedUDPSocket, SocketAttribute

from rwt_graph.graph import Graph
from rwt_protocol.auth import AUTH_CHALLENGE_ID, rosauth_op
from rwt_protocol.codecs.json import op_object
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig, rosauth_authenticator
from rwt_transports.udp.transport import UdpOptions
from rwt_transports.udp.validation import (
    AMPLIFICATION,
    CHALLENGE_BUDGET_BYTES,
    CHALLENGE_TEXT,
    EPOCH_S,
    MIN_PROBE_BYTES,
    SESSION_CHALLENGE_TEXT,
)
from tests.hardening.test_udp_spoofing import datagrams_within
from tests.support.clients import Harness, Message, UdpClient, is_op, running_server
from tests.transports.test_auth_bind import SECRET, signed

pytestmark = pytest.mark.anyio

TIMEOUT_S = 20
FIRST_OP_NOT_AUTH = "authentication required: the first op must be auth"


def bound_config(**udp: Any) -> ServerConfig:
    return ServerConfig(session=SessionConfig(auth_challenge=True), udp=UdpOptions(**udp))


@pytest.fixture
async def graph() -> Graph:
    return Graph()


@pytest.fixture
async def harness(graph: Graph) -> AsyncIterator[Harness]:
    authenticator = rosauth_authenticator(SECRET, graph.clock, bind_connection=True)
    with anyio.fail_after(TIMEOUT_S):
        async with running_server(bound_config(), graph=graph, authenticator=authenticator) as h:
            yield h


async def validate(sock: ConnectedUDPSocket) -> tuple[bytes, str]:
    """The address validation as docs/server.md tells it: the token and the auth challenge.

    A client without a token takes either challenge (one saying the address has a
    session comes to a client restarted on the same port).

    Returns:
        The prefix of every later datagram (the token, a newline) and the challenge.
    """
    while True:  # UDP loses datagrams: a probe without both answers is sent again
        await sock.send(b'{"op":"status"}'.ljust(MIN_PROBE_BYTES))
        token = nonce = None
        with anyio.move_on_after(1.0):
            while token is None or nonce is None:
                reply = json.loads(await sock.receive())
                if reply.get("msg") in (CHALLENGE_TEXT, SESSION_CHALLENGE_TEXT):
                    token = reply["id"]
                elif reply.get("id") == AUTH_CHALLENGE_ID:
                    nonce = reply["msg"]
        if token is not None and nonce is not None:
            return token.encode() + b"\n", nonce


async def udp_socket(harness: Harness, local_port: int = 0) -> ConnectedUDPSocket:
    sock = await anyio.create_connected_udp_socket(
        "127.0.0.1", harness.port("udp"), local_host="127.0.0.1", local_port=local_port
    )
    harness.stack.push_async_callback(sock.aclose)
    return sock


def udp_sessions(harness: Harness) -> int:
    return sum(1 for client_id in harness.server.sessions if client_id.startswith("udp:"))


async def until(condition: Any) -> None:
    while not condition():
        await anyio.sleep(0.01)


async def authenticated(harness: Harness, name: str) -> UdpClient:
    """A UDP client through the whole documented flow: validation, then its ``auth``."""
    sock = await udp_socket(harness)
    prefix, nonce = await validate(sock)
    client = UdpClient(name, sock=sock, prefix=prefix)
    await client.send(signed(nonce))
    await client.send({"op": "set_level", "level": "info", "id": "in"})
    assert (await client.expect(is_op("status", id="in")))["level"] == "info"
    return client


async def test_an_honest_udp_client_authenticates_then_subscribes_and_publishes(
    harness: Harness, graph: Graph
) -> None:
    received: list[Message] = []
    graph.create_subscription("/cmd", received.append, "std_msgs/msg/String")
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    with anyio.fail_after(TIMEOUT_S):
        client = await authenticated(harness, "udp")
        await client.send({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/String"})
        await client.send({"op": "advertise", "topic": "/cmd", "type": "std_msgs/String"})
        await client.send({"op": "set_level", "level": "info", "id": "ready"})
        await client.expect(is_op("status", id="ready"))
        publisher.publish({"data": "to the udp client"})
        message = await client.expect(is_op("publish", topic="/chatter"))
        assert message["msg"] == {"data": "to the udp client"}
        await client.send({"op": "publish", "topic": "/cmd", "msg": {"data": "from udp"}})
        await until(lambda: received)
    assert received == [{"data": "from udp"}]
    assert udp_sessions(harness) == 1


async def test_a_wrong_mac_is_refused_and_the_client_may_sign_again(harness: Harness) -> None:
    sock = await udp_socket(harness)
    with anyio.fail_after(TIMEOUT_S):
        prefix, nonce = await validate(sock)
        client = UdpClient("udp", sock=sock, prefix=prefix)
        await client.send(signed(nonce, secret="not the secret"))
        refused = await client.expect(is_op("status", level="error"))
        assert "authentication failed" in refused["msg"]
        await until(lambda: udp_sessions(harness) == 0)  # the refused session is gone
        await client.send({"op": "set_level", "level": "info", "id": "x"})
        refused = await client.expect(is_op("status", level="error", id="x"))
        assert refused["msg"] == f"set_level: {FIRST_OP_NOT_AUTH}"  # not admitted
        await client.send(signed(nonce))  # the address's challenge still holds
        await client.send({"op": "set_level", "level": "info", "id": "in"})
        assert (await client.expect(is_op("status", id="in")))["level"] == "info"


async def test_an_auth_op_signed_for_another_address_is_refused(harness: Harness) -> None:
    with anyio.fail_after(TIMEOUT_S):
        first = await udp_socket(harness)
        prefix, nonce = await validate(first)
        captured = signed(nonce)
        thief = await udp_socket(harness)
        thief_prefix, thief_nonce = await validate(thief)
        assert thief_nonce != nonce  # one challenge per address
        client = UdpClient("thief", sock=thief, prefix=thief_prefix)
        await client.send(captured)
        refused = await client.expect(is_op("status", level="error"))
        assert "authentication failed" in refused["msg"]
        owner = UdpClient("owner", sock=first, prefix=prefix)
        await owner.send(captured)
        await owner.send({"op": "set_level", "level": "info", "id": "in"})
        assert (await owner.expect(is_op("status", id="in")))["level"] == "info"


async def test_an_op_before_auth_gets_an_error_and_opens_no_session(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)
    sock = await udp_socket(harness)
    with anyio.fail_after(TIMEOUT_S):
        prefix, nonce = await validate(sock)
        client = UdpClient("udp", sock=sock, prefix=prefix)
        await client.send({"op": "subscribe", "topic": "/chatter", "id": "sub"})
        refused = await client.expect(is_op("status", id="sub"))
        assert refused["level"] == "error"
        assert refused["msg"] == f"subscribe: {FIRST_OP_NOT_AUTH}"
        again = await client.expect(is_op("status", id=AUTH_CHALLENGE_ID))
        assert again["msg"] == nonce  # the challenge again, for a client that lost it
        call = {"op": "call_service", "service": "/rosapi/topics", "id": "call"}
        await client.send(call)
        reply = await client.expect(is_op("service_response", id="call"))
        assert reply["result"] is False  # a call is answered, never left waiting (D4)
        await client.send_raw(b"not json")
        refused = await client.expect(lambda m: "invalid JSON" in m.get("msg", ""))
        assert refused["msg"].startswith("authentication required: invalid JSON")
    assert udp_sessions(harness) == 0
    assert udp_connects(caplog) == 0  # no session began and ended at once
    with anyio.fail_after(TIMEOUT_S):
        await client.send(signed(nonce))
        await client.send({"op": "set_level", "level": "info", "id": "in"})
        assert (await client.expect(is_op("status", id="in")))["level"] == "info"
    assert udp_connects(caplog) == 1  # the auth op began the session


def udp_connects(caplog: pytest.LogCaptureFixture) -> int:
    """Sessions begun over UDP, by their ``event=connect`` log lines."""
    lines = [r.getMessage() for r in caplog.records if r.name.startswith("rwt")]
    return sum(1 for line in lines if "event=connect" in line and "transport=udp" in line)


async def test_an_unvalidated_auth_op_draws_only_the_bounded_challenge(harness: Harness) -> None:
    # The challenge and the auth challenge together stay within the amplification
    # bound and the per-address budget; no session, whatever the datagram holds.
    victim = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    victim.setblocking(False)
    victim.bind(("127.0.0.1", 0))
    server = ("127.0.0.1", harness.port("udp"))
    probe = json.dumps(signed("0" * 32)).encode()
    epoch = int(time.monotonic() // EPOCH_S)  # the server's clock, in this process
    try:
        victim.sendto(probe, server)
        first = await datagrams_within(victim, 1.0, server[1])
        for _ in range(100):
            victim.sendto(probe, server)
        later = await datagrams_within(victim, 1.0, server[1])
    finally:
        victim.close()
    # the budget is per epoch: a run that crossed an epoch's end had two
    epochs = int(time.monotonic() // EPOCH_S) - epoch + 1
    assert [json.loads(d).get("id") for d in first][1:] == [AUTH_CHALLENGE_ID]
    assert sum(map(len, first)) <= AMPLIFICATION * len(probe)
    assert sum(map(len, first + later)) <= CHALLENGE_BUDGET_BYTES * epochs
    assert udp_sessions(harness) == 0


async def test_with_trusted_addresses_a_refusal_carries_the_challenge(graph: Graph) -> None:
    # No validation to carry it: the first plain datagram that is not auth brings it.
    authenticator = rosauth_authenticator(SECRET, graph.clock, bind_connection=True)
    config = bound_config(trust_source_address=True)
    async with running_server(config, graph=graph, authenticator=authenticator) as harness:
        sock = await udp_socket(harness)
        client = UdpClient("udp", sock=sock)
        with anyio.fail_after(TIMEOUT_S):
            await client.send({"op": "set_level", "level": "info", "id": "early"})
            refused = await client.expect(is_op("status", id="early"))
            assert refused["msg"] == f"set_level: {FIRST_OP_NOT_AUTH}"
            challenge = await client.expect(is_op("status", id=AUTH_CHALLENGE_ID))
            await client.send(signed(challenge["msg"]))
            await client.send({"op": "set_level", "level": "info", "id": "in"})
            assert (await client.expect(is_op("status", id="in")))["level"] == "info"


async def test_rosauth_over_udp_opens_a_session_with_the_auth_op_only(graph: Graph) -> None:
    # Without binding the first datagram is the rosauth op; anything else opens nothing.
    authenticator = rosauth_authenticator(SECRET, graph.clock)
    async with running_server(graph=graph, authenticator=authenticator) as harness:
        client = await harness.connect("udp")
        with anyio.fail_after(TIMEOUT_S):
            await client.send({"op": "set_level", "level": "info", "id": "early"})
            refused = await client.expect(is_op("status", id="early"))
            assert refused["msg"] == f"set_level: {FIRST_OP_NOT_AUTH}"
            assert udp_sessions(harness) == 0
            now = int(time.time())
            fields = {"client": "c", "dest": "d", "rand": "r", "t": now, "level": "user"}
            op = rosauth_op(SECRET, **fields, end=now + 60)  # type: ignore[arg-type]
            await client.send(op_object(op))
            await client.send({"op": "set_level", "level": "info", "id": "in"})
            assert (await client.expect(is_op("status", id="in")))["level"] == "info"


async def test_a_client_restarted_on_the_same_port_authenticates_again(harness: Harness) -> None:
    # Its probe draws the challenge saying the address has a session, and the auth
    # challenge with it, both within the amplification bound of a minimal probe.
    with anyio.fail_after(TIMEOUT_S):
        first = await authenticated(harness, "first")
        port = first.sock.extra(SocketAttribute.local_port)
        await first.sock.aclose()
        sock = await udp_socket(harness, local_port=port)
        await sock.send(b'{"op":"status"}'.ljust(MIN_PROBE_BYTES))
        answer = [json.loads(await sock.receive()) for _ in range(2)]
        assert [m["msg"] for m in answer][:1] == [SESSION_CHALLENGE_TEXT]
        assert answer[1]["id"] == AUTH_CHALLENGE_ID
        client = UdpClient("restarted", sock=sock, prefix=answer[0]["id"].encode() + b"\n")
        await client.send(signed(answer[1]["msg"]))
        await client.send({"op": "set_level", "level": "info", "id": "in"})
        assert (await client.expect(is_op("status", id="in")))["level"] == "info"
    assert udp_sessions(harness) == 1  # the old session was replaced
