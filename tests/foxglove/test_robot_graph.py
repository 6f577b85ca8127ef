"""A robot served through a rosbridge client shows in Foxglove's connection graph (D47).

The robot's program is roslib (roslibjs in Node), the viewer the real Foxglove client
(@foxglove/ws-protocol), both in tests/js/foxglove_extras.mjs's ``robot`` scenario, against
a server with every helper it installs by default (rosapi, the client counts, the TF
republisher): the robot's publisher, subscriptions and service show with its node, rwt's
own helpers and nodes do not (docs/foxglove.md, "What a client sees").
"""

from __future__ import annotations

import subprocess

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_graph.nodes import CLIENT_NODE_PREFIX
from rwt_graph.types import TypeRegistry
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.integration.client_harness import JS_DIR

from . import extras

pytestmark = [pytest.mark.anyio, pytest.mark.node]


async def test_the_robots_publishers_subscribers_and_services_show_with_its_node(
    ros2_types: TypeRegistry,
) -> None:
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    server = RosbridgeServer(Graph(ros2_types), ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        with anyio.fail_after(60):
            done = await anyio.run_process(
                extras.command("robot", server.urls["websocket"]),
                cwd=JS_DIR,
                check=False,
                stdin=subprocess.DEVNULL,
            )
        tg.cancel_scope.cancel()
    assert done.returncode == 0, done.stderr.decode()
    got = extras.result_of(done.stdout.decode())
    assert set(got["published"]) == {"/chatter"}, got  # with a publisher: the robot's node
    [robot] = got["published"]["/chatter"]
    assert robot.startswith(CLIENT_NODE_PREFIX)
    # /tf: the robot's subscription only, not the TF republisher's (rwt's own)
    assert got["subscribed"] == {"/cmd_vel": [robot], "/tf": [robot]}
    assert got["services"] == {"/reset": [robot]}
    # none of rwt's own helpers, as channels or services (nor nodes: the ids above are all)
    assert got["channels"] == ["/chatter"] and got["advertisedServices"] == ["/reset"]
