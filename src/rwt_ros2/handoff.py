"""Work handed from rclpy's threads to the event loop, bounded in bytes.

rclpy calls back on its own threads; the graph may only be touched on the event
loop's. ``Handoff.put`` (any thread) queues a callback with its size in bytes
(``put_many``: a batch of samples of one topic) and, unless a wake-up is pending
already, asks the loop to run what is queued, in order (``drain``). Samples beyond
``max_bytes`` queued are dropped, one log line per topic and episode
(``rwt_graph.ratelog``), so a ROS 2 publisher faster than the bridge cannot
exhaust memory; replies and graph events are never dropped (they are small and
each answers something this process asked for).

Samples are bounded by time too: the queue holds at most ``max_wait_s``
(``MAX_WAIT_S``) of one publisher's samples of a topic, by when they were
published (their source timestamps, on the publisher's clock, so a clock of
another host skews nothing: samples of one publisher are only compared with
each other). A sample published more than that before the newest queued sample
of its publisher, with at least ``KEEP_NEWER`` (the link's history depth) of that
publisher's samples queued after it, is dropped when its turn comes, and counted
in ``expired`` (docs/ros2.md, "Latency under rate"). So a
loop that fell behind a steady stream (a busy machine, a flood) catches up with
the newest samples rather than working through old ones, as a ROS 2
subscription's history drops its oldest samples when its node falls behind,
while a burst that came within ``max_wait_s``, or of fewer samples than that
history keeps, reaches the graph whole. While
the oldest queued sample has waited half that (``behind``), the taking thread
pauses (``pause_while_behind``): new samples wait in the middleware's history,
which keeps the newest at no cost to the loop, rather than being taken only to
expire here.

A sample queued with a run callback (``put_many``'s ``run``) goes with the
samples of its topic and publisher queued right behind it, up to ``RUN_MAX``,
in one call: the link publishes them as one run, which each subscriber that
takes runs gets in one call.

A topic whose delivery congested a subscriber is held back alone
(``rwt_graph.topic_holds``): its samples wait, still counted here, while every
other topic's go on.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections import deque
from typing import TYPE_CHECKING

import anyio

from rwt_graph.link import OPEN_GATE
from rwt_graph.ratelog import EpisodeLog
from rwt_graph.topic_holds import TopicHolds

from .graphview import INWARD_DEPTH

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.link import InflowGate

__all__ = ["MAX_QUEUED_BYTES", "MAX_WAIT_S", "Handoff"]

logger = logging.getLogger("rwt.ros2")

MAX_QUEUED_BYTES = 64 * 1024 * 1024
"""Bytes of ROS 2 samples waiting for the event loop beyond which new ones are dropped."""

MAX_WAIT_S = 0.020
"""Seconds of a topic's ROS 2 samples waiting for the event loop: a sample that came
more than this before the newest queued one of its topic is dropped (module text)."""

KEEP_NEWER = INWARD_DEPTH
"""Newer queued samples of its publisher a sample must have behind it before its wait
can drop it (``MAX_WAIT_S``): the link's subscriptions' history depth
(``graphview.INWARD_DEPTH``), so the handoff never drops a sample such a history
would still keep (a burst of a publisher the machine slowed down)."""

PAUSE_S = 0.001
"""Seconds the taking thread sleeps at a time while the loop is behind (``behind``)."""

TURN_S = 0.005
"""Seconds of queued callbacks one turn of the event loop runs at most; the rest go on
the next turn, after the connections have written what these queued (a flood of
samples to ten subscribers cost 0.2 ms each, so 1,000 in one turn held every frame
they made for 0.2 s: benchmarks/README.md, "ROS 2 bridge")."""

_BATCH = 1000

RUN_MAX = 64
"""The most samples of one topic and publisher handed to a run callback at once
(``put_many``'s ``run``): what a topic held back for a congested subscriber
overshoots its high watermark by at most."""

_Event = tuple[
    "Callable[..., None]",
    tuple[object, ...],
    int,
    str,
    float,
    bytes,
    float,
    "Callable[[list[tuple[object, ...]]], None] | None",
    int,
]
"""A queued callback, its arguments, its bytes, its topic ("" if no sample), when
it came (``Sample``), its publisher, when it was queued (``clock``), the
callback that takes a run of such samples' arguments at once (or None), and how
many samples of its topic and publisher were queued before it."""

Sample = tuple[tuple[object, ...], int, float, bytes]
"""A sample for ``Handoff.put_many``: its callback's arguments, its bytes, when it
was published (seconds, any clock its publisher keeps monotonic) and its publisher
(its GID; samples of one publisher are compared with each other only)."""


class Handoff:
    """A byte- and time-bounded queue of callbacks from other threads to one event loop's task.

    Args:
        max_bytes: samples' bytes kept waiting at most (``MAX_QUEUED_BYTES``).
        max_wait_s: seconds of one publisher's samples of a topic queued at most
            (``MAX_WAIT_S``) once ``keep_newer`` newer ones of it are queued too.
        keep_newer: newer samples of its publisher a sample waits behind at least
            before its wait can drop it (``KEEP_NEWER``).
        clock: monotonic seconds (a test's hand-moved clock).

    Attributes:
        expired: samples dropped for their wait, by topic.
    """

    def __init__(
        self,
        max_bytes: int = MAX_QUEUED_BYTES,
        max_wait_s: float = MAX_WAIT_S,
        clock: Callable[[], float] = time.monotonic,
        keep_newer: int = KEEP_NEWER,
    ) -> None:
        self.max_bytes = max_bytes
        self.max_wait_s = max_wait_s
        self.keep_newer = keep_newer
        self.clock = clock
        self.queued_bytes = 0
        self.dropped = 0
        self.expired: dict[str, int] = {}
        # by topic and publisher with samples waiting: when the newest came, how many were
        # queued since the first of those waiting, and how many wait (the key goes with
        # its last sample, so publishers that come and go, or forged GIDs, leave nothing)
        self._newest: dict[tuple[str, bytes], list[float]] = {}
        self._events: deque[_Event] = deque()
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None  # while ``drain`` runs
        self._holds: TopicHolds[_Event] | None = None
        #: topics never held back (``TopicHolds``): the mirrored actions' feedback
        self.never_held: set[str] = set()
        self._gate: Callable[[], InflowGate] = lambda: OPEN_GATE
        self._signalled = False
        self._closed = False
        self._drops = EpisodeLog(logger)

    def put(
        self, callback: Callable[..., None], *args: object, size: int = 0, topic: str = ""
    ) -> bool:
        """Queue ``callback(*args)`` (any thread); a sample (``topic``) may be dropped.

        Args:
            callback: runs in the link's task.
            *args: its arguments.
            size: the sample's bytes, counted against ``max_bytes``.
            topic: the sample's topic; empty for an event that is never dropped.

        Returns:
            False when the sample was dropped (or the handoff is closed).
        """
        with self._lock:
            if self._closed:
                return False
            if topic and self.queued_bytes + size > self.max_bytes:
                self._refuse(topic)
                return False
            self.queued_bytes += size
            came = self.clock()
            index = self._note(topic, b"", came) if topic else 0
            self._events.append((callback, args, size, topic, came, b"", came, None, index))
            signal = self._signal()
        if signal:
            self._wake_loop()
        return True

    def put_many(
        self,
        callback: Callable[..., None],
        samples: list[Sample],
        topic: str,
        run: Callable[[list[tuple[object, ...]]], None] | None = None,
    ) -> int:
        """Queue ``callback(*args)`` for each ``Sample`` of ``samples``, in order.

        ``samples``: one batch taken from ``topic``'s subscription; one lock and
        at most one wake-up of the loop for all of them, where ``put`` takes both
        per sample. A sample past ``max_bytes`` is dropped as ``put`` drops it.
        ``run``: when given, the loop calls ``run([args, ...])`` instead, once for
        each run of queued samples of ``topic`` from one publisher (up to
        ``RUN_MAX``, none of them outdated), so that their delivery costs one call
        per subscriber (``rwt_graph.link.Relays.deliver_many``).

        Returns:
            How many were queued (the rest were dropped, or the handoff is closed).
        """
        queued = 0
        with self._lock:
            if self._closed:
                return 0
            events, now = self._events, self.clock()
            for args, size, came, source in samples:
                if self.queued_bytes + size > self.max_bytes:
                    self._refuse(topic)
                    continue
                self.queued_bytes += size
                index = self._note(topic, source, came)
                events.append((callback, args, size, topic, came, source, now, run, index))
                queued += 1
            signal = queued > 0 and self._signal()
        if signal:
            self._wake_loop()
        return queued

    def _note(self, topic: str, source: bytes, came: float) -> int:
        """Note a sample of ``topic`` from ``source`` that came at ``came`` (under the lock).

        Returns:
            How many of that publisher's samples of the topic were queued before it.
        """
        noted = self._newest.get((topic, source))
        if noted is None:
            self._newest[topic, source] = [came, 1, 1]
            return 0
        count = int(noted[1])
        noted[0], noted[1], noted[2] = came, count + 1, noted[2] + 1
        return count

    def _left(self, topic: str, source: bytes, count: int = 1) -> None:
        """``count`` samples of ``topic`` from ``source`` left the queue (under the lock)."""
        key = (topic, source)
        noted = self._newest[key]
        noted[2] -= count
        if noted[2] <= 0:
            del self._newest[key]

    def _outdated(self, topic: str, source: bytes, came: float, index: int) -> bool:
        """Whether a sample (``came``, ``index`` as ``_note`` gave it) is to be dropped.

        It came more than ``max_wait_s`` before the newest sample of its publisher
        and topic, and ``keep_newer`` of those came after it (under the lock).
        """
        newest, count, _ = self._newest[topic, source]
        return newest - came > self.max_wait_s and count - index > self.keep_newer

    def behind(self) -> bool:
        """Whether the oldest queued event has waited over half ``max_wait_s`` (any thread).

        Its wait counts from when it was queued, by ``clock``: the loop is behind.
        """
        try:
            queued = self._events[0][6]
        except IndexError:
            return False
        return queued < self.clock() - self.max_wait_s / 2

    def pause_while_behind(self) -> None:
        """Sleep while ``behind``, ``PAUSE_S`` at a time, ``max_wait_s`` at most (taking thread)."""
        waited = 0.0
        while waited < self.max_wait_s and not self._closed and self.behind():
            time.sleep(PAUSE_S)
            waited += PAUSE_S

    def _refuse(self, topic: str) -> None:
        """Count and log a dropped sample of ``topic`` (under the lock)."""
        self.dropped += 1
        self._drops.log(
            logging.WARNING,
            f"drop:{topic}",
            "event=ros2_samples_dropped topic=%s queued_bytes=%d limit=%d",
            topic,
            self.queued_bytes,
            self.max_bytes,
        )

    def _signal(self) -> bool:
        """Whether the loop must be woken: no wake-up is pending yet (under the lock)."""
        signal = not self._signalled
        self._signalled = True
        return signal

    def _wake_loop(self) -> None:
        loop = self._loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(self._turn)

    async def drain(self, gate: Callable[[], InflowGate] = lambda: OPEN_GATE) -> None:
        """Run queued callbacks in order on this task's loop, until cancelled.

        A put wakes the loop with a call of ``_turn``, which runs what is queued
        right there, without a task switch: one callback per hand-over, where
        an event set for a waiting task cost a second turn of the loop. Each
        batch runs inside ``gate()`` (the graph's ``InflowGate``); a sample
        that congested a subscriber holds its topic back (``TopicHolds``) until
        that subscriber drains, within its hold budget (``rwt_graph.link``,
        "Backpressure"), while the other topics go on; each hold waits in this
        task's task group. Errors of a callback are logged; the others still run.
        """
        loop = asyncio.get_running_loop()
        async with anyio.create_task_group() as tg:
            self._holds = TopicHolds(tg.start_soon, self._resume, self.never_held)
            self._gate = gate
            self._loop = loop
            try:
                loop.call_soon(self._turn)  # whatever was queued before the loop was known
                await anyio.sleep_forever()
            finally:
                self._loop = None
                self._holds = None

    def _turn(self) -> None:
        """Run queued callbacks for up to ``TURN_S`` (and ``_BATCH`` of them) on the loop.

        A flood goes on next turn, after the connections have written.
        """
        with self._lock:
            self._signalled = False
        holds = self._holds
        if holds is not None and self._events:
            inflow = self._gate()
            inflow.begin()
            try:
                self._run_batch(inflow, holds)
            finally:
                inflow.end()
        if self._events and self._loop is not None:
            self._loop.call_soon(self._turn)  # a flood: let the servers send meanwhile

    def _run_batch(self, inflow: InflowGate, holds: TopicHolds[_Event]) -> None:
        clock = self.clock
        end = clock() + TURN_S
        events = self._events
        for _ in range(_BATCH):
            if not events or clock() > end:
                return
            with self._lock:
                event = events.popleft()
                callback, args, size, topic, came, source, _, run, index = event
                outdated = bool(topic) and self._outdated(topic, source, came, index)
                if outdated:
                    self._left(topic, source)
            if outdated:
                self._expire(topic, size)
                continue
            if topic and holds.park(topic, event):
                continue  # still counted in ``queued_bytes``: it waits here
            if run is not None and self._follows(run, topic, source):
                self._run(run, args, size, topic, source)
            else:
                with self._lock:
                    self.queued_bytes -= size
                    if topic:
                        self._left(topic, source)
                try:
                    callback(*args)
                except Exception:
                    logger.exception("ros2 link: %s failed", getattr(callback, "__name__", ""))
            holds.delivered(topic or None, inflow)

    def _follows(
        self, run: Callable[[list[tuple[object, ...]]], None], topic: str, source: bytes
    ) -> bool:
        """Whether the next queued sample would join a run of ``topic`` from ``source``.

        A sample alone goes to its own callback: one call less (1 kHz and below).
        """
        try:
            follower = self._events[0]
        except IndexError:
            return False
        return follower[7] is run and follower[3] == topic and follower[5] == source

    def _run(
        self,
        run: Callable[[list[tuple[object, ...]]], None],
        args: tuple[object, ...],
        size: int,
        topic: str,
        source: bytes,
    ) -> None:
        """Call ``run`` with ``args`` and the samples' queued right behind it.

        Those of ``topic`` from ``source``, up to ``RUN_MAX``; the outdated ones expire.
        """
        runs = [args]
        events, taken = self._events, 1
        with self._lock:
            while events and len(runs) < RUN_MAX:
                follower = events[0]
                if follower[7] is not run or follower[3] != topic or follower[5] != source:
                    break
                events.popleft()
                taken += 1
                size += follower[2]
                if self._outdated(topic, source, follower[4], follower[8]):
                    self.expired[topic] = self.expired.get(topic, 0) + 1
                    continue
                runs.append(follower[1])
            self.queued_bytes -= size
            self._left(topic, source, taken)
        try:
            run(runs)
        except Exception:
            logger.exception("ros2 link: a run of %s failed", topic)

    def _expire(self, topic: str, size: int) -> None:
        """Drop a sample of ``topic`` that a newer one outdated (on the loop)."""
        with self._lock:
            self.queued_bytes -= size
        self.expired[topic] = self.expired.get(topic, 0) + 1

    def _resume(self, events: list[_Event]) -> None:
        """Put a held topic's samples back at the front, oldest first (on the loop)."""
        with self._lock:
            if self._closed:
                return
            self._events.extendleft(reversed(events))
        if self._loop is not None:
            self._loop.call_soon(self._turn)

    def close(self) -> None:
        """Refuse new work and forget what is queued."""
        with self._lock:
            self._closed = True
            self._events.clear()
            self._newest.clear()
            self.queued_bytes = 0
