"""Local samples for Zenoh's reliable publishers, put on a thread of their own.

rwt's publishers on Zenoh are reliable with congestion control BLOCK (as
rmw_zenoh declares a reliable KEEP_ALL publisher): a full transmission queue
makes ``put`` wait rather than drop the sample. Waiting must never happen on the
event loop, so the loop only hands samples here and one thread puts them, in
order. What waits is bounded in bytes, as the link's inbox is (docs/zenoh.md,
"Reliability"): a Zenoh peer slower than the local publishers costs the oldest
samples of the busiest topic past that bound, never the loop's time.

What the loop puts in one of its turns (the fan-out of a reader's batch of
publishes) reaches the thread together when the turn ends: one lock and one
wake-up of the thread per turn, not per sample, and the thread runs while the
loop waits for input rather than taking the GIL from it mid-turn
(benchmarks/README.md, "Scaling out"). A program that blocks its event loop
after publishing holds its samples back until the loop runs again.
"""

from __future__ import annotations

import asyncio
import logging
import queue
import threading
from typing import TYPE_CHECKING, Any, cast

from rwt_graph.ratelog import EpisodeLog

from .inbox import Inbox, Sample
from .limits import MAX_OUTBOX_BYTES

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["Outbox"]

logger = logging.getLogger("rwt.zenoh")


class Outbox:
    """Samples waiting for Zenoh's blocking ``put``, bounded in bytes (thread-safe).

    Args:
        max_bytes: bytes held at most (``limits.MAX_OUTBOX_BYTES`` by default);
            past it the oldest samples of the topic holding the most are dropped,
            logged once per episode.
    """

    def __init__(self, max_bytes: int = MAX_OUTBOX_BYTES) -> None:
        self._held = Inbox(max_bytes, drop_log=EpisodeLog(logger))
        self._tickets: queue.SimpleQueue[list[str] | None] = queue.SimpleQueue()
        self._turn: list[tuple[str, Sample]] = []  # put in this turn of the loop
        self._thread: threading.Thread | None = None
        self._log = EpisodeLog(logger)

    @property
    def dropped(self) -> int:
        """Samples dropped because the bound was reached."""
        return self._held.dropped

    def put(self, key: str, handle: Any, payload: bytes | bytearray, attachment: bytes) -> None:
        """Hand ``payload`` for ``handle`` (a ``zenoh.Publisher`` of topic ``key``) over.

        Never waits: runs on the event loop. The sample goes to the sender thread
        (started on first use) when this turn of the loop ends, with the others
        of the turn, in order; at once when no asyncio loop runs here.
        """
        send: Callable[[bytes, bytes | None], None] = lambda data, extra: handle.put(  # noqa: E731
            data, attachment=extra
        )
        first = not self._turn
        self._turn.append((key, Sample(send, cast("bytes", payload), attachment)))
        if first:
            try:
                asyncio.get_running_loop().call_soon(self._hand_over)
            except RuntimeError:  # no loop: nothing to wait for
                self._hand_over()

    def close(self, timeout_s: float = 1.0) -> None:
        """Stop the sender thread after what it holds is put (waits ``timeout_s`` at most)."""
        self._hand_over()
        thread, self._thread = self._thread, None
        if thread is not None:
            self._tickets.put(None)
            thread.join(timeout_s)

    def _hand_over(self) -> None:
        """Give the sender thread what this turn put (on the loop)."""
        turn, self._turn = self._turn, []
        keys = self._held.put_all(turn)
        if keys:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="rwt-zenoh-out", daemon=True)
                self._thread.start()
            self._tickets.put(keys)

    def _run(self) -> None:
        while (keys := self._tickets.get()) is not None:
            for key in keys:
                self._send(key)

    def _send(self, key: str) -> None:
        sample = self._held.take(key)
        if sample is None:
            return  # dropped while it waited
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
