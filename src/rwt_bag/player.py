"""Replay a bag into a graph with its original timing (``rwt play``, ``rwt serve --play``).

Every topic of the bag gets an in-process publisher (node ``/rwt_player``),
latched where the bag says so or for ``/tf_static`` and maps (``reader``). A
message recorded ``t`` seconds after the playback's start point is published
``t / rate`` seconds after playback started; a reader thread decodes ahead
into a bounded queue so the event loop only waits and publishes.

With ``clock`` the player publishes ``/clock`` (rosgraph_msgs/Clock) and the
graph's wall clock reads bag time (so rosapi ``get_time`` and default header
stamps follow the bag, as with ``use_sim_time``). Always, while it runs, the graph's
``timeline`` is the bag's clock (``clock_ns``), which Foxglove clients get as
server time, and the graph's ``playback`` is the player (``rwt_graph.playback``),
which Foxglove's playback bar drives. ``pause``, ``resume`` and
``seek`` drive it from Python; ``serve_controls`` offers them as services under
``/rwt/player/`` (``controls``).
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import anyio
import anyio.to_thread

from rwt_graph.playback import PlaybackStatus, rate_problem
from rwt_graph.types.convert import time_value
from rwt_protocol.errors import GraphError
from rwt_protocol.names import name_problem

from .background import BackgroundJob
from .errors import BagError
from .reader import BagItem, BagSource

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from anyio.abc import TaskStatus
    from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

    from rwt_graph.clock import Clock
    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalPublisher

__all__ = ["PlayStats", "Player"]

logger = logging.getLogger("rwt.bag")

#: One trip to the reader thread decodes up to this many messages or bytes, so
#: the thread hop is paid once per batch, not per message.
_BATCH_MESSAGES = 512
#: 1 MiB keeps the decoded bytes alive at once small, so the allocator reuses
#: the buffers freed after publishing; with 8 MiB every large message (an image)
#: landed on fresh pages, which cost more than its copy (B20).
_BATCH_BYTES = 1024 * 1024
_QUEUE = 2  # decoded batches waiting to be published: bounded memory (~3 MB)


@dataclass
class PlayStats:
    """What a player has published.

    Attributes:
        messages: messages published.
        loops: completed passes over the bag.
    """

    messages: int = 0
    loops: int = 0


class BagClock:
    """The graph's clock during playback with ``clock``: wall time is bag time."""

    def __init__(self, real: Clock, player: Player) -> None:
        self.real = real
        self._player = player

    def monotonic(self) -> float:
        """The real monotonic clock (timeouts stay real)."""
        return self.real.monotonic()

    def wall(self) -> float:
        """The bag time of the playback position, seconds since the epoch."""
        return self._player.bag_time_ns() / 1e9


class Player(BackgroundJob):
    """Publishes the messages of a bag into ``graph`` with their timing.

    Use it as an async context manager (playing in the background) or run
    ``await player.run()``, which returns at the bag's end (never with ``loop``)::

        player = Player(graph, [Path("run1")], rate=2.0)
        await player.run()

    Args:
        graph: where to publish.
        paths: the bag (several for split parts, read as one).
        rate: speed factor (2.0: twice as fast), from ``rwt_graph.playback.MIN_RATE``
            (0.001) to ``MAX_RATE`` (1000000).
        loop: start over at the end.
        start_offset: seconds into the bag to start at.
        topics: glob patterns of the topics to play; all by default.
        clock: publish ``/clock`` at this many Hz and make the graph's wall clock
            bag time; None: neither.
        check: decode every message once before publishing anything, so a corrupt
            bag fails at start (set False to start large bags at once).
        remap: bag topic -> the name it is published under (``ros2 bag play
            --remap old:=new``); names are checked as the graph checks any topic.
        delay: seconds to wait after advertising, before the first message
            (``ros2 bag play --delay``), so subscribers can join.
        duration: seconds of bag time to play from the start position
            (``--playback-duration``); None: to the end.
        until_ns: bag time (nanoseconds since the epoch) past which nothing is
            played (``--playback-until-sec``); None: the end.
        prefix: put in front of every published name (``/sim``: ``/tf`` is played
            as ``/sim/tf``; after ``remap``), as ``rosbag play --prefix``; "": none.
        wait_for_subscribers: after advertising, wait until every played topic
            has a subscriber before the first message (and before ``delay``).
        wait_timeout: seconds to wait for them; then play anyway, logging the
            topics still without one. None: wait until cancelled.

    Raises:
        BagError: as ``BagSource`` (the bag cannot be read, an unknown or
            conflicting type), or a ``rate`` outside ``MIN_RATE``..``MAX_RATE``.
    """

    def __init__(
        self,
        graph: Graph,
        paths: Sequence[Path | str] | Path | str,
        *,
        rate: float = 1.0,
        loop: bool = False,
        start_offset: float = 0.0,
        topics: Sequence[str] = (),
        clock: float | None = None,
        check: bool = True,
        linger: bool = False,
        paused: bool = False,
        remap: Mapping[str, str] | None = None,
        delay: float = 0.0,
        duration: float | None = None,
        until_ns: int | None = None,
        prefix: str = "",
        wait_for_subscribers: bool = False,
        wait_timeout: float | None = None,
    ) -> None:
        _check_rate(rate)
        self.prefix = _prefix(prefix)
        for old, new in (remap or {}).items():  # before the bag is opened
            problem = name_problem(_under(self.prefix, new))
            if problem is not None:
                raise BagError(f"cannot play {old} as {_under(self.prefix, new)}: {problem}")
        checked = (("delay", delay), ("duration", duration), ("wait timeout", wait_timeout))
        for name, value in checked:
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise BagError(f"the {name} must be a finite number of seconds >= 0, not {value}")
        self.graph = graph
        self.paths = [Path(paths)] if isinstance(paths, str | Path) else [Path(p) for p in paths]
        self.rate = rate
        self.loop = loop
        self.clock_hz = clock
        self.check = check
        self.linger = linger
        self.stats = PlayStats()
        self.source = BagSource(self.paths, graph.registry, topics)
        self._start_offset_ns = max(0, int(start_offset * 1e9))
        self._publishers: dict[str, LocalPublisher] = {}
        self._paused = paused
        self._changed = anyio.Event()
        self._seek_to: int | None = None
        self._step = False  # ``play_next``: publish one message while paused
        self._segment: anyio.CancelScope | None = None
        self._ended = False  # the end was reached (no loop); a seek plays again (``linger``)
        self._done = False  # ``run`` returned: nothing plays any more
        self._jumps = 0  # seeks and loop restarts so far (``jumps``)
        self._anchor_mono = 0.0
        self._anchor_ns = self.start_ns
        self._position_ns = self.start_ns
        self._publishing_ns: int | None = None  # the record time of the message being published
        # the record time of the next message to publish (the last published while the
        # next is read): the bag's clock does not pass a message before it is published
        self._next_ns: int | None = None
        self.remap = dict(remap or {})
        self.delay = delay
        self.wait_for_subscribers = wait_for_subscribers
        self.wait_timeout = wait_timeout
        self._stop_ns = self.source.end_ns
        if duration is not None:
            self._stop_ns = min(self._stop_ns, self.start_ns + int(duration * 1e9))
        if until_ns is not None:
            self._stop_ns = min(self._stop_ns, until_ns)

    # ---- state ----------------------------------------------------------------

    @property
    def start_ns(self) -> int:
        """Bag time where playback starts (the first message plus ``start_offset``)."""
        return min(self.source.start_ns + self._start_offset_ns, self.source.end_ns)

    @property
    def duration_s(self) -> float:
        """Seconds from the bag's first to its last message."""
        return max(0, self.source.end_ns - self.source.start_ns) / 1e9

    @property
    def paused(self) -> bool:
        """Whether playback is paused."""
        return self._paused

    @property
    def status(self) -> PlaybackStatus:
        """Playing, paused, or ended (the end reached without ``loop``, or ``run`` over)."""
        if self._ended or self._done:
            return PlaybackStatus.ENDED
        return PlaybackStatus.PAUSED if self._paused else PlaybackStatus.PLAYING

    @property
    def time_range_ns(self) -> tuple[int, int]:
        """The bag's first and last record times (ns since the epoch): what ``seek`` reaches."""
        return self.source.start_ns, self.source.end_ns

    @property
    def jumps(self) -> int:
        """How many times the position jumped: each seek and each loop's restart."""
        return self._jumps

    @property
    def position_s(self) -> float:
        """Seconds from the bag's start of the playback position."""
        return (self.bag_time_ns() - self.source.start_ns) / 1e9

    def bag_time_ns(self) -> int:
        """The bag time of the playback position, nanoseconds since the epoch.

        It runs with the wall clock (times ``rate``) but waits at the next
        message's record time until that message is published, so it only
        goes forward between seeks, also on a busy event loop.
        """
        if self._paused:
            return self._position_ns
        elapsed = (time.monotonic() - self._anchor_mono) * self.rate
        now = min(self._anchor_ns + int(elapsed * 1e9), max(self._stop_ns, self._anchor_ns))
        held = self._next_ns
        # a message published late (a busy loop) must not find the clock past it:
        # the clock runs monotonic through every message's record time
        return now if held is None else min(now, max(held, self._anchor_ns))

    def clock_ns(self) -> int:
        """Bag time (ns since the epoch) for what happens now.

        The record time of the message being published while one is (exact,
        for its subscribers), else ``bag_time_ns``. The graph's ``timeline``
        while the player runs (Foxglove's server time).
        """
        publishing = self._publishing_ns
        return self.bag_time_ns() if publishing is None else publishing

    def pause(self) -> None:
        """Stop publishing until ``resume``; ``/clock`` stands still."""
        if not self._paused:
            self._position_ns = self.bag_time_ns()
            self._paused = True
            self._notify()

    def resume(self) -> None:
        """Go on from where ``pause`` stopped."""
        if self._paused:
            self._paused = False
            self._step = False
            self._anchor(self._position_ns)
            self._notify()

    def play_next(self) -> bool:
        """While paused, publish the next message (``ros2 bag play``'s right arrow).

        Returns:
            Whether it applies: False while playing.
        """
        if not self._paused:
            return False
        self._step = True
        self._notify()
        return True

    def set_rate(self, rate: float) -> None:
        """Play on at ``rate`` from the current position.

        Raises:
            BagError: ``rate`` is not a number from ``rwt_graph.playback.MIN_RATE``
                to ``MAX_RATE`` (0.001 to 1000000); the rate stays as it was.
        """
        _check_rate(rate)
        if not self._paused:
            self._anchor(self.bag_time_ns())
        self.rate = rate
        self._notify()

    def seek(self, offset_s: float, *, clamp: bool = True) -> None:
        """Go to ``offset_s`` seconds from the bag's start.

        Latched topics keep their last message; messages between the old and the
        new position are not published.

        Args:
            offset_s: seconds from the bag's first message.
            clamp: move an offset outside ``0..duration_s`` to the nearest end;
                False: refuse it (the ``/rwt/player/seek`` service).

        Raises:
            BagError: ``offset_s`` is NaN or infinite, or outside the bag and not
                ``clamp``.
        """
        span = self.source.end_ns - self.source.start_ns
        if not math.isfinite(offset_s):
            raise BagError(f"offset {offset_s} is not a finite number of seconds")
        if not clamp and not 0 <= offset_s <= span / 1e9:
            raise BagError(f"offset {offset_s:.6g} s is outside the bag (0 to {span / 1e9:.3f} s)")
        self._go_to(self.source.start_ns + min(int(max(offset_s, 0.0) * 1e9), span))

    def seek_ns(self, time_ns: int) -> None:
        """Go to the bag time ``time_ns`` (ns since the epoch), clamped to ``time_range_ns``.

        As ``seek``, by absolute time (Foxglove's playback bar seeks so).
        """
        first, last = self.time_range_ns
        self._go_to(min(max(time_ns, first), last))

    def _go_to(self, target: int) -> None:
        self._jumps += 1
        if not self._done:  # a lingering player plays on from there
            self._ended = False
        self._seek_to = target
        self._next_ns = target  # the clock waits there for the new segment's first message
        self._position_ns = target
        self._anchor(target)
        if self._segment is not None:
            self._segment.cancel()
        self._notify()

    def _anchor(self, bag_ns: int) -> None:
        self._anchor_ns = bag_ns
        self._anchor_mono = time.monotonic()

    def _notify(self) -> None:
        self._changed.set()
        self._changed = anyio.Event()

    # ---- running --------------------------------------------------------------

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """Play the bag (forever with ``loop``); publishers and the file close at the end.

        Raises:
            BagError: the bag is corrupt (found by ``check`` before anything is
                published, or while playing), or a topic of the bag exists in the
                graph with another type.
        """
        try:
            if self.check:
                await anyio.to_thread.run_sync(self.source.check_all)
            self._advertise()
        except BaseException:
            self.source.close()
            raise
        try:
            with contextlib.ExitStack() as bag_time:
                timeline = self.graph.port.use_timeline(self.clock_ns, playback=self)
                bag_time.enter_context(timeline)
                async with anyio.create_task_group() as tg:
                    if self.clock_hz:  # the graph's wall time is bag time while it plays
                        clock = BagClock(self.graph.clock, self)
                        bag_time.enter_context(self.graph.port.use_clock(clock))
                        tg.start_soon(self._publish_clock, self.clock_hz)
                    task_status.started()
                    if self.wait_for_subscribers:
                        await self._await_subscribers()
                    if self.delay:
                        await anyio.sleep(self.delay)
                    await self._play()
                    tg.cancel_scope.cancel()
        finally:
            self._done = True
            for publisher in self._publishers.values():
                publisher.close()
            self._publishers.clear()
            self.source.close()

    def published_name(self, topic: str) -> str:
        """The name the bag's ``topic`` is published under (``remap``, then ``prefix``)."""
        return _under(self.prefix, self.remap.get(topic, topic))

    def unsubscribed(self) -> list[str]:
        """The published names that no subscriber of the graph takes yet, sorted."""
        topics = self.graph.topics
        missing = set()
        for publisher in self._publishers.values():
            entry = topics.get(publisher.topic)
            if entry is None or not entry.subscribers:
                missing.add(publisher.topic)
        return sorted(missing)

    async def _await_subscribers(self) -> None:
        """Wait until every played topic has a subscriber, or ``wait_timeout`` passes.

        The graph tells no one when a subscriber comes, so this looks every 50 ms.
        """
        missing = self.unsubscribed()
        if not missing:
            return
        logger.info("event=play_waiting topics=%s (for a subscriber each)", ",".join(missing))
        with anyio.move_on_after(self.wait_timeout if self.wait_timeout is not None else math.inf):
            while missing:
                await anyio.sleep(0.05)
                missing = self.unsubscribed()
        if missing:
            logger.warning(
                "event=play_wait_timeout seconds=%g topics=%s (playing without their subscribers)",
                self.wait_timeout,
                ",".join(missing),
            )

    def _advertise(self) -> None:
        """A publisher per topic, all or none (a conflicting topic publishes nothing)."""
        try:
            for topic in self.source.topics.values():
                if topic.topic not in self._publishers:
                    self._publishers[topic.topic] = self.graph.create_publisher(
                        self.published_name(topic.topic),
                        topic.mtype.name,
                        latch=topic.latched,
                        node="/rwt_player",
                    )
        except GraphError as exc:
            for publisher in self._publishers.values():
                publisher.close()
            self._publishers.clear()
            name = self.published_name(topic.topic)
            what = f"{topic.topic} as {name}" if name != topic.topic else topic.topic
            raise BagError(f"cannot play {what} (type {topic.msgtype}): {exc}") from exc

    async def _play(self) -> None:
        position = self.start_ns
        while True:
            self._anchor(position)
            self._position_ns = position
            self._seek_to = None
            with anyio.CancelScope() as self._segment:
                await self._play_from(position)
            self._segment = None
            if self._seek_to is not None:
                position = self._seek_to
                continue
            self.stats.loops += 1
            if self.loop:
                position = self.start_ns
                self._jumps += 1
            elif self.linger:
                self._ended = True
                position = await self._next_seek()
            else:
                self._ended = True
                return

    async def _next_seek(self) -> int:
        """Wait at the end of the bag until ``seek`` (``linger``)."""
        self._seek_to = None
        while self._seek_to is None:
            await self._changed.wait()
        return self._seek_to

    async def _play_from(self, start_ns: int) -> None:
        send, receive = anyio.create_memory_object_stream[list[BagItem]](_QUEUE)
        async with anyio.create_task_group() as tg:
            tg.start_soon(self._produce, send, start_ns)
            self._next_ns = start_ns  # the clock starts with the first message read
            try:
                await self._consume(receive)
            finally:
                if self._seek_to is None:  # no message pending: the clock runs on to the end
                    self._next_ns = None
            tg.cancel_scope.cancel()  # stopped early (duration, until): the reader too

    async def _produce(self, send: MemoryObjectSendStream[list[BagItem]], start_ns: int) -> None:
        batches = self.source.batches(
            start_ns, max_messages=_BATCH_MESSAGES, max_bytes=_BATCH_BYTES
        )
        async with send:
            while True:
                batch: list[BagItem] = await anyio.to_thread.run_sync(next, batches, [])
                if not batch:
                    return
                await send.send(batch)

    async def _consume(self, receive: MemoryObjectReceiveStream[list[BagItem]]) -> None:
        first = True
        async with receive:
            async for batch in receive:
                if first:
                    # the schedule starts when the first message is ready, not when
                    # the reader thread was asked for it (its first read takes a while);
                    # paused, ``resume`` sets it. Once only: a later batch re-anchoring
                    # at the old position stalled playback for as long as it had played
                    first = False
                    if not self._paused:
                        self._anchor(self._anchor_ns)
                publishers, stats = self._publishers, self.stats
                for topic, ns, msg, record in batch:
                    if ns > self._stop_ns:
                        return
                    self._next_ns = ns
                    if self._paused or self._due(ns) > time.monotonic():
                        await self._wait_until(ns)  # not yet (or paused): wait
                    self._position_ns = self._publishing_ns = ns
                    try:
                        publishers[topic.topic].publish(msg, validated=True, wire=record)
                    finally:
                        self._publishing_ns = None
                    stats.messages += 1

    def _due(self, ns: int) -> float:
        """The monotonic time at which the message of bag time ``ns`` is published."""
        return self._anchor_mono + (ns - self._anchor_ns) / 1e9 / self.rate

    async def _wait_until(self, ns: int) -> None:
        while True:
            changed = self._changed
            if self._paused:
                if self._step:  # play_next: this one message, then paused again
                    self._step = False
                    return
                await changed.wait()
                continue
            delay = self._due(ns) - time.monotonic()
            if delay <= 0:
                return
            with anyio.move_on_after(delay):
                await changed.wait()

    async def _publish_clock(self, hz: float) -> None:
        publisher = self.graph.create_publisher("/clock", "rosgraph_msgs/Clock", node="/rwt_player")
        dialect = self.graph.registry.dialect
        try:
            while True:
                now = self.bag_time_ns() / 1e9
                publisher.publish({"clock": time_value(now, dialect)}, validated=True)
                await anyio.sleep(1 / hz)
        finally:
            publisher.close()


def _check_rate(rate: float) -> None:
    """The one check of a speed where a player's is set (``rwt_graph.playback.rate_problem``).

    Raises:
        BagError: ``the rate: speed ... is not from 0.001 to 1000000 times the recorded speed``.
    """
    problem = rate_problem(rate)
    if problem is not None:
        raise BagError(f"the rate: {problem}")


def _prefix(prefix: str) -> str:
    """``prefix`` as a namespace: a leading ``/``, no trailing one ("" stays "").

    Raises:
        BagError: not a name (``rosbag play --prefix`` takes a namespace).
    """
    prefix = prefix.strip().rstrip("/")
    if not prefix:
        return ""
    prefix = prefix if prefix.startswith("/") else f"/{prefix}"
    problem = name_problem(prefix)
    if problem is not None:
        raise BagError(f"the prefix {prefix!r} is not a namespace: {problem}")
    return prefix


def _under(prefix: str, name: str) -> str:
    """``name`` in the namespace ``prefix``: ``/tf`` or ``tf`` in ``/sim`` is ``/sim/tf``.

    A relative name (a bag may hold one, a remap may give one) resolves against
    the root namespace, so under a prefix it is the prefix's child, not its
    name run on (``/simtf``).
    """
    if not prefix or name.startswith("/"):
        return prefix + name
    return f"{prefix}/{name}"
