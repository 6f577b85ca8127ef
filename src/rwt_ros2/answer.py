"""What the graph owes one call or goal from ROS 2, awaited by an rclpy coroutine.

rclpy runs coroutine callbacks of services and action servers as tasks of its
executor; a task awaiting an ``Answer`` is resumed when the executor next wakes.
``Answer.set`` (any thread: the event loop, as a rule) completes it once and
wakes the executor, so the ROS 2 caller hears back without waiting for the
executor's spin timeout.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Generator

    from .node import RosNode

__all__ = ["Answer"]


class Answer:
    """One answer, set once (``set``) and awaited once in an executor coroutine.

    Attributes:
        ok: whether the graph answered (``value``: the response's CDR bytes) or
            the call failed (``value``: the reason, a string).
        value: see ``ok``.
    """

    def __init__(self, ros: RosNode) -> None:
        from rclpy.task import Future  # noqa: PLC0415

        self._ros = ros
        self._future: Any = Future()
        self._lock = threading.Lock()
        self.ok = False
        self.value: object = None

    @property
    def done(self) -> bool:
        """Whether it was set."""
        return bool(self._future.done())

    def set(self, ok: bool, value: object, *detail: object) -> bool:
        """Answer (any thread); False, and nothing changes, if it was answered already.

        ``detail``: what a subclass keeps besides (``_settle``).
        """
        with self._lock:
            if self._future.done():
                return False
            self._settle(ok, value, *detail)
            self._future.set_result(None)
        self._ros.executor.wake()
        return True

    def _settle(self, ok: bool, value: object, *detail: object) -> None:
        """Keep the answer (under the lock, before the awaiting task can resume)."""
        del detail
        self.ok, self.value = ok, value

    def __await__(self) -> Generator[None, None, None]:
        yield from self._future.__await__()
