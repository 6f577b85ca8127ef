"""A rosbridge client's ``qos`` (protocol 2.1.0) reaches rclpy nodes through `rwt serve --ros2`.

The link creates its rclpy publisher and subscription of a topic with the QoS the
topic's first registration fixed (D62; docs/ros2.md, "QoS"): an rclpy node sees it
with ``get_publishers_info_by_topic`` and ``get_subscriptions_info_by_topic``
(``peer.py qos_info``), and a late transient-local rclpy subscription of depth 5 gets
the last five messages the client published through the link's publisher. A subscriber
that comes and goes with a ``qos`` beside one that asked none (an MCP agent reading and
watching a topic resource beside a rosbridge subscriber) leaves the subscription they share as it
is: made once, and the rosbridge subscriber misses nothing.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import anyio
import pytest
from websockets.asyncio.client import connect

from tests.agents.test_rwt_mcp import rwt_serve_mcp

from .support import Peer, serve_ros2, skip_without_rclpy

if TYPE_CHECKING:
    from pathlib import Path

    from tests.integration.client_harness import ServerProcess

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

STRING = "std_msgs/msg/String"
SECOND_NS = 1_000_000_000


async def _until(peer: Peer, key: str) -> list[dict[str, Any]]:
    """The first non-empty ``key`` endpoints the ``qos_info`` peer reports."""
    while True:
        seen = await anyio.to_thread.run_sync(peer.next)
        if seen[key]:
            return seen[key]  # type: ignore[no-any-return]


async def test_an_rclpy_node_sees_the_qos_the_client_asked(
    server: ServerProcess, ros_env: Path
) -> None:
    advertised = {"durability": "transient_local", "depth": 5, "deadline": 2.5, "lifespan": 4}
    subscribed = {
        "reliability": "best_effort",
        "depth": 3,
        "deadline": {"secs": 1, "nsecs": 500_000_000},
    }
    async with connect(f"ws://127.0.0.1:{server.port}", ping_interval=None) as ws:
        with (
            Peer("qos_info", "/qos_adv", ros_env) as pubs,
            Peer("qos_info", "/qos_sub", ros_env, node="peer_qos_sub") as subs,
        ):
            await ws.send(
                json.dumps(
                    {"op": "advertise", "topic": "/qos_adv", "type": STRING, "qos": advertised}
                )
            )
            await ws.send(
                json.dumps(
                    {"op": "subscribe", "topic": "/qos_sub", "type": STRING, "qos": subscribed}
                )
            )
            [publisher] = await _until(pubs, "publishers")
            [subscription] = await _until(subs, "subscriptions")
    assert publisher["reliability"] == "RELIABLE"
    assert publisher["durability"] == "TRANSIENT_LOCAL"
    assert publisher["deadline_ns"] == 5 * SECOND_NS // 2
    assert publisher["lifespan_ns"] == 4 * SECOND_NS
    assert subscription["reliability"] == "BEST_EFFORT"
    assert subscription["durability"] == "VOLATILE"
    assert subscription["deadline_ns"] == 3 * SECOND_NS // 2


async def test_a_late_transient_local_rclpy_subscription_gets_the_last_five(
    server: ServerProcess, ros_env: Path
) -> None:
    qos = {"durability": "transient_local", "depth": 5}
    async with connect(f"ws://127.0.0.1:{server.port}", ping_interval=None) as ws:
        with (
            Peer("qos_info", "/qos_kept", ros_env, node="peer_qos_kept") as info,
            # durable itself, so it hears m7 however late it matches the link's publisher
            Peer("durable_listen", "/qos_kept", ros_env, node="peer_qos_live") as live,
        ):
            await ws.send(
                json.dumps({"op": "advertise", "topic": "/qos_kept", "type": STRING, "qos": qos})
            )
            await _until(info, "publishers")  # the link's rclpy publisher is there
            for i in range(8):
                publish = {"op": "publish", "topic": "/qos_kept", "msg": {"data": f"m{i}"}}
                await ws.send(json.dumps(publish))
            while (await anyio.to_thread.run_sync(live.next))["heard"] != "m7":
                pass  # all eight went out through the link's publisher
        with Peer("durable_listen", "/qos_kept", ros_env) as late:
            heard = [(await anyio.to_thread.run_sync(late.next))["heard"] for _ in range(5)]
    assert heard == ["m3", "m4", "m5", "m6", "m7"]


def _reports(peer: Peer) -> list[dict[str, Any]]:
    """What the ``qos_info`` peer reported since it was last read (a report is a change)."""
    reports = []
    while True:
        try:
            reports.append(peer.next(1.0))
        except AssertionError:  # nothing more within the second
            return reports


async def test_a_topic_resource_read_leaves_the_shared_subscription_alone(ros_env: Path) -> None:
    server = serve_ros2(ros_env, "--mcp", "--ros2-node-name", "rwt_shared")
    heard: list[int] = []
    try:
        with (
            Peer("talk", "/shared", ros_env),
            Peer("qos_info", "/shared", ros_env, node="peer_shared_info") as info,
        ):
            url = f"ws://127.0.0.1:{server.port}"
            async with connect(url, ping_interval=None) as ws:
                await ws.send(json.dumps({"op": "subscribe", "topic": "/shared", "type": STRING}))
                [made] = await _until(info, "subscriptions")  # the link's, for the client

                async def listen() -> None:
                    async for text in ws:
                        op = json.loads(text)
                        if op.get("op") == "publish":
                            heard.append(int(op["msg"]["data"]))

                with anyio.fail_after(60):
                    async with anyio.create_task_group() as tg:
                        tg.start_soon(listen)
                        async with rwt_serve_mcp(url) as agent:  # each asks the latest (D63)
                            read = await agent.session.read_resource("ros://topics/shared")
                            assert int(json.loads(read.contents[0].text)["data"]) >= 0  # type: ignore[union-attr]
                            await agent.session.subscribe_resource("ros://topics/shared")
                            await anyio.sleep(1.0)  # watched: updates come, at most 2 a second
                            await agent.session.unsubscribe_resource("ros://topics/shared")
                        await anyio.sleep(1.0)  # the link's sweeps after the last read
                        tg.cancel_scope.cancel()
                later = await anyio.to_thread.run_sync(_reports, info)  # still subscribed
    finally:
        server.stop()
    gids = [[s["gid"] for s in report["subscriptions"]] for report in later]  # (node names
    assert all(seen == [made["gid"]] for seen in gids), (made, later)  # come late): made once
    assert made["reliability"] == "RELIABLE"  # the link's own rules (Fast DDS reports no depth)
    assert len(heard) > 20
    assert heard == list(range(heard[0], heard[0] + len(heard)))  # nothing missed
