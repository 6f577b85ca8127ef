"""Remote samples of one topic handed to the event loop a batch at a time.

With a Python callback, Zenoh calls into Python once per sample on a thread of
its own, and that thread and the event loop take the interpreter lock in turn
for every sample: under a flood each side spent much of its time waiting for
the other (Z3 in benchmarks/README.md, "Scaling out"). A ``SampleFeed`` lets
Zenoh queue samples in its own channel instead (no Python per sample there);
one thread of the feed waits for the first sample of a batch, asks the loop to
run once, and sleeps until the loop has taken everything queued meanwhile.

This is the ``zenoh-sample-batch`` shortcut (rwt_protocol.shortcuts); with it
off, the link declares a callback per sample (``ZenohLink._subscribe``).
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

import zenoh

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["BATCH", "SampleFeed"]

BATCH = 256
"""Samples handled in one turn of the loop before others run."""


class SampleFeed:
    """Feeds the samples a Zenoh channel holds to ``handle``, in the loop's task.

    Args:
        handler: the subscriber's channel (``zenoh.handlers.RingChannel``: when
            the loop falls behind, the oldest samples are dropped there, which
            bounds memory).
        handle: called with each sample, on the loop, in arrival order.
        soon: runs a callable in the loop's task (``ZenohLink.soon``); it may
            drop the call once the link closed.
    """

    def __init__(
        self,
        handler: Any,
        handle: Callable[[zenoh.Sample], None],
        soon: Callable[..., None],
    ) -> None:
        self._handler = handler
        self._handle = handle
        self._soon = soon
        self._drained = threading.Event()
        self._closed = False
        self._thread = threading.Thread(target=self._wait, name="rwt-zenoh-feed", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop after the subscriber was undeclared (its channel then ends ``recv``)."""
        self._closed = True
        self._drained.set()

    def _wait(self) -> None:  # the feed's thread
        while not self._closed:
            try:
                first = self._handler.recv()  # without the interpreter lock while it waits
            except zenoh.ZError:
                return  # the subscriber was undeclared
            self._drained.clear()
            self._soon(self._batch, first)
            self._drained.wait()

    def _batch(self, first: zenoh.Sample | None = None) -> None:  # the loop
        """Handle ``first`` and what queued behind it, up to ``BATCH``, then let others run."""
        handle, try_recv = self._handle, self._handler.try_recv
        if first is not None:
            handle(first)
        for _ in range(BATCH):
            if self._closed:
                return
            sample = try_recv()
            if sample is None:
                self._drained.set()  # the thread waits for the next one again
                return
            handle(sample)
        self._soon(self._batch)  # more queued: the rest in a later turn
