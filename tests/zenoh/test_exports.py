"""The Zenoh link shares the graph's local entities as its change feed announces them.

The link's outward side follows the feed (rwt_graph.exports) rather than walking
the graph each sweep: with its periodic sweep an hour away, every token a local
entity gets or loses on the network below comes from the feed alone.
"""

from __future__ import annotations

from typing import Any

import anyio
import pytest

import zenoh
from rwt_graph.graph import Graph
from rwt_zenoh.config import make_config
from rwt_zenoh.link import ZenohLink
from rwt_zenoh.wire import EntityKind

from .support import WAIT_S, endpoint, peer
from .test_ros2_peers import bare_session, tokens_of

pytestmark = pytest.mark.anyio

STRING = "std_msgs/msg/String"
TRIGGER = "std_srvs/srv/Trigger"
SHARED = {
    (EntityKind.PUBLISHER, "/odom"),
    (EntityKind.SUBSCRIPTION, "/cmd"),
    (EntityKind.SERVICE, "/reset"),
}


async def shared_by(watcher: Any, node: str) -> set[tuple[EntityKind, str]]:
    """The topics and services ``node``'s tokens name on the network now."""
    return {
        (entity.kind, entity.topic.name)
        for entity in await tokens_of(watcher)
        if entity.node == node and entity.topic is not None
    }


async def test_local_entities_get_and_lose_their_tokens_without_a_sweep() -> None:
    graph = Graph()
    listen = endpoint()
    with bare_session(listen=listen) as watcher:
        session = zenoh.open(make_config(peer(connect=(listen,))))
        try:
            link = ZenohLink(graph, session, sweep_s=3600.0)  # one sweep, as it starts
            async with anyio.create_task_group() as tg:
                await tg.start(link.run)
                handles: list[Any] = [
                    graph.create_publisher("/odom", STRING, node="/robot"),
                    graph.create_subscription("/cmd", lambda msg: None, STRING, node="/robot"),
                    graph.create_service("/reset", TRIGGER, lambda request: {}, node="/robot"),
                ]
                with anyio.fail_after(WAIT_S):
                    while await shared_by(watcher, "robot") != SHARED:
                        await anyio.sleep(0.05)
                for handle in handles:
                    handle.close()
                with anyio.fail_after(WAIT_S):
                    while await shared_by(watcher, "robot"):
                        await anyio.sleep(0.05)
                tg.cancel_scope.cancel()
        finally:
            session.close()
