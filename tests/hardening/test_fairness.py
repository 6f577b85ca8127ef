"""Reader fairness: a flood of tiny frames on one connection does not hold the others up.

One TCP client sends 100,000 tiny frames (``1 1 1 ...``, each an invalid op
answered by an error status) in one write, then a publish on ``/fair``; right
after, a bystander publishes on ``/fair`` too and is subscribed to it. Without
a bound on the work a reader does per loop turn, the server handled the whole
flood (which arrives in one read) before the bystander's frame, so the flood's
publish reached the bystander first. Now a reader yields to the loop every
``READ_SLICE_FRAMES`` frames: the bystander's own publish comes back while the
flood is still being handled. Every flood frame is still answered.
"""

from __future__ import annotations

import json

import anyio
import anyio.to_thread
import pytest

from tests.hardening.peers import TcpPeer, settle
from tests.support.clients import Harness

pytestmark = pytest.mark.anyio

FLOOD = 100_000
TOPIC = "/fair"


def count_statuses(peer: TcpPeer, count: int) -> int:
    """Read the flooder's answers until ``count`` error statuses came; return how many."""
    seen = 0
    while seen < count:
        message = peer.receive()
        if message.get("op") == "status" and message.get("level") == "error":
            seen += 1
    return seen


def publishes(peer: TcpPeer, count: int) -> list[str]:
    """The data of the next ``count`` messages published on ``TOPIC``, in arrival order."""
    data: list[str] = []
    while len(data) < count:
        message = peer.receive()
        if message.get("op") == "publish" and message.get("topic") == TOPIC:
            data.append(message["msg"]["data"])
    return data


def publish(text: str) -> bytes:
    return json.dumps({"op": "publish", "topic": TOPIC, "msg": {"data": text}}).encode()


async def test_a_flood_of_tiny_frames_does_not_starve_a_bystander(harness: Harness) -> None:
    port = harness.port("tcp")
    bystander = await anyio.to_thread.run_sync(TcpPeer, port)
    flooder = await anyio.to_thread.run_sync(TcpPeer, port)
    for peer in (bystander, flooder):
        peer.send({"op": "advertise", "topic": TOPIC, "type": "std_msgs/String"})
    bystander.send({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String"})
    await anyio.to_thread.run_sync(settle, bystander, "b")
    await anyio.to_thread.run_sync(settle, flooder, "f")
    answered: list[int] = []
    order: list[str] = []

    def flood_then_bystander() -> None:
        flooder.send_raw(b"1 " * FLOOD + publish("flood end"))
        bystander.send_raw(publish("bystander"))

    async def drain_flooder() -> None:
        answered.append(await anyio.to_thread.run_sync(count_statuses, flooder, FLOOD))

    async def read_bystander() -> None:
        order.extend(await anyio.to_thread.run_sync(publishes, bystander, 2))

    with anyio.fail_after(120):
        async with anyio.create_task_group() as tg:
            tg.start_soon(drain_flooder)
            tg.start_soon(read_bystander)
            await anyio.to_thread.run_sync(flood_then_bystander)
    # The bystander was served while the flood was still being handled.
    assert order == ["bystander", "flood end"]
    assert answered == [FLOOD]  # and every flood frame was answered
    # The server is up and serves a new client.
    late = await anyio.to_thread.run_sync(TcpPeer, port)
    await anyio.to_thread.run_sync(settle, late, "late")
    for peer in (bystander, flooder, late):
        peer.close()
