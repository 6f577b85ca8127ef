"""Record topics of a graph into a bag (``rwt record``, ``rwt serve --record``).

The recorder subscribes in-process to every topic whose name matches one of its
patterns, including topics that appear later (it looks every ``discover_s``).
Each message is serialized where it is delivered (CDR for a ROS 2 graph, the
ROS 1 format for a ROS 1 graph, from the registry's rosbags typestore) and
stamped with the graph's wall clock: the receive time. A writer thread takes the
queued messages in batches, so the event loop never waits for the disk. The
queue is bounded in bytes: past ``max_queue_bytes`` messages are dropped and
counted (``stats.dropped``), as a slow disk must not exhaust memory.

ROS 2 bags are checkpointed every ``checkpoint_s`` and at each full MCAP chunk
(``rwt_bag.mcap``): a killed recorder leaves a bag that reads up to the last
checkpoint. A ROS 1 bag's checkpoint writes its open chunk, which ``rwt bag
reindex`` (or ``rosbag reindex``) indexes again after a kill. Closing (the
context's end, or cancelling ``run``) writes the rest.
"""

from __future__ import annotations

import logging
import sqlite3
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import anyio
import anyio.to_thread

from rwt_graph.ratelog import EpisodeLog
from rwt_graph.types import Dialect, codec_for

from .background import BackgroundJob
from .errors import BagError
from .formats import BagFormat, Compression, SplitPolicy
from .selection import TopicSelection
from .writer import BagWriter, TopicInfo

if TYPE_CHECKING:
    from collections.abc import Sequence

    from anyio.abc import TaskStatus

    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalSubscription
    from rwt_graph.types import MessageType

__all__ = ["MAX_RECORD_TOPICS", "RecordStats", "Recorder"]

logger = logging.getLogger("rwt.bag")

#: What a bag writer raises when the disk refuses data: OSError (ENOSPC, EFBIG,
#: EIO) from the MCAP and ROS 1 writers, sqlite3.Error ("database or disk is full")
#: from the sqlite3 one.
WRITE_ERRORS = (OSError, sqlite3.Error)

_Item = tuple[TopicInfo, int, bytes | memoryview]

#: Distinct topics (name and type) one recording takes (docs/limits.md). Each
#: stays in the bag's connection table, which every checkpoint rewrites (rosbags
#: renders its metadata.yaml, milliseconds per topic): clients inventing names
#: must not grow that work without bound. Real robots have a few hundred.
MAX_RECORD_TOPICS = 1000


@dataclass
class RecordStats:
    """What a recorder has done so far.

    Attributes:
        messages: messages written (queued ones not yet).
        bytes: serialized bytes written.
        dropped: messages dropped because the queue was full.
        started: ``time.monotonic()`` at start.
        topics: message count per recorded topic.
    """

    messages: int = 0
    bytes: int = 0
    dropped: int = 0
    started: float = field(default_factory=time.monotonic)
    topics: dict[str, int] = field(default_factory=dict)


class Recorder(BackgroundJob):
    """Records topics of ``graph`` into the bag at ``path``.

    Use it as an async context manager (it records until the block ends) or
    run ``await recorder.run()`` in a task and cancel it to stop::

        async with Recorder(graph, Path("run1"), topics=["/tf", "/scan"]):
            await anyio.sleep(10)

    Args:
        graph: the graph to record from.
        path: the bag to create: a directory for ROS 2 bags, a file for ROS 1.
        topics: glob patterns of the topic names to record (``/tf*``); all by default.
        selection: the topics to record with regular expressions and exclusions
            (``TopicSelection``); replaces ``topics`` when given.
        fmt: MCAP (default), sqlite3, or ROS 1; ROS 1 bags need a ROS 1 graph.
        split: when to start a new file (``BagWriter``).
        checkpoint_s: seconds between checkpoints.
        discover_s: seconds between looks for new matching topics.
        max_queue_bytes: bytes of messages waiting for the disk before dropping.
        max_bytes: stop recording (the bag is closed, the graph goes on) before
            the serialized messages pass this many bytes; None: no limit. To start
            a new part instead, give ``split`` a ``max_bytes``.
        compression: how MCAP chunks are compressed; None: not.
        repeat_latched: start each split part with the last message of every
            latched topic, so a part played alone has its /tf_static and maps.

    Attributes:
        stats: what was recorded so far (``RecordStats``).
        full: ``max_bytes`` was reached and recording has stopped.

    Raises:
        BagError: the format does not fit the graph's dialect, or a chunk
            compression is given for a format other than MCAP.
    """

    def __init__(
        self,
        graph: Graph,
        path: Path | str,
        *,
        topics: Sequence[str] = ("*",),
        fmt: BagFormat | str = BagFormat.MCAP,
        split: SplitPolicy | None = None,
        checkpoint_s: float = 1.0,
        discover_s: float = 0.2,
        max_queue_bytes: int = 256 * 1024 * 1024,
        max_bytes: int | None = None,
        selection: TopicSelection | None = None,
        compression: Compression | None = None,
        repeat_latched: bool = True,
    ) -> None:
        self.graph = graph
        self.path = Path(path)
        self.fmt = BagFormat(fmt)
        ros1_graph = graph.registry.dialect is Dialect.ROS1
        if (self.fmt is BagFormat.ROS1) != ros1_graph:
            wanted = "a ROS 1" if self.fmt is BagFormat.ROS1 else "a ROS 2"
            raise BagError(f"a {self.fmt.value} bag needs {wanted} graph (--dialect)")
        self.selection = selection or TopicSelection(tuple(topics))
        self._compression = (compression or Compression()).check_format(self.fmt)
        self._repeat_latched = repeat_latched
        self.stats = RecordStats()
        self._split = split
        self._checkpoint_s = checkpoint_s
        self._discover_s = discover_s
        self._max_queue = max_queue_bytes
        self._queue: list[_Item] = []
        self._queued_bytes = 0
        self._wake = anyio.Event()
        self._subscriptions: dict[str, LocalSubscription] = {}
        self._writer: BagWriter | None = None
        self._max_bytes = max_bytes
        self._accepted_bytes = 0  # queued or written, counted against ``max_bytes``
        self.full = False  # ``max_bytes`` reached (or a write failed): recording has stopped
        self.failed: str | None = None  # why the disk refused data, if it did
        self._log = EpisodeLog(logger)  # topics past the cap: once per episode
        self._taken: set[tuple[str, str]] = set()  # (topic, type) recorded: MAX_RECORD_TOPICS

    @property
    def live_topics(self) -> int:
        """Topics subscribed to now (each still has a publisher or another subscriber)."""
        return len(self._subscriptions)

    @property
    def paths(self) -> list[Path]:
        """The files written so far (more than one after a split)."""
        return list(self._writer.paths) if self._writer else [self.path]

    def matches(self, topic: str) -> bool:
        """Whether ``topic`` is recorded (the selection takes its resolved name)."""
        return self.selection.matches(topic)

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """Record until cancelled; the bag is complete when this returns.

        A write error (a full disk, a file size limit, a storage error) ends the
        recording, not its caller: one error line names the bag and the cause, the
        subscriptions go, and the bag keeps what reached it (readable up to its last
        checkpoint, as after a kill); ``failed`` holds the cause.

        Raises:
            BagError: the bag cannot be created.
        """
        self.stats = RecordStats()
        registry = self.graph.registry
        self._writer = await anyio.to_thread.run_sync(
            lambda: BagWriter(
                self.path,
                self.fmt,
                registry.typestore(),
                self._split,
                definitions=lambda name: registry.message(name).full_text(),
                compression=self._compression,
                repeat_latched=self._repeat_latched,
            )
        )
        try:
            self.discover()
            task_status.started()
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._discover_loop)
                try:
                    await self._write_loop()  # returns when ``max_bytes`` is reached
                except WRITE_ERRORS as exc:
                    self._fail(exc)
                tg.cancel_scope.cancel()
        finally:
            with anyio.CancelScope(shield=True):
                self._unsubscribe()
                await anyio.to_thread.run_sync(self._finish)
            from .progress import record_line  # noqa: PLC0415 - rich, for the CLI's lines

            # what was recorded and what was not, once, however the recording ended
            level = logging.WARNING if self.stats.dropped or self.failed else logging.INFO
            logger.log(level, "event=record_done %s", record_line(self, final=True))

    async def _discover_loop(self) -> None:
        while True:
            await anyio.sleep(self._discover_s)
            self.discover()

    def discover(self) -> None:
        """Subscribe to each matching topic not yet recorded; let go of abandoned ones."""
        if self.full:
            return
        self._forget_abandoned()
        for name, entry in list(self.graph.topics.items()):
            if name in self._subscriptions or not self.matches(name):
                continue
            key = (name, entry.msgtype.name)
            if key not in self._taken:
                if len(self._taken) >= MAX_RECORD_TOPICS:
                    self._log.log(
                        logging.WARNING,
                        "record_topics_full",
                        "event=record_topics_full topic=%s limit=%d bag=%s (not recorded)",
                        name,
                        MAX_RECORD_TOPICS,
                        self.path,
                    )
                    continue
                self._taken.add(key)
                # once per topic and type: at most MAX_RECORD_TOPICS lines, however
                # often clients bring a topic back
                logger.info("event=record topic=%s type=%s", name, entry.msgtype.name)
            latched = any(entry.publishers.values()) or entry.latched is not None
            offered = None if entry.qos is None else entry.qos.offered  # (D62)
            info = TopicInfo(name, entry.msgtype.rosbags_name, latched, offered)
            callback = self._sink(info, entry.msgtype)
            self._subscriptions[name] = self.graph.create_subscription(
                name, callback, node="/rwt_recorder"
            )

    def _forget_abandoned(self) -> None:
        """Unsubscribe from topics whose only participant left is the recorder.

        Their client left: keeping the subscription would keep the topic in the
        graph with the type that client gave it (refusing anyone who brings it
        back with another type) and grow the recorder with every topic ever seen.
        """
        topics = self.graph.topics
        for name, subscription in list(self._subscriptions.items()):
            entry = topics.get(name)
            if entry is not None and (
                entry.publishers or any(s is not subscription for s in entry.subscribers.values())
            ):
                continue
            del self._subscriptions[name]
            subscription.close()

    def _sink(self, info: TopicInfo, mtype: MessageType) -> _Callback:
        serialize = codec_for(self.graph.registry, mtype).serializer()
        clock = self.graph.clock

        def on_message(msg: dict[str, object]) -> None:
            if self.full:
                return
            raw = serialize(msg)
            if self._max_bytes is not None and self._accepted_bytes + len(raw) > self._max_bytes:
                self._stop_full()
                return
            if self._queued_bytes + len(raw) > self._max_queue:
                self.stats.dropped += 1
                self._log.log(
                    logging.WARNING,
                    "record_dropped",
                    "event=record_dropped bag=%s reason='the disk is slower than the messages' "
                    "queue_bytes=%d (the summary at the end counts them)",
                    self.path,
                    self._max_queue,
                )
                return
            self._queue.append((info, int(clock.wall() * 1e9), raw))
            self._queued_bytes += len(raw)
            self._accepted_bytes += len(raw)
            self._wake.set()

        return on_message

    def _stop_full(self) -> None:
        """``max_bytes`` is reached: write what is queued, close the bag, record no more."""
        self.full = True
        self._wake.set()
        logger.warning(
            "event=record_stopped reason=max_size limit_bytes=%d bag=%s "
            "(recording stopped; the server goes on; --record-split starts new parts instead)",
            self._max_bytes,
            self.path,
        )

    async def _write_loop(self) -> None:
        next_checkpoint = time.monotonic() + self._checkpoint_s
        while True:
            with anyio.move_on_after(max(0.0, next_checkpoint - time.monotonic())):
                await self._wake.wait()
            self._wake = anyio.Event()
            await self._flush()
            if self.full:
                return
            if time.monotonic() >= next_checkpoint:
                assert self._writer is not None
                await anyio.to_thread.run_sync(self._writer.checkpoint)
                next_checkpoint = time.monotonic() + self._checkpoint_s

    async def _flush(self) -> None:
        batch, self._queue = self._queue, []
        self._queued_bytes = 0
        if batch:
            await anyio.to_thread.run_sync(self._write_batch, batch)

    def _write_batch(self, batch: list[_Item]) -> None:
        writer = self._writer
        assert writer is not None
        stats = self.stats
        topics = stats.topics
        count = size = 0
        try:
            for info, ns, raw in batch:
                writer.write(info, ns, raw)
                topics[info.topic] = topics.get(info.topic, 0) + 1
                count += 1
                size += len(raw)
        finally:  # counted once per batch, also when the disk refused the rest
            stats.messages += count
            stats.bytes += size

    def _unsubscribe(self) -> None:
        for subscription in self._subscriptions.values():
            subscription.close()
        self._subscriptions.clear()

    def _fail(self, exc: BaseException) -> None:
        """The disk refused data: stop recording, keep serving (docs/record-replay.md)."""
        self.failed = f"{type(exc).__name__}: {exc}"
        self.full = True
        self._unsubscribe()
        logger.error(
            "event=record_failed bag=%s reason=%r (recording stopped; the server goes on; "
            "the bag holds what was written up to its last checkpoint)",
            self.path,
            self.failed,
        )

    def _finish(self) -> None:
        """Write what is queued and close the bag (in the writer thread)."""
        batch, self._queue = self._queue, []
        writer = self._writer
        if writer is None:
            return
        try:
            if self.failed is None:
                self._write_batch(batch)
        except WRITE_ERRORS as exc:
            self._fail(exc)
        finally:
            try:
                writer.close()
            except WRITE_ERRORS as exc:  # the footer did not fit: the last checkpoint stays
                if self.failed is None:
                    self._fail(exc)
                else:
                    logger.debug("closing %s after a write error: %s", self.path, exc)


if TYPE_CHECKING:
    from collections.abc import Callable

    _Callback = Callable[[dict[str, object]], None]
