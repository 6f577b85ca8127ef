"""The work a session leaves to its transport, to run off the event loop.

Two kinds, one queue each (``Jobs``): an input job (a ``png`` op to inflate) keeps
the frames' order, so the transport's reader waits for it before its next frame; a
background job (a Foxglove client's asset file, a ``png`` message to deflate) runs
while the reader goes on. The transport takes them, runs ``Job.run`` in a worker
thread and hands the outcome back to the session (``ServerSession.finish_job``);
without a transport that runs jobs (a bare session in a test) the caller does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["Job", "Jobs"]


class Job(Protocol):
    """Work a session leaves to its transport: run ``run()`` off the event loop.

    ``ready_at`` (monotonic seconds) is when it may start: the sender's own budget.
    """

    @property
    def ready_at(self) -> float:
        """Monotonic seconds before which the job must not run."""

    def run(self) -> object:
        """Do the work (in a worker thread); its result, or an exception, goes to ``finish_job``."""


class Jobs:
    """One session's jobs waiting for its transport: input jobs, then background ones.

    Attributes:
        transport_runs: the transport runs the jobs, off its event loop (the pump
            sets it before ``start``); False: the caller runs them at once (a
            protocol may then do the work inline: rosbridge's png).
        on_background: called when a background job was queued (the transport's
            wake-up; set by the pump).
        on_taken: called with each background job the transport takes (a protocol
            that counts what waits for it: rosbridge's png messages).
    """

    __slots__ = ("_background", "_input", "on_background", "on_taken", "transport_runs")

    def __init__(self) -> None:
        self._input: list[Job] = []  # the reader waits for each
        self._background: list[Job] = []  # the reader goes on meanwhile
        self.transport_runs = False
        self.on_background: Callable[[], None] | None = None
        self.on_taken: Callable[[Job], None] | None = None

    @property
    def waiting(self) -> bool:
        """Whether input jobs wait: the transport runs them before the next frame."""
        return bool(self._input)

    def add(self, job: Job, *, background: bool = False) -> None:
        """Queue ``job``; ``background``: the reader goes on meanwhile (``on_background``)."""
        if background:
            self._background.append(job)
            if self.on_background is not None:
                self.on_background()
        else:
            self._input.append(job)

    def take(self) -> Job | None:
        """The oldest input job (the reader waits for it before its next frame), or None."""
        return self._input.pop(0) if self._input else None

    def take_background(self) -> Job | None:
        """The oldest background job (``on_taken`` is told), or None."""
        if not self._background:
            return None
        job = self._background.pop(0)
        if self.on_taken is not None:
            self.on_taken(job)
        return job

    def withdraw(self, job: Job) -> bool:
        """Take back a waiting background job; False: the transport took it already."""
        try:
            self._background.remove(job)
        except ValueError:
            return False
        return True

    def clear(self) -> None:
        """Forget every waiting job (the connection closed)."""
        self._input.clear()
        self._background.clear()
