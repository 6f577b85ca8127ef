"""Foxglove clients on `rwt serve --ros2` with real rclpy nodes.

A talker's topic reaches a FoxgloveClient (@foxglove/ws-protocol in Node) with
the talker's own CDR, byte for byte: its alignment padding byte is 0xAB, which
a fresh serialization writes as 0, so a payload that keeps it was passed on as
the link received it. A FoxgloveClient's publish reaches an rclpy subscriber.
"""

from __future__ import annotations

import json
import struct
import subprocess
from pathlib import Path

import pytest
from websockets.sync.client import connect

from rwt_graph.types import Dialect, TypeRegistry
from tests.foxglove import extras
from tests.integration.client_harness import JS_DIR, ServerProcess

from .support import Peer, serve_ros2, skip_without_rclpy

pytestmark = [skip_without_rclpy(), pytest.mark.node]

POINT = "geometry_msgs/msg/PointStamped"
PADDING = 4 + 15  # CDR header, then sec, nanosec, length 3, "ab\0"


@pytest.fixture(autouse=True)
def _node() -> None:
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)


def expected_cdr() -> bytes:
    """What the peer's point_raw mode publishes."""
    registry = TypeRegistry(Dialect.ROS2)
    mtype = registry.message(POINT)
    values = {
        "header": {"stamp": {"sec": 7, "nanosec": 0}, "frame_id": "ab"},
        "point": {"x": 1.0, "y": -2.0, "z": 0.5},
    }
    data = bytearray(registry.serialize(mtype, mtype.from_python(values)))
    data[PADDING] = 0xAB
    return bytes(data)


def test_a_talkers_cdr_reaches_a_foxglove_client_as_it_was_sent(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("point_raw", "/fg_point", ros_env):
        got = extras.run("receive", server.url, "/fg_point", "3")
    assert got["encoding"] == "cdr" and got["schemaName"] == POINT
    assert [bytes.fromhex(p["hex"]) for p in got["payloads"]] == [expected_cdr()] * 3
    assert got["decoded"]["header"]["frame_id"] == "ab"
    assert got["decoded"]["point"] == {"x": 1.0, "y": -2.0, "z": 0.5}


def test_a_foxglove_clients_publish_reaches_an_rclpy_subscriber(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("listen", "/fg_to_ros", ros_env) as listener:
        publisher = subprocess.Popen(
            extras.command("publish", server.url, "/fg_to_ros", "from foxglove"),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            cwd=JS_DIR,
        )
        try:
            heard = listener.next()
        finally:
            publisher.kill()
            publisher.communicate(timeout=10)
    assert heard == {"heard": "from foxglove"}


def test_with_use_sim_time_a_simulators_clock_is_foxglove_server_time(ros_env: Path) -> None:
    server = serve_ros2(ros_env, "--use-sim-time")
    try:
        with (
            Peer("clock", "/clock", ros_env),
            connect(server.url, subprotocols=["foxglove.sdk.v1"]) as ws,
        ):
            assert "time" in json.loads(ws.recv(timeout=20))["capabilities"]
            times: list[int] = []
            while len(times) < 3:
                frame = ws.recv(timeout=20)
                if isinstance(frame, bytes) and frame[0] == 2:  # a time frame
                    times.append(struct.unpack_from("<Q", frame, 1)[0])
    finally:
        server.stop()
    # the rclpy node's sim time (from 1000 s), not the wall clock, in order
    assert all(1000 * 10**9 <= t < 2000 * 10**9 for t in times), times
    assert times == sorted(times) and len(set(times)) == 3
