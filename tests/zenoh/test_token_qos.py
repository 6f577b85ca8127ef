"""A client's QoS (protocol 2.1.0) in the Zenoh link's rmw_zenoh tokens, and what it delivers (D62).

Two graphs in one process, each linked by its own Zenoh session. A publisher of graph A
with a transient-local offer of depth 5 and a deadline: graph B's link reads A's
token as rmw_zenoh's nodes do (``wire.Entity.parse``) and finds that QoS, and a late
subscriber of B gets the last five messages from A's publication cache. A
subscription with a best-effort request is announced so.
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING

import pytest

import rwt
from rwt.types import Durability, Reliability
from rwt_graph.graph import Graph
from rwt_zenoh.link import ZenohLink, open_zenoh_link
from rwt_zenoh.wire import INFINITE, QoS
from rwt_zenoh.wire import Durability as WireDurability
from rwt_zenoh.wire import Reliability as WireReliability

from .support import endpoint, peer, until

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

pytestmark = pytest.mark.anyio

STRING = "std_msgs/msg/String"


@contextlib.asynccontextmanager
async def _linked() -> AsyncIterator[tuple[Graph, tuple[Graph, ZenohLink]]]:
    first = endpoint()
    async with contextlib.AsyncExitStack() as stack:
        a, b = Graph(), Graph()
        await stack.enter_async_context(open_zenoh_link(a, peer(listen=first)))
        link_b = await stack.enter_async_context(open_zenoh_link(b, peer(connect=(first,))))
        yield a, (b, link_b)


def _remote_qos(graph: Graph, link: ZenohLink, topic: str, role: str) -> list[QoS]:
    entry = graph.topics.get(topic)
    if entry is None:
        return []
    clients = entry.publishers if role == "publisher" else entry.subscribers
    found = [link._mirror.entity(client) for client in clients]  # what its link read
    return [e.detail.qos for e in found if e is not None and e.detail is not None]  # type: ignore[attr-defined]


async def test_a_publishers_token_says_its_offer_and_its_cache_keeps_that_many() -> None:
    offer = rwt.QosProfile(durability=Durability.TRANSIENT_LOCAL, depth=5, deadline_s=2.5)
    async with _linked() as (a, (b, link_b)):
        publisher = a.create_publisher("/kept", STRING, qos=offer, node="/mapper")
        for i in range(8):
            publisher.publish({"data": f"m{i}"})
        await until(lambda: bool(_remote_qos(b, link_b, "/kept", "publisher")), "A's token")
        [qos] = _remote_qos(b, link_b, "/kept", "publisher")
        assert qos.durability is WireDurability.TRANSIENT_LOCAL
        assert qos.reliability is WireReliability.RELIABLE
        assert qos.depth == 5
        assert qos.deadline == (2, 500_000_000)
        assert qos.lifespan == INFINITE  # the cache does not expire samples (docs/zenoh.md)
        got: list[object] = []
        b.create_subscription("/kept", lambda msg: got.append(msg["data"]), STRING)
        await until(lambda: len(got) >= 5, "the kept messages")
        assert got == ["m3", "m4", "m5", "m6", "m7"]


async def test_a_subscriptions_token_says_what_it_asked() -> None:
    asked = rwt.QosProfile(reliability=Reliability.BEST_EFFORT, depth=3)
    async with _linked() as (a, (b, link_b)):
        a.create_subscription("/scan", lambda msg: None, STRING, node="/viewer", qos=asked)
        await until(lambda: bool(_remote_qos(b, link_b, "/scan", "subscription")), "A's token")
        [qos] = _remote_qos(b, link_b, "/scan", "subscription")
        assert qos.reliability is WireReliability.BEST_EFFORT
        assert qos.durability is WireDurability.VOLATILE
        assert qos.depth == 3
