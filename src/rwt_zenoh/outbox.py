"""Local samples for Zenoh's reliable publishers, put on a thread of their own.

rwt's publishers on Zenoh are reliable with congestion control BLOCK (as
rmw_zenoh declares a reliable KEEP_ALL publisher): a full transmission queue
makes ``put`` wait rather than drop the sample. Waiting must never happen on the
event loop, so the loop only hands samples here and one thread puts them, in
order. What waits is bounded in bytes, as the link's inbox is (docs/zenoh.md,
"Reliability"). Past half the bound the outbox is congested: the connection
whose publish took it there is held back until it is under a quarter
(``rwt_graph.link.Backlog``, as a congested subscriber holds publishers back),
within the hold budget; what still comes past the bound (an in-process
publisher, a peer stalled past the budget) costs the oldest samples of the
busiest topic, never the loop's time.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import queue
import threading
import time
from typing import TYPE_CHECKING, Any

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.runtime.outbox import water_marks

from .deferred import Deferred
from .inbox import Inbox, Sample
from .limits import MAX_OUTBOX_BYTES

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["NOTIFY_EVERY_S", "Outbox"]

logger = logging.getLogger("rwt.zenoh")

NOTIFY_EVERY_S = 0.01
"""Seconds between two progress calls to a watcher, at most (``Outbox.watch``): each
wakes the event loop, and a peer slow enough to congest the outbox may still take
thousands of small samples a second. The call saying the outbox emptied is never
held back."""


class Outbox:
    """Samples waiting for Zenoh's blocking ``put``, bounded in bytes (thread-safe).

    A ``rwt_graph.link.Backlog``: congested above half of ``max_bytes``, and
    readers held back by it wait until it is under a quarter.

    Args:
        max_bytes: bytes held at most (``limits.MAX_OUTBOX_BYTES`` by default);
            past it the oldest samples of the topic holding the most are dropped,
            logged once per episode.
    """

    def __init__(self, max_bytes: int = MAX_OUTBOX_BYTES) -> None:
        self._held = Inbox(max_bytes, drop_log=EpisodeLog(logger))
        # a topic's sample to put, a call to make after the samples before it, or the end
        self._tickets: queue.SimpleQueue[str | Callable[[], None] | None] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._log = EpisodeLog(logger)
        self._marks = water_marks(max_bytes)
        self._on_take: Callable[[bool], None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._notified = 0.0  # time.monotonic() of the last call to the watcher

    @property
    def queued_bytes(self) -> int:
        """Bytes waiting for their put now."""
        return self._held.bytes

    @property
    def water_marks(self) -> tuple[int, int]:
        """(high, low) watermarks in bytes: half and a quarter of the bound."""
        return self._marks

    @property
    def congested(self) -> bool:
        """Whether more than the high watermark waits."""
        return self._held.bytes > self._marks[0]

    def watch(self, on_take: Callable[[bool], None] | None) -> None:
        """Call ``on_take(caught_up)`` on this event loop as puts go out (None: stop).

        Called on the event loop. ``caught_up`` says nothing waited after the put;
        that call always comes, the others at most every ``NOTIFY_EVERY_S``.
        """
        if on_take is not None:
            self._loop = asyncio.get_running_loop()
        self._on_take = on_take

    @property
    def dropped(self) -> int:
        """Samples dropped because the bound was reached."""
        return self._held.dropped

    def put(
        self, key: str, handle: Any, payload: bytes | bytearray | Deferred, attachment: bytes
    ) -> None:
        """Hand ``payload`` for ``handle`` (a ``zenoh.Publisher`` of topic ``key``) over.

        A ``Deferred`` payload is made on the sender thread, right before its put,
        and counts its exact length against the bound (``deferred``).

        Never waits: runs on the event loop. The sender thread starts on first use.
        """

        def send(data: object, extra: bytes | None) -> None:
            handle.put(data.make() if isinstance(data, Deferred) else data, attachment=extra)

        if self._held.put(key, Sample(send, payload, attachment)):
            self._start()
            self._tickets.put(key)

    def call_after_puts(self, call: Callable[[], None]) -> None:
        """Run ``call`` on the sender thread once the samples handed over before it are put.

        Never dropped, never waits (on the event loop): for an answer that must not
        overtake them, as an action's result its feedback (``link_actions``). The
        caller bounds how many it hands over.
        """
        self._start()
        self._tickets.put(call)

    def _start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="rwt-zenoh-out", daemon=True)
            self._thread.start()

    def close(self, timeout_s: float = 1.0) -> None:
        """Stop the sender thread after what it holds is put (waits ``timeout_s`` at most)."""
        thread, self._thread = self._thread, None
        if thread is not None:
            self._tickets.put(None)
            thread.join(timeout_s)

    def _run(self) -> None:
        while (key := self._tickets.get()) is not None:
            if not isinstance(key, str):
                self._call(key)
                continue
            sample = self._held.take(key)
            if sample is not None:  # else dropped while it waited
                self._put(key, sample)
            self._notify()

    def _put(self, key: str, sample: Sample) -> None:
        try:
            sample.deliver(sample.payload, sample.attachment)
        except Exception as exc:
            self._log.log(
                logging.WARNING,
                f"zenoh_put_failed:{key}",
                "event=zenoh_put_failed topic=%s reason=%r",
                key,
                str(exc),
            )

    def _call(self, call: Callable[[], None]) -> None:
        try:
            call()
        except Exception as exc:
            self._log.log(
                logging.WARNING,
                "zenoh_put_failed:call",
                "event=zenoh_put_failed reason=%r",
                str(exc),
            )

    def _notify(self) -> None:
        """Tell the watcher of a put (the sender thread): see ``watch``."""
        on_take, loop = self._on_take, self._loop
        if on_take is None or loop is None:
            return
        caught_up = self._held.bytes == 0
        now = time.monotonic()
        if caught_up or now - self._notified >= NOTIFY_EVERY_S:
            self._notified = now
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(on_take, caught_up)
