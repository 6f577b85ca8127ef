"""The ``ros2-take-loop`` shortcut (docs/shortcuts.md) against its general path.

Its own code (``rwt_ros2.takeloop.TakeLoop``) with a real rclpy publisher, and two
``rwt serve --ros2``, one taking from its wait set and one through rclpy's executor
(the shortcut off), fed by one real rclpy publisher: each one's roslibpy subscriber
gets the same samples in the same order.
"""

from __future__ import annotations

import json
import threading
import time
import warnings
from pathlib import Path
from typing import Any

import anyio
import pytest

from rwt_protocol.shortcuts import ENV_VAR
from rwt_ros2.takeloop import TAKE_BATCH, TakeLoop
from tests.support.realclients import run_python

from .support import roslibpy_prelude, serve_ros2, skip_without_rclpy

pytestmark = skip_without_rclpy()

N = 600
"""Samples published: more than one wake-up can take (``TAKE_BATCH``)."""


def _wait_matched(pub: Any, count: int) -> None:
    end = time.monotonic() + 30
    while pub.get_subscription_count() < count and time.monotonic() < end:
        time.sleep(0.05)
    assert pub.get_subscription_count() == count, "the subscriptions never matched"


def test_the_loop_takes_a_publishers_samples_in_order_in_bounded_batches(ros_env: Path) -> None:
    with warnings.catch_warnings():  # rosidl's type support imports lark, which imports sre_parse
        warnings.simplefilter("ignore", DeprecationWarning)
        _take_in_order()
    del ros_env  # the module's domain, set in the environment


def _take_in_order() -> None:
    import rclpy  # noqa: PLC0415
    from rclpy.qos import QoSProfile  # noqa: PLC0415
    from std_msgs.msg import String  # noqa: PLC0415

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("take_loop_probe", context=context)
        takes = TakeLoop(node)
        batches: list[list[bytes]] = []
        arrived = threading.Condition()

        def on_batch(batch: list[tuple[bytes, dict[str, Any]]]) -> None:
            assert all(info.get("publisher_gid") for _, info in batch)
            with arrived:
                batches.append([data[8:].rstrip(b"\x00") for data, _ in batch])
                arrived.notify_all()

        handle = takes.subscribe(String, "/taken", QoSProfile(depth=N), on_batch)
        assert node.get_subscriptions_info_by_topic("/taken")  # a real subscription...
        assert all(s.topic_name != "/taken" for s in node.subscriptions)  # not the executor's
        pub = node.create_publisher(String, "/taken", QoSProfile(depth=N))
        _wait_matched(pub, 1)
        for i in range(N):  # published before the loop runs: it finds them all waiting
            pub.publish(String(data=f"m{i}"))
        takes.start()
        with arrived:
            arrived.wait_for(lambda: sum(map(len, batches)) >= N, timeout=30)
        assert [m for batch in batches for m in batch] == [f"m{i}".encode() for i in range(N)]
        assert max(map(len, batches)) == TAKE_BATCH  # the bound holds
        takes.unsubscribe(handle)
        pub.publish(String(data="after"))
        time.sleep(0.5)  # nothing may come; a late batch would show below
        assert sum(map(len, batches)) == N
        takes.close()
        node.destroy_node()
    finally:
        context.try_shutdown()


SUBSCRIBE = """
got = []
roslibpy.Topic(ros, "/same", "std_msgs/msg/String").subscribe(lambda m: got.append(m["data"]))
wait_for(lambda: len(got) >= {n}, within=40)
time.sleep(0.5)  # nothing more comes
print(json.dumps(got))
ros.terminate()
"""


def _publish(heard: threading.Semaphore, failure: list[BaseException]) -> None:
    """Wait for both links' subscriptions, publish ``N`` strings in bursts, and stay until
    both subscribers are done (``heard`` released twice) or 30 s."""
    try:
        with warnings.catch_warnings():  # rosidl's type support imports lark (sre_parse)
            warnings.simplefilter("ignore", DeprecationWarning)
            _publish_n(heard)
    except BaseException as exc:  # reported by the test
        failure.append(exc)


def _publish_n(heard: threading.Semaphore) -> None:
    import rclpy  # noqa: PLC0415
    from rclpy.qos import QoSProfile  # noqa: PLC0415
    from std_msgs.msg import String  # noqa: PLC0415

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("same_talker", context=context)
        pub = node.create_publisher(String, "/same", QoSProfile(depth=N))
        _wait_matched(pub, 2)
        for i in range(N):
            pub.publish(String(data=f"m{i}"))
            if i % 50 == 49:  # bursts: wake-ups that take several samples; two bursts fit
                time.sleep(0.5)  # the link's history (INWARD_DEPTH), so a server a loaded
                # machine stalls for a moment loses none (0.05 s pauses lost 97 in CI once,
                # 0.2 s lost 49 with three test workers beside two busy cores)
        end = time.monotonic() + 30  # the publisher stays until both subscribers are done
        for _ in range(2):
            heard.acquire(timeout=max(0.0, end - time.monotonic()))
        node.destroy_node()
    finally:
        context.try_shutdown()


@pytest.mark.anyio
async def test_both_paths_deliver_the_same_samples_in_the_same_order(ros_env: Path) -> None:
    looped = serve_ros2(ros_env)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(ENV_VAR, "ros2-take-loop")
        general = serve_ros2(ros_env)
    got: dict[str, list[str]] = {}
    failure: list[BaseException] = []
    heard = threading.Semaphore(0)
    try:
        async with anyio.create_task_group() as tg:
            for name, server in (("loop", looped), ("executor", general)):

                async def subscribe(name: str = name, port: int = server.port) -> None:
                    try:
                        out = await run_python(roslibpy_prelude(port) + SUBSCRIBE.format(n=N))
                    finally:
                        heard.release()
                    got[name] = json.loads(out.strip().splitlines()[-1])

                tg.start_soon(subscribe)
            await anyio.to_thread.run_sync(_publish, heard, failure)
    finally:
        looped.stop()
        general.stop()
    assert not failure, failure
    assert got["loop"] == got["executor"] == [f"m{i}" for i in range(N)]
