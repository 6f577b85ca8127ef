"""`rwt serve --workers 2`: a burst reaches a reading subscriber on the other worker whole.

A client publishes a burst as fast as its socket takes it, on one worker; a subscriber
on the same worker and one on the other, each a WebSocket client reading as fast as it
can in a process of its own, get every message, in order, and no warning. The
subscriber's worker is short of CPU meanwhile (stopped for 1-1.5 s at a time, running
150 ms between): its link hands the burst over faster than it writes to the
subscriber, which takes all it is sent. Before D61 that subscriber was judged not to
read and lost thousands of messages, in five runs of five on a loaded machine (only
``event=slow_consumer`` in the log said so, and a warning it had to ask for). When a
message is lost between the workers (here: the publisher is never held,
``--hold-budget 0``, and the link's queue for the other worker is small), the
subscriber is told, with a ``warning`` status (docs/scaling.md, D61).
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import signal
import threading
from collections.abc import AsyncIterator, Iterator

import anyio
import pytest

from tests.support.rawws import masked_text

from .processes import Process, python_client, rwt, started
from .test_workers import _listening, worker_serving, workers_of

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux /proc"),
]

STRING = "std_msgs/msg/String"
PAD = "x" * 1000  # about 1 KB a message: a burst of 30,000 is twice a send buffer
BURST = 30_000
# the other worker stopped 1 s, then runs 150 ms, is stopped 1.5 s, runs 150 ms, over again:
# a worker short of CPU, stalled past the 1 s in which a subscriber must show it reads
BUSY = ((1.0, 0.15), (1.5, 0.15))

SUBSCRIBER = """
import json, sys
from websockets.sync.client import connect
url, last = sys.argv[1], sys.argv[2]
with connect(url, max_size=None) as ws:
    ws.send(json.dumps({"op": "set_level", "level": "warning"}))
    ws.send(json.dumps({"op": "subscribe", "topic": "/burst", "type": "std_msgs/msg/String"}))
    print(ws.socket.getsockname()[1], flush=True)
    numbers, statuses = [], []
    while True:
        try:
            message = json.loads(ws.recv(timeout=float(sys.argv[3]) if numbers else 60))
        except TimeoutError:
            break
        if message["op"] == "publish":
            numbers.append(int(message["msg"]["data"].rsplit(" ", 1)[1]))
            if numbers[-1] == int(last):
                break
        elif message["op"] == "status" and message["level"] == "warning":
            statuses.append(message["msg"])
print(json.dumps({"numbers": numbers, "statuses": statuses}), flush=True)
"""


class Workers:
    """A two-worker server's parent, its URL and port, and its workers' pids."""

    def __init__(self, parent: Process, url: str) -> None:
        self.parent = parent
        self.url = url
        self.port = int(url.rsplit(":", 1)[1])
        self.pids = workers_of(parent.process.pid)


@contextlib.asynccontextmanager
async def two_workers(*extra: str) -> AsyncIterator[Workers]:
    """``rwt serve --workers 2`` with ``extra`` options, once both workers accept."""
    command = rwt("serve", "--port", "0", "--no-tf", "--workers", "2", *extra, cold=True)
    async with started(command, "parent") as parent:
        url = (await parent.line(within=60)).strip().removeprefix("listening on ")
        workers = Workers(parent, url)
        with anyio.fail_after(60):
            while not all(_listening(pid, workers.port) for pid in workers.pids):
                await anyio.sleep(0.1)
        yield workers


class Publisher:
    """A client publishing ``/burst`` over a plain socket, writing frames as fast as it can."""

    def __init__(self, workers: Workers) -> None:
        self.socket: anyio.abc.SocketStream | None = None
        self.workers = workers

    async def open(self) -> int:
        """Connect and advertise; the pid of the worker serving it."""
        sock = self.socket = await anyio.connect_tcp("127.0.0.1", self.workers.port)
        await sock.send(
            b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
        )
        head = b""
        while b"\r\n\r\n" not in head:
            head += await sock.receive()
        assert head.startswith(b"HTTP/1.1 101"), head
        advertise = {"op": "advertise", "topic": "/burst", "type": STRING}
        await sock.send(masked_text(json.dumps(advertise).encode()))
        local = sock.extra(anyio.abc.SocketAttribute.local_port)
        return worker_serving(local, self.workers.port, self.workers.pids)

    async def close(self) -> None:
        """Close the socket (left to the garbage collector, it is a ResourceWarning)."""
        if self.socket is not None:
            await anyio.aclose_forcefully(self.socket)
            self.socket = None

    async def burst(self, count: int) -> None:
        """Publish ``count`` messages, ``PAD`` and their number, as one write."""
        assert self.socket is not None
        frames = [
            masked_text(
                json.dumps(
                    {"op": "publish", "topic": "/burst", "msg": {"data": f"{PAD} {n}"}}
                ).encode()
            )
            for n in range(1, count + 1)
        ]
        await self.socket.send(b"".join(frames))


async def subscriber_on(
    workers: Workers, pid: int, stack: contextlib.AsyncExitStack, last: int, idle_s: float
) -> Process:
    """A subscriber process whose connection the worker ``pid`` serves (others are closed).

    It reads until message ``last`` (0: none) or, once messages came, ``idle_s`` seconds
    without one.
    """
    for _ in range(64):
        code = SUBSCRIBER.replace("sys.argv[1]", repr(workers.url))
        code = code.replace("sys.argv[2]", repr(str(last))).replace("sys.argv[3]", repr(idle_s))
        client = await stack.enter_async_context(python_client(code, "subscriber"))
        local = int((await client.line()).strip())
        if worker_serving(local, workers.port, workers.pids) == pid:
            return client
        client.kill()
    raise AssertionError("every subscriber landed on the other worker")


async def outcome(client: Process) -> tuple[list[int], list[str]]:
    """The numbers a subscriber got, in order, and the warnings it was told."""
    report = json.loads(await client.line(within=120))
    return report["numbers"], report["statuses"]


@contextlib.contextmanager
def kept_busy(pid: int, pattern: tuple[tuple[float, float], ...]) -> Iterator[None]:
    """Stop ``pid``, then continue and stop it in turn while the block runs.

    ``pattern``: (seconds stopped, seconds running) pairs, repeated: a worker short
    of CPU, whose subscribers read all the while.
    """
    done = threading.Event()

    def cycle() -> None:
        for stop_s, run_s in itertools.cycle(pattern):
            os.kill(pid, signal.SIGSTOP)
            stopped = done.wait(stop_s)
            os.kill(pid, signal.SIGCONT)
            if stopped or done.wait(run_s):
                return

    thread = threading.Thread(target=cycle, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()
        os.kill(pid, signal.SIGCONT)


async def test_a_burst_reaches_a_reading_subscriber_on_the_other_worker_whole() -> None:
    async with two_workers() as workers, contextlib.AsyncExitStack() as stack:
        publisher = Publisher(workers)
        stack.push_async_callback(publisher.close)
        home = await publisher.open()
        other = next(pid for pid in workers.pids if pid != home)
        local = await subscriber_on(workers, home, stack, BURST, 30.0)
        remote = await subscriber_on(workers, other, stack, BURST, 30.0)
        await anyio.sleep(1.0)  # the subscriptions known to both workers (over Zenoh)
        with kept_busy(other, BUSY):
            await publisher.burst(BURST)
            got = [await outcome(local), await outcome(remote)]
        log = workers.parent.whole_stderr()
    for side, (numbers, statuses) in zip(("local", "remote"), got, strict=True):
        assert statuses == [], (side, statuses)
        assert numbers == list(range(1, BURST + 1)), (side, len(numbers), log[-3000:])
    assert "event=slow_consumer" not in log


async def test_messages_lost_between_the_workers_are_told_to_the_subscriber() -> None:
    burst = BURST // 3  # 10 MB: far past the link's queue and Zenoh's
    small = ("--hold-budget", "0", "--zenoh-outbox-bytes", str(256 * 1024))
    async with two_workers(*small) as workers, contextlib.AsyncExitStack() as stack:
        publisher = Publisher(workers)
        stack.push_async_callback(publisher.close)
        home = await publisher.open()
        other = next(pid for pid in workers.pids if pid != home)
        remote = await subscriber_on(workers, other, stack, 0, 3.0)  # until 3 s without one
        await anyio.sleep(1.0)
        os.kill(other, signal.SIGSTOP)  # the other worker takes nothing: its link's queue fills
        try:
            await publisher.burst(burst)
            await anyio.sleep(1.0)  # the publishing worker puts what it can, drops the rest
        finally:
            os.kill(other, signal.SIGCONT)
        numbers, statuses = await outcome(remote)
        log = workers.parent.whole_stderr()
    assert 0 < len(numbers) < burst, (len(numbers), statuses, log[-3000:])
    assert numbers == sorted(numbers)  # what came, in order
    lost = [status for status in statuses if "on the way to this server" in status]
    assert lost, (statuses, log[-3000:])
    told = sum(int(status.split()[1]) for status in lost)
    if lost == statuses:  # it lost none itself (D24): each message it missed was told
        assert told == burst - len(numbers)
    else:  # and those it lost itself, "dropping the oldest topic messages"
        assert told < burst - len(numbers)
