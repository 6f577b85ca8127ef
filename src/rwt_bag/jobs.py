"""Record and replay as jobs of a running server or command (``rwt serve --record/--play``).

``BagJobs`` holds what the command line asked for, opens and checks it before
anything is served (a bad bag fails at start, naming the topic and type), and
runs it next to the server: the recorder, the player with its ``/rwt/player``
services, and the progress display.
"""

from __future__ import annotations

import logging
import signal
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TextIO

import anyio

from .controls import serve_controls
from .errors import BagError
from .formats import BagFormat, Compression, SplitPolicy
from .keys import HELP, keyboard_controls
from .player import Player
from .progress import play_line, record_line, show_progress
from .recorder import Recorder
from .remote import RemoteRecorder
from .selection import TopicSelection

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping, Sequence
    from pathlib import Path

    from anyio.abc import TaskStatus

    from rwt_graph.graph import Graph
    from rwt_graph.types import TypeRegistry

__all__ = ["BagJobs", "PlayOptions", "RecordOptions", "record_remote"]

logger = logging.getLogger("rwt.bag")


@dataclass(frozen=True)
class RecordOptions:
    """``--record`` and its options.

    Attributes:
        max_bytes: ``--record-max-size`` without ``--record-split``: stop recording
            there (bytes of serialized messages); None: no limit.
        selection: the topics (globs, regular expressions, exclusions).
        compression: the MCAP chunk compression.
        repeat_latched: each split part starts with the latched topics' last messages.
    """

    path: Path
    selection: TopicSelection = field(default_factory=TopicSelection)
    fmt: BagFormat = BagFormat.MCAP
    split: SplitPolicy = field(default_factory=SplitPolicy)
    max_bytes: int | None = None
    compression: Compression = field(default_factory=Compression)
    repeat_latched: bool = True


@dataclass(frozen=True)
class PlayOptions:
    """``--play`` and its options."""

    paths: Sequence[Path]
    rate: float = 1.0
    loop: bool = False
    start_offset: float = 0.0
    topics: Sequence[str] = ()
    clock: float | None = None
    check: bool = True
    paused: bool = False
    remap: Mapping[str, str] = field(default_factory=dict)
    delay: float = 0.0
    duration: float | None = None
    until_ns: int | None = None
    prefix: str = ""
    wait_for_subscribers: bool = False
    wait_timeout: float | None = None


class BagJobs:
    """The recorder and player of one server.

    Args:
        graph: the server's graph.
        record: what to record, if anything.
        play: what to play, if anything.
        progress: where to show progress (a terminal: live; else a final line).
        stop_at_end: called when the player reaches the bag's end (``rwt play``
            stops its server); None: the player lingers (``rwt serve --play``).
        keyboard: a terminal's file descriptor whose keys drive the player
            (``rwt_bag.keys``); None: no keyboard controls.

    Raises:
        BagError: the bag to play cannot be read, or has an unknown or
            conflicting type; the bag to record cannot fit the graph's dialect.
    """

    def __init__(
        self,
        graph: Graph,
        *,
        record: RecordOptions | None = None,
        play: PlayOptions | None = None,
        progress: TextIO | None = None,
        stop_at_end: Callable[[], None] | None = None,
        keyboard: int | None = None,
    ) -> None:
        self.graph = graph
        self.keyboard = keyboard
        self.progress = progress
        self.stop_at_end = stop_at_end
        self.recorder = None
        self.player = None
        if record is not None:
            self.recorder = Recorder(
                graph,
                record.path,
                selection=record.selection,
                fmt=record.fmt,
                split=record.split,
                max_bytes=record.max_bytes,
                compression=record.compression,
                repeat_latched=record.repeat_latched,
            )
        if play is not None:
            self.player = Player(
                graph,
                play.paths,
                rate=play.rate,
                loop=play.loop,
                start_offset=play.start_offset,
                topics=play.topics,
                clock=play.clock,
                check=play.check,
                linger=stop_at_end is None,
                paused=play.paused,
                remap=play.remap,
                delay=play.delay,
                duration=play.duration,
                until_ns=play.until_ns,
                prefix=play.prefix,
                wait_for_subscribers=play.wait_for_subscribers,
                wait_timeout=play.wait_timeout,
            )

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """Run until cancelled (or, with ``stop_at_end``, until the bag has played).

        Raises:
            BagError: as ``Player.run`` and ``Recorder.run``.
        """
        services = [] if self.player is None else serve_controls(self.graph, self.player)
        try:
            async with anyio.create_task_group() as tg:
                if self.recorder is not None:
                    await tg.start(self.recorder.run)
                if self.player is not None:
                    await tg.start(self._play, tg.cancel_scope)
                if self.player is not None and self.keyboard is not None:
                    if self.progress is not None:
                        self.progress.write(f"{HELP}\n")
                        self.progress.flush()
                    tg.start_soon(keyboard_controls, self.player, self.keyboard)
                if self.progress is not None:
                    line = self._record_line if self.player is None else self._play_line
                    tg.start_soon(show_progress, line, self.progress)
                task_status.started()
        finally:
            for service in services:
                service.close()

    async def _play(
        self, scope: anyio.CancelScope, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        assert self.player is not None
        started = False

        def on_started(value: None = None) -> None:
            nonlocal started
            started = True
            task_status.started(value)

        status = _Started(on_started)
        try:
            await self.player.run(task_status=status)
        except BaseException as exc:
            # Before the start (the check pass) the error stops the command, as a bad
            # bag must. Later (``--no-play-check``) a corrupt part or a decompression
            # limit ends playback only: ``rwt serve`` goes on serving its clients.
            error = _only_bag_error(exc)
            if error is None or not started or self.stop_at_end is not None:
                raise
            logger.error("event=play_failed reason=%s (playback stopped; serving on)", error)
            return
        scope.cancel()  # the bag has played (no loop, no linger): the progress line goes too
        if self.stop_at_end is not None:
            self.stop_at_end()

    def _record_line(self, *, final: bool = False) -> str:
        assert self.recorder is not None
        return record_line(self.recorder, final=final)

    def _play_line(self, *, final: bool = False) -> str:
        assert self.player is not None
        return play_line(self.player, final=final)


async def record_remote(
    url: str,
    path: Path,
    registry: TypeRegistry,
    *,
    record: RecordOptions | None = None,
    compression: str = "cbor",
    duration: float | None = None,
    out: TextIO = sys.stdout,
) -> None:
    """``rwt record URL OUT``: record until SIGINT/SIGTERM, showing progress on ``out``.

    ``record`` gives the topics, format, split and chunk compression (its path
    and ``max_bytes`` are not used: ``path`` is the bag). With ``duration``,
    recording also stops that many seconds after it started (connected and
    subscribed). ``compression`` is the subscriptions' (cbor or none).

    Raises:
        BagError: the bag cannot be created.
        OSError, TransportError: the server cannot be reached.
    """
    record = record or RecordOptions(path)
    remote = RemoteRecorder(
        url,
        path,
        registry,
        selection=record.selection,
        fmt=record.fmt,
        split=record.split,
        compression=compression,
        chunk_compression=record.compression,
        repeat_latched=record.repeat_latched,
    )
    async with anyio.create_task_group() as tg:
        tg.start_soon(_stop_on_signal, remote.stop)
        if duration is not None:
            tg.start_soon(_stop_after, remote, duration)
        tg.start_soon(show_progress, lambda **kw: record_line(remote.recorder, **kw), out)
        await remote.run()
        tg.cancel_scope.cancel()


async def _stop_after(remote: RemoteRecorder, seconds: float) -> None:
    await remote.started.wait()
    await anyio.sleep(seconds)
    remote.stop()


async def _stop_on_signal(stop: Callable[[], None]) -> None:
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            stop()
            return


class _Started:
    """A ``TaskStatus`` that also tells ``BagJobs`` the player has started."""

    def __init__(self, callback: Callable[[None], None]) -> None:
        self._callback = callback

    def started(self, value: None = None) -> None:
        self._callback(value)


def _only_bag_error(exc: BaseException) -> BagError | None:
    """The ``BagError`` that ``exc`` is, or that its task groups hold alone; else None."""
    while isinstance(exc, BaseExceptionGroup) and len(exc.exceptions) == 1:
        exc = exc.exceptions[0]
    return exc if isinstance(exc, BagError) else None
