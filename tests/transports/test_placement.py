"""Topic placement's parts (``rwt_transports.workers.placement``, D57): which first message places a
connection, which worker owns a topic, and the hand-off of a socket with the bytes read.

The whole path, with roslibpy clients on ``rwt serve --workers 2 --placement topic``, is
tests/zenoh/test_placement.py.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import struct
import zlib
from pathlib import Path

import anyio
import pytest
from websockets.frames import Frame, Opcode

from rwt_protocol.runtime.inframes import InFrame
from rwt_transports.config import ServerConfig
from rwt_transports.rosbridge import first_topic as placed_topic
from rwt_transports.server import RosbridgeServer
from rwt_transports.websocket import _whole_messages
from rwt_transports.workers import placement
from rwt_transports.workers.placement import RECORD_LIMIT_BYTES, Placement
from tests.support.cli import invoke_rwt
from tests.support.rawws import server_frame, upgrade_with

pytestmark = pytest.mark.anyio


def text(message: object) -> InFrame:
    return InFrame(json.dumps(message).encode())


@pytest.mark.parametrize("op", ["subscribe", "advertise", "publish"])
def test_a_first_topic_op_places_the_connection_by_its_topic(op: str) -> None:
    assert placed_topic(text({"op": op, "topic": "/chatter", "type": "std_msgs/String"})) == (
        "/chatter"
    )


@pytest.mark.parametrize(
    "frame",
    [
        text({"op": "call_service", "service": "/rosapi/topics"}),  # the session would hold it
        text({"op": "auth", "mac": "x"}),
        text({"op": "subscribe"}),
        text({"op": "subscribe", "topic": 7}),
        text({"op": "subscribe", "topic": ""}),
        text({"op": "subscribe", "topic": 10**400}),  # a huge int: not a name
        InFrame(b'{"op": "subscribe", "topic": "/a", "topic": [0]}'),  # the last key counts
        text(["subscribe", "/chatter"]),
        InFrame(b'{"op": "subscribe", "topic": "/chatter"', False),  # not JSON
        InFrame(b"\xa2bopisubscribeetopich/chatter", True),  # CBOR stays
    ],
)
def test_anything_else_stays_where_it_landed(frame: InFrame) -> None:
    assert placed_topic(frame) is None


def test_topics_are_owned_in_turn_and_every_worker_names_the_same_owner(tmp_path: Path) -> None:
    workers = [Placement(str(tmp_path), index, 4) for index in range(4)]
    topics = [f"/fan{n}" for n in range(6)]
    first = [workers[n % 4].owner(topic) for n, topic in enumerate(topics)]  # claimed by any
    assert first == [0, 1, 2, 3, 0, 1]
    for worker in workers:
        assert [worker.owner(topic) for topic in topics] == first
    assert Placement(str(tmp_path), 2, 4).owner("/fan3") == 3  # a restarted worker too


def test_past_the_claims_or_without_a_folder_a_topics_hash_names_its_owner(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(placement, "MAX_CLAIMS", 2)
    worker = Placement(str(tmp_path), 0, 4)
    assert [worker.owner("/a"), worker.owner("/b")] == [0, 1]
    for topic in ("/c", "/ü", "/camera/image_raw"):
        assert worker.owner(topic) == zlib.crc32(topic.encode()) % 4
    assert len(list(tmp_path.iterdir())) == 2  # no more claims than that
    gone = Placement(str(tmp_path / "gone"), 1, 4)
    assert gone.owner("/tf") == zlib.crc32(b"/tf") % 4


def test_an_odd_topic_still_names_one_owner_and_stays_within_the_claims(tmp_path: Path) -> None:
    """A lone surrogate, a reserved name, a 1 MB name: one owner each, a small file each.

    The session refuses such names afterwards, on whichever worker, as ever.
    """
    workers = [Placement(str(tmp_path), index, 2) for index in range(2)]
    for topic in (json.loads('"/\\ud800"'), "/rosout", "/" + "x" * 1_000_000):
        assert workers[0].owner(topic) == workers[1].owner(topic) in (0, 1)
    assert all(len(path.name) < 64 for path in tmp_path.iterdir())


def test_a_worker_knows_its_place_from_its_state_file() -> None:
    assert Placement.of_state("/run/w/worker-3", 4) == Placement("/run/w", 3, 4)
    assert Placement.of_state("/run/w/worker-3", 1) is None  # one worker: nowhere to go
    assert Placement.of_state("/run/w/elsewhere", 4) is None


async def test_a_connection_handed_over_is_the_same_connection_with_its_bytes(
    tmp_path: Path,
) -> None:
    giver, taker = Placement(str(tmp_path), 0, 2), Placement(str(tmp_path), 1, 2)
    taken: list[tuple[socket.socket, bytes]] = []
    arrived = anyio.Event()

    def take(sock: socket.socket, record: bytes) -> None:
        taken.append((sock, record))
        arrived.set()

    client, server = socket.socketpair()
    async with anyio.create_task_group() as tg:
        await tg.start(taker.serve, take)
        assert await giver.hand_off(1, server.fileno(), b"GET / HTTP/1.1\r\n\r\nframes") is True
        server.close()  # the giver's descriptor goes; the connection stays the taker's
        with anyio.fail_after(5):
            await arrived.wait()
        tg.cancel_scope.cancel()
    sock, record = taken[0]
    assert record == b"GET / HTTP/1.1\r\n\r\nframes"
    with client, sock:
        sock.sendall(b"from the new worker")
        assert client.recv(100) == b"from the new worker"


async def test_an_owner_that_cannot_be_reached_leaves_the_connection_here(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, "rwt.workers")
    client, server = socket.socketpair()
    with client, server:
        assert await Placement(str(tmp_path), 0, 2).hand_off(1, server.fileno(), b"x") is False
        server.sendall(b"still ours")
        assert client.recv(100) == b"still ours"
    assert "event=placement_failed owner=1" in caplog.text


@pytest.mark.parametrize(
    "send",
    [
        "no descriptor",
        "a record over the limit",
        "a record cut short",
        "not a stream socket",
    ],
)
async def test_a_bad_hand_off_is_dropped_and_the_next_is_taken(tmp_path: Path, send: str) -> None:
    taker = Placement(str(tmp_path), 1, 2)
    taken: list[bytes] = []

    def take(sock: socket.socket, record: bytes) -> None:
        sock.close()
        taken.append(record)

    async with anyio.create_task_group() as tg:
        await tg.start(taker.serve, take)
        bad = await anyio.connect_unix(taker.path(1))
        async with bad:
            header = struct.pack("!I", 10)
            if send == "no descriptor":
                await bad.send(header + b"0123456789")
            elif send == "a record over the limit":
                one, two = socket.socketpair()
                with one, two:
                    await bad.send_fds(struct.pack("!I", RECORD_LIMIT_BYTES + 1), [one.fileno()])
            elif send == "a record cut short":
                one, two = socket.socketpair()
                with one, two:
                    await bad.send_fds(header, [one.fileno()])
                    await bad.send(b"0123")
            else:
                one, two = socket.socketpair(type=socket.SOCK_DGRAM)
                with one, two:
                    await bad.send_fds(header, [one.fileno()])
                    await bad.send(b"0123456789")
            await bad.send_eof()
            with anyio.fail_after(5), pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
                await bad.receive(1)  # dropped without a word: no ``taken``
        one, two = socket.socketpair()
        with one, two:
            assert await Placement(str(tmp_path), 0, 2).hand_off(1, one.fileno(), b"good") is True
        with anyio.fail_after(5):
            while not taken:
                await anyio.sleep(0.01)
        tg.cancel_scope.cancel()
    assert taken == [b"good"]
    assert len(os.listdir(tmp_path)) == 1  # the socket only


def _landed(port: int, messages: list[object]) -> tuple[socket.socket, socket.socket, bytes]:
    """A client that sent its upgrade and ``messages`` at once to a socket of the test's
    (the worker it landed on): the client, the landed side, and every byte read there.
    """
    with socket.create_server(("127.0.0.1", 0)) as landing:
        client = socket.create_connection(landing.getsockname())
        landed, _ = landing.accept()
    sent = upgrade_with(port, messages)
    client.sendall(sent)
    record = b""
    while len(record) < len(sent):
        record += landed.recv(65536)
    return client, landed, record


def _next_frame(client: socket.socket, data: bytes) -> tuple[int, bytes, bytes]:
    while (frame := server_frame(data)) is None:
        more = client.recv(65536)
        assert more, "the connection ended"
        data += more
    return frame


async def test_a_connection_handed_here_is_served_and_one_refused_here_closes_with_1013(
    tmp_path: Path,
) -> None:
    """The owner's side of a hand-off (``serve_websocket_connection(resumed=...)``).

    The client's first messages, read by the worker it landed on, are answered here,
    with no second upgrade response; when this server is full the connection is closed
    with 1013 (try again later), since its upgrade was accepted already.
    """
    giver = Placement(str(tmp_path), 0, 2)
    config = ServerConfig(port=0, max_connections=2, placement=Placement(str(tmp_path), 1, 2))
    server = RosbridgeServer(config=config)
    async with anyio.create_task_group() as tg:
        port = int((await tg.start(server.serve)).rsplit(":", 1)[1])
        with anyio.fail_after(5):
            while not await anyio.Path(giver.path(1)).exists():
                await anyio.sleep(0.01)
        call = {"op": "call_service", "id": "c1", "service": "/rosapi/topics", "args": {}}
        subscribe = {"op": "subscribe", "topic": "/placed", "type": "std_msgs/msg/String"}
        client, landed, record = _landed(port, [subscribe, call])
        with landed:  # the landed worker's descriptor goes once handed over
            assert await giver.hand_off(1, landed.fileno(), record) is True
        with client:
            data = b""
            opcode, payload, data = await anyio.to_thread.run_sync(_next_frame, client, data)
            assert opcode == 1, payload  # a text frame: no HTTP response came first
            answer = json.loads(payload)
            assert answer["op"] == "service_response" and answer["id"] == "c1"
            assert "/placed" in answer["values"]["topics"]
            # full: this one and another fill both slots; the next handed here is closed
            async with await anyio.connect_tcp("127.0.0.1", port) as other:
                await other.send(upgrade_with(port, []))
                assert (await other.receive()).startswith(b"HTTP/1.1 101")
                third, landed, record = _landed(port, [subscribe])
                with landed:
                    assert await giver.hand_off(1, landed.fileno(), record) is True
                with third:
                    opcode, payload, _ = await anyio.to_thread.run_sync(_next_frame, third, b"")
                    assert opcode == 8  # close
                    assert int.from_bytes(payload[:2], "big") == 1013
                    assert b"too many connections" in payload
        server.stop()


def test_a_record_of_whole_messages_lets_the_fast_reader_take_over_after_it() -> None:
    """``_handshake``'s test for where ``FrameReader`` may start: after the request, whole
    frames each a whole message or control (a handed-off record, or frames sent with it).
    """
    request = bytearray(b"GET / HTTP/1.1\r\n\r\n")
    at = len(request)
    text = Frame(Opcode.TEXT, b'{"op": "subscribe"}').serialize(mask=True)
    long = Frame(Opcode.TEXT, b"x" * 70_000).serialize(mask=True)
    ping = Frame(Opcode.PING, b"").serialize(mask=True)
    first = Frame(Opcode.TEXT, b"part", fin=False).serialize(mask=True)
    rest = Frame(Opcode.CONT, b"rest").serialize(mask=True)
    assert _whole_messages(request, at)
    assert _whole_messages(request + text + ping + long, at)
    assert not _whole_messages(request + text[:-1], at)  # a frame cut short
    assert not _whole_messages(request + long[:5], at)  # within its length field
    assert not _whole_messages(request + first, at)  # a message goes on
    assert not _whole_messages(request + first + rest, at)


def test_placement_without_workers_is_refused_before_serving() -> None:
    result = invoke_rwt("serve", "--placement", "topic")
    assert result.exit_code == 2
    assert "--placement places connections among workers: add --workers N" in result.stderr
