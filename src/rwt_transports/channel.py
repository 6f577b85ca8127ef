"""A connection's frame I/O as the pump drives it: the ``Channel`` every transport offers.

Every transport (WebSocket, TCP, UDP, stdio, in-memory) reduces a connection to
a channel: receive a batch of frames, send a batch of frames, close. What a
channel can do beyond that (pause its socket, probe for input, read its kernel
send queue, write without awaiting) it reports once, as
``ChannelAbilities``; the pump calls those methods only when the channel
said it can. A channel with none of them inherits ``PlainChannel``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rwt_protocol.runtime.commands import CloseCode
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.inframes import FramerEvent
    from rwt_protocol.runtime.outbox import OutFrame

__all__ = ["NO_ABILITIES", "Channel", "ChannelAbilities", "PlainChannel"]


@dataclass(frozen=True, slots=True)
class ChannelAbilities:
    """What a connection's channel can do beyond receive, send and close.

    Attributes:
        pause_reading: its socket can stop being read between ``receive`` calls
            (``pause_reading``), so a held reader's peer is pushed back by TCP.
        probe_input: it can tell whether input is already here without reading
            it (``input_pending``): a starting connection's first input goes
            first (admission/arrival.py).
        unsent_bytes: it can read its kernel's send queue (``unsent_bytes``,
            sendqueue.py): progress no completed send shows.
        send_now: it can write without awaiting when ``can_send_now`` says so
            (``send_now``): the ``deferred-send`` path.
    """

    pause_reading: bool = False
    probe_input: bool = False
    unsent_bytes: bool = False
    send_now: bool = False


NO_ABILITIES = ChannelAbilities()
"""The abilities of a channel that can only receive, send and close."""


class Channel(Protocol):
    """One connection's frame I/O, as the pump needs it."""

    transport: str
    """Short transport name for logs and client ids (``ws``, ``tcp``, ``udp``, ``stdio``)."""

    awaits_peer_close: bool
    """Whether, after ``close``, the peer answers (a WebSocket close frame) and the
    reader should be given ``CLOSE_WAIT_S`` to see it."""

    abilities: ChannelAbilities
    """What it can do beyond receive, send and close: which of the methods below work."""

    async def receive(self) -> Sequence[FramerEvent]:
        """Wait for the next incoming frames (possibly none, e.g. control frames only).

        Raises:
            anyio.EndOfStream: the peer is gone or the connection is closed.
        """

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Send frames in order; returns when the transport took them.

        Raises:
            anyio.BrokenResourceError: the connection broke.
        """

    async def close(self, code: CloseCode, reason: str) -> None:
        """Start closing: tell the peer where the transport can (WebSocket close frame)."""

    async def background(self, session: ServerSession) -> None:
        """Run transport chores (WebSocket keepalive) until cancelled; may return at once."""

    def pause_reading(self) -> None:
        """Stop reading from the socket; the next ``receive`` that must wait resumes it.

        Called only with ``abilities.pause_reading``.
        """

    def input_pending(self) -> bool | None:
        """Whether ``receive`` would return at once; None when it cannot tell.

        Called only with ``abilities.probe_input``.
        """

    def unsent_bytes(self) -> int | None:
        """Bytes the kernel holds for the peer, not yet acknowledged; None when it cannot tell.

        Called only with ``abilities.unsent_bytes`` (sendqueue.py).
        """

    def can_send_now(self) -> bool:
        """Whether ``send_now`` would write at once, nothing else being written.

        Called only with ``abilities.send_now``.
        """

    def send_now(self, frames: Sequence[OutFrame]) -> None:
        """Write ``frames`` now, without blocking.

        The pump calls it only while its writer is idle and only after
        ``can_send_now`` said yes, so nothing else is writing and order is
        kept. What the socket cannot take at once stays in the transport, ahead
        of anything sent later.

        Raises:
            RuntimeError: the transport refused (it is closing).
        """


class PlainChannel:
    """The optional part of a ``Channel`` that can only receive, send and close."""

    abilities = NO_ABILITIES

    def pause_reading(self) -> None:
        """Nothing to pause: the transport reads only when asked."""

    def input_pending(self) -> bool | None:
        """It cannot tell."""
        return None

    def unsent_bytes(self) -> int | None:
        """It cannot tell."""
        return None

    def can_send_now(self) -> bool:
        """Never: every frame goes through the writer."""
        return False

    def send_now(self, frames: Sequence[OutFrame]) -> None:
        """Refused: every frame goes through the writer.

        Raises:
            RuntimeError: always.
        """
        raise RuntimeError("this channel writes only through the pump's writer")
