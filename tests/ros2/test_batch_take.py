"""The ``ros2-batch-take`` shortcut (docs/shortcuts.md): its own code against rclpy's real
subscription handle, and the general path (switched off) through `rwt serve --ros2`.

The transports' shortcut probe runs no ROS 2 link, so this module covers the shortcut.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

from rwt_protocol.shortcuts import ENV_VAR
from rwt_ros2.takeloop import take_queued
from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import Peer, roslibpy_prelude, serve_ros2, skip_without_rclpy

pytestmark = skip_without_rclpy()


@pytest.fixture(scope="module")
def server(ros_env: Path) -> Iterator[ServerProcess]:
    """`rwt serve --ros2` with the shortcut off (and the take loop, which takes in
    batches of its own): one executor callback per sample."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(ENV_VAR, "ros2-batch-take,ros2-take-loop")
        process = serve_ros2(ros_env)
    try:
        yield process
    finally:
        process.stop()


def test_take_queued_hands_over_what_waits_in_order(ros_env: Path) -> None:
    with warnings.catch_warnings():  # rosidl's type support imports lark, which imports sre_parse
        warnings.simplefilter("ignore", DeprecationWarning)
        _take_queued_in_order()
    del ros_env  # the module's domain, set in the environment


def _take_queued_in_order() -> None:
    import rclpy  # noqa: PLC0415
    from rclpy.qos import QoSProfile  # noqa: PLC0415
    from std_msgs.msg import String  # noqa: PLC0415

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("batch_probe", context=context)
        sub = node.create_subscription(String, "/batched", lambda *_: None, 50, raw=True)
        pub = node.create_publisher(String, "/batched", QoSProfile(depth=50))
        end = time.monotonic() + 20
        while pub.get_subscription_count() < 1 and time.monotonic() < end:
            time.sleep(0.05)
        for i in range(5):
            pub.publish(String(data=f"m{i}"))
        got: list[tuple[bytes, dict[str, object]]] = []
        while len(got) < 5 and time.monotonic() < end:
            got += take_queued(sub.handle, String, 3)  # at most 3 a call: the bound holds
            time.sleep(0.05)
        assert [data[8:].rstrip(b"\x00") for data, _ in got] == [b"m0", b"m1", b"m2", b"m3", b"m4"]
        assert all(info.get("publisher_gid") for _, info in got)
        assert take_queued(sub.handle, String, 3) == []  # nothing waits: an empty take ends it
        node.destroy_subscription(sub)
        assert take_queued(sub.handle, String, 3) == []  # destroyed meanwhile: nothing, no error
        node.destroy_node()
    finally:
        context.try_shutdown()


SUBSCRIBE = """
got = []
roslibpy.Topic(ros, "/general", "std_msgs/msg/String").subscribe(lambda m: got.append(m["data"]))
wait_for(lambda: len(got) >= 20)
print(json.dumps(got[:20]))
ros.terminate()
"""


@pytest.mark.anyio
async def test_the_general_path_carries_a_talker_in_order(
    server: ServerProcess, ros_env: Path
) -> None:
    import json  # noqa: PLC0415

    with Peer("talk", "/general", ros_env):
        out = await run_python(roslibpy_prelude(server.port) + SUBSCRIBE)
    numbers = [int(n) for n in json.loads(out.strip().splitlines()[-1])]
    assert numbers == list(range(numbers[0], numbers[0] + 20))  # in order, none lost
