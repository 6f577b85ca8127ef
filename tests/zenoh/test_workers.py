"""`rwt serve --workers 2`: two processes on one port and one graph, supervised by the parent.

roslibpy clients connect to the one announced port (the kernel spreads them over
the workers); a publisher's messages reach every subscriber whichever worker it
landed on. A worker killed with SIGKILL is restarted (logged); SIGTERM on the
parent stops every worker and the parent exits 0. Workers that are Zenoh clients of
a router share one graph with a server of another machine through it
(docs/scaling.md, "Workers on several machines").
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import anyio
import pytest

from rwt_transports.workers import reserve_port

from .processes import Process, python_client, rwt, serving, started
from .support import endpoint

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
    with anyio.fail_after(60):
        while parent.stderr().count(text) < count:
            await anyio.sleep(0.1)


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
