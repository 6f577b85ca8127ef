"""The thin async driver of a ``FoxgloveSession`` over a WebSocket connection.

The tasks of a connection: the reader hands each received frame to the
session; the writer sends what the session queued, a batch at a time, whenever
it is woken (a reply, a graph message); the watcher calls ``sync`` every
``sync_interval_s`` so that topics and services that appeared or went are
(un)advertised, the connection graph's changes sent and old service calls
timed out (the graph announces no changes, so it is looked at: one pass over
its topics and services); while a bag plays, the ticker calls ``tick`` every
``TIME_INTERVAL_S`` (server time); with assets, the fetcher reads the files clients
ask for in a worker thread.
The session never awaits, so a slow client only fills its own queue.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Protocol

import anyio
import anyio.to_thread

from rwt_protocol.framing.streams import InFrame

from .assets import AssetError
from .servertime import TIME_INTERVAL_S

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rwt_protocol.framing.streams import FramerEvent
    from rwt_protocol.server.commands import CloseCode
    from rwt_protocol.server.outbox import OutFrame

    from .assets import AssetRoots
    from .session import FoxgloveSession

__all__ = ["SYNC_INTERVAL_S", "FoxgloveChannel", "Wakeup", "run_foxglove"]

logger = logging.getLogger("rwt.foxglove")

SYNC_INTERVAL_S = 0.25
"""Seconds between two looks at the graph's topics (how late an advertise may come)."""


class FoxgloveChannel(Protocol):
    """A connection the driver reads and writes (``rwt_transports.websocket.WebSocketChannel``)."""

    async def receive(self) -> Sequence[FramerEvent]:
        """The whole messages received next; raises ``anyio.EndOfStream`` at the end."""

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Send data frames (text or binary), in order."""

    async def close(self, code: CloseCode, reason: str) -> None:
        """Send a close frame."""


class Wakeup:
    """Wakes the writer: ``set`` from the session's callbacks, ``wait`` in the writer."""

    def __init__(self) -> None:
        self._event = anyio.Event()

    def set(self) -> None:
        """Something was queued."""
        self._event.set()

    async def wait(self) -> None:
        """Wait until something was queued since the last wait."""
        await self._event.wait()
        self._event = anyio.Event()


async def run_foxglove(
    channel: FoxgloveChannel,
    session: FoxgloveSession,
    wakeup: Wakeup,
    *,
    sync_interval_s: float = SYNC_INTERVAL_S,
    assets: AssetRoots | None = None,
) -> None:
    """Run ``session`` on ``channel`` until the peer's end; the session is closed on return.

    Args:
        channel: the accepted connection.
        session: made with ``on_output=wakeup.set`` (and ``assets=True`` with ``assets``).
        wakeup: the writer's wake-up.
        sync_interval_s: seconds between topic syncs.
        assets: where the fetcher reads the files clients ask for; None: no fetcher.
    """
    sent = Wakeup()  # the writer sent something: a queued asset response may be gone
    asked = Wakeup()  # the reader handed frames over: a fetchAsset may wait
    try:
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(_write, channel, session, wakeup, sent)
            tasks.start_soon(_watch, session, sync_interval_s)
            if session.announces_time:
                tasks.start_soon(_tick, session, TIME_INTERVAL_S)
            if assets is not None:
                tasks.start_soon(_fetch, session, assets, wakeup, asked, sent)
            wakeup.set()  # serverInfo and the first advertise
            try:
                await _read(channel, session, wakeup, asked)
            finally:
                tasks.cancel_scope.cancel()
    finally:
        session.close()


async def _read(
    channel: FoxgloveChannel, session: FoxgloveSession, wakeup: Wakeup, asked: Wakeup
) -> None:
    while True:
        try:
            messages = await channel.receive()
        except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            return
        for message in messages:
            if isinstance(message, InFrame):
                session.receive(message.data, binary=message.binary)
        wakeup.set()
        asked.set()


async def _write(
    channel: FoxgloveChannel, session: FoxgloveSession, wakeup: Wakeup, sent: Wakeup
) -> None:
    while True:
        await wakeup.wait()
        while frames := session.take():
            try:
                await channel.send(frames)
            except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
                return
            sent.set()


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


async def _watch(session: FoxgloveSession, interval_s: float) -> None:
    while True:
        await anyio.sleep(interval_s)
        session.sync(anyio.current_time())
