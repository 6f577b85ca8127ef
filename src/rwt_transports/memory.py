"""In-process transport: a rosbridge connection made of two memory streams.

``GraphServer.connect_memory()`` gives embedding code (and tests) a client
connection without a socket that goes through the same pump, gates and limits
as every network client (D22).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import TYPE_CHECKING

import anyio

from rwt_protocol.runtime.inframes import FramerEvent, InFrame
from rwt_protocol.runtime.outbox import OutFrame

from .channel import PlainChannel

if TYPE_CHECKING:
    from collections.abc import Sequence

    from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

    from rwt_protocol.runtime.commands import CloseCode
    from rwt_protocol.runtime.contract import ServerSession

__all__ = ["MemoryChannel", "MemoryConnection", "memory_pair"]

_BUFFERED_FRAMES = 64


class MemoryChannel(PlainChannel):
    """The server's end of an in-process connection, as a pump ``Channel``."""

    transport = "memory"
    awaits_peer_close = False

    def __init__(
        self,
        inbound: MemoryObjectReceiveStream[InFrame],
        outbound: MemoryObjectSendStream[OutFrame],
    ) -> None:
        self.inbound = inbound
        self.outbound = outbound
        self.close_code: CloseCode | None = None
        self.close_reason = ""

    async def receive(self) -> Sequence[FramerEvent]:
        """The client's next frame."""
        try:
            return [await self.inbound.receive()]
        except anyio.ClosedResourceError:
            raise anyio.EndOfStream from None

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Hand frames to the client; waits while the client's buffer is full."""
        for frame in frames:
            await self.outbound.send(frame)

    async def close(self, code: CloseCode, reason: str) -> None:
        """End the client's stream of frames, remembering why."""
        self.close_code, self.close_reason = code, reason
        self.outbound.close()
        self.inbound.close()

    async def background(self, session: ServerSession) -> None:
        """Nothing to do."""


@dataclass
class MemoryConnection:
    """The client's end of an in-process connection.

    Attributes:
        channel: the server's end (``close_code``/``close_reason`` once closed).
    """

    channel: MemoryChannel
    _send: MemoryObjectSendStream[InFrame]
    _receive: MemoryObjectReceiveStream[OutFrame]

    async def send_frame(self, data: bytes | str, *, binary: bool = False) -> None:
        """Send one frame (JSON text, or CBOR with ``binary``)."""
        payload = data.encode() if isinstance(data, str) else data
        await self._send.send(InFrame(payload, binary=binary))

    async def send(self, op: dict[str, object]) -> None:
        """Send an op given as a dict."""
        await self.send_frame(json.dumps(op))

    async def receive_frame(self) -> str | bytes:
        """The next frame from the server: text (JSON) as ``str``, binary (CBOR) as ``bytes``.

        Raises:
            anyio.EndOfStream: the server closed the connection.
        """
        frame = await self._receive.receive()
        return frame.data if frame.binary else frame.data.decode()

    async def aclose(self) -> None:
        """Close the client's end; the server sees the end of input."""
        self._send.close()
        self._receive.close()


def memory_pair() -> tuple[MemoryChannel, MemoryConnection]:
    """Make both ends of an in-process connection."""
    to_server, from_client = anyio.create_memory_object_stream[InFrame](_BUFFERED_FRAMES)
    to_client, from_server = anyio.create_memory_object_stream[OutFrame](_BUFFERED_FRAMES)
    channel = MemoryChannel(from_client, to_client)
    return channel, MemoryConnection(channel, to_server, from_server)
