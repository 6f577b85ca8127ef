"""The link's per-stage counters add up: a real rclpy publisher of N messages, one roslibpy
subscriber, and the server's ``event=ros2_counters`` and ``event=disconnect`` lines.

Counts only: every stage's figure is compared with the one before it and with what the
subscriber got, never with a time.
"""

from __future__ import annotations

import json
import re
import threading
import time
import warnings
from pathlib import Path

import anyio
import pytest

from tests.support.realclients import run_python

from .support import roslibpy_prelude, serve_ros2, skip_without_rclpy

pytestmark = skip_without_rclpy()

TOPIC = "/counted"
N = 300

SUBSCRIBE = f"""
got = []
roslibpy.Topic(ros, "{TOPIC}", "std_msgs/msg/String").subscribe(lambda m: got.append(m["data"]))
wait_for(lambda: len(got) >= {N}, within=30)
time.sleep(0.5)  # nothing more comes
print(json.dumps(got))
ros.terminate()
"""


def _publish(done: threading.Event, heard: threading.Event, failure: list[BaseException]) -> None:
    """``_publish_n`` on this thread; its error goes to ``failure``."""
    try:
        with warnings.catch_warnings():  # rosidl's type support imports lark (sre_parse)
            warnings.simplefilter("ignore", DeprecationWarning)
            _publish_n(heard)
    except BaseException as exc:  # reported by the test
        failure.append(exc)
    finally:
        done.set()


def _publish_n(heard: threading.Event) -> None:
    """Wait for the link's subscription, publish ``N`` strings (reliable, depth ``N``), and
    stay until ``heard`` (the subscriber is done) or 30 s."""
    import rclpy  # noqa: PLC0415
    from rclpy.qos import QoSProfile  # noqa: PLC0415
    from std_msgs.msg import String  # noqa: PLC0415

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("counted_talker", context=context)
        pub = node.create_publisher(String, TOPIC, QoSProfile(depth=N))
        end = time.monotonic() + 30
        while pub.get_subscription_count() < 1 and time.monotonic() < end:
            time.sleep(0.05)
        assert pub.get_subscription_count() == 1, "the link never subscribed"
        for i in range(N):
            pub.publish(String(data=f"m{i}"))
            if i % 25 == 24:  # bursts of 25: more than ROS 2's default depth (10), within
                time.sleep(0.1)  # the link's (INWARD_DEPTH): nothing lost, counts comparable
        heard.wait(30)  # the publisher stays until the subscriber has had everything
        node.destroy_node()
    finally:
        context.try_shutdown()


def _fields(line: str) -> dict[str, str]:
    return dict(re.findall(r"(\w+)=(\S+)", line))


@pytest.mark.anyio
async def test_each_stage_counts_every_message_of_a_real_publisher(ros_env: Path) -> None:
    server = serve_ros2(ros_env)
    try:
        done, heard, failure = threading.Event(), threading.Event(), []
        async with anyio.create_task_group() as tg:
            got: list[str] = []

            async def subscribe() -> None:
                try:
                    out = await run_python(roslibpy_prelude(server.port) + SUBSCRIBE)
                finally:
                    heard.set()
                got.extend(json.loads(out.strip().splitlines()[-1]))

            tg.start_soon(subscribe)
            await anyio.to_thread.run_sync(_publish, done, heard, failure)
        assert not failure, failure
    finally:
        server.stop()
    assert got == [f"m{i}" for i in range(N)]
    log = server.stderr_path.read_text("utf-8", "replace")
    counted = [_fields(x) for x in log.splitlines() if "event=ros2_counters" in x]
    stage = next(c for c in counted if c["topic"] == TOPIC)
    # stage 1: every wake-up took at least one; the histogram holds each wake-up once
    batches = {k: int(v) for k, v in (b.split(":") for b in stage["batches"].split(","))}
    assert sum(batches.values()) == int(stage["wakes"]) >= 1
    assert int(stage["max_batch"]) >= 1
    # stages 1 to 3: taken = handed + refused = published + skipped + refused
    assert int(stage["taken"]) == N
    assert int(stage["handed"]) == N and int(stage["refused"]) == 0
    assert int(stage["published"]) == N and int(stage["skipped"]) == 0
    # stage 4: the subscriber's queue got each one, dropped none, sent them all
    left = [_fields(x) for x in log.splitlines() if "event=disconnect" in x]
    assert len(left) == 1, log[-3000:]
    assert int(left[0]["topic_messages"]) == N
    assert int(left[0]["dropped"]) == 0
    assert int(left[0]["frames_sent"]) >= N  # and the replies
