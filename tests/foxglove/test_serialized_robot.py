"""A robot that publishes rclpy's CDR as it is (``LocalPublisher.publish(bytes)``), to real clients.

The robot process serializes a ``sensor_msgs/msg/Image`` with rclpy's
``serialize_message`` and publishes those bytes, latched, on a graph it serves.
The real Foxglove client (Node, @foxglove/ws-protocol, decoded with
@foxglove/rosmsg2-serialization) gets rclpy's bytes unchanged; roslibpy on the
same port gets the values, decoded by the server.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from collections.abc import Iterator

import pytest

from tests.foxglove.extras import missing
from tests.foxglove.test_node_client import run
from tests.ros2.support import skip_without_rclpy
from tests.support.realclients import run_python

pytestmark = [skip_without_rclpy(), pytest.mark.node]

ROBOT = textwrap.dedent(
    """
    import sys

    import anyio
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image

    import rwt

    image = Image(height=2, width=3, encoding="mono8", step=3, data=bytes(range(10, 16)))
    image.header.frame_id = "camera"
    image.header.stamp.sec, image.header.stamp.nanosec = 1_700_000_000, 42
    data = bytes(serialize_message(image))

    async def main() -> None:
        graph = rwt.Graph()
        graph.create_publisher("/camera/image", "sensor_msgs/msg/Image", latch=True).publish(data)
        server = rwt.RosbridgeServer(graph, rwt.ServerConfig(port=0))
        async with anyio.create_task_group() as tg:
            await tg.start(server.serve)
            print(json.dumps({"url": server.urls["websocket"], "cdr": data.hex()}), flush=True)
            await anyio.to_thread.run_sync(sys.stdin.read)
            server.stop()

    import json
    anyio.run(main)
    """
)


@pytest.fixture(scope="module")
def robot() -> Iterator[dict[str, str]]:
    if (reason := missing()) is not None:
        pytest.skip(reason)
    proc = subprocess.Popen(
        [sys.executable, "-c", ROBOT],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line, "the robot did not start"
        yield json.loads(line)
    finally:
        assert proc.stdin is not None and proc.stdout is not None
        proc.stdin.close()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stdout.close()


def test_foxglove_gets_rclpys_bytes_as_published(robot: dict[str, str]) -> None:
    result = run("latched", robot["url"], "/camera/image")
    assert result["schemaName"] == "sensor_msgs/msg/Image"
    assert result["payload"] == robot["cdr"]  # the robot's bytes, not a fresh serialization
    message = result["message"]
    stamp = {"sec": 1_700_000_000, "nanosec": 42}
    assert message["header"] == {"stamp": stamp, "frame_id": "camera"}
    assert (message["height"], message["width"], message["encoding"]) == (2, 3, "mono8")
    assert message["data"] == {"bytes": 6, "sum": sum(range(10, 16))}


@pytest.mark.anyio
async def test_roslibpy_gets_the_values(robot: dict[str, str]) -> None:
    port = robot["url"].rsplit(":", 1)[1]
    out = await run_python(
        f"""
        import base64, json, threading
        import roslibpy

        ros = roslibpy.Ros("127.0.0.1", {port})
        ros.run()
        got = threading.Event()
        heard = []
        topic = roslibpy.Topic(ros, "/camera/image", "sensor_msgs/msg/Image")
        topic.subscribe(lambda msg: (heard.append(msg), got.set()))
        assert got.wait(20), "no message"
        msg = heard[0]
        msg["data"] = list(base64.b64decode(msg["data"]))
        print(json.dumps(msg))
        ros.terminate()
        """
    )
    msg = json.loads(out.strip().splitlines()[-1])
    assert msg["header"] == {"stamp": {"sec": 1_700_000_000, "nanosec": 42}, "frame_id": "camera"}
    assert (msg["height"], msg["width"], msg["encoding"], msg["step"]) == (2, 3, "mono8", 3)
    assert msg["data"] == list(range(10, 16))
