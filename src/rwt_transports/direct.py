"""Direct use of the asyncio transport under an anyio socket stream (benchmarks/README.md).

Writing: a connection's writer task (pump.py) sends every frame by default.
A frame's small header and its large payload are written together
(``DirectWriter.writev``: one ``writev`` system call, the payload not copied)
where Python 3.11's transport would make two sends, the header a TCP segment
of its own.
For a small message fanned out to many subscribers that costs several task
switches per subscriber (wake the writer, take the lock, await the stream's
send). When a connection's writer is idle and its socket has nothing buffered,
the frames can go out at once instead: the asyncio transport takes bytes
without blocking (it writes what the kernel accepts and keeps the rest).

Reading: anyio's ``SocketStream.receive`` resumes reading before it waits and
pauses it again after each chunk: two ``epoll_ctl`` system calls per message,
plus a loop turn when data was already queued. For a 100 Hz topic that was a
sixth of the server's CPU (py-spy, B6's Twist stream). ``DirectReader`` keeps
reading on while the pump waits for input and takes what has arrived at once.

Only plain sockets on the asyncio backend (the default loop or uvloop) qualify:
a TLS stream encrypts in anyio and must be read and written through it, and
other backends have no transport; those always use anyio's stream. Both are
shortcuts (``direct-read``, ``direct-write``: rwt_protocol/shortcuts.py); with
one switched off, ``for_stream`` gives None and anyio's stream is used.
"""

from __future__ import annotations

import os
import select
from typing import TYPE_CHECKING, Any, Protocol, cast

if TYPE_CHECKING:
    import asyncio
    from collections import deque
    from collections.abc import Sequence

    from anyio.abc import ByteReceiveStream

from rwt_protocol.shortcuts import enabled

__all__ = ["DirectReader", "DirectWriter", "asyncio_parts"]

_IOV_MAX = 1024  # buffers one ``writev`` takes at most (Linux's IOV_MAX)


class _Transport(Protocol):
    """The part of ``asyncio.Transport`` used here (uvloop's transports have it too)."""

    def write(self, data: bytes | memoryview) -> None: ...

    def get_write_buffer_size(self) -> int: ...

    def is_closing(self) -> bool: ...

    def is_reading(self) -> bool: ...

    def pause_reading(self) -> None: ...

    def resume_reading(self) -> None: ...

    def get_extra_info(self, name: str, default: Any = None) -> Any: ...

    def abort(self) -> None: ...


class _StreamProtocol(Protocol):
    """The part of anyio's asyncio ``StreamProtocol`` used here."""

    read_queue: deque[bytes]
    read_event: asyncio.Event
    exception: Exception | None
    is_at_eof: bool


def asyncio_parts(stream: object) -> tuple[_Transport, _StreamProtocol] | None:
    """The transport and protocol of a plain anyio asyncio socket stream, else None.

    Relies on anyio's asyncio ``SocketStream`` keeping them in ``_transport``
    and ``_protocol`` (anyio 4); any other stream (TLS, trio, in-memory) or a
    future anyio without them gets None and is served through anyio alone.
    """
    if type(stream).__module__ != "anyio._backends._asyncio":
        return None
    transport = getattr(stream, "_transport", None)
    protocol = getattr(stream, "_protocol", None)
    if not all(
        callable(getattr(transport, name, None))
        for name in (
            "write",
            "get_write_buffer_size",
            "is_closing",
            "is_reading",
            "pause_reading",
            "resume_reading",
            "get_extra_info",
            "abort",
        )
    ) or not all(
        hasattr(protocol, name) for name in ("read_queue", "read_event", "exception", "is_at_eof")
    ):
        return None
    return cast("_Transport", transport), cast("_StreamProtocol", protocol)


class DirectWriter:
    """Non-blocking writes to the asyncio transport under an anyio socket stream.

    Args:
        transport: the stream's transport.
        protocol: anyio's protocol object of that transport (its ``exception``
            is set when the connection broke).

    The caller keeps the order: it writes here only when no other task is in
    the middle of writing to the same stream (the pump's writer is idle and the
    channel's lock is free). Bytes the kernel does not take at once stay in the
    transport, which then reports itself busy (``ready`` is False) and anyio's
    next ``send`` waits for them to go, so at most one write is held outside
    the session's outbox, as with the writer task.
    """

    __slots__ = ("_fd", "_protocol", "_transport")

    def __init__(self, transport: _Transport, protocol: _StreamProtocol) -> None:
        self._transport = transport
        self._protocol = protocol
        # Gathered writes (``writev``) only under asyncio's own socket transport, whose
        # buffer is all that stands between its writes and the socket; -1: none.
        sock = transport.get_extra_info("socket")
        asyncio_own = type(transport).__module__.startswith("asyncio.")
        self._fd: int = sock.fileno() if asyncio_own and sock is not None else -1

    @classmethod
    def for_stream(cls, stream: object) -> DirectWriter | None:
        """The direct writer of ``stream``, or None.

        None when ``stream`` is not a plain asyncio socket or the ``direct-write``
        shortcut is off.
        """
        parts = asyncio_parts(stream) if enabled("direct-write") else None
        return None if parts is None else cls(*parts)

    @property
    def ready(self) -> bool:
        """Whether a write now would go straight out: open, unbroken, nothing buffered."""
        transport = self._transport
        return (
            not transport.is_closing()
            and transport.get_write_buffer_size() == 0
            and self._protocol.exception is None
        )

    def write(self, data: bytes) -> None:
        """Hand ``data`` to the transport (never blocks; check ``ready`` first).

        Raises:
            RuntimeError: the transport refused (it is closing).
        """
        self._transport.write(data)

    def writev(self, parts: Sequence[bytes]) -> None:
        """Write ``parts`` in order, in one system call where the socket takes them.

        A large payload and the small header before it go out together without
        being joined (``os.writev``), which the transport cannot do (Python
        3.11's ``write`` sends one buffer). That is done only while the
        transport holds nothing, so nothing it holds is overtaken; what the
        socket does not take at once, and every part otherwise, goes to the
        transport as ``write`` would. Never blocks.

        Raises:
            RuntimeError: the transport refused (it is closing).
        """
        transport = self._transport
        sent = 0
        if (
            self._fd >= 0
            and len(parts) > 1
            and not transport.is_closing()
            and transport.get_write_buffer_size() == 0
        ):
            try:
                sent = os.writev(self._fd, parts[:_IOV_MAX])
            except OSError:  # full (EAGAIN), or broken: the transport's write meets it again
                sent = 0
        for part in parts:
            if sent >= len(part):
                sent -= len(part)
                continue
            transport.write(memoryview(part)[sent:] if sent else part)
            sent = 0


class DirectReader:
    """Reads what anyio's protocol has queued, leaving the socket readable between reads.

    Args:
        stream: the anyio stream; at the end of the connection its own
            ``receive`` is called, so the errors are anyio's.
        transport: its asyncio transport.
        protocol: anyio's protocol object of that transport.

    Memory stays bounded as with anyio's pausing: the loop queues a chunk
    (at most 256 KiB on asyncio) per turn only while the reader waits here,
    and the reader takes all of them before it waits again. A reader that must
    await anything else first (a flush of control frames to a peer that may
    not be reading) calls ``pause``; the next ``receive`` resumes reading.
    Only one task may read.

    Whether the socket is being read is asked of the transport each time, not
    remembered: anyio's listener leaves a new connection reading, and its
    ``receive`` pauses only when it had to wait. A handshake whose bytes were
    already queued left reading on, which a remembered "paused" flag hid from
    ``pause``, and a peer that never read its pongs was buffered without bound
    (seen on uvloop under load).
    """

    __slots__ = ("_protocol", "_stream", "_transport")

    def __init__(
        self, stream: ByteReceiveStream, transport: _Transport, protocol: _StreamProtocol
    ) -> None:
        self._stream = stream
        self._transport = transport
        self._protocol = protocol

    @classmethod
    def for_stream(cls, stream: ByteReceiveStream) -> DirectReader | None:
        """The direct reader of ``stream``, or None.

        None when ``stream`` is not a plain asyncio socket or the ``direct-read``
        shortcut is off.
        """
        parts = asyncio_parts(stream) if enabled("direct-read") else None
        return None if parts is None else cls(stream, *parts)

    async def receive(self, max_bytes: int) -> bytes:
        """The next received chunk, at most ``max_bytes`` long; waits for one if none is queued.

        Raises:
            anyio.EndOfStream: the peer closed its side.
            anyio.BrokenResourceError: the connection broke.
            anyio.ClosedResourceError: the stream was closed here.
        """
        protocol = self._protocol
        queue = protocol.read_queue
        if not queue:
            if protocol.is_at_eof or protocol.exception is not None or self._transport.is_closing():
                return await self._stream.receive(max_bytes)
            if not self._transport.is_reading():
                self._transport.resume_reading()
            event = protocol.read_event
            event.clear()  # nothing is queued; only new data (or the end) sets it
            await event.wait()
            if not queue:  # the end of the stream: anyio raises what fits
                return await self._stream.receive(max_bytes)
        chunk = queue.popleft()
        if len(chunk) > max_bytes:
            queue.appendleft(chunk[max_bytes:])
            chunk = chunk[:max_bytes]
        if not queue:
            protocol.read_event.clear()
        return chunk

    def input_pending(self) -> bool:
        """Whether ``receive`` would return at once.

        True for input queued by the loop or readable in the kernel, and for the
        end of the connection. One ``poll`` system call; readers ask it of new
        connections (admission/arrival.py).
        """
        protocol = self._protocol
        if protocol.read_queue or protocol.is_at_eof or protocol.exception is not None:
            return True
        sock = self._transport.get_extra_info("socket")
        if sock is None:
            return True  # closed: ``receive`` says so at once
        poller = select.poll()
        poller.register(sock.fileno(), select.POLLIN)
        return bool(poller.poll(0))

    def pause(self) -> None:
        """Stop reading from the socket until the next ``receive`` waits."""
        transport = self._transport
        if transport.is_reading() and not transport.is_closing():
            transport.pause_reading()
