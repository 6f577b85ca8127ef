"""rosapi describes the ROS 2 graph through `rwt serve --ros2`; the access globs hold on it."""

from __future__ import annotations

import json
import os
from pathlib import Path

import anyio
import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import JsonLines, Peer, peers, roslibpy_prelude, serve_ros2, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

DESCRIBE = """
def rosapi(name, **args):
    service = roslibpy.Service(ros, "/rosapi/" + name, "rosapi_msgs/srv/" + name.title())
    return service.call(roslibpy.ServiceRequest(args), timeout=10)

def seen():
    return (
        "/graph_talk" in ros.get_topics()
        and "/graph_listen" in ros.get_topics()
        and "/peer_serve" in ros.get_nodes()
        and "/graph_srv" in ros.get_services()
    )
wait_for(seen)
print(json.dumps({
    "topic_type": ros.get_topic_type("/graph_talk"),
    "publishers": rosapi("publishers", topic="/graph_talk")["publishers"],
    "subscribers": rosapi("subscribers", topic="/graph_listen")["subscribers"],
    "service_type": ros.get_service_type("/graph_srv"),
    "nodes": ros.get_nodes(),
}), flush=True)
input()  # the talker stops meanwhile
gone = wait_for(lambda: "/graph_talk" not in ros.get_topics())
# the node goes after its publisher: DDS discovery says each when it learns it
node_gone = wait_for(lambda: "/peer_talk" not in ros.get_nodes())
print(json.dumps({"gone": gone, "node_gone": node_gone, "nodes": ros.get_nodes()}))
ros.terminate()
"""


async def test_rosapi_lists_the_ros2_graph_as_it_changes(
    server: ServerProcess, ros_env: Path
) -> None:
    specs = [("talk", "/graph_talk"), ("listen", "/graph_listen"), ("serve", "/graph_srv")]
    with peers(ros_env, *specs) as (talker, _, _):
        async with await anyio.open_process(
            ["python", "-c", roslibpy_prelude(server.port) + DESCRIBE]
        ) as client:
            assert client.stdout is not None and client.stdin is not None
            lines = JsonLines(client.stdout)
            with anyio.fail_after(40):
                described = await lines.next()
                talker.stop()
                await client.stdin.send(b"\n")
                after = await lines.last()
    assert described["topic_type"] == "std_msgs/msg/String"
    assert described["publishers"] == ["/peer_talk"]
    assert described["subscribers"] == ["/peer_listen"]
    assert described["service_type"] == "std_srvs/srv/SetBool"
    assert {"/peer_talk", "/peer_listen", "/peer_serve", "/rwt"} <= set(described["nodes"])
    assert after["gone"] is True and after["node_gone"] is True
    assert "/peer_talk" not in after["nodes"]
    assert "/peer_listen" in after["nodes"]


GLOBBED = """
got = {"open": [], "secret": []}
roslibpy.Topic(ros, "/open/chatter", "std_msgs/msg/String").subscribe(got["open"].append)
roslibpy.Topic(ros, "/secret", "std_msgs/msg/String").subscribe(got["secret"].append)
wait_for(lambda: len(got["open"]) >= 3 and "/open/switch" in ros.get_services())
# the ROS 2 graph is discovered by now (the two servers started together)
secret = roslibpy.Service(ros, "/secret_switch", "std_srvs/srv/SetBool")
try:
    secret.call(roslibpy.ServiceRequest({"data": True}), timeout=10)
    called = "answered"
except Exception as exc:
    called = str(exc)
print(json.dumps({"open": len(got["open"]) >= 3, "secret": got["secret"],
                  "topics": ros.get_topics(), "services": ros.get_services(), "called": called}))
ros.terminate()
"""


async def test_the_topics_and_services_globs_hold_on_the_ros2_side(ros_env: Path) -> None:
    server = serve_ros2(
        ros_env, "--topics-glob", "[/open/*]", "--services-glob", "[/open/*, /rosapi/*]"
    )
    try:
        with peers(
            ros_env,
            ("talk", "/open/chatter", "open_talker"),
            ("talk", "/secret", "secret_talker"),
            ("serve", "/secret_switch", "secret_server"),
            ("serve", "/open/switch", "open_server"),
        ):
            out = await run_python(roslibpy_prelude(server.port) + GLOBBED)
    finally:
        server.stop()
    got = json.loads(out.strip().splitlines()[-1])
    assert got["open"] is True
    assert got["secret"] == []
    assert "/secret" not in got["topics"]
    assert "/open/chatter" in got["topics"]
    assert "/secret_switch" not in got["services"]
    assert "/open/switch" in got["services"]
    assert "/secret_switch" in got["called"] and got["called"] != "answered"


VERSION = """
service = roslibpy.Service(ros, "/rosapi/get_ros_version", "rosapi_msgs/srv/GetROSVersion")
print(json.dumps(dict(service.call(roslibpy.ServiceRequest({}), timeout=10))))
ros.terminate()
"""


async def test_rosapi_reports_the_distribution_of_the_running_ros(server: ServerProcess) -> None:
    # the test extra's rclpy is PyPI's Kilted wheels; a sourced ROS says its own
    out = await run_python(roslibpy_prelude(server.port) + VERSION)
    expected = os.environ.get("ROS_DISTRO") or "kilted"
    assert json.loads(out.strip().splitlines()[-1]) == {"version": 2, "distro": expected}


async def test_ros_distro_in_the_environment_names_the_distribution(
    ros_env: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ROS_DISTRO", "rolling")
    server = serve_ros2(ros_env)
    try:
        out = await run_python(roslibpy_prelude(server.port) + VERSION)
    finally:
        server.stop()
    assert json.loads(out.strip().splitlines()[-1]) == {"version": 2, "distro": "rolling"}


MANY = """
import sys
def topics():
    service = roslibpy.Service(ros, "/rosapi/topics", "rosapi_msgs/srv/Topics")
    return set(service.call(roslibpy.ServiceRequest({}), timeout=10)["topics"])

print(json.dumps({"before": sorted(t for t in topics() if t.startswith("/many/"))}), flush=True)
sys.stdin.readline()  # the node with 200 publishers starts meanwhile
wanted = {f"/many/t{n:03}" for n in range(200)}
wait_for(lambda: wanted <= topics(), 20)
nodes = roslibpy.Service(ros, "/rosapi/nodes", "rosapi_msgs/srv/Nodes")
found = topics()
print(json.dumps({
    "missing": sorted(wanted - found),
    "nodes": nodes.call(roslibpy.ServiceRequest({}), timeout=10)["nodes"],
}))
ros.terminate()
"""


async def test_a_node_starting_after_the_client_shows_with_its_200_topics(
    server: ServerProcess, ros_env: Path
) -> None:
    # The node comes after the client connected: the link sees the graph change
    # (its names, read every 50 ms) and sweeps, so rosapi lists every topic.
    async with await anyio.open_process(
        ["python", "-c", roslibpy_prelude(server.port) + MANY]
    ) as client:
        assert client.stdout is not None and client.stdin is not None
        lines = JsonLines(client.stdout)
        with anyio.fail_after(40):
            assert await lines.next() == {"before": []}
            with Peer("many_topics", "200", ros_env):
                await client.stdin.send(b"\n")
                after = await lines.last()
    assert after["missing"] == []
    assert "/peer_many_topics" in after["nodes"]
