"""Connections that say nothing and hold nothing are closed (docs/limits.md, per server).

Before, a WebSocket or TCP connection could be opened and left silent for ever,
holding its slot. Now one that sends nothing and holds nothing for
``--idle-timeout`` is closed; one that holds a subscription, even without
sending anything more (roslibpy or roslib that subscribe and listen), stays.
"""

from __future__ import annotations

import anyio
import pytest
from websockets.exceptions import ConnectionClosed

from rwt_graph.graph import Graph
from rwt_transports.server import ServerConfig
from tests.support.clients import Client, is_op, running_server
from tests.support.realclients import node_missing, run_node, run_python

pytestmark = pytest.mark.anyio

TIMEOUT_S = 30
IDLE_S = 0.3
LISTEN_S = 4 * IDLE_S  # a listener hears messages published this long after it subscribed


async def closed(client: Client) -> bool:
    """Read until the server ends the connection."""
    try:
        while True:
            await client.receive()
    except (ConnectionClosed, anyio.EndOfStream, anyio.BrokenResourceError):
        return True


async def listen(listener: Client, seconds: float) -> None:
    """Read until a ``/chatter`` message arrives ``seconds`` from now: still served.

    The listener sends nothing meanwhile; it reads all along, as roslibpy does, so
    its client's queue never fills (a full one stops reading the socket, and its
    close then waits for a close frame behind the unread messages).
    """
    until = anyio.current_time() + seconds
    while True:
        message = await listener.receive()
        if is_op("publish", topic="/chatter")(message) and anyio.current_time() > until:
            return


async def chatter(graph: Graph) -> None:
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    while True:
        publisher.publish({"data": "hi"})
        await anyio.sleep(0.05)


@pytest.mark.parametrize("transport", ["ws", "tcp"])
async def test_a_silent_connection_holding_nothing_is_closed_a_listener_stays(
    transport: str,
) -> None:
    graph = Graph()
    async with (
        running_server(ServerConfig(idle_timeout_s=IDLE_S), graph=graph) as harness,
        anyio.create_task_group() as tg,
    ):
        silent = await harness.connect(transport, "silent")
        listener = await harness.connect(transport, "listener")
        tg.start_soon(chatter, graph)
        with anyio.fail_after(TIMEOUT_S):
            await listener.send({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/String"})
            assert await closed(silent)
            await listen(listener, LISTEN_S)  # several idle periods without a word from it
            assert sum(1 for c in harness.server.sessions if c.startswith(transport)) == 1
        tg.cancel_scope.cancel()


async def test_roslibpy_and_roslib_that_only_listen_are_not_cut() -> None:
    graph = Graph()
    async with (
        running_server(ServerConfig(idle_timeout_s=IDLE_S), graph=graph) as harness,
        anyio.create_task_group() as tg,
    ):
        port = harness.port("websocket")
        silent = await harness.connect("tcp", "silent")
        tg.start_soon(chatter, graph)
        python = f"""
            import time, roslibpy
            ros = roslibpy.Ros("127.0.0.1", {port})
            ros.run(timeout=20)
            heard = []
            topic = roslibpy.Topic(ros, "/chatter", "std_msgs/String")
            topic.subscribe(lambda msg: heard.append(time.monotonic()))
            start = time.monotonic()
            while not [t for t in heard if t > start + {LISTEN_S}]:
                assert time.monotonic() < start + 20, "no message after listening"
                time.sleep(0.05)
            print("heard", ros.is_connected)
            ros.terminate()
            """
        out = await run_python(python)
        assert out.split() == ["heard", "True"]
        if node_missing() is None:
            js = f"""
                import * as ROSLIB from "roslib";
                const ros = new ROSLIB.Ros({{url: "ws://127.0.0.1:{port}"}});
                let closed = false;
                ros.on("close", () => {{ closed = true; }});
                const topic = new ROSLIB.Topic({{ros, name: "/chatter",
                                               messageType: "std_msgs/String"}});
                const start = Date.now();
                topic.subscribe(() => {{
                  if (Date.now() > start + {LISTEN_S * 1000}) {{
                    console.log("heard", !closed); topic.unsubscribe(); ros.close();
                  }}
                }});
                """
            out = await run_node(js)
            assert out.split()[:2] == ["heard", "true"]
        with anyio.fail_after(TIMEOUT_S):
            assert await closed(silent)
        tg.cancel_scope.cancel()
