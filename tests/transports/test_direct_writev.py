"""``DirectWriter.writev``: parts written in one system call, or handed to the transport.

Whatever the socket takes at once, the peer must read exactly the parts
joined, in order: when they all fit, when the socket takes only some (the rest
waits in the transport), and when the transport already holds bytes (nothing
may overtake them). Over a real TCP connection on the default loop and uvloop
(where the transport takes every part itself).
"""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import pytest
from anyio.abc import SocketStream

from rwt_protocol.shortcuts import ENV_VAR
from rwt_transports.direct import DirectWriter

pytestmark = [pytest.mark.anyio, pytest.mark.uvloop_too]  # the paths differ under uvloop


@pytest.fixture(autouse=True)
def shortcuts_on(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)


@asynccontextmanager
async def connected() -> AsyncIterator[tuple[SocketStream, SocketStream]]:
    """A TCP connection on loopback: (the writing end, the reading end)."""
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with listener:
        accepted: list[SocketStream] = []

        async def accept() -> None:
            async with anyio.create_task_group() as tg:

                async def keep(stream: SocketStream) -> None:
                    accepted.append(stream)
                    tg.cancel_scope.cancel()

                await listener.serve(keep, tg)

        async with anyio.create_task_group() as tg:
            tg.start_soon(accept)
            writer = await anyio.connect_tcp("127.0.0.1", port)
        async with writer, accepted[0] as reader:
            yield writer, reader


async def _read(stream: SocketStream, count: int) -> bytes:
    data = bytearray()
    while len(data) < count:
        data += await stream.receive(1 << 20)
    return bytes(data)


def _parts(sizes: list[int]) -> list[bytes]:
    return [os.urandom(size) for size in sizes]


@pytest.mark.parametrize(
    "sizes",
    [
        [2, 100_000],  # a header and its payload: both fit
        [14, 8_000_000, 3, 4_000_000, 9],  # more than the socket takes at once
        [5],
    ],
)
async def test_the_peer_reads_the_parts_in_order(sizes: list[int]) -> None:
    parts = _parts(sizes)
    async with connected() as (writer_end, reader_end):
        writer = DirectWriter.for_stream(writer_end)
        assert writer is not None
        writer.writev(parts)
        with anyio.fail_after(30):
            got = await _read(reader_end, sum(sizes))
    assert got == b"".join(parts)


async def test_bytes_the_transport_holds_are_not_overtaken() -> None:
    first, then = _parts([16_000_000]), _parts([10, 200_000])
    async with connected() as (writer_end, reader_end):
        writer = DirectWriter.for_stream(writer_end)
        assert writer is not None
        writer.write(first[0])  # more than the socket takes: the transport keeps the rest
        assert not writer.ready
        writer.writev(then)
        with anyio.fail_after(30):
            got = await _read(reader_end, 16_000_000 + 200_010)
    assert got == first[0] + b"".join(then)
