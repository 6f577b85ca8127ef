"""`rwt serve --workers 2 --placement topic`: a topic's connections are served by one worker.

roslibpy clients connect to the one port (the kernel spreads them over the workers) and
subscribe or advertise first: each connection ends up held by the worker that owns the
topic (docs/scaling.md, "Topic placement"; D57), the clients notice nothing, and every
message arrives once, in order. A client whose upgrade request, first message and a
service call come in one write gets its answer from the worker it was handed to: every
byte read before the hand-off went with it.
"""

from __future__ import annotations

import json
import os
import socket
from pathlib import Path

import anyio
import pytest

from tests.support.rawws import server_frame, upgrade_with

from .processes import python_client, rwt, started
from .test_workers import _listening, _socket_inodes, workers_of

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux /proc"),
]

COUNT = 200
SUBSCRIBERS = 9
CLIENTS = """
import json, sys, time
import roslibpy
host, port = sys.argv[1].removeprefix("ws://").rsplit(":", 1)
def ros():
    client = roslibpy.Ros(host, int(port))
    client.run(timeout=20)
    return client
inboxes = [[] for _ in range(SUBSCRIBERS)]
for inbox in inboxes:
    topic = roslibpy.Topic(ros(), "/placed", "std_msgs/msg/Int32")
    topic.subscribe(lambda msg, inbox=inbox: inbox.append(msg["data"]))
publisher = roslibpy.Topic(ros(), "/placed", "std_msgs/msg/Int32")
publisher.advertise()
time.sleep(1.5)  # every subscription made
for number in range(1, COUNT + 1):
    publisher.publish(roslibpy.Message({"data": number}))
    time.sleep(0.002)
deadline = time.monotonic() + 20
while time.monotonic() < deadline and any(len(inbox) < COUNT for inbox in inboxes):
    time.sleep(0.05)
print(json.dumps(inboxes), flush=True)
sys.stdin.read()  # the connections stay open until the test has looked at them
"""


def _held(port: int, workers: list[int]) -> dict[int, int]:
    """How many established connections on ``port`` each worker holds."""
    held = {pid: 0 for pid in workers}
    inodes = {pid: _socket_inodes(pid) for pid in workers}
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] != "01" or int(fields[1].rsplit(":", 1)[1], 16) != port:
                continue
            for pid in workers:
                if fields[9] in inodes[pid]:
                    held[pid] += 1
    return held


def _answer(port: int, ident: str) -> dict[str, object]:
    """The service call's answer to a client that sent everything in one write."""
    with socket.create_connection(("127.0.0.1", port), timeout=20) as sock:
        subscribe = {"op": "subscribe", "topic": "/placed", "type": "std_msgs/msg/Int32"}
        call = {"op": "call_service", "id": ident, "service": "/rosapi/topics", "args": {}}
        sock.sendall(upgrade_with(port, [subscribe, call]))
        data = b""
        while b"\r\n\r\n" not in data:
            data += _received(sock)
        head, _, data = data.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 101"), head
        while True:
            while (frame := server_frame(data)) is None:
                data += _received(sock)
            _, payload, data = frame
            assert not payload.startswith(b"HTTP/1.1"), "the upgrade response came twice"
            message = json.loads(payload)
            if message.get("op") == "service_response":
                return message


def _received(sock: socket.socket) -> bytes:
    more = sock.recv(65536)
    assert more, "the connection ended before the answer"
    return more


async def test_a_topics_connections_end_on_one_worker_and_get_every_message_in_order() -> None:
    async with started(
        rwt("serve", "--port", "0", "--no-tf", "--workers", "2", "--placement", "topic"), "parent"
    ) as parent:
        url = (await parent.line(within=60)).strip().removeprefix("listening on ")
        port = int(url.rsplit(":", 1)[1])
        workers = workers_of(parent.process.pid)
        with anyio.fail_after(60):  # the port is announced when the first one listens
            while not all(_listening(pid, port) for pid in workers):
                await anyio.sleep(0.1)
        code = CLIENTS.replace("sys.argv[1]", repr(url))
        code = code.replace("SUBSCRIBERS", str(SUBSCRIBERS)).replace("COUNT", str(COUNT))
        async with python_client(code, "roslibpy") as clients:
            inboxes = json.loads(await clients.line(within=90))
            assert inboxes == [list(range(1, COUNT + 1))] * SUBSCRIBERS
            held = _held(port, workers)
            assert sorted(held.values()) == [0, SUBSCRIBERS + 1], held
        # the first message and what came with it (a service call) go with the connection
        for ident in (f"call-{n}" for n in range(8)):
            answer = await anyio.to_thread.run_sync(_answer, port, ident)
            assert answer["id"] == ident
            assert answer["result"] is True
            assert "/placed" in answer["values"]["topics"]  # type: ignore[index]
        placed = parent.whole_stderr().count("event=placed")
        assert placed >= 1, parent.stderr()  # some landed on the other worker, and moved
