"""`rwt serve --zenoh` against a Zenoh peer that floods it, as a real user's server meets one.

A bare Zenoh session (loopback only, multicast off) stands for a hostile peer or an
honest camera on rmw_zenoh publishing faster than the server decodes: it floods
1 MB samples on a topic a WebSocket client subscribes to, and the server's RSS
(read from /proc) stays bounded while a bystander connects and is answered; it
declares 20,000 publisher tokens and withdraws them at once, and a WebSocket
client connected meanwhile stays connected and is answered (docs/limits.md,
"Zenoh peers: what they are trusted with").
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any, cast

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect

import zenoh
from rwt_graph.graph import Graph
from rwt_zenoh.config import make_config
from rwt_zenoh.payload import encode_message, type_hash
from rwt_zenoh.wire import (
    VOLATILE_QOS,
    Entity,
    EntityKind,
    Topic,
    dds_type_name,
    topic_keyexpr,
    zid_text,
)

from .processes import serving
from .support import endpoint, peer

pytestmark = [pytest.mark.anyio, pytest.mark.timeout(120)]

STRING = "std_msgs/msg/String"
MiB = 1024 * 1024
RSS_BOUND = 500 * MiB  # generous: the server starts near 80 MB and queues 64 MB at most
FLOOD_SAMPLES = 2000  # 2 GB sent, far past any bound
TOKENS = 5_000  # Zenoh's own declare_token grows with the count: 20,000 took minutes


def rss(pid: int) -> int:
    """The resident set of process ``pid``, bytes (VmRSS in /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError(f"no VmRSS for {pid}")


REGISTRY = Graph().registry
STRING_HASH = type_hash(REGISTRY, STRING)


def string_key(name: str) -> str:
    return topic_keyexpr(0, name, dds_type_name(STRING), STRING_HASH)


def string_sample(size: int) -> bytes:
    return bytes(encode_message(REGISTRY, REGISTRY.message(STRING), {"data": "x" * size}))


async def call(ws: ClientConnection, service: str, tag: str) -> dict[str, Any]:
    """Call ``service`` with no arguments; its ``service_response`` (other frames skipped)."""
    await ws.send(json.dumps({"op": "call_service", "service": service, "id": tag}))
    while True:
        reply = json.loads(await ws.recv())
        if reply.get("id") == tag and reply.get("op") == "service_response":
            return dict(reply)


async def subscribe(ws: ClientConnection, topic: str) -> None:
    await ws.send(
        json.dumps({"op": "subscribe", "topic": topic, "type": STRING, "throttle_rate": 100})
    )
    await call(ws, "/rosapi/topics", "subscribed")  # in order: the subscription is in place


class Flood:
    """A bare Zenoh session putting 1 MB samples on a topic, in a thread, watching a pid's RSS."""

    def __init__(self, session: zenoh.Session, topic: str, pid: int) -> None:
        self.publisher = session.declare_publisher(string_key(topic))
        self.payload = string_sample(MiB)
        self.pid = pid
        self.sent = 0
        self.max_rss = 0
        self.stop = threading.Event()

    def run(self) -> None:
        while self.sent < FLOOD_SAMPLES and not self.stop.is_set():
            self.publisher.put(self.payload)
            self.sent += 1
            if self.sent % 20 == 0:
                self.max_rss = max(self.max_rss, rss(self.pid))
                if self.max_rss > RSS_BOUND:
                    return  # it grows without bound: no need to take the machine down


async def test_a_flood_of_1mb_samples_keeps_rss_bounded_and_a_bystander_is_served() -> None:
    ep = endpoint()
    async with (
        serving("A", listen=ep, cold=True) as (server, url),  # its RSS is read
        connect(url, max_size=None) as subscriber,
    ):
        await subscribe(subscriber, "/flood")
        received = 0

        async def read() -> None:
            nonlocal received
            async for frame in subscriber:
                received += json.loads(frame).get("topic") == "/flood"

        session = await anyio.to_thread.run_sync(zenoh.open, make_config(peer(connect=(ep,))))
        try:
            flood = Flood(session, "/flood", server.process.pid)
            async with anyio.create_task_group() as tg:
                tg.start_soon(read)
                tg.start_soon(anyio.to_thread.run_sync, flood.run)
                while flood.sent < FLOOD_SAMPLES // 4 and flood.max_rss <= RSS_BOUND:
                    await anyio.sleep(0.05)
                async with connect(url) as bystander:  # a handshake during the flood
                    topics = await call(bystander, "/rosapi/topics", "bystander")
                flood.stop.set()
                # the flood's route may have come up late on a loaded machine: once it is
                # over, samples still reach the subscriber (the server took no harm)
                with anyio.move_on_after(20):
                    while not received:
                        await anyio.to_thread.run_sync(flood.publisher.put, flood.payload)
                        await anyio.sleep(0.2)
                tg.cancel_scope.cancel()
        finally:
            flood.stop.set()
            await anyio.to_thread.run_sync(session.close)
        assert flood.max_rss <= RSS_BOUND, f"RSS reached {flood.max_rss // MiB} MB"
        assert topics["result"] is True
        assert "/flood" in topics["values"]["topics"]
        assert received >= 1  # the flood did reach the server and its subscriber


def publisher_token(zid: str, n: int) -> str:
    topic = Topic(f"/many/t{n}", dds_type_name(STRING), STRING_HASH, VOLATILE_QOS)
    return Entity(0, zid, 1, n + 2, EntityKind.PUBLISHER, "/", "crowd", topic=topic).token()


async def test_five_thousand_tokens_withdrawn_at_once_leave_a_client_connected_and_served() -> None:
    ep = endpoint()
    async with serving("A", listen=ep) as (_, url), connect(url) as client:
        session = await anyio.to_thread.run_sync(zenoh.open, make_config(peer(connect=(ep,))))
        try:
            zid = zid_text(bytes(cast("Any", session.info.zid())))
            liveliness = session.liveliness()
            node = Entity(0, zid, 1, 1, EntityKind.NODE, "/", "crowd").token()
            tokens = [liveliness.declare_token(node)]
            tokens += [liveliness.declare_token(publisher_token(zid, n)) for n in range(TOKENS)]
            last = f"/many/t{TOKENS - 1}"
            while last not in (await call(client, "/rosapi/topics", "all"))["values"]["topics"]:
                await anyio.sleep(0.5)
        finally:
            await anyio.to_thread.run_sync(session.close)  # every token goes at once
        # the client is still connected and the server answers it once the tokens are gone
        while any(
            name.startswith("/many/")
            for name in (await call(client, "/rosapi/topics", "gone"))["values"]["topics"]
        ):
            await anyio.sleep(0.2)
        async with connect(url) as late:
            nodes = await call(late, "/rosapi/nodes", "late")
        assert "/crowd" not in nodes["values"]["nodes"]
