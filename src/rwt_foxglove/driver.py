"""The thin async driver of a ``FoxgloveSession`` over a WebSocket connection.

The tasks of a connection: the reader hands each received frame to the
session, and yields to the event loop after each slice of them (``read_slice``:
a flood of tiny frames on one connection does not hold the others up); the
writer sends what the session queued, a batch at a time, whenever it is woken
(a reply, a graph message); the watcher calls ``sync`` every
``sync_interval_s`` so that topics and services that appeared or went are
(un)advertised, the connection graph's changes sent and old service calls
timed out (the graph announces no changes, so it is looked at: one pass over
its topics and services); while a bag plays, the ticker calls ``tick`` every
``TIME_INTERVAL_S`` (server time); with assets, the fetcher reads the files clients
ask for in a worker thread.
The session never awaits, so a slow client only fills its own queue.

Direct sends (``run_foxglove(direct=True)``, the ``deferred-send`` shortcut:
a plain socket): while the writer is idle, output is written from an event
loop callback instead of waking the writer task, after the burst it belongs to
was gathered over loop turns (gather.py): one system call for many messages
instead of one each. What the socket cannot take at once is left to the
writer task, so frames keep their order and a slow reader only fills its own
queue.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING, Protocol

import anyio
import anyio.lowlevel
import anyio.to_thread

from rwt_protocol.framing.streams import InFrame

from .assets import AssetError
from .gather import GATHER_BYTES, Gatherer
from .servertime import TIME_INTERVAL_S

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from rwt_protocol.framing.streams import FramerEvent
    from rwt_protocol.server.commands import CloseCode
    from rwt_protocol.server.outbox import OutFrame

    from .assets import AssetRoots
    from .outqueue import OutQueue
    from .session import FoxgloveSession

__all__ = ["SYNC_INTERVAL_S", "FoxgloveChannel", "InBatch", "ReadGate", "Wakeup", "run_foxglove"]

logger = logging.getLogger("rwt.foxglove")

SYNC_INTERVAL_S = 0.25
"""Seconds between two looks at the graph's topics (how late an advertise may come)."""


class ReadGate(Protocol):
    """What the server does around each slice of frames the reader hands over (flow control).

    ``begin`` comes before the slice's first frame and ``end`` after its last,
    with nothing else run on the loop between them; ``hold`` then.
    """

    def begin(self) -> None:
        """The slice's frames are about to be handed to the session."""

    def end(self) -> None:
        """The slice was handled: what it queued for others is written."""

    async def hold(self) -> None:
        """Wait while the queues the slice filled past their high watermark drain."""


class InBatch(Protocol):
    """Whether a batch is being handled (``rwt_transports.flow.FlowControl``)."""

    in_batch: bool


class FoxgloveChannel(Protocol):
    """A connection the driver reads and writes (``rwt_transports.websocket.WebSocketChannel``)."""

    async def receive(self) -> Sequence[FramerEvent]:
        """The whole messages received next; raises ``anyio.EndOfStream`` at the end."""

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Send data frames (text or binary), in order."""

    async def close(self, code: CloseCode, reason: str) -> None:
        """Send a close frame."""

    def can_send_now(self) -> bool:
        """Whether ``send_now`` would write at once (used only with ``direct``)."""

    def send_now(self, frames: Sequence[OutFrame]) -> None:
        """Write ``frames`` without awaiting (used only with ``direct``, after ``can_send_now``).

        Raises:
            RuntimeError: the transport refused (it is closing).
            anyio.ClosedResourceError: the connection is closing.
        """


class Wakeup:
    """Wakes the writer: ``set`` from the session's callbacks, ``wait`` in the writer.

    Attached to a connection that can be written directly (``attach``), ``set``
    joins the loop's gathering while the writer is idle and the frames are
    written from there (gather.py); the writer is woken only for what the
    socket cannot take at once.
    """

    def __init__(self, on_sent: Callable[[], None] | None = None) -> None:
        self.on_sent = on_sent
        """Called after each batch handed to the channel (the peer's progress, flow control)."""
        self._event = anyio.Event()
        self._woken = False  # ``_event`` is set
        self._channel: FoxgloveChannel | None = None
        self._session: FoxgloveSession | None = None
        self._queue: OutQueue | None = None  # the session's (``set``: no property call)
        self._gatherer: Gatherer | None = None
        self._idle = False  # the writer waits, holding no frames
        self._gathering = False  # in the gatherer's list
        self.batch: InBatch | None = None
        """The server's flow control: output queued while it handles a batch (a reader's
        frames) calls ``on_batch_output`` too (``set``), which notes this client's queue."""
        self.on_batch_output: Callable[[], None] | None = None

    def attach(self, channel: FoxgloveChannel, session: FoxgloveSession) -> None:
        """Write ``session``'s output to ``channel`` directly while the writer is idle.

        Needs a running asyncio loop; without one the writer does every write.
        """
        try:
            self._gatherer = Gatherer.for_loop(asyncio.get_running_loop())
        except RuntimeError:
            return
        self._channel = channel
        self._session = session
        self._queue = session.queue

    def detach(self) -> None:
        """No more direct writes (the connection ends)."""
        self._channel = self._session = self._gatherer = self._queue = None

    def set(self) -> None:
        """Something was queued."""
        gatherer, queue = self._gatherer, self._queue
        if self._gathering and gatherer is not None and queue is not None:  # a burst: first
            gatherer.more = True  # (gathering: idle and not woken, ``flush`` ends it)
            if queue.data_bytes >= GATHER_BYTES:  # enough for a write of its own
                gatherer.release(self)
        elif gatherer is None or not self._idle or self._woken:
            self._wake()
        else:
            self._gathering = True
            gatherer.join(self)
        batch = self.batch  # (here, not in a callback around ``set``: a call less per message)
        if batch is not None and batch.in_batch and self.on_batch_output is not None:
            self.on_batch_output()

    def _wake(self) -> None:
        if not self._woken:
            self._woken = True
            self._event.set()

    def queued_bytes(self) -> int:
        """Bytes of message data the session holds (``gather.Member``)."""
        session = self._session
        return 0 if session is None else session.queued_bytes

    def flush(self) -> None:
        """Write what the session queued now, or wake the writer (``gather.Member``)."""
        self._gathering = False
        session, channel = self._session, self._channel
        if session is None or channel is None or not self._idle or self._woken:
            return
        try:
            while channel.can_send_now():  # at most a gathering's bytes held by the transport
                frames = session.take(GATHER_BYTES)
                if not frames:
                    return
                channel.send_now(frames)
                if self.on_sent is not None:
                    self.on_sent()
        except Exception:  # a broken or closing connection: its writer finds out and ends
            logger.debug("event=direct_send_failed", exc_info=True)
        self._wake()

    async def wait(self) -> None:
        """Wait until something was queued since the last wait."""
        self._idle = True
        try:
            await self._event.wait()
        finally:
            self._idle = False
        self._event = anyio.Event()
        self._woken = False


async def run_foxglove(
    channel: FoxgloveChannel,
    session: FoxgloveSession,
    wakeup: Wakeup,
    *,
    sync_interval_s: float = SYNC_INTERVAL_S,
    assets: AssetRoots | None = None,
    direct: bool = False,
    read_slice: tuple[int, int] | None = None,
    gate: ReadGate | None = None,
    first_input: Callable[[], None] | None = None,
) -> None:
    """Run ``session`` on ``channel`` until the peer's end; the session is closed on return.

    Args:
        channel: the accepted connection.
        session: made with ``on_output=wakeup.set`` (and ``assets=True`` with ``assets``).
        wakeup: the writer's wake-up.
        sync_interval_s: seconds between topic syncs.
        assets: where the fetcher reads the files clients ask for; None: no fetcher.
        direct: ``channel`` can write without awaiting (``can_send_now``,
            ``send_now``): output is gathered and written from the loop while
            the writer is idle (the module's text).
        read_slice: the frames and bytes of frames the reader hands over before it
            yields to the loop for a turn (the server's fairness bounds,
            docs/limits.md); None: it yields only when it waits for input.
        gate: called around each slice (the server's input backpressure: a
            client whose publishing filled another's queue waits while that
            one reads, docs/limits.md); None: the reader never waits for others.
        first_input: called once, when the client's first input was handled (the
            server's "first input first" ticket, docs/limits.md: until then the
            readers of other connections may wait for this one's input).
    """
    sent = Wakeup()  # something was sent: a queued asset response may be gone
    asked = Wakeup()  # the reader handed frames over: a fetchAsset may wait
    _also_on_sent(wakeup, sent.set)
    if direct:
        wakeup.attach(channel, session)
    try:
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(_write, channel, session, wakeup)
            tasks.start_soon(_watch, session, sync_interval_s)
            if session.announces_time:
                tasks.start_soon(_tick, session, TIME_INTERVAL_S)
            if assets is not None:
                tasks.start_soon(_fetch, session, assets, wakeup, asked, sent)
            wakeup.set()  # serverInfo and the first advertise
            try:
                await _read(channel, session, (wakeup, asked), read_slice, gate, first_input)
            finally:
                tasks.cancel_scope.cancel()
    finally:
        wakeup.detach()
        session.close()


async def _read(
    channel: FoxgloveChannel,
    session: FoxgloveSession,
    wakeups: tuple[Wakeup, Wakeup],
    read_slice: tuple[int, int] | None,
    gate: ReadGate | None,
    first_input: Callable[[], None] | None,
) -> None:
    max_frames, max_bytes = read_slice or (0, 0)
    frames = size = 0  # of the current slice
    while True:
        try:
            messages = await channel.receive()
        except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            return
        begun = False
        for message in messages:
            if not isinstance(message, InFrame):
                continue
            if gate is not None and not begun:
                gate.begin()
                begun = True
            session.receive(message.data, binary=message.binary)
            frames, size = frames + 1, size + len(message.data)
            if read_slice is not None and (frames >= max_frames or size >= max_bytes):
                await _end_slice(wakeups, gate if begun else None)
                # the others' turn; the socket stays read, so its frames keep their place
                await anyio.lowlevel.checkpoint()
                frames = size = 0
                begun = False
        await _end_slice(wakeups, gate if begun else None)
        if first_input is not None:
            first_input()
            first_input = None


async def _end_slice(wakeups: tuple[Wakeup, Wakeup], gate: ReadGate | None) -> None:
    if gate is not None:
        gate.end()
    for wakeup in wakeups:
        wakeup.set()
    if gate is not None:
        await gate.hold()


async def _write(channel: FoxgloveChannel, session: FoxgloveSession, wakeup: Wakeup) -> None:
    while True:
        await wakeup.wait()
        while frames := session.take():
            try:
                await channel.send(frames)
            except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
                return
            if wakeup.on_sent is not None:
                wakeup.on_sent()


async def _fetch(
    session: FoxgloveSession, assets: AssetRoots, wakeup: Wakeup, asked: Wakeup, sent: Wakeup
) -> None:
    """Read the files the client asks for, one at a time, off the event loop.

    The next file is read once the client took the last response, so one
    client holds at most one file in memory (``assetrequests``).
    """
    while True:
        request = session.next_asset_request()
        if request is None:
            await (sent if session.assets_queued else asked).wait()
            continue
        try:
            data = await anyio.to_thread.run_sync(assets.read, request.uri)
        except AssetError as exc:
            session.asset_fetched(request.requestId, None, str(exc))
        else:
            session.asset_fetched(request.requestId, data)
        wakeup.set()


async def _tick(session: FoxgloveSession, interval_s: float) -> None:
    while True:
        await anyio.sleep(interval_s)
        session.tick()


def _also_on_sent(wakeup: Wakeup, call: Callable[[], None]) -> None:
    """Make ``call`` run after each batch sent too (by the writer or a gathered write)."""
    before = wakeup.on_sent

    def on_sent() -> None:
        call()
        if before is not None:
            before()

    wakeup.on_sent = on_sent


async def _watch(session: FoxgloveSession, interval_s: float) -> None:
    while True:
        await anyio.sleep(interval_s)
        session.sync(anyio.current_time())
