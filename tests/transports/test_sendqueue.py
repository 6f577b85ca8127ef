"""A socket's send queue shrinks as its peer reads, before any blocked send completes.

Real loopback TCP: the peer reads nothing at first, so what the kernel holds for
it is counted; then it reads, and the count falls (sendqueue.py, the progress
``holding.wait_for`` asks of a writer it saw complete no send).
"""

from __future__ import annotations

import socket
import sys

import anyio
import pytest

from rwt_transports.sendqueue import stream_unsent_bytes, unsent_bytes

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SIOCOUTQ is Linux's")


def connected_pair(rcvbuf: int) -> tuple[socket.socket, socket.socket]:
    """A TCP connection on loopback: (the writer's end, the reader's end)."""
    with socket.create_server(("127.0.0.1", 0)) as server:
        reader = socket.socket()
        reader.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        reader.connect(server.getsockname())
        writer, _ = server.accept()
    return writer, reader


def fill(sock: socket.socket) -> int:
    """Write until the kernel takes no more; return how much it took."""
    sock.setblocking(False)
    sent = 0
    try:
        while True:
            sent += sock.send(bytes(64 * 1024))
    except BlockingIOError:
        return sent


def test_the_queue_counts_what_the_peer_has_not_read_and_falls_as_it_reads() -> None:
    writer, reader = connected_pair(rcvbuf=64 * 1024)
    try:
        sent = fill(writer)
        before = unsent_bytes(writer)
        assert before is not None and 0 < before <= sent
        taken = 0
        while taken < 256 * 1024:  # the peer reads a quarter of a megabyte
            taken += len(reader.recv(64 * 1024))
        after = unsent_bytes(writer)
        assert after is not None and after < before
    finally:
        writer.close()
        reader.close()


def test_sockets_it_cannot_read_give_none() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        assert unsent_bytes(udp) is None
    closed = socket.socket()
    closed.close()
    assert unsent_bytes(closed) is None


@pytest.mark.anyio
async def test_an_anyio_stream_gives_its_socket_s_queue() -> None:
    async with await anyio.create_tcp_listener(local_host="127.0.0.1") as listener:
        port = listener.extra(anyio.abc.SocketAttribute.local_port)
        async with await anyio.connect_tcp("127.0.0.1", port) as stream:
            assert stream_unsent_bytes(stream) == 0  # nothing written yet
