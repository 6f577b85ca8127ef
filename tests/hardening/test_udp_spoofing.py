"""UDP does not trust the source address (docs/limits.md, UDP).

Before, a 62-byte ``subscribe`` from an address that never spoke again drew a
stream to it until the idle timeout (a reflection and amplification tool), and a
datagram with a forged source address acted inside that peer's session, after
it authenticated too. Forged datagrams are sent for real here: a raw socket
writes the UDP header itself, with the victim's source port (needs root).
"""

from __future__ import annotations

import json
import os
import socket
import struct
from collections.abc import AsyncIterator
from dataclasses import replace

import anyio
import pytest
from anyio.abc import SocketAttribute

from rwt_graph.graph import Graph
from rwt_protocol.ops import Auth
from rwt_transports.server import ServerConfig
from rwt_transports.udp.transport import UdpOptions
from rwt_transports.udp.validation import (
    AMPLIFICATION,
    CHALLENGE_BUDGET_BYTES,
    CHALLENGE_TEXT,
    SESSION_CHALLENGE_TEXT,
    AddressValidator,
)
from tests.support.clients import Harness, Message, UdpClient, is_op, running_server, validate_udp

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10
SUBSCRIBE = b'{"op":"subscribe","topic":"/camera","type":"std_msgs/String"}'
AUTH = {
    "op": "auth",
    "mac": "secret",
    "client": "c",
    "dest": "d",
    "rand": "r",
    "t": 0,
    "level": "admin",
    "end": 0,
}
needs_root = pytest.mark.skipif(os.geteuid() != 0, reason="forging a source port needs root")


async def camera(graph: Graph) -> None:
    """Publish on /camera every 10 ms: what a reflected subscription would stream."""
    publisher = graph.create_publisher("/camera", "std_msgs/msg/String")
    while True:
        publisher.publish({"data": "x" * 500})
        await anyio.sleep(0.01)


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    graph = Graph()
    async with running_server(graph=graph) as h, anyio.create_task_group() as tg:
        tg.start_soon(camera, graph)
        yield h
        tg.cancel_scope.cancel()


def udp_sessions(harness: Harness) -> int:
    return sum(1 for client_id in harness.server.sessions if client_id.startswith("udp:"))


async def datagrams_within(sock: socket.socket, seconds: float, server_port: int) -> list[bytes]:
    """What the server (127.0.0.1:``server_port``) sent to ``sock`` within ``seconds``.

    Datagrams from elsewhere are not counted: the port is ephemeral, and other
    processes on the machine (DDS discovery of ROS 2 nodes) may reach it.
    """
    received = []
    with anyio.move_on_after(seconds):
        while True:
            await anyio.wait_readable(sock)
            data, (_host, port) = sock.recvfrom(65536)
            if port == server_port:
                received.append(data)
    return received


def forge(port_from: int, port_to: int, payload: bytes) -> None:
    """Send ``payload`` to 127.0.0.1:``port_to`` as if from 127.0.0.1:``port_from``."""
    raw = socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_UDP)
    try:
        header = struct.pack("!HHHH", port_from, port_to, 8 + len(payload), 0)  # no checksum
        raw.sendto(header + payload, ("127.0.0.1", 0))
    finally:
        raw.close()


async def forging_works(server_port: int) -> None:
    """A forged probe from a port we listen on draws the challenge there: forging works."""
    witness = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    witness.setblocking(False)
    witness.bind(("127.0.0.1", 0))
    try:
        forge(witness.getsockname()[1], server_port, SUBSCRIBE)
        [challenge] = await datagrams_within(witness, 0.5, server_port)
        assert json.loads(challenge)["msg"] == CHALLENGE_TEXT
    finally:
        witness.close()


async def test_an_unvalidated_subscribe_draws_one_small_answer_and_no_stream(
    harness: Harness,
) -> None:
    victim = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    victim.setblocking(False)
    victim.bind(("127.0.0.1", 0))
    try:
        victim.sendto(SUBSCRIBE, ("127.0.0.1", harness.port("udp")))
        received = await datagrams_within(victim, 1.0, harness.port("udp"))
    finally:
        victim.close()
    assert len(received) == 1
    assert len(received[0]) <= AMPLIFICATION * len(SUBSCRIBE)
    assert json.loads(received[0])["msg"] == CHALLENGE_TEXT
    assert udp_sessions(harness) == 0


async def test_a_datagram_too_short_to_answer_gets_nothing(harness: Harness) -> None:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.setblocking(False)
    try:
        probe.sendto(b"{}", ("127.0.0.1", harness.port("udp")))
        assert await datagrams_within(probe, 0.5, harness.port("udp")) == []
    finally:
        probe.close()


@needs_root
async def test_a_forged_source_cannot_act_inside_an_authenticated_session() -> None:
    def admit(op: Auth, peer: str) -> bool:
        return op.mac == "secret"

    async with running_server(ServerConfig(), authenticator=admit) as harness:
        victim = await harness.connect("udp", "victim")
        assert isinstance(victim, UdpClient)
        listener = await harness.connect("ws", "listener")
        with anyio.fail_after(TIMEOUT_S):
            for client in (victim, listener):
                await client.send(AUTH)
            await listener.send({"op": "subscribe", "topic": "/cmd", "type": "std_msgs/String"})
            await listener.send({"op": "set_level", "level": "info", "id": "ready"})
            await listener.expect(is_op("status", id="ready"))
            await victim.send({"op": "advertise", "topic": "/cmd", "type": "std_msgs/String"})
            await victim.send({"op": "set_level", "level": "info", "id": "advertised"})
            await victim.expect(is_op("status", id="advertised"))
            server_port = harness.port("udp")
            await forging_works(server_port)
            victim_port = victim.sock.extra(SocketAttribute.local_port)
            forged = b'{"op":"publish","topic":"/cmd","msg":{"data":"forged"}}'
            forge(victim_port, server_port, forged)  # no token
            forge(victim_port, server_port, b"A" * 22 + b"\n" + forged)  # a guessed one
            await anyio.sleep(0.2)
            await victim.send({"op": "publish", "topic": "/cmd", "msg": {"data": "real"}})
            message = await listener.expect(is_op("publish", topic="/cmd"))
            assert message["msg"] == {"data": "real"}  # the forged ones never arrived
            await victim.send({"op": "set_level", "level": "info", "id": "alive"})
            assert (await victim.expect(is_op("status", id="alive")))["level"] == "info"


async def test_udp_sessions_are_capped_and_the_others_served() -> None:
    config = ServerConfig(udp=UdpOptions(max_sessions=2))
    async with running_server(config) as harness:
        first, second, third = [await harness.connect("udp", f"c{i}") for i in range(3)]
        with anyio.fail_after(TIMEOUT_S):
            for client in (first, second):
                await client.send({"op": "set_level", "level": "info", "id": "in"})
                assert (await client.expect(is_op("status", id="in")))["level"] == "info"
            await third.send({"op": "set_level", "level": "info", "id": "in"})
            assert (await third.receive())["msg"] == "too many connections"
            await first.send({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
            assert (await first.expect(is_op("service_response", id="t")))["result"] is True


async def test_trusting_the_source_address_serves_plain_datagrams() -> None:
    config = ServerConfig()
    config = replace(config, udp=UdpOptions(trust_source_address=True))
    async with running_server(config) as harness:
        sock = await anyio.create_connected_udp_socket("127.0.0.1", harness.port("udp"))
        async with sock:
            with anyio.fail_after(TIMEOUT_S):
                await sock.send(b'{"op":"set_level","level":"info","id":"plain"}')
                assert json.loads(await sock.receive())["id"] == "plain"


async def test_a_validated_client_keeps_its_token_for_the_session(harness: Harness) -> None:
    sock = await anyio.create_connected_udp_socket("127.0.0.1", harness.port("udp"))
    async with sock:
        with anyio.fail_after(TIMEOUT_S):
            prefix = await validate_udp(sock)
            await sock.send(prefix + b'{"op":"set_level","level":"info","id":"one"}')
            assert json.loads(await sock.receive())["id"] == "one"
            assert udp_sessions(harness) == 1
            bare = b'{"op":"set_level","level":"info","id":"bare"}'
            await sock.send(bare)  # no token: not served, only challenged
            assert json.loads(await sock.receive())["msg"] == SESSION_CHALLENGE_TEXT
            await sock.send(prefix + b'{"op":"set_level","level":"info","id":"two"}')
            assert json.loads(await sock.receive())["id"] == "two"


async def test_challenges_to_one_address_are_capped_in_bytes(harness: Harness) -> None:
    # A forged source can draw challenges towards its victim, but only so many bytes.
    victim = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    victim.setblocking(False)
    victim.bind(("127.0.0.1", 0))
    try:
        for _ in range(100):
            victim.sendto(SUBSCRIBE, ("127.0.0.1", harness.port("udp")))
        received = await datagrams_within(victim, 1.0, harness.port("udp"))
    finally:
        victim.close()
    assert len(received) >= 1 and sum(map(len, received)) <= CHALLENGE_BUDGET_BYTES
    healthy = await harness.connect("udp", "healthy")  # another address is still answered
    with anyio.fail_after(TIMEOUT_S):
        await healthy.send({"op": "set_level", "level": "info", "id": "ok"})
        assert (await healthy.expect(is_op("status", id="ok")))["level"] == "info"


async def test_udp_peers_written_at_once_all_stay_served(
    harness: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    # Every peer's writer shares one socket; two writing at once once closed a session.
    peers = [await harness.connect("udp", f"peer{i}") for i in range(8)]
    with anyio.fail_after(TIMEOUT_S):
        for peer in peers:
            await peer.send({"op": "subscribe", "topic": "/camera", "type": "std_msgs/String"})
        for peer in peers:  # the camera publishes every 10 ms: several messages each
            for _ in range(5):
                await peer.expect(is_op("publish", topic="/camera"))
        for peer in peers:
            await peer.send({"op": "set_level", "level": "info", "id": "alive"})
            await peer.expect(is_op("status", id="alive"))
    assert "event=bug" not in caplog.text


async def test_a_client_restarted_on_the_same_port_validates_again(harness: Harness) -> None:
    # Its old session still holds the address; a fresh token for it takes over at once.
    first = await anyio.create_udp_socket(local_host="127.0.0.1", local_port=0)
    port = first.extra(SocketAttribute.local_port)
    server = ("127.0.0.1", harness.port("udp"))
    await first.aclose()
    for run in ("first", "restarted"):
        sock = await anyio.create_connected_udp_socket(
            *server, local_host="127.0.0.1", local_port=port
        )
        async with sock:
            with anyio.fail_after(TIMEOUT_S):
                prefix = await validate_udp(sock)
                await sock.send(
                    prefix + b'{"op":"set_level","level":"info","id":"%s"}' % run.encode()
                )
                assert json.loads(await sock.receive())["id"] == run
    assert udp_sessions(harness) == 1  # the old session was replaced, not kept


def follow_challenge(client: UdpClient, challenge: Message) -> None:
    """Do what docs/limits.md tells a client that holds a token to do with a challenge.

    A plain one (its session is gone) gives the new token, which it takes; one
    saying the address has a session is ignored.
    """
    if challenge["msg"] == CHALLENGE_TEXT:
        client.prefix = challenge["id"].encode() + b"\n"


def is_challenge(message: Message) -> bool:
    return message.get("msg") in (CHALLENGE_TEXT, SESSION_CHALLENGE_TEXT)


@needs_root
async def test_a_forged_datagram_after_the_token_epoch_costs_the_session_nothing(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Once the 30 s epoch rolled, the challenge a forged datagram drew carried a new
    # token; the victim, taking it as the docs said, lost its session, its
    # subscription and its authentication to a fresh one.
    epoch = [0]
    monkeypatch.setattr(AddressValidator, "_epoch", lambda self: epoch[0])

    def admit(op: Auth, peer: str) -> bool:
        return op.mac == "secret"

    graph = Graph()
    async with (
        running_server(ServerConfig(), graph=graph, authenticator=admit) as harness,
        anyio.create_task_group() as tg,
    ):
        victim = await harness.connect("udp", "victim")
        assert isinstance(victim, UdpClient)
        listener = await harness.connect("ws", "listener")
        with anyio.fail_after(TIMEOUT_S):
            for client in (victim, listener):
                await client.send(AUTH)
            await listener.send({"op": "subscribe", "topic": "/cmd", "type": "std_msgs/String"})
            await listener.send({"op": "set_level", "level": "info", "id": "ready"})
            await listener.expect(is_op("status", id="ready"))
            await victim.send(json.loads(SUBSCRIBE))
            await victim.send({"op": "advertise", "topic": "/cmd", "type": "std_msgs/String"})
            await victim.send({"op": "set_level", "level": "info", "id": "set"})
            await victim.expect(is_op("status", id="set"))
            server_port = harness.port("udp")
            await forging_works(server_port)
            epoch[0] += 1  # the token epoch rolls: a challenge now carries a new token
            victim_port = victim.sock.extra(SocketAttribute.local_port)
            forge(victim_port, server_port, SUBSCRIBE)
            follow_challenge(victim, await victim.expect(is_challenge))
            tg.start_soon(camera, graph)
            await victim.expect(is_op("publish", topic="/camera"))  # still subscribed
            await victim.send({"op": "publish", "topic": "/cmd", "msg": {"data": "still me"}})
            await victim.send({"op": "set_level", "level": "info", "id": "alive"})
            assert (await victim.expect(is_op("status", id="alive")))["level"] == "info"
            message = await listener.expect(is_op("publish", topic="/cmd"))
            assert message["msg"] == {"data": "still me"}  # still authenticated
        assert udp_sessions(harness) == 1
        tg.cancel_scope.cancel()
