"""The MCP tools take protocol 2.1.0's ``qos`` (D62-D63), with the official MCP SDK's client.

``publish`` with ``qos`` advertises the topic with it: a transient-local one keeps its
message for a later ``echo``, which asks transient local; an ``echo`` asking volatile
gets nothing kept; a bad ``qos`` is a tool error naming the field. ``publish_for``
takes one too; a topic resource asks for the topic's latest message. Over ``rwt serve
--mcp`` (the session calls the graph) and ``rwt mcp`` (a rosbridge client in front).
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import anyio
import pytest

import rwt
from rwt import RosbridgeServer, ServerConfig
from rwt.types import Durability
from rwt_graph.graph import Graph
from rwt_transports.http.mcp_options import McpOptions
from tests.agents.test_rwt_mcp import rwt_mcp, rwt_serve_mcp

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = pytest.mark.anyio

KEPT = {"durability": "transient_local", "depth": 2}


@pytest.mark.parametrize("way", ["http", "stdio"])
async def test_publish_and_echo_take_qos(way: str, tmp_path: Path) -> None:
    graph = Graph()
    graph.create_subscription("/keep", lambda msg: None, "std_msgs/msg/String")  # holds /keep
    server = RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions()))
    with anyio.fail_after(120):
        async with anyio.create_task_group() as tg:
            url = await tg.start(server.serve)
            opened = rwt_serve_mcp(url) if way == "http" else rwt_mcp(url, tmp_path)
            async with opened as agent:
                bad = await agent.result(
                    "publish",
                    topic="/keep",
                    type="std_msgs/msg/String",
                    msg={"data": "x"},
                    qos={"durability": "forever"},
                )
                assert bad.is_error and "qos.durability" in bad.content[0].text  # type: ignore[union-attr]
                for text in ("a", "b", "c"):
                    await agent.call(
                        "publish",
                        topic="/keep",
                        type="std_msgs/msg/String",
                        msg={"data": text},
                        qos=KEPT,
                    )
                kept = await agent.result(
                    "echo",
                    topic="/keep",
                    count=2,
                    timeout_s=5,
                    qos={"durability": "transient_local"},
                )
                texts = [json.loads(c.text) for c in kept.content[1:]]  # type: ignore[union-attr]
                assert [m["data"] for m in texts] == ["b", "c"]
                none = await agent.result(
                    "echo", topic="/keep", count=1, timeout_s=0.5, qos={"durability": "volatile"}
                )
                assert json.loads(none.content[0].text)["received"] == 0  # type: ignore[union-attr]
            tg.cancel_scope.cancel()


@pytest.mark.parametrize("way", ["http", "stdio"])
async def test_publish_for_takes_qos_and_a_resource_reads_the_newest_kept(
    way: str, tmp_path: Path
) -> None:
    # publish_for advertises with its qos: a transient-local one keeps its final message
    # (the stop) for a later subscriber; a topic resource reads the newest message a
    # transient-local topic keeps, not the oldest (it asks depth 1, best_available)
    graph = Graph()
    graph.create_subscription("/cmd", lambda msg: None, "std_msgs/msg/String")  # holds /cmd
    kept = rwt.QosProfile(durability=Durability.TRANSIENT_LOCAL, depth=3)
    publisher = graph.create_publisher("/map", "std_msgs/msg/String", qos=kept)
    for text in ("a", "b", "c"):
        publisher.publish({"data": text})
    server = RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0, mcp=McpOptions()))
    with anyio.fail_after(120):
        async with anyio.create_task_group() as tg:
            url = await tg.start(server.serve)
            opened = rwt_serve_mcp(url) if way == "http" else rwt_mcp(url, tmp_path)
            async with opened as agent:
                read = await agent.session.read_resource("ros://topics/map")
                assert json.loads(read.contents[0].text)["data"] == "c"  # type: ignore[union-attr]
                sent = await agent.call(
                    "publish_for",
                    topic="/cmd",
                    type="std_msgs/msg/String",
                    msg={"data": "go"},
                    rate_hz=20,
                    duration_s=0.2,
                    final_msg={"data": "stop"},
                    qos={"durability": "transient_local", "depth": 1},
                )
                assert sent["final_sent"] is True
                late = await agent.result(
                    "echo",
                    topic="/cmd",
                    count=1,
                    timeout_s=5,
                    qos={"durability": "transient_local"},
                )
                [stop] = [json.loads(c.text) for c in late.content[1:]]  # type: ignore[union-attr]
                assert stop == {"data": "stop"}
            tg.cancel_scope.cancel()
