"""The built-ins on real ROS 2 data: video of an image topic, a bag played and recorded."""

from __future__ import annotations

import io
from pathlib import Path

import anyio
import httpx
import numpy as np
import pytest
from PIL import Image

from rwt_bag.errors import BagError
from rwt_bag.reader import BagSource
from rwt_graph.types import Dialect, TypeRegistry
from tests.bag.bags import write_bag
from tests.bag.support import CHECKPOINTS

from .support import Peer, serve_ros2, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]


async def test_the_video_server_streams_a_real_image_topic(ros_env: Path) -> None:
    server = serve_ros2(ros_env, "--video", "--video-port", "0")
    try:
        line = server.next_stdout_line()
        assert line is not None and line.startswith("video on http://"), line
        video = line.removeprefix("video on ")
        with Peer("image", "/ros2_camera", ros_env):
            async with httpx.AsyncClient(timeout=20) as http:
                snapshot = None
                with anyio.fail_after(30):
                    while snapshot is None or snapshot.status_code != 200:
                        if snapshot is not None:  # 404 until the ROS 2 topic is discovered
                            await anyio.sleep(0.1)
                        snapshot = await http.get(
                            f"{video}/snapshot", params={"topic": "/ros2_camera"}
                        )
    finally:
        server.stop()
    assert snapshot.headers["content-type"] == "image/jpeg"
    pixels = np.asarray(Image.open(io.BytesIO(snapshot.content)).convert("RGB")).astype(int)
    assert pixels.shape == (4, 8, 3)
    assert pixels[:, :4, 0].mean() > 200 and pixels[:, :4, 2].mean() < 60  # red left half
    assert pixels[:, 4:, 2].mean() > 200 and pixels[:, 4:, 0].mean() < 60  # blue right half


async def test_a_bag_played_by_rwt_reaches_a_ros2_listener(ros_env: Path, tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    server = serve_ros2(ros_env, "--play", str(bag), "--loop")
    try:
        with Peer("listen", "/chatter", ros_env) as listener:
            heard = await anyio.to_thread.run_sync(listener.next)
    finally:
        server.stop()
    assert heard["heard"].startswith("chatter ") and heard["heard"].endswith(" ✓")


@CHECKPOINTS  # read while it records: the checkpoint writer's
async def test_record_records_a_ros2_topic(ros_env: Path, tmp_path: Path) -> None:
    out = tmp_path / "recorded"
    server = serve_ros2(ros_env, "--record", str(out), "--record-topics", "[/recorded_chatter]")
    try:
        with Peer("talk", "/recorded_chatter", ros_env):
            registry = TypeRegistry(Dialect.ROS2)
            count = 0
            with anyio.fail_after(30):
                while count < 5:  # the recorder writes as it goes; read what is there
                    await anyio.sleep(0.5)
                    count = _recorded(out, registry)
    finally:
        server.stop()
    assert count >= 5


def _recorded(out: Path, registry: TypeRegistry) -> int:
    if not any(out.glob("*.mcap")):
        return 0
    try:
        source = BagSource([out], registry)
    except BagError:  # not readable yet (no metadata until it closes)
        return 0
    try:
        return sum(1 for topic, *_ in source.messages() if topic.topic == "/recorded_chatter")
    except BagError:  # a chunk being written
        return 0
    finally:
        source.close()
