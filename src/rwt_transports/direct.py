"""Writing to an idle socket from the publish path, without a task switch (issue 8).

A connection's writer task (pump.py) sends every frame by default. For a small
message fanned out to many subscribers that costs several task switches per
subscriber (wake the writer, take the lock, await the stream's send). When a
connection's writer is idle and its socket has nothing buffered, the frames can
go out at once instead: the asyncio transport under anyio's socket stream takes
bytes without blocking (it writes what the kernel accepts and keeps the rest).

Only plain sockets on the asyncio backend (the default loop or uvloop) qualify:
a TLS stream encrypts in anyio and must be written through it, and other
backends have no transport to write to; those always use the writer task.
"""

from __future__ import annotations

from typing import Protocol, cast

__all__ = ["DirectWriter"]


class _Transport(Protocol):
    """The part of ``asyncio.WriteTransport`` used here (uvloop's transports have it too)."""

    def write(self, data: bytes) -> None: ...

    def get_write_buffer_size(self) -> int: ...

    def is_closing(self) -> bool: ...


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

    __slots__ = ("_protocol", "_transport")

    def __init__(self, transport: _Transport, protocol: object) -> None:
        self._transport = transport
        self._protocol = protocol

    @classmethod
    def for_stream(cls, stream: object) -> DirectWriter | None:
        """The direct writer of ``stream``, or None when it is not a plain asyncio socket.

        Relies on anyio's asyncio ``SocketStream`` keeping its transport and
        protocol in ``_transport`` and ``_protocol`` (anyio 4); any other
        stream (TLS, trio, in-memory) or a future anyio without them gets None
        and is served by the writer task alone.
        """
        if type(stream).__module__ != "anyio._backends._asyncio":
            return None
        transport = getattr(stream, "_transport", None)
        protocol = getattr(stream, "_protocol", None)
        if protocol is None or not all(
            callable(getattr(transport, name, None))
            for name in ("write", "get_write_buffer_size", "is_closing")
        ):
            return None
        return cls(cast(_Transport, transport), protocol)

    @property
    def ready(self) -> bool:
        """Whether a write now would go straight out: open, unbroken, nothing buffered."""
        transport = self._transport
        return (
            not transport.is_closing()
            and transport.get_write_buffer_size() == 0
            and getattr(self._protocol, "exception", None) is None
        )

    def write(self, data: bytes) -> None:
        """Hand ``data`` to the transport (never blocks; check ``ready`` first).

        Raises:
            RuntimeError: the transport refused (it is closing).
        """
        self._transport.write(data)
