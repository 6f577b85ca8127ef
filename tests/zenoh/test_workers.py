"""`rwt serve --workers 2`: two processes on one port and one graph, supervised by the parent.

roslibpy clients connect to the one announced port (the kernel spreads them over
the workers); a publisher's messages reach every subscriber whichever worker it
landed on. A worker killed with SIGKILL is restarted (logged); killed mid-burst,
it costs its own clients one bounded gap and the other worker's clients nothing.
SIGTERM on the parent stops every worker and the parent exits 0. Workers that are Zenoh clients of
a router share one graph with a server of another machine through it
(docs/scaling.md, "Workers on several machines").
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
from collections.abc import Awaitable
from pathlib import Path

import anyio
import pytest
from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake

from rwt_transports.workers.supervisor import reserve_port

from .processes import Process, python_client, rwt, serving, started
from .support import endpoint

INT32 = "std_msgs/msg/Int32"
FAN_OUT = """
import sys, time, threading
import roslibpy
urls = sys.argv[1].split()  # the publisher's first; the subscribers' in turn
def ros(url):
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    return roslibpy.Ros(host, int(port))
clients = [ros(urls[i % len(urls)]) for i in range(6)]
for ros in clients:
    ros.run(timeout=20)
got = [set() for _ in clients[1:]]
for inbox, ros in zip(got, clients[1:]):
    topic = roslibpy.Topic(ros, "/fan", "std_msgs/msg/Int32")
    topic.subscribe(lambda msg, inbox=inbox: inbox.add(msg["data"]))
pub = roslibpy.Topic(clients[0], "/fan", "std_msgs/msg/Int32")
pub.advertise()
deadline = time.monotonic() + 30
number = 0
while not all(got) and time.monotonic() < deadline:
    number += 1
    pub.publish(roslibpy.Message({"data": number}))
    time.sleep(0.1)
print("all" if all(got) else f"missing {[len(g) for g in got]}", flush=True)
"""


def workers_of(parent: int) -> list[int]:
    """The pids of ``parent``'s children (its workers)."""
    text = Path(f"/proc/{parent}/task/{parent}/children").read_text()
    return [int(pid) for pid in text.split()]


async def fan_out(*urls: str) -> None:
    """A publisher on ``urls[0]``, five subscribers over ``urls`` in turn: all get its messages."""
    code = FAN_OUT.replace("sys.argv[1]", repr(" ".join(urls)))
    async with python_client(code, "roslibpy") as client:
        assert (await client.line(within=60)).strip() == "all"


async def until_logged(parent: Process, text: str, count: int) -> None:
    with anyio.move_on_after(60):
        while parent.whole_stderr().count(text) < count:  # the workers log there too
            await anyio.sleep(0.1)
        return
    raise AssertionError(f"{text!r} logged fewer than {count} times:\n{parent.stderr()}")


@pytest.mark.anyio
@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux /proc")
async def test_two_workers_share_the_port_and_the_graph_and_are_supervised() -> None:
    async with started(
        rwt("serve", "--port", "0", "--no-tf", "--workers", "2", cold=True), "parent"
    ) as parent:
        first = (await parent.line(within=60)).strip()
        assert first.startswith("listening on ws://")
        url = first.removeprefix("listening on ")
        pid = parent.process.pid
        assert len(workers_of(pid)) == 2
        await fan_out(url)
        # a crashed worker is restarted and logged; the service goes on
        victim = workers_of(pid)[1]
        os.kill(victim, signal.SIGKILL)
        await until_logged(parent, "event=worker_exit", 1)
        await until_logged(parent, "event=worker_started", 3)
        assert victim not in workers_of(pid)
        assert len(workers_of(pid)) == 2
        await fan_out(url)
        # SIGTERM stops all of them; the listening line was printed once
        children = workers_of(pid)
        parent.process.send_signal(signal.SIGTERM)
        with anyio.fail_after(30):
            code = await parent.process.wait()
        assert code == 0, parent.stderr()
        for child in children:
            assert _gone(child)
        assert "listening on" not in await parent.rest()  # the line came once


@pytest.mark.anyio
@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux /proc")
async def test_workers_share_the_graph_with_another_machine_through_a_router() -> None:
    router_ep = endpoint()
    client_mode = ("--zenoh-mode", "client", "--zenoh-connect", router_ep)
    async with started(rwt("router", "--listen", router_ep), "router") as router:
        assert (await router.line()).strip() == f"router listening on {router_ep}"
        workers = rwt("serve", "--port", "0", "--no-tf", "--workers", "2", *client_mode, cold=True)
        async with (
            started(workers, "workers") as parent,
            serving("other machine", connect=(router_ep,), extra=client_mode[:2]) as (_, other),
        ):
            url = (await parent.line(within=60)).strip().removeprefix("listening on ")
            assert len(workers_of(parent.process.pid)) == 2
            await fan_out(url, other)  # the publisher on the workers' port
            await fan_out(other, url)  # the publisher on the other machine


def _gone(pid: int) -> bool:
    """Whether ``pid`` has exited (no process, or a zombie its parent has not reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    except OSError:
        return True


def test_reserved_ports_are_shared_by_reuse_port() -> None:
    with reserve_port("127.0.0.1", 0) as first:
        port = first.getsockname()[1]
        with reserve_port("127.0.0.1", port) as second:
            assert second.getsockname()[1] == port


def _socket_inodes(pid: int) -> set[str]:
    """The inodes of the sockets ``pid`` holds open."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        with contextlib.suppress(OSError):
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    return inodes


def _listening(pid: int, port: int) -> bool:
    """Whether ``pid`` holds a socket listening on ``port``."""
    inodes = _socket_inodes(pid)
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            listen = fields[3] == "0A"
            if listen and int(fields[1].rsplit(":", 1)[1], 16) == port and fields[9] in inodes:
                return True
    return False


def worker_serving(client_port: int, server_port: int, workers: list[int]) -> int:
    """The pid of the worker that holds the server side of the connection from ``client_port``."""
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            local, remote, inode = fields[1], fields[2], fields[9]
            if int(local.rsplit(":", 1)[1], 16) != server_port:
                continue
            if int(remote.rsplit(":", 1)[1], 16) != client_port:
                continue
            for pid in workers:
                if inode in _socket_inodes(pid):
                    return pid
    raise AssertionError(f"no worker holds the connection from port {client_port}")


class Reader:
    """A rosbridge subscriber over a plain WebSocket: every number it got, and its drops."""

    def __init__(self, url: str, sent: list[int]) -> None:
        self.url = url
        self.sent = sent  # how many the publisher has sent so far, in its one element
        self.got: list[int] = []
        self.reconnected_at: int | None = None  # len(got) when it was dropped
        self.subscribed_again_at = 0  # how many had been sent when it subscribed again
        self.ws: ClientConnection | None = None

    async def open(self) -> None:
        self.ws = await ws_connect(self.url)
        await self.ws.send(json.dumps({"op": "subscribe", "topic": "/burst", "type": INT32}))

    async def close(self) -> None:
        if self.ws is not None:
            await self.ws.close()

    async def read(self, resubscribed: anyio.Event) -> None:
        """Read until cancelled; when the worker dies, connect again (to any) and subscribe."""
        while True:
            assert self.ws is not None
            try:
                async for frame in self.ws:
                    message = json.loads(frame)
                    if message.get("op") == "publish":
                        self.got.append(message["msg"]["data"])
            except ConnectionClosed:
                pass
            # the server went away: a client connects again, as roslib's reconnecting ones do
            self.reconnected_at = len(self.got)
            with anyio.fail_after(30):
                while True:
                    try:
                        await self.open()
                        break
                    except (OSError, InvalidHandshake):  # e.g. taken into the dead one's queue
                        await anyio.sleep(0.05)
            self.subscribed_again_at = self.sent[0]
            resubscribed.set()


@pytest.mark.anyio
@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux /proc")
async def test_a_worker_killed_mid_burst_costs_its_own_clients_one_gap_and_the_others_nothing() -> (
    None
):
    """A publisher bursts to subscribers on both workers; the other worker is SIGKILLed.

    Subscribers on the publisher's worker get every number in order; those of the
    killed worker lose what was published from the kill until they had connected again
    (to the worker left, or the restarted one) and subscribed: one gap, in order on
    both sides of it (here about 5 of 600 at 2 ms apart). The parent logs the exit
    with the number of connections the worker held, and restarts it (docs/scaling.md).
    """
    async with started(
        rwt("serve", "--port", "0", "--no-tf", "--workers", "2", cold=True), "parent"
    ) as parent:
        url = (await parent.line(within=60)).strip().removeprefix("listening on ")
        port = int(url.rsplit(":", 1)[1])
        workers = workers_of(parent.process.pid)
        with anyio.fail_after(60):  # the port is announced when the first one listens
            while not all(_listening(pid, port) for pid in workers):
                await anyio.sleep(0.1)
        async with ws_connect(url) as publisher, contextlib.AsyncExitStack() as cleanup:
            await publisher.send(json.dumps({"op": "advertise", "topic": "/burst", "type": INT32}))
            home = worker_serving(publisher.local_address[1], port, workers)
            victim = next(pid for pid in workers if pid != home)
            progress = [0]
            readers: list[Reader] = []
            on: dict[int, list[Reader]] = {home: [], victim: []}
            while not (on[home] and on[victim]) and len(readers) < 64:
                reader = Reader(url, progress)
                readers.append(reader)
                cleanup.push_async_callback(reader.close)
                await reader.open()
                assert reader.ws is not None
                on[worker_serving(reader.ws.local_address[1], port, workers)].append(reader)
            assert on[home] and on[victim], "the kernel put every connection on one worker"
            await anyio.sleep(1.0)  # subscriptions known on both workers (over Zenoh)
            resubscribed = [anyio.Event() for _ in on[victim]]
            async with anyio.create_task_group() as readers_running:
                for reader in on[home]:
                    readers_running.start_soon(reader.read, anyio.Event())
                for reader, event in zip(on[victim], resubscribed, strict=True):
                    readers_running.start_soon(reader.read, event)
                sent = 0
                with anyio.fail_after(60):
                    # 300 before the kill, then on until every dropped reader is back and got 300
                    while sent < 300 or not all(
                        event.is_set() and len(r.got) >= (r.reconnected_at or 0) + 300
                        for r, event in zip(on[victim], resubscribed, strict=True)
                    ):
                        sent += 1
                        progress[0] = sent
                        msg = {"op": "publish", "topic": "/burst", "msg": {"data": sent}}
                        await publisher.send(json.dumps(msg))
                        if sent == 300:
                            os.kill(victim, signal.SIGKILL)
                        await anyio.sleep(0.002)
                    # the last ones in flight reach both workers' readers (the victim's over Zenoh)
                    while any(len(r.got) < sent for r in on[home]) or any(
                        r.got[-1:] != [sent] for r in on[victim]
                    ):
                        await anyio.sleep(0.05)
                readers_running.cancel_scope.cancel()
        for reader in on[home]:
            assert reader.got == list(range(1, sent + 1))
        for reader in on[victim]:
            cut = reader.reconnected_at
            assert cut is not None, "a reader of the killed worker was not dropped"
            before, after = reader.got[:cut], reader.got[cut:]
            assert before == list(range(1, len(before) + 1))  # nothing lost before the kill
            assert after == list(range(after[0], sent + 1))  # nor after it subscribed again
            assert after[0] > len(before)  # one gap, forward in time
            # and bounded: what was sent until it had connected and subscribed again (a few
            # more may pass before the worker has taken the subscription in)
            assert after[0] <= reader.subscribed_again_at + 50, (len(before), after[0])
        await until_logged(parent, "event=worker_exit", 1)
        await until_logged(parent, "event=worker_started", 3)
        # the parent says how many clients the crash dropped: those the kernel gave the victim
        exits = [line for line in parent.whole_stderr().splitlines() if "event=worker_exit" in line]
        assert f"connections={len(on[victim])} " in exits[0], exits


async def _round_trip(url: str) -> str:
    """Connect, ask the server for its time, and say how it went: ``ok`` or the failure."""
    try:
        async with ws_connect(url, open_timeout=30) as ws:
            request = {"op": "call_service", "service": "/rosapi/get_time", "id": "t"}
            await ws.send(json.dumps(request))
            with anyio.fail_after(30):
                answer = json.loads(await ws.recv())
            return "ok" if answer.get("result") is True else f"answer {answer}"
    except (OSError, InvalidHandshake, ConnectionClosed, TimeoutError) as exc:
        return f"{type(exc).__name__}: {exc}"


@pytest.mark.anyio
@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux /proc")
async def test_connections_waiting_for_a_killed_worker_are_served_by_another() -> None:
    """A worker hangs (SIGSTOP) while clients connect, then is killed: every client is served.

    The workers accept from the parent's listening socket: a connection waits in its
    one queue until a running worker takes it, so none waits on the hung worker nor is
    reset when it dies (with a socket of each worker's own, the kernel queued about
    half of them for the hung one and reset them at its death). Its replacement then
    serves as the others do.
    """
    command = rwt("serve", "--port", "0", "--no-tf", "--workers", "2", cold=True)
    async with started(command, "parent") as parent:
        url = (await parent.line(within=60)).strip().removeprefix("listening on ")
        port = int(url.rsplit(":", 1)[1])
        workers = workers_of(parent.process.pid)
        with anyio.fail_after(60):
            while not all(_listening(pid, port) for pid in workers):
                await anyio.sleep(0.1)
        victim = workers[0]
        os.kill(victim, signal.SIGSTOP)
        results: list[str] = []
        try:
            async with anyio.create_task_group() as clients:
                for _ in range(8):
                    clients.start_soon(lambda: _append(results, _round_trip(url)))
                await anyio.sleep(1.0)  # connected: served, or queued
                os.kill(victim, signal.SIGKILL)
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.kill(victim, signal.SIGKILL)
        assert results == ["ok"] * 8, results
        await until_logged(parent, "event=worker_started", 3)  # its replacement
        with anyio.fail_after(60):
            while len(replaced := workers_of(parent.process.pid)) < 2 or not all(
                _listening(pid, port) for pid in replaced
            ):
                await anyio.sleep(0.1)
        assert [await _round_trip(url) for _ in range(8)] == ["ok"] * 8


async def _append(results: list[str], outcome: Awaitable[str]) -> None:
    results.append(await outcome)
