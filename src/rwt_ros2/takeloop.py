"""The link's subscriptions taken from an rcl wait set on a thread of their own.

rclpy's single-threaded executor, for each sample it wakes up for, builds a wait
set of every entity of the node, walks them in Python, makes a task of the
callback and runs it: most of a 1 kHz stream's cost on the executor's thread
(benchmarks/README.md, "ROS 2 bridge"). ``TakeLoop`` waits on the link's
subscriptions alone, and on each wake-up takes what waits in every ready one (at
most ``TAKE_BATCH`` each) and hands it over as one batch per subscription. While
samples come faster than one per ``LINGER_GAP_S`` it waits ``LINGER_S`` before
the next wake-up, so that one wake-up (of this thread and of the event loop)
carries several. The executor still serves everything else (services, clients,
actions, parameters).

This is the ``ros2-take-loop`` shortcut (docs/shortcuts.md): it reaches below
rclpy's ``Node`` (``rclpy.impl.implementation_singleton``'s ``Subscription``,
``WaitSet`` and ``GuardCondition``, as the executor uses them), so the node does
not list these subscriptions and its executor never waits on them. With the
shortcut off, the link subscribes through ``Node.create_subscription`` and the
executor calls it back (the general path, ``rwt_ros2.link``).
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["LINGER_GAP_S", "LINGER_S", "TAKE_BATCH", "WAIT_S", "TakeLoop", "take_queued"]

logger = logging.getLogger("rwt.ros2")

TAKE_BATCH = 256
"""Samples of one subscription taken per wake-up at most: the rest wait for the
next, so one busy topic cannot hold the others back for long."""

LINGER_S = 0.0005
"""How long the loop waits after a wake-up before the next, seconds, while samples
come faster than ``LINGER_GAP_S``: at 5 kHz a wake-up then takes 2-15 samples
instead of one, for 0.2 ms more latency (benchmarks/README.md, "ROS 2 bridge")."""

LINGER_GAP_S = 0.0005
"""The time per sample of the last wake-up below which the loop lingers, seconds
(faster than 2 kHz); a 1 kHz topic's samples each go at once."""

WAIT_S = 0.1
"""How long one wait lasts at most, seconds: how soon the thread sees the context end."""

Taken = tuple[bytes, dict[str, Any]]
"""A raw sample as rclpy takes it: its CDR and its message info (``publisher_gid``...)."""


@dataclass(eq=False)
class _Entry:
    handle: Any  # the rcl subscription (rclpy's pybind11 ``Subscription``)
    msg_type: Any
    on_batch: Callable[[list[Taken]], None]


class TakeLoop:
    """Raw subscriptions of one rclpy node, taken on a daemon thread (see the module text).

    Args:
        node: the ``rclpy.node.Node`` the subscriptions belong to (not listed in it).

    ``subscribe`` and ``unsubscribe`` may be called from any thread; each batch's
    callback runs on the loop's thread.
    """

    def __init__(self, node: Any) -> None:
        from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: PLC0415

        self._rclpy = rclpy_implementation
        self._node = node
        self._context = node.context
        self._guard = rclpy_implementation.GuardCondition(self._context.handle)
        self._entries: dict[int, _Entry] = {}  # by the handle's pointer
        self._lock = threading.Lock()
        self._changed = True
        self._stopped = False
        self._last = 0.0  # when the last wake-up took samples (``time.monotonic``)
        self.pace: Callable[[], None] | None = None
        """Called before each wait: the link's ``Handoff.pause_while_behind``, so that
        samples wait in the middleware while the event loop is behind."""
        self._thread = threading.Thread(target=self._run, name="rwt-ros2-take", daemon=True)

    def start(self) -> None:
        """Start taking."""
        self._thread.start()

    def subscribe(
        self, msg_type: Any, topic: str, qos: Any, on_batch: Callable[[list[Taken]], None]
    ) -> Any:
        """A raw subscription of ``topic`` whose samples go to ``on_batch``, in order.

        Args:
            msg_type: the generated rclpy class of the topic's type.
            topic: the absolute topic name.
            qos: an ``rclpy.qos.QoSProfile``.
            on_batch: gets each wake-up's samples of this subscription (1 to
                ``TAKE_BATCH``), on the loop's thread.

        Returns:
            The subscription's handle, for ``unsubscribe``.

        Raises:
            rclpy's errors for a bad topic name or type (as ``Node.create_subscription``).
        """
        from rclpy.type_support import check_is_valid_msg_type  # noqa: PLC0415

        check_is_valid_msg_type(msg_type)
        with self._node.handle:
            handle = self._rclpy.Subscription(
                self._node.handle, msg_type, topic, qos.get_c_qos_profile(), None
            )
        with self._lock:
            self._entries[handle.pointer] = _Entry(handle, msg_type, on_batch)
            self._changed = True
        self._guard.trigger_guard_condition()
        return handle

    def unsubscribe(self, handle: Any) -> None:
        """Stop taking ``handle``'s samples and destroy it (once no wait uses it)."""
        with self._lock:
            self._entries.pop(handle.pointer, None)
            self._changed = True
        handle.destroy_when_not_in_use()
        with contextlib.suppress(Exception):  # the context is going
            self._guard.trigger_guard_condition()

    def close(self) -> None:
        """Stop the thread (before the node is destroyed) and destroy every subscription."""
        with self._lock:
            self._stopped = True
            entries, self._entries = list(self._entries.values()), {}
        with contextlib.suppress(Exception):
            self._guard.trigger_guard_condition()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        for entry in entries:
            entry.handle.destroy_when_not_in_use()
        self._guard.destroy_when_not_in_use()

    def _run(self) -> None:
        try:
            self._loop()
        except Exception:  # the context ended under the wait
            if self._context.ok() and not self._stopped:
                logger.exception("ros2 link: the take loop failed")

    def _loop(self) -> None:
        from rclpy.exceptions import InvalidHandle  # noqa: PLC0415

        entries: list[_Entry] = []
        wait_set: Any = None
        timeout_ns = int(WAIT_S * 1e9)
        while self._context.ok() and not self._stopped:
            if self._changed:
                with self._lock:
                    entries, self._changed = list(self._entries.values()), False
                wait_set = self._rclpy.WaitSet(len(entries), 1, 0, 0, 0, 0, self._context.handle)
            if self.pace is not None:
                self.pace()
            try:
                count = self._wait_and_take(wait_set, entries, timeout_ns)
            except InvalidHandle:  # unsubscribed meanwhile: the next turn leaves it out
                continue
            if count:
                self._linger(count)

    def _wait_and_take(self, wait_set: Any, entries: list[_Entry], timeout_ns: int) -> int:
        """One wait of ``wait_set`` on ``entries`` and the guard; the samples taken."""
        with contextlib.ExitStack() as held:  # no handle destroyed while waited on
            for entry in entries:
                held.enter_context(entry.handle)
            held.enter_context(self._context.handle)
            wait_set.clear_entities()
            for entry in entries:
                wait_set.add_subscription(entry.handle)
            wait_set.add_guard_condition(self._guard)
            wait_set.wait(timeout_ns)
            ready = wait_set.get_ready_entities("subscription")
            return sum(self._take(entry) for entry in entries if entry.handle.pointer in ready)

    def _linger(self, count: int) -> None:
        """Wait ``LINGER_S`` after a wake-up when samples come faster than ``LINGER_GAP_S``.

        The next wake-up then takes several samples for one hand-over (one wake-up
        of the event loop, one socket write per subscriber); at lower rates each
        sample goes at once.
        """
        now = time.monotonic()
        gap = (now - self._last) / count
        self._last = now
        if gap < LINGER_GAP_S:
            time.sleep(LINGER_S)

    def _take(self, entry: _Entry) -> int:
        batch = take_queued(entry.handle, entry.msg_type, TAKE_BATCH)
        if batch:
            try:
                entry.on_batch(batch)
            except Exception:
                logger.exception("ros2 link: a batch of samples failed")
        return len(batch)


def take_queued(handle: Any, msg_type: Any, most: int) -> list[Taken]:
    """The raw samples queued in the rcl subscription ``handle``, at most ``most``.

    What rclpy's executor does per sample (``Executor._take_subscription``: the
    handle's ``take_message``, raw, under the handle's context). Stops at the first
    empty take, or if the subscription was destroyed meanwhile.
    """
    from rclpy.exceptions import InvalidHandle  # noqa: PLC0415

    taken: list[Taken] = []
    try:
        with handle:
            for _ in range(most):
                sample = handle.take_message(msg_type, True)
                if sample is None:
                    break
                taken.append((sample[0], sample[1]))
    except InvalidHandle:
        pass
    return taken
