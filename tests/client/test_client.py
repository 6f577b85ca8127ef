"""The Python client against rwt's server: every feature, over each transport."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
from typing import Any

import anyio
import pytest
from anyio.abc import TaskStatus
from anyio.from_thread import start_blocking_portal
from websockets.asyncio.server import ServerConnection

from rwt_client import (
    Action,
    CallTimeoutError,
    ConnectionClosedError,
    Param,
    Ros,
    ServerGoal,
    Service,
    ServiceCallError,
    SyncRos,
    Topic,
    message_class,
)
from rwt_client.ros import jittered
from rwt_graph.graph import Graph
from rwt_protocol.errors import ConfigError, OpRefusedError
from rwt_protocol.levels import StatusLevel
from rwt_protocol.ops import Status
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.conformance import hostile
from tests.support.realclients import REPO

pytestmark = pytest.mark.anyio


class Inbox:
    """Collects callback values; ``wait(n)`` returns once n arrived (bounded)."""

    def __init__(self) -> None:
        self.items: list[Any] = []
        self._event = anyio.Event()

    def __call__(self, item: Any) -> None:
        self.items.append(item)
        self._event.set()

    async def wait(self, count: int = 1, timeout_s: float = 5.0) -> list[Any]:
        with anyio.fail_after(timeout_s):
            while len(self.items) < count:
                await self._event.wait()
                self._event = anyio.Event()
        return self.items


async def test_publish_and_subscribe(url: str) -> None:
    async with Ros(url) as a, Ros(url) as b:
        inbox = Inbox()
        listener = Topic(b, "/chatter", "std_msgs/String")
        await listener.subscribe(inbox)
        await _sync(b)
        talker = Topic(a, "/chatter", "std_msgs/msg/String")
        await talker.publish({"data": "hello"})
        assert await inbox.wait() == [{"data": "hello"}]
        assert talker.is_advertised and listener.is_subscribed
        await listener.unsubscribe()
        await talker.unadvertise()
        assert not talker.is_advertised and not listener.is_subscribed


async def test_subscription_options_and_latching(url: str) -> None:
    async with Ros(url) as a, Ros(url) as b:
        latched = Topic(a, "/map", "std_msgs/Int32", latch=True)
        await latched.publish({"data": 7})
        await _sync(a)
        inbox = Inbox()
        topic = Topic(b, "/map", throttle_rate=0, queue_length=1, compression="none")
        await topic.subscribe(inbox)
        assert await inbox.wait() == [{"data": 7}]


async def test_typed_messages(url: str) -> None:
    point = message_class("geometry_msgs/msg/Point")
    quaternion = message_class("geometry_msgs/Quaternion")
    assert quaternion().w == 1.0
    async with Ros(url) as a, Ros(url) as b:
        inbox = Inbox()
        await Topic(b, "/p", "geometry_msgs/Point", message_class=point).subscribe(inbox)
        await _sync(b)
        await Topic(a, "/p", "geometry_msgs/Point").publish(point(x=1.0, y=2.0))
        [received] = await inbox.wait()
        assert received == point(x=1.0, y=2.0, z=0.0)


async def test_service_call_and_advertise(url: str) -> None:
    async with Ros(url) as provider, Ros(url) as caller:
        await Service(provider, "/add", "example_interfaces/AddTwoInts").advertise(
            lambda req: {"sum": req["a"] + req["b"]}
        )

        async def set_bool(req: dict[str, Any]) -> dict[str, Any]:
            return {"success": req["data"], "message": f"set to {req['data']}"}

        await Service(provider, "/set_bool", "std_srvs/SetBool").advertise(set_bool)
        await _sync(provider)
        add = Service(caller, "/add", "example_interfaces/AddTwoInts")
        assert await add.call({"a": 2, "b": 3}) == {"sum": 5}
        assert await Service(caller, "/set_bool").call({"data": True}) == {
            "success": True,
            "message": "set to True",
        }


async def test_service_failures_are_clear_errors(url: str) -> None:
    async with Ros(url) as provider, Ros(url) as caller:

        def broken(req: object) -> object:
            raise RuntimeError("disk on fire")

        async def silent(req: object) -> object:
            await anyio.sleep_forever()

        await Service(provider, "/broken", "std_srvs/Trigger").advertise(broken)
        await Service(provider, "/silent", "std_srvs/Trigger").advertise(silent)
        await _sync(provider)
        with pytest.raises(ServiceCallError, match="disk on fire"):
            await Service(caller, "/broken").call()
        with pytest.raises(ServiceCallError, match="/missing"):
            await Service(caller, "/missing").call()
        with pytest.raises(CallTimeoutError, match="no service_response for /silent"):
            await Service(caller, "/silent").call(timeout_s=0.3)


async def test_refusals_raise_clear_errors() -> None:
    """Refused parameters (``--params-glob``, the store) and an advertise of another type raise."""
    access = AccessPolicy(params=("/open_*",))
    graph = Graph()
    graph.params.declare("/open_door", {"state": 0})
    config = ServerConfig(port=0, session=SessionConfig(access=access))
    server = RosbridgeServer(graph, config)
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        url = server.urls["websocket"]
        async with Ros(url) as ros, Ros(url) as other:
            await Param(ros, "/open_door:state").set(1)
            assert await Param(ros, "/open_door:state").get() == 1
            with pytest.raises(ServiceCallError, match="parameter /secret is not allowed"):
                await Param(ros, "/secret").set(1)
            # rosapi answers successful: false (ROS 2), which raises with its reason
            with pytest.raises(ServiceCallError, match="node /open_ghost does not exist"):
                await Param(ros, "/open_ghost:x").set(1)
            with pytest.raises(ServiceCallError, match="expected <node>:<parameter>"):
                await ros.delete_param("/open_door")
            await Topic(other, "/t", "std_msgs/String").advertise()
            wrong = Topic(ros, "/t", "std_msgs/Int32")
            with pytest.raises(OpRefusedError, match="established with type std_msgs/msg/String"):
                await wrong.advertise()
            assert not wrong.is_advertised and ros.session.advertisements == {}
            with pytest.raises(OpRefusedError):  # publishing advertises first
                await wrong.publish({"data": 1})
            inbox = Inbox()
            await Topic(other, "/t").subscribe(inbox)
            await _sync(other)
            await Topic(ros, "/t", "std_msgs/msg/String").publish({"data": "right"})
            assert await inbox.wait() == [{"data": "right"}]
        tg.cancel_scope.cancel()


async def _refuses_by_status_only(ws: ServerConnection) -> None:
    """A foreign server that answers calls and advertisements with an error status only."""
    async for frame in ws:
        op = json.loads(frame)
        if op.get("op") in ("call_service", "advertise"):
            status = {"op": "status", "level": "error", "msg": "refused here", "id": op["id"]}
            await ws.send(json.dumps(status))


async def test_an_error_status_alone_refuses_a_call_or_an_advertise() -> None:
    with hostile.serving(_refuses_by_status_only) as url:
        async with Ros(url, reconnect=False) as ros:
            with pytest.raises(ServiceCallError, match="/x failed: refused here"):
                await ros.call_service("/x", timeout_s=10)  # at once, not after 10 s
            with pytest.raises(OpRefusedError, match=r"refused advertise .*: refused here"):
                await Topic(ros, "/t", "std_msgs/String").advertise()


def test_reconnect_waits_are_jittered() -> None:
    waits = [jittered(2.0) for _ in range(200)]
    assert all(1.0 <= wait <= 3.0 for wait in waits)
    assert max(waits) - min(waits) > 0.5  # spread, not one fixed back-off


async def test_actions_with_feedback_and_cancel(url: str) -> None:
    async with Ros(url) as server, Ros(url) as client:

        async def fibonacci(goal: ServerGoal) -> dict[str, Any]:
            sequence = [0, 1]
            for _ in range(goal.args["order"] - 1):  # type: ignore[index]
                sequence.append(sequence[-1] + sequence[-2])
                await goal.send_feedback({"sequence": sequence})
            return {"sequence": sequence}

        async def forever(goal: ServerGoal) -> dict[str, Any]:
            await goal.cancel_requested.wait()
            goal.canceled()
            return {"sequence": []}

        await Action(server, "/fib", "example_interfaces/Fibonacci").advertise(fibonacci)
        await Action(server, "/slow", "example_interfaces/Fibonacci").advertise(forever)
        await _sync(server)
        feedback = Inbox()
        handle = await Action(client, "/fib", "example_interfaces/Fibonacci").send_goal(
            {"order": 3}, on_feedback=feedback
        )
        result = await handle.result(timeout_s=5)
        assert (result.status, result.result, result.values) == (
            4,
            True,
            {"sequence": [0, 1, 1, 2]},
        )
        assert feedback.items == [{"sequence": [0, 1, 1]}, {"sequence": [0, 1, 1, 2]}]
        slow = await Action(client, "/slow", "example_interfaces/Fibonacci").send_goal({"order": 1})
        await slow.cancel()
        assert (await slow.result(timeout_s=5)).status == 5


async def test_status_level_and_callbacks(url: str) -> None:
    async with Ros(url) as ros:
        statuses = Inbox()
        ros.on_status(statuses)
        await ros.set_level(StatusLevel.INFO)
        await Topic(ros, "/s", "std_msgs/String").advertise()
        [*_, last] = await statuses.wait(2)
        assert isinstance(last, Status) and last.level == "info"
        assert last.msg.startswith("advertise: ")


async def test_rosapi_helpers_and_params(url: str) -> None:
    """rwt's built-in rosapi answers the helpers."""
    async with Ros(url) as ros:
        await Topic(ros, "/a", "std_msgs/String").advertise()
        await Topic(ros, "/b", "std_msgs/Int32").advertise()
        await _sync(ros)
        assert {"/a", "/b", "/client_count"} <= set(await ros.get_topics())
        types = await ros.get_topics_and_types()
        assert types["/a"] == "std_msgs/msg/String" and types["/b"] == "std_msgs/msg/Int32"
        assert await ros.get_topic_type("/b") == "std_msgs/msg/Int32"
        assert await ros.get_nodes() == [
            "/rosapi",
            "/rosbridge_websocket",
            "/rwt_client_1",
            "/tf2_web_republisher",
        ]
        param = Param(ros, "/rwt_client_1:answer")
        await param.set([1, 2])
        assert await param.get() == [1, 2]
        assert await ros.get_params() == ["/rwt_client_1:answer"]
        await ros.delete_param("/rwt_client_1:answer")
        assert await ros.get_param("/rwt_client_1:answer", 7) == 7
        assert await ros.get_time() > 1_600_000_000


async def test_reconnect_resubscribes_and_readvertises(transport: str) -> None:
    def config(port: int) -> ServerConfig:
        return (
            ServerConfig(port=port) if transport == "ws" else ServerConfig(port=None, tcp_port=port)
        )

    first = RosbridgeServer(config=config(0))
    stop_first, first_stopped = anyio.CancelScope(), anyio.Event()

    async def run_first(*, task_status: TaskStatus[str]) -> None:
        try:
            with stop_first:
                await first.serve(task_status=task_status)
        finally:
            first_stopped.set()

    async with anyio.create_task_group() as tg:
        url = await tg.start(run_first)  # the only listener's URL
        port = int(url.rsplit(":", 1)[1])
        async with Ros(url) as listener, Ros(url) as talker:
            inbox, reconnected = Inbox(), Inbox()
            listener.on_reconnect(reconnected)
            talker.on_reconnect(reconnected)
            await Topic(listener, "/r", "std_msgs/String").subscribe(inbox)
            chatter = Topic(talker, "/r", "std_msgs/String")
            await chatter.advertise()
            stop_first.cancel()
            await first_stopped.wait()
            await tg.start(RosbridgeServer(config=config(port)).serve)
            assert await reconnected.wait(2, timeout_s=10) == [1, 1]
            await _sync(listener)
            await chatter.publish({"data": "back"})
            assert await inbox.wait() == [{"data": "back"}]
        tg.cancel_scope.cancel()


async def _sync(ros: Ros) -> None:
    """A round trip: everything sent before has been processed by the server."""
    inbox = Inbox()
    topic = Topic(ros, f"/sync_{id(ros)}", "std_msgs/String")
    await topic.subscribe(inbox)
    await topic.publish({"data": "sync"})
    await inbox.wait()
    await topic.unsubscribe()


async def test_a_call_or_goal_while_the_connection_is_down_fails_at_once() -> None:
    """Sent while down it would be lost: it fails now, not after its timeout (10 min here)."""
    stop, stopped = anyio.CancelScope(), anyio.Event()

    async def run(*, task_status: TaskStatus[str]) -> None:
        try:
            with stop:
                await RosbridgeServer(config=LOCAL).serve(task_status=task_status)
        finally:
            stopped.set()

    async with anyio.create_task_group() as tg:
        url = await tg.start(run)
        async with Ros(url, timeout_s=600) as ros:
            await _sync(ros)
            stop.cancel()
            await stopped.wait()
            with anyio.fail_after(60):  # a hang guard: the call would wait 600 s
                while ros.is_connected:  # the reader sees the close
                    await anyio.sleep(0.01)
                with pytest.raises(ConnectionClosedError) as caught:
                    await Service(ros, "/rosapi/get_time").call(timeout_s=600)
                with pytest.raises(ConnectionClosedError):
                    await Action(ros, "/a", "example_interfaces/Fibonacci").send_goal({})
                await Topic(ros, "/t", "std_msgs/String").publish({"data": "dropped"})
        assert caught.value.message.startswith(f"not connected to {url}: ")
        assert caught.value.message.endswith("(reconnecting)")
        tg.cancel_scope.cancel()


async def test_a_subscription_made_as_the_connection_drops_is_replayed() -> None:
    """The drop lands between the client's "connected" and its send (``rwt record``
    subscribing as its server vanishes): the subscribe does not fail, and the
    reconnection's replay carries it."""
    async with anyio.create_task_group() as tg:
        url = await tg.start(RosbridgeServer(config=LOCAL).serve)
        async with Ros(url) as listener, Ros(url) as talker:
            reconnected, inbox = Inbox(), Inbox()
            listener.on_reconnect(reconnected)
            conn = listener._conn
            assert conn is not None
            send = conn.send

            async def send_as_it_drops(frame: str | bytes) -> None:
                await conn.aclose()  # the drop lands after the client chose to send
                await send(frame)

            conn.send = send_as_it_drops  # type: ignore[method-assign]
            await Topic(listener, "/dropped", "std_msgs/String").subscribe(inbox)
            assert await reconnected.wait(timeout_s=10) == [1]
            chatter = Topic(talker, "/dropped", "std_msgs/String")
            await chatter.advertise()
            await _sync(listener)
            await chatter.publish({"data": "replayed"})
            assert await inbox.wait() == [{"data": "replayed"}]
        tg.cancel_scope.cancel()


LOCAL = ServerConfig(port=0)


def _served_robot() -> Graph:
    """A graph with an action, for the blocking facade."""
    graph = Graph()

    async def fibonacci(goal: dict[str, Any], context: object) -> dict[str, Any]:
        sequence = [0, 1]
        for _ in range(1, goal["order"]):
            sequence.append(sequence[-1] + sequence[-2])
        return {"sequence": sequence}

    graph.create_action_server("/fibonacci", "example_interfaces/action/Fibonacci", fibonacci)
    return graph


def test_sync_facade() -> None:
    received = threading.Event()
    inbox: list[object] = []

    def on_message(msg: object) -> None:
        inbox.append(msg)
        received.set()

    with start_blocking_portal() as portal:
        future, url = portal.start_task(RosbridgeServer(_served_robot(), LOCAL).serve)
        with SyncRos(url) as ros:
            topic = ros.topic("/sync", "std_msgs/String")
            ros.subscribe(topic, on_message)  # the Topic object, as before
            ros.publish(topic, {"data": "blocking"})
            assert received.wait(5)
            with pytest.raises(ServiceCallError, match="/missing"):
                ros.call_service("/missing")
        future.cancel()
    assert inbox == [{"data": "blocking"}]


def test_the_sync_facade_takes_names_as_the_async_api_does() -> None:
    received = threading.Event()
    inbox: list[object] = []

    def on_message(msg: object) -> None:
        inbox.append(msg)
        received.set()

    with start_blocking_portal() as portal:
        future, url = portal.start_task(RosbridgeServer(_served_robot(), LOCAL).serve)
        with SyncRos(url) as ros:
            topic = ros.subscribe("/named", on_message, "std_msgs/String")
            ros.publish("/named", {"data": "by name"}, "std_msgs/String")
            assert received.wait(5)
            ros.unsubscribe(topic)
            assert not topic.is_subscribed
            types = ros.call_service(
                Service(ros.ros, "/rosapi/topic_type"), {"topic": "/named"}, timeout_s=5
            )
            assert types == {"type": "std_msgs/msg/String"}
            goal = ros.send_goal(
                "/fibonacci", {"order": 4}, action_type="example_interfaces/Fibonacci"
            )
            assert ros.result(goal, timeout_s=5).values == {"sequence": [0, 1, 1, 2, 3]}
            with pytest.raises(ConfigError, match="needs its action_type"):
                ros.send_goal("/fibonacci", {"order": 1})
        future.cancel()
    assert inbox == [{"data": "by name"}]


def test_the_sync_facade_runs_nothing_before_it_connects() -> None:
    ros = SyncRos("ws://127.0.0.1:1")
    with pytest.raises(ConnectionClosedError, match="call connect"):
        ros.call_service("/rosapi/get_time")
    ros.close()  # nothing to close: no thread was started


SYNC_DOWN = """
import sys
import rwt

try:
    with rwt.SyncRos(sys.argv[1]) as ros:
        print("connected?")
except rwt.ConnectionClosedError as exc:
    print(exc, file=sys.stderr)
    if sys.argv[2:] == ["raise"]:
        raise
print("the script ends")
"""


@pytest.mark.parametrize("caught", [True, False], ids=["caught", "uncaught"])
def test_sync_ros_against_a_server_that_is_down_fails_and_the_process_ends(
    caught: bool,
) -> None:
    """The background thread ends with the failed connect: the interpreter exits by itself."""
    with socket.socket() as sock:  # bound, not listening: connections are refused
        sock.bind(("127.0.0.1", 0))
        url = f"ws://127.0.0.1:{sock.getsockname()[1]}"
        try:
            done = subprocess.run(
                [sys.executable, "-c", SYNC_DOWN, url, *([] if caught else ["raise"])],
                env={**os.environ, "PYTHONPATH": str(REPO / "src")},
                capture_output=True,
                text=True,
                timeout=60,  # a hang guard: before the fix the process never ended
                check=False,
            )
        except subprocess.TimeoutExpired as exc:
            pytest.fail(f"the process did not end: {exc.stderr!r}")
    line = f"cannot connect to {url}: All connection attempts failed"
    if caught:
        assert (done.returncode, done.stderr, done.stdout) == (0, line + "\n", "the script ends\n")
    else:
        assert done.returncode == 1
        assert done.stderr.splitlines()[0] == line
        assert done.stderr.splitlines()[-1] == f"rwt.ConnectionClosedError: {line}"
        assert done.stdout == ""
