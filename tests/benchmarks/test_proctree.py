"""The thread-by-thread CPU reading behind Z2's "where the CPU goes" table.

A real child process spends known CPU time (``time.thread_time``, the clock
``schedstat`` also counts) in threads named as a server's are: its main thread,
a thread named as Zenoh's receive runtime names its threads, and a plain Python
thread; with ``--workers``, in a grandchild under a parent that only waits.
"""

from __future__ import annotations

import subprocess
import sys

from benchmarks.proctree import by_role, tree_cpu_ns, tree_threads

SPINNER = """
import ctypes, subprocess, sys, threading, time

spun, finish = threading.Semaphore(0), threading.Event()

def spin(name, seconds):
    if name:  # PR_SET_NAME: what the thread's comm shows
        ctypes.CDLL(None).prctl(15, name.encode(), 0, 0, 0)
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass
    spun.release()
    finish.wait()  # alive while read: a thread that ended is not counted

if sys.argv[1] == "parent":  # a --workers parent: it only waits for its worker
    worker = subprocess.Popen([sys.executable, "-c", sys.argv[2], "worker", sys.argv[2]])
    sys.exit(worker.wait())
print("ready", flush=True)
sys.stdin.readline()
threads = [
    threading.Thread(target=spin, args=("rx-0", 0.3)),
    threading.Thread(target=spin, args=(None, 0.2)),
]
for thread in threads:
    thread.start()
end = time.thread_time() + 0.1
while time.thread_time() < end:
    pass
for _ in threads:
    spun.acquire()
print("done", flush=True)
sys.stdin.readline()
finish.set()
"""


def run_spinner(kind: str) -> tuple[dict[str, float], int]:
    """Spin in a ``kind`` ("worker" or "parent") process tree; return the seconds and
    runs by role over the spin, and the tree's CPU ns (``tree_cpu_ns``) after it."""
    proc = subprocess.Popen(
        [sys.executable, "-c", SPINNER, kind, SPINNER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdin is not None and proc.stdout is not None
    try:
        assert proc.stdout.readline() == "ready\n"
        before = tree_threads(proc.pid)
        proc.stdin.write("go\n")
        proc.stdin.flush()
        assert proc.stdout.readline() == "done\n"
        after = tree_threads(proc.pid)
        total = tree_cpu_ns(proc.pid)
        spent = by_role(before, after, proc.pid)
        found = {k: v / 1e9 if k.endswith(" ns") else v for k, v in spent.items()}
    finally:
        proc.communicate(timeout=30)  # closes the pipes
    return found, total


def test_a_server_process_is_read_thread_by_thread_and_by_role() -> None:
    found, total = run_spinner("worker")
    assert found["zenoh rx ns"] >= 0.3
    assert found["other threads ns"] >= 0.2
    assert found["event loop ns"] >= 0.1
    assert "supervisor ns" not in found
    assert found["zenoh rx runs"] >= 1 and found["other threads runs"] >= 1
    assert total >= 0.6e9  # every thread of the tree, since it started


def test_a_workers_parent_counts_as_supervisor_and_its_worker_as_the_event_loop() -> None:
    found, total = run_spinner("parent")
    assert found["zenoh rx ns"] >= 0.3
    assert found["event loop ns"] >= 0.1  # the worker's main thread
    assert found["supervisor ns"] < 0.1  # the parent only waited
    assert total >= 0.6e9  # the worker's threads are the parent's tree's
