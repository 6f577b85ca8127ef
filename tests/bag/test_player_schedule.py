"""Pause, seek and resume keep the playback schedule (docs/record-replay.md).

The player reads a bag in batches (``player._BATCH_MESSAGES``). A playback that
started paused, or was paused, moved and resumed, used to take up its old
schedule again when the next batch came: the position went back to where it was
resumed and the player went silent for as long as it had already played. A web
scrub bar does exactly that, so the position a client reads
(``/rwt/player/get_status``, ``Player.position_s``) must only go forward, and
every message arrive, once, in order.
"""

from __future__ import annotations

import time
from pathlib import Path

import anyio
import anyio.lowlevel
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

import rwt
from rwt_bag import player as player_module

pytestmark = pytest.mark.anyio

SPACING_NS = 2_000_000  # a message every 2 ms of bag time
COUNT = 3 * player_module._BATCH_MESSAGES  # three reads: the old schedule came back at the second


def write_chatter(path: Path) -> Path:
    store = get_typestore(Stores.ROS2_HUMBLE)
    String = store.types["std_msgs/msg/String"]
    with Ros2Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        for i in range(COUNT):
            data = store.serialize_cdr(String(data=f"m{i}"), "std_msgs/msg/String")
            writer.write(conn, 1_000_000_000 + i * SPACING_NS, data)
    return path


async def watch(player: rwt.bag.Player, got: list[str], positions: list[float]) -> None:
    while len(got) < COUNT:
        positions.append(player.position_s)
        await anyio.sleep(0.01)


@pytest.mark.parametrize("rate", [1.0, 2.0])
async def test_a_playback_started_paused_keeps_its_schedule_after_resume(
    tmp_path: Path, rate: float
) -> None:
    bag = write_chatter(tmp_path / "bag")
    graph = rwt.Graph()
    got: list[str] = []
    graph.create_subscription("/chatter", lambda msg: got.append(msg["data"]), "std_msgs/String")
    player = rwt.bag.Player(graph, bag, rate=rate, paused=True, check=False)
    positions: list[float] = []
    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            await tg.start(player.run)
            await anyio.sleep(0.3)  # the first batch is read meanwhile, nothing published
            assert got == []
            player.resume()
            await watch(player, got, positions)
    assert got == [f"m{i}" for i in range(COUNT)]
    assert positions == sorted(positions), "the position went back"


@pytest.mark.parametrize("rate", [1.0, 2.0])
async def test_pause_seek_and_resume_go_on_from_the_new_position(
    tmp_path: Path, rate: float
) -> None:
    bag = write_chatter(tmp_path / "bag")
    graph = rwt.Graph()
    got: list[str] = []
    graph.create_subscription("/chatter", lambda msg: got.append(msg["data"]), "std_msgs/String")
    player = rwt.bag.Player(graph, bag, rate=rate, check=False)
    positions: list[float] = []
    seek_s = 0.5  # message 250
    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            await tg.start(player.run)
            while len(got) < 100:
                await anyio.sleep(0.01)
            player.pause()
            player.seek(seek_s)
            await anyio.sleep(0.3)
            before = len(got)
            player.resume()
            first = int(seek_s * 1e9 / SPACING_NS)
            while not got or got[-1] != f"m{COUNT - 1}":
                positions.append(player.position_s)
                await anyio.sleep(0.01)
    resumed = got[before:]
    assert resumed == [f"m{i}" for i in range(first, COUNT)]
    assert positions == sorted(positions), "the position went back"


async def test_the_clock_never_passes_a_message_published_late(tmp_path: Path) -> None:
    # A busy event loop publishes a message after its due time. The bag's clock
    # (the graph's timeline: Foxglove server time, /clock) must not have been read
    # past that message's record time meanwhile, or time steps back when it goes out.
    bag = write_chatter(tmp_path / "bag")
    graph = rwt.Graph()
    player = rwt.bag.Player(graph, bag, rate=4.0, check=False)
    readings: list[int] = []  # the clock as read by anyone, in the order read
    stamps: list[int] = []  # the clock when each message was published
    graph.create_subscription(
        "/chatter", lambda _msg: stamps.append(player.clock_ns()), "std_msgs/String"
    )
    graph.create_subscription(
        "/chatter", lambda _msg: readings.append(player.clock_ns()), "std_msgs/String"
    )
    with anyio.fail_after(60):
        async with anyio.create_task_group() as tg:
            await tg.start(player.run)
            while len(stamps) < COUNT:
                readings.append(player.bag_time_ns())
                time.sleep(0.01)  # noqa: ASYNC251 (the loop is busy: 5 messages' bag time)
                readings.append(player.bag_time_ns())
                await anyio.lowlevel.checkpoint()
            tg.cancel_scope.cancel()
    assert stamps == [1_000_000_000 + i * SPACING_NS for i in range(COUNT)]
    assert readings == sorted(readings), "the clock stepped back at a late message"
