"""CPU time of a process and its descendants, thread by thread, from ``/proc`` (Linux).

``/proc/<pid>/task/<tid>/schedstat`` gives each thread's time on a CPU (ns) and
how many times it was scheduled in to run. The second is the figure that says
what a message crossing ``--workers`` costs beyond its own work: every hand-over
between threads (the event loop to the Zenoh sender, Zenoh's receive thread to
the event loop) wakes a sleeping thread, and a wake-up on a virtual machine costs
tens of microseconds of CPU (benchmarks/JOURNAL.md, "Where a message crossing
workers spends its CPU").
"""

from __future__ import annotations

import contextlib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ThreadTime", "by_role", "tree_cpu_ns", "tree_threads"]

ZENOH_RUNTIMES = ("rx", "tx", "acc", "net", "app")
"""Names (before ``-N``) of Zenoh's runtime threads: receive, transmit, accept,
network and application (zenoh-runtime's ``ZRuntime``)."""


@dataclass(frozen=True)
class ThreadTime:
    """One thread: its process ``pid``, ``tid``, ``name`` (``comm``), ``cpu_ns`` on a
    CPU so far and ``runs``, the times it was scheduled in so far."""

    pid: int
    tid: int
    name: str
    cpu_ns: int
    runs: int


def tree_threads(pid: int) -> list[ThreadTime]:
    """Every live thread of ``pid`` and of its live descendants; threads that end
    while read are left out."""
    found: list[ThreadTime] = []
    pending = [pid]
    while pending:
        current = pending.pop()
        tasks: list[Path] = []
        with contextlib.suppress(OSError):  # the process ended
            tasks = list(Path(f"/proc/{current}/task").iterdir())
        for task in tasks:
            with contextlib.suppress(OSError, ValueError, IndexError):  # the thread ended
                fields = (task / "schedstat").read_text().split()
                name = (task / "comm").read_text().strip()
                found.append(
                    ThreadTime(current, int(task.name), name, int(fields[0]), int(fields[2]))
                )
                pending += [int(c) for c in (task / "children").read_text().split()]
    return found


def tree_cpu_ns(pid: int) -> int:
    """CPU ns of every thread of ``pid`` and its live descendants."""
    return sum(thread.cpu_ns for thread in tree_threads(pid))


def role(thread: ThreadTime, root: int, parent_only: bool) -> str:
    """What a thread of the server rooted at ``root`` does, by its name and place.

    ``parent_only``: the root process serves nothing (``--workers``: it only
    supervises its workers).
    """
    if thread.tid == thread.pid:
        return "supervisor" if thread.pid == root and parent_only else "event loop"
    runtime = thread.name.rsplit("-", 1)[0]
    if runtime in ZENOH_RUNTIMES:
        return f"zenoh {runtime}"
    return "other threads"  # Python's: the Zenoh outbox's sender, Zenoh's callback thread


def by_role(before: list[ThreadTime], after: list[ThreadTime], root: int) -> Counter[str]:
    """CPU ns and runs between two readings of ``root``'s tree, summed by ``role``.

    Keys are ``"<role> ns"`` and ``"<role> runs"``; a thread started meanwhile
    counts from zero.
    """
    start = {(t.pid, t.tid): t for t in before}
    parent_only = any(t.pid != root for t in after)
    found: Counter[str] = Counter()
    for thread in after:
        earlier = start.get((thread.pid, thread.tid))
        name = role(thread, root, parent_only)
        found[f"{name} ns"] += thread.cpu_ns - (earlier.cpu_ns if earlier else 0)
        found[f"{name} runs"] += thread.runs - (earlier.runs if earlier else 0)
    return found
